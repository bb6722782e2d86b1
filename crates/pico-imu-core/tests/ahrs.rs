//! The device's AHRS (`pico_imu_core::ahrs`) against the truth of simulated trajectories
//! (`imu_sim::trajectory`): static at random attitudes, constant-rate turns, tilts, the
//! emulator's standard run; hard iron with no calibration; a magnetic disturbance; the
//! declination; and micromath's functions against libm on the values that matter.
//!
//! The parameters are drawn at random for every run (the generator's start is printed, and
//! `AHRS_TEST_SEED=N` repeats a run).
use imu_sim::trajectory::{angle_diff, reading, Euler, Part, Trajectory};
use imu_sim::Rng;
use pico_imu_core::ahrs::{
    Accum, Ahrs, AhrsState, Attitude, GyroStep, CONVERGED_ERR2, REDIVERGED_ERR2,
};

fn seed() -> u64 {
    std::env::var("AHRS_TEST_SEED")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or_else(|| {
            std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map(|d| d.as_nanos() as u64)
                .unwrap_or(1)
        })
}

/// Errors of one run against the truth, degrees rms, from `from_s` on.
#[derive(Debug)]
struct Errors {
    roll: f64,
    pitch: f64,
    heading: f64,
    /// First time the filter reported anything but `Converging`, s.
    converged_s: Option<f64>,
    /// The time from which it never reported `Converging` again, s.
    settled_s: Option<f64>,
    states: Vec<AhrsState>,
}

/// Runs the filter on `traj` read by `part` for `seconds`: 1 kHz IMU samples in bursts of 10,
/// then the two 200 Hz magnetometer samples of those 10 ms (the device's order). `field` scales
/// the magnetometer between the given times (a disturbance).
fn run(
    traj: &Trajectory,
    part: &Part,
    seconds: f64,
    from_s: f64,
    rng: &mut Rng,
    ahrs: &mut Ahrs,
    field: Option<(f64, f64, f64)>,
) -> Errors {
    let s = pico_imu_core::config::scales();
    let (ka, kg, km) = (s.accel as f64, s.gyro as f64, s.mag as f64);
    let step = GyroStep::from_rad(f64::from(s.gyro).to_radians() * 1e-3);
    let mut acc = Accum::default();
    let mut sq = [0.0f64; 3];
    let mut n = [0usize; 3];
    let (mut converged_s, mut settled_s) = (None, None);
    let mut states = Vec::new();
    let count = |v: f64, k: f64| (v / k).round().clamp(-32768.0, 32767.0) as i32;
    let bursts = (seconds * 100.0) as usize;
    for b in 0..bursts {
        let mut t_last = 0.0;
        for i in 0..10 {
            let t = (b * 10 + i) as f64 * 1e-3;
            let r = reading(traj, part, t, rng);
            acc.add(
                &r.accel.map(|v| count(v, ka)),
                &r.gyro.map(|v| count(v, kg)),
            );
            t_last = t;
        }
        for j in 0..2 {
            let t = b as f64 * 0.01 + j as f64 * 0.005;
            let mut r = reading(traj, part, t, rng);
            if let Some((t0, t1, k)) = field {
                if t >= t0 && t < t1 {
                    r.mag = r.mag.map(|v| v * k);
                }
            }
            let m = r.mag.map(|v| count(v, km));
            let Some(att) = ahrs.update(&mut acc, step, Some(&m), 5000) else {
                continue;
            };
            states.push(att.state);
            if att.state == AhrsState::Converging {
                settled_s = None;
            } else {
                converged_s = converged_s.or(Some(t));
                settled_s = settled_s.or(Some(t));
            }
            let (e, _) = traj.at(t_last);

            if t_last >= from_s {
                let err = errors(&att, &e);
                for k in 0..3 {
                    if k == 2 && e.pitch.abs() > 80.0 {
                        continue; // heading undefined near the vertical
                    }
                    sq[k] += err[k] * err[k];
                    n[k] += 1;
                }
            }
        }
    }
    let rms = |k: usize| (sq[k] / n[k].max(1) as f64).sqrt();
    Errors {
        roll: rms(0),
        pitch: rms(1),
        heading: rms(2),
        converged_s,
        settled_s,
        states,
    }
}

fn errors(att: &Attitude, e: &Euler) -> [f64; 3] {
    [
        angle_diff(att.roll_deg as f64, e.roll),
        angle_diff(att.pitch_deg as f64, e.pitch),
        angle_diff(att.heading_deg as f64, e.heading),
    ]
}

