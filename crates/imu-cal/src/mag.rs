//! Magnetometer hard and soft iron.
//!
//! Correction `m_cal = S · (m − h)`; the lab residual per sample is `|m_cal| − F`.
//!
//! * **hard_iron** (Jaime et al., eq. 3): `h`, the centre of the sphere (initial value from the
//!   linear least-squares sphere fit `|m|² = 2h·m + (F² − |h|²)`).
//! * **soft_iron_2d** (Jaime et al., eqs. 4–5, exactly): for data rotated in a plane, the ellipse of the
//!   in-plane components has semi-major axis r, semi-minor q and tilt θ; the correction rotates by
//!   `R(θ) = [[cos θ, sin θ], [−sin θ, cos θ]]` (eq. 4) and scales the first axis by `σ = q/r`
//!   (eq. 5): `S₂ = diag(σ, 1)·R(θ)`; the matrix reported and applied is `R(θ)ᵀ·S₂`, which
//!   rotates back so the axes (and headings) keep their meaning. Initial values from the algebraic conic fit
//!   `a x² + b xy + c y² + d x + e y = 1`, refined with the rest by Levenberg–Marquardt.
//! * **soft_iron**: a symmetric 3×3 `S` from an ellipsoid fit: the algebraic quadric least
//!   squares `Ax² + By² + Cz² + 2Dxy + 2Exz + 2Fyz + 2Gx + 2Hy + 2Iz = 1` (the design matrix of
//!   Li & Griffiths 2004, without their ellipsoid-specific constraint, which a well-spread
//!   recording does not need; a non-ellipsoid result is reported as an error), `S = F·Q̂^{1/2}`
//!   with `Q̂` the normalised quadric, then Levenberg–Marquardt on Σ(|S(m − h)| − F)². With F
//!   fitted, F and the scale of S are not separable; we report `S` with det S = 1 and F its
//!   geometric-mean radius.
//!
//! **Robust start.** The robust fit of the lab (`lab` module docs, 1) starts from the samples
//! within [`START_CUT`] robust scales of the least-median-of-squares sphere (planar data: circle
//! of the in-plane components), found over [`START_TRIALS`] random minimal subsets (4 samples
//! define a sphere, 3 a circle) drawn by a xorshift generator keyed by the data. The sphere is
//! used for every model: it only has to tell gross outliers from the shell of the data, which a
//! soft-iron ellipsoid of ±10 % stays within; the lab then judges each sample again with the
//! model's own residual. The median's breakdown point is 50 %: the start holds while fewer than
//! half the samples are gross outliers, where least squares of every sample is pulled by a few.
//!
//! **Noise floor.** σ of one residual, from the residuals themselves: the residual series (in
//! recording order) of the robust fit of the most complete model the data identify
//! (hard_iron+soft_iron, planar hard_iron+soft_iron_2d; hard_iron if that fit fails), and
//! σ = 1.4826·MAD(second differences)/√6. The model removes the motion (|m| is constant on the
//! sphere however fast the sensor turns) and the second differences any slow misfit of orientation
//! that the model lacks, so a missing effect still shows above the floor. Second differences of
//! the raw axes (the fallback when no fit succeeds) hold the motion itself, `F·ω²` per sample for
//! a turn of ω rad between samples, which exceeds the noise of a hand-turned board.
//!
//! **Planar data.** When the measurements lie in a plane (smallest principal standard deviation
//! below [`PLANAR_RATIO`] of the largest), the axis closest to the plane normal is not excited:
//! the problem becomes 2-D on the other two axes (hard iron in-plane only; `F` is the in-plane
//! field; the residual is `|(S(m − h))_plane| − F`) and only `soft_iron_2d` is identifiable. In
//! 3-D data `soft_iron_2d` is not the answer and `soft_iron` is used instead.
//!
//! **Tilt (out-of-plane motion).** A hand-held "level" turn wobbles: the rotation plane tilts by
//! a few degrees, and the vertical field (40 µT at mid latitudes) leaks into the horizontal axes
//! by `B_z·sin(tilt)`, so the in-plane magnitude varies with the out-of-plane component while
//! the full magnitude is conserved. The `tilt` effect of planar data takes the out-of-plane axis
//! back into the magnitude: the residual becomes `|S(m − h)| − F` over all three axes, with the
//! out-of-plane hard-iron component `h_k` fitted (one more parameter, identifiable through the
//! wobble itself: `|m_plane − h|² = F² − (m_k − h_k)²` is a straight line in `m_k`, whose fit
//! gives the starting values). Its evidence in the time domain is the correlation of the
//! in-plane residual with `m_k`, and the effect is tried only when that correlation is at least
//! [`TILT_MIN_CORRELATION`]: without the evidence the 3-D magnitude would let a sphere of huge
//! radius, centred far away, pass through any planar data (a plane is a sphere of infinite
//! radius) and "explain" an ellipse that is soft iron.
use crate::lab::{
    model_names, params_sigma, CalError, Effect, Fitted, NoiseFloor, Params, Problem, SoftIron2d,
};
use crate::solve::{
    covariance, data_key, fit_model, lmeds, lstsq, mean, second_diff_dof, sigma_second_diff,
    sym_eigen,
};
use nalgebra::{DMatrix, DVector, Matrix2, Matrix3, Matrix4, Vector2, Vector3, Vector4};
use std::sync::OnceLock;

