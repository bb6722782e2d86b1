//! Accelerometer calibration from static poses.
//!
//! Model (Jaime et al. eq. 1 extended with misalignment, Tedaldi et al. 2014 eq. 9 in
//! lower-triangular form):
//!
//! ```text
//! a_cal = T · K · (a − o),   K = diag(s_x, s_y, s_z),
//! T = [[1, 0, 0], [α₁, 1, 0], [α₂, α₃, 1]]      (α in rad; x defines the frame, y lies in x–y)
//! ```
//!
//! fitted by minimising Σ_poses (|a_cal(ā_i)| − g)² (ā_i = mean of pose i) with Levenberg–Marquardt.
//! Effects absent from the model keep o = 0, s = 1, α = 0.
//!
//! Static poses are found in a continuous recording as Tedaldi et al. (2014, §IV-A) do: the
//! variance over a sliding window of `window_s` seconds, summed over the three axes, is compared
//! with `k ×` the at-rest variance; runs longer than `min_static_s` are poses. Tedaldi take the
//! at-rest variance from an initial static period; we take the 10th percentile of all window
//! variances, which is the at-rest level whenever ≥ 10 % of the recording is static (true of
//! the "slow turns with pauses" of Jaime et al. and of any multi-pose run).
//!
//! Two poses recorded back to back with no motion between them (concatenated pose files) leave
//! no window above the threshold to separate them, yet every window straddling the join is
//! non-static (the jump in the mean is far above the noise). A run of static samples is therefore
//! split wherever its static windows are not consecutive and the means on the two sides differ
//! by more than [`JUMP_SIGMAS`] standard errors of their difference; a noise spike, which also
//! interrupts the windows, leaves the means equal and the pose whole. Samples flagged by the
//! caller (overflow sentinels) are never static.
use crate::lab::{
    model_names, params_sigma, CalError, Effect, Fitted, NoiseFloor, Params, Problem,
};
use crate::solve::{covariance, fit_model, mean};
use nalgebra::{DVector, Matrix3, Vector3};

/// A jump in the mean larger than this many standard errors splits a static run in two.
pub const JUMP_SIGMAS: f64 = 8.0;

/// Standard gravity (m/s²), the default g.
pub const G_STANDARD: f64 = 9.80665;

/// One static pose.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pose {
    /// First sample index (inclusive).
    pub start: usize,
    /// Last sample index (exclusive).
    pub end: usize,
    /// Mean specific force over the pose (input unit).
    pub mean: [f64; 3],
    /// Radial component of (mean of the first half − mean of the second half): an estimate of
    /// 2× the noise of the pose's |mean| (see [`AccelProblem::noise_floor`]).
    pub half_diff: f64,
}

impl Pose {
    /// Build a pose from samples `[start, end)` of the three axes.
    pub fn from_samples(a: [&[f64]; 3], start: usize, end: usize) -> Pose {
        let mid = start + (end - start) / 2;
        let m = |lo: usize, hi: usize| -> Vector3<f64> {
            Vector3::new(
                mean(&a[0][lo..hi]),
                mean(&a[1][lo..hi]),
                mean(&a[2][lo..hi]),
            )
        };
        let all = m(start, end);
        let d = m(start, mid) - m(mid, end);
        let u = all.normalize();
        Pose {
            start,
            end,
            mean: [all.x, all.y, all.z],
            half_diff: d.dot(&u),
        }
    }
}

/// Static-interval detection settings (module docs).
#[derive(Debug, Clone, Copy)]
pub struct StaticDetect {
    /// Sliding window (s).
    pub window_s: f64,
    /// Threshold multiplier k on the at-rest variance.
    pub k: f64,
    /// Shortest pose kept (s).
    pub min_static_s: f64,
}

impl Default for StaticDetect {
    fn default() -> Self {
        StaticDetect {
            window_s: 1.0,
            k: 6.0,
            min_static_s: 1.5,
        }
    }
}

/// Find static poses in a continuous recording sampled at `rate_hz` (module docs).
pub fn detect_static(
    a: [&[f64]; 3],
    rate_hz: f64,
    cfg: StaticDetect,
) -> Result<Vec<Pose>, CalError> {
    detect_static_masked(a, rate_hz, cfg, &[])
}

