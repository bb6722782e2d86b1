//! Numerical tools shared by the fits: Levenberg–Marquardt least squares, robust statistics and
//! the F / χ² tail probabilities of the diagnosis.
use crate::error::CalError;
use nalgebra::{DMatrix, DVector};

/// Result of a nonlinear least-squares fit.
#[derive(Debug, Clone)]
pub struct LmFit {
    /// Parameters at the minimum.
    pub x: DVector<f64>,
    /// Residuals at the minimum.
    pub r: DVector<f64>,
    /// Residual sum of squares.
    pub rss: f64,
    /// Iterations used.
    pub iterations: usize,
    /// Jacobian of the residuals at `x` (central differences), for the parameters' covariance.
    pub jacobian: DMatrix<f64>,
    /// None when the iteration converged; else why `x` is only the best point reached (the
    /// iteration cap, with how fast the sum of squares was still falling).
    pub not_converged: Option<String>,
}

/// Jacobian of `f` at `x` by central differences.
fn jacobian<F>(f: &F, x: &DVector<f64>, m: usize) -> DMatrix<f64>
where
    F: Fn(&DVector<f64>) -> DVector<f64>,
{
    let p = x.len();
    let mut j = DMatrix::<f64>::zeros(m, p);
    for k in 0..p {
        let h = 1e-6 * x[k].abs().max(1e-3);
        let mut xp = x.clone();
        xp[k] += h;
        let mut xm = x.clone();
        xm[k] -= h;
        let d = (f(&xp) - f(&xm)) / (2.0 * h);
        j.set_column(k, &d);
    }
    j
}

/// A fit with no free parameter: the residuals of `f` at the empty vector.
pub fn no_parameters<F>(f: F) -> LmFit
where
    F: Fn(&DVector<f64>) -> DVector<f64>,
{
    let r = f(&DVector::zeros(0));
    LmFit {
        rss: r.norm_squared(),
        jacobian: DMatrix::zeros(r.len(), 0),
        x: DVector::zeros(0),
        r,
        iterations: 0,
        not_converged: None,
    }
}

/// The fit of a model: [`levenberg_marquardt`] from `x0`, or [`no_parameters`] when the model
/// has no free parameter (`x0` empty). `what` names the fit in errors; it is built only when
/// there is an iteration to run.
pub fn fit_model<F>(
    x0: Vec<f64>,
    f: F,
    max_iter: usize,
    what: impl FnOnce() -> String,
) -> Result<LmFit, CalError>
where
    F: Fn(&DVector<f64>) -> DVector<f64>,
{
    if x0.is_empty() {
        Ok(no_parameters(f))
    } else {
        levenberg_marquardt(DVector::from_vec(x0), f, max_iter, &what())
    }
}