/// Random minimal subsets the robust start tries (module docs): with 25 % gross outliers a
/// 4-sample subset is clean with probability 0.32, so 200 trials all miss with probability
/// 1e-33; at 50 % (the breakdown point of the median) 1e-6.
pub const START_TRIALS: usize = 200;
/// Samples within this many robust scales of the robust start's sphere (or circle) start the
/// robust fit (Rousseeuw & Leroy 1987, §5.1: 2.5 s₀).
pub const START_CUT: f64 = 2.5;

/// Ratio of principal standard deviations below which data counts as planar.
pub const PLANAR_RATIO: f64 = 0.15;
/// Smallest |correlation| of the in-plane residual with the out-of-plane component for which
/// `tilt` is tried (module docs).
pub const TILT_MIN_CORRELATION: f64 = 0.3;

const EFFECTS: [Effect; 4] = [
    Effect::HardIron,
    Effect::SoftIron,
    Effect::SoftIron2d,
    Effect::Tilt,
];

/// The magnetometer problem.
#[derive(Debug, Clone)]
pub struct MagProblem {
    /// Samples (µT).
    pub m: Vec<Vector3<f64>>,
    /// Field magnitude, when given.
    pub field: Option<f64>,
    /// For planar data: the two in-plane axes (the third is not excited).
    pub plane: Option<[usize; 2]>,
    /// Principal standard deviations, largest first (µT).
    pub principal_sd: [f64; 3],
    /// The data's unit (µT for the contract; LSB for raw counts).
    pub unit: String,
    /// Per-axis second-difference σ, the floor's fallback (module docs).
    sigma: f64,
    /// The noise floor, estimated once (it needs a robust fit).
    floor: OnceLock<NoiseFloor>,
}

/// Hard iron as Jaime et al. estimate it: the midpoint of each axis' range over a full rotation.
pub fn hard_iron_minmax(m: &[Vector3<f64>]) -> [f64; 3] {
    let mut out = [0.0; 3];
    for (k, o) in out.iter_mut().enumerate() {
        let lo = m.iter().map(|v| v[k]).fold(f64::INFINITY, f64::min);
        let hi = m.iter().map(|v| v[k]).fold(f64::NEG_INFINITY, f64::max);
        *o = 0.5 * (lo + hi);
    }
    out
}

/// Linear least-squares sphere fit: centre and radius.
pub fn sphere_fit(m: &[Vector3<f64>]) -> Result<(Vector3<f64>, f64), CalError> {
    let n = m.len();
    let a = DMatrix::from_fn(n, 4, |i, j| if j < 3 { 2.0 * m[i][j] } else { 1.0 });
    let b = DVector::from_fn(n, |i, _| m[i].norm_squared());
    let x = lstsq(a, &b, "sphere fit")?;
    let c = Vector3::new(x[0], x[1], x[2]);
    let r2 = x[3] + c.norm_squared();
    if !(r2 > 0.0) {
        return Err(CalError::Fit("sphere fit gives no real radius".into()));
    }
    Ok((c, r2.sqrt()))
}

/// Algebraic ellipse fit on 2-D points: (centre, r, q, θ in rad) — the parameters of
/// Jaime et al., eqs. 4–5.
pub fn ellipse_fit(p: &[Vector2<f64>]) -> Result<(Vector2<f64>, f64, f64, f64), CalError> {
    let n = p.len();
    // Centre the data first for conditioning.
    let c0 = p.iter().fold(Vector2::zeros(), |a, v| a + v) / n as f64;
    let sc = p.iter().map(|v| (v - c0).norm()).sum::<f64>() / n as f64;
    let q: Vec<Vector2<f64>> = p.iter().map(|v| (v - c0) / sc).collect();
    let a = DMatrix::from_fn(n, 5, |i, j| {
        let (x, y) = (q[i].x, q[i].y);
        [x * x, x * y, y * y, x, y][j]
    });
    let b = DVector::from_element(n, 1.0);
    let s = lstsq(a, &b, "ellipse fit")?;
    let qf = Matrix2::new(s[0], s[1] / 2.0, s[1] / 2.0, s[2]);
    let l = Vector2::new(s[3], s[4]);
    let x0 = -qf
        .try_inverse()
        .ok_or_else(|| CalError::Fit("ellipse fit is degenerate".into()))?
        * l
        / 2.0;
    let kappa = 1.0 + x0.dot(&(qf * x0));
    let eig = sym_eigen(qf / kappa, "ellipse fit")?;
    let (i_min, i_max) = if eig.eigenvalues[0] <= eig.eigenvalues[1] {
        (0, 1)
    } else {
        (1, 0)
    };
    let (l1, l2) = (eig.eigenvalues[i_min], eig.eigenvalues[i_max]);
    if !(l1 > 0.0 && l2 > 0.0) {
        return Err(CalError::Fit(
            "the in-plane data do not form an ellipse".into(),
        ));
    }
    let v = eig.eigenvectors.column(i_min);
    let mut theta = v[1].atan2(v[0]);
    if theta > std::f64::consts::FRAC_PI_2 {
        theta -= std::f64::consts::PI;
    } else if theta <= -std::f64::consts::FRAC_PI_2 {
        theta += std::f64::consts::PI;
    }
    Ok((c0 + x0 * sc, sc / l1.sqrt(), sc / l2.sqrt(), theta))
}

