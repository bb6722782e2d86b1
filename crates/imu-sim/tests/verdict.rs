//! The verdict on ordinary data, analysed exactly as `imu-lab fit --auto` does (OADEV at octave τ,
//! the noise lab on the record, the automatic walk at the default level): no statistic that is not
//! finite, a found step or warm-up that lowers the error instead of raising it, one warm-up rather
//! than a staircase of steps, and the data's resolution named only when it changes the fit.
//! Parameters and seeds are drawn at random for each run (printed on failure), so the tests probe
//! the behaviour rather than one realisation.
use imu_sim::{gyro_background, Rng, SimConfig, SimEffect};
use noise_model::{walk, Effect, Model, NoiseLab, Stop, TermSpec, Walk};

fn cfg(rate: f64, secs: f64, seed: u64, effects: Vec<SimEffect>) -> SimConfig {
    SimConfig::new(rate, (rate * secs) as usize, seed, effects)
}

fn describe(c: &SimConfig, w: &Walk<Effect, Model>) -> String {
    let mut s = format!("seed {} effects {:?} lsb {:?}\n", c.seed, c.effects, c.lsb);
    for st in &w.steps {
        s += &format!(
            "  {}: χ²/dof {:.2} → {:.2} ({})\n",
            st.edit, st.before.chi2_dof, st.after.chi2_dof, st.reading
        );
    }
    s + &format!("  stop: {}\n", w.stop)
}

/// Every statistic of a model the lab reports is a finite number.
fn all_finite(m: &Model) -> Result<(), String> {
    let f = &m.fit;
    let a = &m.assessment;
    let mut named: Vec<(&str, f64)> = vec![
        ("χ²/dof", f.chi2_dof()),
        ("dof", f.dof),
        ("p", a.p_value),
        ("T", a.sum_z2),
        ("rms log-residual", a.rms_log_residual),
        ("−2ℓ", m.neg2ll),
        ("−2ℓ time", m.neg2ll_time),
        ("criterion", NoiseLab::criterion(m)),
    ];
    named.extend(f.model_avar.iter().map(|v| ("model", *v)));
    named.extend(a.z.iter().map(|v| ("z", *v)));
    named.extend(a.residuals.iter().map(|v| ("r", *v)));
    for t in &f.terms {
        for p in t.params() {
            named.push(("param", p.value));
        }
    }
    match named.iter().find(|(_, v)| !v.is_finite()) {
        Some((n, v)) => Err(format!("{n} = {v}")),
        None => Ok(()),
    }
}

fn run(c: &SimConfig) -> (Walk<Effect, Model>, String) {
    let a = c.analyse();
    let lab = NoiseLab::new(a.record(None)).expect("lab");
    let start = lab.fit(&lab.default_specs()).expect("five-term fit");
    let w = walk(&lab, start, 6).expect("walk");
    let report = describe(c, &w);
    for m in &w.models {
        if let Err(e) = all_finite(m) {
            panic!("a statistic that is not finite: {e}\n{report}");
        }
    }
    // no step of the walk makes the criterion worse
    for pair in w.models.windows(2) {
        assert!(
            NoiseLab::criterion(&pair[1]) < NoiseLab::criterion(&pair[0]),
            "a step raised the criterion\n{report}"
        );
    }
    (w, report)
}

fn added(w: &Walk<Effect, Model>) -> Vec<Effect> {
    w.steps.iter().flat_map(|s| s.edit.add.clone()).collect()
}

/// A bias step in white + flicker + random walk: named once, at its size, and the model with it
/// is adequate, its χ²/dof near 1 rather than raised by the step's own Allan variance.
#[test]
fn a_found_step_lowers_the_error_and_is_added_once() {
    let mut rng = Rng::new(0x5eed_57e9);
    for _ in 0..3 {
        let size = (0.05 + 0.1 * rng.uniform()) * if rng.uniform() < 0.5 { -1.0 } else { 1.0 };
        let at = 3600.0 * (0.25 + 0.5 * rng.uniform());
        let mut e = gyro_background(true);
        e.push(SimEffect::BiasStep { at_s: at, size });
        let c = cfg(100.0, 3600.0, rng.next_u64() % 10_000, e);
        let (w, report) = run(&c);
        let steps = added(&w).iter().filter(|e| **e == Effect::BiasStep).count();
        assert_eq!(steps, 1, "{report}");
        assert_eq!(w.stop, Stop::Adequate, "{report}");
        let last = w.last();
        assert!(last.fit.chi2_dof() < 2.5, "{report}");
        let t = last.fit.term(&Effect::BiasStep).expect("the step");
        assert!(
            (t.amplitude() - size).abs() < 0.1 * size.abs(),
            "size {} vs {size}\n{report}",
            t.amplitude()
        );
    }
}

