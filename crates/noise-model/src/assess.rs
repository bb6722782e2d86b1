//! Model against measurement: normalised residuals, failing τ ranges and the adequacy verdict.
//!
//! Residual (for display): r = (σ̂ − σ_model) / h, where h is the half-width of the measurement's
//! 68.3 % confidence interval on the side of the model (σ̂ − lo if the model is below, hi − σ̂ if
//! above). |r| ≤ 1 ⇔ the model lies inside the interval.
//!
//! Verdict. Each point gets an exact z-score, z = Φ⁻¹(P(χ²_ν ≤ ν σ̂²/σ²_model)), with ν the
//! point's EDF under the model (from the covariance of the estimates, [`crate::cov`]); the
//! points' correlation ρ (same source) gives the statistic T = zᵀ ρ⁻¹ z, which is χ² with n − p
//! degrees of freedom for a complete model (z is the Gaussian-copula transform of the estimates,
//! so the skewed χ² shape of the long-τ points is respected). The model is inadequate when
//! 1. the global test fails: P(χ²_{n−p} ≥ T) < α/2; or
//! 2. a local failure: some point has |z| beyond the Bonferroni-corrected two-sided normal
//!    quantile for a family-wise rate α/2 over all points.
//!
//! The default α is [`ALPHA`]; a Monte Carlo test checks the false-alarm rate against it on
//! short and day-long records. When only points are known (diagonal weighting), the EDFs are the
//! points' own and T = Σz²/[`CORRELATION_INFLATION`], an allowance for the unmodelled correlation.
use crate::cov::correlation_factor;
use crate::fit::{Fit, Weighting};
pub use crate::zscore::{correlated_chi2, z_score, CORRELATION_INFLATION};
use allan::confidence::{chi2_sf, norm_ppf as normal_quantile};
use nalgebra::{DMatrix, DVector};

/// Level of the verdict's global test (the local test runs at a tenth of it).
pub const ALPHA: f64 = 1e-3;
/// Global false-alarm probability of the χ² test at the default α.
pub const P_GLOBAL: f64 = ALPHA;
/// Family-wise false-alarm probability of the per-point test at the default α.
pub const P_LOCAL: f64 = ALPHA / 10.0;

/// A contiguous range of τ where the model is outside the measurement's 68.3 % interval.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TauRange {
    pub lo: f64,
    pub hi: f64,
    /// Index of the first and last point of the range.
    pub first: usize,
    pub last: usize,
    /// +1 when the measurement is above the model, −1 below.
    pub sign: i32,
    /// Largest |r| in the range.
    pub worst: f64,
    /// Largest |z| in the range.
    pub worst_z: f64,
}

/// The assessment of a fit.
#[derive(Debug, Clone, PartialEq)]
pub struct Assessment {
    /// Normalised residuals, one per point.
    pub residuals: Vec<f64>,
    /// Runs of points with |r| > 1 (outside the 68.3 % interval), in τ order.
    pub outside: Vec<TauRange>,
    /// Runs that contain a significant point (|z| > `threshold`), which make the verdict fail.
    pub failing: Vec<TauRange>,
    /// Exact z-scores, one per point (see module docs).
    pub z: Vec<f64>,
    /// The per-point significance threshold on |z|.
    pub threshold: f64,
    /// The statistic T = zᵀρ⁻¹z (χ²_{n−p} for a complete model).
    pub sum_z2: f64,
    /// p-value of the global χ² test.
    pub p_value: f64,
    /// RMS of ln(σ̂/σ_model) — the "log-residual" of the step report.
    pub rms_log_residual: f64,
    pub adequate: bool,
}

impl Assessment {
    /// The largest |z| of the points (NaN if one is NaN: not a number that passes).
    pub fn largest_z(&self) -> f64 {
        self.z.iter().fold(0.0, |m: f64, z| {
            if m.is_nan() || z.is_nan() {
                f64::NAN
            } else {
                m.max(z.abs())
            }
        })
    }
}