/// A part with the MPU-6050 / QMC5883L noise and a small random gyro bias the calibration
/// left (≤ 0.05 deg/s).
fn noisy_part(rng: &mut Rng) -> Part {
    Part {
        gyro_bias: [0; 3].map(|_| 0.05 * (2.0 * rng.uniform() - 1.0)),
        noise: [0.05, 0.04, 0.2],
        field_ut: 30.0 + 30.0 * rng.uniform(),
        dip_deg: -70.0 + 140.0 * rng.uniform(),
        ..Part::ideal()
    }
}

fn random_attitude(rng: &mut Rng) -> Euler {
    Euler::new(
        -180.0 + 360.0 * rng.uniform(),
        -70.0 + 140.0 * rng.uniform(),
        360.0 * rng.uniform(),
    )
}

#[test]
fn static_at_random_attitudes_converges_within_half_a_second() {
    let s = seed();
    let mut rng = Rng::new(s);
    for _ in 0..20 {
        let e = random_attitude(&mut rng);
        let part = noisy_part(&mut rng);
        let traj = Trajectory {
            keys: vec![(0.0, e), (3.0, e)],
        };
        let mut ahrs = Ahrs::new();
        let r = run(&traj, &part, 3.0, 1.0, &mut rng, &mut ahrs, None);
        let at = r.converged_s.unwrap_or(f64::INFINITY);
        assert!(at < 0.5, "seed {s}: {e:?} {part:?}: converged at {at} s");
        assert!(
            r.roll < 0.5 && r.pitch < 0.5 && r.heading < 1.0,
            "seed {s}: {e:?} {part:?}: {r:?}"
        );
    }
}

/// A noisy part with a gyro bias of `lo`–`hi` deg/s about a random axis, still for 60 s at a
/// random attitude (pitch within ±60°), and the bias's size.
fn still_with_a_gyro_bias(rng: &mut Rng, lo: f64, hi: f64) -> (Part, Euler, Trajectory, f64) {
    let mut part = noisy_part(rng);
    let b = lo + (hi - lo) * rng.uniform();
    let dir = [0; 3].map(|_| rng.normal());
    let n = dir.iter().map(|x| x * x).sum::<f64>().sqrt();
    part.gyro_bias = dir.map(|x| b * x / n);
    let mut e = random_attitude(rng);
    e.pitch = e.pitch.clamp(-60.0, 60.0);
    let traj = Trajectory {
        keys: vec![(0.0, e), (60.0, e)],
    };
    (part, e, traj, b)
}

/// A gyro bias the calibration left (1.5–3 deg/s, random axis): the bias estimate takes it
/// out (a proportional correction alone would leave it as an error of bias/KP ≈ 1.5–3°).
#[test]
fn a_gyro_bias_is_learnt() {
    let s = seed();
    let mut rng = Rng::new(s);
    let (part, e, traj, _) = still_with_a_gyro_bias(&mut rng, 1.5, 3.0);
    let mut ahrs = Ahrs::new();
    let r = run(&traj, &part, 60.0, 50.0, &mut rng, &mut ahrs, None);
    assert!(
        r.roll < 0.3 && r.pitch < 0.3 && r.heading < 0.5,
        "seed {s}: {e:?} {part:?}: {r:?}"
    );
}

/// A gyro bias no calibration took out (4–20 deg/s, random axis: an uncalibrated MPU-6050's
/// zero-rate offset is up to ±20 deg/s): its steady error, bias/KP ≈ 4–20°, is above the
/// convergence threshold, so only the bias estimate can bring the filter out of `Converging`.
/// It leaves it for good within 40 s and holds roll and pitch within 0.3°, heading 0.5°, after
/// 50 s. From an exact start the bias's error builds over seconds, so the filter may first
/// report converged and learn the field from a tilted estimate; watched while settling, it goes
/// back to `Converging` and learns the field again: the learnt dip within 2.5° of the truth
/// (5° and more without the watch, outside the dip band).
#[test]
fn a_gyro_bias_no_calibration_took_out_is_learnt_while_converging() {
    let s = seed();
    let mut rng = Rng::new(s);
    for _ in 0..4 {
        let (part, e, traj, b) = still_with_a_gyro_bias(&mut rng, 4.0, 20.0);
        let mut ahrs = Ahrs::new();
        let r = run(&traj, &part, 60.0, 50.0, &mut rng, &mut ahrs, None);
        let at = r.settled_s.unwrap_or(f64::INFINITY);
        let dip = ahrs.reference().map_or(f64::NAN, |(_, d)| f64::from(d));
        println!(
            "gyro bias {b:.1} deg/s: converged for good at {at:.2} s; learnt dip {:+.2}° off; \
             after 50 s roll {:.3}°, pitch {:.3}°, heading {:.3}° rms",
            dip - part.dip_deg,
            r.roll,
            r.pitch,
            r.heading
        );
        assert!(
            at < 40.0,
            "seed {s}: {e:?} {part:?}: converged for good at {at} s"
        );
        assert!(
            (dip - part.dip_deg).abs() < 2.5,
            "seed {s}: {e:?} {part:?}: learnt dip {dip}°"
        );
        assert!(
            r.roll < 0.3 && r.pitch < 0.3 && r.heading < 0.5,
            "seed {s}: {e:?} {part:?}: {r:?}"
        );
    }
}