/// Algebraic ellipsoid fit (module docs): centre and the normalised quadric Q̂ with
/// (m − c)ᵀ Q̂ (m − c) = 1.
pub fn ellipsoid_fit(m: &[Vector3<f64>]) -> Result<(Vector3<f64>, Matrix3<f64>), CalError> {
    let n = m.len();
    let c0 = m.iter().fold(Vector3::zeros(), |a, v| a + v) / n as f64;
    let sc = m.iter().map(|v| (v - c0).norm()).sum::<f64>() / n as f64;
    let q: Vec<Vector3<f64>> = m.iter().map(|v| (v - c0) / sc).collect();
    let a = DMatrix::from_fn(n, 9, |i, j| {
        let (x, y, z) = (q[i].x, q[i].y, q[i].z);
        [
            x * x,
            y * y,
            z * z,
            2.0 * x * y,
            2.0 * x * z,
            2.0 * y * z,
            2.0 * x,
            2.0 * y,
            2.0 * z,
        ][j]
    });
    let s = lstsq(a, &DVector::from_element(n, 1.0), "ellipsoid fit")?;
    let qf = Matrix3::new(s[0], s[3], s[4], s[3], s[1], s[5], s[4], s[5], s[2]);
    let g = Vector3::new(s[6], s[7], s[8]);
    let c = -qf
        .try_inverse()
        .ok_or_else(|| CalError::Fit("ellipsoid fit is degenerate".into()))?
        * g;
    let kappa = 1.0 + c.dot(&(qf * c));
    let qn = qf / kappa;
    let eig = sym_eigen(qn, "ellipsoid fit")?;
    if eig.eigenvalues.iter().any(|&l| !(l > 0.0)) {
        return Err(CalError::Fit(
            "the measurements do not form an ellipsoid (rotate the sensor through more orientations)"
                .into(),
        ));
    }
    Ok((c0 + c * sc, qn / (sc * sc)))
}

/// The sphere through the four points `s` of `pts` (centre, radius); None when they are
/// (nearly) coplanar.
fn sphere_through(pts: &[Vector3<f64>], s: &[usize]) -> Option<(Vector3<f64>, f64)> {
    let a = Matrix4::from_fn(|i, j| if j < 3 { 2.0 * pts[s[i]][j] } else { 1.0 });
    let b = Vector4::from_fn(|i, _| pts[s[i]].norm_squared());
    let x = a.lu().solve(&b)?;
    let c = Vector3::new(x[0], x[1], x[2]);
    let r2 = x[3] + c.norm_squared();
    (r2 > 0.0 && r2.is_finite()).then(|| (c, r2.sqrt()))
}

/// The circle through the three points `s` of `pts` (in their first two components).
fn circle_through(pts: &[Vector3<f64>], s: &[usize]) -> Option<(Vector3<f64>, f64)> {
    let a = Matrix3::from_fn(|i, j| if j < 2 { 2.0 * pts[s[i]][j] } else { 1.0 });
    let b = Vector3::from_fn(|i, _| pts[s[i]].xy().norm_squared());
    let x = a.lu().solve(&b)?;
    let c = Vector3::new(x[0], x[1], 0.0);
    let r2 = x[2] + c.norm_squared();
    (r2 > 0.0 && r2.is_finite()).then(|| (c, r2.sqrt()))
}

/// Distance of point `i` from the shell (sphere or circle) `(c, r)`.
fn shell_residual(pts: &[Vector3<f64>]) -> impl Fn(&(Vector3<f64>, f64), usize) -> f64 + '_ {
    |(c, r), i| (pts[i] - c).norm() - r
}

/// Symmetric square root of a positive-definite matrix.
fn sqrtm(a: &Matrix3<f64>) -> Result<Matrix3<f64>, CalError> {
    let e = sym_eigen(*a, "matrix square root")?;
    let d = Matrix3::from_diagonal(&e.eigenvalues.map(|l| l.max(0.0).sqrt()));
    Ok(e.eigenvectors * d * e.eigenvectors.transpose())
}

