//! The device's requests as the host's tools use them (`imu-lab device`, `imu-lab record`,
//! `pico_imu.Device`): one function each, the replies checked, the device's answers in the
//! host's words. The argument checks are pure functions returning the message for a bad
//! argument (`Err(String)`), so that every front end refuses the same values the same way
//! before anything is sent.
use std::collections::BTreeMap;
use std::time::{Duration, Instant};

use anyhow::{bail, Result};
use imu_proto::{
    AllanTable, CalProblem, CalStatus, Channel, DeviceMsg, ErrorCode, Identity, MagReference,
    OrientationConfig, Reply, Request, Status, StreamMode, Vec as HVec, MAX_CAL_BLOB,
};

use crate::Link;

/// A flash write pauses sampling and can take a few hundred ms (sector erase): the wait for the
/// answer to a calibration upload.
pub const UPLOAD_TIMEOUT: Duration = Duration::from_secs(10);

/// The device refused a calibration it was sent, in the calibration file's words
/// ([`cal_problem`]). Carried inside the `anyhow::Error` of [`upload_calibration`], so that a
/// front end can tell it from a link failure (`downcast_ref`).
#[derive(Debug, Clone, PartialEq)]
pub struct CalibrationRefused(pub String);

impl std::fmt::Display for CalibrationRefused {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "the device refused the calibration: {}", self.0)
    }
}

impl std::error::Error for CalibrationRefused {}

/// Who the device is (`Identify`).
pub fn identify(link: &mut Link) -> Result<Identity> {
    match link.request(Request::Identify)? {
        Reply::Identity(id) => Ok(id),
        other => bail!("unexpected reply to Identify: {other:?}"),
    }
}

/// The device's counters and health (`GetStatus`).
pub fn status(link: &mut Link) -> Result<Status> {
    match link.request(Request::GetStatus)? {
        Reply::Status(s) => Ok(s),
        other => bail!("unexpected reply to GetStatus: {other:?}"),
    }
}

/// Switches what the device streams.
pub fn set_mode(link: &mut Link, mode: StreamMode) -> Result<()> {
    link.request_ok(Request::SetMode(mode))
}

/// Forgets the Allan state on the device (every channel's engine starts again).
pub fn reset_allan(link: &mut Link) -> Result<()> {
    link.request_ok(Request::ResetAllan)
}

/// The attitude filter's declination and expected field (`GetOrientation`).
pub fn orientation(link: &mut Link) -> Result<OrientationConfig> {
    match link.request(Request::GetOrientation)? {
        Reply::Orientation(c) => Ok(c),
        other => bail!("unexpected reply to GetOrientation: {other:?}"),
    }
}

/// The `SetOrientation` request for new settings, checked: `declination` in degrees (east
/// positive, within ±180; `None` keeps `current`'s), `field` = (strength µT within 1–1000, dip
/// degrees within ±90) the expected field, or `learn` to let the device learn it; with neither,
/// a field the host set is kept and a learnt one is learnt again. `Err` names the bad value.
pub fn orientation_request(
    current: &OrientationConfig,
    declination: Option<f64>,
    field: Option<(f64, f64)>,
    learn: bool,
) -> Result<Request, String> {
    let decl = declination.unwrap_or(f64::from(current.declination_cdeg) * 0.01);
    if !(-180.0..=180.0).contains(&decl) {
        return Err(format!("declination {decl}: degrees within ±180"));
    }
    if field.is_some() && learn {
        return Err("give the expected field or ask the device to learn it, not both".into());
    }
    let reference = match field {
        Some((b, d)) => {
            if !(1.0..=1000.0).contains(&b) {
                return Err(format!("field {b}: µT within 1 to 1000"));
            }
            if !(-90.0..=90.0).contains(&d) {
                return Err(format!("dip {d}: degrees within ±90"));
            }
            Some(MagReference {
                field_nt: (b * 1000.0).round() as u32,
                dip_cdeg: (d * 100.0).round() as i16,
            })
        }
        None if learn || current.learnt => None,
        None => current.reference,
    };
    Ok(Request::SetOrientation {
        declination_cdeg: (decl * 100.0).round() as i16,
        reference,
    })
}

/// Sends a `SetOrientation` request ([`orientation_request`]) and returns the settings the
/// device then reports.
pub fn set_orientation(link: &mut Link, req: Request) -> Result<OrientationConfig> {
    match link.request(req)? {
        Reply::Ok => {}
        other => bail!("the device refused the orientation settings: {other:?}"),
    }
    orientation(link)
}