#[test]
fn constant_rate_turns_and_tilts_track_the_truth() {
    let s = seed();
    let mut rng = Rng::new(s);
    for case in 0..12 {
        let e0 = Euler::new(
            -30.0 + 60.0 * rng.uniform(),
            -30.0 + 60.0 * rng.uniform(),
            360.0 * rng.uniform(),
        );
        // A constant-rate turn (10–60 deg/s, either way) at a fixed tilt, or a tilt to ±60°
        // at 10–40 deg/s and back.
        let traj = if case % 2 == 0 {
            let rate = (10.0 + 50.0 * rng.uniform()) * if rng.uniform() < 0.5 { -1.0 } else { 1.0 };
            let e1 = Euler::new(e0.roll, e0.pitch, e0.heading + rate * 8.0);
            Trajectory {
                keys: vec![(0.0, e0), (2.0, e0), (10.0, e1)],
            }
        } else {
            let rate = 10.0 + 30.0 * rng.uniform();
            let to = 60.0 * if rng.uniform() < 0.5 { -1.0 } else { 1.0 };
            let (r1, p1) = if rng.uniform() < 0.5 {
                (to, e0.pitch)
            } else {
                (e0.roll, to)
            };
            let dur = (to - e0.roll.min(e0.pitch)).abs().max(30.0) / rate;
            let e1 = Euler::new(r1, p1, e0.heading);
            Trajectory {
                keys: vec![(0.0, e0), (2.0, e0), (2.0 + dur, e1), (2.0 + 2.0 * dur, e0)],
            }
        };
        let part = noisy_part(&mut rng);
        let mut ahrs = Ahrs::new();
        let secs = traj.duration() + 1.0;
        let r = run(&traj, &part, secs, 1.0, &mut rng, &mut ahrs, None);
        assert!(
            r.roll < 1.0 && r.pitch < 1.0 && r.heading < 2.0,
            "seed {s}, case {case}: {traj:?} {part:?}: {r:?}"
        );
    }
}

#[test]
fn the_standard_trajectory_is_within_one_degree_and_two_of_heading() {
    let s = seed();
    let mut rng = Rng::new(s);
    let part = noisy_part(&mut rng);
    let traj = Trajectory::standard();
    let mut ahrs = Ahrs::new();
    let r = run(
        &traj,
        &part,
        traj.duration(),
        1.0,
        &mut rng,
        &mut ahrs,
        None,
    );
    println!(
        "standard trajectory, calibrated part: rms roll {:.3}°, pitch {:.3}°, heading {:.3}°",
        r.roll, r.pitch, r.heading
    );
    assert!(
        r.roll < 1.0 && r.pitch < 1.0 && r.heading < 2.0,
        "seed {s}: {part:?}: {r:?}"
    );
}

/// Identity calibration on a part with hard iron: the heading is far off, and the field's
/// strength leaving its learnt band is reported.
#[test]
fn hard_iron_without_calibration_is_far_off_and_reported() {
    let s = seed();
    let mut rng = Rng::new(s);
    let part = Part::hard_iron();
    let traj = Trajectory::standard();
    let mut ahrs = Ahrs::new();
    let r = run(
        &traj,
        &part,
        traj.duration(),
        1.0,
        &mut rng,
        &mut ahrs,
        None,
    );
    println!(
        "standard trajectory, hard iron, identity calibration: rms roll {:.3}°, pitch {:.3}°, heading {:.3}°",
        r.roll, r.pitch, r.heading
    );
    assert!(r.heading > 10.0, "seed {s}: {r:?}");
    assert!(
        r.states.contains(&AhrsState::MagField),
        "seed {s}: no field disturbance reported"
    );
    // Roll and pitch do not take the magnetometer's errors (tilt-decoupled correction).
    assert!(r.roll < 1.5 && r.pitch < 1.5, "seed {s}: {r:?}");
}

