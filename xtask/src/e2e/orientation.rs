//! `cargo xtask e2e --scenario orientation`: the emulated board turned through a known
//! trajectory (`imu_sim::trajectory::Trajectory::standard`: level turn, tilts to 60°, a tumble
//! through the sphere) by a part with hard and soft iron and a gyro bias
//! (`Part::hard_iron`). The device's attitude and heading are compared with the truth twice,
//! on the same trajectory: first with the identity calibration it boots with (the heading must
//! be far off, and the field's strength reported out of its band), then with the part's
//! calibration uploaded (roll and pitch within 1° rms, still and moving, heading within 2° rms).
use std::fmt::Write as _;
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use imu_cal::device::{encode_blob, Affine, Calibration, GyroCorrection, Sensor as CalSensor};
use imu_proto::{AhrsState, Orientation, Reply, Request, Vec as HVec};
use imu_sim::trajectory::{angle_diff, Part, Trajectory};

use super::Report;
use crate::emu::{build_firmware, ensure_sim, out_dir, Sim};
use crate::emu_link::Link;

/// Goals with a good calibration, degrees rms.
pub const ROLL_PITCH_GOAL_DEG: f64 = 1.0;
pub const HEADING_GOAL_DEG: f64 = 2.0;
/// With the identity calibration on the hard-iron part the heading error must be at least
/// this (rms, degrees): the test's evidence that the calibration is what buys the accuracy.
pub const UNCALIBRATED_AT_LEAST_DEG: f64 = 10.0;
/// After a (re)start the filter is given this long before it is judged, s.
const SETTLE_S: f64 = 1.0;

/// The part's exact calibration: the inverse of its soft iron and its hard iron, its gyro bias,
/// in the device's fixed point (counts).
pub fn part_calibration(part: &Part) -> Result<Calibration> {
    let s = pico_imu_core::config::scales();
    let inv = invert(&part.soft_iron).context("soft iron is singular")?;
    let mag = Affine::from_float(
        CalSensor::Mag,
        inv,
        part.hard_iron.map(|h| h / s.mag as f64),
    )
    .map_err(|e| anyhow::anyhow!("magnetometer correction: {e:?}"))?;
    let one = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    let gyro =
        GyroCorrection::from_float(one, part.gyro_bias.map(|b| b / s.gyro as f64), [0.0; 3], 0)
            .map_err(|e| anyhow::anyhow!("gyro correction: {e:?}"))?;
    let accel = Affine::from_float(CalSensor::Accel, one, [0.0; 3])
        .map_err(|e| anyhow::anyhow!("accelerometer correction: {e:?}"))?;
    // fitted at the ranges the firmware runs, as the host's calibration file would say
    let (imu, mag_part) = pico_imu_core::config::PARTS;
    let fitted =
        imu_cal::device::Fitted::new(imu, mag_part, [1.0 / s.accel, 1.0 / s.gyro, 1.0 / s.mag])
            .map_err(|e| anyhow::anyhow!("{e}"))?;
    Calibration::fitted(accel, gyro, mag, fitted).map_err(|e| anyhow::anyhow!("{e}"))
}

fn invert(m: &[[f64; 3]; 3]) -> Option<[[f64; 3]; 3]> {
    let c = |i: usize, j: usize| {
        let (a, b) = ((i + 1) % 3, (i + 2) % 3);
        let (p, q) = ((j + 1) % 3, (j + 2) % 3);
        m[a][p] * m[b][q] - m[a][q] * m[b][p]
    };
    let det = m[0][0] * c(0, 0) + m[0][1] * c(0, 1) + m[0][2] * c(0, 2);
    if det.abs() < 1e-12 {
        return None;
    }
    Some([0, 1, 2].map(|i| [0, 1, 2].map(|j| c(j, i) / det)))
}

/// Errors of a run of estimates against the truth.
#[derive(Debug, Default, Clone)]
pub struct Stats {
    n: [usize; 2],
    sq: [[f64; 3]; 2],
    max: [[f64; 3]; 2],
    states: [usize; 4],
}

impl Stats {
    fn add(&mut self, still: bool, err: [f64; 3], state: AhrsState) {
        let k = usize::from(!still);
        self.n[k] += 1;
        for (i, e) in err.iter().enumerate() {
            self.sq[k][i] += e * e;
            self.max[k][i] = self.max[k][i].max(e.abs());
        }
        self.states[state as usize] += 1;
    }

    /// rms of roll, pitch, heading: still (`k = 0`), moving (1), or both (`None`).
    pub fn rms(&self, k: Option<usize>) -> [f64; 3] {
        let (n, sq) = match k {
            Some(k) => (self.n[k], self.sq[k]),
            None => (
                self.n[0] + self.n[1],
                [0, 1, 2].map(|i| self.sq[0][i] + self.sq[1][i]),
            ),
        };
        sq.map(|s| (s / n.max(1) as f64).sqrt())
    }

