//! The real recordings (tests/data, see PROVENANCE.md).
mod common;
use imu_cal::accel::{detect_static, AccelProblem, StaticDetect, G_STANDARD};
use imu_cal::lab::{analyse, Effect, Verdict};
use imu_cal::mag::MagProblem;
use nalgebra::Vector3;

/// Read every column of a recording (after `skip` metadata lines) with the contract's reader.
fn read_csv(path: &str, skip: usize) -> (Vec<String>, Vec<Vec<f64>>) {
    let full = format!("{}/tests/data/{path}", env!("CARGO_MANIFEST_DIR"));
    let file = std::fs::File::open(&full).expect("test data");
    let opts = imu_proto::csv::ReadOptions {
        skip_lines: skip,
        renames: vec![],
    };
    let mut r = imu_proto::csv::Reader::new(file, &full, &opts).unwrap();
    let header: Vec<String> = r.header().iter().map(|c| c.name.clone()).collect();
    let names: Vec<&str> = header.iter().map(String::as_str).collect();
    // The file's own columns, in its order (no `t` or `gap_before` of the contract among them).
    let got = r.select(&names, &[]).unwrap();
    assert_eq!(got, header);
    let mut cols = vec![Vec::new(); header.len()];
    let mut row = vec![0.0; header.len()];
    while r.next_row(&mut row).unwrap() {
        for (c, v) in cols.iter_mut().zip(&row) {
            c.push(*v);
        }
    }
    (header, cols)
}

const LSB_PER_G: f64 = 16384.0;

fn multipose() -> AccelProblem {
    let (_, c) = read_csv("mpu6050-static/multipose_calibration.csv", 4);
    let k = G_STANDARD / LSB_PER_G;
    let a: Vec<Vec<f64>> = (0..3)
        .map(|j| c[j].iter().map(|v| v * k).collect())
        .collect();
    let poses = detect_static([&a[0], &a[1], &a[2]], 100.0, StaticDetect::default()).unwrap();
    AccelProblem::new(poses, G_STANDARD)
}

/// The multi-pose run (10 static poses: the 36.5 s initial rest + 9 poses) against the
/// upstream repository's own fit. Upstream's model is `a = T·S_up·(raw + b_up)` with S_up in
/// m/s² per LSB and b_up in LSB (its signs are the opposite of our `o`); converted to our
/// parameters: `scale = S_up / (g/16384)`, `offset = −b_up · g/16384`.
/// Agreement we state and assert: scale within 1.5e-3 (0.15 %), offset within 20 LSB
/// (1.2 mg, 0.012 m/s²); measured: Δscale ≤ 6e-4, Δoffset ≤ 9 LSB. Ten poses leave 4 residual
/// degrees of freedom for the 6 parameters of offset + scale, and every parameter is determined
/// far within its plausible range (σ ≤ 0.003 m/s² against ±0.98 m/s², ≤ 4e-4 against ±0.1), so
/// the model is judged on its residual: at the floor (P ≈ 0.07), adequate. With misalignment
/// too (9 parameters, 1 degree of freedom) the x scale (σ 0.01) and two angles (σ 5.1° and
/// 0.3°) are not: underdetermined, and those are named.
#[test]
fn multipose_accelerometer_vs_upstream() {
    let p = multipose();
    assert_eq!(p.poses.len(), 10, "poses {:?}", p.poses);
    let r = analyse(&p, &[Effect::Offset, Effect::Scale]).unwrap();
    eprintln!("{}", r.diagnosis.explanation);
    assert!(
        r.model.verdict == Verdict::Adequate && r.model.unidentified.is_empty(),
        "{}",
        r.diagnosis.explanation
    );
    assert_eq!(r.diagnosis.missing, None);
    // Residual: 4 mg-level at most (measured 0.0041 m/s²).
    assert!(r.model.fitted.rms() < 0.01, "rms {}", r.model.fitted.rms());
    let r9 = analyse(&p, &[Effect::Offset, Effect::Scale, Effect::Misalignment]).unwrap();
    eprintln!("{}", r9.diagnosis.explanation);
    assert_eq!(r9.model.verdict, Verdict::Underdetermined);
    let named = r9.model.unidentified.join(", ");
    assert!(
        named.contains("misalignment_deg.x") && !named.contains("offset"),
        "{named}"
    );
    // Offset alone is far off the floor: not adequate (whatever the degrees of freedom), and
    // scale is named.
    let r3 = analyse(&p, &[Effect::Offset]).unwrap();
    assert_eq!(r3.model.verdict, Verdict::NotAdequate);
    assert_eq!(r3.diagnosis.missing, Some(Effect::Scale));
    let ms = r9.model.fitted.sigma.misalignment_deg.unwrap();
    assert!(ms.iter().all(|v| v.is_finite() && *v > 0.0), "{ms:?}");

    // Nine values, one per line: misalignment ×3 (rad), scale ×3 (m/s² per LSB), bias ×3 (LSB).
    let text = std::fs::read_to_string(format!(
        "{}/tests/data/mpu6050-static/upstream_params_acc.csv",
        env!("CARGO_MANIFEST_DIR")
    ))
    .unwrap();
    let up: Vec<f64> = text
        .lines()
        .filter(|l| !l.trim().is_empty())
        .map(|l| l.trim().parse().unwrap())
        .collect();
    assert_eq!(up.len(), 9);
    let k = G_STANDARD / LSB_PER_G;
    let s = r.model.fitted.params.scale.unwrap();
    let o = r.model.fitted.params.offset.unwrap();
    for j in 0..3 {
        let s_up = up[3 + j] / k;
        let o_up_lsb = -up[6 + j];
        let o_lsb = o[j] / k;
        eprintln!(
            "axis {j}: scale {:.5} vs upstream {:.5}; offset {:.1} vs upstream {:.1} LSB",
            s[j], s_up, o_lsb, o_up_lsb
        );
        assert!(
            (s[j] - s_up).abs() < 1.5e-3,
            "axis {j} scale {} vs {}",
            s[j],
            s_up
        );
        assert!(
            (o_lsb - o_up_lsb).abs() < 20.0,
            "axis {j} offset {o_lsb} vs {o_up_lsb} LSB"
        );
    }
}

