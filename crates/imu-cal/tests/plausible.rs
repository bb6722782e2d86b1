//! The datasheet bounds (`imu_cal::device::plausible`): every parameter of the calibration file
//! is accepted inside its bound and refused outside it, naming the file key, the axis, the value
//! and the bound — by the host on the file (`CalFile::to_device`) and by the decoder the
//! firmware runs on the blob (`decode_blob`, values recovered from the fixed point); old files
//! and version-2 blobs; the bounds table of docs/calibration.md against the code.
use imu_cal::device::plausible::{bounds_table, mag_bounds, Key, F_MAX_UT, MPU_MARGIN};
use imu_cal::device::{
    decode_blob, encode_blob, Affine, BlobError, Calibration, GyroCorrection, ImuPart, MagPart,
    Refusal, BLOB_MAGIC, MAX_BLOB_LEN,
};
use imu_cal::file::CalFile;
use proptest::prelude::*;

/// Sets the parameter `key` on `axis` of a calibration file to a value.
type Set = fn(&mut CalFile, usize, f64);

/// Every per-axis file parameter with a fixed bound: key, number of axes, setter, bound of axis.
fn per_axis() -> Vec<(Key, usize, Set)> {
    vec![
        (Key::AccelScale, 3, |f, i, v| f.accel.scale[i] = v),
        (Key::AccelOffset, 3, |f, i, v| f.accel.offset[i] = v),
        (Key::AccelMisalignment, 3, |f, i, v| {
            f.accel.misalignment_deg[i] = v
        }),
        (Key::GyroScale, 3, |f, i, v| f.gyro.scale[i] = v),
        (Key::GyroBias, 3, |f, i, v| f.gyro.bias[i] = v),
        (Key::GyroTempCoeff, 3, |f, i, v| f.gyro.temp_coeff[i] = v),
        (Key::GyroMisalignment, 6, |f, i, v| {
            f.gyro.misalignment_deg[i] = v
        }),
        (Key::MagHardIron, 3, |f, i, v| f.mag.hard_iron[i] = v),
    ]
}

/// The bound of `key` on `axis` at the default file's ranges, from the datasheet figures as the
/// docs state them (not read from the code's table, so that a wrong table fails).
fn bound(key: Key, axis: usize) -> (f64, f64) {
    let g0 = 9.80665;
    let cross = MPU_MARGIN * 0.02_f64.to_degrees();
    let b = match key {
        Key::AccelScale | Key::GyroScale => return (1.0 - 0.09, 1.0 + 0.09),
        Key::AccelOffset if axis < 2 => 0.150 * g0,
        Key::AccelOffset => 0.240 * g0,
        Key::AccelMisalignment | Key::GyroMisalignment => cross,
        Key::GyroBias => 60.0,
        Key::GyroTempCoeff => 3.0 * 20.0 / 125.0,
        // ±2 G = 200 µT, less the strongest geomagnetic field through S = I.
        Key::MagHardIron => 200.0 - F_MAX_UT,
        _ => unreachable!(),
    };
    (-b, b)
}

/// The message a refusal must print.
fn message(key: Key, axis: Option<usize>, value: &str, bound: &str) -> String {
    let a = axis.map(|a| format!("[{a}]")).unwrap_or_default();
    format!(
        "{}{a} = {value}{} is outside {bound}{}",
        key.name(),
        key.unit(),
        key.unit()
    )
}

