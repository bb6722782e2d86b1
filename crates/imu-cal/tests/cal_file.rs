//! The TOML calibration file: round trip, errors, and agreement of its device form with the
//! physical correction (≤ 1 LSB, the fixed-point bound of `device`).
#![allow(clippy::needless_range_loop)]
use imu_cal::device::{decode_blob, encode_blob, MAX_BLOB_LEN};
use imu_cal::file::CalFile;
use imu_cal::lab::{Params, SoftIron2d};

fn fitted_file() -> CalFile {
    let mut f = CalFile::default();
    f.set(
        "accel",
        &Params {
            offset: Some([0.42, -0.21, -1.1]),
            scale: Some([1.005, 0.997, 0.979]),
            misalignment_deg: Some([0.3, -0.2, 0.5]),
            ..Params::default()
        },
    )
    .unwrap();
    f.set(
        "gyro",
        &Params {
            bias: Some([-1.6022, 0.2899, 1.8464]),
            temp_coeff: Some([0.004, -0.003, 0.002]),
            temp_ref: Some(28.0),
            ..Params::default()
        },
    )
    .unwrap();
    f.set(
        "mag",
        &Params {
            hard_iron: Some([-7.7272842, -0.4699849, 1.3977473]),
            soft_iron: Some([
                [0.988, 0.034, 0.002],
                [0.034, 1.11, -0.047],
                [0.002, -0.047, 0.915],
            ]),
            soft_iron_2d: Some(SoftIron2d {
                r: 1.0,
                q: 1.0,
                theta_deg: 0.0,
                sigma: 1.0,
            }),
            ..Params::default()
        },
    )
    .unwrap();
    f
}

#[test]
fn toml_round_trip_and_blob() {
    let f = fitted_file();
    let text = f.to_toml();
    assert!(text.contains("[mag]") && text.contains("hard_iron"));
    let g = CalFile::from_toml(&text).unwrap();
    assert_eq!(f, g);
    let cal = g.to_device().unwrap();
    let mut buf = [0u8; MAX_BLOB_LEN];
    let blob = encode_blob(&cal, &mut buf).unwrap();
    assert_eq!(decode_blob(blob).unwrap(), cal);
}

#[test]
fn device_form_matches_physical_correction() {
    let f = fitted_file();
    let cal = f.to_device().unwrap();
    // Mag: out = s·S·(raw/s − h) in nominal LSB.
    let s = f.mag.lsb_per_unit;
    for raw in [
        [0i16, 0, 0],
        [1200, -3400, 560],
        [-32768, 32767, 100],
        [-927, -56, 168],
    ] {
        let out = cal.apply_mag(raw);
        for i in 0..3 {
            let mut e = 0.0;
            for j in 0..3 {
                e += f.mag.soft_iron[i][j] * (raw[j] as f64 / s - f.mag.hard_iron[j]) * s;
            }
            assert!(
                (out[i] as f64 - e).abs() <= 1.0,
                "mag {raw:?} axis {i}: {} vs {e}",
                out[i]
            );
        }
    }
    // Gyro at the reference temperature and 10 °C above it.
    let g = &f.gyro;
    for (t_c, raw) in [(28.0, [-210i16, 38, 242]), (38.0, [0, 0, 0])] {
        let t_raw = ((t_c - g.temp_offset_c) * g.temp_lsb_per_c).round() as i16;
        let out = cal.apply_gyro(raw, t_raw);
        let t_used = t_raw as f64 / g.temp_lsb_per_c + g.temp_offset_c;
        for i in 0..3 {
            let e = raw[i] as f64
                - (g.bias[i] + g.temp_coeff[i] * (t_used - g.temp_ref)) * g.lsb_per_unit;
            assert!(
                (out[i] as f64 - e).abs() <= 1.0,
                "gyro axis {i} at {t_c} °C: {} vs {e}",
                out[i]
            );
        }
    }
}

#[test]
fn malformed_files_are_rejected_with_the_place() {
    let text = fitted_file()
        .to_toml()
        .replace("lsb_per_unit = 131.0", "lsb_per_unit = \"x\"");
    let e = CalFile::from_toml(&text).unwrap_err().to_string();
    assert!(e.contains("lsb_per_unit") && e.contains("line"), "{e}");
    let e = CalFile::from_toml("version = 2\n").unwrap_err().to_string();
    assert!(e.contains("missing") || e.contains("version"), "{e}");
    let mut f = fitted_file();
    f.mag.soft_iron[0][0] = 9.0; // outside the device's fixed-point range
    assert!(f.to_device().is_err());
}