/// Sets the device's declination (degrees, east positive), keeping its expected field (a
/// host's, or learnt).
pub fn set_declination(link: &mut Link, deg: f64) -> Result<()> {
    let current = orientation(link)?;
    let req = orientation_request(&current, Some(deg), None, false).map_err(anyhow::Error::msg)?;
    set_orientation(link, req).map(|_| ())
}

/// The calibration blob in use and where it came from (`GetCalibration`).
pub fn calibration(link: &mut Link) -> Result<(Vec<u8>, CalStatus)> {
    match link.request(Request::GetCalibration)? {
        Reply::Calibration { blob, status } => Ok((blob.to_vec(), status)),
        Reply::Error(e) => bail!("the device could not report its calibration: {e:?}"),
        other => bail!("unexpected reply to GetCalibration: {other:?}"),
    }
}

/// Sends a calibration blob (checked by the caller: `imu_cal::file::CalFile::to_blob`, or
/// `imu_cal::device::decode_blob` for a blob file) and waits for the device's answer; with
/// `persist` the device also writes it to flash. A refusal is a [`CalibrationRefused`].
pub fn upload_calibration(link: &mut Link, blob: &[u8], persist: bool) -> Result<()> {
    let blob_bytes = blob;
    let blob = HVec::<u8, MAX_CAL_BLOB>::from_slice(blob).map_err(|_| {
        anyhow::anyhow!(
            "calibration blob of {} B exceeds {MAX_CAL_BLOB} B",
            blob.len()
        )
    })?;
    match link.request_with(
        Request::SetCalibration { blob, persist },
        UPLOAD_TIMEOUT,
        |_| {},
    )? {
        Reply::Ok => Ok(()),
        Reply::Error(ErrorCode::BadCalibration(p)) => {
            Err(CalibrationRefused(refusal_of(&p, blob_bytes)).into())
        }
        Reply::Error(e) => bail!("the device refused the calibration: {e:?}"),
        other => bail!("unexpected reply to SetCalibration: {other:?}"),
    }
}

/// The device's refusal of `blob`, in words: for other ranges or parts, what the blob was
/// fitted for (the wire carries only the reason), in the calibration file's keys.
fn refusal_of(p: &CalProblem, blob: &[u8]) -> String {
    use imu_cal::device::plausible::Num;
    let why = cal_problem(p);
    let fitted = imu_cal::device::decode_blob(blob)
        .ok()
        .and_then(|c| c.fitted_for().copied());
    match (p, fitted) {
        (CalProblem::OtherRanges, Some(f)) => format!(
            "{why}: the file's accel.lsb_per_unit, gyro.lsb_per_unit and mag.lsb_per_unit \
             ({}, {}, {} LSB per m/s², deg/s, µT) are the ranges ±{} g, ±{} deg/s, ±{} G",
            Num(f64::from(f.lsb_per_unit[0])),
            Num(f64::from(f.lsb_per_unit[1])),
            Num(f64::from(f.lsb_per_unit[2])),
            f.ranges.accel_g,
            f.ranges.gyro_dps,
            Num(f.ranges.mag_gauss())
        ),
        (CalProblem::OtherPart, Some(f)) => format!(
            "{why}: the file's accel.part and mag.part are {} and {}",
            f.imu.name(),
            f.mag.name()
        ),
        _ => why,
    }
}

/// Where the corrections in use came from, and what went wrong with the stored record, in words.
pub fn format_cal(c: &CalStatus) -> String {
    let src = match c.source {
        imu_proto::CalSource::Identity => "identity (none stored)",
        imu_proto::CalSource::Flash => "from flash",
        imu_proto::CalSource::Host => "set by the host, not persisted",
    };
    match c.fault {
        None => src.to_string(),
        Some(imu_proto::CalFault::Flash) => {
            format!("{src}; the flash could not be read or written")
        }
        Some(imu_proto::CalFault::Rejected(p)) => {
            format!("{src}; stored record refused: {}", cal_problem(&p))
        }
    }
}

