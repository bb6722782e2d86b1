//! The fit against exact theoretical curves (no simulation noise): what goes in must come out,
//! absent terms must be reported with their estimate and interval and not detected, the reported
//! parameters must reproduce the model curve, bad input must be refused, nothing may hang.
use noise_model::effect::{markov_avar_unit, sinusoid_avar_unit};
use noise_model::{
    assess, fit, fit_model, Effect, FitError, FitOptions, Measurement, Point, TermSpec,
    DEFAULT_TERMS,
};

/// Points on an exact curve at octave τ (2^log2n samples) with a white-FM-like EDF ν = N/m;
/// bounds from the χ² 68.3 % quantiles approximated as σ(1 ∓ 1/√(2ν)).
fn curve_n(tau0: f64, log2n: u32, f: impl Fn(f64) -> f64) -> Vec<Point> {
    let n = (1u64 << log2n) as f64;
    (0..log2n - 2)
        .map(|k| {
            let m = 1u64 << k;
            let tau = m as f64 * tau0;
            let dev = f(tau).sqrt();
            let edf = (n / m as f64).max(2.0);
            let h = 1.0 / (2.0 * edf).sqrt();
            Point {
                tau,
                dev,
                edf,
                lo: dev * (1.0 - h),
                hi: dev * (1.0 + h),
                m,
            }
        })
        .collect()
}

fn specs(effects: &[Effect]) -> Vec<TermSpec> {
    effects.iter().cloned().map(TermSpec::new).collect()
}

#[test]
fn recovers_the_five_terms_from_an_exact_curve() {
    let (q, n, b, k, r) = (2e-4, 5e-3, 3e-3, 3e-4, 2e-5);
    let tau0 = 0.01;
    // the sampled forms: RRW K²(τ/3 + τ0²/(6τ)); 2^22 samples so each term dominates somewhere
    let pts = curve_n(tau0, 22, |t| {
        3.0 * q * q / (t * t)
            + n * n / t
            + 2.0 * std::f64::consts::LN_2 / std::f64::consts::PI * b * b
            + k * k * (t / 3.0 + tau0 * tau0 / (6.0 * t))
            + r * r * t * t / 2.0
    });
    let meas = Measurement::from_record(pts, tau0, 1 << 22);
    let f = fit_model(&meas, &specs(&DEFAULT_TERMS)).unwrap();
    for (e, v) in [
        (Effect::Quantization, q),
        (Effect::White, n),
        (Effect::Flicker, b),
        (Effect::RateRandomWalk, k),
        (Effect::RateRamp, r),
    ] {
        let t = f.term(&e).unwrap();
        assert!(t.detected, "{e}: {t:?}");
        assert!(
            // the fit is on the logs with their χ² bias corrected (E[ln χ²_ν/ν] ≈ −1/ν), so a
            // curve of exact expectations is recovered to 1 % (its long-τ points have ν of a few), not to rounding
            (t.amplitude() / v - 1.0).abs() < 1e-2,
            "{e}: {} vs {v}",
            t.amplitude()
        );
        assert!(
            t.amplitude_sigma() > 0.0 && t.amplitude_sigma() < 0.5 * v,
            "{e}"
        );
    }
    // the criterion vanishes; the goodness-of-fit statistic is small but not 0, since an estimate
    // at its mean sits slightly above the χ² median
    assert!(f.objective < 1e-2, "{}", f.objective);
    assert!(f.chi2_dof() < 0.1, "{}", f.chi2_dof());
    assert!(assess(&f).adequate);
}

#[test]
fn absent_terms_report_their_estimate_and_interval() {
    let n = 5e-3;
    let tau0 = 0.01;
    let pts = curve_n(tau0, 18, |t| n * n / t);
    let meas = Measurement::from_record(pts.clone(), tau0, 1 << 18);
    let f = fit_model(&meas, &specs(&DEFAULT_TERMS)).unwrap();
    for t in &f.terms {
        assert!(t.coef >= 0.0, "{t:?}");
        if t.effect == Effect::White {
            assert!(t.detected);
            continue;
        }
        assert!(!t.detected, "{t:?}");
        let p = &t.params()[0];
        // the estimate is what the model uses (here 0), with a finite σ and 95 % interval
        assert_eq!(p.value, t.amplitude());
        assert!(p.sigma.is_finite() && p.sigma > 0.0, "{p:?}");
        let (lo, hi) = p.interval;
        assert!(lo == 0.0 && hi > 0.0 && hi.is_finite(), "{p:?}");
        // at the top of its interval the term stays below the white noise somewhere in the τ
        // range (otherwise the data would have shown it)
        let basis = t.effect.basis(&t.theta, &f.ctx).unwrap();
        let at_top = pts
            .iter()
            .any(|p| hi * hi * basis.avar(p.m as f64, tau0) < n * n / p.tau);
        assert!(at_top, "{:?} interval top {hi}", t.effect);
    }
}

