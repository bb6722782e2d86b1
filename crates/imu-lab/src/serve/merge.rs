//! What an upload from the page sends: the device's current calibration (read back with
//! `GetCalibration` before the offer and again before the upload) with only the fitted
//! sensor's part replaced, so a gyro bias, or the sensor the page did not fit, is kept bit for
//! bit (the kept corrections are the device's own fixed-point ones, not a round trip through
//! floats).
//!
//! The level turn (Jaime et al., eqs. 3–5: I. Jaime, F. Beck Ferrero, M. L. Miretti,
//! E. Bernardi, "Caracterización y calibración de unidades de medición inercial de bajo
//! costo") identifies only the horizontal plane: the corrected x and y come from the fit (the
//! in-plane hard iron and the soft iron's x and y rows, their z column zero: the fit says
//! nothing of a coupling from z), the corrected z from the device's current calibration (its
//! z hard iron and the soft iron's z row).
use imu_cal::device::plausible::Physical;
use imu_cal::device::{encode_blob, Calibration, MAX_BLOB_LEN};
use imu_cal::file::CalFile;

/// Which part of the calibration a fit replaces.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Section {
    /// The accelerometer's offset, scale and misalignment.
    Accel,
    /// The magnetometer's hard and soft iron (a fit of the sphere).
    Mag,
    /// The magnetometer's in-plane terms (x, y) of a level turn.
    MagPlane,
}

/// A merged calibration ready for the device, and what it changes and keeps, in words.
#[derive(Debug, Clone)]
pub struct Merged {
    pub cal: Calibration,
    pub blob: Vec<u8>,
    pub replaces: Vec<String>,
    pub keeps: Vec<String>,
}

/// The identity's parameters (no correction).
fn identity() -> Physical {
    let f = CalFile::default();
    f.physical()
}

/// A device calibration's parameters in the calibration file's units (identity for none).
pub fn physical(cal: &Calibration) -> Physical {
    match cal.fitted_for() {
        Some(f) => Physical::of(cal, f),
        None => identity(),
    }
}

fn v3(v: &[f64], digits: usize) -> String {
    let s: Vec<String> = v.iter().map(|x| format!("{x:.digits$}")).collect();
    format!("({})", s.join(", "))
}

fn m3(m: &[[f64; 3]; 3]) -> String {
    let rows: Vec<String> = m.iter().map(|r| v3(r, 4)).collect();
    format!("[{}]", rows.join(", "))
}

/// The accelerometer's part of `p`, in words.
fn accel_words(p: &Physical) -> String {
    format!(
        "the accelerometer's offset {} m/s², scale {}, misalignment {} deg",
        v3(&p.accel_offset, 4),
        v3(&p.accel_scale, 5),
        v3(&p.accel_misalignment_deg, 3)
    )
}

fn gyro_words(p: &Physical) -> String {
    format!(
        "the gyro's bias {} deg/s, temperature coefficient {} deg/s/°C, scale {}, \
         misalignment {} deg",
        v3(&p.gyro_bias, 4),
        v3(&p.gyro_temp_coeff, 5),
        v3(&p.gyro_scale, 5),
        v3(&p.gyro_misalignment_deg, 3)
    )
}

fn mag_words(p: &Physical) -> String {
    format!(
        "the magnetometer's hard iron {} µT and soft iron {}",
        v3(&p.hard_iron, 3),
        m3(&p.soft_iron)
    )
}

