//! Checks the allan crate's EDF against simulation: for each octave τ, the observed variance of
//! ln σ̂² over seeds vs the χ² prediction ψ'(ν/2) ≈ 2/ν. `cargo run --release -p imu-sim
//! --example edfcheck --target host-tuple -- [seeds]`.
use allan::{deviation, Stat, TauSet};
use imu_sim::{SimConfig, SimEffect};

fn main() {
    let seeds: u64 = std::env::args()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or(40);
    let kind = std::env::args().nth(2).unwrap_or_default();
    let mut acc: Vec<(f64, f64, f64, f64, usize)> = Vec::new(); // tau, sum z2 (theory), sum ln ratio², sum edf, count
    for seed in 0..seeds {
        let eff = match kind.as_str() {
            "white" => vec![SimEffect::White { n: 5e-3 }],
            "flicker" => vec![SimEffect::Flicker { b: 3e-3 }],
            "rrw" => vec![SimEffect::RateRandomWalk { k: 1e-4 }],
            _ => vec![
                SimEffect::Quantization { q: 2e-4 },
                SimEffect::White { n: 5e-3 },
                SimEffect::Flicker { b: 3e-3 },
                SimEffect::RateRandomWalk { k: 1e-4 },
            ],
        };
        let c = SimConfig {
            rate_hz: 100.0,
            n_samples: 1 << 18,
            seed: 5000 + seed,
            effects: eff,
        };
        let y = c.generate();
        let rows = deviation(&y, c.tau0(), Stat::Oadev, &TauSet::Octave).unwrap();
        for (i, r) in rows.iter().enumerate() {
            if acc.len() <= i {
                acc.push((r.tau, 0.0, 0.0, 0.0, 0));
            }
            let th = c.avar(r.m as usize).sqrt();
            let z = noise_model::assess::z_score(r.dev, r.edf, th);
            let lr = (r.dev * r.dev / (th * th)).ln();
            acc[i].1 += z * z;
            acc[i].2 += lr * lr;
            acc[i].3 += r.edf;
            acc[i].4 += 1;
        }
    }
    for (tau, z2, lr2, edf, n) in acc {
        let n = n as f64;
        let edf = edf / n;
        // var(ln χ²_ν/ν) ≈ 2/ν (+ bias² ≈ (1/ν)²·… small): the EDF implied by the scatter
        let implied = 2.0 / (lr2 / n);
        println!(
            "tau {tau:9.2}  mean z² {:.2}  mean edf {:10.1}  edf implied by scatter {:10.1}",
            z2 / n,
            edf,
            implied
        );
    }
}