/// Minimise Σ r_i(x)² by Levenberg–Marquardt (Marquardt 1963, with Nielsen's damping update)
/// with a central-difference Jacobian, in at most `max_iter` iterations of at most 30 damping
/// trials each. `f` must return the same number of residuals for every x; non-finite residuals
/// make a step be rejected. The one error, naming the routine and `what`: residuals not finite
/// at the start. The iteration cap reached while the sum of squares was still falling by more than
/// 1e-9 of itself per iteration is not an error: the best point reached is returned with
/// [`LmFit::not_converged`] saying so, for the caller to report (a fit of valid data never fails
/// for want of iterations).
pub fn levenberg_marquardt<F>(
    x0: DVector<f64>,
    f: F,
    max_iter: usize,
    what: &str,
) -> Result<LmFit, CalError>
where
    F: Fn(&DVector<f64>) -> DVector<f64>,
{
    let mut x = x0;
    let mut r = f(&x);
    let mut rss = r.norm_squared();
    if !rss.is_finite() {
        return Err(CalError::Fit(format!(
            "Levenberg–Marquardt ({what}): the residuals at the starting point are not finite"
        )));
    }
    let p = x.len();
    let mut lambda = 1e-3;
    let mut nu = 2.0;
    let mut it = 0;
    let mut last_rel = f64::INFINITY;
    let mut converged = false;
    while it < max_iter {
        it += 1;
        let j = jacobian(&f, &x, r.len());
        let jtj = j.transpose() * &j;
        let g = j.transpose() * &r;
        if g.amax() < 1e-14 * (1.0 + rss) {
            converged = true;
            break;
        }
        let mut accepted = false;
        for _ in 0..30 {
            let mut a = jtj.clone();
            for k in 0..p {
                a[(k, k)] += lambda * jtj[(k, k)].max(1e-12);
            }
            let Some(chol) = a.cholesky() else {
                lambda *= nu;
                nu *= 2.0;
                continue;
            };
            let step = chol.solve(&(-&g));
            let xn = &x + &step;
            let rn = f(&xn);
            let rssn = rn.norm_squared();
            if rssn.is_finite() && rssn < rss {
                let rel = (rss - rssn) / rss.max(1e-300);
                x = xn;
                r = rn;
                rss = rssn;
                lambda = (lambda / 3.0).max(1e-12);
                nu = 2.0;
                accepted = true;
                last_rel = rel;
                if rel < 1e-12 || step.norm() < 1e-12 * (1.0 + x.norm()) {
                    converged = true;
                }
                break;
            }
            lambda *= nu;
            nu *= 2.0;
        }
        // No step lowers the sum of squares: a minimum to working precision.
        if !accepted || converged {
            converged = true;
            break;
        }
    }
    let not_converged = (!converged && last_rel > 1e-9).then(|| {
        format!(
            "Levenberg–Marquardt ({what}) did not converge in {max_iter} iterations (the sum of \
             squares was still falling by {last_rel:.1e} of itself per iteration): the parameters \
             are the best point reached"
        )
    });
    let jacobian = jacobian(&f, &x, r.len());
    Ok(LmFit {
        x,
        r,
        rss,
        iterations: it,
        jacobian,
        not_converged,
    })
}

/// Covariance of least-squares parameters, `s²·(JᵀJ)⁻¹` with `s² = rss/dof`; `None` when the
/// problem has no residual degree of freedom or `JᵀJ` is singular.
pub fn covariance(j: &DMatrix<f64>, rss: f64, dof: f64) -> Option<DMatrix<f64>> {
    if !(dof >= 1.0) || j.ncols() == 0 {
        return None;
    }
    let jtj = j.transpose() * j;
    let inv = jtj.try_inverse()?;
    let cov = inv * (rss / dof);
    cov.iter().all(|v| v.is_finite()).then_some(cov)
}

/// Standard deviations of `g(x)` for `x` with covariance `cov` (first-order propagation with a
/// central-difference Jacobian of `g`).
pub fn propagate<G>(g: G, x: &DVector<f64>, cov: &DMatrix<f64>) -> Vec<f64>
where
    G: Fn(&DVector<f64>) -> Vec<f64>,
{
    let y = g(x);
    let gm = |v: &DVector<f64>| DVector::from_vec(g(v));
    let j = jacobian(&gm, x, y.len());
    let c = &j * cov * j.transpose();
    (0..y.len()).map(|i| c[(i, i)].max(0.0).sqrt()).collect()
}

/// Symmetric eigen-decomposition with an iteration cap (nalgebra's default has none: non-finite
/// input would spin), an error naming `what` when it does not converge.
pub fn sym_eigen<D>(
    m: nalgebra::OMatrix<f64, D, D>,
    what: &str,
) -> Result<nalgebra::SymmetricEigen<f64, D>, CalError>
where
    D: nalgebra::Dim + nalgebra::DimSub<nalgebra::U1>,
    nalgebra::DefaultAllocator: nalgebra::allocator::Allocator<D, D>
        + nalgebra::allocator::Allocator<nalgebra::DimDiff<D, nalgebra::U1>>
        + nalgebra::allocator::Allocator<D>,
{
    if m.iter().any(|v| !v.is_finite()) {
        return Err(CalError::Fit(format!(
            "eigen-decomposition ({what}): the matrix is not finite"
        )));
    }
    nalgebra::SymmetricEigen::try_new(m, f64::EPSILON, 1000).ok_or_else(|| {
        CalError::Fit(format!(
            "eigen-decomposition ({what}) did not converge in 1000 iterations"
        ))
    })
}

/// A small deterministic generator (Marsaglia's xorshift64*) for the robust start's subsets: its
/// key comes from the data ([`data_key`]), so the same data always give the same fit.
#[derive(Debug, Clone)]
pub struct XorShift(u64);

