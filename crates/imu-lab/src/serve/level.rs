//! The magnetometer wizard's level turn (2-D): the method of I. Jaime, F. Beck Ferrero,
//! M. L. Miretti, E. Bernardi, "Caracterización y calibración de unidades de medición inercial
//! de bajo costo" (eqs. 3–5), where the board lies level and turns about the vertical, so the
//! horizontal components of the field draw an ellipse (a circle without soft iron) and the
//! vertical one stays constant. The wizard takes the points of the windows where the board is
//! level within [`LEVEL_TILT_DEG`] (the accelerometer's raw mean: its tilt from the sensor's z
//! axis) and turns about the vertical only (the gyro's mean rate about x and y under
//! [`LEVEL_RATE_DPS`]), shows them in the x–y plane with the share of the headings swept, and
//! fits them with the calibration lab's planar problem (`imu_cal::mag`: hard iron in the plane,
//! soft_iron_2d).
//!
//! Why a bound on the tilt: a board tilted by τ leaks the vertical field (about 40 µT at mid
//! latitudes) into the horizontal axes by B_z·sin τ — 3.5 µT at 5° — so the points of a
//! picked-up board would pull the circle; the accelerometer's own offset reads a level board
//! tilted by up to 2.5° for 0.3 m/s² an axis, which the bound leaves room for. Why a bound on
//! the rate: a window in which the board starts to tilt (or ends a tilt) is still within the
//! tilt bound on average, but its field is partly the tilted one; a tilt at 30 deg/s leaves
//! such a window only for its first or last few hundredths of a second (the gyro's mean over
//! the window under 5 deg/s), where the tilt is a fraction of a degree. Without it, the
//! emulated calibration run's transitions pulled the planar walk to its `tilt` effect.

/// Largest tilt of the board (the accelerometer's direction from +z) for a level point, deg.
pub const LEVEL_TILT_DEG: f64 = 5.0;
/// Largest rate about the board's x and y axes (the gyro's window mean) for a level point,
/// deg/s.
pub const LEVEL_RATE_DPS: f64 = 5.0;
/// Heading bins of the level turn's coverage (10° each).
pub const HEADING_BINS: usize = 36;

/// The tilt of the board from level, degrees: the angle between the accelerometer's mean
/// (the specific force, +g on z lying level) and the sensor's +z; `None` for a zero or
/// non-finite vector.
pub fn tilt_deg(a: [f64; 3]) -> Option<f64> {
    let n = (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt();
    (n > 0.0 && n.is_finite()).then(|| (a[2] / n).clamp(-1.0, 1.0).acos().to_degrees())
}

/// Whether a window with this (tilt in degrees, rate about x and y in deg/s) counts for the
/// level turn.
pub fn is_level((tilt, rate): (f64, f64)) -> bool {
    tilt <= LEVEL_TILT_DEG && rate <= LEVEL_RATE_DPS
}

/// The centre of the circle through 2-D points by algebraic least squares (Kåsa:
/// `x² + y² = 2a·x + 2b·y + c`), or their mean when fewer than three or degenerate.
pub fn circle_centre(p: &[[f64; 2]]) -> [f64; 2] {
    let n = p.len() as f64;
    let mean = p
        .iter()
        .fold([0.0; 2], |a, v| [a[0] + v[0] / n, a[1] + v[1] / n]);
    if p.len() < 3 {
        return mean;
    }
    // centred normal equations: [Sxx Sxy; Sxy Syy]·2(a, b)ᵀ = (Sxz, Syz), z = x² + y²
    let (mut sxx, mut sxy, mut syy, mut sxz, mut syz) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for v in p {
        let (x, y) = (v[0] - mean[0], v[1] - mean[1]);
        let z = x * x + y * y;
        sxx += x * x;
        sxy += x * y;
        syy += y * y;
        sxz += x * z;
        syz += y * z;
    }
    let det = sxx * syy - sxy * sxy;
    // collinear points (or NaN) have no circle
    let degenerate = det.abs() <= 1e-12 * (sxx * syy).max(f64::MIN_POSITIVE);
    if degenerate || det.is_nan() {
        return mean;
    }
    let a = (syy * sxz - sxy * syz) / det / 2.0;
    let b = (sxx * syz - sxy * sxz) / det / 2.0;
    [mean[0] + a, mean[1] + b]
}

/// The share of the [`HEADING_BINS`] 10° bins of direction around the circle's centre that
/// hold a point: how much of a full turn the level points sweep.
pub fn heading_coverage(p: &[[f64; 2]]) -> f64 {
    if p.len() < 3 {
        return 0.0;
    }
    let c = circle_centre(p);
    let mut hit = [false; HEADING_BINS];
    for v in p {
        let (x, y) = (v[0] - c[0], v[1] - c[1]);
        if !(x.is_finite() && y.is_finite()) || (x == 0.0 && y == 0.0) {
            continue;
        }
        let a = y.atan2(x).to_degrees().rem_euclid(360.0);
        hit[((a / 10.0) as usize).min(HEADING_BINS - 1)] = true;
    }
    hit.iter().filter(|h| **h).count() as f64 / HEADING_BINS as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::serve::tests::rng;

    /// An arc of a random span around a random hard iron (with noise): the coverage is the
    /// span's share of the 36 bins (within the two bins its ends may touch); the centre is the
    /// hard iron even for a third of a turn; the full turn covers every bin.
    #[test]
    fn the_heading_coverage_is_the_share_of_the_turn_swept() {
        let (key, mut u) = rng();
        let c = [60.0 * u() - 30.0, 60.0 * u() - 30.0];
        let r = 15.0 + 20.0 * u();
        let start = 360.0 * u();
        for span in [120.0 + 100.0 * u(), 360.0] {
            let p: Vec<[f64; 2]> = (0..400)
                .map(|k| {
                    let a = (start + span * k as f64 / 399.0).to_radians();
                    let e = 0.05 * (2.0 * u() - 1.0);
                    [c[0] + (r + e) * a.cos(), c[1] + (r + e) * a.sin()]
                })
                .collect();
            let got = heading_coverage(&p);
            let bins = got * HEADING_BINS as f64;
            assert!(
                bins >= (span / 10.0).floor() && bins <= (span / 10.0).ceil() + 1.0,
                "key {key}: span {span}°: {bins} bins"
            );
            let o = circle_centre(&p);
            assert!(
                (o[0] - c[0]).abs() < 0.1 && (o[1] - c[1]).abs() < 0.1,
                "key {key}: centre {o:?} vs {c:?}"
            );
        }
        assert_eq!(heading_coverage(&[[1.0, 2.0], [3.0, 4.0]]), 0.0);
    }

    /// Level reads 0°, gravity along x 90°, upside down 180°, with the magnitude's unit
    /// anything; a zero vector has no tilt.
    #[test]
    fn the_tilt_is_the_angle_from_z() {
        let (key, mut u) = rng();
        let g = 1.0 + 20.0 * u();
        let t = 80.0 * u();
        let (s, c) = t.to_radians().sin_cos();
        let a = 360f64.to_radians() * u();
        let v = [g * s * a.cos(), g * s * a.sin(), g * c];
        assert!((tilt_deg(v).unwrap() - t).abs() < 1e-9, "key {key}");
        assert!((tilt_deg([0.0, 0.0, g]).unwrap()).abs() < 1e-12);
        assert!((tilt_deg([g, 0.0, 0.0]).unwrap() - 90.0).abs() < 1e-12);
        assert!((tilt_deg([0.0, 0.0, -g]).unwrap() - 180.0).abs() < 1e-12);
        assert_eq!(tilt_deg([0.0; 3]), None);
    }
}
