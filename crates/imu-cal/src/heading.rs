//! Tilt-compensated heading from one accelerometer and one magnetometer reading, and what a
//! calibration buys in degrees of heading: the error against a truth, or — without one — the
//! heading's consistency with the gyro.
//!
//! Axes: the sensors' own (x forward, y left, z up; the accelerometer reads +g on z lying level),
//! taken as the body's forward-right-down `(x, −y, −z)`; angles are aerospace Z-Y-X (roll φ,
//! pitch θ, heading ψ clockwise from magnetic north), as the device's AHRS reports them
//! (docs/firmware.md, "Orientation"). From the specific force `f` (body):
//! `φ = atan2(−f_y, −f_z)`, `θ = atan2(f_x, √(f_y² + f_z²))`; the field levelled,
//! `h_x = m_x cos θ + (m_y sin φ + m_z cos φ) sin θ`, `h_y = m_y cos φ − m_z sin φ`, and
//! `ψ = atan2(−h_y, h_x)`.

/// Roll, pitch and heading, degrees (heading in [0, 360)).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Attitude {
    pub roll: f64,
    pub pitch: f64,
    pub heading: f64,
}

/// The attitude from an accelerometer and a magnetometer reading (sensor axes, any units);
/// `None` when either is zero or not finite.
pub fn tilt_compensated(accel: [f64; 3], mag: [f64; 3]) -> Option<Attitude> {
    let f = [accel[0], -accel[1], -accel[2]];
    let m = [mag[0], -mag[1], -mag[2]];
    let ok = |v: &[f64; 3]| v.iter().all(|x| x.is_finite()) && v.iter().any(|&x| x != 0.0);
    if !ok(&f) || !ok(&m) {
        return None;
    }
    let roll = (-f[1]).atan2(-f[2]);
    let pitch = f[0].atan2(f[1].hypot(f[2]));
    let (sr, cr) = roll.sin_cos();
    let (sp, cp) = pitch.sin_cos();
    let hx = m[0] * cp + (m[1] * sr + m[2] * cr) * sp;
    let hy = m[1] * cr - m[2] * sr;
    Some(Attitude {
        roll: roll.to_degrees(),
        pitch: pitch.to_degrees(),
        heading: (-hy).atan2(hx).to_degrees().rem_euclid(360.0),
    })
}

/// The smallest signed difference `a − b` of two angles, degrees, in (−180, 180].
pub fn angle_diff(a: f64, b: f64) -> f64 {
    let d = (a - b).rem_euclid(360.0);
    if d > 180.0 {
        d - 360.0
    } else {
        d
    }
}

/// An rms error with its standard uncertainty.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rms {
    /// Root mean square, degrees.
    pub rms: f64,
    /// Standard uncertainty of `rms`, degrees: from the spread of the mean squares of the
    /// blocks the errors were grouped in (consecutive errors are correlated, blocks much less).
    pub sigma: f64,
    /// Largest |error|, degrees.
    pub max: f64,
    /// Errors counted.
    pub n: usize,
}

/// rms of `errors` grouped into blocks of `block` consecutive values (the uncertainty's unit).
pub fn rms(errors: &[f64], block: usize) -> Option<Rms> {
    if errors.is_empty() {
        return None;
    }
    let block = block.max(1);
    let msq: Vec<f64> = errors
        .chunks(block)
        .map(|c| c.iter().map(|e| e * e).sum::<f64>() / c.len() as f64)
        .collect();
    let n = errors.len();
    let total = errors.iter().map(|e| e * e).sum::<f64>() / n as f64;
    let r = total.sqrt();
    let k = msq.len() as f64;
    let sigma = if msq.len() > 1 && r > 0.0 {
        let mean = msq.iter().sum::<f64>() / k;
        let var = msq.iter().map(|m| (m - mean).powi(2)).sum::<f64>() / (k - 1.0);
        // σ(√x) = σ(x) / (2√x), σ(x) the standard error of the blocks' mean.
        (var / k).sqrt() / (2.0 * r)
    } else {
        f64::NAN
    };
    Some(Rms {
        rms: r,
        sigma,
        max: errors.iter().fold(0.0, |a: f64, e| a.max(e.abs())),
        n,
    })
}