/// A field 30 % too strong for 2 s: reported as such all along, and the heading held by the
/// gyro (a disturbance that turned the field would otherwise turn the heading).
#[test]
fn a_field_disturbance_is_reported_and_ignored() {
    let s = seed();
    let mut rng = Rng::new(s);
    let part = noisy_part(&mut rng);
    let e = random_attitude(&mut rng);
    let e = Euler::new(e.roll, e.pitch.clamp(-60.0, 60.0), e.heading);
    let traj = Trajectory {
        keys: vec![(0.0, e), (6.0, e)],
    };
    let mut ahrs = Ahrs::new();
    // Learnt over the first converged second; the disturbance from 3 s to 5 s.
    let r = run(
        &traj,
        &part,
        6.0,
        1.0,
        &mut rng,
        &mut ahrs,
        Some((3.0, 5.0, 1.3)),
    );
    let during = &r.states[(3.2 * 200.0) as usize..(4.9 * 200.0) as usize];
    assert!(
        during.iter().all(|&x| x == AhrsState::MagField),
        "seed {s}: {:?}",
        during.iter().filter(|&&x| x != AhrsState::MagField).count()
    );
    let before = &r.states[(2.0 * 200.0) as usize..(2.9 * 200.0) as usize];
    assert!(before.iter().all(|&x| x == AhrsState::Tracking), "seed {s}");
    // What it learnt: the part's field (counts) and dip.
    let (field, dip) = ahrs.reference().expect("learnt");
    let want = part.field_ut / pico_imu_core::config::scales().mag as f64;
    assert!(
        (field as f64 / want - 1.0).abs() < 0.01 && (dip as f64 - part.dip_deg).abs() < 0.5,
        "seed {s}: learnt {field} counts, dip {dip}°; part {want} counts, {}°",
        part.dip_deg
    );
    assert!(r.heading < 1.0, "seed {s}: {r:?}");
    // A reference set by the host: a dip 20° off the real one is a dip disturbance.
    let mut ahrs = Ahrs::new();
    let counts = part.field_ut as f32 / pico_imu_core::config::scales().mag;
    ahrs.set_reference(Some((counts, part.dip_deg as f32 + 20.0)));
    let r = run(&traj, &part, 2.0, 1.0, &mut rng, &mut ahrs, None);
    assert!(
        r.states[100..].iter().all(|&x| x == AhrsState::MagDip),
        "seed {s}: {:?}",
        &r.states[100..110]
    );
}

#[test]
fn declination_is_added_to_the_heading() {
    let s = seed();
    let mut rng = Rng::new(s);
    let part = noisy_part(&mut rng);
    let e = Euler::new(0.0, 0.0, 360.0 * rng.uniform());
    let decl = -30.0 + 60.0 * rng.uniform();
    let traj = Trajectory {
        keys: vec![(0.0, e), (2.0, e)],
    };
    let mut ahrs = Ahrs::new();
    ahrs.set_declination(decl as f32);
    let truth = Trajectory {
        keys: vec![
            (0.0, Euler::new(0.0, 0.0, e.heading + decl)),
            (2.0, Euler::new(0.0, 0.0, e.heading + decl)),
        ],
    };
    // Read on `traj`, compared with `truth` (the true heading).
    let mut acc = Accum::default();
    let mut last = None;
    let sc = pico_imu_core::config::scales();
    for b in 0..200 {
        for _ in 0..10 {
            let r = reading(&traj, &part, b as f64 * 0.01, &mut rng);
            acc.add(
                &r.accel.map(|v| (v / sc.accel as f64) as i32),
                &r.gyro.map(|v| (v / sc.gyro as f64) as i32),
            );
        }
        let r = reading(&traj, &part, b as f64 * 0.01, &mut rng);
        let m = r.mag.map(|v| (v / sc.mag as f64) as i32);
        last = ahrs
            .update(
                &mut acc,
                GyroStep::from_rad(f64::from(sc.gyro).to_radians() * 1e-3),
                Some(&m),
                10_000,
            )
            .or(last);
    }
    let att = last.expect("started");
    let want = truth.at(1.0).0.heading;
    assert!(
        angle_diff(att.heading_deg as f64, want).abs() < 1.5,
        "seed {s}: {} vs {want}",
        att.heading_deg
    );
}