impl XorShift {
    /// A generator from `key` (any value; 0 is mapped to a fixed non-zero state).
    pub fn new(key: u64) -> XorShift {
        XorShift(if key == 0 { 0x9e37_79b9_7f4a_7c15 } else { key })
    }
    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        let mut x = self.0;
        x ^= x >> 12;
        x ^= x << 25;
        x ^= x >> 27;
        self.0 = x;
        x.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }
    /// A uniform index below `n` (n > 0).
    pub fn below(&mut self, n: usize) -> usize {
        (self.next_u64() % n as u64) as usize
    }
}

/// A key for [`XorShift`] from the bits of a data set (FNV-1a over every value).
pub fn data_key(values: impl Iterator<Item = f64>) -> u64 {
    values.fold(0xcbf2_9ce4_8422_2325, |h, v| {
        (h ^ v.to_bits()).wrapping_mul(0x0100_0000_01b3)
    })
}

/// The least-median-of-squares fit of Rousseeuw (1984, "Least median of squares regression",
/// JASA 79) over minimal subsets drawn as in RANSAC (Fischler & Bolles 1981): `trials` random
/// subsets of `k` of the `n` items are fitted exactly by `fit` (None: a degenerate subset), each
/// scored by the median of `resid²` over at most 1000 items spread evenly through the data; the
/// best is returned with its robust scale over all items,
/// `s₀ = 1.4826·(1 + 5/(n − k))·√med rᵢ²` (Rousseeuw & Leroy 1987, eq. 5.1.7), and the
/// residuals of every item. None when every subset was degenerate.
pub fn lmeds<P, F, R>(
    n: usize,
    k: usize,
    trials: usize,
    key: u64,
    fit: F,
    resid: R,
) -> Option<(P, f64, Vec<f64>)>
where
    F: Fn(&[usize]) -> Option<P>,
    R: Fn(&P, usize) -> f64,
{
    if n <= k || k == 0 {
        return None;
    }
    let mut rng = XorShift::new(key);
    let stride = n.div_ceil(1000);
    let probe: Vec<usize> = (0..n).step_by(stride).collect();
    let mut best: Option<(P, f64)> = None;
    let mut subset = Vec::with_capacity(k);
    for _ in 0..trials {
        subset.clear();
        while subset.len() < k {
            let i = rng.below(n);
            if !subset.contains(&i) {
                subset.push(i);
            }
        }
        let Some(cand) = fit(&subset) else { continue };
        let r2: Vec<f64> = probe.iter().map(|&i| resid(&cand, i).powi(2)).collect();
        if r2.iter().any(|v| !v.is_finite()) {
            continue;
        }
        let med = median(&r2);
        if best.as_ref().is_none_or(|(_, b)| med < *b) {
            best = Some((cand, med));
        }
    }
    let (cand, _) = best?;
    let r: Vec<f64> = (0..n).map(|i| resid(&cand, i)).collect();
    let r2: Vec<f64> = r.iter().map(|v| v * v).collect();
    let s0 = 1.4826 * (1.0 + 5.0 / (n - k) as f64) * median(&r2).sqrt();
    Some((cand, s0, r))
}

/// Robust σ of a sample: 1.4826 × the median absolute deviation from the median (NaN if
/// empty).
pub fn mad_sigma(v: &[f64]) -> f64 {
    let m = median(v);
    let dev: Vec<f64> = v.iter().map(|x| (x - m).abs()).collect();
    1.4826 * median(&dev)
}

/// Linear least squares `a·x ≈ b` by SVD, refusing non-finite input and rank-deficient
/// systems (data that do not determine the fit) with an error naming `what`. The SVD runs
/// with an iteration limit, so no input can make it spin.
pub fn lstsq(a: DMatrix<f64>, b: &DVector<f64>, what: &str) -> Result<DVector<f64>, CalError> {
    if a.iter().chain(b.iter()).any(|v| !v.is_finite()) {
        return Err(CalError::Fit(format!(
            "{what}: the data contain non-finite values"
        )));
    }
    let svd = nalgebra::SVD::try_new(a, true, true, f64::EPSILON, 1000)
        .ok_or_else(|| CalError::Fit(format!("{what}: the SVD did not converge")))?;
    let smax = svd.singular_values.max();
    let smin = svd.singular_values.min();
    if !(smax > 0.0) || smin < 1e-10 * smax {
        return Err(CalError::Fit(format!(
            "{what}: the data do not determine the fit (rank-deficient design: the sensor did \
             not go through enough different orientations)"
        )));
    }
    svd.solve(b, 0.0)
        .map_err(|e| CalError::Fit(format!("{what}: {e}")))
}