/// One row of a recording for the consistency check: time (s), accelerometer, gyro (deg/s),
/// magnetometer, sensor axes.
#[derive(Debug, Clone, Copy)]
pub struct Row {
    pub t: f64,
    pub accel: [f64; 3],
    pub gyro: [f64; 3],
    pub mag: [f64; 3],
}

/// Heading consistency with the gyro: over consecutive windows of `window` s, the change of
/// the tilt-compensated heading minus the heading change the gyro integrates
/// (`ψ̇ = (q sin φ + r cos φ)/cos θ`, body rates, φ and θ from the accelerometer), degrees, one
/// value per window. Windows with a gap (a step over 1.5× the median spacing) or reaching
/// |pitch| > `max_pitch` are skipped. What it sees: heading errors that change as the board
/// turns (hard and soft iron do); what it cannot: an error that is the same at every attitude
/// (a declination, a turned mounting) — that needs a truth.
pub fn gyro_consistency(rows: &[Row], window: f64, max_pitch: f64) -> Vec<f64> {
    check_windows(rows, window, max_pitch)
        .into_iter()
        .map(|w| w.0)
        .collect()
}

/// The heading change the gyro integrates over each window [`gyro_consistency`] counts,
/// degrees, one value a window: how far the board turned while it was judged. The check sees
/// a heading error only where the heading changes: on a board that hardly turned, hard iron
/// and a good calibration read alike.
pub fn gyro_turns(rows: &[Row], window: f64, max_pitch: f64) -> Vec<f64> {
    check_windows(rows, window, max_pitch)
        .into_iter()
        .map(|w| w.1)
        .collect()
}

/// Each counted window of [`gyro_consistency`]: its inconsistency and the gyro's heading
/// change, degrees.
fn check_windows(rows: &[Row], window: f64, max_pitch: f64) -> Vec<(f64, f64)> {
    let Some(step) = median_spacing(rows) else {
        return Vec::new();
    };
    if !(window > 0.0) {
        return Vec::new();
    }
    let mut out = Vec::new();
    let mut i = 0;
    while i < rows.len() {
        let t0 = rows[i].t;
        let Some(a0) = tilt_compensated(rows[i].accel, rows[i].mag) else {
            i += 1;
            continue;
        };
        let mut gyro = 0.0;
        let mut ok = a0.pitch.abs() <= max_pitch;
        let mut j = i;
        while j + 1 < rows.len() && rows[j + 1].t - t0 <= window {
            let (r, n) = (&rows[j], &rows[j + 1]);
            let dt = n.t - r.t;
            if is_gap(dt, step) {
                ok = false;
                break;
            }
            match tilt_compensated(r.accel, r.mag) {
                Some(a) if a.pitch.abs() <= max_pitch => {
                    let (sr, cr) = a.roll.to_radians().sin_cos();
                    let cp = a.pitch.to_radians().cos();
                    // Body rates forward-right-down: q = −g_y, r = −g_z.
                    gyro += (-r.gyro[1] * sr - r.gyro[2] * cr) / cp * dt;
                }
                _ => {
                    ok = false;
                    break;
                }
            }
            j += 1;
        }
        let complete = rows[j].t - t0 >= window - 1.5 * step;
        match (ok && complete, tilt_compensated(rows[j].accel, rows[j].mag)) {
            (true, Some(a1)) if a1.pitch.abs() <= max_pitch => {
                // Both sides wrapped: a window may turn further than ±180°.
                out.push((
                    angle_diff(angle_diff(a1.heading, a0.heading) - gyro, 0.0),
                    gyro,
                ));
            }
            _ => {}
        }
        i = j + 1;
    }
    out
}