#[test]
fn reported_parameters_reproduce_the_model_curve() {
    // white + flicker + a loosely determined Markov term near τ0: every reported value,
    // detected or not, must give back the model the fit reports, by the textbook formulas
    let tau0 = 0.01;
    let (n, b, s, tc) = (5e-3, 1e-3, 0.02, 0.03);
    let pts = curve_n(tau0, 18, |t| {
        n * n / t
            + 2.0 * std::f64::consts::LN_2 / std::f64::consts::PI * b * b
            + s * s * markov_avar_unit(t, tau0, tc)
    });
    let meas = Measurement::from_record(pts, tau0, 1 << 18);
    let effects = [
        Effect::White,
        Effect::Flicker,
        Effect::RateRandomWalk,
        Effect::Markov,
    ];
    let f = fit_model(&meas, &specs(&effects)).unwrap();
    for (j, p) in f.points.iter().enumerate() {
        let tau = p.tau;
        let mut v = 0.0;
        for t in &f.terms {
            let pv = t.params();
            let a = pv[0].value;
            v += match t.effect {
                Effect::White => a * a / tau,
                Effect::Flicker => 2.0 * std::f64::consts::LN_2 / std::f64::consts::PI * a * a,
                Effect::RateRandomWalk => a * a * (tau / 3.0 + tau0 * tau0 / (6.0 * tau)),
                Effect::Markov => a * a * markov_avar_unit(tau, tau0, pv[1].value),
                _ => unreachable!(),
            };
        }
        let m = f.model_avar[j];
        assert!(
            (v - m).abs() <= 1e-9 * m,
            "τ {tau}: params give {v}, model {m}"
        );
    }
}

#[test]
fn markov_and_sinusoid_are_recovered() {
    let tau0 = 0.01;
    let n = 5e-3;
    let pts = curve_n(tau0, 18, |t| {
        n * n / t + 1e-4 * markov_avar_unit(t, tau0, 2.0)
    });
    let meas = Measurement::from_record(pts.clone(), tau0, 1 << 18);
    let base = fit_model(&meas, &specs(&DEFAULT_TERMS)).unwrap();
    assert!(!assess(&base).adequate);
    let mut sp = specs(&DEFAULT_TERMS);
    sp.push(TermSpec::new(Effect::Markov));
    let f = fit_model(&meas, &sp).unwrap();
    let t = f.term(&Effect::Markov).unwrap();
    // within O(1/ν) of the long-τ points (the log fit's bias correction, see above)
    assert!((t.theta[0] / 2.0 - 1.0).abs() < 1e-2, "{t:?}");
    assert!((t.amplitude() / 1e-2 - 1.0).abs() < 1e-2, "{t:?}");
    assert!(
        f.objective < 1e-2 && f.chi2_dof() < 0.1 && base.chi2_dof() > 10.0,
        "{} {} {}",
        f.objective,
        f.chi2_dof(),
        base.chi2_dof()
    );

    let pts = curve_n(tau0, 18, |t| {
        n * n / t + 4e-4 * sinusoid_avar_unit(t, tau0, 0.3)
    });
    let meas = Measurement::from_record(pts, tau0, 1 << 18);
    let mut sp = specs(&DEFAULT_TERMS);
    sp.push(TermSpec::new(Effect::Sinusoid));
    let f = fit_model(&meas, &sp).unwrap();
    let t = f.term(&Effect::Sinusoid).unwrap();
    assert!((t.theta[0] / 0.3 - 1.0).abs() < 1e-3, "{t:?}");
    assert!((t.amplitude() / 0.02 - 1.0).abs() < 1e-3, "{t:?}");
}

#[test]
fn bad_input_is_refused_with_a_reason() {
    let mut pts = curve_n(0.01, 18, |t| 1e-4 / t);
    pts[3].dev = f64::NAN;
    match fit(&pts, 0.01, &DEFAULT_TERMS, &FitOptions::default()) {
        Err(FitError::BadPoint { index: 3, .. }) => {}
        other => panic!("{other:?}"),
    }
    let pts = curve_n(0.01, 18, |t| 1e-4 / t);
    match fit(&pts[..5], 0.01, &DEFAULT_TERMS, &FitOptions::default()) {
        Err(
            e @ FitError::TooFewPoints {
                points: 5,
                params: 5,
            },
        ) => {
            assert!(e.to_string().contains("need at least 6"))
        }
        other => panic!("{other:?}"),
    }
    assert!(matches!(
        fit(
            &pts,
            0.01,
            &[Effect::White, Effect::White],
            &FitOptions::default()
        ),
        Err(FitError::BadTerms(_))
    ));
    assert!(matches!(
        fit(&pts, 0.0, &DEFAULT_TERMS, &FitOptions::default()),
        Err(FitError::BadTerms(_))
    ));
}

