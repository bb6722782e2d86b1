//! Hidden-effect and control tests on simulated data, analysed exactly as `imu-lab fit --auto`
//! does: OADEV at octave τ from `allan::deviation`, the noise lab on the record (time series,
//! spectrum, lattice), the automatic walk diagnose → add → refit.
//!
//! Each case is a failure mode of real recordings: a bias step, a temperature-driven bias, a
//! warm-up, a spectral line (near Nyquist and slow), the sensor's own filters, correlated noise, a
//! mount resonance, irregular timestamps. Each runs more than one seed; estimates must lie within
//! 4σ of the truth (p ≈ 6e-5 per check for a Gaussian estimator) and within a relative band that
//! says what "recovered" means physically.
use allan::{deviation, Stat, TauSet};
use imu_sim::{SimConfig, SimEffect};
use noise_model::{
    walk, Effect, Model, NoiseLab, Stop, Timing, Walk, ALL_EFFECTS, EQUAL_SUPPORT, NEAR_SUPPORT,
};

use imu_sim::gyro_background as gyro;

fn cfg(rate: f64, secs: f64, seed: u64, effects: Vec<SimEffect>) -> SimConfig {
    SimConfig::new(rate, (rate * secs) as usize, seed, effects)
}

struct Run {
    walk: Walk<Effect, Model>,
    report: String,
}

impl Run {
    /// The effects the walk added and those it removed, each in order.
    fn edits(&self) -> (Vec<Effect>, Vec<Effect>) {
        let (mut added, mut removed) = (Vec::new(), Vec::new());
        for s in &self.walk.steps {
            added.extend(s.edit.add.iter().cloned());
            removed.extend(s.edit.remove.iter().cloned());
        }
        (added, removed)
    }

    /// Parameter `i` of `e` in the last model is `truth` (4σ and `rel`, see [`check`]).
    fn recovered(&self, name: &str, e: &Effect, i: usize, truth: f64, rel: f64) {
        let (est, sigma) = param(self.walk.last(), e, i);
        check(name, est, sigma, truth, rel, &self.report);
    }
}

fn run_with(c: &SimConfig, timing: Option<Timing>) -> Run {
    run_full(c, timing).0
}

/// The walk and the diagnosis of its last model.
fn run_full(c: &SimConfig, timing: Option<Timing>) -> (Run, noise_model::Diagnosis) {
    let a = c.analyse();
    let lab = NoiseLab::new(a.record(timing)).expect("lab");
    let start = lab.fit(&lab.default_specs()).expect("fit");
    let w = walk(&lab, start, 5).expect("walk");
    let mut report = format!("seed {} effects {:?}\n", c.seed, c.effects);
    for s in &w.steps {
        report += &format!(
            "  step {}: χ²/dof {:.2} → {:.2} ({}; p {:.1e})\n",
            s.edit, s.before.chi2_dof, s.after.chi2_dof, s.reading, s.p_value
        );
    }
    report += &format!("  stop: {}\n", w.stop);
    for t in &w.last().fit.terms {
        report += &format!(
            "  {} {:?}\n",
            t.effect,
            t.params()
                .iter()
                .map(|p| (p.name.clone(), p.value, p.sigma))
                .collect::<Vec<_>>()
        );
    }
    for c in w.last_candidates.iter().take(4) {
        report += &format!("  tried {}: p {:.1e} {}\n", c.edit, c.p_value, c.reason);
    }
    let d = noise_model::diagnose(&lab, w.last()).expect("diagnosis");
    (Run { walk: w, report }, d)
}

fn run(c: &SimConfig) -> Run {
    run_with(c, None)
}

/// The gyro background (with its white noise) plus `extra`, an hour at 100 Hz.
fn hidden(extra: SimEffect, seed: u64) -> Run {
    let mut e = gyro(true);
    e.push(extra);
    run(&cfg(100.0, 3600.0, seed, e))
}

/// `est` within 4σ of `truth` and within `rel` of it.
fn check(name: &str, est: f64, sigma: f64, truth: f64, rel: f64, rep: &str) {
    assert!(
        (est - truth).abs() <= 4.0 * sigma + 1e-300 && (est / truth - 1.0).abs() <= rel,
        "{name}: estimate {est} ± {sigma}, truth {truth} (4σ and {rel} relative)\n{rep}"
    );
}