/// Median of a slice (NaN-free input; empty → NaN).
pub fn median(v: &[f64]) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    let mut s = v.to_vec();
    s.sort_by(|a, b| a.total_cmp(b));
    let n = s.len();
    if n % 2 == 1 {
        s[n / 2]
    } else {
        0.5 * (s[n / 2 - 1] + s[n / 2])
    }
}

/// Degrees of freedom per point of [`sigma_second_diff`]'s σ² as a variance estimate: for n
/// points of white noise σ̂²/σ² scatters like χ²_ν/ν with ν ≈ n/4, not n. The MAD keeps 37 % of
/// the sample variance's efficiency, and consecutive second differences are correlated (−2/3 at
/// lag 1, 1/6 at lag 2). Monte Carlo of the estimator: ν/(n − 2) = 0.24–0.27 for n = 50 to 20,000.
pub const SECOND_DIFF_DOF_PER_POINT: f64 = 0.25;

/// ν of [`sigma_second_diff`] over `n` points ([`SECOND_DIFF_DOF_PER_POINT`]), at least 1.
pub fn second_diff_dof(n: usize) -> f64 {
    (SECOND_DIFF_DOF_PER_POINT * (n as f64 - 2.0)).max(1.0)
}

/// Robust standard deviation of white noise from second differences:
/// σ = 1.4826 · MAD(x_{k+1} − 2x_k + x_{k−1}) / √6 (var of a second difference of white noise is
/// 6σ²; the median absolute deviation ignores the few samples where the motion dominates).
pub fn sigma_second_diff(x: &[f64]) -> f64 {
    if x.len() < 3 {
        return f64::NAN;
    }
    let d: Vec<f64> = x.windows(3).map(|w| w[2] - 2.0 * w[1] + w[0]).collect();
    let m = median(&d);
    let dev: Vec<f64> = d.iter().map(|v| (v - m).abs()).collect();
    1.4826 * median(&dev) / 6f64.sqrt()
}

/// Root mean square.
pub fn rms(v: &[f64]) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt()
}