#[test]
fn absurd_scales_end_in_finite_time() {
    // deviations from 1e-300 to 1e300 and a τ0 of 1e-300: a result or an error, never a hang
    for scale in [1e-300f64, 1e-150, 1e150, 1e300] {
        let pts: Vec<Point> = curve_n(0.01, 16, |t| 1e-4 / t)
            .into_iter()
            .map(|mut p| {
                p.dev *= scale.sqrt();
                p.lo *= scale.sqrt();
                p.hi *= scale.sqrt();
                p
            })
            .collect();
        let _ = fit(&pts, 0.01, &DEFAULT_TERMS, &FitOptions::default());
    }
    let pts = curve_n(0.01, 16, |t| 1e-4 / t);
    for tau0 in [1e-300, 1e300] {
        let _ = fit(&pts, tau0, &DEFAULT_TERMS, &FitOptions::default());
    }
}

/// The model's 1σ per τ (`Fit::model_dev_sigma`): with white noise alone it is N's σ over √τ
/// exactly (one coefficient, its basis 1/τ); with white noise and a Markov process (a
/// non-linear τ_c) it agrees with the deviation's spread over draws of the parameters from
/// their covariance, within the sampling error of 4,000 draws.
#[test]
fn the_models_sigma_per_tau_is_the_parameters_propagated() {
    let key = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(1, |d| d.subsec_nanos() as u64)
        | 1;
    let n = 2e-3 * (1.0 + (key % 97) as f64 / 50.0);
    let tau0 = 0.01;
    let pts = curve_n(tau0, 18, |t| n * n / t);
    let meas = Measurement::from_record(pts, tau0, 1 << 18);
    let f = fit_model(&meas, &specs(&[Effect::White])).unwrap();
    let w = f.term(&Effect::White).unwrap();
    let want = w.coef_sigma / (2.0 * w.coef.sqrt());
    for (i, p) in f.points.iter().enumerate() {
        let got = f.model_dev_sigma(i) * p.tau.sqrt();
        assert!(
            (got / want - 1.0).abs() < 1e-9,
            "key {key}: τ {}: {got} vs {want}",
            p.tau
        );
    }
    // A covariance that is not finite leaves the model's σ unknown, never 0.
    let mut broken = f.clone();
    broken.param_cov[(0, 0)] = f64::NAN;
    assert!(broken.model_dev_sigma(0).is_nan());

    // White + Markov (σ, τ_c): the propagation against a Monte-Carlo of the parameters.
    let (sigma, tau_c) = (4e-3, 0.5 * (1.0 + (key % 13) as f64 / 10.0));
    let pts = curve_n(tau0, 20, |t| {
        n * n / t + sigma * sigma * markov_avar_unit(t, tau0, tau_c)
    });
    let meas = Measurement::from_record(pts, tau0, 1 << 20);
    let f = fit_model(&meas, &specs(&[Effect::White, Effect::Markov])).unwrap();
    let dim = f.param_index.len();
    assert_eq!(dim, 3, "white c, Markov c and τ_c: {:?}", f.param_index);
    // Cholesky of the covariance.
    let c = &f.param_cov;
    let mut l = vec![vec![0.0; dim]; dim];
    for i in 0..dim {
        for j in 0..=i {
            let s: f64 = (0..j).map(|k| l[i][k] * l[j][k]).sum();
            l[i][j] = if i == j {
                (c[(i, i)] - s).max(0.0).sqrt()
            } else {
                (c[(i, j)] - s) / l[j][j]
            };
        }
    }
    let mut state = key;
    let mut normal = || {
        // Box–Muller from xorshift uniforms.
        let mut u = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            ((state >> 11) as f64 + 0.5) / (1u64 << 53) as f64
        };
        let (a, b) = (u(), u());
        (-2.0 * a.ln()).sqrt() * (std::f64::consts::TAU * b).cos()
    };
    let draws = 4000;
    for (i, p) in f.points.iter().enumerate().step_by(3) {
        let mut acc = (0.0, 0.0);
        for _ in 0..draws {
            let z: Vec<f64> = (0..dim).map(|_| normal()).collect();
            let mut terms = f.terms.clone();
            for (r, &(k, j)) in f.param_index.iter().enumerate() {
                let d: f64 = (0..=r).map(|q| l[r][q] * z[q]).sum();
                if j == 0 {
                    terms[k].coef += d;
                } else {
                    terms[k].theta[j - 1] += d;
                }
            }
            let avar: f64 = terms.iter().map(|t| t.avar(p.tau, &f.ctx)).sum();
            let dev = avar.max(0.0).sqrt();
            acc = (acc.0 + dev, acc.1 + dev * dev);
        }
        let mean = acc.0 / draws as f64;
        let sd = (acc.1 / draws as f64 - mean * mean).max(0.0).sqrt();
        let got = f.model_dev_sigma(i);
        // The spread of a sample SD of 4,000 normal draws is ≈ 1.1 %; the linearisation adds
        // its own where a parameter's σ is not small.
        assert!(
            (got / sd - 1.0).abs() < 0.08,
            "key {key}: τ {}: propagated {got}, drawn {sd}",
            p.tau
        );
    }
}