/// The walk added exactly `effects` (in order), removed `removed`, and ended adequate.
fn named(r: &Run, effects: &[Effect], removed: &[Effect]) {
    let (added, gone) = r.edits();
    assert_eq!(added, effects, "{}", r.report);
    assert_eq!(gone, removed, "{}", r.report);
    assert_eq!(r.walk.stop, Stop::Adequate, "{}", r.report);
    assert!(r.walk.last().adequate, "{}", r.report);
    for s in &r.walk.steps {
        assert!(
            s.after.rms_residual <= s.before.rms_residual * 1.05,
            "{}",
            r.report
        );
    }
}

fn param(m: &Model, e: &Effect, i: usize) -> (f64, f64) {
    let t = m.fit.term(e).unwrap_or_else(|| panic!("{e} in the model"));
    let p = &t.params()[i];
    (p.value, p.sigma)
}

#[test]
fn controls_stay_silent() {
    // power-law mixes, 100 Hz and 1 kHz, 10 min to 1 h: adequate, nothing added, no finding
    let sets = [
        (100.0, 3600.0, gyro(true)),
        (1000.0, 600.0, gyro(true)),
        (
            100.0,
            1800.0,
            vec![
                SimEffect::White { n: 4e-3 },
                SimEffect::RateRandomWalk { k: 3e-4 },
            ],
        ),
        (
            100.0,
            3600.0,
            vec![
                SimEffect::White { n: 5e-3 },
                SimEffect::RateRamp { r: 2e-5 },
            ],
        ),
    ];
    for (i, (rate, secs, eff)) in sets.into_iter().enumerate() {
        for seed in 0..2 {
            let r = run(&cfg(rate, secs, 100 + 10 * i as u64 + seed, eff.clone()));
            named(&r, &[], &[]);
        }
    }
}

#[test]
fn a_bias_step_is_named_and_no_longer_read_as_random_walk() {
    for (seed, size, at) in [(1u64, 0.1, 1800.0), (2, 0.03, 1234.5)] {
        let r = hidden(SimEffect::BiasStep { at_s: at, size }, seed);
        named(&r, &[Effect::BiasStep], &[]);
        let m = r.walk.last();
        let (s, ss) = param(m, &Effect::BiasStep, 0);
        check("step size", s, ss, size, 0.1, &r.report);
        let (t, _) = param(m, &Effect::BiasStep, 1);
        assert!(
            (t - at).abs() < 60.0,
            "step at {t} s, truth {at} s\n{}",
            r.report
        );
        // the random walk no longer absorbs the step: K within 4σ of the truth
        let (k, ks) = param(m, &Effect::RateRandomWalk, 0);
        assert!((k - 1e-4).abs() <= 4.0 * ks, "K {k} ± {ks}\n{}", r.report);
    }
}

#[test]
fn a_temperature_driven_bias_is_named_in_place_of_the_ramp() {
    for seed in [3u64, 4] {
        let r = hidden(
            SimEffect::Temperature {
                coef: 0.02,
                start_c: 25.0,
                rise_c: 15.0,
                tau_s: 900.0,
            },
            seed,
        );
        named(&r, &[Effect::Temperature], &[Effect::RateRamp]);
        r.recovered("coefficient", &Effect::Temperature, 0, 0.02, 0.1);
    }
}

#[test]
fn a_warm_up_without_a_temperature_column_is_named() {
    for seed in [5u64, 6] {
        let r = hidden(
            SimEffect::WarmUp {
                amplitude: 0.2,
                tau_s: 600.0,
            },
            seed,
        );
        let (added, _) = r.edits();
        assert_eq!(added.first(), Some(&Effect::Temperature), "{}", r.report);
        assert_eq!(r.walk.stop, Stop::Adequate, "{}", r.report);
        r.recovered("warm-up amplitude", &Effect::Temperature, 0, 0.2, 0.15);
        let (tw, _) = param(r.walk.last(), &Effect::Temperature, 1);
        assert!((tw / 600.0 - 1.0).abs() < 0.35, "τ_w {tw}\n{}", r.report);
    }
}

