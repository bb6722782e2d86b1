//! The fit against exact theoretical curves (no simulation noise): what goes in must come out,
//! absent terms must be reported as not detected with an upper bound, bad input must be refused.
use noise_model::{
    assess, diagnose, fit, step, Effect, FitError, FitOptions, Point, DEFAULT_TERMS,
};

/// Points on an exact curve at octave τ with a white-FM-like EDF ν = N/m (N = 2^18 samples);
/// bounds from the χ² 68.3 % quantiles approximated as σ(1 ∓ 1/√(2ν)).
fn curve(tau0: f64, f: impl Fn(f64) -> f64) -> Vec<Point> {
    curve_n(tau0, 18, f)
}

fn curve_n(tau0: f64, log2n: u32, f: impl Fn(f64) -> f64) -> Vec<Point> {
    let n = (1u64 << log2n) as f64;
    (0..log2n - 2)
        .map(|k| {
            let m = (1u64 << k) as f64;
            let tau = m * tau0;
            let dev = f(tau).sqrt();
            let edf = (n / m).max(2.0);
            let h = 1.0 / (2.0 * edf).sqrt();
            Point {
                tau,
                dev,
                edf,
                lo: dev * (1.0 - h),
                hi: dev * (1.0 + h),
            }
        })
        .collect()
}

#[test]
fn recovers_the_five_terms_from_an_exact_curve() {
    let (q, n, b, k, r) = (2e-4, 5e-3, 3e-3, 3e-4, 2e-5);
    let tau0 = 0.01;
    // 2^22 samples (11.6 h at 100 Hz): enough octaves for each term to dominate somewhere
    let pts = curve_n(tau0, 22, |t| {
        3.0 * q * q / (t * t)
            + n * n / t
            + 2.0 * std::f64::consts::LN_2 / std::f64::consts::PI * b * b
            + k * k * t / 3.0
            + r * r * t * t / 2.0
    });
    let f = fit(&pts, tau0, &DEFAULT_TERMS, &FitOptions::default()).unwrap();
    // an exact curve is fitted exactly: every amplitude to 1e-6 relative, χ² ≈ 0
    for (e, v) in [
        (Effect::Quantization, q),
        (Effect::White, n),
        (Effect::Flicker, b),
        (Effect::RateRandomWalk, k),
        (Effect::RateRamp, r),
    ] {
        let t = f.term(e).unwrap();
        assert!(t.detected, "{e}: {t:?}");
        assert!(
            (t.amplitude() / v - 1.0).abs() < 1e-6,
            "{e}: {} vs {v}",
            t.amplitude()
        );
        assert!(
            t.amplitude_sigma() > 0.0 && t.amplitude_sigma() < 0.5 * v,
            "{e}"
        );
    }
    assert!(f.chi2 < 1e-9);
    assert!(assess(&f).adequate);
}

#[test]
fn absent_terms_are_not_detected_with_an_upper_bound() {
    let n = 5e-3;
    let pts = curve(0.01, |t| n * n / t);
    let f = fit(&pts, 0.01, &DEFAULT_TERMS, &FitOptions::default()).unwrap();
    for t in &f.terms {
        assert!(t.coef >= 0.0, "{:?}", t);
        if t.effect == Effect::White {
            assert!(t.detected);
            continue;
        }
        assert!(!t.detected, "{:?}", t);
        let p = &t.params()[0];
        assert_eq!(p.value, 0.0);
        let ub = p.upper_bound.expect("upper bound");
        // the bound is positive and the term at its bound stays below the white noise somewhere
        // in the τ range (otherwise the data would have shown it)
        assert!(ub > 0.0 && ub.is_finite());
        let at_bound = pts
            .iter()
            .any(|p| ub * ub * t.effect.basis(p.tau, 0.01, f64::NAN) < n * n / p.tau);
        assert!(at_bound, "{:?} bound {ub}", t.effect);
    }
}

#[test]
fn markov_and_sinusoid_are_recovered_and_named() {
    let tau0 = 0.01;
    let n = 5e-3;
    let mk = |t: f64| n * n / t + 1e-4 * noise_model::effect::markov_avar_unit(t, tau0, 2.0);
    let pts = curve(tau0, mk);
    let base = fit(&pts, tau0, &DEFAULT_TERMS, &FitOptions::default()).unwrap();
    let a = assess(&base);
    assert!(!a.adequate);
    let d = diagnose(&base, &a, None);
    assert_eq!(d.missing, Some(Effect::Markov), "{}", d.explanation);
    let c = &d.candidates[0];
    let t = c.fit.term(Effect::Markov).unwrap();
    // exact curve: τ_c and sigma to 1e-4 relative
    assert!((t.theta.unwrap() / 2.0 - 1.0).abs() < 1e-4, "{t:?}");
    assert!((t.amplitude() / 1e-2 - 1.0).abs() < 1e-4, "{t:?}");
    let s = step(&base, &a, &c.fit, &c.assessment);
    assert_eq!(s.added, vec![Effect::Markov]);
    assert!(s.after.chi2_dof < 1e-6 && s.before.chi2_dof > 10.0);
    assert!(s.after.rms_log_residual < 1e-4 && s.before.rms_log_residual > 0.01);

    let sn = |t: f64| n * n / t + 4e-4 * noise_model::effect::sinusoid_avar_unit(t, tau0, 0.3);
    let pts = curve(tau0, sn);
    let base = fit(&pts, tau0, &DEFAULT_TERMS, &FitOptions::default()).unwrap();
    let a = assess(&base);
    let d = diagnose(&base, &a, None);
    assert_eq!(d.missing, Some(Effect::Sinusoid), "{}", d.explanation);
    let t = d.candidates[0].fit.term(Effect::Sinusoid).unwrap().clone();
    assert!((t.theta.unwrap() / 0.3 - 1.0).abs() < 1e-3, "{t:?}");
    assert!((t.amplitude() / 0.02 - 1.0).abs() < 1e-3, "{t:?}");
}

#[test]
fn bad_input_is_refused_with_a_reason() {
    let mut pts = curve(0.01, |t| 1e-4 / t);
    pts[3].dev = f64::NAN;
    match fit(&pts, 0.01, &DEFAULT_TERMS, &FitOptions::default()) {
        Err(FitError::BadPoint { index: 3, .. }) => {}
        other => panic!("{other:?}"),
    }
    let pts = curve(0.01, |t| 1e-4 / t);
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
}
