//! Runs the noise lab's automatic walk on one simulated scenario and prints every step: the
//! hidden-effect cases of the test suite, for looking at one closely.
//!
//! `cargo run --release -p imu-sim --example scenario --target host-tuple -- NAME [SEED]`
use imu_sim::{SimConfig, SimEffect};
use noise_model::{walk, NoiseLab};

fn scenario(name: &str, seed: u64) -> SimConfig {
    let (rate, secs, extra): (f64, f64, Vec<SimEffect>) = match name {
        "control" => (100.0, 3600.0, vec![]),
        "control1k" => (1000.0, 600.0, vec![]),
        "step" => (
            100.0,
            3600.0,
            vec![SimEffect::BiasStep {
                at_s: 1800.0,
                size: 0.1,
            }],
        ),
        "step_small" => (
            100.0,
            3600.0,
            vec![SimEffect::BiasStep {
                at_s: 1300.0,
                size: 0.01,
            }],
        ),
        "temperature" => (
            100.0,
            3600.0,
            vec![SimEffect::Temperature {
                coef: 0.02,
                start_c: 25.0,
                rise_c: 15.0,
                tau_s: 900.0,
            }],
        ),
        "warmup" => (
            100.0,
            3600.0,
            vec![SimEffect::WarmUp {
                amplitude: 0.2,
                tau_s: 600.0,
            }],
        ),
        "slow_markov" => (
            100.0,
            10800.0,
            vec![SimEffect::Markov {
                sigma: 0.01,
                tau_c: 300.0,
            }],
        ),
        "slow_markov3" => (
            100.0,
            10800.0,
            vec![SimEffect::Markov {
                sigma: 0.03,
                tau_c: 300.0,
            }],
        ),
        "line49" => (
            100.0,
            3600.0,
            vec![SimEffect::Sinusoid {
                amplitude: 0.01,
                freq_hz: 49.5,
            }],
        ),
        "line10" => (
            100.0,
            3600.0,
            vec![SimEffect::Sinusoid {
                amplitude: 0.003,
                freq_hz: 10.0,
            }],
        ),
        "line01" => (
            100.0,
            3600.0,
            vec![SimEffect::Sinusoid {
                amplitude: 0.003,
                freq_hz: 0.1,
            }],
        ),
        "bartlett" => (100.0, 10000.0, vec![]),
        "lowpass" => (100.0, 3600.0, vec![]),
        _ => panic!("unknown scenario {name}"),
    };
    let mut effects = imu_sim::gyro_background(true);
    match name {
        "bartlett" => {
            effects.retain(|e| !matches!(e, SimEffect::White { .. }));
            effects.push(SimEffect::Decimated {
                n: 5e-3,
                length: 4,
                bartlett: true,
            });
        }
        "lowpass" => {
            effects.retain(|e| !matches!(e, SimEffect::White { .. }));
            effects.push(SimEffect::LowPassWhite {
                n: 5e-3,
                cutoff_hz: 5.0,
                order: 1,
            });
        }
        _ => {}
    }
    effects.extend(extra);
    SimConfig::new(rate, (rate * secs) as usize, seed, effects)
}

fn main() {
    let a: Vec<String> = std::env::args().collect();
    let name = a.get(1).map(String::as_str).unwrap_or("step");
    let seed: u64 = a.get(2).and_then(|s| s.parse().ok()).unwrap_or(1);
    let c = scenario(name, seed);
    let t0 = std::time::Instant::now();
    let a = c.analyse();
    let lab = NoiseLab::new(a.record(None)).unwrap();
    let c_cfg = c.clone();
    let cfg_truth = |c: &SimConfig, m: u64| c.avar(m as usize).sqrt();
    let start = lab.fit(&lab.default_specs()).unwrap();
    println!("lines: {:?}", lab.lines.iter().take(3).collect::<Vec<_>>());
    if std::env::var("CANDS").is_ok() {
        for c in lab.candidate_edits(&start).unwrap() {
            println!(
                "  cand {}: p {:.1e}, χ²/dof {:.2}, adm {} {}",
                c.edit, c.p_value, c.summary.chi2_dof, c.admissible, c.reason
            );
            if std::env::var("CURVE").is_ok() && c.edit.add[0] == noise_model::Effect::Markov {
                for t in &c.model.fit.terms {
                    println!(
                        "     {} {:?}",
                        t.effect,
                        t.params()
                            .iter()
                            .map(|v| (v.name.clone(), v.value, v.sigma))
                            .collect::<Vec<_>>()
                    );
                }
                for (j, p) in c.model.fit.points.iter().enumerate() {
                    println!(
                        "     τ {:>9.3}  dev {:.4e}  model {:.4e}  truth {:.4e}  z {:+.2}",
                        p.tau,
                        p.dev,
                        c.model.fit.model_avar[j].sqrt(),
                        cfg_truth(&c_cfg, p.m),
                        c.model.assessment.z[j]
                    );
                }
            }
        }
    }
    let w = walk(&lab, start, 6).unwrap();
    for s in &w.steps {
        println!(
            "step {}: χ²/dof {:.3} → {:.3}, rms log {:.4} → {:.4}, adequate {} → {}  ({}; p {:.1e})",
            s.edit, s.before.chi2_dof, s.after.chi2_dof, s.before.rms_residual, s.after.rms_residual,
            s.before.adequate, s.after.adequate, s.reading, s.p_value
        );
    }
    let m = w.last();
    println!(
        "stop: {}  χ²/dof {:.3} dof {}",
        w.stop,
        m.fit.chi2_dof(),
        m.fit.dof
    );
    for t in &m.fit.terms {
        let p = t.params();
        println!(
            "  {:<18} {}",
            t.effect.name(),
            p.iter()
                .map(|v| format!("{} = {:.4e} ± {:.1e}", v.name, v.value, v.sigma))
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    if std::env::var("CURVE").is_ok() {
        for (j, p) in m.fit.points.iter().enumerate() {
            println!(
                "  τ {:>9.3}  dev {:.4e}  model {:.4e}  truth {:.4e}  z {:+.2}  edf {:.0}/{:.0}",
                p.tau,
                p.dev,
                m.fit.model_avar[j].sqrt(),
                c.avar(p.m as usize).sqrt(),
                m.assessment.z[j],
                m.fit.model_edf[j],
                p.edf
            );
        }
    }
    for f in &m.findings {
        println!("  finding: {}", f.text);
    }
    for c in w.last_candidates.iter().take(6) {
        println!(
            "  tried {}: p {:.1e}, χ²/dof {:.2}, {}",
            c.edit, c.p_value, c.summary.chi2_dof, c.reason
        );
    }
    println!("{:.1} s", t0.elapsed().as_secs_f64());
}