#[test]
fn a_smooth_drift_is_one_drift_not_a_staircase() {
    // random shapes (a logistic transition of random instant, width and sign plus a quadratic
    // bow) and random data: one edit, the drift in place of the ramp, adequate, no step, the
    // RMS log-residual not worse, and the drift's size recovered
    let mut rng = imu_sim::Rng::new(0xd21f_7000);
    for _ in 0..3 {
        let rms = 0.03 + 0.03 * rng.uniform();
        let r = hidden(
            SimEffect::Drift {
                rms,
                shape_seed: rng.next_u64() % 10_000,
            },
            rng.next_u64() % 10_000,
        );
        let drift = Effect::Drift { components: 0 };
        let (added, gone) = r.edits();
        assert_eq!(added, std::slice::from_ref(&drift), "{}", r.report);
        assert_eq!(gone, [Effect::RateRamp], "{}", r.report);
        assert_eq!(r.walk.stop, Stop::Adequate, "{}", r.report);
        // the Allan fit not worse: χ²/dof not up, and the RMS log-residual not up by more than
        // 5 % unless both sit at the level of the points' own scatter (1-h record: ~0.02)
        let s = &r.walk.steps[0];
        assert!(s.after.chi2_dof <= s.before.chi2_dof * 1.05, "{}", r.report);
        assert!(
            s.after.rms_residual <= (s.before.rms_residual * 1.05).max(0.03),
            "{}",
            r.report
        );
        r.recovered("drift rms", &drift, 0, rms, 0.25);
    }
}

#[test]
fn spectral_lines_are_named_sinusoid_not_markov() {
    // a line just below Nyquist and a slow one: named from the periodogram, f pinned there
    for (seed, amp, f) in [(7u64, 0.01, 49.5), (8, 0.003, 0.1)] {
        let r = hidden(
            SimEffect::Sinusoid {
                amplitude: amp,
                freq_hz: f,
            },
            seed,
        );
        named(&r, &[Effect::Sinusoid], &[]);
        let m = r.walk.last();
        let (fe, fs) = param(m, &Effect::Sinusoid, 1);
        check("frequency", fe, fs.max(1e-4), f, 0.01, &r.report);
        let (a, s) = param(m, &Effect::Sinusoid, 0);
        check("amplitude", a, s, amp, 0.3, &r.report);
    }
}

#[test]
fn the_sensors_own_filters_are_named() {
    // one-pole DLPF at 5 Hz; a Bartlett decimation filter of 4 samples; a boxcar of 8 samples:
    // each replaces the white term it shapes, with its corner or length recovered
    let lp = cfg(100.0, 1800.0, 9, {
        let mut e = gyro(false);
        e.push(SimEffect::LowPassWhite {
            n: 5e-3,
            cutoff_hz: 5.0,
            order: 1,
        });
        e
    });
    let r = run(&lp);
    named(&r, &[Effect::Lowpass], &[Effect::White]);
    r.recovered("cutoff", &Effect::Lowpass, 1, 5.0, 0.1);
    for (seed, length, bartlett) in [(10u64, 4usize, true), (11, 8, false)] {
        let mut e = gyro(false);
        e.push(SimEffect::Decimated {
            n: 5e-3,
            length,
            bartlett,
        });
        let r = run(&cfg(100.0, 10_000.0, seed, e));
        let eff = if bartlett {
            Effect::Bartlett
        } else {
            Effect::Boxcar
        };
        named(&r, std::slice::from_ref(&eff), &[Effect::White]);
        r.recovered("length", &eff, 1, length as f64, 0.05);
        r.recovered("N", &eff, 0, 5e-3, 0.02);
    }
}