/// A fast warm-up without a temperature column is one warm-up term, not a staircase of steps.
#[test]
fn a_warm_up_is_one_warm_up_not_a_staircase() {
    let mut rng = Rng::new(0x3a7e_0b0e);
    for _ in 0..3 {
        let amplitude = 0.1 + 0.3 * rng.uniform();
        let tau_s = 60.0 + 240.0 * rng.uniform();
        let mut e = gyro_background(true);
        e.push(SimEffect::WarmUp { amplitude, tau_s });
        let c = cfg(100.0, 3600.0, rng.next_u64() % 10_000, e);
        let (w, report) = run(&c);
        let a = added(&w);
        assert!(!a.contains(&Effect::BiasStep), "{report}");
        assert_eq!(
            a.iter().filter(|e| **e == Effect::Temperature).count(),
            1,
            "{report}"
        );
        assert_eq!(w.stop, Stop::Adequate, "{report}");
    }
}

/// Data written with a fixed number of decimals sit on a lattice; when its LSB is far below the
/// noise, adding the resolution changes nothing and it is not named.
#[test]
fn resolution_is_named_only_when_it_changes_the_fit() {
    let mut rng = Rng::new(0x1eb5);
    for _ in 0..3 {
        let mut e = gyro_background(true);
        e.push(SimEffect::Markov {
            sigma: 0.01 + 0.01 * rng.uniform(),
            tau_c: 1.0 + 3.0 * rng.uniform(),
        });
        let mut c = cfg(100.0, 1200.0, rng.next_u64() % 10_000, e);
        c.lsb = Some(1e-6);
        let a = c.analyse();
        let lab = NoiseLab::new(a.record(None)).expect("lab");
        // the five terms and the correlated noise, without the resolution term
        let mut specs: Vec<TermSpec> = noise_model::DEFAULT_TERMS
            .iter()
            .cloned()
            .map(TermSpec::new)
            .collect();
        specs.push(TermSpec::new(Effect::Markov));
        let m = lab.fit(&specs).expect("fit");
        let cands = lab.candidate_edits(&m).expect("candidates");
        let res = cands
            .iter()
            .find(|c| c.edit.add.contains(&Effect::Resolution))
            .expect("the lattice makes the resolution a candidate");
        assert!(
            !res.admissible,
            "resolution named with p = {:.1e} while χ²/dof {:.3} → {:.3}",
            res.p_value,
            m.fit.chi2_dof(),
            res.model.fit.chi2_dof()
        );
    }
}

/// The default model holds the data's resolution only where the lattice changes the fit: a
/// coarse LSB (a part's own counts) is in it, a CSV's sixth decimal is not.
#[test]
fn the_resolution_is_in_the_default_model_only_when_it_matters() {
    let mut rng = Rng::new(0x7e5_0111);
    for _ in 0..3 {
        let n = 3e-3 + 4e-3 * rng.uniform();
        // per-sample σ of the white noise at 100 Hz is 10·n
        for (lsb, want) in [
            (10.0 * n * (0.6 + 0.6 * rng.uniform()), true),
            (1e-6, false),
        ] {
            let mut c = cfg(100.0, 600.0, rng.next_u64() % 10_000, gyro_background(true));
            c.effects.retain(|e| !matches!(e, SimEffect::White { .. }));
            c.effects.push(SimEffect::White { n });
            c.lsb = Some(lsb);
            let a = c.analyse();
            let lab = NoiseLab::new(a.record(None)).expect("lab");
            let has = lab
                .default_specs()
                .iter()
                .any(|s| s.effect == Effect::Resolution);
            assert_eq!(has, want, "LSB {lsb:.3e} on N {n:.3e}");
        }
    }
}