/// The refusal of `f` by the host (on the file's numbers) and by the device's decoder (on the
/// blob's fixed point, encoded without the check).
fn refusals(f: &CalFile) -> (Result<(), BlobError>, Result<(), BlobError>) {
    let host = f.to_device().map(|_| ());
    let device = f.to_device_unchecked().and_then(|c| {
        let mut buf = [0u8; MAX_BLOB_LEN];
        let blob = encode_blob(&c, &mut buf)?;
        decode_blob(blob).map(|_| ())
    });
    (host, device)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    /// A value drawn inside a bound is accepted by both; one drawn 0.5–100 % of the half-width
    /// beyond either end is refused by both with the key, axis, value and bound.
    #[test]
    fn every_bound_holds_on_the_host_and_on_the_device(
        which in 0usize..8, axis in 0usize..6, inside in 0.0f64..0.98, beyond in 0.005f64..1.0,
        above in any::<bool>(),
    ) {
        let (key, n, set) = per_axis()[which];
        let axis = axis % n;
        let (lo, hi) = bound(key, axis);
        let (mid, half) = ((lo + hi) / 2.0, (hi - lo) / 2.0);
        let sign = if above { 1.0 } else { -1.0 };
        let mut f = CalFile::default();
        set(&mut f, axis, mid + sign * inside * half);
        let (host, device) = refusals(&f);
        prop_assert!(host.is_ok(), "{key:?}[{axis}] inside: {host:?}");
        prop_assert!(device.is_ok(), "{key:?}[{axis}] inside, device: {device:?}");

        let value = mid + sign * (1.0 + beyond) * half;
        let mut f = CalFile::default();
        set(&mut f, axis, value);
        let (host, device) = refusals(&f);
        for (who, r, tol) in [("host", host, 0.0), ("device", device, 1e-6)] {
            match r {
                Err(BlobError::Implausible(Refusal { key: k, axis: a, value: v, lo: l, hi: h })) => {
                    prop_assert_eq!((k, a), (key, Some(axis as u8)), "{}", who);
                    prop_assert!((v - value).abs() <= tol * value.abs().max(1.0), "{who}: {v} vs {value}");
                    prop_assert!((l - lo).abs() < 1e-9 && (h - hi).abs() < 1e-9, "{who}: {l}–{h} vs {lo}–{hi}");
                }
                other => prop_assert!(false, "{who}: {key:?}[{axis}] = {value}: {other:?}"),
            }
        }
    }

    /// The soft iron: a condition number over 3 (gains inside) and a gain outside
    /// F_max/range–3 (condition 1) are refused naming `mag.soft_iron`, by both.
    #[test]
    fn soft_iron_conditioning_and_gain(k in 3.02f64..3.5, g_hi in 3.02f64..3.9, g_lo in 0.05f64..0.34) {
        let ((gain_lo, gain_hi), (_, cond_hi)) = mag_bounds(200.0);
        prop_assert!((gain_lo - F_MAX_UT / 200.0).abs() < 1e-12 && gain_hi == 3.0 && cond_hi == 3.0);
        let r = k.sqrt();
        for (s, key, value) in [
            ([[r, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0 / r]], Key::MagSoftIronCondition, k),
            ([[g_hi, 0.0, 0.0], [0.0, g_hi, 0.0], [0.0, 0.0, g_hi]], Key::MagSoftIronGain, g_hi),
            ([[g_lo, 0.0, 0.0], [0.0, g_lo, 0.0], [0.0, 0.0, g_lo]], Key::MagSoftIronGain, g_lo),
        ] {
            let mut f = CalFile::default();
            f.mag.soft_iron = s;
            let (host, device) = refusals(&f);
            for (who, r) in [("host", host), ("device", device)] {
                match r {
                    Err(BlobError::Implausible(x)) => {
                        prop_assert_eq!((x.key, x.axis), (key, None), "{}", who);
                        prop_assert!((x.value - value).abs() < 1e-6 * value, "{who}: {} vs {value}", x.value);
                    }
                    other => prop_assert!(false, "{who}: {s:?}: {other:?}"),
                }
            }
        }
    }

    /// A soft iron turned by any rotation, its gains and conditioning inside their bounds, is
    /// accepted by both (a board may turn the magnetometer against the MPU-6050); the same
    /// matrix with one axis flipped (a mirrored frame) is refused by both, naming the
    /// determinant.
    #[test]
    fn a_turned_soft_iron_passes_and_a_mirrored_one_is_refused(
        q in prop::array::uniform4(-1.0f64..1.0), g in prop::array::uniform3(0.6f64..1.7),
        flip in 0usize..3,
    ) {
        let n = q.iter().map(|v| v * v).sum::<f64>().sqrt();
        prop_assume!(n > 0.1);
        let [w, x, y, z] = q.map(|v| v / n);
        let r = [
            [1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - w * z), 2.0 * (x * z + w * y)],
            [2.0 * (x * y + w * z), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - w * x)],
            [2.0 * (x * z - w * y), 2.0 * (y * z + w * x), 1.0 - 2.0 * (x * x + y * y)],
        ];
        let s = [0, 1, 2].map(|i| [0, 1, 2].map(|j| r[i][j] * g[j]));
        let mut f = CalFile::default();
        f.mag.soft_iron = s;
        let (host, device) = refusals(&f);
        prop_assert!(host.is_ok() && device.is_ok(), "{s:?}: {host:?} / {device:?}");

        let mut m = s;
        for row in &mut m {
            row[flip] = -row[flip];
        }
        let det = -(g[0] * g[1] * g[2]);
        let mut f = CalFile::default();
        f.mag.soft_iron = m;
        let (host, device) = refusals(&f);
        for (who, r) in [("host", host), ("device", device)] {
            match r {
                Err(BlobError::Implausible(x)) => {
                    prop_assert_eq!((x.key, x.axis), (Key::MagSoftIronDeterminant, None), "{}", who);
                    prop_assert!((x.value - det).abs() < 1e-5, "{who}: {} vs {det}", x.value);
                    prop_assert!(x.lo > 0.0, "{who}: {}", x.lo);
                }
                other => prop_assert!(false, "{who}: {m:?}: {other:?}"),
            }
        }
    }

    /// A soft-iron entry that is not a number is refused by its place (NaN passes through the
    /// singular values as a number); the device cannot even hold it (no blob is made).
    #[test]
    fn a_soft_iron_entry_not_a_number_is_refused_by_its_place(
        at in 0usize..9, which in 0usize..3,
    ) {
        let v = [f64::NAN, f64::INFINITY, f64::NEG_INFINITY][which];
        let mut f = CalFile::default();
        f.mag.soft_iron[at / 3][at % 3] = v;
        let (host, device) = refusals(&f);
        match host {
            Err(BlobError::Implausible(x)) => {
                prop_assert_eq!((x.key, x.axis), (Key::MagSoftIron, Some(at as u8)));
                prop_assert!(!x.value.is_finite());
                prop_assert_eq!((x.lo, x.hi), (-3.0, 3.0));
            }
            other => prop_assert!(false, "[{at}] = {v}: {other:?}"),
        }
        prop_assert!(device.is_err(), "[{at}] = {v}: the device held it");
    }

    /// The gyro's temperature reference within the sensor's range and the offset within 10 °C
    /// of 36.53 °C are accepted; beyond either, refused naming it (by the host: the blob holds
    /// the reference in raw counts only).
    #[test]
    fn the_temperature_reference_and_offset_are_bounded(
        inside in -0.98f64..0.98, beyond in 0.005f64..1.0, above in any::<bool>(), offset in any::<bool>(),
    ) {
        let (key, lo, hi) = if offset {
            (Key::GyroTempOffset, 26.53, 46.53)
        } else {
            (Key::GyroTempRef, -40.0, 85.0)
        };
        let set = |f: &mut CalFile, v: f64| {
            if offset {
                f.gyro.temp_offset_c = v
            } else {
                f.gyro.temp_ref = v
            }
        };
        let (mid, half) = ((lo + hi) / 2.0, (hi - lo) / 2.0);
        let mut f = CalFile::default();
        set(&mut f, mid + inside * half);
        prop_assert!(f.to_device().is_ok(), "{key:?} = {}", mid + inside * half);
        let value = mid + if above { 1.0 } else { -1.0 } * (1.0 + beyond) * half;
        let mut f = CalFile::default();
        set(&mut f, value);
        match f.to_device() {
            Err(BlobError::Implausible(x)) => {
                prop_assert_eq!((x.key, x.axis, x.value), (key, None, value));
                prop_assert!((x.lo - lo).abs() < 1e-9 && (x.hi - hi).abs() < 1e-9);
            }
            other => prop_assert!(false, "{key:?} = {value}: {other:?}"),
        }
    }
}

