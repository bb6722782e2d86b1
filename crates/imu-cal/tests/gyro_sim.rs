//! Simulated gyro recordings at rest: a temperature-dependent bias is diagnosed; controls are
//! adequate; Jaime et al.'s bias numbers as a worked example.
mod common;
use common::*;
use imu_cal::gyro::GyroProblem;
use imu_cal::lab::{analyse, Effect};

const PAPER_BIAS: [f64; 3] = [-1.6022, 0.2899, 1.8464]; // deg/s, Jaime et al., "Resultados"

/// 20 min at 100 Hz, white noise σ = 0.05 deg/s, temperature warming 25 → 31 °C
/// (exponential, as a board warming up) plus ±0.02 °C quantisation-like noise.
fn recording(run: u64, k: [f64; 3]) -> ([Vec<f64>; 3], Vec<f64>) {
    let mut rng = Rng::new(run);
    let n = 120_000;
    let t: Vec<f64> = (0..n)
        .map(|i| 25.0 + 6.0 * (1.0 - (-(i as f64) / 40_000.0).exp()) + 0.02 * rng.gauss())
        .collect();
    let t_mean = t.iter().sum::<f64>() / n as f64;
    let g = [0, 1, 2].map(|j| {
        (0..n)
            .map(|i| PAPER_BIAS[j] + k[j] * (t[i] - t_mean) + 0.05 * rng.gauss())
            .collect()
    });
    (g, t)
}

/// Tolerances: block means (50 blocks of 2400 samples) have σ ≈ 0.001 deg/s; the bias is
/// determined to ≈ 0.0002 deg/s and the coefficient to ≈ 0.0001 deg/s/°C; we allow 0.002 deg/s
/// and 0.0005 deg/s/°C.
#[test]
fn temperature_dependence_is_diagnosed_and_recovered() {
    let k = [0.004, -0.003, 0.002];
    for run in 1..=3 {
        let (g, t) = recording(run, k);
        let p = GyroProblem::new([&g[0], &g[1], &g[2]], Some(&t), 50).unwrap();
        let r = analyse(&p, &[Effect::Bias]).unwrap();
        assert_missing(&r, Effect::Temperature, run);
        let r2 = next_adequate(&p, &r, run);
        let kc = r2.model.fitted.params.temp_coeff.unwrap();
        let b = r2.model.fitted.params.bias.unwrap();
        for j in 0..3 {
            assert!((kc[j] - k[j]).abs() < 5e-4, "run {run}: k {kc:?}");
            assert!((b[j] - PAPER_BIAS[j]).abs() < 2e-3, "run {run}: b {b:?}");
        }
    }
}

#[test]
fn control_constant_bias_is_adequate() {
    for run in 11..=13 {
        let (g, t) = recording(run, [0.0; 3]);
        let p = GyroProblem::new([&g[0], &g[1], &g[2]], Some(&t), 50).unwrap();
        let r = analyse(&p, &[Effect::Bias]).unwrap();
        assert_adequate(&r, run);
        assert_eq!(r.diagnosis.missing, None);
    }
}

#[test]
fn without_temperature_column_the_effect_is_not_offered() {
    let (g, _) = recording(3, [0.004, 0.0, 0.0]);
    let p = GyroProblem::new([&g[0], &g[1], &g[2]], None, 50).unwrap();
    let r = analyse(&p, &[Effect::Bias]).unwrap();
    let c = not_tried_reason(&r, Effect::Temperature);
    assert_eq!(c, "no temperature column");
    assert!(analyse(&p, &[Effect::Bias, Effect::Temperature]).is_err());
}

/// Jaime et al.'s worked example: bias = the mean of 90 minutes at rest (Jaime et al., eq. 2). At 100 Hz
/// (Jaime et al.'s system rate) with the MPU-6050's ≈ 0.05 deg/s rms noise, the mean of 540 000
/// samples has σ ≈ 7e-5 deg/s, so Jaime et al.'s four-digit values are reproduced to ±0.0005 deg/s
/// (5e-4, the last published digit).
#[test]
fn paper_gyro_bias_worked_example() {
    let mut rng = Rng::new(90);
    let n = 90 * 60 * 100;
    let g = [0, 1, 2].map(|j| {
        (0..n)
            .map(|_| PAPER_BIAS[j] + 0.05 * rng.gauss())
            .collect::<Vec<f64>>()
    });
    let p = GyroProblem::new([&g[0], &g[1], &g[2]], None, 60).unwrap();
    let r = analyse(&p, &[Effect::Bias]).unwrap();
    let b = r.model.fitted.params.bias.unwrap();
    for j in 0..3 {
        assert!((b[j] - PAPER_BIAS[j]).abs() < 5e-4, "{b:?}");
    }
    assert!(r.model.adequate(), "{}", r.diagnosis.explanation);
}

/// A constant gyro column (a stuck sensor, or the wrong column) is a clear refusal naming the
/// axis and the value, not a verdict built on a zero noise floor.
#[test]
fn constant_column_is_refused_by_name() {
    let x: Vec<f64> = (0..5000).map(|i| (i % 7) as f64 * 0.01).collect();
    let c = vec![12.5; 5000];
    let e = GyroProblem::new([&x, &c, &x], None, 50)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("gyro axis y is constant (all 5000 samples are 12.5 deg/s)"),
        "{e}"
    );
}

/// The reported residual is what the reported parameters give; bias and temperature
/// coefficient have positive uncertainties of the size the block scatter implies.
#[test]
fn residual_recomputes_and_parameters_have_uncertainties() {
    let (g, t) = recording(77, [0.004, -0.003, 0.002]);
    let p = GyroProblem::new([&g[0], &g[1], &g[2]], Some(&t), 50).unwrap();
    let r = analyse(&p, &[Effect::Bias, Effect::Temperature]).unwrap();
    let f = &r.model.fitted;
    let nb = p.blocks[0].len();
    let s: f64 = (0..3)
        .flat_map(|j| (0..nb).map(move |i| (j, i)))
        .map(|(j, i)| p.residual(&f.params, j, i).powi(2))
        .sum();
    assert!(((s / (3 * nb) as f64).sqrt() / f.rms() - 1.0).abs() < 1e-9);
    // Block means scatter by 0.05/√2400 ≈ 0.001 deg/s: the bias to ≈ 0.00015 deg/s.
    for v in f.sigma.bias.unwrap() {
        assert!((5e-5..5e-4).contains(&v), "{v}");
    }
    for v in f.sigma.temp_coeff.unwrap() {
        assert!(v > 0.0 && v < 5e-4, "{v}");
    }
}