/// Random mixtures of every effect the simulator makes, at random levels, rates and lengths, some
/// with lines far above the background: every model of every walk has finite statistics, and a
/// fit that cannot be made is an error that says why, never a verdict.
#[test]
fn no_statistic_is_ever_nan() {
    let mut rng = Rng::new(0x0a0a_0b0b);
    for _ in 0..8 {
        let rate: f64 = [50.0, 100.0, 200.0][(rng.next_u64() % 3) as usize];
        let secs = 300.0 + 900.0 * rng.uniform();
        let n = 10f64.powf(-3.0 + 1.5 * rng.uniform());
        let mut e = vec![SimEffect::White { n }];
        let mut pick = |p: f64| rng.uniform() < p;
        let draws: Vec<bool> = (0..6).map(|_| pick(0.5)).collect();
        let (u1, u2, u3) = (rng.uniform(), rng.uniform(), rng.uniform());
        if draws[0] {
            e.push(SimEffect::Flicker { b: n * (0.1 + u1) });
        }
        if draws[1] {
            e.push(SimEffect::RateRandomWalk { k: n * 0.01 * u2 });
        }
        if draws[2] {
            // a line up to a thousand times the background's density
            e.push(SimEffect::Sinusoid {
                amplitude: n * (rate.sqrt()) * (0.1 + 3.0 * u3),
                freq_hz: rate * (0.002 + 0.45 * u1),
            });
        }
        if draws[3] {
            e.push(SimEffect::Markov {
                sigma: n * (0.5 + 2.0 * u2),
                tau_c: 0.05 + 5.0 * u3,
            });
        }
        if draws[4] {
            e.push(SimEffect::BiasStep {
                at_s: secs * (0.1 + 0.8 * u1),
                size: n * (0.5 + 5.0 * u2),
            });
        }
        if draws[5] {
            e.push(SimEffect::RateRamp { r: n * 1e-3 * u3 });
        }
        let mut c = cfg(rate, secs, rng.next_u64() % 10_000, e);
        if rng.uniform() < 0.4 {
            c.lsb = Some(n * 10f64.powf(-1.0 + 1.5 * rng.uniform()));
        }
        let a = c.analyse();
        let lab = NoiseLab::new(a.record(None)).expect("lab");
        let start = match lab.fit(&lab.default_specs()) {
            Ok(m) => m,
            Err(e) => {
                let s = e.to_string();
                assert!(!s.is_empty());
                continue;
            }
        };
        let w = walk(&lab, start, 4).expect("walk");
        let report = describe(&c, &w);
        for m in &w.models {
            if let Err(e) = all_finite(m) {
                panic!("a statistic that is not finite: {e}\n{report}");
            }
        }
        for cand in &w.last_candidates {
            if let Err(e) = all_finite(&cand.model) {
                panic!("candidate {}: {e}\n{report}", cand.edit);
            }
        }
    }
}