/// The messages of the checks that are the host's alone or that the fixed point cannot carry:
/// a NaN soft-iron entry, a mirrored soft iron, a temperature reference out of range, and a
/// huge value in short form.
#[test]
fn the_host_only_refusals_read_as_quoted() {
    type Edit = fn(&mut CalFile);
    let cases: [(Edit, &str); 4] = [
        (
            |f| f.mag.soft_iron[0][1] = f64::NAN,
            "mag.soft_iron[0][1] = NaN is outside ±3",
        ),
        (
            |f| f.mag.soft_iron[2][2] = -1.0,
            "mag.soft_iron determinant = −1 is outside 0.04287–27",
        ),
        (
            |f| f.gyro.temp_ref = 120.0,
            "gyro.temp_ref = 120 °C is outside −40–85 °C",
        ),
        (
            |f| f.mag.hard_iron[0] = 1e30,
            "mag.hard_iron[0] = 1e30 µT is outside ±130 µT",
        ),
    ];
    for (edit, want) in cases {
        let mut f = CalFile::default();
        edit(&mut f);
        assert_eq!(f.to_device().unwrap_err().to_string(), want);
    }
}

/// The refusals the users quoted, word for word: a 1.9 accelerometer scale, a zero scale, a
/// soft iron of zeros, an 89° misalignment.
#[test]
fn the_quoted_refusals_name_key_axis_value_and_bound() {
    type Edit = fn(&mut CalFile);
    let cases: [(Edit, String); 5] = [
        (
            |f| f.accel.scale = [1.9, 1.0, 1.0],
            message(Key::AccelScale, Some(0), "1.9", "0.91–1.09"),
        ),
        (
            |f| f.accel.scale = [1.0, 0.0, 1.0],
            message(Key::AccelScale, Some(1), "0", "0.91–1.09"),
        ),
        (
            |f| f.mag.soft_iron = [[0.0; 3]; 3],
            message(Key::MagSoftIronCondition, None, "∞", "1–3"),
        ),
        (
            |f| f.accel.misalignment_deg = [89.0, 0.0, 0.0],
            message(Key::AccelMisalignment, Some(0), "89", "±3.438"),
        ),
        (
            |f| f.gyro.bias = [0.0, 0.0, -200.0],
            message(Key::GyroBias, Some(2), "−200", "±60"),
        ),
    ];
    for (edit, want) in &cases {
        let mut f = CalFile::default();
        edit(&mut f);
        let (host, device) = refusals(&f);
        assert_eq!(host.unwrap_err().to_string(), *want);
        assert_eq!(device.unwrap_err().to_string(), *want, "device");
    }
    // A sensitivity that is no range of the part.
    let mut f = CalFile::default();
    f.accel.lsb_per_unit = 900.0;
    let e = f.to_device().unwrap_err();
    assert_eq!(
        e,
        BlobError::NoRange {
            key: Key::AccelLsbPerUnit,
            value: 900.0
        }
    );
    assert!(e
        .to_string()
        .starts_with("accel.lsb_per_unit = 900 LSB per m/s² is none"));
    // The gyro at 100 LSB per deg/s and the magnetometer at 50 LSB per µT are no ranges either;
    // ±500 °/s (65.5) and ±8 G (30 LSB per µT) are.
    for (gyro, mag, bad) in [
        (100.0, 120.0, Some((Key::GyroLsbPerUnit, 100.0))),
        (131.0, 50.0, Some((Key::MagLsbPerUnit, 50.0))),
        (65.5, 30.0, None),
    ] {
        let mut f = CalFile::default();
        f.gyro.lsb_per_unit = gyro;
        f.mag.lsb_per_unit = mag;
        match (f.to_device(), bad) {
            (Err(BlobError::NoRange { key, value }), Some((k, v))) => {
                assert_eq!((key, value), (k, v))
            }
            (Ok(cal), None) => {
                let r = cal.fitted_for().unwrap().ranges;
                assert_eq!((r.gyro_dps, r.mag_ut), (500, 800));
            }
            other => panic!("{gyro}, {mag}: {other:?}"),
        }
    }
    let mut f = CalFile::default();
    f.gyro.temp_lsb_per_c = 0.0;
    assert!(matches!(
        f.to_device(),
        Err(BlobError::NoRange {
            key: Key::GyroTempLsbPerC,
            ..
        })
    ));
}