/// Why the device refused a calibration, in words: an implausible parameter in the calibration
/// file's words (`imu_cal::device::Refusal`), key, index, value and bound.
pub fn cal_problem(p: &CalProblem) -> String {
    match *p {
        CalProblem::Corrupt => {
            "not a valid calibration blob (length, magic, CRC or payload)".into()
        }
        CalProblem::Version(v) => format!("blob format version {v}, not one the firmware reads"),
        CalProblem::OutOfRange => "a coefficient outside the fixed-point range".into(),
        CalProblem::Implausible {
            key,
            axis,
            value,
            lo,
            hi,
        } => match imu_cal::device::Key::from_u8(key) {
            Some(key) => imu_cal::device::Refusal {
                key,
                axis,
                value: value.into(),
                lo: lo.into(),
                hi: hi.into(),
            }
            .to_string(),
            None => format!(
                "parameter {key} (unknown to this host) index {axis:?} = {value} is outside {lo}–{hi}"
            ),
        },
        CalProblem::OtherRanges => "fitted for other full-scale ranges than the firmware's".into(),
        CalProblem::OtherPart => {
            "fitted for other sensor parts than the firmware's, or recording none".into()
        }
    }
}

/// Collect one table per wanted channel after a `GetTables` request: all from the round that
/// answers it (one snapshot of the device, `Reply::Tables`); tables of another round are not
/// mixed in.
pub fn fetch_tables(
    link: &mut Link,
    wanted: &[Channel],
    timeout: Duration,
) -> Result<BTreeMap<usize, AllanTable>> {
    let mut got = BTreeMap::new();
    let mut early = Vec::new();
    let round = match link.request_with(Request::GetTables, link.reply_timeout(), |m| {
        if let DeviceMsg::Table(t) = m {
            early.push(t);
        }
    })? {
        Reply::Tables { snapshot } => snapshot,
        other => bail!("unexpected reply to GetTables: {other:?}"),
    };
    let keep = |t: AllanTable, got: &mut BTreeMap<usize, AllanTable>| {
        if t.snapshot == round {
            got.insert(t.channel.index(), t);
        }
    };
    for t in early {
        keep(t, &mut got);
    }
    let until = Instant::now() + timeout;
    while wanted.iter().any(|c| !got.contains_key(&c.index())) {
        let left = until.saturating_duration_since(Instant::now());
        match link.recv(left)? {
            Some(DeviceMsg::Table(t)) => keep(t, &mut got),
            Some(_) => {}
            None => {
                let missing: Vec<&str> = wanted
                    .iter()
                    .filter(|c| !got.contains_key(&c.index()))
                    .map(|c| c.name())
                    .collect();
                bail!(
                    "tables for {} of round {round} did not arrive within {:.0} s",
                    missing.join(", "),
                    timeout.as_secs_f64()
                );
            }
        }
    }
    got.retain(|k, _| wanted.iter().any(|c| c.index() == *k));
    Ok(got)
}

/// One row of a table as the host derives it from the device's sums.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TableRow {
    /// τ = m·τ0, s (τ0 the sensor's measured period).
    pub tau: f64,
    /// Overlapping ADEV, contract unit: `σ² = Σ D2² / (2 n m²)` × scale² (NIST SP 1065 eq. 11).
    pub dev: f64,
    /// The noise exponent the EDF was computed for (S_y ∝ f^α), from the local slope.
    pub alpha: i32,
    /// Equivalent degrees of freedom (`allan::confidence`).
    pub edf: f64,
    /// 68.3 % bounds of `dev` (`allan::confidence::chi2_bounds`).
    pub lo: f64,
    pub hi: f64,
}