fn sym(x: &[f64]) -> Matrix3<f64> {
    Matrix3::new(x[0], x[1], x[2], x[1], x[3], x[4], x[2], x[4], x[5])
}

fn s2d(theta: f64, sigma: f64) -> Matrix2<f64> {
    let (s, c) = theta.sin_cos();
    Matrix2::new(sigma, 0.0, 0.0, 1.0) * Matrix2::new(c, s, -s, c)
}

impl MagProblem {
    /// Prepare the data: checks, principal axes, planarity, noise.
    pub fn new(m: Vec<Vector3<f64>>, field: Option<f64>) -> Result<Self, CalError> {
        Self::with_unit(m, field, "µT")
    }

    /// As [`MagProblem::new`], for data (and `field`) in `unit`.
    pub fn with_unit(
        m: Vec<Vector3<f64>>,
        field: Option<f64>,
        unit: &str,
    ) -> Result<Self, CalError> {
        if m.len() < 20 {
            return Err(CalError::Input(format!(
                "{} magnetometer samples; at least 20 are needed",
                m.len()
            )));
        }
        if let Some(i) = m.iter().position(|v| !v.iter().all(|x| x.is_finite())) {
            return Err(CalError::Input(format!(
                "magnetometer sample {i} is not finite"
            )));
        }
        if let Some(f) = field {
            if !(f > 0.0 && f.is_finite()) {
                return Err(CalError::Input(format!(
                    "field magnitude {f} {unit} is not positive"
                )));
            }
        }
        let c = m.iter().fold(Vector3::zeros(), |a, v| a + v) / m.len() as f64;
        let cov = m
            .iter()
            .fold(Matrix3::zeros(), |a, v| a + (v - c) * (v - c).transpose())
            / m.len() as f64;
        let e = sym_eigen(cov, "principal axes of the magnetometer data")?;
        let mut idx = [0usize, 1, 2];
        idx.sort_by(|&a, &b| e.eigenvalues[b].total_cmp(&e.eigenvalues[a]));
        let sd = idx.map(|i| e.eigenvalues[i].max(0.0).sqrt());
        let scale = m.iter().map(|v| v.norm()).fold(0.0, f64::max);
        if !(sd[1] > 1e-6 * scale.max(1e-30)) {
            return Err(CalError::Input(format!(
                "the magnetometer data span only {:.3e}/{:.3e}/{:.3e} (principal s.d.): turn the \
                 sensor through a full rotation (planar) or many orientations (3-D)",
                sd[0], sd[1], sd[2]
            )));
        }
        let plane = if sd[2] < PLANAR_RATIO * sd[0] {
            let normal = e.eigenvectors.column(idx[2]);
            let k = (0..3)
                .max_by(|&a, &b| normal[a].abs().total_cmp(&normal[b].abs()))
                .unwrap_or(2);
            let axes: Vec<usize> = (0..3).filter(|&a| a != k).collect();
            Some([axes[0], axes[1]])
        } else {
            None
        };
        let axes: Vec<usize> = match plane {
            Some(p) => p.to_vec(),
            None => vec![0, 1, 2],
        };
        let s2: f64 = axes
            .iter()
            .map(|&k| {
                let x: Vec<f64> = m.iter().map(|v| v[k]).collect();
                sigma_second_diff(&x).powi(2)
            })
            .sum::<f64>()
            / axes.len() as f64;
        Ok(MagProblem {
            m,
            field,
            plane,
            principal_sd: sd,
            unit: unit.into(),
            sigma: s2.sqrt(),
            floor: OnceLock::new(),
        })
    }

    /// The points the robust start fits: the in-plane components for planar data, else all
    /// three, relative to the data's centroid.
    fn start_points(&self) -> Vec<Vector3<f64>> {
        let c = centroid(&self.m);
        match self.plane {
            Some([i, j]) => self
                .m
                .iter()
                .map(|v| Vector3::new(v[i] - c[i], v[j] - c[j], 0.0))
                .collect(),
            None => self.m.iter().map(|v| v - c).collect(),
        }
    }