    pub fn count(&self) -> usize {
        self.n[0] + self.n[1]
    }
}

/// The estimates with device time in `[from_s, to_s)` against the trajectory's truth (the
/// stream repeats it from boot, every `traj.duration()` s).
pub fn compare(traj: &Trajectory, got: &[Orientation], from_s: f64, to_s: f64) -> Stats {
    let period = traj.duration();
    let mut st = Stats::default();
    for o in got {
        let t = o.t_us as f64 * 1e-6;
        if t < from_s || t >= to_s {
            continue;
        }
        let tt = t % period;
        let (e, _) = traj.at(tt);
        let err = [
            angle_diff(o.roll_deg as f64, e.roll),
            angle_diff(o.pitch_deg as f64, e.pitch),
            angle_diff(o.heading_deg as f64, e.heading),
        ];
        st.add(traj.is_still(tt), err, o.state);
    }
    st
}

/// `cargo xtask e2e --scenario orientation [--out DIR]`.
pub fn orientation(args: &super::E2eArgs) -> Result<()> {
    let wall = Instant::now();
    let traj = Trajectory::standard();
    let part = Part::hard_iron();
    let period = traj.duration();
    let elf = build_firmware()?;
    ensure_sim()?;
    let out = out_dir(args.out.as_deref().unwrap_or("e2e-orientation"))?;
    let stream = out.join("stream.csv");
    // One period: the models wrap to its start, so the board repeats the trajectory.
    let f = std::fs::File::create(&stream).with_context(|| stream.display().to_string())?;
    imu_sim::trajectory::write_stream(std::io::BufWriter::new(f), &traj, &part, 1000.0, period, 7)
        .with_context(|| format!("writing {}", stream.display()))?;
    let seconds = 2.0 * period;
    let sim_args: Vec<String> = vec![
        "--seconds".into(),
        format!("{}", seconds + 60.0),
        "--stream".into(),
        stream.display().to_string(),
        "--summary".into(),
        out.join("summary.json").display().to_string(),
        "--log".into(),
        out.join("firmware.log").display().to_string(),
        "--quiet".into(),
        "--exit-on-disconnect".into(),
    ];
    let cal = part_calibration(&part)?;
    let sim = Sim::start(&elf, &sim_args, &out)?;
    let (got, upload_s) = match session(sim.port, period, &cal) {
        Ok(x) => x,
        Err(e) => {
            sim.finish_after_error();
            return Err(e);
        }
    };
    sim.wait("the orientation run")?;
    let mut r = Report::default();
    let before = compare(&traj, &got, SETTLE_S, upload_s);
    // After the upload the filter starts again: judged from its first estimate after it
    // converged (plus the settling time), up to the end of the second pass. The estimates
    // queued before the upload took effect still come from the old filter: the restart is the
    // first `Converging` one after the upload.
    let secs = |o: &Orientation| o.t_us as f64 * 1e-6;
    let restart_s = got
        .iter()
        .skip_while(|o| secs(o) <= upload_s || o.state != AhrsState::Converging)
        .find(|o| o.state != AhrsState::Converging)
        .map(secs)
        .unwrap_or(f64::INFINITY);
    let after = compare(&traj, &got, restart_s + SETTLE_S, 2.0 * period);
    writeln!(
        r.text,
        "# End-to-end emulator test: scenario `orientation`\n\nThe board turned through \
         `imu_sim::trajectory::Trajectory::standard` ({period} s: still 3 s, level turn 360° at \
         45°/s, roll and pitch to 60° and back at 30°/s, a tumble through the sphere at 30–53°/s) \
         twice, by `Part::hard_iron` (hard iron {:?} µT, soft iron, gyro bias {:?} deg/s, noise \
         {:?}). Firmware {}.\n",
        part.hard_iron,
        part.gyro_bias,
        part.noise,
        elf.display()
    )?;
    writeln!(
        r.text,
        "Pass 1: identity calibration (as booted), {SETTLE_S} s to {upload_s:.1} s. Pass 2: the \
         part's calibration uploaded at {upload_s:.2} s, converged at {restart_s:.2} s ({:.2} s \
         later), judged from {:.1} s to {:.0} s.\n",
        restart_s - upload_s,
        restart_s + SETTLE_S,
        2.0 * period
    )?;
    writeln!(
        r.text,
        "| calibration | motion | estimates | roll rms | pitch rms | heading rms | heading max |\n|---|---|---:|---:|---:|---:|---:|"
    )?;
    for (name, st) in [("identity", &before), ("the part's", &after)] {
        for (k, what) in [(Some(0), "still"), (Some(1), "moving"), (None, "all")] {
            let rms = st.rms(k);
            let (n, max) = match k {
                Some(k) => (st.n[k], st.max[k][2]),
                None => (st.count(), st.max[0][2].max(st.max[1][2])),
            };
            writeln!(
                r.text,
                "| {name} | {what} | {n} | {:.3}° | {:.3}° | {:.3}° | {:.2}° |",
                rms[0], rms[1], rms[2], max
            )?;
        }
    }
    writeln!(
        r.text,
        "\nStates reported (Converging, Tracking, MagField, MagDip): identity {:?}, the part's {:?}.",
        before.states, after.states
    )?;
    // Two passes of 200 estimates a second, less the settling: nearly all must be there.
    let expected = 200.0 * (upload_s - SETTLE_S);
    if (before.count() as f64) < 0.95 * expected {
        r.fail(format!(
            "pass 1: {} estimates, expected ≈ {expected:.0}",
            before.count()
        ));
    }
    // (Never converged after the upload, the bound below would be −∞ and pass.)
    if !restart_s.is_finite() {
        r.fail("pass 2: the filter never converged after the upload".into());
    } else if (after.count() as f64) < 0.95 * 200.0 * (2.0 * period - restart_s - SETTLE_S) {
        r.fail(format!("pass 2: {} estimates only", after.count()));
    }
    // Each goal met only by a number within it: a NaN error fails it.
    let within = |x: f64, goal: f64| x <= goal;
    for (k, what) in [(0, "still"), (1, "moving")] {
        let rms = after.rms(Some(k));
        if !(within(rms[0], ROLL_PITCH_GOAL_DEG) && within(rms[1], ROLL_PITCH_GOAL_DEG)) {
            r.fail(format!(
                "calibrated, {what}: roll {:.3}° / pitch {:.3}° rms over {ROLL_PITCH_GOAL_DEG}°",
                rms[0], rms[1]
            ));
        }
    }
    let h = after.rms(None)[2];
    if !within(h, HEADING_GOAL_DEG) {
        r.fail(format!(
            "calibrated: heading {h:.3}° rms over {HEADING_GOAL_DEG}°"
        ));
    }
    let h0 = before.rms(None)[2];
    if !within(UNCALIBRATED_AT_LEAST_DEG, h0) {
        r.fail(format!(
            "identity calibration on a hard-iron part: heading {h0:.3}° rms, expected at least {UNCALIBRATED_AT_LEAST_DEG}°"
        ));
    }
    if before.states[AhrsState::MagField as usize] == 0 {
        r.fail("identity calibration on a hard-iron part: no MagField disturbance reported".into());
    }
    let tracking = after.states[AhrsState::Tracking as usize] as f64 / after.count().max(1) as f64;
    if tracking < 0.99 {
        r.fail(format!(
            "calibrated: only {:.1} % of the estimates Tracking ({:?})",
            100.0 * tracking,
            after.states
        ));
    }
    writeln!(
        r.text,
        "\nheading error before → after calibration: {h0:.2}° → {h:.2}° rms"
    )?;
    r.finish("orientation", &out, wall)
}

