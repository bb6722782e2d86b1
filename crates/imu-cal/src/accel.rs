//! Accelerometer calibration from static poses.
//!
//! Model (seed eq. 1 extended with misalignment, Tedaldi et al. 2014 eq. 9 in lower-triangular
//! form):
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
//! variances, which is the at-rest level whenever ≥ 10 % of the recording is static (true of the
//! seed's "slow turns with pauses" and of any multi-pose run).
use crate::lab::{CalError, Effect, Fitted, NoiseFloor, Params, Problem};
use crate::solve::{levenberg_marquardt, mean};
use nalgebra::{DVector, Matrix3, Vector3};

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
    // A sample is static when a window that contains it entirely is static; we mark the window
    // starting at i static and its samples [i, i + w) static.
    let mut stat = vec![false; n];
    for (i, &v) in var.iter().enumerate() {
        if v <= thr {
            for s in &mut stat[i..i + w] {
                *s = true;
            }
        }
    }
    let min_len = ((cfg.min_static_s * rate_hz).round() as usize).max(4);
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
        if i - s >= min_len {
            poses.push(Pose::from_samples(a, s, i));
        }
    }
    Ok(poses)
}

/// The accelerometer problem: poses and g.
#[derive(Debug, Clone)]
pub struct AccelProblem {
    /// The static poses.
    pub poses: Vec<Pose>,
    /// Gravity (m/s² or the input unit).
    pub g: f64,
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
    fn unit(&self) -> &'static str {
        "m/s²"
    }
    fn effects(&self) -> &'static [Effect] {
        &EFFECTS
    }
    fn n(&self) -> usize {
        self.poses.len()
    }

    fn identifiable(&self, model: &[Effect], e: Effect) -> Result<(), String> {
        let p = 3 * (model.len() + 1);
        if self.poses.len() <= p {
            return Err(format!(
                "{} poses cannot support {p} parameters",
                self.poses.len()
            ));
        }
        let _ = e;
        Ok(())
    }

    fn fit(&self, model: &[Effect]) -> Result<Fitted, CalError> {
        let p = 3 * model.len();
        if self.poses.len() <= p.max(1) {
            return Err(CalError::Fit(format!(
                "{} static poses found; the model {:?} needs more than {p}",
                self.poses.len(),
                model.iter().map(|e| e.name()).collect::<Vec<_>>()
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
        let means: Vec<Vector3<f64>> = self.poses.iter().map(|p| Vector3::from(p.mean)).collect();
        let res = |x: &DVector<f64>| {
            let (tk, o, _, _) = unpack(model, x);
            DVector::from_iterator(means.len(), means.iter().map(|a| (tk * (a - o)).norm() - g))
        };
        let fit = if p == 0 {
            let r = res(&DVector::zeros(0));
            crate::solve::LmFit {
                rss: r.norm_squared(),
                x: DVector::zeros(0),
                r,
                iterations: 0,
            }
        } else {
            levenberg_marquardt(DVector::from_vec(x0), res, 200)
        };
        let (_, o, s, al) = unpack(model, &fit.x);
        let params = Params {
            offset: model.contains(&Effect::Offset).then_some([o.x, o.y, o.z]),
            scale: model.contains(&Effect::Scale).then_some(s),
            misalignment_deg: model
                .contains(&Effect::Misalignment)
                .then_some(al.map(f64::to_degrees)),
            g: Some(g),
            ..Params::default()
        };
        Ok(Fitted {
            model: model.to_vec(),
            params,
            residuals: fit.r.iter().copied().collect(),
            n_params: p,
        })
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