#[test]
fn equally_supported_filter_shapes_go_to_the_simplest_and_are_named() {
    // The emulated MPU-6050's DLPF: one pole at 188 Hz on 1 kHz samples, one minute. Near
    // Nyquist the one-pole, two-pole and decimation shapes differ by little on 60 s of data.
    // Among candidates within EQUAL_SUPPORT of the best criterion the simplest goes first (fewest
    // parameters, then the vocabulary's order), and its reading names the others within
    // NEAR_SUPPORT. By the criterion alone the one-pole truth came first for 3 of these 10 seeds.
    let order = |c: &noise_model::Candidate<Effect, Model>| {
        let pos = |e: &Effect| ALL_EFFECTS.iter().position(|v| v == e).unwrap_or(99);
        (
            c.extra_params,
            c.edit.add.iter().map(pos).min().unwrap_or(99),
        )
    };
    let mut one_pole_first = 0;
    for seed in 20..30u64 {
        let mut e = gyro(false);
        e.push(SimEffect::LowPassWhite {
            n: 1e-2,
            cutoff_hz: 188.0,
            order: 1,
        });
        let c = cfg(1000.0, 60.0, seed, e);
        let a = c.analyse();
        let lab = NoiseLab::new(a.record(None)).expect("lab");
        let start = lab.fit(&lab.default_specs()).expect("fit");
        let cands = lab.candidate_edits(&start).expect("candidates");
        let adm: Vec<_> = cands.iter().filter(|c| c.admissible).collect();
        let crit = |c: &noise_model::Candidate<Effect, Model>| NoiseLab::criterion(&c.model);
        let best = adm.iter().map(|c| crit(c)).fold(f64::INFINITY, f64::min);
        let first = adm[0];
        let equal: Vec<_> = adm
            .iter()
            .filter(|c| crit(c) <= best + EQUAL_SUPPORT)
            .collect();
        assert!(crit(first) <= best + EQUAL_SUPPORT, "seed {seed}");
        assert!(
            equal.iter().all(|c| order(first) <= order(c)),
            "seed {seed}: {} first",
            first.edit
        );
        for c in &adm[1..] {
            if crit(c) <= crit(first) + NEAR_SUPPORT {
                assert!(
                    first.reading.contains(&c.reading),
                    "seed {seed}: {} not named beside {}",
                    c.edit,
                    first.reading
                );
            }
        }
        if first.edit.add == [Effect::Lowpass] {
            let (fc, s) = param(&first.model, &Effect::Lowpass, 1);
            check("cutoff", fc, s, 188.0, 0.1, &first.reading);
            one_pole_first += 1;
        }
    }
    assert!(
        one_pole_first >= 6,
        "one-pole first for {one_pole_first} of 10 seeds"
    );
}

#[test]
fn correlated_noise_is_named_markov() {
    for seed in [12u64, 13] {
        let r = hidden(
            SimEffect::Markov {
                sigma: 0.01,
                tau_c: 2.0,
            },
            seed,
        );
        named(&r, &[Effect::Markov], &[]);
        r.recovered("τ_c", &Effect::Markov, 1, 2.0, 0.4);
    }
}

#[test]
fn a_resonance_is_named_not_sinusoid_markov_or_lowpass2() {
    // A mount mode: f0 in 8–25 Hz, ζ in 0.05–0.3, sigma 0.02–0.04 °/s on the gyro background,
    // 25 min at 100 Hz, parameters and seeds drawn at random. The Welch PSD shows a band, the lab
    // proposes the resonance there and the Allan fit refines f0 and ζ.
    let mut pick = imu_sim::Rng::new(0x5e50);
    for _ in 0..4 {
        let f0 = 8.0 + 17.0 * pick.uniform();
        let zeta = 0.05 + 0.25 * pick.uniform();
        let sigma = 0.02 + 0.02 * pick.uniform();
        let seed = pick.next_u64() % 1_000_000;
        let mut e = gyro(true);
        e.push(SimEffect::Resonance {
            sigma,
            f0_hz: f0,
            zeta,
        });
        let r = run(&cfg(100.0, 1500.0, seed, e));
        // As `named`, without its RMS check: the unweighted RMS log-residual weighs every octave
        // alike, the long-τ ones of wide CI too, and can rise when the resonance joins (measured
        // 0.146 → 0.194 for f0 11.4 Hz, ζ 0.16, seed 154478, while χ²/dof fell 266 → 0.86). The
        // walk's end (adequate) also rests on the verdict and the candidate criterion.
        let (added, removed) = r.edits();
        assert_eq!(added, [Effect::Resonance], "{}", r.report);
        assert!(removed.is_empty(), "{}", r.report);
        assert_eq!(r.walk.stop, Stop::Adequate, "{}", r.report);
        assert!(r.walk.last().adequate, "{}", r.report);
        let m = r.walk.last();
        let (fe, fs) = param(m, &Effect::Resonance, 1);
        check("f0", fe, fs, f0, 0.05, &r.report);
        let (ze, zs) = param(m, &Effect::Resonance, 2);
        check("ζ", ze, zs, zeta, 0.4, &r.report);
        let (se, ss) = param(m, &Effect::Resonance, 0);
        check("sigma", se, ss, sigma, 0.2, &r.report);
        eprintln!(
            "resonance f0 {f0:.2} Hz → {fe:.2} ± {fs:.2}; ζ {zeta:.3} → {ze:.3} ± {zs:.3}; \
             σ {sigma:.4} → {se:.4} ± {ss:.4}"
        );
    }
}