    /// The noise floor (module docs): second differences of the residual series of the most
    /// complete model the data identify, fitted robustly; the per-axis estimate when no such fit
    /// exists.
    fn estimate_floor(&self) -> NoiseFloor {
        let none = NoiseFloor {
            sigma: 0.0,
            dof: 1.0,
            method: "",
        };
        let tries: [(&[Effect], &'static str); 2] = match self.plane {
            Some(_) => [
                (
                    &[Effect::HardIron, Effect::SoftIron2d],
                    "second differences (MAD) of the robust hard_iron+soft_iron_2d residuals",
                ),
                (
                    &[Effect::HardIron],
                    "second differences (MAD) of the robust hard_iron residuals",
                ),
            ],
            None => [
                (
                    &[Effect::HardIron, Effect::SoftIron],
                    "second differences (MAD) of the robust hard_iron+soft_iron residuals",
                ),
                (
                    &[Effect::HardIron],
                    "second differences (MAD) of the robust hard_iron residuals",
                ),
            ],
        };
        for (model, method) in tries {
            let Ok(f) = crate::lab::robust_fit(self, model, &none) else {
                continue;
            };
            let r: Vec<f64> = f.used_residuals().collect();
            let sigma = sigma_second_diff(&r);
            if r.len() >= 20 && sigma.is_finite() {
                return NoiseFloor {
                    sigma,
                    dof: second_diff_dof(r.len()),
                    method,
                };
            }
        }
        NoiseFloor {
            sigma: self.sigma,
            // One estimate per axis, averaged.
            dof: second_diff_dof(self.m.len()) * if self.plane.is_some() { 2.0 } else { 3.0 },
            method: "per-axis second differences (MAD; no robust fit of the data succeeded)",
        }
    }

    /// Apply fitted params to a sample: `S·(m − h)`.
    pub fn correct(params: &Params, m: Vector3<f64>) -> Vector3<f64> {
        let h = Vector3::from(params.hard_iron.unwrap_or([0.0; 3]));
        let s = params
            .soft_iron
            .map(|s| Matrix3::from_row_slice(&s.concat()))
            .unwrap_or_else(Matrix3::identity);
        s * (m - h)
    }

    /// The lab residual of sample `m` under `params` fitted with `model` (module docs):
    /// `|S(m − h)| − F` for 3-D data and for planar data with `tilt`; for planar data without it
    /// the corrected in-plane magnitude minus the in-plane field `F`.
    pub fn residual(&self, model: &[Effect], params: &Params, m: Vector3<f64>) -> f64 {
        let c = Self::correct(params, m);
        let f = params.field.unwrap_or(0.0);
        match self.plane {
            Some([i, j]) if !model.contains(&Effect::Tilt) => {
                (c[i] * c[i] + c[j] * c[j]).sqrt() - f
            }
            _ => c.norm() - f,
        }
    }

    /// Correlation of the residuals `fitted` used with the out-of-plane component (planar data).
    fn out_of_plane_correlation(&self, fitted: &Fitted) -> Option<(f64, usize, usize, f64)> {
        let [i, j] = self.plane?;
        let k = 3 - i - j;
        let (r, z): (Vec<f64>, Vec<f64>) = fitted
            .residuals
            .iter()
            .zip(&fitted.used)
            .zip(&self.m)
            .filter(|((_, u), _)| **u)
            .map(|((r, _), m)| (*r, m[k]))
            .unzip();
        let (mr, mz) = (mean(&r), mean(&z));
        let sxy: f64 = r.iter().zip(&z).map(|(a, b)| (a - mr) * (b - mz)).sum();
        let sxx: f64 = r.iter().map(|a| (a - mr).powi(2)).sum();
        let syy: f64 = z.iter().map(|b| (b - mz).powi(2)).sum();
        let corr = sxy / (sxx * syy).sqrt();
        corr.is_finite()
            .then(|| (corr, k, r.len(), (syy / z.len() as f64).sqrt()))
    }

    fn fit_planar(
        &self,
        model: &[Effect],
        [i, j]: [usize; 2],
        idx: &[usize],
    ) -> Result<Fitted, CalError> {
        let k = 3 - i - j;
        let p: Vec<Vector2<f64>> = idx
            .iter()
            .map(|&s| Vector2::new(self.m[s][i], self.m[s][j]))
            .collect();
        let mk: Vec<f64> = idx.iter().map(|&s| self.m[s][k]).collect();
        let has_h = model.contains(&Effect::HardIron);
        let has_2d = model.contains(&Effect::SoftIron2d);
        let has_tilt = model.contains(&Effect::Tilt);
        let fit_f = self.field.is_none();
        // Initial values.
        let (mut c0, mut th0, mut sg0, mut f0) = (Vector2::zeros(), 0.0, 1.0, 0.0);
        if has_2d {
            let (c, r, q, th) = ellipse_fit(&p)?;
            if has_h {
                c0 = c;
            }
            th0 = th;
            sg0 = q / r;
            f0 = q;
        } else if has_h {
            let n = p.len();
            let a = DMatrix::from_fn(n, 3, |r, l| if l < 2 { 2.0 * p[r][l] } else { 1.0 });
            let b = DVector::from_fn(n, |r, _| p[r].norm_squared());
            let x = lstsq(a, &b, "circle fit")?;
            c0 = Vector2::new(x[0], x[1]);
            f0 = (x[2] + c0.norm_squared()).max(0.0).sqrt();
        }
        if f0 == 0.0 {
            f0 = p.iter().map(|v| (v - c0).norm()).sum::<f64>() / p.len() as f64;
        }
        // Out-of-plane hard iron: |m_plane − c|² + m_k² = (F² − h_k²) + 2·h_k·m_k, a straight
        // line in m_k (the wobble makes it identifiable).
        let mut hk0 = 0.0;
        if has_tilt {
            let n = p.len();
            let a = DMatrix::from_fn(n, 2, |r, l| if l == 0 { 2.0 * mk[r] } else { 1.0 });
            let b = DVector::from_fn(n, |r, _| (p[r] - c0).norm_squared() + mk[r] * mk[r]);
            let x = lstsq(a, &b, "out-of-plane (tilt) line")?;
            hk0 = x[0];
            f0 = (x[1] + hk0 * hk0).max(0.0).sqrt();
        }
        let mut x0 = Vec::new();
        if has_h {
            x0.extend_from_slice(&[c0.x, c0.y]);
        }
        if has_2d {
            x0.extend_from_slice(&[th0, sg0]);
        }
        if has_tilt {
            x0.push(hk0);
        }
        if fit_f {
            x0.push(f0);
        }
        let fgiven = self.field.unwrap_or(0.0);
        let unpack = |x: &DVector<f64>| {
            let mut q = 0;
            let c = if has_h {
                q += 2;
                Vector2::new(x[0], x[1])
            } else {
                Vector2::zeros()
            };
            let (th, sg) = if has_2d {
                q += 2;
                (x[q - 2], x[q - 1])
            } else {
                (0.0, 1.0)
            };
            let hk = if has_tilt {
                q += 1;
                x[q - 1]
            } else {
                0.0
            };
            let f = if fit_f { x[q] } else { fgiven };
            (c, th, sg, hk, f)
        };
        let res = |x: &DVector<f64>| {
            let (c, th, sg, hk, f) = unpack(x);
            let s = s2d(th, sg);
            DVector::from_iterator(
                p.len(),
                p.iter().zip(&mk).map(|(v, z)| {
                    let w = s * (v - c);
                    if has_tilt {
                        (w.norm_squared() + (z - hk).powi(2)).sqrt() - f
                    } else {
                        w.norm() - f
                    }
                }),
            )
        };
        let fit = fit_model(x0, res, 300, || {
            format!("magnetometer {} (planar data)", model_names(model))
        })?;
        // Jaime et al. stop after eq. 5: diag(σ,1)·R(θ) leaves the frame rotated by θ, which does
        // not change |m| (nor their Fig. 4 circle) but would turn every heading by θ. The matrix
        // handed to the device rotates back: S = R(θ)ᵀ·diag(σ,1)·R(θ) (symmetric, axes kept).
        let to_params = |x: &DVector<f64>| {
            let (c, th, sg, hk, f) = unpack(x);
            let (sn, cs) = th.sin_cos();
            let s = Matrix2::new(cs, -sn, sn, cs) * s2d(th, sg);
            let mut h3 = [0.0; 3];
            h3[i] = c.x;
            h3[j] = c.y;
            h3[k] = hk;
            let mut s3 = [[0.0; 3]; 3];
            s3[k][k] = 1.0;
            for (a, &ra) in [i, j].iter().enumerate() {
                for (b, &cb) in [i, j].iter().enumerate() {
                    s3[ra][cb] = s[(a, b)];
                }
            }
            // Keep θ in (−90°, 90°]; σ = q/r with F = q the corrected radius, so r = q/σ.
            let th = (th + std::f64::consts::FRAC_PI_2).rem_euclid(std::f64::consts::PI)
                - std::f64::consts::FRAC_PI_2;
            // In-plane radius: with tilt the in-plane field is what is left of F.
            let q = if has_tilt {
                let dz = mean(&mk) - hk;
                (f * f - dz * dz).max(0.0).sqrt()
            } else {
                f
            };
            Params {
                hard_iron: (has_h || has_tilt).then_some(h3),
                soft_iron: has_2d.then_some(s3),
                soft_iron_2d: has_2d.then_some(SoftIron2d {
                    r: q / sg.abs(),
                    q,
                    theta_deg: th.to_degrees(),
                    sigma: sg.abs(),
                }),
                field: Some(f),
                ..Params::default()
            }
        };
        let params = to_params(&fit.x);
        let np = 2 * has_h as usize + 2 * has_2d as usize + has_tilt as usize + fit_f as usize;
        let cov = covariance(&fit.jacobian, fit.rss, (idx.len() - np) as f64);
        let sigma = params_sigma(to_params, &fit.x, cov.as_ref());
        Ok(self.fitted(model, params, sigma, idx, np, fit.not_converged))
    }

    /// The fit's residuals for every sample, `used` for the samples of `idx`.
    fn fitted(
        &self,
        model: &[Effect],
        params: Params,
        sigma: Params,
        idx: &[usize],
        n_params: usize,
        not_converged: Option<String>,
    ) -> Fitted {
        let residuals = self
            .m
            .iter()
            .map(|v| self.residual(model, &params, *v))
            .collect();
        let mut used = vec![false; self.m.len()];
        for &s in idx {
            used[s] = true;
        }
        Fitted {
            model: model.to_vec(),
            params,
            sigma,
            residuals,
            used,
            n_params,
            not_converged,
        }
    }

    fn fit_3d(&self, model: &[Effect], idx: &[usize]) -> Result<Fitted, CalError> {
        let has_h = model.contains(&Effect::HardIron);
        let has_s = model.contains(&Effect::SoftIron);
        let fit_f = self.field.is_none();
        let m: Vec<Vector3<f64>> = idx.iter().map(|&s| self.m[s]).collect();
        // Initial values.
        let (mut h0, w0, f0);
        if has_s {
            let (c, qn) = ellipsoid_fit(&m)?;
            let w = sqrtm(&qn)?; // |w (m − c)| ≈ 1
            let fref = match self.field {
                Some(f) => f,
                None => w.determinant().powf(-1.0 / 3.0),
            };
            w0 = w * fref;
            f0 = fref;
            h0 = if has_h { c } else { Vector3::zeros() };
        } else {
            let (c, r) = sphere_fit(&m)?;
            h0 = if has_h { c } else { Vector3::zeros() };
            f0 = if has_h {
                r
            } else {
                m.iter().map(|v| v.norm()).sum::<f64>() / m.len() as f64
            };
            w0 = Matrix3::identity();
        }
        if !has_h {
            h0 = Vector3::zeros();
        }
        let fgiven = self.field.unwrap_or(f0);
        let mut x0 = Vec::new();
        if has_h {
            x0.extend(h0.iter());
        }
        if has_s {
            x0.extend_from_slice(&[
                w0[(0, 0)],
                w0[(0, 1)],
                w0[(0, 2)],
                w0[(1, 1)],
                w0[(1, 2)],
                w0[(2, 2)],
            ]);
        }
        // With soft iron, F is tied to the scale of S (module docs): it stays fixed in the LM.
        let f_free = fit_f && !has_s;
        if f_free {
            x0.push(f0);
        }
        let unpack = |x: &DVector<f64>| {
            let mut k = 0;
            let h = if has_h {
                k += 3;
                Vector3::new(x[0], x[1], x[2])
            } else {
                Vector3::zeros()
            };
            let s = if has_s {
                k += 6;
                sym(&x.as_slice()[k - 6..k])
            } else {
                Matrix3::identity()
            };
            let f = if f_free { x[k] } else { fgiven };
            (h, s, f)
        };
        let res = |x: &DVector<f64>| {
            let (h, s, f) = unpack(x);
            DVector::from_iterator(m.len(), m.iter().map(|v| (s * (v - h)).norm() - f))
        };
        let fit = fit_model(x0, res, 300, || {
            format!("magnetometer {}", model_names(model))
        })?;
        if has_s && fit_f && !(unpack(&fit.x).1.determinant() > 0.0) {
            return Err(CalError::Fit(
                "soft-iron fit gave a non-positive determinant".into(),
            ));
        }
        let to_params = |x: &DVector<f64>| {
            let (h, mut s, mut f) = unpack(x);
            if has_s && fit_f {
                let k = s.determinant().cbrt();
                s /= k;
                f /= k;
            }
            Params {
                hard_iron: has_h.then_some([h.x, h.y, h.z]),
                soft_iron: has_s.then_some([
                    [s[(0, 0)], s[(0, 1)], s[(0, 2)]],
                    [s[(1, 0)], s[(1, 1)], s[(1, 2)]],
                    [s[(2, 0)], s[(2, 1)], s[(2, 2)]],
                ]),
                field: Some(f),
                ..Params::default()
            }
        };
        let params = to_params(&fit.x);
        let np = 3 * has_h as usize + 6 * has_s as usize + (fit_f && !has_s) as usize;
        let cov = covariance(
            &fit.jacobian,
            fit.rss,
            (idx.len() - np.min(idx.len())) as f64,
        );
        let sigma = params_sigma(to_params, &fit.x, cov.as_ref());
        Ok(self.fitted(model, params, sigma, idx, np, fit.not_converged))
    }
}

impl Problem for MagProblem {
    fn sensor(&self) -> &'static str {
        "mag"
    }
    fn unit(&self) -> &str {
        &self.unit
    }
    fn effects(&self) -> &'static [Effect] {
        &EFFECTS
    }
    fn n(&self) -> usize {
        self.m.len()
    }

    fn identifiable(&self, model: &[Effect], e: Effect) -> Result<(), String> {
        let sd = self.principal_sd;
        let u = &self.unit;
        match (e, self.plane) {
            (Effect::SoftIron, Some(_)) => Err(format!(
                "the data are planar (principal s.d. {:.2}/{:.2}/{:.2} {u}): a 3-D ellipsoid is \
                 not determined; soft_iron_2d describes the plane",
                sd[0], sd[1], sd[2]
            )),
            (Effect::SoftIron2d, None) => Err(format!(
                "the data are rotated in 3-D (principal s.d. {:.2}/{:.2}/{:.2} {u}): the planar \
                 ellipse of Jaime et al. does not apply; soft_iron does",
                sd[0], sd[1], sd[2]
            )),
            (Effect::Tilt, None) => Err(format!(
                "the data are rotated in 3-D (principal s.d. {:.2}/{:.2}/{:.2} {u}): the full \
                 magnitude is already fitted, out-of-plane motion is part of the data",
                sd[0], sd[1], sd[2]
            )),
            (Effect::SoftIron, None) | (Effect::SoftIron2d, Some(_))
                if model.contains(&Effect::SoftIron) || model.contains(&Effect::SoftIron2d) =>
            {
                Err("a soft-iron effect is already in the model".into())
            }
            _ => Ok(()),
        }
    }

    fn fit_items(&self, model: &[Effect], keep: &[bool]) -> Result<Fitted, CalError> {
        if model.contains(&Effect::SoftIron) && model.contains(&Effect::SoftIron2d) {
            return Err(CalError::Input(
                "use either soft_iron or soft_iron_2d, not both".into(),
            ));
        }
        for &e in model {
            if e != Effect::HardIron {
                self.identifiable(&[], e).map_err(CalError::Fit)?;
            }
        }
        let idx: Vec<usize> = (0..self.m.len()).filter(|&s| keep[s]).collect();
        if idx.len() < 20 {
            return Err(CalError::Fit(format!(
                "{} magnetometer samples left after excluding outliers; at least 20 are needed",
                idx.len()
            )));
        }
        match self.plane {
            Some(p) => self.fit_planar(model, p, &idx),
            None => self.fit_3d(model, &idx),
        }
    }

    fn noise_floor(&self) -> NoiseFloor {
        *self.floor.get_or_init(|| self.estimate_floor())
    }

    /// The least-median-of-squares sphere (3-D) or circle (planar) over minimal subsets
    /// (module docs): the samples within [`START_CUT`] robust scales of it. Whatever the model,
    /// the sphere or circle only has to tell gross outliers from the shell of the data (a
    /// soft-iron ellipsoid lies within a few robust scales of its best sphere); the robust fit
    /// then judges every sample again with the model's own residual.
    fn robust_start(&self, _model: &[Effect]) -> Option<Vec<bool>> {
        let pts = self.start_points();
        let key = data_key(self.m.iter().flat_map(|v| v.iter().copied()));
        let (n, planar) = (pts.len(), self.plane.is_some());
        let (_, s0, r) = if planar {
            lmeds(
                n,
                3,
                START_TRIALS,
                key,
                |s| circle_through(&pts, s),
                shell_residual(&pts),
            )?
        } else {
            lmeds(
                n,
                4,
                START_TRIALS,
                key,
                |s| sphere_through(&pts, s),
                shell_residual(&pts),
            )?
        };
        let keep: Vec<bool> = r.iter().map(|v| v.abs() <= START_CUT * s0).collect();
        (keep.iter().filter(|k| **k).count() >= 20).then_some(keep)
    }

    fn plausible_range(&self, name: &str, params: &Params) -> Option<f64> {
        // Hard iron, field and the ellipse's axes scale with the field; the soft-iron matrix
        // (det 1) within ±0.5 of the identity, σ = q/r within ±0.5, θ anywhere in ±90°.
        let f = params.field.filter(|f| f.is_finite() && *f > 0.0)?;
        let field = name.split(['.', '[']).next().unwrap_or(name);
        match (field, name) {
            (_, "soft_iron_2d.theta_deg") => Some(90.0),
            (_, "soft_iron_2d.sigma") => Some(0.5),
            ("soft_iron", _) => Some(0.5),
            ("hard_iron" | "field" | "soft_iron_2d", _) => Some(f),
            _ => None,
        }
    }

    /// Tilt: the in-plane residual of the current fit against the out-of-plane component.
    fn evidence(&self, fitted: &Fitted, e: Effect) -> Option<Result<String, String>> {
        if e != Effect::Tilt {
            return None;
        }
        let (corr, k, n, sd) = self.out_of_plane_correlation(fitted)?;
        let ax = ["x", "y", "z"][k];
        let text = format!(
            "the in-plane residual {} the out-of-plane component m{ax} (correlation {corr:+.3} \
             over {n} samples; m{ax} varies by {sd:.2} {} s.d.)",
            if corr.abs() >= TILT_MIN_CORRELATION {
                "follows"
            } else {
                "does not follow"
            },
            self.unit
        );
        Some(if corr.abs() >= TILT_MIN_CORRELATION {
            Ok(text)
        } else {
            Err(text)
        })
    }
}

/// Mean of a set of vectors (helper for reports).
pub fn centroid(m: &[Vector3<f64>]) -> Vector3<f64> {
    Vector3::new(
        mean(&m.iter().map(|v| v.x).collect::<Vec<_>>()),
        mean(&m.iter().map(|v| v.y).collect::<Vec<_>>()),
        mean(&m.iter().map(|v| v.z).collect::<Vec<_>>()),
    )
}