/// micromath's approximations against libm where the filter uses them, error in degrees
/// (or relative), over the range the filter meets them.
#[test]
fn micromath_error_on_the_values_that_matter() {
    use micromath::F32;
    let s = seed();
    let mut rng = Rng::new(s);
    let (mut atan2_err, mut pitch_err, mut inv_rel, mut raw_rel, mut asin_err) =
        (0f64, 0f64, 0f64, 0f64, 0f64);
    for _ in 0..100_000 {
        let a = (2.0 * rng.uniform() - 1.0) * std::f64::consts::PI;
        let r = 0.1 + 2.0 * rng.uniform();
        let (y, x) = ((r * a.sin()) as f32, (r * a.cos()) as f32);
        let mm = F32(y).atan2(F32(x)).0 as f64;
        atan2_err = atan2_err.max(
            angle_diff(
                mm.to_degrees(),
                libm::atan2(y as f64, x as f64).to_degrees(),
            )
            .abs(),
        );
        // Pitch as the filter computes it, against the exact asin, |θ| ≤ 89°.
        let th = (2.0 * rng.uniform() - 1.0) * 89f64.to_radians();
        let fi = (2.0 * rng.uniform() - 1.0) * std::f64::consts::PI;
        let (r31, r32, r33) = (
            -th.sin() as f32,
            (fi.sin() * th.cos()) as f32,
            (fi.cos() * th.cos()) as f32,
        );
        let c2 = r32 * r32 + r33 * r33;
        let y0 = F32(c2).invsqrt().0;
        let inv = y0 * (1.5 - 0.5 * c2 * y0 * y0);
        let p = F32(-r31).atan2(F32(c2 * inv)).0 as f64;
        pitch_err = pitch_err.max((p - th).abs().to_degrees());
        let asin = F32(-r31).asin().0 as f64;
        if th.abs() <= 60f64.to_radians() {
            asin_err = asin_err.max((asin - th).abs().to_degrees());
        }
        let v = 1e-3 + 1e4 * rng.uniform();
        let exact = 1.0 / libm::sqrt(v);
        let y0 = F32(v as f32).invsqrt().0;
        raw_rel = raw_rel.max((y0 as f64 / exact - 1.0).abs());
        let y1 = y0 * (1.5 - 0.5 * v as f32 * y0 * y0);
        inv_rel = inv_rel.max((y1 as f64 / exact - 1.0).abs());
    }
    println!(
        "micromath vs libm (max over 100000 draws): atan2 {atan2_err:.3}°, pitch (atan2 + invsqrt·Newton) {pitch_err:.3}°, asin up to 60° {asin_err:.3}°, invsqrt {:.2} %, invsqrt + Newton {:.3} %",
        raw_rel * 100.0,
        inv_rel * 100.0
    );
    assert!(atan2_err < 0.17, "seed {s}: atan2 {atan2_err}°");
    assert!(pitch_err < 0.2, "seed {s}: pitch {pitch_err}°");
    assert!(inv_rel < 2.5e-3, "seed {s}: invsqrt + Newton {inv_rel}");
    assert!(raw_rel < 0.04, "seed {s}: invsqrt {raw_rel}");
    // Why pitch is not micromath's asin: it errs by far more than the 1° goal allows for.
    assert!(asin_err > 0.3, "seed {s}: asin {asin_err}°");
}

/// The largest differences between the device's integer filter and the `f32` reference fed the
/// same samples, degrees, and the updates whose states differ.
#[derive(Debug, Default)]
struct Agreement {
    roll: f64,
    pitch: f64,
    heading: f64,
    /// The rotation between the two estimates, degrees.
    angle: f64,
    /// The integer filter's roll, pitch, heading against the exact angles of its quaternion,
    /// degrees, and as a share of what its arithmetic allows ([`output_bound`]).
    outputs: f64,
    outputs_share: f64,
    states_differ: usize,
    /// Runs of updates whose states differ.
    episodes: usize,
    /// Runs that did not start at a decision of the convergence near its threshold (the
    /// reference's smoothed error within [`NEAR_THRESHOLD`] of it) nor after the two learnt
    /// different expected fields: a real disagreement.
    unexplained: usize,
    /// The largest relative distance of the reference's smoothed error from the threshold at
    /// the start of a run it explains.
    margin: f64,
    /// Updates flagged `MagField` by the integer filter and by the reference.
    mag_field: [usize; 2],
    updates: usize,
}

/// The larger of a running worst and a new value, NaN if either is (`f64::max` drops a NaN,
/// and a filter's NaN output would then pass every bound).
fn worst(acc: f64, x: f64) -> f64 {
    if acc.is_nan() || x.is_nan() {
        f64::NAN
    } else {
        acc.max(x)
    }
}

/// What the integer filter's outputs may differ from its quaternion's exact angles at a pitch
/// of `pitch_deg`, degrees: (roll and heading, pitch). Its rows come from the quaternion in Q15
/// (components within 2⁻¹⁶: an off-diagonal entry `2(xy − wz)` within 6·10⁻⁵, a diagonal one
/// `1 − 2(y² + z²)` within 8.5·10⁻⁵) as it is between renormalisations: |q|² grows by up to four
/// steps' |v|², 6·10⁻⁵ at 90°/s, which scales the off-diagonal entries by as much and moves the
/// diagonal ones by twice that. The atan2 of an off-diagonal and a diagonal entry is then
/// within 2.4·10⁻⁴ rad (0.014°) over their pair's length, cos(pitch) for roll and heading; its
/// atan2 adds up to 0.004°.
fn output_bound(pitch_deg: f64) -> (f64, f64) {
    let rows = 0.014;
    (0.004 + rows / pitch_deg.to_radians().cos(), 0.004 + rows)
}

