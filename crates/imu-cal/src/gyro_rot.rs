//! Gyroscope scale and misalignment from rotations between static poses, after Tedaldi et al.
//! 2014 §IV-C: the accelerometer gives the direction of gravity in
//! each static pose; integrating the corrected gyro over the move from pose k to pose k + 1
//! must carry the first direction onto the second.
//!
//! ```text
//! ω_cal = T_g · K_g · (ω − b),  K_g = diag(s),  T_g = [[1, γ₁, γ₂], [γ₃, 1, γ₄], [γ₅, γ₆, 1]]
//! R_k = Π exp([ω_cal dt]×)   (body k → body k+1, Rodrigues per sample)
//! residual_k = the two components of R_kᵀ·u_k orthogonal to u_{k+1}   (deg)
//! ```
//!
//! b is the mean gyro rate over the middle half of every static pose (Jaime et al., eq. 2),
//! removed first. Six
//! misalignment angles, not three: the gyro triad is referred to the accelerometer frame, which
//! fixes all three of its axes (Tedaldi eq. 10). Rotations *about* gravity are invisible to this
//! residual, so the poses must differ in tilt. Moves where a raw rate reaches `saturation`, or
//! that hold a sample the caller flags (an overflow sentinel, the first sample after a gap in
//! the record), are skipped: the integral would be wrong. Rates are in deg/s.
//!
//! Noise floor per residual component: σ² = σ_u,k² + σ_u,k+1² + σ_ω²·dt²·n_k, from the half-pose
//! differences of the gravity direction and the per-sample white noise of the gyro at rest.
// Sample-index loops over three parallel axis slices read closer to the equations.
#![allow(clippy::needless_range_loop)]

use crate::accel::Pose;
use crate::lab::{
    model_names, params_sigma, CalError, Effect, Fitted, NoiseFloor, Params, Problem,
};
use crate::solve::{covariance, fit_model, mean};
use nalgebra::{DVector, Matrix3, Rotation3, Vector3};

const EFFECTS: [Effect; 2] = [Effect::Scale, Effect::Misalignment];

/// `T_g·K_g` as rows, from scale factors and the six angles in degrees (module docs).
pub fn correction_matrix(scale: [f64; 3], mis_deg: [f64; 6]) -> [[f64; 3]; 3] {
    let g = mis_deg.map(f64::to_radians);
    let s = scale;
    [
        [s[0], g[0] * s[1], g[1] * s[2]],
        [g[2] * s[0], s[1], g[3] * s[2]],
        [g[4] * s[0], g[5] * s[1], s[2]],
    ]
}

/// One move between two static poses.
#[derive(Debug, Clone)]
pub struct Move {
    /// Gravity direction at the end of the first pose (unit, accelerometer frame).
    pub u0: Vector3<f64>,
    /// Gravity direction in the second pose.
    pub u1: Vector3<f64>,
    /// Bias-free gyro rates during the move (deg/s).
    pub omega: Vec<Vector3<f64>>,
    /// Variance of one residual component (rad²).
    pub var: f64,
}

/// The rotation problem.
#[derive(Debug, Clone)]
pub struct GyroRotProblem {
    /// Moves used.
    pub moves: Vec<Move>,
    /// Moves skipped because the gyro saturated.
    pub skipped_saturated: usize,
    /// Moves skipped because they hold a flagged sample (sentinel, gap).
    pub skipped_flagged: usize,
    /// Gyro bias removed (deg/s).
    pub bias: [f64; 3],
    /// Its standard error (deg/s): white noise at rest over the static samples.
    pub bias_sigma: [f64; 3],
    /// Sample interval (s).
    pub dt: f64,
}