/// The median spacing of the rows' times (None with fewer than two rows).
fn median_spacing(rows: &[Row]) -> Option<f64> {
    let mut dts: Vec<f64> = rows.windows(2).map(|w| w[1].t - w[0].t).collect();
    dts.sort_by(f64::total_cmp);
    dts.get(dts.len() / 2).copied()
}

/// A spacing no window spans: beyond 1.5× the median `step`, or not increasing.
fn is_gap(dt: f64, step: f64) -> bool {
    dt > 1.5 * step || dt <= 0.0
}

/// Why [`gyro_consistency`] found no window in `rows`: the record shorter than a window, gaps
/// in the rows' times (a spacing beyond 1.5× the median, as host stamps of a bursty link have),
/// or rows tilted beyond `max_pitch` or without a heading; each counted.
pub fn no_window_reason(rows: &[Row], window: f64, max_pitch: f64) -> String {
    let (Some(first), Some(last)) = (rows.first(), rows.last()) else {
        return "no rows".into();
    };
    let span = last.t - first.t;
    let Some(step) = median_spacing(rows).filter(|_| span >= window) else {
        return format!("the recording ({span:.3} s) is shorter than one {window} s window");
    };
    let gaps = rows
        .windows(2)
        .filter(|w| is_gap(w[1].t - w[0].t, step))
        .count();
    let tilted = rows
        .iter()
        .filter(|r| !tilt_compensated(r.accel, r.mag).is_some_and(|a| a.pitch.abs() <= max_pitch))
        .count();
    format!(
        "every {window} s window holds a gap in the rows' times or a row left out: {gaps} of {} \
         spacings are beyond 1.5× the median {:.3} ms (or not increasing: times stamped on \
         arrival, not on the sensor's clock?), {tilted} of {} rows are beyond ±{max_pitch}° of \
         pitch or have no heading; a shorter --window may find some",
        rows.len() - 1,
        step * 1e3,
        rows.len()
    )
}

/// A calibration file's accelerometer and magnetometer corrections in the recording's units
/// (m/s², µT), and its gyro bias (deg/s: the consistency check's gyro), applied on the host to
/// the raw columns of a recording (`imu-lab record --raw`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Correction {
    /// `a_cal = M·(a − o)`: (M, o).
    pub accel: ([[f64; 3]; 3], [f64; 3]),
    /// `m_cal = S·(m − h)`: (soft iron, hard iron).
    pub mag: ([[f64; 3]; 3], [f64; 3]),
    pub gyro_bias: [f64; 3],
}

impl Correction {
    /// The corrections of a calibration file.
    pub fn of(f: &crate::file::CalFile) -> Correction {
        let m = crate::accel::correction_matrix(&crate::lab::Params {
            scale: Some(f.accel.scale),
            misalignment_deg: Some(f.accel.misalignment_deg),
            ..crate::lab::Params::default()
        });
        Correction {
            accel: (
                [0, 1, 2].map(|i| [0, 1, 2].map(|j| m[(i, j)])),
                f.accel.offset,
            ),
            mag: (f.mag.soft_iron, f.mag.hard_iron),
            gyro_bias: f.gyro.bias,
        }
    }

    fn affine((m, o): &([[f64; 3]; 3], [f64; 3]), v: [f64; 3]) -> [f64; 3] {
        let d = [v[0] - o[0], v[1] - o[1], v[2] - o[2]];
        [0, 1, 2].map(|i| m[i][0] * d[0] + m[i][1] * d[1] + m[i][2] * d[2])
    }

    /// A raw row corrected.
    pub fn apply(&self, r: &Row) -> Row {
        Row {
            t: r.t,
            accel: Correction::affine(&self.accel, r.accel),
            mag: Correction::affine(&self.mag, r.mag),
            gyro: [0, 1, 2].map(|i| r.gyro[i] - self.gyro_bias[i]),
        }
    }
}