/// The rows of a table from its sums: deviation, Greenhall's EDF for the level's estimator
/// (stride `s`, `m/s` differences per cluster; Greenhall & Riley 2003) with the noise exponent
/// from the local slope of the Allan variance (`allan::confidence::alpha_from_slope`), and exact χ²
/// bounds (NIST SP 1065 eq. 45). Where Greenhall's algorithm is undefined, the simple EDF of
/// NIST SP 1065 Table 5 for white FM (`allan::confidence::edf_simple`).
pub fn table_rows(t: &AllanTable) -> Vec<TableRow> {
    use allan::confidence;
    let tau0 = f64::from(t.tau0_ns) * 1e-9;
    let devs: Vec<f64> = t
        .levels
        .iter()
        .map(|l| l.oadev(f64::from(t.scale)).unwrap_or(0.0))
        .collect();
    let n = t.levels.len();
    (0..n)
        .map(|k| {
            let l = &t.levels[k];
            let (a, b) = if k + 1 < n {
                (k, k + 1)
            } else {
                (k.saturating_sub(1), k)
            };
            let alpha = if a == b {
                0
            } else {
                confidence::alpha_from_slope(devs[a] * devs[a], devs[b] * devs[b], 2.0, 2)
            };
            let sums = *l;
            let s_factor = f64::from(l.m) / f64::from(l.stride.max(1));
            let edf = confidence::edf_greenhall(
                alpha,
                f64::from(l.m),
                sums.phase_points(),
                confidence::Variance::Unmodified { d: 2, s_factor },
            )
            .filter(|e| e.is_finite() && *e > 0.0)
            .unwrap_or_else(|| {
                confidence::edf_simple(0, f64::from(l.m), sums.phase_points()).max(1.0)
            });
            let (lo, hi) = confidence::chi2_bounds(devs[k], edf, confidence::ONE_SIGMA);
            TableRow {
                tau: f64::from(l.m) * tau0,
                dev: devs[k],
                alpha,
                edf,
                lo,
                hi,
            }
        })
        .collect()
}

