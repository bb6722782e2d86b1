//! Deterministic simulation helpers for the calibration tests (no external RNG crate: the
//! sequences are fixed by their starting key so every tolerance below is reproducible), and the
//! checks on the lab's reports they share.
#![allow(dead_code)]
use imu_cal::lab::{analyse, Effect, Problem, Report};
use nalgebra::{Matrix3, Vector3};

/// SplitMix64 + Box–Muller Gaussian generator.
pub struct Rng(u64);
impl Rng {
    pub fn new(key: u64) -> Rng {
        Rng(key.wrapping_mul(0x9e37_79b9_7f4a_7c15) ^ 0xd1b5_4a32_d192_ed03)
    }
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }
    pub fn uniform(&mut self) -> f64 {
        ((self.next_u64() >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    }
    pub fn gauss(&mut self) -> f64 {
        let (u1, u2) = (self.uniform(), self.uniform());
        (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
    }
    pub fn unit(&mut self) -> Vector3<f64> {
        Vector3::new(self.gauss(), self.gauss(), self.gauss()).normalize()
    }
}

/// A continuous accelerometer recording: `n_poses` static poses of `hold` samples joined by
/// `moves` samples of motion, measured through `a_meas = D·a_true + o + noise` (D = (T·K)⁻¹).
#[allow(clippy::too_many_arguments)]
pub fn accel_recording(
    rng: &mut Rng,
    n_poses: usize,
    hold: usize,
    moves: usize,
    d: Matrix3<f64>,
    o: Vector3<f64>,
    sigma: f64,
    g: f64,
) -> [Vec<f64>; 3] {
    let mut out: [Vec<f64>; 3] = Default::default();
    let mut push = |v: Vector3<f64>, rng: &mut Rng| {
        let m = d * v + o;
        for k in 0..3 {
            out[k].push(m[k] + sigma * rng.gauss());
        }
    };
    let dirs = spread_directions(rng, n_poses);
    for i in 0..n_poses {
        for _ in 0..hold {
            push(dirs[i] * g, rng);
        }
        if i + 1 < n_poses {
            for s in 0..moves {
                let t = (s as f64 + 0.5) / moves as f64;
                let mut u = dirs[i] * (1.0 - t) + dirs[i + 1] * t;
                if u.norm() < 1e-3 {
                    u = Vector3::new(0.3, 0.3, 0.3);
                }
                // Hand motion adds a linear acceleration of ~1 m/s².
                let shake = (t * std::f64::consts::PI).sin() * 1.0;
                push(u.normalize() * (g + shake), rng);
            }
        }
    }
    out
}

/// Smooth spiral over the whole sphere (`n` samples), each direction a unit vector.
pub fn sphere_spiral(n: usize) -> Vec<Vector3<f64>> {
    (0..n)
        .map(|k| {
            let z = 1.0 - 2.0 * (k as f64 + 0.5) / n as f64;
            let r = (1.0 - z * z).sqrt();
            let phi = 0.03 * k as f64;
            Vector3::new(r * phi.cos(), r * phi.sin(), z)
        })
        .collect()
}

/// `r` judges its model adequate.
pub fn assert_adequate(r: &Report, run: u64) {
    assert!(r.model.adequate(), "run {run}: {}", r.diagnosis.explanation);
}

/// `r` judges its model inadequate and names `missing` as the effect it lacks.
pub fn assert_missing(r: &Report, missing: Effect, run: u64) {
    assert!(
        !r.model.adequate(),
        "run {run}: {}",
        r.diagnosis.explanation
    );
    assert_eq!(
        r.diagnosis.missing,
        Some(missing),
        "run {run}: {}",
        r.diagnosis.explanation
    );
}

/// The report on the model the lab proposes after `r`, which must be adequate.
pub fn next_adequate(p: &dyn Problem, r: &Report, run: u64) -> Report {
    let next = analyse(p, r.next().unwrap().effects()).unwrap();
    assert_adequate(&next, run);
    next
}

/// Why the lab did not try `e` on `r`'s model.
pub fn not_tried_reason(r: &Report, e: Effect) -> &str {
    &r.diagnosis
        .not_tried
        .iter()
        .find(|c| c.effect == e)
        .unwrap()
        .reason
}

/// A magnetometer recording of `n` samples: a spiral over the whole sphere (or its upper half)
/// making `turns` turns about z, seen as `m = D·(F·u) + h + noise` (σ per axis), with a fraction
/// `outliers` of the samples then moved by 100–200 µT in random directions (bumps, corrupted
/// reads). Returns the samples and the indices of the corrupted ones.
#[allow(clippy::too_many_arguments)]
pub fn mag_recording(
    rng: &mut Rng,
    n: usize,
    half: bool,
    turns: f64,
    f: f64,
    d: Matrix3<f64>,
    h: Vector3<f64>,
    sigma: f64,
    outliers: f64,
) -> (Vec<Vector3<f64>>, std::collections::BTreeSet<usize>) {
    let mut m: Vec<Vector3<f64>> = (0..n)
        .map(|k| {
            let t = (k as f64 + 0.5) / n as f64;
            let z = if half { 1.0 - t } else { 1.0 - 2.0 * t };
            let r = (1.0 - z * z).sqrt();
            let phi = turns * 2.0 * std::f64::consts::PI * t;
            let u = Vector3::new(r * phi.cos(), r * phi.sin(), z);
            d * (u * f) + h + Vector3::new(rng.gauss(), rng.gauss(), rng.gauss()) * sigma
        })
        .collect();
    let mut hit = std::collections::BTreeSet::new();
    while (hit.len() as f64) < outliers * n as f64 {
        hit.insert((rng.uniform() * n as f64) as usize);
    }
    for &j in &hit {
        m[j] += rng.unit() * (100.0 + 100.0 * rng.uniform());
    }
    (m, hit)
}

/// A symmetric soft-iron distortion `I + E` with the entries of E uniform in ±`a`.
pub fn soft_iron(rng: &mut Rng, a: f64) -> Matrix3<f64> {
    let mut e = Matrix3::zeros();
    for i in 0..3 {
        for j in i..3 {
            let v = a * (2.0 * rng.uniform() - 1.0);
            e[(i, j)] = v;
            e[(j, i)] = v;
        }
    }
    Matrix3::identity() + e
}

/// `n` pose directions spread over the sphere: the six faces first, then random directions.
pub fn spread_directions(rng: &mut Rng, n: usize) -> Vec<Vector3<f64>> {
    let faces = [
        Vector3::x(),
        -Vector3::x(),
        Vector3::y(),
        -Vector3::y(),
        Vector3::z(),
        -Vector3::z(),
    ];
    (0..n)
        .map(|i| if i < 6 { faces[i] } else { rng.unit() })
        .collect()
}