/// As [`detect_static`], never counting a sample with `flagged[i]` as static (`flagged` may be
/// empty: nothing flagged).
pub fn detect_static_masked(
    a: [&[f64]; 3],
    rate_hz: f64,
    cfg: StaticDetect,
    flagged: &[bool],
) -> Result<Vec<Pose>, CalError> {
    let n = a[0].len();
    if a[1].len() != n || a[2].len() != n {
        return Err(CalError::Input(
            "accelerometer axes have different lengths".into(),
        ));
    }
    if let Some((axis, i)) =
        (0..3).find_map(|k| a[k].iter().position(|v| !v.is_finite()).map(|i| (k, i)))
    {
        return Err(CalError::Input(format!(
            "accelerometer sample {i} (axis {}) is not finite",
            ["x", "y", "z"][axis]
        )));
    }
    if !(rate_hz > 0.0) || !rate_hz.is_finite() {
        return Err(CalError::Input(format!(
            "sample rate {rate_hz} Hz is not positive"
        )));
    }
    let positive = |v: f64| v > 0.0 && v.is_finite();
    let valid = positive(cfg.window_s)
        && positive(cfg.k)
        && cfg.min_static_s >= 0.0
        && cfg.min_static_s.is_finite();
    if !valid {
        return Err(CalError::Input(format!(
            "static detection needs a positive window, threshold and minimum pose length (got \
             {} s, k = {}, {} s)",
            cfg.window_s, cfg.k, cfg.min_static_s
        )));
    }
    if !flagged.is_empty() && flagged.len() != n {
        return Err(CalError::Input(
            "the flags of excluded samples do not match the recording".into(),
        ));
    }
    let flag = |i: usize| flagged.get(i).copied().unwrap_or(false);
    let w = ((cfg.window_s * rate_hz).round() as usize).max(3);
    if n < 2 * w {
        return Err(CalError::Input(format!(
            "{n} samples is too short for a {:.2} s static-detection window",
            cfg.window_s
        )));
    }
    // Prefix sums of x and x² per axis → windowed variance in O(1) each.
    let mut var = vec![0.0; n - w + 1];
    for ax in a {
        let mut s1 = vec![0.0; n + 1];
        let mut s2 = vec![0.0; n + 1];
        let off = ax[0];
        for i in 0..n {
            let x = ax[i] - off;
            s1[i + 1] = s1[i] + x;
            s2[i + 1] = s2[i] + x * x;
        }
        for (i, v) in var.iter_mut().enumerate() {
            let m = (s1[i + w] - s1[i]) / w as f64;
            *v += ((s2[i + w] - s2[i]) / w as f64 - m * m).max(0.0);
        }
    }
    let mut sorted = var.clone();
    sorted.sort_by(|x, y| x.total_cmp(y));
    let rest = sorted[sorted.len() / 10].max(1e-300);
    let thr = cfg.k * rest;
    // Windows holding a flagged sample are never static.
    let mut flagged_in = vec![false; var.len()];
    if !flagged.is_empty() {
        let mut count = (0..w).filter(|&j| flag(j)).count();
        for (i, f) in flagged_in.iter_mut().enumerate() {
            *f = count > 0;
            if i + w < n {
                count = count + flag(i + w) as usize - flag(i) as usize;
            }
        }
    }
    let static_window = |i: usize| var[i] <= thr && !flagged_in[i];
    // A sample is static when a window that contains it entirely is static; we mark the window
    // starting at i static and its samples [i, i + w) static.
    let mut stat = vec![false; n];
    for i in 0..var.len() {
        if static_window(i) {
            for s in &mut stat[i..i + w] {
                *s = true;
            }
        }
    }
    let min_len = ((cfg.min_static_s * rate_hz).round() as usize).max(4);
    // Noise variance of one sample summed over the axes, at rest (the window variance's level).
    let rest_var = rest * w as f64 / (w as f64 - 1.0);
    let mut poses = Vec::new();
    let mut i = 0;
    while i < n {
        if !stat[i] {
            i += 1;
            continue;
        }
        let s = i;
        while i < n && stat[i] {
            i += 1;
        }
        // Split the run [s, i) at jumps in the mean: where consecutive static windows are
        // separated by non-static ones and the means on either side differ.
        let mut cuts = vec![s];
        let mut last_start: Option<usize> = None;
        for j in s..(i.saturating_sub(w) + 1).min(var.len()) {
            if !static_window(j) {
                continue;
            }
            if let Some(prev) = last_start {
                if j > prev + 1 {
                    let lo = *cuts.last().expect("run start");
                    let hi = (prev + w).min(i);
                    let next_end = next_break(j, i, w, &static_window);
                    if jump(a, lo, hi, j, next_end, rest_var) {
                        cuts.push(j);
                    }
                }
            }
            last_start = Some(j);
        }
        cuts.push(i);
        for c in cuts.windows(2) {
            // A cut at j leaves the samples [prev + w, j) of the straddling windows to neither
            // side only when they are non-static; here [c0, c1) are all static samples.
            if c[1] - c[0] >= min_len {
                poses.push(Pose::from_samples(a, c[0], c[1]));
            }
        }
    }
    Ok(poses)
}