/// A file written before the `part` keys loads as MPU-6050 + QMC5883L, converts, and names
/// the parts once the lab writes it again.
#[test]
fn a_file_without_parts_loads_as_the_default_parts() {
    let text = CalFile::default().to_toml();
    let old: String = text
        .lines()
        .filter(|l| !l.starts_with("part ="))
        .map(|l| format!("{l}\n"))
        .collect();
    assert!(!old.contains("part") && text.contains("part = \"MPU-6050\""));
    let mut f = CalFile::from_toml(&old).unwrap();
    assert_eq!(f.accel.part, None);
    assert_eq!(f.parts(), (ImuPart::Mpu6050, MagPart::Qmc5883l));
    let cal = f.to_device().unwrap();
    let fitted = cal.fitted_for().unwrap();
    assert_eq!(
        (fitted.imu, fitted.mag),
        (ImuPart::Mpu6050, MagPart::Qmc5883l)
    );
    assert_eq!(
        (
            fitted.ranges.accel_g,
            fitted.ranges.gyro_dps,
            fitted.ranges.mag_ut
        ),
        (4, 250, 200)
    );
    f.set("gyro", &imu_cal::lab::Params::default()).unwrap();
    assert!(f.to_toml().contains("part = \"QMC5883L\""));
    // A part this build has no datasheet for is refused by the parser, with the place.
    let e = CalFile::from_toml(&text.replacen("MPU-6050", "BMI160", 1))
        .unwrap_err()
        .to_string();
    assert!(e.contains("BMI160") && e.contains("line"), "{e}");
}

