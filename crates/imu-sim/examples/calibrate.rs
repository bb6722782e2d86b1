//! Calibration study for the adequacy verdict and the diagnosis: runs many simulated cases
//! (control and hidden effects) and prints the statistics. `cargo run --release -p imu-sim
//! --example calibrate --target host-tuple -- [cases] [log2 samples]`.
use allan::{deviation, Stat, TauSet};
use imu_sim::{SimConfig, SimEffect};
use noise_model::{assess, diagnose, fit, FitOptions, Point, DEFAULT_TERMS};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let cases: u64 = args.get(1).and_then(|s| s.parse().ok()).unwrap_or(20);
    let lg: u32 = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(18);
    let kind = args.get(3).cloned().unwrap_or("control".into());
    let n = 1usize << lg;
    let mut n_ok = 0;
    for seed in 0..cases {
        let mut eff = vec![
            SimEffect::Quantization { q: 2e-4 },
            SimEffect::Flicker { b: 3e-3 },
            SimEffect::RateRandomWalk { k: 1e-4 },
        ];
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
            _ => eff.push(SimEffect::White { n: 5e-3 }),
        }
        let cfg = SimConfig {
            rate_hz: 100.0,
            n_samples: n,
            seed: 1000 + seed,
            effects: eff,
        };
        let y = cfg.generate();
        let rows = deviation(&y, cfg.tau0(), Stat::Oadev, &TauSet::Octave).unwrap();
        let (pts, skipped) = Point::from_rows(&rows);
        let f = fit(&pts, cfg.tau0(), &DEFAULT_TERMS, &FitOptions::default()).unwrap();
        let a = assess(&f);
        let d = diagnose(&f, &a, Some((&y, 100.0)));
        let line = d.line;
        if a.adequate {
            n_ok += 1;
        }
        let maxr = a.residuals.iter().fold(0.0f64, |m, r| m.max(r.abs()));
        let cand = d.candidates.first().map(|c| {
            format!(
                "{} p={:.1e} sig={} after chi2/dof={:.2} ok={} params={:?}",
                c.effect,
                c.p_value,
                c.significant,
                c.fit.chi2_dof(),
                c.assessment.adequate,
                c.fit.term(c.effect).map(|t| (t.amplitude(), t.theta))
            )
        });
        println!(
            "seed {seed}: pts {} skip {skipped} z2dof {:.3} maxz {:.2} chi2/dof {:.2} p {:.3} max|r| {:.2} (thr {:.2}) adequate {} missing {:?} line {:?} | {:?}",
            pts.len(),
            a.sum_z2 / f.dof as f64,
            a.z.iter().fold(0.0f64, |m, z| m.max(z.abs())),
            f.chi2_dof(),
            a.p_value,
            maxr,
            a.threshold,
            a.adequate,
            d.missing,
            line.map(|l| l.freq_hz),
            cand
        );
    }
    println!("adequate {n_ok}/{cases}");
}