/// How near the threshold (relative) the reference's smoothed error may be where the two
/// filters' convergence decisions part: their errors differ by ≈ 10⁻³ of it.
const NEAR_THRESHOLD: f64 = 0.01;

/// Runs [`Ahrs`] and `float::Ahrs` on the same readings of `traj` (the device's order, as in
/// [`run`]), with the magnetometer scaled by `field` between two times.
fn agreement(
    traj: &Trajectory,
    part: &Part,
    seconds: f64,
    rng: &mut Rng,
    field: Option<(f64, f64, f64)>,
) -> Agreement {
    use pico_imu_core::ahrs::float;
    let s = pico_imu_core::config::scales();
    let (ka, kg, km) = (s.accel as f64, s.gyro as f64, s.mag as f64);
    let rad = f64::from(s.gyro).to_radians() * 1e-3;
    let count = |v: f64, k: f64| (v / k).round().clamp(-32768.0, 32767.0) as i32;
    let (mut fixed, mut reference) = (Ahrs::new(), float::Ahrs::new());
    let (mut acc_i, mut acc_f) = (Accum::default(), Accum::default());
    let mut out = Agreement::default();
    let mut agreed = true;
    for b in 0..(seconds * 100.0) as usize {
        for i in 0..10 {
            let r = reading(traj, part, (b * 10 + i) as f64 * 1e-3, rng);
            let (a, g) = (r.accel.map(|v| count(v, ka)), r.gyro.map(|v| count(v, kg)));
            acc_i.add(&a, &g);
            acc_f.add(&a, &g);
        }
        for j in 0..2 {
            let t = b as f64 * 0.01 + j as f64 * 0.005;
            let mut r = reading(traj, part, t, rng);
            if let Some((t0, t1, k)) = field {
                if t >= t0 && t < t1 {
                    r.mag = r.mag.map(|v| v * k);
                }
            }
            let m = r.mag.map(|v| count(v, km));
            let x = fixed.update(&mut acc_i, GyroStep::from_rad(rad), Some(&m), 5000);
            let y = reference.update(&mut acc_f, rad as f32, Some(&m), 0.005);
            let (Some(x), Some(y)) = (x, y) else {
                assert_eq!(
                    x.is_some(),
                    y.is_some(),
                    "one filter started, the other not"
                );
                continue;
            };
            out.updates += 1;
            out.states_differ += usize::from(x.state != y.state);
            if x.state != y.state && agreed {
                out.episodes += 1;
                // A slowly varying error crossing a threshold: the two arithmetics decide at
                // updates a little apart, and what follows (learning the field, or not yet)
                // differs from there on.
                let (e2, tilt2) = reference.convergence_errors2();
                let near = |x: f32, t: f32| f64::from((x - t).abs() / t);
                let margin = near(e2, CONVERGED_ERR2).min(near(tilt2, REDIVERGED_ERR2));
                let (rx, ry) = (fixed.reference(), reference.reference());
                let fields_differ = match (rx, ry) {
                    (Some((f, d)), Some((g, e))) => {
                        ((f - g) / g).abs() > 1e-3 || (d - e).abs() > 0.05
                    }
                    (None, None) => false,
                    _ => true,
                };
                if margin <= NEAR_THRESHOLD {
                    out.margin = worst(out.margin, margin);
                } else if !fields_differ {
                    out.unexplained += 1;
                }
            }
            agreed = x.state == y.state;
            out.mag_field[0] += usize::from(x.state == AhrsState::MagField);
            out.mag_field[1] += usize::from(y.state == AhrsState::MagField);
            // The angles of each filter's quaternion, exact (the reference's own outputs carry
            // micromath's atan2 error, up to 0.16°).
            let (ex, ey) = (euler(&x.q), euler(&y.q));
            let d = |p: f64, q: f64| angle_diff(p, q).abs();
            out.pitch = worst(out.pitch, d(ex[1], ey[1]));
            // Roll and heading are undefined at ±90° of pitch and ill-conditioned near it.
            if ey[1].abs() < 80.0 {
                out.roll = worst(out.roll, d(ex[0], ey[0]));
                out.heading = worst(out.heading, d(ex[2], ey[2]));
                // The integer filter's outputs against its own quaternion's exact angles.
                let (wide, narrow) = output_bound(ex[1]);
                for (k, bound) in [(0, wide), (1, narrow), (2, wide)] {
                    let got = [x.roll_deg, x.pitch_deg, x.heading_deg][k] as f64;
                    out.outputs = worst(out.outputs, d(got, ex[k]));
                    out.outputs_share = worst(out.outputs_share, d(got, ex[k]) / bound);
                }
            }
            // The rotation between the two estimates, degrees: conj(y) ⊗ x (q and −q are the
            // same).
            let [a0, a1, a2, a3] = y.q.map(f64::from);
            let [b0, b1, b2, b3] = x.q.map(f64::from);
            let w = a0 * b0 + a1 * b1 + a2 * b2 + a3 * b3;
            let v = [
                a0 * b1 - a1 * b0 - a2 * b3 + a3 * b2,
                a0 * b2 + a1 * b3 - a2 * b0 - a3 * b1,
                a0 * b3 - a1 * b2 + a2 * b1 - a3 * b0,
            ];
            let vn = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
            out.angle = worst(out.angle, 2.0 * libm::atan2(vn, w.abs()).to_degrees());
            if std::env::var("AHRS_TRACE").is_ok() {
                let tr = traj.at(t).0;
                println!(
                    "{t:.3} {:?} {:?} {:?} {:?} {:?}",
                    ex,
                    ey,
                    [tr.roll, tr.pitch, tr.heading],
                    x.state,
                    y.state
                );
            }
        }
    }
    out
}