/// Version-2 blobs (sensitivities, no parts) still load when they are plausible, with the parts
/// assumed; an implausible one (the old bounds let a 1.9 scale through) is refused naming it;
/// one without sensitivities that is not identity is refused as not fitted.
#[test]
fn version_2_blobs_load_or_are_refused_with_the_reason() {
    #[derive(serde::Serialize)]
    struct V2 {
        accel: Affine,
        gyro: GyroCorrection,
        mag: Affine,
        lsb_per_unit: Option<[f32; 3]>,
    }
    fn v2_blob(cal: &Calibration, lsb: Option<[f32; 3]>) -> Vec<u8> {
        let mut buf = [0u8; MAX_BLOB_LEN];
        let p = postcard::to_slice(
            &V2 {
                accel: *cal.accel(),
                gyro: *cal.gyro(),
                mag: *cal.mag(),
                lsb_per_unit: lsb,
            },
            &mut buf,
        )
        .unwrap();
        let mut b = BLOB_MAGIC.to_vec();
        b.extend_from_slice(&2u16.to_le_bytes());
        b.extend_from_slice(&(p.len() as u16).to_le_bytes());
        b.extend_from_slice(p);
        let crc = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC).checksum(&b);
        b.extend_from_slice(&crc.to_le_bytes());
        b
    }
    let mut f = CalFile::default();
    f.accel.scale = [1.02, 0.99, 0.98];
    f.mag.hard_iron = [-20.0, 5.0, 12.0];
    let good = f.to_device().unwrap();
    let lsb = good.lsb_per_unit();
    let back = decode_blob(&v2_blob(&good, lsb)).unwrap();
    assert_eq!(back.accel(), good.accel());
    let fitted = back.fitted_for().unwrap();
    assert!(fitted.parts_assumed);
    assert_eq!(fitted.ranges, good.fitted_for().unwrap().ranges);

    f.accel.scale = [1.9, 1.0, 1.0];
    let bad = f.to_device_unchecked().unwrap();
    let e = decode_blob(&v2_blob(&bad, lsb)).unwrap_err();
    assert_eq!(
        e.to_string(),
        message(Key::AccelScale, Some(0), "1.9", "0.91–1.09")
    );
    assert_eq!(decode_blob(&v2_blob(&bad, None)), Err(BlobError::NotFitted));
    let id = Calibration::identity();
    assert_eq!(decode_blob(&v2_blob(&id, None)), Ok(id));
}

/// The bounds table of docs/calibration.md is the code's, character for character.
#[test]
fn the_documented_bounds_are_the_code_bounds() {
    let doc = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../docs/calibration.md"
    ))
    .unwrap();
    let table = bounds_table();
    assert!(
        doc.contains(&table),
        "docs/calibration.md does not hold the bounds table of the code; it should read:\n{table}"
    );
    // And once only: docs/firmware.md refers to it instead of repeating numbers.
    let fw = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../docs/firmware.md"
    ))
    .unwrap();
    assert!(!fw.contains("0.91–1.09") && fw.contains("calibration.md#plausibility"));
}