/// End of the run of consecutive static windows starting at window `j` (its last sample + 1).
fn next_break(j: usize, end: usize, w: usize, static_window: &dyn Fn(usize) -> bool) -> usize {
    let mut k = j;
    while k + 1 + w <= end && static_window(k + 1) {
        k += 1;
    }
    (k + w).min(end)
}

/// Whether the mean over [a0, a1) and the mean over [b0, b1) differ by more than
/// [`JUMP_SIGMAS`] standard errors (white noise of `rest_var` per sample, summed over the axes).
fn jump(a: [&[f64]; 3], a0: usize, a1: usize, b0: usize, b1: usize, rest_var: f64) -> bool {
    if a1 <= a0 || b1 <= b0 {
        return false;
    }
    let d2: f64 = (0..3)
        .map(|k| (mean(&a[k][a0..a1]) - mean(&a[k][b0..b1])).powi(2))
        .sum();
    let se2 = rest_var * (1.0 / (a1 - a0) as f64 + 1.0 / (b1 - b0) as f64);
    d2 > JUMP_SIGMAS * JUMP_SIGMAS * se2
}

/// The accelerometer problem: poses and g.
#[derive(Debug, Clone)]
pub struct AccelProblem {
    /// The static poses.
    pub poses: Vec<Pose>,
    /// Gravity, in the data's unit.
    pub g: f64,
    /// The data's unit (m/s² for the contract; LSB for raw counts).
    pub unit: String,
}

const EFFECTS: [Effect; 3] = [Effect::Offset, Effect::Scale, Effect::Misalignment];

/// `T·K` and `o` from a parameter vector laid out as [o?, s?, α?] for `model`.
fn unpack(model: &[Effect], x: &DVector<f64>) -> (Matrix3<f64>, Vector3<f64>, [f64; 3], [f64; 3]) {
    let mut k = 0;
    let mut take3 = |on: bool, def: f64| -> [f64; 3] {
        if on {
            let v = [x[k], x[k + 1], x[k + 2]];
            k += 3;
            v
        } else {
            [def; 3]
        }
    };
    let o = take3(model.contains(&Effect::Offset), 0.0);
    let s = take3(model.contains(&Effect::Scale), 1.0);
    let al = take3(model.contains(&Effect::Misalignment), 0.0);
    let t = Matrix3::new(1.0, 0.0, 0.0, al[0], 1.0, 0.0, al[1], al[2], 1.0);
    let tk = t * Matrix3::from_diagonal(&Vector3::new(s[0], s[1], s[2]));
    (tk, Vector3::new(o[0], o[1], o[2]), s, al)
}

impl AccelProblem {
    /// Poses and gravity in m/s².
    pub fn new(poses: Vec<Pose>, g: f64) -> AccelProblem {
        AccelProblem {
            poses,
            g,
            unit: "m/s²".into(),
        }
    }

    /// Poses and gravity in another unit (e.g. LSB: g = 16384 for a ±2 g MPU-6050).
    pub fn with_unit(poses: Vec<Pose>, g: f64, unit: &str) -> AccelProblem {
        AccelProblem {
            poses,
            g,
            unit: unit.into(),
        }
    }

    /// The lab residual of one pose mean under `params`: `|T·K·(ā − o)| − g`.
    pub fn residual(params: &Params, g: f64, mean: [f64; 3]) -> f64 {
        Vector3::from(Self::correct(params, mean)).norm() - g
    }

    /// Correct one sample with fitted params (`a_cal = T·K·(a − o)`).
    pub fn correct(params: &Params, a: [f64; 3]) -> [f64; 3] {
        let m = correction_matrix(params);
        let o = params.offset.unwrap_or([0.0; 3]);
        let v = m * (Vector3::from(a) - Vector3::from(o));
        [v.x, v.y, v.z]
    }
}

/// The matrix `T·K` of a parameter set (identity for absent effects).
pub fn correction_matrix(params: &Params) -> Matrix3<f64> {
    let s = params.scale.unwrap_or([1.0; 3]);
    let al = params
        .misalignment_deg
        .unwrap_or([0.0; 3])
        .map(f64::to_radians);
    let t = Matrix3::new(1.0, 0.0, 0.0, al[0], 1.0, 0.0, al[1], al[2], 1.0);
    t * Matrix3::from_diagonal(&Vector3::new(s[0], s[1], s[2]))
}

