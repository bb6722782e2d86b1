//! Calibration study of the noise lab's verdict and automatic walk: many seeds of one case
//! (control or a hidden effect), the walk on each, and the tally of what was named.
//! `cargo run --release -p imu-sim --example calibrate --target host-tuple -- CASES LOG2N KIND`
//! with KIND one of control, markov, sine, dlpf, step.
use imu_sim::{SimConfig, SimEffect};
use noise_model::{walk, NoiseLab, Stop};
use std::collections::BTreeMap;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let cases: u64 = args.get(1).and_then(|s| s.parse().ok()).unwrap_or(20);
    let lg: u32 = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(18);
    let kind = args.get(3).cloned().unwrap_or("control".into());
    let n = 1usize << lg;
    let mut named: BTreeMap<String, usize> = BTreeMap::new();
    let mut adequate = 0;
    for seed in 0..cases {
        let mut eff = imu_sim::gyro_background(false);
        match kind.as_str() {
            "markov" => {
                eff.push(SimEffect::White { n: 5e-3 });
                eff.push(SimEffect::Markov {
                    sigma: 0.01,
                    tau_c: 2.0,
                });
            }
            "sine" => {
                eff.push(SimEffect::White { n: 5e-3 });
                eff.push(SimEffect::Sinusoid {
                    amplitude: 0.01,
                    freq_hz: 0.05,
                });
            }
            "dlpf" => eff.push(SimEffect::LowPassWhite {
                n: 5e-3,
                cutoff_hz: 5.0,
                order: 1,
            }),
            "step" => {
                eff.push(SimEffect::White { n: 5e-3 });
                eff.push(SimEffect::BiasStep {
                    at_s: n as f64 / 100.0 * 0.37,
                    size: 0.03,
                });
            }
            _ => eff.push(SimEffect::White { n: 5e-3 }),
        }
        let cfg = SimConfig::new(100.0, n, 1000 + seed, eff);
        let a = cfg.analyse();
        let lab = NoiseLab::new(a.record(None)).unwrap();
        let start = lab.fit(&lab.default_specs()).unwrap();
        let w = walk(&lab, start, 5).unwrap();
        let added: Vec<String> = w.steps.iter().map(|s| s.edit.to_string()).collect();
        if w.stop == Stop::Adequate {
            adequate += 1;
        }
        *named
            .entry(if added.is_empty() {
                "(nothing)".into()
            } else {
                added.join(" then ")
            })
            .or_default() += 1;
        println!(
            "seed {seed}: start χ²/dof {:.2}, steps [{}], stop: {}",
            w.models[0].fit.chi2_dof(),
            added.join(", "),
            w.stop
        );
    }
    println!("adequate at the end: {adequate}/{cases}");
    for (k, v) in named {
        println!("  {k}: {v}");
    }
}