#[test]
fn gyro_scale_and_misalignment_reach_the_device() {
    let mut f = fitted_file();
    f.set(
        "gyro-rot",
        &Params {
            scale: Some([1.03, 0.97, 1.01]),
            gyro_misalignment_deg: Some([0.5, -0.3, 0.2, 0.8, -0.6, 0.1]),
            ..Params::default()
        },
    )
    .unwrap();
    // The TOML keeps them, and a file without them (older) still parses with identity.
    let text = f.to_toml();
    assert_eq!(CalFile::from_toml(&text).unwrap(), f);
    let cal = f.to_device().unwrap();
    let g = &f.gyro;
    let m = imu_cal::gyro_rot::correction_matrix(g.scale, g.misalignment_deg);
    let t_raw = ((g.temp_ref - g.temp_offset_c) * g.temp_lsb_per_c).round() as i16;
    let t_used = t_raw as f64 / g.temp_lsb_per_c + g.temp_offset_c;
    for raw in [[1000i16, -2000, 3000], [-32768, 32767, 0]] {
        let out = cal.apply_gyro(raw, t_raw);
        for i in 0..3 {
            let mut e = 0.0;
            for j in 0..3 {
                let o = (g.bias[j] + g.temp_coeff[j] * (t_used - g.temp_ref)) * g.lsb_per_unit;
                e += m[i][j] * (raw[j] as f64 - o);
            }
            assert!(
                (out[i] as f64 - e).abs() <= 1.0,
                "axis {i}: {} vs {e}",
                out[i]
            );
        }
    }
}

#[test]
fn a_calibration_fits_only_the_ranges_it_was_fitted_for() {
    let cal = fitted_file().to_device().unwrap();
    let fitted = cal.lsb_per_unit().unwrap();
    assert!(cal.fits_ranges(fitted));
    // The gyro at ±500 °/s (65.5 LSB per deg/s) instead of ±250 °/s.
    assert!(!cal.fits_ranges([fitted[0], 65.5, fitted[2]]));
    // 0.5 % off (rounding of the nominal sensitivities) still fits.
    assert!(cal.fits_ranges(fitted.map(|l| l * 1.005)));
    assert!(imu_cal::device::Calibration::identity().fits_ranges([1.0, 2.0, 3.0]));
    let mut buf = [0u8; MAX_BLOB_LEN];
    let back = decode_blob(encode_blob(&cal, &mut buf).unwrap()).unwrap();
    assert_eq!(back.lsb_per_unit(), Some(fitted));
}

/// `upload_blob` (what `imu-lab device calibrate --upload` and `pico_imu.Device.upload` send):
/// a plausible file becomes the blob the device decodes, the blob itself passes as a `.bin`.
mod upload {
    use imu_cal::file::{upload_blob, CalFile};
    use proptest::prelude::*;

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(32))]

        #[test]
        fn a_plausible_file_becomes_the_blob_the_device_decodes(
            bias in prop::array::uniform3(-50.0f64..50.0)
        ) {
            let mut f = CalFile::default();
            f.gyro.bias = bias;
            let blob = upload_blob(f.to_toml().as_bytes(), false).unwrap();
            prop_assert_eq!(&blob, &f.to_blob().unwrap());
            let cal = imu_cal::device::decode_blob(&blob).unwrap();
            // The offset the device subtracts: the bias in counts (131 LSB per deg/s).
            let c = cal.gyro().affine().folded_offset();
            for k in 0..3 {
                prop_assert!((c[k] - bias[k] * 131.0).abs() < 0.01, "{} vs {}", c[k], bias[k]);
            }
            prop_assert_eq!(upload_blob(&blob, true).unwrap(), blob);
        }

        #[test]
        fn an_implausible_scale_is_refused_naming_key_axis_and_bound(
            axis in 0usize..3,
            value in prop_oneof![1.1f64..2.0, 0.2f64..0.9],
        ) {
            let mut f = CalFile::default();
            f.accel.scale[axis] = value;
            let e = upload_blob(f.to_toml().as_bytes(), false).unwrap_err();
            prop_assert!(e.starts_with("refused, nothing uploaded: "), "{}", e);
            let key = format!("accel.scale[{axis}]");
            prop_assert!(e.contains(&key) && e.contains("0.91–1.09"), "{}", e);
        }

        #[test]
        fn a_blob_with_a_flipped_bit_is_refused(byte in 0usize..1000, bit in 0u8..8) {
            let mut blob = CalFile::default().to_blob().unwrap();
            let i = byte % blob.len();
            blob[i] ^= 1 << bit;
            let e = upload_blob(&blob, true).unwrap_err();
            prop_assert!(e.starts_with("refused, nothing uploaded: "), "{}", e);
        }
    }

    #[test]
    fn text_that_is_no_calibration_file_is_refused_saying_why() {
        let e = upload_blob(&[0xff, 0xfe, 0x00], false).unwrap_err();
        assert!(e.contains("not UTF-8"), "{e}");
        let e = upload_blob(b"version = 99\n", false).unwrap_err();
        assert!(e.contains("calibration file"), "{e}");
    }
}