/// Where one point of an assessment stands, worst first.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Standing {
    /// Inside a failing run.
    Failing,
    /// Outside its 68.3 % interval (|r| > 1) but in no failing run.
    Outside,
    /// Within its interval.
    Fine,
}

impl Assessment {
    /// The standing of point `i`.
    pub fn standing(&self, i: usize) -> Standing {
        if self.failing.iter().any(|r| i >= r.first && i <= r.last) {
            Standing::Failing
        } else if self.residuals[i].abs() > 1.0 {
            Standing::Outside
        } else {
            Standing::Fine
        }
    }
}

/// Normalised residual of one point (see module docs).
pub fn residual(dev: f64, lo: f64, hi: f64, model_dev: f64) -> f64 {
    let diff = dev - model_dev;
    let half = if diff >= 0.0 { dev - lo } else { hi - dev };
    if half > 0.0 {
        diff / half
    } else if diff == 0.0 {
        0.0
    } else {
        diff.signum() * f64::INFINITY
    }
}

/// −2 log-likelihood of the points under the fit's model: χ²_ν/ν marginals (scaled by the model
/// variance) joined by a Gaussian copula with the estimates' correlation ρ,
/// −2ℓ = Σ_j [−2 ln f_{χ²ν_j}(x_j) − 2 ln ν_j + 2 ln σ²_j] + zᵀ(ρ⁻¹ − I)z + ln det ρ,
/// x_j = ν_j σ̂²_j/σ²_j. Unlike T it charges a model for the variance it predicts: a model that
/// explains a misfit away by predicting a huge scatter (a large random walk at τ where the data
/// fall) pays in ln σ² and ln det. Differences of −2ℓ between nested models are the
/// likelihood-ratio statistics of the lab's candidate tests.
pub fn neg2_loglik(fit: &Fit) -> f64 {
    let (z, _) = statistic(fit);
    let edf: Vec<f64> = match fit.weighting {
        Weighting::Model => fit.model_edf.clone(),
        Weighting::Diagonal => fit.points.iter().map(|p| p.edf).collect(),
    };
    let mut d = 0.0;
    for ((p, &m), &nu) in fit.points.iter().zip(&fit.model_avar).zip(&edf) {
        let m = m.max(1e-300);
        let x = nu * p.dev * p.dev / m;
        let ln_f = (nu / 2.0 - 1.0) * x.ln()
            - x / 2.0
            - nu / 2.0 * std::f64::consts::LN_2
            - libm::lgamma(nu / 2.0);
        d += -2.0 * ln_f - 2.0 * nu.ln() + 2.0 * m.ln();
    }
    if fit.weighting == Weighting::Model {
        if let Some(l) = correlation_factor(&fit.point_cov).1 {
            let ln_det: f64 = (0..z.len()).map(|j| 2.0 * l[(j, j)].ln()).sum();
            let zv = DVector::from_column_slice(&z);
            let quad = l
                .solve_lower_triangular(&zv)
                .map_or(0.0, |w| w.norm_squared());
            d += quad - zv.norm_squared() + ln_det;
        }
    }
    d
}