/// The channels named (`ax` … `mz`, `temp`; all ten when none is named); `Err` names an unknown
/// one.
pub fn channels<S: AsRef<str>>(names: &[S]) -> Result<Vec<Channel>, String> {
    if names.is_empty() {
        return Ok(Channel::ALL.to_vec());
    }
    names
        .iter()
        .map(|n| {
            let n = n.as_ref();
            Channel::ALL
                .into_iter()
                .find(|c| c.name() == n.trim())
                .ok_or_else(|| format!("unknown channel `{n}` (ax ay az gx gy gz mx my mz temp)"))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use imu_proto::AllanLevel;

    /// The device's refusal (four numbers on the wire) reads as the host's own refusal of the
    /// file; a key this host does not know is still shown with its numbers.
    #[test]
    fn a_device_refusal_reads_in_the_files_words() {
        let p = imu_proto::CalProblem::Implausible {
            key: imu_cal::device::Key::AccelScale as u8,
            axis: Some(0),
            value: 1.9,
            lo: 0.91,
            hi: 1.09,
        };
        assert_eq!(cal_problem(&p), "accel.scale[0] = 1.9 is outside 0.91–1.09");
        let p = imu_proto::CalProblem::Implausible {
            key: imu_cal::device::Key::MagSoftIronCondition as u8,
            axis: None,
            value: f32::INFINITY,
            lo: 1.0,
            hi: 3.0,
        };
        assert_eq!(
            cal_problem(&p),
            "mag.soft_iron condition number = ∞ is outside 1–3"
        );
        let p = imu_proto::CalProblem::Implausible {
            key: 200,
            axis: Some(1),
            value: 5.0,
            lo: -1.0,
            hi: 1.0,
        };
        let s = cal_problem(&p);
        assert!(
            s.contains("200") && s.contains('5') && s.contains("unknown"),
            "{s}"
        );
    }

    /// A refusal for other ranges or parts says what the blob was fitted for, in the file's
    /// keys (the wire carries only the reason); the mirrored soft iron reads in the file's words.
    #[test]
    fn a_refusal_for_other_ranges_names_what_the_file_was_fitted_for() {
        let mut f = imu_cal::file::CalFile::default();
        f.accel.lsb_per_unit = 4096.0 / 9.80665;
        f.gyro.lsb_per_unit = 65.5;
        let blob = f.to_blob().unwrap();
        let s = refusal_of(&imu_proto::CalProblem::OtherRanges, &blob);
        assert!(
            s.starts_with("fitted for other full-scale ranges")
                && s.contains("accel.lsb_per_unit")
                && s.contains("417.7, 65.5, 120 LSB")
                && s.contains("±8 g, ±500 deg/s, ±2 G"),
            "{s}"
        );
        let s = refusal_of(&imu_proto::CalProblem::OtherPart, &blob);
        assert!(
            s.ends_with("accel.part and mag.part are MPU-6050 and QMC5883L"),
            "{s}"
        );
        // Nothing to add to a corrupt blob's reason.
        let s = refusal_of(&imu_proto::CalProblem::OtherRanges, b"junk");
        assert_eq!(s, cal_problem(&imu_proto::CalProblem::OtherRanges));
        let p = imu_proto::CalProblem::Implausible {
            key: imu_cal::device::Key::MagSoftIronDeterminant as u8,
            axis: None,
            value: -1.0,
            lo: 0.042875,
            hi: 27.0,
        };
        assert_eq!(
            cal_problem(&p),
            "mag.soft_iron determinant = −1 is outside 0.04287–27"
        );
    }

    /// A white-FM table (σ ∝ τ^−½, 60000 samples, strided above m = 8) built from its sums.
    fn white_fm_table() -> AllanTable {
        let mut levels = imu_proto::Vec::new();
        for k in 0..10u32 {
            let m = 1u32 << k;
            let stride = if m <= 8 { 1 } else { m / 8 };
            let dev = 0.1 / f64::from(m).sqrt();
            let n2 = (60_000 - 2 * u64::from(m)) / u64::from(stride);
            let sum2 = (dev / 0.01).powi(2) * 2.0 * n2 as f64 * f64::from(m).powi(2);
            levels
                .push(AllanLevel {
                    m,
                    stride,
                    n2,
                    sum2: sum2 as u128,
                    n3: 0,
                    sum3: 0,
                })
                .unwrap();
        }
        AllanTable {
            channel: Channel::Gz,
            snapshot: 1,
            t_us: 60_000_000,
            tau0_ns: 1_013_171,
            scale: 0.01,
            pushed: 60_000,
            gaps: 0,
            levels,
        }
    }

    #[test]
    fn rows_come_from_the_sums_and_follow_greenhall() {
        // The slope gives alpha = 0, so every EDF must equal allan::confidence's Greenhall value for
        // alpha 0 exactly, and the bounds must bracket the deviation.
        let t = white_fm_table();
        let rows = table_rows(&t);
        for (l, r) in t.levels.iter().zip(&rows) {
            // The deviation is the sums' (to the f64 rounding of the sums built above).
            let want = 0.1 / f64::from(l.m).sqrt();
            assert!((r.dev - want).abs() < 1e-6 * want, "m = {}: {}", l.m, r.dev);
            // τ from the measured period, not the nominal 1 ms.
            assert!((r.tau - f64::from(l.m) * 1.013171e-3).abs() < 1e-12);
            assert!(r.lo < r.dev && r.dev < r.hi, "m = {}", l.m);
            let sums = *l;
            let g = allan::confidence::edf_greenhall(
                0,
                f64::from(l.m),
                sums.phase_points(),
                allan::confidence::Variance::Unmodified {
                    d: 2,
                    s_factor: f64::from(l.m) / f64::from(l.stride),
                },
            )
            .unwrap();
            assert!(
                (r.edf - g).abs() <= 1e-9 * g,
                "m = {}: {} vs {g}",
                l.m,
                r.edf
            );
        }
        // More clusters, tighter bounds: the relative width grows with τ.
        let w = |i: usize| (rows[i].hi - rows[i].lo) / rows[i].dev;
        assert!(w(0) < w(5) && w(5) < w(9));
    }

    #[test]
    fn orientation_settings_are_checked_and_kept_where_not_given() {
        let current = OrientationConfig {
            declination_cdeg: 250,
            reference: Some(MagReference {
                field_nt: 48_000,
                dip_cdeg: 6000,
            }),
            learnt: false,
        };
        let r = orientation_request(&current, None, None, false).unwrap();
        assert_eq!(
            r,
            Request::SetOrientation {
                declination_cdeg: 250,
                reference: current.reference
            }
        );
        let r = orientation_request(&current, Some(-3.456), None, true).unwrap();
        assert_eq!(
            r,
            Request::SetOrientation {
                declination_cdeg: -346,
                reference: None
            }
        );
        let r = orientation_request(&current, None, Some((50.0, -12.5)), false).unwrap();
        assert_eq!(
            r,
            Request::SetOrientation {
                declination_cdeg: 250,
                reference: Some(MagReference {
                    field_nt: 50_000,
                    dip_cdeg: -1250
                })
            }
        );
        for (d, f, learn, says) in [
            (Some(180.5), None, false, "declination 180.5"),
            (None, Some((0.5, 10.0)), false, "field 0.5"),
            (None, Some((50.0, 91.0)), false, "dip 91"),
            (None, Some((50.0, 10.0)), true, "not both"),
        ] {
            let e = orientation_request(&current, d, f, learn).unwrap_err();
            assert!(e.contains(says), "{e}");
        }
    }
}