impl GyroRotProblem {
    /// Build from calibrated accelerometer samples (any unit), gyro rates (deg/s), the static
    /// poses found on the accelerometer, and the saturation level of the raw gyro (deg/s).
    pub fn new(
        acc: [&[f64]; 3],
        gyro: [&[f64]; 3],
        rate_hz: f64,
        poses: &[Pose],
        saturation: Option<f64>,
    ) -> Result<Self, CalError> {
        Self::new_flagged(acc, gyro, rate_hz, poses, saturation, &[])
    }

    /// As [`GyroRotProblem::new`], skipping the moves that hold a sample with `flagged[i]`
    /// (`flagged` may be empty).
    pub fn new_flagged(
        acc: [&[f64]; 3],
        gyro: [&[f64]; 3],
        rate_hz: f64,
        poses: &[Pose],
        saturation: Option<f64>,
        flagged: &[bool],
    ) -> Result<Self, CalError> {
        let n = acc[0].len();
        if !flagged.is_empty() && flagged.len() != n {
            return Err(CalError::Input(
                "the flags of excluded samples do not match the recording".into(),
            ));
        }
        if !(rate_hz > 0.0 && rate_hz.is_finite()) {
            return Err(CalError::Input(format!(
                "sample rate {rate_hz} Hz is not positive"
            )));
        }
        if acc.iter().chain(gyro.iter()).any(|c| c.len() != n) {
            return Err(CalError::Input(
                "accelerometer and gyro columns differ in length".into(),
            ));
        }
        if poses.len() < 2 {
            return Err(CalError::Input(format!(
                "{} static poses: the rotation fit needs at least two",
                poses.len()
            )));
        }
        let dt = 1.0 / rate_hz;
        // Averages use the middle half of each pose: the edges of an accelerometer-detected pose
        // can hold the slow start of a turn (gravity barely moves, the gyro already does). The
        // integration spans the trimmed edges too, so no rotation is lost.
        let core = |p: &Pose| {
            let q = (p.end - p.start) / 4;
            Pose {
                start: p.start + q,
                end: p.end - q,
                ..*p
            }
        };
        let poses: Vec<Pose> = poses.iter().map(core).collect();
        // Bias: mean over every static sample; white noise: pooled per-pose variance.
        let (mut sum, mut cnt) = (Vector3::zeros(), 0usize);
        for p in &poses {
            for i in p.start..p.end {
                sum += Vector3::new(gyro[0][i], gyro[1][i], gyro[2][i]);
                cnt += 1;
            }
        }
        let b = sum / cnt as f64;
        let mut ss = 0.0;
        for p in &poses {
            let m = Vector3::new(
                mean(&gyro[0][p.start..p.end]),
                mean(&gyro[1][p.start..p.end]),
                mean(&gyro[2][p.start..p.end]),
            );
            for i in p.start..p.end {
                ss += (Vector3::new(gyro[0][i], gyro[1][i], gyro[2][i]) - m).norm_squared();
            }
        }
        let var_w = (ss / (3 * cnt) as f64).to_radians().to_radians(); // (rad/s)² per sample
        let dir = |p: &Pose| -> (Vector3<f64>, f64) {
            let mid = p.start + (p.end - p.start) / 2;
            let m = |lo: usize, hi: usize| {
                Vector3::new(
                    mean(&acc[0][lo..hi]),
                    mean(&acc[1][lo..hi]),
                    mean(&acc[2][lo..hi]),
                )
            };
            let u = m(p.start, p.end).normalize();
            let d = m(p.start, mid).normalize() - m(mid, p.end).normalize();
            // |d|² has 2 components of variance 4·var(u) each (d is ⟂ u to first order).
            (u, d.norm_squared() / 8.0)
        };
        let mut moves = Vec::new();
        let mut skipped = 0;
        let mut skipped_flagged = 0;
        for w in poses.windows(2) {
            let (a, c) = (&w[0], &w[1]);
            let raw = a.end..c.start;
            if !flagged.is_empty() && (a.start..c.end).any(|i| flagged[i]) {
                skipped_flagged += 1;
                continue;
            }
            if let Some(sat) = saturation {
                if raw.clone().any(|i| (0..3).any(|k| gyro[k][i].abs() >= sat)) {
                    skipped += 1;
                    continue;
                }
            }
            let (u0, v0) = dir(a);
            let (u1, v1) = dir(c);
            let omega: Vec<Vector3<f64>> = raw
                .clone()
                .map(|i| Vector3::new(gyro[0][i], gyro[1][i], gyro[2][i]) - b)
                .collect();
            let var = v0 + v1 + var_w * dt * dt * omega.len() as f64;
            moves.push(Move { u0, u1, omega, var });
        }
        Ok(GyroRotProblem {
            moves,
            skipped_saturated: skipped,
            skipped_flagged,
            bias: [b.x, b.y, b.z],
            bias_sigma: [(ss / (3 * cnt) as f64 / cnt as f64).sqrt(); 3],
            dt,
        })
    }

