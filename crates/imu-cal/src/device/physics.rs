//! The physical bounds a stored correction must respect, checked by the host before it writes a
//! blob and by the device before it uses one (no `std`: Newton's square root and Jacobi
//! rotations instead of a linear-algebra library).
use super::{Affine, BlobError, Sensor};

/// Physical bounds a stored correction must respect ([`Calibration::check_physics`]).
pub mod bounds {
    /// Least and greatest scale factor (norm of a row of `M`): a MEMS part's sensitivity error
    /// is a few percent; a factor of 2 is a wrong range or a wrong fit.
    pub const SCALE: (f64, f64) = (0.5, 2.0);
    /// Largest angle between a corrected axis (a row of `M`) and the raw axis, degrees
    /// (accelerometer and gyro; mounting and cross-axis errors are ≲ 2°). A flipped axis is
    /// 180°.
    pub const MISALIGNMENT_DEG: f64 = 10.0;
    /// cos² of [`MISALIGNMENT_DEG`].
    pub const MISALIGNMENT_COS2: f64 = 0.969_846_310_392_954;
    /// Largest condition number of the magnetometer's soft-iron matrix (σ_max/σ_min).
    pub const CONDITION: f64 = 3.0;
    /// Largest gyro bias, LSB: a quarter of full scale (2¹⁵/4).
    pub const GYRO_BIAS_LSB: f64 = 8192.0;
    /// Largest accelerometer offset or hard iron, LSB: the sensor's range (2¹⁵).
    pub const OFFSET_LSB: f64 = 32768.0;
}

/// Which physical bound a correction breaks ([`bounds`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Check {
    /// A scale factor outside [`bounds::SCALE`].
    Scale,
    /// An axis turned by more than [`bounds::MISALIGNMENT_DEG`] (or flipped).
    Misalignment,
    /// The soft-iron matrix's condition number over [`bounds::CONDITION`].
    Condition,
    /// A singular matrix (an axis mapped to zero or two axes onto one).
    Singular,
    /// A gyro bias over [`bounds::GYRO_BIAS_LSB`].
    Bias,
    /// An accelerometer offset or hard iron over [`bounds::OFFSET_LSB`].
    Offset,
    /// A non-positive or non-finite LSB-per-unit factor.
    LsbFactor,
}

impl Affine {
    /// The physical bounds ([`bounds`]): every row's norm (scale) in [`bounds::SCALE`], the
    /// matrix non-singular, and for the accelerometer and gyro each corrected axis within
    /// [`bounds::MISALIGNMENT_DEG`] of its raw axis; for the magnetometer (soft iron, a
    /// symmetric stretch) no flipped axis and a condition number within [`bounds::CONDITION`];
    /// the folded offset within `max_offset` LSB.
    pub(super) fn check_physics(&self, sensor: Sensor, max_offset: f64) -> Result<(), BlobError> {
        let m = self.matrix();
        let bad = |check, axis: usize| BlobError::Implausible {
            sensor,
            check,
            axis: axis as u8,
        };
        let (lo, hi) = bounds::SCALE;
        for (i, row) in m.iter().enumerate() {
            let n2: f64 = row.iter().map(|v| v * v).sum();
            if n2 == 0.0 {
                return Err(bad(Check::Singular, i));
            }
            if !(lo * lo..=hi * hi).contains(&n2) {
                return Err(bad(Check::Scale, i));
            }
            let cos_ok = row[i] > 0.0 && row[i] * row[i] >= bounds::MISALIGNMENT_COS2 * n2;
            if !cos_ok && (sensor != Sensor::Mag || row[i] <= 0.0) {
                return Err(bad(Check::Misalignment, i));
            }
        }
        let (smin2, smax2) = singular_values_squared(&m);
        if !(smin2 > 1e-6 * smax2) {
            return Err(bad(Check::Singular, 0));
        }
        if sensor == Sensor::Mag && smax2 > bounds::CONDITION * bounds::CONDITION * smin2 {
            return Err(bad(Check::Condition, 0));
        }
        for (i, c) in self.folded_offset().iter().enumerate() {
            if c.abs() > max_offset {
                let check = if sensor == Sensor::Gyro {
                    Check::Bias
                } else {
                    Check::Offset
                };
                return Err(bad(check, i));
            }
        }
        Ok(())
    }
}

/// `√x` for x ≥ 0 without `std` (Newton's iteration from an exponent-halved start; 8 steps
/// reach f64 precision for the matrices checked here).
fn sqrt(x: f64) -> f64 {
    if !(x > 0.0) {
        return 0.0;
    }
    let mut r = f64::from_bits((x.to_bits() >> 1) + (0x3ff << 51));
    for _ in 0..8 {
        r = 0.5 * (r + x / r);
    }
    r
}

/// The least and greatest squared singular values of `m`: the extreme eigenvalues of the
/// symmetric `MᵀM`, by cyclic Jacobi rotations (Golub & Van Loan, §8.5; 3×3 converges to
/// f64 precision in a few sweeps; at most 16 are run).
fn singular_values_squared(m: &[[f64; 3]; 3]) -> (f64, f64) {
    let mut a = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            a[i][j] = (0..3).map(|k| m[k][i] * m[k][j]).sum();
        }
    }
    for _ in 0..16 {
        let off = a[0][1] * a[0][1] + a[0][2] * a[0][2] + a[1][2] * a[1][2];
        let diag = a[0][0] * a[0][0] + a[1][1] * a[1][1] + a[2][2] * a[2][2];
        if !(off > 1e-30 * diag) {
            break;
        }
        for (p, q) in [(0, 1), (0, 2), (1, 2)] {
            if a[p][q] == 0.0 {
                continue;
            }
            let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
            let t = theta.signum() / (theta.abs() + sqrt(theta * theta + 1.0));
            let c = 1.0 / sqrt(t * t + 1.0);
            let s = t * c;
            for k in 0..3 {
                let (akp, akq) = (a[k][p], a[k][q]);
                a[k][p] = c * akp - s * akq;
                a[k][q] = s * akp + c * akq;
            }
            for k in 0..3 {
                let (apk, aqk) = (a[p][k], a[q][k]);
                a[p][k] = c * apk - s * aqk;
                a[q][k] = s * apk + c * aqk;
            }
        }
    }
    let d = [a[0][0], a[1][1], a[2][2]];
    (
        d.iter().copied().fold(f64::INFINITY, f64::min),
        d.iter().copied().fold(f64::NEG_INFINITY, f64::max),
    )
}