/// Roll, pitch, heading (degrees, heading in [0, 360)) of a body → NED quaternion, exact.
fn euler(q: &[f32; 4]) -> [f64; 3] {
    let [w, x, y, z] = q.map(f64::from);
    let n = (w * w + x * x + y * y + z * z).sqrt();
    let [w, x, y, z] = [w / n, x / n, y / n, z / n];
    let roll = libm::atan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y));
    let pitch = libm::asin((2.0 * (w * y - z * x)).clamp(-1.0, 1.0));
    let heading = libm::atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z));
    [
        roll.to_degrees(),
        pitch.to_degrees(),
        heading.to_degrees().rem_euclid(360.0),
    ]
}

/// The integer filter against the `f32` reference on random trajectories: static at random
/// attitudes with a field disturbance, turns, a gyro bias being learnt, the standard
/// trajectory. Roll, pitch and heading (each filter's quaternion, exact angles) within 0.05° of
/// each other at every update, and the same states (the convergence and the field's flags)
/// but where a slowly varying error crosses a threshold: the two arithmetics may decide a few
/// updates apart, and what follows (the field learnt or not yet) differs from there on. Each
/// run of differing states must start there (the reference's smoothed error within
/// [`NEAR_THRESHOLD`] of the threshold) or once the two learnt different fields; at most three
/// such runs. Its outputs within what their arithmetic allows ([`output_bound`]). Then hard
/// iron with no calibration, where |B| crosses
/// its band's edges as the part turns (the flag there decided by the noise): the same share of
/// updates flagged within 2 % of them.
#[test]
fn the_integer_filter_agrees_with_the_f32_reference() {
    let s = seed();
    let mut rng = Rng::new(s);
    let mut worst = Agreement::default();
    for case in 0..16 {
        let mut part = noisy_part(&mut rng);
        let e0 = random_attitude(&mut rng);
        let (traj, field) = match case % 4 {
            0 => (
                Trajectory {
                    keys: vec![(0.0, e0), (6.0, e0)],
                },
                // Clear of the ±10 % band's edge, where the noise alone decides the flag.
                Some((
                    3.0,
                    5.0,
                    if rng.uniform() < 0.5 {
                        0.5 + 0.3 * rng.uniform()
                    } else {
                        1.2 + 0.3 * rng.uniform()
                    },
                )),
            ),
            1 => {
                let rate =
                    (10.0 + 80.0 * rng.uniform()) * if rng.uniform() < 0.5 { -1.0 } else { 1.0 };
                let e1 = Euler::new(
                    e0.roll,
                    e0.pitch.clamp(-50.0, 50.0),
                    e0.heading + rate * 5.0,
                );
                (
                    Trajectory {
                        keys: vec![(0.0, e0), (1.0, e0), (6.0, e1)],
                    },
                    None,
                )
            }
            2 => {
                part.gyro_bias = [0; 3].map(|_| 3.0 * (2.0 * rng.uniform() - 1.0));
                (Trajectory::standard(), None)
            }
            _ => (Trajectory::standard(), None),
        };
        let secs = traj.duration().min(30.0);
        let a = agreement(&traj, &part, secs, &mut rng, field);
        assert!(a.updates > 100, "seed {s}, case {case}: {a:?}");
        assert!(
            a.roll <= 0.05 && a.pitch <= 0.05 && a.heading <= 0.05,
            "seed {s}, case {case}: {traj:?} {part:?}: {a:?}"
        );
        assert!(
            a.unexplained == 0 && a.episodes <= 3,
            "seed {s}, case {case}: {a:?}"
        );
        assert!(a.outputs_share <= 1.0, "seed {s}, case {case}: {a:?}");
        worst.roll = worst.roll.max(a.roll);
        worst.pitch = worst.pitch.max(a.pitch);
        worst.heading = worst.heading.max(a.heading);
        worst.angle = worst.angle.max(a.angle);
        worst.outputs = worst.outputs.max(a.outputs);
        worst.outputs_share = worst.outputs_share.max(a.outputs_share);
        worst.states_differ = worst.states_differ.max(a.states_differ);
        worst.episodes = worst.episodes.max(a.episodes);
        worst.margin = worst.margin.max(a.margin);
        worst.updates += a.updates;
    }
    let mut rng2 = Rng::new(s ^ 0x5eed);
    let traj = Trajectory::standard();
    let a = agreement(&traj, &Part::hard_iron(), 30.0, &mut rng2, None);
    let share = a.mag_field.map(|n| n as f64 / a.updates as f64);
    assert!(
        share[0] > 0.05 && (share[0] - share[1]).abs() < 0.02,
        "seed {s}, hard iron: {a:?}"
    );
    println!(
        "hard iron, identity calibration: MagField at {:.1} % (integer) and {:.1} % (f32) of the updates",
        share[0] * 100.0,
        share[1] * 100.0
    );
    println!(
        "integer vs f32 filter, largest difference over {} updates: roll {:.4}°, pitch {:.4}°, heading {:.4}°, rotation {:.4}°; states differing at ≤ {} updates a run, in ≤ {} runs of updates, each starting with the smoothed error within {:.2} % of its threshold; integer outputs vs their quaternion's exact angles ≤ {:.4}° ({:.0} % of what its arithmetic allows)",
        worst.updates,
        worst.roll,
        worst.pitch,
        worst.heading,
        worst.angle,
        worst.states_differ,
        worst.episodes,
        worst.margin * 100.0,
        worst.outputs,
        worst.outputs_share * 100.0
    );
}