    /// `T_g·K_g` for a parameter vector laid out [s?, γ?].
    fn matrix(model: &[Effect], x: &DVector<f64>) -> (Matrix3<f64>, [f64; 3], [f64; 6]) {
        let mut k = 0;
        let s = if model.contains(&Effect::Scale) {
            k = 3;
            [x[0], x[1], x[2]]
        } else {
            [1.0; 3]
        };
        let g = if model.contains(&Effect::Misalignment) {
            [x[k], x[k + 1], x[k + 2], x[k + 3], x[k + 4], x[k + 5]]
        } else {
            [0.0; 6]
        };
        let t = Matrix3::new(1.0, g[0], g[1], g[2], 1.0, g[3], g[4], g[5], 1.0);
        (t * Matrix3::from_diagonal(&Vector3::from(s)), s, g)
    }

    /// The two residual components of one move (rad) under the correction `m`.
    fn residual(&self, mv: &Move, m: &Matrix3<f64>) -> [f64; 2] {
        let mut r = Rotation3::identity();
        for w in &mv.omega {
            let v = m * w.map(f64::to_radians) * self.dt;
            r *= Rotation3::new(v);
        }
        let p = r.inverse() * mv.u0;
        // Orthonormal basis ⟂ u1.
        let a = if mv.u1.x.abs() < 0.9 {
            Vector3::x()
        } else {
            Vector3::y()
        };
        let e1 = mv.u1.cross(&a).normalize();
        let e2 = mv.u1.cross(&e1);
        [e1.dot(&p), e2.dot(&p)]
    }

    /// The lab residual of one move under `params` (deg): the two components, orthogonal to the
    /// second pose's gravity direction, of the first pose's direction carried by the corrected
    /// rotation (`ω_cal = T_g·K_g·(ω − b)`, with the bias already removed from the move).
    pub fn residual_of(&self, params: &Params, mv: &Move) -> [f64; 2] {
        let c = correction_matrix(
            params.scale.unwrap_or([1.0; 3]),
            params.gyro_misalignment_deg.unwrap_or([0.0; 6]),
        );
        let m = Matrix3::from_row_slice(&c.concat());
        self.residual(mv, &m).map(f64::to_degrees)
    }
}

