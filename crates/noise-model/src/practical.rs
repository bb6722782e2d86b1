//! Practical outputs: the recalibration period and Kalibr `imu.yaml` values.
use crate::effect::UnitFamily;

/// The recalibration period for a bias tolerance.
#[derive(Debug, Clone, PartialEq)]
pub struct Recalibration {
    /// Tolerance on the bias error [u].
    pub tolerance: f64,
    /// Longest T [s] for which the predicted drift stays within the tolerance, from the best
    /// estimates; None = unbounded (no K or R), or impossible when `floor > tolerance`.
    pub period_s: Option<f64>,
    /// Same with K and R at their +1σ values (or upper bounds when not detected).
    pub period_conservative_s: Option<f64>,
    /// The flicker floor √2·√(2ln2/π)·B [u] below which no recalibration rate suffices.
    pub floor: f64,
    pub possible: bool,
}

/// Predicted rms bias change after T seconds, D(T) = √2·σ_drift(T), where
/// σ²_drift(T) = (2 ln2/π)B² + K²T/3 + R²T²/2 is the Allan variance of the drift terms only
/// (Jaime et al., "Caracterización y calibración de unidades de medición inercial de bajo
/// costo", eqs. 12–14). By the definition of the Allan variance, √2·σ(T) is the rms difference
/// between the bias averaged over one window of length T and over the next: calibrate the bias
/// by averaging for T and it stays within D(T) (1σ) over the following T.
pub fn bias_drift(b: f64, k: f64, r: f64, t: f64) -> f64 {
    let c0 = 2.0 * std::f64::consts::LN_2 / std::f64::consts::PI * b * b;
    (2.0 * (c0 + k * k * t / 3.0 + r * r * t * t / 2.0)).sqrt()
}

fn solve_period(b: f64, k: f64, r: f64, tol: f64) -> Option<f64> {
    // R²T²/2 + K²T/3 + (c0 − tol²/2) = 0, positive root.
    let c0 = 2.0 * std::f64::consts::LN_2 / std::f64::consts::PI * b * b;
    let cc = c0 - tol * tol / 2.0;
    if cc >= 0.0 {
        return Some(0.0);
    }
    let (qa, qb) = (r * r / 2.0, k * k / 3.0);
    if qa > 0.0 {
        Some((-qb + (qb * qb - 4.0 * qa * cc).sqrt()) / (2.0 * qa))
    } else if qb > 0.0 {
        Some(-cc / qb)
    } else {
        None
    }
}

/// Recalibration period from B, K, R (canonical units) and their conservative values.
pub fn recalibration(b: f64, k: f64, r: f64, k_cons: f64, r_cons: f64, tol: f64) -> Recalibration {
    let floor = bias_drift(b, 0.0, 0.0, 0.0);
    let possible = floor < tol;
    Recalibration {
        tolerance: tol,
        period_s: if possible {
            solve_period(b, k, r, tol)
        } else {
            Some(0.0)
        },
        period_conservative_s: if possible {
            solve_period(b, k_cons, r_cons, tol)
        } else {
            Some(0.0)
        },
        floor,
        possible,
    }
}

/// Kalibr imu.yaml noise values (continuous-time densities, SI).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct KalibrImu {
    /// rad/s/√Hz
    pub gyroscope_noise_density: f64,
    /// rad/s²/√Hz
    pub gyroscope_random_walk: f64,
    /// m/s²/√Hz
    pub accelerometer_noise_density: f64,
    /// m/s³/√Hz
    pub accelerometer_random_walk: f64,
    /// Hz
    pub update_rate: f64,
}

/// Convert a gyro channel's N [u·√s] and K [u/√s] to Kalibr's rad/s/√Hz and rad/s²/√Hz.
/// Since 1/√Hz = √s: N[rad/s/√Hz] = N[deg/s·√s]·π/180; K[rad/s²/√Hz] = K[deg/s/√s]·π/180.
pub fn kalibr_gyro(n: f64, k: f64, unit: &str) -> Result<(f64, f64), String> {
    let f = match UnitFamily::of(unit) {
        UnitFamily::DegPerS => std::f64::consts::PI / 180.0,
        UnitFamily::RadPerS => 1.0,
        _ => return Err(format!("gyro unit '{unit}' is not deg/s or rad/s")),
    };
    Ok((n * f, k * f))
}

/// Convert an accelerometer channel's N [m/s²·√s] and K [m/s²/√s] to Kalibr's m/s²/√Hz and
/// m/s³/√Hz (the same numbers: only the unit names change).
pub fn kalibr_accel(n: f64, k: f64, unit: &str) -> Result<(f64, f64), String> {
    match UnitFamily::of(unit) {
        UnitFamily::MPerS2 => Ok((n, k)),
        _ => Err(format!("accelerometer unit '{unit}' is not m/s²")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn period_solves_the_drift_equation() {
        let (b, k, r, tol) = (0.002, 1e-4, 1e-7, 0.01);
        let rc = recalibration(b, k, r, k, r, tol);
        let t = rc.period_s.unwrap();
        assert!((bias_drift(b, k, r, t) - tol).abs() < 1e-12);
        // only K
        let t2 = recalibration(0.0, 1e-3, 0.0, 1e-3, 0.0, 0.01)
            .period_s
            .unwrap();
        assert!((t2 - 0.01f64.powi(2) / 2.0 * 3.0 / 1e-6).abs() < 1e-6);
        // no drift terms: unbounded
        assert_eq!(
            recalibration(0.001, 0.0, 0.0, 0.0, 0.0, 0.01).period_s,
            None
        );
        // tolerance below the flicker floor: impossible
        assert!(!recalibration(0.1, 0.0, 0.0, 0.0, 0.0, 0.01).possible);
    }

    #[test]
    fn kalibr_conversions() {
        let (n, k) = kalibr_gyro(0.3 / 60.0, 1.0, "deg/s").unwrap();
        assert!((n - 0.005 * std::f64::consts::PI / 180.0).abs() < 1e-15);
        assert!((k - std::f64::consts::PI / 180.0).abs() < 1e-15);
        assert!(kalibr_accel(1.0, 1.0, "deg/s").is_err());
    }
}