impl Problem for AccelProblem {
    fn sensor(&self) -> &'static str {
        "accel"
    }
    fn unit(&self) -> &str {
        &self.unit
    }
    fn effects(&self) -> &'static [Effect] {
        &EFFECTS
    }
    fn n(&self) -> usize {
        self.poses.len()
    }

    fn identifiable(&self, model: &[Effect], _e: Effect) -> Result<(), String> {
        let p = 3 * (model.len() + 1);
        if self.poses.len() <= p {
            return Err(format!(
                "{} poses cannot support {p} parameters",
                self.poses.len()
            ));
        }
        Ok(())
    }

    fn fit_items(&self, model: &[Effect], keep: &[bool]) -> Result<Fitted, CalError> {
        let p = 3 * model.len();
        let used: Vec<usize> = (0..self.poses.len()).filter(|&i| keep[i]).collect();
        // Fewer poses than parameters still fit (Levenberg–Marquardt's damping keeps the step
        // defined); the verdict then names what the poses leave undetermined.
        if used.is_empty() {
            return Err(CalError::Fit(format!(
                "{} static poses found{}; the model {:?} needs at least one",
                self.poses.len(),
                if used.len() < self.poses.len() {
                    format!(" ({} after excluding outliers)", used.len())
                } else {
                    String::new()
                },
                model.iter().map(|e| e.name()).collect::<Vec<_>>()
            )));
        }
        if !(self.g > 0.0 && self.g.is_finite()) {
            return Err(CalError::Input(format!(
                "gravity {} {} is not a positive number",
                self.g, self.unit
            )));
        }
        let mut x0 = Vec::new();
        for e in EFFECTS {
            if model.contains(&e) {
                x0.extend_from_slice(&if e == Effect::Scale {
                    [1.0; 3]
                } else {
                    [0.0; 3]
                });
            }
        }
        let g = self.g;
        let means: Vec<Vector3<f64>> = used
            .iter()
            .map(|&i| Vector3::from(self.poses[i].mean))
            .collect();
        let res = |x: &DVector<f64>| {
            let (tk, o, _, _) = unpack(model, x);
            DVector::from_iterator(means.len(), means.iter().map(|a| (tk * (a - o)).norm() - g))
        };
        let fit = fit_model(x0, res, 200, || {
            format!("accelerometer {}", model_names(model))
        })?;
        let to_params = |x: &DVector<f64>| {
            let (_, o, s, al) = unpack(model, x);
            Params {
                offset: model.contains(&Effect::Offset).then_some([o.x, o.y, o.z]),
                scale: model.contains(&Effect::Scale).then_some(s),
                misalignment_deg: model
                    .contains(&Effect::Misalignment)
                    .then_some(al.map(f64::to_degrees)),
                g: Some(g),
                ..Params::default()
            }
        };
        let params = to_params(&fit.x);
        let cov = covariance(&fit.jacobian, fit.rss, used.len().saturating_sub(p) as f64);
        let sigma = params_sigma(to_params, &fit.x, cov.as_ref());
        let residuals: Vec<f64> = self
            .poses
            .iter()
            .map(|pose| Self::residual(&params, g, pose.mean))
            .collect();
        Ok(Fitted {
            model: model.to_vec(),
            params,
            sigma,
            residuals,
            used: keep.to_vec(),
            n_params: p,
            not_converged: fit.not_converged,
        })
    }

    /// Datasheet-sized spreads of a low-cost accelerometer (the MPU-6050's: zero-g offset
    /// ±50–80 mg, sensitivity ±3 %, cross-axis ±2 % ≈ 1.2°), rounded up: offset ±0.1 g, scale
    /// ±0.1, misalignment ±2°.
    fn plausible_range(&self, name: &str, _params: &Params) -> Option<f64> {
        match name.split('.').next().unwrap_or(name) {
            "offset" => Some(0.1 * self.g),
            "scale" => Some(0.1),
            "misalignment_deg" => Some(2.0),
            _ => None,
        }
    }

    /// σ of |ā_i| per pose: the radial half-split differences d_i have variance 4·var(|ā_i|) for
    /// white noise (each half-mean has twice the variance of the whole-pose mean), so
    /// σ² = mean(d_i²)/4 with one degree of freedom per pose.
    fn noise_floor(&self) -> NoiseFloor {
        let d: Vec<f64> = self
            .poses
            .iter()
            .map(|p| p.half_diff * p.half_diff)
            .collect();
        NoiseFloor {
            sigma: (mean(&d) / 4.0).sqrt(),
            dof: self.poses.len() as f64,
            method: "half-pose mean differences",
        }
    }
}