/// `device` with the part `section` names taken from `fit` (a calibration file holding the
/// fit's section; its other sections are not used). Refused — with the reason — when the
/// device's calibration was fitted for other parts or ranges than the file's (its kept
/// corrections would not mean the same), or when the result fails the datasheet bounds.
pub fn merge(device: &Calibration, fit: &CalFile, section: Section) -> Result<Merged, String> {
    let (imu, mag) = fit.parts();
    let lsb = [
        fit.accel.lsb_per_unit as f32,
        fit.gyro.lsb_per_unit as f32,
        fit.mag.lsb_per_unit as f32,
    ];
    if let Some(f) = device.fitted_for() {
        if f.imu != imu || f.mag != mag || !device.fits_ranges(lsb) {
            return Err(format!(
                "the device's calibration was fitted for {} and {} at {:?} LSB per unit, this \
                 fit for {} and {} at {lsb:?}: its kept sections would not mean the same; \
                 upload a whole calibration file with `imu-lab device calibrate --upload`",
                f.imu.name(),
                f.mag.name(),
                f.lsb_per_unit,
                imu.name(),
                mag.name()
            ));
        }
    }
    let dev = physical(device);
    let mut file = fit.clone();
    let mut replaces = Vec::new();
    let mut keeps = Vec::new();
    match section {
        Section::Accel => {
            replaces.push(accel_words(&fit.physical()));
            keeps.push(gyro_words(&dev));
            keeps.push(mag_words(&dev));
        }
        Section::Mag => {
            replaces.push(mag_words(&fit.physical()));
            keeps.push(accel_words(&dev));
            keeps.push(gyro_words(&dev));
        }
        Section::MagPlane => {
            // x and y from the fit (no coupling from z), z from the device
            let (h, s) = (fit.mag.hard_iron, fit.mag.soft_iron);
            file.mag.hard_iron = [h[0], h[1], dev.hard_iron[2]];
            file.mag.soft_iron = [
                [s[0][0], s[0][1], 0.0],
                [s[1][0], s[1][1], 0.0],
                dev.soft_iron[2],
            ];
            let m = &file.mag;
            replaces.push(format!(
                "the magnetometer's in-plane terms from this level turn: hard iron x, y = ({:.3}, \
                 {:.3}) µT, the soft iron's x and y rows {} and {} (their z column 0)",
                m.hard_iron[0],
                m.hard_iron[1],
                v3(&m.soft_iron[0], 4),
                v3(&m.soft_iron[1], 4)
            ));
            keeps.push(format!(
                "the magnetometer's out-of-plane terms (a level turn does not see them): hard \
                 iron z = {:.3} µT, the soft iron's z row {}",
                dev.hard_iron[2],
                v3(&dev.soft_iron[2], 4)
            ));
            keeps.push(accel_words(&dev));
            keeps.push(gyro_words(&dev));
        }
    }
    let new = file
        .to_device()
        .map_err(|e| format!("refused, not uploaded: {e}"))?;
    let fitted = *new
        .fitted_for()
        .ok_or("the fit's calibration records no parts")?;
    let cal = match section {
        Section::Accel => Calibration::fitted(*new.accel(), *device.gyro(), *device.mag(), fitted),
        Section::Mag | Section::MagPlane => {
            Calibration::fitted(*device.accel(), *device.gyro(), *new.mag(), fitted)
        }
    }
    .map_err(|e| format!("refused, not uploaded: {e}"))?;
    let mut buf = [0u8; MAX_BLOB_LEN];
    let blob = encode_blob(&cal, &mut buf)
        .map_err(|e| format!("encoding the blob: {e}"))?
        .to_vec();
    if blob.len() > imu_proto::MAX_CAL_BLOB {
        return Err(format!(
            "a blob of {} B exceeds the device's {} B",
            blob.len(),
            imu_proto::MAX_CAL_BLOB
        ));
    }
    Ok(Merged {
        cal,
        blob,
        replaces,
        keeps,
    })
}

