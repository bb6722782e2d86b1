//! Non-negative least squares, min ‖A·x − b‖² subject to x ≥ 0, by the Lawson–Hanson active-set
//! algorithm (C. L. Lawson & R. J. Hanson, *Solving Least Squares Problems*, 1974, ch. 23).
use nalgebra::{DMatrix, DVector, SVD};

/// Iteration cap of the SVDs (nalgebra's default, 0, means "until converged", which never
/// happens on some inputs with extreme dynamic range).
const SVD_ITERATIONS: usize = 500;

/// SVD with an iteration cap; None when the input is not finite or it does not converge.
fn svd(m: DMatrix<f64>) -> Option<SVD<f64, nalgebra::Dyn, nalgebra::Dyn>> {
    if m.iter().any(|v| !v.is_finite()) {
        return None;
    }
    SVD::try_new(m, true, true, f64::EPSILON, SVD_ITERATIONS)
}

/// Moore–Penrose pseudo-inverse (relative singular-value cut 1e-12), None when the SVD fails.
pub fn pinv(m: &DMatrix<f64>) -> Option<DMatrix<f64>> {
    svd(m.clone())?.pseudo_inverse(1e-12).ok()
}

/// Least squares restricted to the columns in `set` (others are zero), via SVD (rank-safe).
fn ls_subset(a: &DMatrix<f64>, b: &DVector<f64>, set: &[usize]) -> DVector<f64> {
    let n = a.nrows();
    let mut sub = DMatrix::<f64>::zeros(n, set.len());
    for (k, &j) in set.iter().enumerate() {
        sub.set_column(k, &a.column(j));
    }
    let z = svd(sub)
        .and_then(|s| s.solve(b, 1e-12).ok())
        .unwrap_or_else(|| DVector::zeros(set.len()));
    let mut x = DVector::zeros(a.ncols());
    for (k, &j) in set.iter().enumerate() {
        x[j] = z[k];
    }
    x
}

/// Solve min ‖A·x − b‖², x ≥ 0. Columns should be scaled to comparable norms by the caller.
pub fn nnls(a: &DMatrix<f64>, b: &DVector<f64>) -> DVector<f64> {
    let p = a.ncols();
    if a.iter().chain(b.iter()).any(|v| !v.is_finite()) {
        return DVector::zeros(p);
    }
    let mut x = DVector::<f64>::zeros(p);
    let mut passive: Vec<usize> = Vec::new();
    let scale = a.norm() * b.norm();
    let tol = 1e-12 * scale.max(1e-300);
    for _outer in 0..(3 * p + 10) {
        let w = a.transpose() * (b - a * &x);
        let cand = (0..p)
            .filter(|j| !passive.contains(j))
            .max_by(|&i, &j| w[i].total_cmp(&w[j]));
        let Some(t) = cand else { break };
        if w[t] <= tol {
            break;
        }
        passive.push(t);
        for _inner in 0..(3 * p + 10) {
            let z = ls_subset(a, b, &passive);
            if passive.iter().all(|&j| z[j] > 0.0) {
                x = z;
                break;
            }
            let mut alpha = f64::INFINITY;
            for &j in &passive {
                if z[j] <= 0.0 {
                    let d = x[j] - z[j];
                    if d > 0.0 {
                        alpha = alpha.min(x[j] / d);
                    }
                }
            }
            if !alpha.is_finite() {
                alpha = 0.0;
            }
            x = &x + (z - &x) * alpha;
            passive.retain(|&j| x[j] > 1e-15 * x.amax().max(1e-300));
            for j in 0..p {
                if !passive.contains(&j) {
                    x[j] = 0.0;
                }
            }
            if passive.is_empty() {
                break;
            }
        }
    }
    x
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unconstrained_solution_when_positive() {
        let a = DMatrix::from_row_slice(3, 2, &[1.0, 0.0, 0.0, 1.0, 1.0, 1.0]);
        let b = DVector::from_vec(vec![1.0, 2.0, 3.0]);
        let x = nnls(&a, &b);
        assert!((x[0] - 1.0).abs() < 1e-12 && (x[1] - 2.0).abs() < 1e-12);
    }

    #[test]
    fn negative_component_clamped() {
        // Unconstrained LS gives x1 < 0; NNLS must put x1 = 0 and refit x0.
        let a = DMatrix::from_row_slice(3, 2, &[1.0, 1.0, 1.0, 2.0, 1.0, 3.0]);
        let b = DVector::from_vec(vec![3.0, 2.0, 1.0]);
        let x = nnls(&a, &b);
        assert_eq!(x[1], 0.0);
        assert!((x[0] - 2.0).abs() < 1e-12);
    }
}
