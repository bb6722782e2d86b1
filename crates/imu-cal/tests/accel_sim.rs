//! Simulated accelerometer recordings: hidden misalignment is found, and controls are adequate.
//!
//! Set-up: 40 static poses of 3 s at 100 Hz (6 faces + random), 1 s hand moves in between,
//! white noise σ = 0.02 m/s² per sample. A pose mean then has σ ≈ 0.0014 m/s², so with 40 poses
//! offsets are determined to ≈ 0.001 m/s², scales to ≈ 2e-4 and angles to ≈ 0.01°. 40 poses
//! leave 31 residual degrees of freedom for the 9 parameters of offset + scale + misalignment,
//! more than the 3 per parameter the lab needs to judge a model.
//! Tolerances (≈ 5–10 standard errors, so a failure means a real error, not bad luck):
//! offset 0.01 m/s², scale 2e-3, misalignment 0.1°.
mod common;
use common::*;
use imu_cal::accel::{detect_static, AccelProblem, StaticDetect, G_STANDARD};
use imu_cal::lab::{analyse, Effect};
use nalgebra::{Matrix3, Vector3};

fn problem(run: u64, mis_deg: [f64; 3]) -> (AccelProblem, usize) {
    let mut rng = Rng::new(run);
    let s = Vector3::new(1.02, 0.985, 1.01);
    let al = mis_deg.map(f64::to_radians);
    let t = Matrix3::new(1.0, 0.0, 0.0, al[0], 1.0, 0.0, al[1], al[2], 1.0);
    let tk = t * Matrix3::from_diagonal(&s);
    let d = tk.try_inverse().unwrap();
    let o = Vector3::new(0.35, -0.2, 0.5);
    let n_poses = 40;
    let rec = accel_recording(&mut rng, n_poses, 300, 100, d, o, 0.02, G_STANDARD);
    let poses = detect_static([&rec[0], &rec[1], &rec[2]], 100.0, StaticDetect::default()).unwrap();
    (AccelProblem::new(poses, G_STANDARD), n_poses)
}

#[test]
fn static_detection_finds_every_pose() {
    for run in 1..=4 {
        let (p, n) = problem(run, [0.0; 3]);
        assert_eq!(p.poses.len(), n, "run {run}");
        for pose in &p.poses {
            // Each pose holds 300 samples; detection trims at most the window at each end.
            assert!(
                pose.end - pose.start >= 200,
                "run {run}: short pose {pose:?}"
            );
        }
    }
}

#[test]
fn hidden_misalignment_is_diagnosed_and_recovered() {
    let truth = [1.5, -1.0, 2.0];
    for run in 1..=4 {
        let (p, _) = problem(run, truth);
        let r = analyse(&p, &[Effect::Offset, Effect::Scale]).unwrap();
        assert_missing(&r, Effect::Misalignment, run);
        let step = r.step.as_ref().unwrap();
        assert!(step.after.rms_residual < 0.2 * step.before.rms_residual);
        let r2 = next_adequate(&p, &r, run);
        let m = r2.model.fitted.params.misalignment_deg.unwrap();
        let ms = r2.model.fitted.sigma.misalignment_deg.unwrap();
        for k in 0..3 {
            assert!(
                (m[k] - truth[k]).abs() < 0.1,
                "run {run}: misalignment {m:?}"
            );
            // The reported uncertainty is the scatter's: the truth within 5σ, σ near 0.01°.
            assert!(
                (m[k] - truth[k]).abs() < 5.0 * ms[k] && (0.002..0.05).contains(&ms[k]),
                "run {run}: misalignment {m:?} ± {ms:?}"
            );
        }
        let o = r2.model.fitted.params.offset.unwrap();
        for (k, t) in [0.35, -0.2, 0.5].iter().enumerate() {
            assert!((o[k] - t).abs() < 0.01, "run {run}: offset {o:?}");
        }
        let s = r2.model.fitted.params.scale.unwrap();
        for (k, t) in [1.02, 0.985, 1.01].iter().enumerate() {
            assert!((s[k] - t).abs() < 2e-3, "run {run}: scale {s:?}");
        }
    }
}

#[test]
fn control_without_misalignment_is_adequate() {
    for run in 11..=14 {
        let (p, _) = problem(run, [0.0; 3]);
        let r = analyse(&p, &[Effect::Offset, Effect::Scale]).unwrap();
        assert_adequate(&r, run);
        assert_eq!(r.diagnosis.missing, None);
        // Residual RMS close to the floor: within a factor 1.5 (40 poses: the RMS of 34 d.o.f.
        // scatters by ≈ ±12 %).
        assert!(
            r.model.fitted.rms() < 1.5 * r.model.expected_rms,
            "run {run}"
        );
    }
}

#[test]
fn offset_only_model_misses_scale_or_is_flagged() {
    // Scale errors of 1.5–2 % are far above the noise: the offset-only model must not be
    // adequate, and the diagnosis must name scale (not misalignment, which is absent).
    for run in 21..=23 {
        let (p, _) = problem(run, [0.0; 3]);
        let r = analyse(&p, &[Effect::Offset]).unwrap();
        assert_missing(&r, Effect::Scale, run);
    }
}

/// 24 poses recorded back to back with no motion between them (concatenated pose files): the
/// detector splits the static run at every jump in the mean, at the exact sample. A control
/// with one noise spike inside a pose does not split it.
#[test]
fn abutting_poses_are_split_at_the_jump() {
    let mut rng = Rng::new(31);
    let rec = accel_recording(
        &mut rng,
        24,
        300,
        0,
        Matrix3::identity(),
        Vector3::zeros(),
        0.02,
        G_STANDARD,
    );
    let poses = detect_static([&rec[0], &rec[1], &rec[2]], 100.0, StaticDetect::default()).unwrap();
    assert_eq!(poses.len(), 24, "{poses:?}");
    for (k, p) in poses.iter().enumerate() {
        assert_eq!((p.start, p.end), (300 * k, 300 * (k + 1)), "pose {k}");
    }
    let p = AccelProblem::new(poses, G_STANDARD);
    let r = analyse(&p, &[Effect::Offset, Effect::Scale]).unwrap();
    assert!(r.model.adequate(), "{}", r.diagnosis.explanation);
}

/// The reported residual RMS is what the reported parameters give for the poses used, and
/// every fitted parameter has a positive uncertainty (g is given: 0).
#[test]
fn residual_recomputes_and_every_parameter_has_an_uncertainty() {
    let (p, _) = problem(41, [1.5, -1.0, 2.0]);
    for model in [
        vec![Effect::Offset, Effect::Scale],
        vec![Effect::Offset, Effect::Scale, Effect::Misalignment],
    ] {
        let r = analyse(&p, &model).unwrap();
        let f = &r.model.fitted;
        let s: Vec<f64> = p
            .poses
            .iter()
            .zip(&f.used)
            .filter(|(_, u)| **u)
            .map(|(pose, _)| AccelProblem::residual(&f.params, p.g, pose.mean).powi(2))
            .collect();
        let rms = (s.iter().sum::<f64>() / s.len() as f64).sqrt();
        assert!((rms / f.rms() - 1.0).abs() < 1e-9, "{rms} vs {}", f.rms());
        let sig = f.sigma.values();
        let (given, fitted) = sig.split_last().unwrap();
        assert_eq!(*given, 0.0, "g is given");
        assert!(fitted.iter().all(|v| v.is_finite() && *v > 0.0), "{sig:?}");
    }
}