/// The `q` quantile of max_j |z_j| for z ~ N(0, ρ), ρ the correlation of the covariance `cov`:
/// the per-point threshold that gives the local test a family-wise level 1 − q with the points'
/// correlation taken into account (Bonferroni ignores it and is conservative by a factor of ~2
/// for octave Allan points). Monte Carlo with a fixed stream of 20 000 draws (xorshift, Box–Muller),
/// so the verdict is reproducible.
pub fn max_z_quantile(cov: &DMatrix<f64>, q: f64) -> f64 {
    let n = cov.nrows();
    let Some(l) = correlation_factor(cov).1 else {
        return f64::INFINITY;
    };
    const DRAWS: usize = 20_000;
    let mut state: u64 = 0x9E37_79B9_7F4A_7C15;
    let mut uniform = || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        ((state >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    };
    let mut e = vec![0.0; n];
    let mut maxima: Vec<f64> = Vec::with_capacity(DRAWS);
    for _ in 0..DRAWS {
        for k in (0..n).step_by(2) {
            let (u1, u2) = (uniform(), uniform());
            let r = (-2.0 * u1.ln()).sqrt();
            let th = 2.0 * std::f64::consts::PI * u2;
            e[k] = r * th.cos();
            if k + 1 < n {
                e[k + 1] = r * th.sin();
            }
        }
        let mut m: f64 = 0.0;
        for a in 0..n {
            let mut v = 0.0;
            for b in 0..=a {
                v += l[(a, b)] * e[b];
            }
            m = m.max(v.abs());
        }
        maxima.push(m);
    }
    let k = ((q * DRAWS as f64).ceil() as usize).clamp(1, DRAWS) - 1;
    *maxima.select_nth_unstable_by(k, f64::total_cmp).1
}

/// z-scores of a fit's points and the statistic T (see module docs): [`Fit::statistic`].
pub fn statistic(fit: &Fit) -> (Vec<f64>, f64) {
    fit.statistic()
}

/// Assess a fit at the default level [`ALPHA`].
pub fn assess(fit: &Fit) -> Assessment {
    assess_at(fit, ALPHA)
}

/// Assess a fit at level `alpha` (the global test at α, the local one at α/10).
pub fn assess_at(fit: &Fit, alpha: f64) -> Assessment {
    let n = fit.points.len();
    let residuals: Vec<f64> = fit
        .points
        .iter()
        .zip(&fit.model_avar)
        .map(|(p, &m)| residual(p.dev, p.lo, p.hi, m.max(0.0).sqrt()))
        .collect();
    let (z, sum_z2) = statistic(fit);
    let local = alpha / 10.0;
    let bonferroni = normal_quantile(1.0 - local / (2.0 * n as f64));
    let threshold = match fit.weighting {
        Weighting::Model => max_z_quantile(&fit.point_cov, 1.0 - local).min(bonferroni),
        Weighting::Diagonal => bonferroni,
    };
    let mut outside: Vec<TauRange> = Vec::new();
    let mut j = 0;
    while j < n {
        if residuals[j].abs() > 1.0 {
            let sign = if residuals[j] > 0.0 { 1 } else { -1 };
            let first = j;
            let (mut worst, mut worst_z): (f64, f64) = (0.0, 0.0);
            while j < n && residuals[j].abs() > 1.0 && (residuals[j] > 0.0) == (sign > 0) {
                worst = worst.max(residuals[j].abs());
                worst_z = worst_z.max(z[j].abs());
                j += 1;
            }
            outside.push(TauRange {
                lo: fit.points[first].tau,
                hi: fit.points[j - 1].tau,
                first,
                last: j - 1,
                sign,
                worst,
                worst_z,
            });
        } else {
            j += 1;
        }
    }
    // A significant point that the (model-free) interval does not flag still fails: its own run.
    for (i, &zi) in z.iter().enumerate() {
        if zi.abs() > threshold && !outside.iter().any(|r| r.first <= i && i <= r.last) {
            outside.push(TauRange {
                lo: fit.points[i].tau,
                hi: fit.points[i].tau,
                first: i,
                last: i,
                sign: if zi > 0.0 { 1 } else { -1 },
                worst: residuals[i].abs(),
                worst_z: zi.abs(),
            });
        }
    }
    outside.sort_by_key(|r| r.first);
    let failing: Vec<TauRange> = outside
        .iter()
        .copied()
        .filter(|r| r.worst_z > threshold)
        .collect();
    let p_value = chi2_sf(sum_z2, fit.dof);
    let rms_log_residual = (fit
        .points
        .iter()
        .zip(&fit.model_avar)
        .map(|(p, &m)| (p.dev.ln() - 0.5 * m.max(1e-300).ln()).powi(2))
        .sum::<f64>()
        / n.max(1) as f64)
        .sqrt();
    let adequate = failing.is_empty() && p_value >= alpha;
    Assessment {
        residuals,
        outside,
        failing,
        z,
        threshold,
        sum_z2,
        p_value,
        rms_log_residual,
        adequate,
    }
}