/// The HMC5883L columns of a recording (in G) as a magnetometer problem in µT.
fn hmc5883l(recording: &str) -> MagProblem {
    let (_, c) = read_csv(&format!("{recording}/hmc5883l.csv"), 0);
    let m: Vec<Vector3<f64>> = (0..c[0].len())
        .map(|i| Vector3::new(c[1][i], c[2][i], c[3][i]) * 100.0)
        .collect();
    MagProblem::new(m, None).unwrap()
}

fn tilt_sphere() -> MagProblem {
    hmc5883l("mpu6050-hmc5883l-tilt-sphere")
}

/// tilt-sphere: hard iron alone leaves a 3 µT residual; the lab names soft_iron (3-D data, so
/// not soft_iron_2d); the ellipsoid fit brings it to ≈ 0.44 µT. The remaining excess over the
/// 0.17 µT floor is reported, not hidden. Reference (shared/reference README, a quick fit):
/// centre (−0.004, 0.056, −0.206) G = (−0.4, 5.6, −20.6) µT, radii 59/54/47 µT; asserted within
/// 0.5 µT (centre) and 2 µT (radii: the README gives two digits).
#[test]
fn tilt_sphere_soft_iron() {
    let p = tilt_sphere();
    assert!(
        p.plane.is_none(),
        "tilt-sphere must be 3-D: sd {:?}",
        p.principal_sd
    );
    let r0 = analyse(&p, &[Effect::HardIron]).unwrap();
    eprintln!("{}", r0.diagnosis.explanation);
    assert!(!r0.model.adequate());
    assert_eq!(r0.diagnosis.missing, Some(Effect::SoftIron));
    let step = r0.step.as_ref().unwrap();
    assert!(
        step.before.rms_residual > 2.0 && step.after.rms_residual < 0.6,
        "{step:?}"
    );
    let r1 = analyse(&p, r0.next().unwrap().effects()).unwrap();
    eprintln!("{}", r1.diagnosis.explanation);
    // The catalogue is exhausted: nothing more is proposed.
    assert_eq!(r1.diagnosis.missing, None);
    let h = r1.model.fitted.params.hard_iron.unwrap();
    for (k, t) in [-0.4, 5.6, -20.6].iter().enumerate() {
        assert!((h[k] - t).abs() < 0.5, "hard iron {h:?}");
    }
    // Radii of the fitted ellipsoid: F / eigenvalues of S.
    let s = nalgebra::Matrix3::from_row_slice(&r1.model.fitted.params.soft_iron.unwrap().concat());
    let f = r1.model.fitted.params.field.unwrap();
    let mut radii: Vec<f64> = s
        .symmetric_eigen()
        .eigenvalues
        .iter()
        .map(|l| f / l)
        .collect();
    radii.sort_by(|a, b| b.total_cmp(a));
    eprintln!("radii {radii:?} µT, F {f} µT");
    for (r, t) in radii.iter().zip([59.0, 54.0, 47.0]) {
        assert!((r - t).abs() < 2.0, "radii {radii:?}");
    }
}