#[test]
fn no_band_without_a_resonance() {
    // The band detector stays silent on the power-law background, on a spectral line, on
    // first-order Markov noise and on the sensor's own low-pass filters, and finds the band of a
    // resonance at its f0. Measured with the thresholds removed: the quiet records' best band
    // shapes reach Δχ² 6–14 (threshold 100) and peak ratios 0.10–0.38 (threshold 0.25: the Δχ²
    // gate is the one that separates them); the resonance's band Δχ² ≈ 3200, peak ratio 3.4.
    let with = |extra: Option<SimEffect>, seed: u64| {
        let mut e = gyro(true);
        e.extend(extra);
        let c = cfg(100.0, 1500.0, seed, e);
        let y = c.generate();
        let p = noise_model::psd::welch(&y, c.rate_hz, noise_model::psd::default_segment(y.len()))
            .unwrap();
        noise_model::psd::find_band(&p, c.tau0())
    };
    let quiet = [
        None,
        Some(SimEffect::Sinusoid {
            amplitude: 0.01,
            freq_hz: 12.0,
        }),
        Some(SimEffect::Markov {
            sigma: 0.02,
            tau_c: 0.05,
        }),
        Some(SimEffect::LowPassWhite {
            n: 5e-3,
            cutoff_hz: 10.0,
            order: 2,
        }),
        Some(SimEffect::LowPassWhite {
            n: 5e-3,
            cutoff_hz: 20.0,
            order: 1,
        }),
    ];
    for (i, e) in quiet.into_iter().enumerate() {
        for seed in 0..2 {
            let b = with(e, 1400 + 10 * i as u64 + seed);
            assert_eq!(b, None, "{e:?} seed {seed}");
        }
    }
    let b = with(
        Some(SimEffect::Resonance {
            sigma: 0.03,
            f0_hz: 15.0,
            zeta: 0.1,
        }),
        1450,
    )
    .expect("a band");
    assert!((b.f0_hz / 15.0 - 1.0).abs() < 0.1, "{b:?}");
}

#[test]
fn irregular_timestamps_are_named_before_any_spectral_effect() {
    // a record whose stamps came in bursts: the line is not turned into a sinusoid or a Markov
    // term, and the diagnosis says why
    let mut e = gyro(true);
    e.push(SimEffect::Sinusoid {
        amplitude: 0.01,
        freq_hz: 31.6,
    });
    // host read times: bursts of four samples 0.9 ms apart every 40 ms (the real MPU-6050 logs
    // of sensor-fusion have median 0.9 ms, 95th percentile 44 ms)
    let c = cfg(100.0, 1800.0, 14, e);
    let t: Vec<f64> = (0..c.n_samples)
        .map(|i| (i / 4) as f64 * 0.04 + (i % 4) as f64 * 0.0009)
        .collect();
    let timing = imu_proto::csv::timing(&t, None).unwrap();
    assert!(timing.irregular());
    let (r, d) = run_full(&c, Some(timing));
    for s in &r.walk.steps {
        for e in &s.edit.add {
            assert!(
                !matches!(e, Effect::Sinusoid | Effect::Markov | Effect::Lowpass),
                "{}",
                r.report
            );
        }
    }
    assert!(
        d.evidence
            .iter()
            .any(|e| e.contains("timestamps are irregular")),
        "{:?}",
        d.evidence
    );
}

