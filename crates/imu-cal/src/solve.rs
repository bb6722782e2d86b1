//! Numerical tools shared by the fits: Levenberg–Marquardt least squares, robust statistics and
//! the F / χ² tail probabilities of the diagnosis.
use crate::lab::CalError;
use nalgebra::{DMatrix, DVector};
use statrs::distribution::{ContinuousCDF, FisherSnedecor};

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
}

/// Minimise Σ r_i(x)² by Levenberg–Marquardt (Marquardt 1963, with Nielsen's damping update)
/// with a central-difference Jacobian. `f` must return the same number of residuals for every
/// x; non-finite residuals make a step be rejected.
pub fn levenberg_marquardt<F>(x0: DVector<f64>, f: F, max_iter: usize) -> LmFit
where
    F: Fn(&DVector<f64>) -> DVector<f64>,
{
    let mut x = x0;
    let mut r = f(&x);
    let mut rss = r.norm_squared();
    let p = x.len();
    let mut lambda = 1e-3;
    let mut nu = 2.0;
    let mut it = 0;
    while it < max_iter {
        it += 1;
        // Jacobian by central differences.
        let mut j = DMatrix::<f64>::zeros(r.len(), p);
        for k in 0..p {
            let h = 1e-6 * x[k].abs().max(1e-3);
            let mut xp = x.clone();
            xp[k] += h;
            let mut xm = x.clone();
            xm[k] -= h;
            let d = (f(&xp) - f(&xm)) / (2.0 * h);
            j.set_column(k, &d);
        }
        let jtj = j.transpose() * &j;
        let g = j.transpose() * &r;
        if g.amax() < 1e-14 * (1.0 + rss) {
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
                if rel < 1e-12 || step.norm() < 1e-12 * (1.0 + x.norm()) {
                    return LmFit {
                        x,
                        r,
                        rss,
                        iterations: it,
                    };
                }
                break;
            }
            lambda *= nu;
            nu *= 2.0;
        }
        if !accepted {
            break;
        }
    }
    LmFit {
        x,
        r,
        rss,
        iterations: it,
    }
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

/// Upper tail P(F > f) of the Fisher–Snedecor distribution with (d1, d2) degrees of freedom.
pub fn f_sf(f: f64, d1: f64, d2: f64) -> f64 {
    if !(f.is_finite()) || d1 <= 0.0 || d2 <= 0.0 {
        return if f.is_infinite() { 0.0 } else { 1.0 };
    }
    if f <= 0.0 {
        return 1.0;
    }
    match FisherSnedecor::new(d1, d2) {
        Ok(d) => d.sf(f),
        Err(_) => 1.0,
    }
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
        );
        assert!(
            (fit.x[0] - 2.0).abs() < 1e-8 && (fit.x[1] - 0.5).abs() < 1e-8,
            "{:?}",
            fit.x
        );
    }

    #[test]
    fn f_tail_matches_tables() {
        // F(3, 20) 0.95 quantile is 3.098 (standard tables): the upper tail there is 0.05.
        assert!((f_sf(3.098, 3.0, 20.0) - 0.05).abs() < 1e-3);
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