/// Mean.
pub fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len() as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lm_fits_exponential() {
        // y = 2·exp(−0.5 t) sampled exactly: LM must find (2, 0.5) from (1, 1).
        let t: Vec<f64> = (0..20).map(|i| i as f64 * 0.3).collect();
        let y: Vec<f64> = t.iter().map(|t| 2.0 * (-0.5 * t).exp()).collect();
        let fit = levenberg_marquardt(
            DVector::from_vec(vec![1.0, 1.0]),
            |x| {
                DVector::from_iterator(
                    t.len(),
                    t.iter().zip(&y).map(|(t, y)| x[0] * (-x[1] * t).exp() - y),
                )
            },
            100,
            "test exponential",
        )
        .unwrap();
        assert!(
            (fit.x[0] - 2.0).abs() < 1e-8 && (fit.x[1] - 0.5).abs() < 1e-8,
            "{:?}",
            fit.x
        );
    }

    #[test]
    fn lm_cap_is_reported_and_bad_start_is_an_error_naming_the_fit() {
        // Rosenbrock's valley from far away: 2 iterations cannot reach the minimum; the best
        // point is returned (lower than the start) and says it did not converge.
        let rosen =
            |x: &DVector<f64>| DVector::from_vec(vec![10.0 * (x[1] - x[0] * x[0]), 1.0 - x[0]]);
        let start = rosen(&DVector::from_vec(vec![-1.2, 1.0])).norm_squared();
        let fit =
            levenberg_marquardt(DVector::from_vec(vec![-1.2, 1.0]), rosen, 2, "valley").unwrap();
        let e = fit.not_converged.as_deref().unwrap_or("");
        assert!(
            e.contains("Levenberg–Marquardt (valley) did not converge in 2") && fit.rss < start,
            "{e}"
        );
        let fit =
            levenberg_marquardt(DVector::from_vec(vec![-1.2, 1.0]), rosen, 200, "valley").unwrap();
        assert!(fit.not_converged.is_none());
        assert!((fit.x[0] - 1.0).abs() < 1e-8 && (fit.x[1] - 1.0).abs() < 1e-8);
        let e = levenberg_marquardt(
            DVector::from_vec(vec![1e300]),
            |x| DVector::from_vec(vec![x[0] * x[0]]),
            10,
            "overflow",
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("(overflow)") && e.contains("not finite"), "{e}");
    }

    #[test]
    fn covariance_of_a_straight_line() {
        // y = a + b t with unit noise: var(b) = s²/Σ(t − t̄)² for the design below.
        let t = [0.0, 1.0, 2.0, 3.0, 4.0];
        let y = [0.1, 0.9, 2.2, 2.8, 4.1];
        let fit = levenberg_marquardt(
            DVector::from_vec(vec![0.0, 0.0]),
            |x| DVector::from_iterator(5, t.iter().zip(&y).map(|(t, y)| x[0] + x[1] * t - y)),
            50,
            "line",
        )
        .unwrap();
        let cov = covariance(&fit.jacobian, fit.rss, 3.0).unwrap();
        let sxx = 10.0;
        assert!((cov[(1, 1)] - fit.rss / 3.0 / sxx).abs() < 1e-9 * cov[(1, 1)]);
        // σ of 2b by propagation is twice σ(b).
        let s = propagate(|x| vec![2.0 * x[1]], &fit.x, &cov);
        assert!((s[0] - 2.0 * cov[(1, 1)].sqrt()).abs() < 1e-6 * s[0]);
    }

    #[test]
    fn eigen_refuses_non_finite_input() {
        let m = nalgebra::Matrix3::new(1.0, f64::NAN, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0);
        assert!(sym_eigen(m, "test")
            .unwrap_err()
            .to_string()
            .contains("(test)"));
    }

    /// The scatter of σ̂² over white-noise records of a random length is that of a χ² with
    /// [`second_diff_dof`] degrees of freedom: var(σ̂²) ≈ 2σ⁴/ν. Counting every point (ν = n − 2)
    /// gives a ratio near 4.
    #[test]
    fn second_diff_sigma_scatters_as_its_stated_dof() {
        let mut state = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(1, |d| d.as_nanos() as u64);
        let key = state;
        let mut next = move || {
            state = state.wrapping_add(0x9e37_79b9_7f4a_7c15);
            let mut z = state;
            z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
            ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
        };
        let n = 100 + (next() * 900.0) as usize;
        let sigma = 0.1 + next() * 10.0;
        let draws = 1500;
        let est: Vec<f64> = (0..draws)
            .map(|_| {
                let x: Vec<f64> = (0..n)
                    .map(|_| {
                        let (u, v) = (next().max(1e-300), next());
                        sigma * (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
                    })
                    .collect();
                sigma_second_diff(&x).powi(2) / (sigma * sigma)
            })
            .collect();
        let m = mean(&est);
        let var = est.iter().map(|e| (e - m).powi(2)).sum::<f64>() / (draws - 1) as f64;
        let ratio = var * second_diff_dof(n) / 2.0;
        // 1,500 draws: the sample variance's own relative error is ≈ 4 %.
        assert!(
            (0.8..1.25).contains(&ratio),
            "n = {n}, σ = {sigma}: var(σ̂²)·ν/2 = {ratio} (mean {m}; key {key})"
        );
        assert!(
            (m - 1.0).abs() < 0.05,
            "n = {n}: mean σ̂²/σ² = {m} (key {key})"
        );
    }

    #[test]
    fn second_diff_sigma_of_white_noise_on_a_ramp() {
        // A slow ramp plus ±1 alternating "noise": the estimator must ignore the ramp.
        let x: Vec<f64> = (0..1002)
            .map(|i| 0.01 * i as f64 + if i % 2 == 0 { 1.0 } else { -1.0 })
            .collect();
        // Second difference of ±1 alternating is ±4 → 1.4826·4/√6 ≈ 2.42 (not white, but fixed).
        assert!((sigma_second_diff(&x) - 1.4826 * 4.0 / 6f64.sqrt()).abs() < 1e-9);
    }
}