/// One pass with the identity calibration, the part's calibration uploaded, a second pass.
/// Returns the estimates and the device time of the upload, s.
fn session(port: u16, period: f64, cal: &Calibration) -> Result<(Vec<Orientation>, f64)> {
    let long = Duration::from_secs(300);
    let mut link = Link::connect(port, Duration::from_secs(30))?;
    if link.request(
        Request::SetIntervals {
            status_ms: 500,
            tables_ms: 0,
        },
        long,
    )? != Reply::Ok
    {
        bail!("SetIntervals refused");
    }
    let uptime = |g: &crate::emu_link::Collected| {
        g.statuses.last().map_or(0.0, |s| s.uptime_us as f64 * 1e-6)
    };
    link.wait_until(
        Duration::from_secs(900),
        "the first pass of the trajectory",
        |g| uptime(g) >= period,
    )?;
    let mut buf = [0u8; 256];
    let blob = encode_blob(cal, &mut buf).map_err(|e| anyhow::anyhow!("{e:?}"))?;
    let blob = HVec::from_slice(blob).map_err(|_| anyhow::anyhow!("blob too large"))?;
    let r = link.request(
        Request::SetCalibration {
            blob,
            persist: false,
        },
        long,
    )?;
    if r != Reply::Ok {
        bail!("SetCalibration answered {r:?}");
    }
    // The device time of the upload: the newest estimate before the reply.
    let upload_s = link
        .got
        .orientations
        .last()
        .map_or(period, |o| o.t_us as f64 * 1e-6);
    link.wait_until(
        Duration::from_secs(900),
        "the second pass of the trajectory",
        |g| uptime(g) >= 2.0 * period,
    )?;
    Ok((std::mem::take(&mut link.got.orientations), upload_s))
}