/// Any input, however absurd — sums at the ends of `i32`, a zero or saturated magnetometer, any
/// step — gives no panic (no overflow in these checked builds) and a unit quaternion with
/// angles in their ranges; and a sane stream afterwards still converges.
#[test]
fn absurd_inputs_neither_panic_nor_derail_the_filter() {
    let s = seed();
    let mut rng = Rng::new(s);
    let mut ahrs = Ahrs::new();
    let mut estimates = 0;
    let pick = |rng: &mut Rng| -> i32 {
        match (rng.uniform() * 6.0) as u32 {
            0 => i32::MAX,
            1 => i32::MIN,
            2 => 0,
            3 => ((rng.uniform() - 0.5) * 2e5) as i32,
            4 => ((rng.uniform() - 0.5) * 8e9) as i32,
            _ => ((rng.uniform() - 0.5) * 65536.0) as i32,
        }
    };
    for _ in 0..20_000 {
        let mut acc = Accum {
            gyro: [0; 3].map(|_| pick(&mut rng)),
            accel: [0; 3].map(|_| pick(&mut rng)),
            n: (rng.uniform() * 200.0) as u32,
        };
        let m = [0; 3].map(|_| pick(&mut rng));
        let mag = (rng.uniform() < 0.8).then_some(&m);
        let dt = if rng.uniform() < 0.5 {
            5000
        } else {
            (rng.uniform() * 2e6) as u32
        };
        let step = GyroStep::from_rad(rng.uniform() * 1e-6);
        if let Some(a) = ahrs.update(&mut acc, step, mag, dt) {
            estimates += 1;
            let n: f32 = a.q.iter().map(|c| c * c).sum();
            assert!((n - 1.0).abs() < 0.05, "seed {s}: |q|² {n} for {a:?}");
            assert!(
                a.roll_deg.abs() <= 180.0 && a.pitch_deg.abs() <= 90.0,
                "seed {s}: {a:?}"
            );
            assert!((0.0..360.0).contains(&a.heading_deg), "seed {s}: {a:?}");
        }
    }
    assert!(estimates > 10_000, "seed {s}: {estimates} estimates");
    // Then the part at rest: the filter comes back.
    let part = noisy_part(&mut rng);
    let e = random_attitude(&mut rng);
    let traj = Trajectory {
        keys: vec![(0.0, e), (8.0, e)],
    };
    ahrs.reset();
    let r = run(&traj, &part, 8.0, 6.0, &mut rng, &mut ahrs, None);
    assert!(
        r.roll < 0.5 && r.pitch < 0.5 && r.heading < 1.0,
        "seed {s}: {e:?}: {r:?}"
    );
}