/// The verdict is calibrated under every kind of effect: records made of a true model (white
/// noise plus one effect of each kind — a power law, correlated noise, a line, the sensor's filter,
/// a resonance, a step, a warm-up), each with parameters drawn at random per record, fitted with
/// that model, give χ²/dof with a median in 0.8–1.25 and z-scores near N(0, 1). A covariance
/// that mistreats an effect (the deterministic ones, above all) shows as a median far from 1 or
/// z-scores far too wide or too narrow.
#[test]
fn the_verdict_is_calibrated_under_every_effect() {
    let fixed = |e: Effect, theta: Vec<f64>| TermSpec {
        theta: Some(theta),
        theta_fixed: true,
        ..TermSpec::new(e)
    };
    let n_white = 5e-3;
    let secs = 655.36;
    let runs = 40;
    type Draw = Box<dyn Fn(&mut Rng) -> (SimEffect, TermSpec)>;
    // (name, a draw of the extra simulated effect and its term as the lab states the true model)
    let cases: Vec<(&str, Draw)> = vec![
        (
            "flicker",
            Box::new(|r: &mut Rng| {
                let b = 2e-3 + 4e-3 * r.uniform();
                (SimEffect::Flicker { b }, TermSpec::new(Effect::Flicker))
            }),
        ),
        (
            "markov",
            Box::new(move |r: &mut Rng| {
                let sigma = 3e-3 + 5e-3 * r.uniform();
                let tau_c = 0.5 * 20f64.powf(r.uniform());
                (
                    SimEffect::Markov { sigma, tau_c },
                    fixed(Effect::Markov, vec![tau_c]),
                )
            }),
        ),
        (
            "sinusoid",
            Box::new(move |r: &mut Rng| {
                let amplitude = 2e-3 + 6e-3 * r.uniform();
                let freq_hz = 20f64.powf(r.uniform());
                (
                    SimEffect::Sinusoid { amplitude, freq_hz },
                    fixed(Effect::Sinusoid, vec![freq_hz]),
                )
            }),
        ),
        (
            "resonance",
            Box::new(move |r: &mut Rng| {
                let sigma = 3e-3 + 5e-3 * r.uniform();
                let f0_hz = 5.0 * 6f64.powf(r.uniform());
                let zeta = 0.05 * 10f64.powf(r.uniform());
                (
                    SimEffect::Resonance { sigma, f0_hz, zeta },
                    fixed(Effect::Resonance, vec![f0_hz, zeta]),
                )
            }),
        ),
        (
            "bias_step",
            Box::new(move |r: &mut Rng| {
                let at_s = (0.15 + 0.7 * r.uniform()) * secs;
                let sign = if r.uniform() < 0.5 { -1.0 } else { 1.0 };
                let size = sign * (0.02 + 0.08 * r.uniform());
                (
                    SimEffect::BiasStep { at_s, size },
                    fixed(Effect::BiasStep, vec![at_s]),
                )
            }),
        ),
        (
            "warm-up",
            Box::new(move |r: &mut Rng| {
                let amplitude = 0.05 + 0.15 * r.uniform();
                let tau_s = 20.0 * 6f64.powf(r.uniform());
                (
                    SimEffect::WarmUp { amplitude, tau_s },
                    fixed(Effect::Temperature, vec![tau_s]),
                )
            }),
        ),
        (
            "lowpass",
            Box::new(move |r: &mut Rng| {
                let n = 3e-3 + 5e-3 * r.uniform();
                let cutoff_hz = 2.0 * 10f64.powf(r.uniform());
                (
                    SimEffect::LowPassWhite {
                        n,
                        cutoff_hz,
                        order: 1,
                    },
                    fixed(Effect::Lowpass, vec![cutoff_hz]),
                )
            }),
        ),
        (
            "rate_ramp",
            Box::new(move |r: &mut Rng| {
                let sign = if r.uniform() < 0.5 { -1.0 } else { 1.0 };
                let rate = sign * 1e-5 * (1.0 + 4.0 * r.uniform());
                (
                    SimEffect::RateRamp { r: rate },
                    TermSpec::new(Effect::RateRamp),
                )
            }),
        ),
        (
            "temperature",
            // a warm-up's exponential rise, or a smooth wander read at 1/340 °C
            Box::new(move |r: &mut Rng| {
                let sign = if r.uniform() < 0.5 { -1.0 } else { 1.0 };
                let coef = sign * (0.005 + 0.02 * r.uniform());
                let effect = if r.uniform() < 0.5 {
                    SimEffect::Temperature {
                        coef,
                        start_c: 20.0 + 10.0 * r.uniform(),
                        rise_c: 5.0 + 15.0 * r.uniform(),
                        tau_s: 60.0 + 300.0 * r.uniform(),
                    }
                } else {
                    SimEffect::TemperatureWander {
                        coef: 2.0 * coef,
                        rms_c: 0.5 + 2.5 * r.uniform(),
                        shape_seed: r.next_u64() % 1000,
                    }
                };
                (effect, TermSpec::new(Effect::Temperature))
            }),
        ),
        (
            "drift",
            Box::new(move |r: &mut Rng| {
                (
                    SimEffect::Drift {
                        rms: 0.01 + 0.04 * r.uniform(),
                        shape_seed: r.next_u64() % 1000,
                    },
                    // the simulated drift (a logistic transition and a bow) is not of the lab's
                    // form; twelve cosines describe it to well below the noise, six leave a
                    // shape error that puts the median near 1.25
                    TermSpec::new(Effect::Drift { components: 12 }),
                )
            }),
        ),
    ];
    // a fixed stream of draws by default (the bounds hold for it); PICO_IMU_VERDICT_SEED draws
    // another set
    let seed = std::env::var("PICO_IMU_VERDICT_SEED")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(0xca11_b4a7u64);
    eprintln!("draws from seed {seed}");
    let mut rng = Rng::new(seed);
    let mut failures = Vec::new();
    for (name, draw) in cases {
        let mut chi = Vec::new();
        let (mut zs, mut zz, mut nz) = (0.0, 0.0, 0.0);
        for _ in 0..runs {
            let (extra, spec) = draw(&mut rng);
            let sim_seed = rng.next_u64() % 100_000;
            let what = format!("{extra:?}, simulator seed {sim_seed}");
            let c = cfg(
                100.0,
                secs,
                sim_seed,
                vec![SimEffect::White { n: n_white }, extra],
            );
            let a = c.analyse();
            let lab = NoiseLab::new(a.record(None)).expect("lab");
            let specs = vec![TermSpec::new(Effect::White), spec.clone()];
            let m = lab
                .fit(&specs)
                .unwrap_or_else(|e| panic!("{name}: fit of the true model on {what}: {e}"));
            all_finite(&m).unwrap_or_else(|e| panic!("{name}: {e}"));
            chi.push(m.fit.chi2_dof());
            for z in &m.assessment.z {
                zs += z;
                zz += z * z;
                nz += 1.0;
            }
        }
        chi.sort_by(f64::total_cmp);
        let median = 0.5 * (chi[chi.len() / 2 - 1] + chi[chi.len() / 2]);
        let mean_z = zs / nz;
        let sd_z = (zz / nz - mean_z * mean_z).sqrt();
        let line = format!("{name}: median χ²/dof {median:.2}, z mean {mean_z:+.2} sd {sd_z:.2}");
        eprintln!("{line}");
        // Before the localised signals had their exact noise sums and the estimates' share taken
        // out (fit/solve.rs), a step, a warm-up or a bias following the temperature put the
        // median at 0.6–0.7; the coherent-mean form before that put it far above 1.
        let (lo, sd_lo) = (0.8, 0.7);
        if !((lo..=1.25).contains(&median) && mean_z.abs() < 0.3 && (sd_lo..1.3).contains(&sd_z)) {
            failures.push(line);
        }
    }
    assert!(failures.is_empty(), "{failures:#?}");
}