impl Problem for GyroRotProblem {
    fn sensor(&self) -> &'static str {
        "gyro"
    }
    fn unit(&self) -> &str {
        "deg"
    }
    fn effects(&self) -> &'static [Effect] {
        &EFFECTS
    }
    fn n(&self) -> usize {
        self.moves.len()
    }
    fn residuals_per_item(&self) -> usize {
        2
    }
    fn basis(&self) -> &'static str {
        "per-move"
    }
    fn items(&self) -> &'static str {
        "moves"
    }
    fn identifiable(&self, model: &[Effect], e: Effect) -> Result<(), String> {
        let p = 3 * model.len() + if e == Effect::Misalignment { 6 } else { 3 };
        if 2 * self.n() <= p {
            return Err(format!(
                "{} usable moves give {} residuals, not enough for {p} parameters",
                self.moves.len(),
                2 * self.n()
            ));
        }
        Ok(())
    }

    fn fit_items(&self, model: &[Effect], keep: &[bool]) -> Result<Fitted, CalError> {
        let p = 3 * model.contains(&Effect::Scale) as usize
            + 6 * model.contains(&Effect::Misalignment) as usize;
        let used: Vec<&Move> = self
            .moves
            .iter()
            .zip(keep)
            .filter(|(_, k)| **k)
            .map(|(m, _)| m)
            .collect();
        if 2 * used.len() <= p {
            return Err(CalError::Fit(format!(
                "{} usable moves ({} skipped as saturated, {} holding flagged samples) give {} \
                 residuals, not enough for {p} parameters",
                used.len(),
                self.skipped_saturated,
                self.skipped_flagged,
                2 * used.len()
            )));
        }
        let mut x0 = Vec::new();
        if model.contains(&Effect::Scale) {
            x0.extend_from_slice(&[1.0; 3]);
        }
        if model.contains(&Effect::Misalignment) {
            x0.extend_from_slice(&[0.0; 6]);
        }
        // Unweighted: each move's variance is estimated from only ≈ 4 degrees of freedom, and
        // weighting by a noisy inverse variance would inflate the residual (E[1/χ²₄·4] = 2); the
        // floor is the mean variance, on the same unweighted basis.
        let res = |x: &DVector<f64>| {
            let (m, _, _) = Self::matrix(model, x);
            DVector::from_iterator(
                2 * used.len(),
                used.iter()
                    .flat_map(|mv| self.residual(mv, &m).map(f64::to_degrees)),
            )
        };
        let fit = fit_model(x0, res, 200, || {
            format!("gyro {} from rotations", model_names(model))
        })?;
        let bias = self.bias;
        let to_params = |x: &DVector<f64>| {
            let (_, s, g) = Self::matrix(model, x);
            Params {
                bias: Some(bias),
                scale: model.contains(&Effect::Scale).then_some(s),
                gyro_misalignment_deg: model
                    .contains(&Effect::Misalignment)
                    .then_some(g.map(|v| v.to_degrees())),
                ..Params::default()
            }
        };
        let params = to_params(&fit.x);
        let cov = covariance(&fit.jacobian, fit.rss, (2 * used.len() - p) as f64);
        let mut sigma = params_sigma(to_params, &fit.x, cov.as_ref());
        // The bias comes from the poses at rest: its σ is the white noise over those samples.
        sigma.bias = Some(self.bias_sigma);
        let (m, _, _) = Self::matrix(model, &fit.x);
        let residuals = self
            .moves
            .iter()
            .flat_map(|mv| self.residual(mv, &m).map(f64::to_degrees))
            .collect();
        Ok(Fitted {
            model: model.to_vec(),
            params,
            sigma,
            residuals,
            used: keep.iter().flat_map(|k| [*k, *k]).collect(),
            n_params: p,
            not_converged: fit.not_converged,
        })
    }

    /// Scale within ±0.1 and axis angles within ±2° (the MPU-6050's ±3 % sensitivity and ±2 %
    /// cross-axis, rounded up); the bias comes from the rest and is not judged here.
    fn plausible_range(&self, name: &str, _params: &Params) -> Option<f64> {
        match name.split(['.', '[']).next().unwrap_or(name) {
            "scale" => Some(0.1),
            "gyro_misalignment_deg" => Some(2.0),
            _ => None,
        }
    }

    fn noise_floor(&self) -> NoiseFloor {
        let v = self.moves.iter().map(|m| m.var).sum::<f64>() / self.moves.len().max(1) as f64;
        NoiseFloor {
            sigma: v.sqrt().to_degrees(),
            // The per-pose direction variances are each a 2-d.o.f. estimate.
            dof: (4 * self.moves.len()).max(1) as f64,
            method: "half-pose gravity-direction differences + gyro white noise at rest",
        }
    }
}
