//! Monte Carlo check of the covariance of octave OADEV estimates ([`noise_model::cov`]) and of the
//! fit's goodness-of-fit statistic: simulate many records of one noise mix, compare the scatter
//! of σ̂² with the predicted covariance at the true model, then fit the five-term model to each
//! record and report the χ²/dof distribution and the verdict's false-alarm rate.
//!
//! `cargo run --release -p imu-sim --example covcheck --target host-tuple -- SEEDS LOG2N RATE MIX`
//! with MIX one of white, flicker, rrw, mix (default: 200 16 1000 mix).
use allan::{deviation, Stat, TauSet};
use imu_sim::{flicker_components, SimConfig, SimEffect};
use noise_model::cov::{allan_covariance, Component, Design, Deterministic};
use noise_model::structure::Structure;
use noise_model::{assess_at, fit_model, Measurement, Point, TermSpec, DEFAULT_TERMS};

fn main() {
    let a: Vec<String> = std::env::args().collect();
    let seeds: u64 = a.get(1).and_then(|s| s.parse().ok()).unwrap_or(200);
    let log2n: u32 = a.get(2).and_then(|s| s.parse().ok()).unwrap_or(16);
    let rate: f64 = a.get(3).and_then(|s| s.parse().ok()).unwrap_or(1000.0);
    let mix = a.get(4).cloned().unwrap_or_else(|| "mix".into());
    let n = 1usize << log2n;
    let tau0 = 1.0 / rate;
    let effects = match mix.as_str() {
        "white" => vec![SimEffect::White { n: 5e-3 }],
        "flicker" => vec![SimEffect::White { n: 5e-3 }, SimEffect::Flicker { b: 3e-3 }],
        "rrw" => vec![
            SimEffect::White { n: 5e-3 },
            SimEffect::RateRandomWalk { k: 1e-4 },
        ],
        _ => vec![
            SimEffect::Quantization { q: 2e-4 },
            SimEffect::White { n: 5e-3 },
            SimEffect::Flicker { b: 3e-3 },
            SimEffect::RateRandomWalk { k: 1e-4 },
        ],
    };
    // the true model as structure functions
    let mut comps = Vec::new();
    for e in &effects {
        match *e {
            SimEffect::White { n: nd } => comps.push(Component {
                coef: nd * nd / tau0,
                structure: Structure::Linear,
            }),
            SimEffect::Quantization { q } => comps.push(Component {
                coef: q * q / (tau0 * tau0),
                structure: Structure::PhaseWhite,
            }),
            SimEffect::RateRandomWalk { k } => comps.push(Component {
                coef: k * k * tau0,
                structure: Structure::Cubic,
            }),
            SimEffect::Flicker { b } => {
                for (s, tc) in flicker_components(b, tau0, n) {
                    comps.push(Component {
                        coef: s * s,
                        structure: Structure::Ar1 {
                            phi: (-tau0 / tc).exp(),
                        },
                    });
                }
            }
            _ => unreachable!(),
        }
    }
    let mut samples: Vec<Vec<f64>> = Vec::new();
    let mut ms: Vec<u64> = Vec::new();
    let (mut t_dof, mut fa01, mut fa002, mut fits) = (Vec::new(), 0, 0, 0);
    let (mut pvals, mut local) = (Vec::new(), 0);
    let t0 = std::time::Instant::now();
    for seed in 0..seeds {
        let c = SimConfig::new(rate, n, 9000 + seed, effects.clone());
        let y = c.generate();
        let rows = deviation(&y, tau0, Stat::Oadev, &TauSet::Octave).unwrap();
        if ms.is_empty() {
            ms = rows.iter().map(|r| r.m).collect();
        }
        samples.push(rows.iter().map(|r| r.dev * r.dev).collect());
        let (pts, _) = Point::from_rows(&rows);
        let meas = Measurement::from_record(pts, tau0, n as u64);
        let specs: Vec<TermSpec> = DEFAULT_TERMS.iter().cloned().map(TermSpec::new).collect();
        if let Ok(f) = fit_model(&meas, &specs) {
            fits += 1;
            t_dof.push(f.chi2_dof());
            let a = assess_at(&f, 0.2);
            pvals.push(a.p_value);
            if !a.failing.is_empty() {
                local += 1;
            }
            if !assess_at(&f, 0.1).adequate {
                fa01 += 1;
            }
            if !assess_at(&f, 2e-3).adequate {
                fa002 += 1;
            }
        }
    }
    let k = ms.len();
    let design = Design {
        ms: ms.clone(),
        segments: vec![n as u64],
    };
    let pred = allan_covariance(&design, &comps, &Deterministic::default());
    let mean: Vec<f64> = (0..k)
        .map(|j| samples.iter().map(|s| s[j]).sum::<f64>() / seeds as f64)
        .collect();
    let cov = |a: usize, b: usize| {
        samples
            .iter()
            .map(|s| (s[a] - mean[a]) * (s[b] - mean[b]))
            .sum::<f64>()
            / (seeds as f64 - 1.0)
    };
    println!("{mix}: {seeds} records of 2^{log2n} samples at {rate} Hz");
    println!("  m        var ratio (emp/pred)   corr(m,2m) emp  pred   edf pred");
    for j in 0..k {
        let th: f64 = comps
            .iter()
            .map(|c| c.coef * c.structure.avar(ms[j] as f64))
            .sum();
        let edf = 2.0 * th * th / pred[(j, j)];
        let (ce, cp) = if j + 1 < k {
            (
                cov(j, j + 1) / (cov(j, j) * cov(j + 1, j + 1)).sqrt(),
                pred[(j, j + 1)] / (pred[(j, j)] * pred[(j + 1, j + 1)]).sqrt(),
            )
        } else {
            (f64::NAN, f64::NAN)
        };
        println!(
            "  {:<8} {:>8.3}               {:>6.3}         {:>6.3}  {:>10.1}",
            ms[j],
            cov(j, j) / pred[(j, j)],
            ce,
            cp,
            edf
        );
    }
    t_dof.sort_by(f64::total_cmp);
    println!(
        "five-term fits: {fits}; χ²/dof median {:.3} (10–90 %: {:.3}–{:.3}); inadequate at α = 0.1: {} ({:.3}); at α = 2e-3: {}",
        t_dof[t_dof.len() / 2],
        t_dof[t_dof.len() / 10],
        t_dof[t_dof.len() * 9 / 10],
        fa01,
        fa01 as f64 / fits as f64,
        fa002
    );
    pvals.sort_by(f64::total_cmp);
    let below = |x: f64| pvals.iter().filter(|&&p| p < x).count();
    println!(
        "global p-values: < 0.01: {}, < 0.05: {}, < 0.1: {}, < 0.5: {} of {}; local failures at α = 0.2: {local}",
        below(0.01),
        below(0.05),
        below(0.1),
        below(0.5),
        pvals.len()
    );
    println!("{:.1} s", t0.elapsed().as_secs_f64());
}
