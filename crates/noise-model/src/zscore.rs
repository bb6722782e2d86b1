//! The z-score of a measured deviation against a model's, and the statistic T the points' z-scores
//! add up to (the verdict's global test, [`crate::assess`]): T = zᵀ ρ⁻¹ z with the estimates'
//! correlation ρ, or Σz²/[`CORRELATION_INFLATION`] when only the points are known.
use crate::cov::correlation_factor;
use allan::confidence::{chi2_cdf, chi2_sf, norm_ppf as normal_quantile};
use nalgebra::{DMatrix, DVector};

/// Points-only fits: the χ² of correlated octave-spaced OADEV points is larger than that of
/// independent points by about this factor under the null; Σz² is divided by it.
pub const CORRELATION_INFLATION: f64 = 1.5;

/// Exact z-score of a measured deviation with `edf` degrees of freedom against a model deviation.
pub fn z_score(dev: f64, edf: f64, model_dev: f64) -> f64 {
    if !(model_dev > 0.0) {
        // a model with no variance where the data have some: as far off as a z-score is taken
        return if dev > 0.0 { 38.0 } else { 0.0 };
    }
    if !(edf > 0.0 && edf.is_finite()) {
        // no degrees of freedom about the model (a model with no variance at this τ, its EDF
        // 2m²/var → 0): the point is as far off as a z-score is taken, on its side
        return if dev > model_dev {
            38.0
        } else if dev < model_dev {
            -38.0
        } else {
            0.0
        };
    }
    let x = edf * (dev / model_dev).powi(2);
    if edf > 2e4 {
        // Wilson–Hilferty: (χ²_ν/ν)^{1/3} is normal with mean 1 − 2/(9ν), variance 2/(9ν)
        // (relative error of the quantile below 1e-4 at this ν, where the series for the
        // incomplete gamma function would need ~√ν terms)
        let v = 2.0 / (9.0 * edf);
        return (((x / edf).cbrt() - (1.0 - v)) / v.sqrt()).clamp(-38.0, 38.0);
    }
    let c = chi2_cdf(x, edf);
    let z = if c <= 0.5 {
        normal_quantile(c)
    } else {
        -normal_quantile(chi2_sf(x, edf))
    };
    z.clamp(-38.0, 38.0)
}

/// The generalised statistic zᵀ ρ⁻¹ z for z-scores with correlation matrix ρ (from a covariance).
pub fn correlated_chi2(z: &[f64], cov: &DMatrix<f64>) -> f64 {
    let zv = DVector::from_column_slice(z);
    match correlation_factor(cov).1 {
        Some(l) => l
            .solve_lower_triangular(&zv)
            .map_or(f64::NAN, |w| w.norm_squared()),
        None => zv.norm_squared(),
    }
}

/// The z-scores of deviations `dev` with `edf` degrees of freedom against the model variances
/// `model_avar`, and T: correlated through `cov` when given, else Σz²/[`CORRELATION_INFLATION`].
pub fn t_statistic(
    dev: impl Iterator<Item = f64>,
    edf: &[f64],
    model_avar: &[f64],
    cov: Option<&DMatrix<f64>>,
) -> (Vec<f64>, f64) {
    let z: Vec<f64> = dev
        .zip(model_avar)
        .zip(edf)
        .map(|((d, &m), &nu)| z_score(d, nu, m.max(0.0).sqrt()))
        .collect();
    let t = match cov {
        Some(c) => correlated_chi2(&z, c),
        None => z.iter().map(|v| v * v).sum::<f64>() / CORRELATION_INFLATION,
    };
    (z, t)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_point_without_degrees_of_freedom_is_finite_and_on_its_side() {
        // a model with no variance at a τ has EDF 2m²/var = 0 there: the z-score must still be
        // a number (NaN made the verdict's T NaN, and the whole fit fail), as far off as taken
        assert_eq!(z_score(1.0, 0.0, 0.5), 38.0);
        assert_eq!(z_score(0.2, 0.0, 0.5), -38.0);
        assert_eq!(z_score(1.0, f64::NAN, 0.5), 38.0);
        assert_eq!(z_score(1.0, 10.0, 0.0), 38.0);
        // far out in the upper tail (a step the model lacks, 70× its variance at 22 EDF: the
        // survival function is subnormal, ~1e-309, where Φ⁻¹ once returned NaN): every
        // z-score is finite and rises with the ratio, on a dense grid through that band
        for nu in [2.5, 5.0, 9.8, 21.778, 50.0, 100.0] {
            let mut last = f64::NEG_INFINITY;
            for i in 0..400 {
                let ratio = 10f64.powf(1.0 + 3.0 * i as f64 / 399.0);
                let z = z_score(ratio.sqrt(), nu, 1.0);
                assert!(
                    z.is_finite() && z >= last,
                    "z({ratio}, {nu}) = {z} after {last}"
                );
                last = z;
            }
        }
        assert!(z_score((70.4f64).sqrt(), 21.778, 1.0) > 30.0);
        let z = z_score(1.0, 10.0, 1.0);
        assert!(z.is_finite() && z.abs() < 1.0, "{z}");
    }
}