#[test]
fn theoretical_curve_matches_measurement() {
    // The simulator's exact curve against OADEV of its own data, for a mix of every effect it
    // makes: every octave point within 3.5 CI half-widths.
    let c = SimConfig {
        rate_hz: 100.0,
        n_samples: 1 << 17,
        seed: 42,
        effects: vec![
            SimEffect::Quantization { q: 3e-4 },
            SimEffect::White { n: 4e-3 },
            SimEffect::Flicker { b: 2e-3 },
            SimEffect::RateRandomWalk { k: 2e-4 },
            SimEffect::RateRamp { r: 1e-6 },
            SimEffect::Markov {
                sigma: 5e-3,
                tau_c: 1.0,
            },
            SimEffect::Sinusoid {
                amplitude: 3e-3,
                freq_hz: 0.7,
            },
            SimEffect::LowPassWhite {
                n: 2e-3,
                cutoff_hz: 5.0,
                order: 2,
            },
            SimEffect::Decimated {
                n: 2e-3,
                length: 3,
                bartlett: true,
            },
            SimEffect::BiasStep {
                at_s: 700.0,
                size: 0.01,
            },
            SimEffect::WarmUp {
                amplitude: 0.02,
                tau_s: 100.0,
            },
            SimEffect::Resonance {
                sigma: 4e-3,
                f0_hz: 17.0,
                zeta: 0.1,
            },
        ],
        lsb: Some(1e-3),
    };
    let y = c.generate();
    let rows = deviation(&y, c.tau0(), Stat::Oadev, &TauSet::Octave).unwrap();
    for r in rows.iter().filter(|r| r.edf.is_finite()) {
        let th = c.avar(r.m as usize).sqrt();
        let z = noise_model::assess::residual(r.dev, r.lo, r.hi, th);
        assert!(
            z.abs() < 3.5,
            "τ {} s: measured {} theory {} (z {z})",
            r.tau,
            r.dev,
            th
        );
    }
}

#[test]
fn no_spectral_line_in_control_data() {
    // The Welch line detector must not report a line in line-free noise whose spectrum rises
    // steeply towards DC (flicker + random walk): family-wise false-alarm rate 1e-3 by design.
    for seed in 0..4 {
        let c = cfg(100.0, 2621.44, 1300 + seed, gyro(true));
        let y = c.generate();
        let p = noise_model::psd::welch(&y, c.rate_hz, noise_model::psd::default_segment(y.len()))
            .unwrap();
        assert_eq!(noise_model::find_line(&p), None, "seed {seed}");
    }
}

#[test]
fn a_user_described_effect_fits_like_the_builtin() {
    // a user's file describing the Gauss–Markov term by its autocovariance gives the built-in's
    // fit; the example file of the docs (a Bartlett decimation filter) gives the built-in
    // bartlett's
    use noise_model::user::UserEffect;
    use noise_model::TermSpec;
    use std::sync::Arc;
    let markov = UserEffect::parse(
        r#"
name = "my_markov"
physics = "the Markov term described by hand"
amplitude = "sigma"
autocovariance = "sigma^2 * exp(-k * tau0 / tau_c)"
[parameters.tau_c]
unit = "s"
min = 0.01
max = 200
"#,
        "my_markov.toml",
    )
    .unwrap();
    let bart = UserEffect::parse(
        &std::fs::read_to_string(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../../docs/effects/bartlett_decimation.toml"
        ))
        .unwrap(),
        "bartlett_decimation.toml",
    )
    .unwrap();
    let mut e = gyro(true);
    e.push(SimEffect::Markov {
        sigma: 0.01,
        tau_c: 2.0,
    });
    e.push(SimEffect::Decimated {
        n: 3e-3,
        length: 3,
        bartlett: true,
    });
    let c = cfg(100.0, 3600.0, 21, e);
    let a = c.analyse();
    let lab = NoiseLab::new(a.record(None)).unwrap();
    let base: Vec<TermSpec> = [
        Effect::Quantization,
        Effect::White,
        Effect::Flicker,
        Effect::RateRandomWalk,
    ]
    .into_iter()
    .map(TermSpec::new)
    .collect();
    let with = |a: Effect, b: Effect| {
        let mut s = base.clone();
        s.push(TermSpec::new(a));
        s.push(TermSpec::new(b));
        lab.fit(&s).unwrap()
    };
    let builtin = with(Effect::Markov, Effect::Bartlett);
    let user = with(Effect::User(Arc::new(markov)), Effect::User(Arc::new(bart)));
    for (b, u) in builtin.fit.terms.iter().zip(&user.fit.terms) {
        for (pb, pu) in b.params().iter().zip(u.params()) {
            assert!(
                (pb.value - pu.value).abs() <= 1e-3 * pb.value.abs() + 1e-3 * pb.sigma,
                "{} {}: built-in {} vs user {}",
                b.effect,
                pb.name,
                pb.value,
                pu.value
            );
        }
    }
    assert!((builtin.fit.chi2 - user.fit.chi2).abs() < 1e-3 * builtin.fit.chi2.max(1.0));
}