/// Below this rms turn a window (degrees, the gyro's), the consistency check says little: a
/// hard iron of a few µT in a 50 µT field turns the heading by a few degrees, and its change
/// over a window is that times the turn in radians, under the gyro's noise when the turn is
/// small.
pub const LITTLE_TURN_DEG: f64 = 10.0;

/// What [`before_after`] finds, each an rms in degrees with its uncertainty (one value a
/// window), `None` when no window counts.
#[derive(Debug, Clone, Copy)]
pub struct BeforeAfter {
    /// The heading's inconsistency with the gyro, the raw columns as recorded (the identity).
    pub before: Option<Rms>,
    /// The same through the calibration.
    pub after: Option<Rms>,
    /// The heading change the gyro integrates over each window ([`gyro_turns`]), the
    /// calibration's gyro bias taken out: how much the check could see.
    pub turned: Option<Rms>,
}

impl BeforeAfter {
    /// The board turned less than [`LITTLE_TURN_DEG`] rms a window: the check is weak.
    pub fn little_turn(&self) -> bool {
        self.turned.is_some_and(|t| t.rms < LITTLE_TURN_DEG)
    }
}

/// What a calibration buys in heading on one raw recording, without a truth: the heading's
/// consistency with the gyro ([`gyro_consistency`], windows of `window` s, rows beyond
/// `max_pitch` left out) with the raw columns as recorded and through `cal`, and how far the
/// board turned in those windows.
pub fn before_after(rows: &[Row], cal: &Correction, window: f64, max_pitch: f64) -> BeforeAfter {
    let fitted: Vec<Row> = rows.iter().map(|r| cal.apply(r)).collect();
    let (judged, turns): (Vec<f64>, Vec<f64>) = check_windows(&fitted, window, max_pitch)
        .into_iter()
        .unzip();
    BeforeAfter {
        before: rms(&gyro_consistency(rows, window, max_pitch), 1),
        after: rms(&judged, 1),
        turned: rms(&turns, 1),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A reading made from a known attitude: level field B (50 µT, dip 60°) and gravity turned
    /// into the sensor's axes.
    fn reading(roll: f64, pitch: f64, heading: f64) -> ([f64; 3], [f64; 3]) {
        let (sf, cf) = roll.to_radians().sin_cos();
        let (st, ct) = pitch.to_radians().sin_cos();
        let (sp, cp) = heading.to_radians().sin_cos();
        let r = [
            [ct * cp, sf * st * cp - cf * sp, cf * st * cp + sf * sp],
            [ct * sp, sf * st * sp + cf * cp, cf * st * sp - sf * cp],
            [-st, sf * ct, cf * ct],
        ];
        let body =
            |v: [f64; 3]| [0, 1, 2].map(|j| r[0][j] * v[0] + r[1][j] * v[1] + r[2][j] * v[2]);
        let flu = |v: [f64; 3]| [v[0], -v[1], -v[2]];
        let d = 60f64.to_radians();
        (
            flu(body([0.0, 0.0, -9.81])),
            flu(body([50.0 * d.cos(), 0.0, 50.0 * d.sin()])),
        )
    }

    #[test]
    fn the_attitude_of_a_reading_is_the_one_it_was_made_at() {
        let mut s = 0x9e37_79b9_7f4a_7c15u64;
        let mut u = || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s >> 11) as f64 / (1u64 << 53) as f64
        };
        for _ in 0..1000 {
            let (r, p, h) = (-180.0 + 360.0 * u(), -85.0 + 170.0 * u(), 360.0 * u());
            let (a, m) = reading(r, p, h);
            let att = tilt_compensated(a, m).unwrap();
            assert!(angle_diff(att.roll, r).abs() < 1e-9, "{r} {p} {h}: {att:?}");
            assert!((att.pitch - p).abs() < 1e-9, "{r} {p} {h}: {att:?}");
            assert!(
                angle_diff(att.heading, h).abs() < 1e-7,
                "{r} {p} {h}: {att:?}"
            );
        }
        assert_eq!(tilt_compensated([0.0; 3], [1.0, 0.0, 0.0]), None);
        assert_eq!(
            tilt_compensated([0.0, 0.0, 1.0], [f64::NAN, 0.0, 0.0]),
            None
        );
    }

    /// A level turn at 30°/s: an exact field gives zero inconsistency; a hard iron along x
    /// (a heading error that changes with the heading) gives a large one.
    /// A turn of any rate and a window of any length: the heading's change wraps at ±180°, the
    /// gyro's integral does not, so the error is wrapped (a window that turned 240° read 120°
    /// against the gyro's 240°: an exact field was off by 360°).
    #[test]
    fn consistency_sees_a_hard_iron_and_not_an_exact_field() {
        let key = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(3, |d| d.subsec_nanos());
        let rate = (30 + key % 90) as f64 * if key.is_multiple_of(2) { 1.0 } else { -1.0 };
        // Each window turns 30°–330°, past ±180° half the time.
        let turn = (30 + key / 7 % 301) as f64;
        let window = turn / rate.abs();
        let rows = |rate: f64, hard: [f64; 3]| -> Vec<Row> {
            (0..24_000)
                .map(|i| {
                    let t = i as f64 * 1e-3;
                    let (a, m) = reading(10.0, -5.0, rate * t);
                    // Level-ish turn about the world's vertical: body rates of ψ̇ = rate.
                    let (sf, cf) = 10f64.to_radians().sin_cos();
                    let (st, ct) = (-5f64).to_radians().sin_cos();
                    let w = [-rate * st, rate * sf * ct, rate * cf * ct];
                    Row {
                        t,
                        accel: a,
                        gyro: [w[0], -w[1], -w[2]],
                        mag: [0, 1, 2].map(|k| m[k] + hard[k]),
                    }
                })
                .collect()
        };
        let good = gyro_consistency(&rows(rate, [0.0; 3]), window, 70.0);
        // windows of `window` s and a step each
        let expected = (24.0 / (window + 1e-3)).floor() as usize;
        assert!(
            good.len() + 1 >= expected && good.len() <= expected,
            "key {key}: {} windows of {window} s in 24 s",
            good.len()
        );
        let r = rms(&good, 1).unwrap();
        assert!(r.rms < 0.05, "key {key}: {rate}°/s, {window} s: {good:?}");
        // 60° windows: the hard iron's error differs between their ends (over a whole turn, or
        // half a turn across its axis, it would not).
        let bad = gyro_consistency(&rows(30.0, [15.0, 0.0, 0.0]), 2.0, 70.0);
        let r = rms(&bad, 1).unwrap();
        assert!(r.rms > 10.0, "{bad:?}");
    }

    /// Rows stamped in bursts (a host's arrival times) give no window, and the reason says
    /// how many spacings are gaps; a record shorter than a window says that.
    #[test]
    fn no_window_is_explained() {
        let key = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(5, |d| d.subsec_nanos() as usize);
        let every = 20 + key % 50;
        let mut t = 0.0;
        let rows: Vec<Row> = (0..6_000)
            .map(|i: usize| {
                // a burst every `every` rows: one spacing of 8 ms among 1 ms ones
                t += if i > 0 && i.is_multiple_of(every) {
                    8e-3
                } else {
                    1e-3
                };
                let (a, m) = reading(3.0, -2.0, 20.0 * t);
                Row {
                    t,
                    accel: a,
                    gyro: [0.0; 3],
                    mag: m,
                }
            })
            .collect();
        assert!(gyro_consistency(&rows, 2.0, 70.0).is_empty());
        let why = no_window_reason(&rows, 2.0, 70.0);
        let gaps = (1..6_000)
            .filter(|i: &usize| i.is_multiple_of(every))
            .count();
        assert!(
            why.contains(&format!(
                "{gaps} of 5999 spacings are beyond 1.5× the median 1.000 ms"
            )) && why.contains("0 of 6000 rows"),
            "key {key}: {why}"
        );
        assert!(no_window_reason(&rows[..100], 2.0, 70.0).contains("shorter than one 2 s window"));
    }

    /// A level-ish turn read through a hard and soft iron drawn at random, by a gyro with a
    /// bias the file knows: before, the heading disagrees with the gyro by degrees; after the
    /// file that undoes them, not at all; and the turn the check saw is the turn made (the
    /// bias out), "little" when the board turns slowly.
    #[test]
    fn before_after_a_calibration_that_undoes_the_iron() {
        let mut s = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .unwrap()
            .as_nanos() as u64
            | 1;
        let key = s;
        let mut u = move || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s >> 11) as f64 / (1u64 << 53) as f64
        };
        let hard = [0; 3].map(|_| 10.0 + 20.0 * u());
        let soft = [
            [1.0 + 0.1 * u(), 0.02, 0.0],
            [0.02, 1.0 - 0.1 * u(), 0.0],
            [0.0, 0.0, 1.0],
        ];
        let bias = 2.0 * u() - 1.0;
        let rows = |rate: f64| -> Vec<Row> {
            (0..12_000)
                .map(|i| {
                    let t = i as f64 * 1e-3;
                    let (a, m) = reading(0.0, 0.0, rate * t);
                    let read =
                        [0, 1, 2].map(|k| (0..3).map(|j| soft[k][j] * m[j]).sum::<f64>() + hard[k]);
                    Row {
                        t,
                        accel: a,
                        gyro: [0.0, 0.0, -rate + bias],
                        mag: read,
                    }
                })
                .collect()
        };
        // the file's correction: S⁻¹ (soft iron inverted), the hard iron and the gyro's bias
        let inv = nalgebra::Matrix3::from_fn(|i, j| soft[i][j])
            .try_inverse()
            .unwrap();
        let cal = Correction {
            accel: (
                [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
                [0.0; 3],
            ),
            mag: ([0, 1, 2].map(|i| [0, 1, 2].map(|j| inv[(i, j)])), hard),
            gyro_bias: [0.0, 0.0, bias],
        };
        let r = before_after(&rows(30.0), &cal, 2.0, 70.0);
        let (b, a, turned) = (r.before.unwrap(), r.after.unwrap(), r.turned.unwrap());
        assert!(b.rms > 5.0, "key {key}: {b:?}");
        assert!(a.rms < 0.05, "key {key}: {a:?}");
        assert_eq!(a.n, 5);
        // 30°/s for 2 s a window (each window 1 ms short of it: its rows' span)
        assert!((turned.rms - 60.0).abs() < 0.05, "key {key}: {turned:?}");
        assert_eq!(turned.n, 5);
        assert!(!r.little_turn());
        let slow = before_after(&rows(3.0), &cal, 2.0, 70.0);
        let t = slow.turned.unwrap();
        assert!(
            (t.rms - 6.0).abs() < 0.01 && slow.little_turn(),
            "key {key}: {t:?}"
        );
    }

    #[test]
    fn rms_and_its_uncertainty() {
        let e: Vec<f64> = (0..1000)
            .map(|i| if i % 2 == 0 { 2.0 } else { -2.0 })
            .collect();
        let r = rms(&e, 10).unwrap();
        assert!((r.rms - 2.0).abs() < 1e-12 && r.sigma < 1e-12 && r.max == 2.0);
        let e: Vec<f64> = (0..1000).map(|i| (i / 100) as f64).collect();
        let r = rms(&e, 100).unwrap();
        assert!(r.sigma > 0.5, "{r:?}");
        assert_eq!(rms(&[], 1), None);
    }
}