/// Gyro on the same multi-pose run. Bias at rest (Jaime et al., eq. 2) against upstream's bias
/// (−427.46, 147.95, −80.72 LSB, same sign convention as the raw counts): within 8 LSB
/// (0.06 deg/s; measured ≤ 4.7 LSB). Scale/misalignment from the rotations: 3 of the 9 moves
/// saturate the ±250 °/s gyro and are skipped; on the other 6 the integrated turns miss the
/// gravity direction by ≈ 6.6° RMS and neither scale nor misalignment explains it
/// (not significant) — the moves are too fast for 100 Hz sampling. The lab must say so rather
/// than report a scale: upstream's scale (1.031, 0.998, 1.005) is not reproducible from these
/// moves by our method, and we assert that the verdict is "not adequate, nothing missing".
#[test]
fn multipose_gyro_bias_and_rotations() {
    let (_, c) = read_csv("mpu6050-static/multipose_calibration.csv", 4);
    let k = G_STANDARD / LSB_PER_G;
    let a: Vec<Vec<f64>> = (0..3)
        .map(|j| c[j].iter().map(|v| v * k).collect())
        .collect();
    let g: Vec<Vec<f64>> = (3..6)
        .map(|j| c[j].iter().map(|v| v / 131.0).collect())
        .collect();
    let poses = detect_static([&a[0], &a[1], &a[2]], 100.0, StaticDetect::default()).unwrap();
    let p = imu_cal::gyro_rot::GyroRotProblem::new(
        [&a[0], &a[1], &a[2]],
        [&g[0], &g[1], &g[2]],
        100.0,
        &poses,
        Some(32767.0 / 131.0 - 0.01),
    )
    .unwrap();
    assert_eq!((p.moves.len(), p.skipped_saturated), (6, 3));
    for (j, up) in [-427.46, 147.95, -80.72].iter().enumerate() {
        let ours = p.bias[j] * 131.0;
        assert!(
            (ours - up).abs() < 8.0,
            "axis {j}: bias {ours} LSB vs upstream {up}"
        );
    }
    let r = analyse(&p, &[]).unwrap();
    eprintln!("{}", r.diagnosis.explanation);
    assert!(!r.model.adequate());
    assert_eq!(r.diagnosis.missing, None);
    assert!(r.model.fitted.rms() > 3.0, "rms {}", r.model.fitted.rms());
}

fn rotate_z() -> MagProblem {
    hmc5883l("mpu6050-hmc5883l-rotate-z")
}

/// A real hand-held 360° turn: planar data (the x–z plane of this board), whose in-plane
/// magnitude follows the out-of-plane component (correlation ≈ +0.68): the lab names tilt first
/// (residual 2.04 → 0.25 µT, measured), not soft iron; then, on top of it, the in-plane soft
/// iron that the tilt sphere of the same board shows (0.25 → 0.18 µT against a 0.135 µT floor:
/// still not adequate, and said so). Asserted: the order, and each drop to within 20 %.
#[test]
fn real_level_turn_is_tilt_then_soft_iron() {
    let p = rotate_z();
    assert_eq!(p.plane, Some([0, 2]), "{:?}", p.principal_sd);
    let r0 = analyse(&p, &[Effect::HardIron]).unwrap();
    eprintln!("{}", r0.diagnosis.explanation);
    assert_eq!(r0.diagnosis.missing, Some(Effect::Tilt));
    let s0 = r0.step.as_ref().unwrap();
    assert!((s0.before.rms_residual / 2.04 - 1.0).abs() < 0.2, "{s0:?}");
    assert!((s0.after.rms_residual / 0.252 - 1.0).abs() < 0.2, "{s0:?}");
    let r1 = analyse(&p, r0.next().unwrap().effects()).unwrap();
    eprintln!("{}", r1.diagnosis.explanation);
    assert_eq!(r1.diagnosis.missing, Some(Effect::SoftIron2d));
    let s1 = r1.step.as_ref().unwrap();
    assert!((s1.after.rms_residual / 0.177 - 1.0).abs() < 0.2, "{s1:?}");
    let r2 = analyse(&p, r1.next().unwrap().effects()).unwrap();
    assert!(!r2.model.adequate() && r2.diagnosis.missing.is_none());
}