/// A time-domain finding that the one criterion refuses (its refit does not lower the criterion)
/// is said, not a veto: on control data that pass the Allan test, a step put among the findings
/// at a random instant is tried, refused, and the model is adequate, with a diagnosis that names
/// the finding and why it was not taken; the walk stops adequate without adding it.
#[test]
fn a_finding_the_criterion_refuses_is_said_and_is_no_veto() {
    let mut rng = Rng::new(0x0f1d_1e55);
    let mut tried = 0;
    for run in 0..3 {
        let secs = 300.0 + 300.0 * rng.uniform();
        let seed = rng.next_u64() % 100_000;
        let at = (0.2 + 0.6 * rng.uniform()) * secs;
        let c = cfg(
            100.0,
            secs,
            seed,
            vec![
                SimEffect::White { n: 5e-3 },
                SimEffect::Flicker {
                    b: 1e-3 + 3e-3 * rng.uniform(),
                },
            ],
        );
        let a = c.analyse();
        let lab = NoiseLab::new(a.record(None)).expect("lab");
        let specs = vec![TermSpec::new(Effect::White), TermSpec::new(Effect::Flicker)];
        let mut m = lab.fit(&specs).expect("fit");
        if !(m.adequate && m.assessment.adequate) {
            // a control that fails its own test at the default level (rare): not this test's case
            continue;
        }
        let text = format!("a bias step near t = {at:.1} s (put here by the test)");
        m.findings.push(noise_model::lab::Finding {
            effect: Effect::BiasStep,
            spec: TermSpec {
                theta: Some(vec![at]),
                theta_fixed: true,
                ..TermSpec::new(Effect::BiasStep)
            },
            p_value: 1e-4,
            text: text.clone(),
        });
        m.adequate = false;
        let what = format!("run {run}: {secs:.0} s, seed {seed}, step at {at:.1} s");
        let d = noise_model::diagnose(&lab, &m).expect("diagnosis");
        assert!(d.missing.is_none(), "{what}: {}", d.explanation);
        assert!(d.adequate, "{what}: {}", d.explanation);
        assert!(
            d.explanation.contains("adequate on the one criterion")
                && d.explanation.contains(&text),
            "{what}: {}",
            d.explanation
        );
        let w = walk(&lab, m, 4).expect("walk");
        assert!(
            w.steps.is_empty() && w.stop == Stop::Adequate,
            "{what}: {} steps, {:?}",
            w.steps.len(),
            w.stop
        );
        tried += 1;
    }
    assert!(
        tried >= 2,
        "only {tried} of 3 controls passed their own test"
    );
}