/// A calibration's parameters as the page shows them (and the browser test reads back).
pub fn physical_json(cal: &Calibration) -> serde_json::Value {
    let p = physical(cal);
    serde_json::json!({
        "accel": { "offset": p.accel_offset, "scale": p.accel_scale,
                   "misalignment_deg": p.accel_misalignment_deg, "offset_unit": "m/s²" },
        "gyro": { "bias": p.gyro_bias, "temp_coeff": p.gyro_temp_coeff, "scale": p.gyro_scale,
                  "misalignment_deg": p.gyro_misalignment_deg, "bias_unit": "deg/s",
                  "temp_coeff_unit": "deg/s/°C" },
        "mag": { "hard_iron": p.hard_iron, "soft_iron": p.soft_iron, "hard_iron_unit": "µT" },
        "identity": cal.is_identity(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::serve::tests::rng;

    /// A plausible calibration file with every section drawn at random.
    fn drawn(u: &mut impl FnMut() -> f64) -> CalFile {
        let mut s = |a: f64| a * (2.0 * u() - 1.0);
        let mut f = CalFile::default();
        f.accel.offset = [s(0.5), s(0.5), s(0.5)];
        f.accel.scale = [1.0 + s(0.04), 1.0 + s(0.04), 1.0 + s(0.04)];
        f.accel.misalignment_deg = [s(0.5), s(0.5), s(0.5)];
        f.gyro.bias = [s(2.0), s(2.0), s(2.0)];
        f.mag.hard_iron = [s(40.0), s(40.0), s(40.0)];
        let (a, b, c) = (s(0.03), s(0.03), s(0.03));
        f.mag.soft_iron = [
            [1.0 + s(0.08), a, b],
            [a, 1.0 + s(0.08), c],
            [b, c, 1.0 + s(0.08)],
        ];
        f
    }

    /// The kept sections are the device's bit for bit, the replaced one the fit's: an
    /// accelerometer fit keeps the gyro and the magnetometer, a magnetometer fit the
    /// accelerometer and the gyro; an identity device keeps identity.
    #[test]
    fn an_upload_replaces_only_the_fitted_section() {
        let (key, mut u) = rng();
        let device = drawn(&mut u).to_device().unwrap();
        let fit = drawn(&mut u);
        let new = fit.to_device().unwrap();
        let m = merge(&device, &fit, Section::Mag).unwrap();
        assert_eq!(m.cal.accel(), device.accel(), "key {key}");
        assert_eq!(m.cal.gyro(), device.gyro(), "key {key}");
        assert_eq!(m.cal.mag(), new.mag(), "key {key}");
        assert_eq!(
            imu_cal::device::decode_blob(&m.blob).unwrap(),
            m.cal,
            "key {key}"
        );
        assert!(m.keeps.iter().any(|k| k.contains("gyro's bias")));
        let a = merge(&device, &fit, Section::Accel).unwrap();
        assert_eq!(a.cal.accel(), new.accel(), "key {key}");
        assert_eq!(a.cal.gyro(), device.gyro(), "key {key}");
        assert_eq!(a.cal.mag(), device.mag(), "key {key}");
        let i = merge(&Calibration::identity(), &fit, Section::Accel).unwrap();
        assert_eq!(i.cal.accel(), new.accel());
        assert_eq!(
            i.cal.gyro(),
            &imu_cal::device::GyroCorrection::IDENTITY,
            "key {key}"
        );
        assert_eq!(i.cal.mag(), &imu_cal::device::Affine::IDENTITY);
    }

    /// A level turn's upload: x and y of the corrected field are the fit's (the soft iron's x
    /// and y rows without a z column, the in-plane hard iron), z is the device's (its z hard
    /// iron and soft-iron row), the accelerometer and gyro the device's.
    #[test]
    fn a_level_turn_replaces_the_in_plane_terms_and_keeps_z() {
        let (key, mut u) = rng();
        let dev_file = drawn(&mut u);
        let device = dev_file.to_device().unwrap();
        let mut fit = CalFile::default();
        let (t, sg) = (1.2 * u() - 0.6, 0.9 + 0.1 * u());
        let (s, c) = t.sin_cos();
        // Rᵀ·diag(σ, 1)·R, as the planar fit reports it
        let r = [[c, s], [-s, c]];
        let mut s2 = [[0.0; 2]; 2];
        for (i, row) in s2.iter_mut().enumerate() {
            for (j, x) in row.iter_mut().enumerate() {
                *x = (0..2)
                    .map(|k| r[k][i] * if k == 0 { sg } else { 1.0 } * r[k][j])
                    .sum();
            }
        }
        fit.mag.hard_iron = [60.0 * u() - 30.0, 60.0 * u() - 30.0, 0.0];
        fit.mag.soft_iron = [
            [s2[0][0], s2[0][1], 0.0],
            [s2[1][0], s2[1][1], 0.0],
            [0.0, 0.0, 1.0],
        ];
        let m = merge(&device, &fit, Section::MagPlane).unwrap();
        assert_eq!(m.cal.accel(), device.accel(), "key {key}");
        assert_eq!(m.cal.gyro(), device.gyro(), "key {key}");
        let p = physical(&m.cal);
        let d = physical(&device);
        let close = |a: f64, b: f64, tol: f64| (a - b).abs() <= tol;
        for (k, row) in s2.iter().enumerate() {
            assert!(
                close(p.hard_iron[k], fit.mag.hard_iron[k], 1e-4),
                "key {key}: {:?}",
                p.hard_iron
            );
            for (j, x) in row.iter().enumerate() {
                assert!(close(p.soft_iron[k][j], *x, 1e-7), "key {key}");
            }
            assert_eq!(p.soft_iron[k][2], 0.0, "key {key}");
        }
        assert!(
            close(p.hard_iron[2], d.hard_iron[2], 1e-4),
            "key {key}: {} vs {}",
            p.hard_iron[2],
            d.hard_iron[2]
        );
        assert_eq!(p.soft_iron[2], d.soft_iron[2], "key {key}");
        assert!(m.keeps[0].contains("hard iron z"), "{:?}", m.keeps);
    }

    /// A device calibrated for another accelerometer range: its kept sections would not mean
    /// the same, so the merge is refused with both ranges named.
    #[test]
    fn a_device_fitted_for_other_ranges_is_refused() {
        let (_, mut u) = rng();
        let mut other = drawn(&mut u);
        other.accel.lsb_per_unit = 4096.0 / imu_cal::accel::G_STANDARD;
        let device = other.to_device().unwrap();
        let e = merge(&device, &drawn(&mut u), Section::Mag).unwrap_err();
        assert!(
            e.contains("fitted for") && e.contains("LSB per unit"),
            "{e}"
        );
    }
}