/// A version-3 blob (the magnetometer's range in gauss) reads as the same ranges as the
/// version-4 blob of the same file, at either QMC5883L range.
#[test]
fn a_version_3_blob_reads_its_magnetometer_range_in_gauss() {
    for lsb in [120.0, 30.0] {
        let mut f = CalFile::default();
        f.mag.lsb_per_unit = lsb;
        f.mag.hard_iron = [-20.0, 5.0, 12.0];
        let cal = f.to_device().unwrap();
        let mut buf = [0u8; MAX_BLOB_LEN];
        let v4 = encode_blob(&cal, &mut buf).unwrap().to_vec();
        let ut = cal.fitted_for().unwrap().ranges.mag_ut;
        // The payload ends with the range's varint and the three f32 sensitivities.
        let payload = &v4[8..v4.len() - 4];
        let tail = payload.len() - 12;
        let varint = [(ut & 0x7f) as u8 | 0x80, (ut >> 7) as u8];
        assert_eq!(&payload[tail - 2..tail], &varint, "{ut} µT");
        let mut p3 = payload[..tail - 2].to_vec();
        p3.push((ut / 100) as u8);
        p3.extend_from_slice(&payload[tail..]);
        let mut b = BLOB_MAGIC.to_vec();
        b.extend_from_slice(&3u16.to_le_bytes());
        b.extend_from_slice(&(p3.len() as u16).to_le_bytes());
        b.extend_from_slice(&p3);
        let crc = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC).checksum(&b);
        b.extend_from_slice(&crc.to_le_bytes());
        let back = decode_blob(&b).unwrap();
        assert_eq!(back.fitted_for(), cal.fitted_for(), "{lsb} LSB per µT");
        assert_eq!(
            back.fitted_for().unwrap().ranges.mag_gauss(),
            f64::from(ut) / 100.0
        );
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]
    /// An HMC5883L file converts at each of its eight gain settings, records the part and the
    /// range, survives its TOML, and is judged by that range's bounds: a hard iron just inside
    /// `range − F_max` passes and just outside is refused naming the key.
    #[test]
    fn an_hmc5883l_file_is_judged_at_its_own_range(gain in 0usize..8, axis in 0usize..3, inside in 0.05f64..0.95) {
        let part = MagPart::Hmc5883l;
        let (range_ut, lsb_per_gauss) = part.ranges()[gain];
        let mut f = CalFile::default();
        f.mag.lsb_per_unit = 120.0;
        f.set_mag_part(part);
        // A QMC5883L sensitivity is none of the HMC5883L's: the power-on gain's (1090 LSB/G).
        prop_assert_eq!(f.mag.lsb_per_unit, 10.9);
        f.mag.lsb_per_unit = lsb_per_gauss / 100.0;
        f.set_mag_part(part);
        prop_assert_eq!(f.mag.lsb_per_unit, lsb_per_gauss / 100.0);
        let back = CalFile::from_toml(&f.to_toml()).unwrap();
        prop_assert!(f.to_toml().contains("part = \"HMC5883L\""));
        prop_assert_eq!(back.parts(), (ImuPart::Mpu6050, part));
        let bound = f64::from(range_ut) - F_MAX_UT;
        let mut ok = back.clone();
        ok.mag.hard_iron[axis] = inside * bound;
        let cal = ok.to_device().unwrap();
        let fitted = cal.fitted_for().unwrap();
        prop_assert_eq!((fitted.mag, fitted.ranges.mag_ut), (part, range_ut));
        let mut bad = back;
        bad.mag.hard_iron[axis] = -(1.0 + inside) * bound;
        match bad.to_device() {
            Err(BlobError::Implausible(r)) => {
                prop_assert_eq!(r.key, Key::MagHardIron);
                prop_assert_eq!(r.axis, Some(axis as u8));
            }
            other => prop_assert!(false, "{:?}", other),
        }
    }
}

/// Part names as the calibration file and `--part` write them, in any case.
#[test]
fn magnetometer_parts_are_found_by_name() {
    for p in MagPart::ALL {
        assert_eq!(MagPart::from_name(&p.name().to_lowercase()), Some(p));
    }
    assert_eq!(MagPart::from_name("HMC5983"), None);
}

/// Naming the part keeps a sensitivity that is not a number, so that the conversion refuses it
/// by its key instead of a default standing in for it.
#[test]
fn naming_the_part_keeps_a_non_finite_sensitivity_for_the_refusal() {
    for bad in [f64::NAN, f64::INFINITY] {
        let mut f = CalFile::default();
        f.mag.lsb_per_unit = bad;
        f.set_mag_part(MagPart::Hmc5883l);
        assert!(matches!(
            f.to_device(),
            Err(BlobError::NoRange {
                key: Key::MagLsbPerUnit,
                ..
            })
        ));
    }
}
