//! `cargo xtask e2e`: the firmware on the emulated board, faults injected, everything the device
//! says checked against the models' ground truth (docs/emulator.md, "The end-to-end test").
//!
//! Scenarios:
//! * `faults` (default): both parts' clocks 1.3 % slow and every fault kind the harness has
//!   (NACK bursts, parts unpowered, SDA held with arbitration lost or with a hung START, CPU
//!   stalls that overflow the FIFO, parts that stop producing), then the calibration round trip;
//! * `boot-stall`: the magnetometer never sets DRDY from boot;
//! * `sine`: no faults, a sine on the x gyro (the device's 64-bit squares in the Allan engine).
use std::collections::{BTreeMap, BTreeSet};
use std::fmt::Write as _;
use std::path::Path;
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use imu_cal::device::{encode_blob, Affine, Calibration, GyroCorrection, Sensor as CalSensor};
use imu_proto::{
    Channel, Event, GapCause, Reply, Request, SampleBatch, Sensor, SensorState, StreamMode,
    Vec as HVec,
};
use pico_imu_core::replay::{self, ChannelCheck};

use crate::emu::{arg_value, build_firmware, ensure_sim, out_dir, Sim};
use crate::emu_check::{self, ImuRaw, MagRaw};
use crate::emu_link::Link;
use crate::run;

/// What a fault does, for the checks.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Kind {
    /// NACK every address phase to the sensor for the duration.
    Nack,
    /// NACK this many address phases.
    NackCount,
    Vanish,
    Stall,
    /// SDA held, arbitration lost (for the duration, or until recovered).
    Stuck,
    /// SDA held, START hangs.
    Hang,
    /// CPU stall.
    Cpu,
}

#[derive(Clone, Copy, Debug)]
struct Fault {
    spec: &'static str,
    kind: Kind,
    sensor: Option<Sensor>,
    at_s: f64,
    /// The fault's own duration, s (0 for a count or until recovered).
    dur_s: f64,
}

const fn f(spec: &'static str, kind: Kind, sensor: Option<Sensor>, at_s: f64, dur_s: f64) -> Fault {
    Fault {
        spec,
        kind,
        sensor,
        at_s,
        dur_s,
    }
}

const MPU: Option<Sensor> = Some(Sensor::Imu);
const QMC: Option<Sensor> = Some(Sensor::Mag);

/// The faults of the default scenario, one at a time, 2 s or more apart.
const FAULTS: &[Fault] = &[
    f("nack:mpu@3s:30ms", Kind::Nack, MPU, 3.0, 0.030),
    f("nack:qmc@4s:30ms", Kind::Nack, QMC, 4.0, 0.030),
    f("nack:mpu@5s:50ms", Kind::Nack, MPU, 5.0, 0.050),
    f("nack:qmc@6s:50ms", Kind::Nack, QMC, 6.0, 0.050),
    f("vanish:mpu@8s:200ms", Kind::Vanish, MPU, 8.0, 0.2),
    f("vanish:qmc@10s:200ms", Kind::Vanish, QMC, 10.0, 0.2),
    f("stuck@12s:50ms", Kind::Stuck, None, 12.0, 0.05),
    f("hang@14s:50ms", Kind::Hang, None, 14.0, 0.05),
    f("overflow@16s:150ms", Kind::Cpu, None, 16.0, 0.15),
    f("overflow@18s:500ms", Kind::Cpu, None, 18.0, 0.5),
    f("stall:qmc@20s:1s", Kind::Stall, QMC, 20.0, 1.0),
    f("stall:mpu@23s:200ms", Kind::Stall, MPU, 23.0, 0.2),
    f("stuck@25s", Kind::Stuck, None, 25.0, 0.0),
    f("nack:mpu@27s:3", Kind::NackCount, MPU, 27.0, 0.0),
    f("nack:qmc@28s:3", Kind::NackCount, QMC, 28.0, 0.0),
    f("vanish:mpu@30s:2s", Kind::Vanish, MPU, 30.0, 2.0),
    f("vanish:qmc@33s:2s", Kind::Vanish, QMC, 33.0, 2.0),
];

/// The parts' clocks in the default scenario: both 1.3 % slow.
const SLOW_CLOCKS: &str = "mpu:-1.3%,qmc:-1.3%";

/// Stamp error goal after the clocks have settled, µs rms.
const STAMP_RMS_GOAL_US: f64 = 20.0;
/// From when stamps are held to the goal, s of emulated time.
const STAMPS_FROM_S: f64 = 10.0;
/// A stall must be named within this long, s.
const STALL_REPORT_S: f64 = 0.050;

/// `cargo xtask e2e [--scenario faults|boot-stall|sine] [--seconds S] [--out DIR]`.
pub fn e2e(args: &[String]) -> Result<()> {
    let scenario = arg_value(args, "--scenario").unwrap_or_else(|| "faults".into());
    let (default_s, faults, clock, sine, stall_from_boot): (f64, &[Fault], Option<&str>, _, bool) =
        match scenario.as_str() {
            "faults" => (40.0, FAULTS, Some(SLOW_CLOCKS), None, false),
            "sine" => (20.0, &[], None, Some("3,3"), false),
            "boot-stall" => (3.0, &[], None, None, true),
            other => bail!("unknown scenario `{other}` (faults, sine, boot-stall)"),
        };
    let seconds: f64 = arg_value(args, "--seconds")
        .map(|s| s.parse())
        .transpose()
        .context("--seconds")?
        .unwrap_or(default_s);
    let faults: Vec<Fault> = faults
        .iter()
        .copied()
        .filter(|x| x.at_s + x.dur_s + 1.0 < seconds)
        .collect();
    let wall = Instant::now();
    let elf = build_firmware()?;
    let sim_dir = ensure_sim()?;
    let out = out_dir(&arg_value(args, "--out").unwrap_or_else(|| format!("e2e-{scenario}")))?;
    let stream = out.join("stream.csv");
    let mut gen = std::process::Command::new("node");
    gen.arg(sim_dir.join("src/cli.js"))
        .args(["gen-stream", "--seed", "7", "--seconds"])
        .arg(format!("{}", seconds + 60.0))
        .arg("--out")
        .arg(&stream);
    if let Some(s) = sine {
        gen.args(["--sine", s]);
    }
    run(&mut gen)?;
    let mut sim_args: Vec<String> = vec![
        "--seconds".into(),
        format!("{}", seconds + 60.0),
        "--stream".into(),
        stream.display().to_string(),
        "--served".into(),
        out.display().to_string(),
        "--summary".into(),
        out.join("summary.json").display().to_string(),
        "--log".into(),
        out.join("firmware.log").display().to_string(),
        "--quiet".into(),
        "--exit-on-disconnect".into(),
    ];
    if let Some(c) = clock {
        sim_args.push("--clock".into());
        sim_args.push(c.into());
    }
    for x in &faults {
        sim_args.push("--fault".into());
        sim_args.push(x.spec.into());
    }
    if stall_from_boot {
        sim_args.push("--fault".into());
        sim_args.push("stall:qmc@0s".into());
    }
    let sim = Sim::start(&elf, &sim_args, &out)?;
    let session = match session(sim.port, seconds, !stall_from_boot) {
        Ok(s) => s,
        Err(e) => {
            sim.finish_after_error();
            print_log_tail(&out.join("firmware.log"));
            return Err(e);
        }
    };
    sim.wait("the end-to-end run")?;
    let imu = emu_check::read_imu(&out.join("mpu_served.csv"))?;
    let mag = emu_check::read_mag(&out.join("qmc_served.csv"))?;
    let mut r = Report::default();
    writeln!(
        r.text,
        "# End-to-end emulator test: scenario `{scenario}`\n\n{seconds} s of emulated time, firmware {}{}\n",
        elf.display(),
        clock.map(|c| format!(", part clocks {c}")).unwrap_or_default()
    )?;
    if stall_from_boot {
        check_boot_stall(&session, &mut r);
    } else {
        check_tables(&session, &imu, &mag, &mut r)?;
        check_losses(&session, &imu, &mag, &faults, &mut r);
        check_stamps(&session, &imu, &mag, &mut r);
        check_faults(&session, &imu, &mag, &faults, &mut r);
        check_calibration(&session, &imu, &mut r);
    }
    writeln!(r.text, "\nwall time: {:.1} s", wall.elapsed().as_secs_f64())?;
    std::fs::write(out.join("report.md"), &r.text)?;
    println!("{}", r.text);
    if !r.failures.is_empty() {
        bail!(
            "end-to-end test `{scenario}` FAILED:\n  {}",
            r.failures.join("\n  ")
        );
    }
    println!(
        "end-to-end test `{scenario}` passed ({:.1} s wall); report in {}",
        wall.elapsed().as_secs_f64(),
        out.join("report.md").display()
    );
    Ok(())
}

fn print_log_tail(log: &Path) {
    let tail = std::fs::read_to_string(log).unwrap_or_default();
    let tail: Vec<&str> = tail.lines().rev().take(40).collect();
    eprintln!("--- last lines of {} ---", log.display());
    for l in tail.iter().rev() {
        eprintln!("{l}");
    }
}

#[derive(Default)]
struct Report {
    text: String,
    failures: Vec<String>,
}

impl Report {
    fn fail(&mut self, what: String) {
        self.failures.push(what);
    }
}

/// Everything the host saw of the device.
struct Session {
    /// Tables of the round answering `GetTables`.
    tables: BTreeMap<usize, imu_proto::AllanTable>,
    snapshot: u32,
    /// Events, with the sample batches, in arrival order up to the tables (the calibration
    /// upload resets the engines, and so the split positions).
    events: Vec<Event>,
    /// Every event of the run.
    all_events: Vec<Event>,
    batches: Vec<SampleBatch>,
    /// Device status right after the tables.
    status: imu_proto::Status,
    /// Calibrated batches after the upload.
    cal_batches: Vec<SampleBatch>,
    cal: Calibration,
    cal_report: String,
    persisted: bool,
}

/// A calibration far enough from identity that its effect on every channel is visible, within
/// the physical bounds the device checks.
fn test_calibration() -> Result<Calibration> {
    let m = [[1.02, 0.01, 0.0], [0.0, 0.98, -0.02], [0.005, 0.0, 1.01]];
    let accel = Affine::from_float(CalSensor::Accel, m, [12.0, -30.0, 250.0])
        .map_err(|e| anyhow::anyhow!("{e:?}"))?;
    let gyro = GyroCorrection::from_float(m, [-40.0, 25.0, 13.0], [0.01, -0.02, 0.0], -3000)
        .map_err(|e| anyhow::anyhow!("{e:?}"))?;
    let mag = Affine::from_float(CalSensor::Mag, m, [100.0, -200.0, 50.0])
        .map_err(|e| anyhow::anyhow!("{e:?}"))?;
    // Fitted at the ranges the firmware runs, as the host's calibration file would say.
    let s = pico_imu_core::config::scales();
    Calibration::fitted(accel, gyro, mag, [1.0 / s.accel, 1.0 / s.gyro, 1.0 / s.mag])
        .map_err(|e| anyhow::anyhow!("{e:?}"))
}

fn session(port: u16, seconds: f64, calibrate: bool) -> Result<Session> {
    let long = Duration::from_secs(300);
    let mut link = Link::connect(port, Duration::from_secs(30))?;
    let id = link.request(Request::Identify, long)?;
    let Reply::Identity(ident) = id else {
        bail!("Identify answered {id:?}")
    };
    eprintln!("xtask: device: {ident:?}");
    if link.request(
        Request::SetIntervals {
            status_ms: 1000,
            tables_ms: 0,
        },
        long,
    )? != Reply::Ok
    {
        bail!("SetIntervals refused");
    }
    link.wait_until(
        Duration::from_secs(900),
        "the device's uptime to reach the end of the run",
        |g| {
            g.statuses
                .last()
                .is_some_and(|s| s.uptime_us as f64 * 1e-6 >= seconds - 1.0)
        },
    )?;
    link.got.tables.clear();
    let snapshot = match link.request(Request::GetTables, long)? {
        Reply::Tables { snapshot } => snapshot,
        other => bail!("GetTables answered {other:?}"),
    };
    link.wait_until(long, "all channel tables of the round", |g| {
        g.tables.len() == Channel::ALL.len() && g.tables.values().all(|t| t.snapshot == snapshot)
    })?;
    let tables = std::mem::take(&mut link.got.tables);
    let events = link.got.events.clone();
    let status = match link.request(Request::GetStatus, long)? {
        Reply::Status(s) => s,
        other => bail!("GetStatus answered {other:?}"),
    };
    let batches = std::mem::take(&mut link.got.batches);
    let mut s = Session {
        tables,
        snapshot,
        events,
        all_events: Vec::new(),
        batches,
        status,
        cal_batches: Vec::new(),
        cal: Calibration::identity(),
        cal_report: String::new(),
        persisted: false,
    };
    if calibrate {
        calibration_round_trip(&mut link, &mut s)?;
    }
    s.all_events = std::mem::take(&mut link.got.events);
    Ok(s)
}

/// Upload a calibration, read it back, see it applied to the streamed samples, persist it.
fn calibration_round_trip(link: &mut Link, s: &mut Session) -> Result<()> {
    let long = Duration::from_secs(300);
    let cal = test_calibration()?;
    let mut buf = [0u8; 256];
    let blob = encode_blob(&cal, &mut buf).map_err(|e| anyhow::anyhow!("{e:?}"))?;
    let hblob = HVec::from_slice(blob).map_err(|_| anyhow::anyhow!("blob too large"))?;
    let r = link.request(
        Request::SetCalibration {
            blob: hblob.clone(),
            persist: false,
        },
        long,
    )?;
    writeln!(s.cal_report, "SetCalibration → {r:?}")?;
    if r != Reply::Ok {
        bail!("SetCalibration answered {r:?}");
    }
    match link.request(Request::GetCalibration, long)? {
        Reply::Calibration { blob: b, status } => {
            writeln!(
                s.cal_report,
                "GetCalibration → {} bytes, {status:?}; equal to the upload: {}",
                b.len(),
                b == hblob
            )?;
            if b != hblob {
                bail!("the calibration read back differs from the one uploaded");
            }
        }
        other => bail!("GetCalibration answered {other:?}"),
    }
    if link.request(Request::SetMode(StreamMode::Calibrated), long)? != Reply::Ok {
        bail!("SetMode(Calibrated) refused");
    }
    link.got.batches.clear();
    if let Err(e) = link.wait_until(Duration::from_secs(90), "calibrated sample batches", |g| {
        g.batches.iter().filter(|b| b.calibrated).count() >= 10
    }) {
        writeln!(s.cal_report, "{e:#}")?;
    }
    let r = link.request(
        Request::SetCalibration {
            blob: hblob.clone(),
            persist: true,
        },
        long,
    )?;
    writeln!(s.cal_report, "SetCalibration(persist) → {r:?}")?;
    let back = link.request(Request::GetCalibration, long)?;
    s.persisted = matches!(&back, Reply::Calibration { blob: b, status } if *b == hblob && status.source == imu_proto::CalSource::Flash);
    writeln!(
        s.cal_report,
        "GetCalibration after persisting → source Flash and same blob: {}",
        s.persisted
    )?;
    s.cal_batches = link
        .got
        .batches
        .iter()
        .filter(|b| b.calibrated)
        .cloned()
        .collect();
    s.cal = cal;
    Ok(())
}

/// The device's split positions and losses per sensor, from its `Gap` events: `at` → (lost,
/// causes).
fn gaps(events: &[Event], sensor: Sensor) -> BTreeMap<u64, (u64, Vec<GapCause>)> {
    let mut m: BTreeMap<u64, (u64, Vec<GapCause>)> = BTreeMap::new();
    for e in events {
        if let Event::Gap {
            sensor: s,
            at,
            cause,
            lost,
            ..
        } = e
        {
            if *s == sensor {
                let x = m.entry(*at).or_default();
                x.0 += u64::from(*lost);
                x.1.push(*cause);
            }
        }
    }
    m
}

/// The ten tables bit for bit against the host replay, and one snapshot for all.
fn check_tables(s: &Session, imu: &[ImuRaw], mag: &[MagRaw], r: &mut Report) -> Result<()> {
    let identity = Calibration::identity();
    let splits: [BTreeSet<u64>; 2] = [
        gaps(&s.events, Sensor::Imu).keys().copied().collect(),
        gaps(&s.events, Sensor::Mag).keys().copied().collect(),
    ];
    let mut checks: Vec<ChannelCheck> = Vec::new();
    for (idx, table) in &s.tables {
        let ch = Channel::ALL[*idx];
        let rep = if ch.sensor() == Sensor::Mag {
            replay::replay::<allan::MagEngine, _>(
                mag,
                table.pushed,
                |x| x.k,
                |x| replay::channel_input(ch, None, Some(&identity.apply_mag(x.mag))).unwrap_or(0),
                &splits[1],
            )
        } else {
            replay::replay::<allan::DeviceEngine, _>(
                imu,
                table.pushed,
                |x| x.k,
                |x| {
                    let i = replay::imu_inputs(&identity, x.accel, x.gyro, Some(x.temp));
                    replay::channel_input(ch, Some(&i), None).unwrap_or(0)
                },
                &splits[0],
            )
        };
        checks.push(replay::compare(table, &rep));
    }
    r.text.push_str("## Allan tables: device vs host replay of the served samples\n\n| channel | pushed | gaps (device/host) | levels compared | result |\n|---|---|---|---|---|\n");
    for c in &checks {
        let ok = c.mismatches.is_empty() && c.levels_compared > 0;
        writeln!(
            r.text,
            "| {} | {} | {}/{} | {} | {} |",
            c.channel.name(),
            c.pushed,
            c.device_gaps,
            c.host_gaps,
            c.levels_compared,
            if ok {
                "bit-exact".to_string()
            } else {
                c.mismatches.join("; ")
            }
        )?;
        if !ok {
            r.fail(format!(
                "{}: {}",
                c.channel.name(),
                c.mismatches.first().cloned().unwrap_or("no levels".into())
            ));
        }
    }
    if checks.len() != Channel::ALL.len() {
        r.fail(format!(
            "only {} of {} tables",
            checks.len(),
            Channel::ALL.len()
        ));
    }
    // One instant: one round, one time; every IMU channel the same count, every magnetometer
    // channel too.
    let rounds: BTreeSet<(u32, u64)> = s.tables.values().map(|t| (t.snapshot, t.t_us)).collect();
    let pushed = |sensor: Sensor| -> BTreeSet<u64> {
        s.tables
            .values()
            .filter(|t| t.channel.sensor() == sensor)
            .map(|t| t.pushed)
            .collect()
    };
    let consistent = rounds.len() == 1
        && rounds.iter().all(|(n, _)| *n == s.snapshot)
        && pushed(Sensor::Imu).len() == 1
        && pushed(Sensor::Mag).len() == 1;
    writeln!(
        r.text,
        "\nSnapshot: round(s) {rounds:?}, IMU pushed {:?}, magnetometer pushed {:?}: {}\n",
        pushed(Sensor::Imu),
        pushed(Sensor::Mag),
        if consistent {
            "one instant"
        } else {
            "NOT consistent"
        }
    )?;
    if !consistent {
        r.fail("the tables of one GetTables answer are not one snapshot".into());
    }
    Ok(())
}

/// Ground truth per pushed position: the slots skipped before served sample `i` (the i-th
/// sample pushed), for `i ≥ 1`.
fn truth_jumps(slots: &[u64], pushed: u64) -> BTreeMap<u64, u64> {
    slots
        .windows(2)
        .enumerate()
        .take(pushed.saturating_sub(1) as usize)
        .filter(|(_, w)| w[1] != w[0] + 1)
        .map(|(i, w)| ((i + 1) as u64, w[1].saturating_sub(w[0] + 1)))
        .collect()
}

/// Every loss the device reported equals the models' ground truth, position by position.
fn check_losses(s: &Session, imu: &[ImuRaw], mag: &[MagRaw], faults: &[Fault], r: &mut Report) {
    r.text.push_str("## Losses: device vs the models' ground truth\n\n| sensor | samples pushed | lost (device Gap events) | lost (model: slots never served) | per position | status counter |\n|---|---|---|---|---|---|\n");
    for (sensor, slots, counter) in [
        (
            Sensor::Imu,
            imu.iter().map(|x| x.slot).collect::<Vec<_>>(),
            s.status.samples_dropped,
        ),
        (
            Sensor::Mag,
            mag.iter().map(|x| x.slot).collect::<Vec<_>>(),
            s.status.mag_dropped,
        ),
    ] {
        let ch = if sensor == Sensor::Imu {
            Channel::Ax
        } else {
            Channel::Mx
        };
        let pushed = s.tables.get(&ch.index()).map_or(0, |t| t.pushed);
        let truth = truth_jumps(&slots, pushed);
        let device: BTreeMap<u64, u64> = gaps(&s.events, sensor)
            .into_iter()
            .filter(|(at, (lost, _))| *at < pushed && *lost > 0)
            .map(|(at, (lost, _))| (at, lost))
            .collect();
        let (t_sum, d_sum): (u64, u64) = (truth.values().sum(), device.values().sum());
        let mismatched: Vec<String> = truth
            .keys()
            .chain(device.keys())
            .collect::<BTreeSet<_>>()
            .into_iter()
            .filter(|at| truth.get(at) != device.get(at))
            .take(5)
            .map(|at| {
                format!(
                    "at {at}: device {:?}, model {:?}",
                    device.get(at),
                    truth.get(at)
                )
            })
            .collect();
        // The device's own counter equals the sum of its Gap events so far.
        let all: u64 = gaps(&s.events, sensor).values().map(|v| v.0).sum();
        let _ = writeln!(
            r.text,
            "| {sensor:?} | {pushed} | {d_sum} | {t_sum} | {} | {counter} (events {all}) |",
            if mismatched.is_empty() {
                "equal".to_string()
            } else {
                mismatched.join("; ")
            }
        );
        if !mismatched.is_empty() || d_sum != t_sum {
            r.fail(format!(
                "{sensor:?}: device reports {d_sum} samples lost, the model {t_sum}: {}",
                mismatched.join("; ")
            ));
        }
        if counter != all {
            r.fail(format!(
                "{sensor:?}: status counter {counter} differs from its Gap events' sum {all}"
            ));
        }
        // Losses only where a fault was.
        let served_ns: Vec<f64> = if sensor == Sensor::Imu {
            imu.iter().map(|x| x.served_ns).collect()
        } else {
            mag.iter().map(|x| x.served_ns).collect()
        };
        for (at, lost) in &truth {
            let t = served_ns[*at as usize] * 1e-9;
            let inside = faults
                .iter()
                .any(|x| t >= x.at_s && t <= x.at_s + x.dur_s + 3.0);
            if !inside {
                r.fail(format!(
                    "{sensor:?}: {lost} samples lost at {t:.3} s, outside every fault"
                ));
            }
        }
    }
}

/// Stamp errors against the models' sample instants, matched by slot (and checked by value).
fn check_stamps(s: &Session, imu: &[ImuRaw], mag: &[MagRaw], r: &mut Report) {
    r.text.push_str("\n## Timestamps: device stamps vs the instants the models sampled\n\n| sensor | samples compared | mean (fixed latency) | rms about the mean | largest | value mismatches | stamps going back |\n|---|---|---|---|---|---|---|\n");
    let imu_by_slot: BTreeMap<u64, &ImuRaw> = imu.iter().map(|x| (x.slot, x)).collect();
    let mag_by_slot: BTreeMap<u64, &MagRaw> = mag.iter().map(|x| (x.slot, x)).collect();
    for sensor in [Sensor::Imu, Sensor::Mag] {
        let mut errs = Vec::new();
        let mut wrong = 0usize;
        let mut back = 0usize;
        let mut last: Option<u64> = None;
        let samples: Vec<(u32, u64, Option<bool>)> = s
            .batches
            .iter()
            .filter(|b| b.calibrated)
            .flat_map(|b| -> Vec<(u32, u64, Option<bool>)> {
                if sensor == Sensor::Imu {
                    b.imu
                        .iter()
                        .map(|x| {
                            let same = imu_by_slot.get(&u64::from(x.seq)).map(|m| {
                                m.accel.map(i32::from) == x.accel && m.gyro.map(i32::from) == x.gyro
                            });
                            (x.seq, x.t_us, same)
                        })
                        .collect()
                } else {
                    b.mag
                        .iter()
                        .map(|x| {
                            let same = mag_by_slot
                                .get(&u64::from(x.seq))
                                .map(|m| m.mag.map(i32::from) == x.mag);
                            (x.seq, x.t_us, same)
                        })
                        .collect()
                }
            })
            .collect();
        for (seq, t_us, same) in &samples {
            if last.is_some_and(|l| *t_us <= l) {
                back += 1;
            }
            last = Some(*t_us);
            match same {
                Some(true) => {}
                _ => {
                    wrong += 1;
                    continue;
                }
            }
            let t_ns = match sensor {
                Sensor::Imu => imu_by_slot[&u64::from(*seq)].t_ns,
                Sensor::Mag => mag_by_slot[&u64::from(*seq)].t_ns,
            };
            if t_ns * 1e-9 >= STAMPS_FROM_S {
                errs.push(*t_us as f64 - t_ns * 1e-3);
            }
        }
        let n = errs.len().max(1) as f64;
        let mean = errs.iter().sum::<f64>() / n;
        let rms = (errs.iter().map(|e| (e - mean).powi(2)).sum::<f64>() / n).sqrt();
        let max = errs.iter().map(|e| (e - mean).abs()).fold(0.0, f64::max);
        let _ = writeln!(
            r.text,
            "| {sensor:?} | {} | {mean:+.1} µs | {rms:.1} µs | {max:.1} µs | {wrong} of {} | {back} |",
            errs.len(),
            samples.len()
        );
        if errs.is_empty() {
            r.fail(format!("{sensor:?}: no stamps to compare"));
        }
        if rms > STAMP_RMS_GOAL_US {
            r.fail(format!(
                "{sensor:?}: stamp error {rms:.1} µs rms after {STAMPS_FROM_S} s (goal ≤ {STAMP_RMS_GOAL_US} µs)"
            ));
        }
        if wrong > 0 {
            r.fail(format!(
                "{sensor:?}: {wrong} streamed samples are not the model's sample of the same slot"
            ));
        }
        if back > 0 {
            r.fail(format!(
                "{sensor:?}: {back} stamps not after the previous one"
            ));
        }
    }
    let _ = writeln!(
        r.text,
        "\nMeasured periods (status): IMU {} ns, magnetometer {} ns.",
        s.status.imu_period_ns, s.status.mag_period_ns
    );
}

/// Per fault: what the device reported and what it lost (the fault table of docs/firmware.md),
/// stalls named in time, NACK bursts cheap.
fn check_faults(s: &Session, imu: &[ImuRaw], mag: &[MagRaw], faults: &[Fault], r: &mut Report) {
    r.text.push_str("\n## Faults: what the device reported, what was lost\n\n| fault | reported by the device | IMU samples lost (cause) | magnetometer samples lost (cause) | model: IMU / magnetometer slots lost |\n|---|---|---|---|---|\n");
    let imu_slots: Vec<u64> = imu.iter().map(|x| x.slot).collect();
    let mag_slots: Vec<u64> = mag.iter().map(|x| x.slot).collect();
    for (i, x) in faults.iter().enumerate() {
        let from = x.at_s;
        let until = faults.get(i + 1).map_or(f64::INFINITY, |n| n.at_s);
        let in_window = |t_us: u64| {
            let t = t_us as f64 * 1e-6;
            t >= from && t < until
        };
        let mut reported: Vec<String> = Vec::new();
        let mut lost = [BTreeMap::<String, u64>::new(), BTreeMap::new()];
        let mut stalled_at = None;
        for e in &s.all_events {
            let (t, text) = match e {
                Event::SensorLost { sensor, t_us } => (*t_us, format!("SensorLost({sensor:?})")),
                Event::SensorBack {
                    sensor,
                    t_us,
                    down_us,
                } => (
                    *t_us,
                    format!(
                        "SensorBack({sensor:?}, down {:.0} ms)",
                        *down_us as f64 * 1e-3
                    ),
                ),
                Event::SensorStalled {
                    sensor,
                    t_us,
                    since_us,
                } => {
                    if Some(*sensor) == x.sensor && in_window(*t_us) && stalled_at.is_none() {
                        stalled_at = Some((*t_us, *since_us));
                    }
                    (*t_us, format!("SensorStalled({sensor:?})"))
                }
                Event::BusFault { t_us, fault } => (*t_us, format!("BusFault({fault:?})")),
                Event::BusRecovered {
                    t_us, sda_released, ..
                } => (
                    *t_us,
                    format!(
                        "BusRecovered({})",
                        if *sda_released {
                            "SDA free"
                        } else {
                            "SDA held"
                        }
                    ),
                ),
                Event::Gap {
                    sensor,
                    cause,
                    lost: n,
                    t_us,
                    ..
                } => {
                    if in_window(*t_us) && *n > 0 {
                        *lost[*sensor as usize]
                            .entry(format!("{cause:?}"))
                            .or_default() += u64::from(*n);
                    }
                    continue;
                }
            };
            if in_window(t) && !reported.contains(&text) {
                reported.push(text);
            }
        }
        let model = |slots: &[u64], served: &dyn Fn(usize) -> f64| -> u64 {
            slots
                .windows(2)
                .enumerate()
                .filter(|(i, _)| {
                    let t = served(i + 1) * 1e-9;
                    t >= from && t < until
                })
                .map(|(_, w)| w[1].saturating_sub(w[0] + 1))
                .sum()
        };
        let mi = model(&imu_slots, &|i| imu[i].served_ns);
        let mm = model(&mag_slots, &|i| mag[i].served_ns);
        let show = |m: &BTreeMap<String, u64>| {
            if m.is_empty() {
                "0".to_string()
            } else {
                m.iter()
                    .map(|(c, n)| format!("{n} ({c})"))
                    .collect::<Vec<_>>()
                    .join(", ")
            }
        };
        let _ = writeln!(
            r.text,
            "| `{}` | {} | {} | {} | {mi} / {mm} |",
            x.spec,
            if reported.is_empty() {
                "nothing".to_string()
            } else {
                reported.join(", ")
            },
            show(&lost[0]),
            show(&lost[1])
        );
        if x.kind == Kind::Stall {
            match stalled_at {
                Some((t, _)) if (t as f64 * 1e-6 - from) <= STALL_REPORT_S => {}
                Some((t, _)) => r.fail(format!(
                    "`{}`: stall named {:.1} ms after it began (goal ≤ {:.0} ms)",
                    x.spec,
                    (t as f64 * 1e-6 - from) * 1e3,
                    STALL_REPORT_S * 1e3
                )),
                None => r.fail(format!("`{}`: the stall was never reported", x.spec)),
            }
        }
        if x.kind == Kind::Nack {
            let (sensor_lost, period) = match x.sensor {
                Some(Sensor::Mag) => (mm, 1.0 / 200.0 / 0.987),
                _ => (mi, 1.0 / 1000.0 / 0.987),
            };
            let bound = (x.dur_s / period).ceil() as u64 + 2;
            if sensor_lost > bound {
                r.fail(format!(
                    "`{}`: {sensor_lost} samples lost, more than the fault's {:.0} ms + 2 samples ({bound})",
                    x.spec,
                    x.dur_s * 1e3
                ));
            }
        }
    }
}

/// A magnetometer that never produces: named within 50 ms of its start, status not "Ok".
fn check_boot_stall(s: &Session, r: &mut Report) {
    let stalled = s.all_events.iter().chain(&s.events).find_map(|e| match e {
        Event::SensorStalled {
            sensor: Sensor::Mag,
            t_us,
            since_us,
        } => Some((*t_us, *since_us)),
        _ => None,
    });
    let _ = writeln!(
        r.text,
        "## Magnetometer stalled from boot\n\nSensorStalled: {stalled:?}; status: magnetometer {:?}, IMU {:?}, {} IMU samples\n",
        s.status.mag, s.status.imu, s.status.samples_taken
    );
    match stalled {
        Some((t, since)) if t.saturating_sub(since) as f64 * 1e-6 <= STALL_REPORT_S => {}
        Some((t, since)) => r.fail(format!(
            "the stall was named {:.1} ms after the part started",
            t.saturating_sub(since) as f64 * 1e-3
        )),
        None => r.fail("a magnetometer that never produced was not reported stalled".into()),
    }
    if s.status.mag != SensorState::Stalled {
        r.fail(format!(
            "status says the magnetometer is {:?}",
            s.status.mag
        ));
    }
    if s.status.imu != SensorState::Ok || s.status.samples_taken == 0 {
        r.fail("the IMU did not run beside the stalled magnetometer".into());
    }
}

/// Every calibrated IMU sample streamed after the upload is the uploaded correction applied to
/// the model's sample of the same slot.
fn check_calibration(s: &Session, imu: &[ImuRaw], r: &mut Report) {
    let by_slot: BTreeMap<u64, &ImuRaw> = imu.iter().map(|x| (x.slot, x)).collect();
    let mut total = 0;
    let mut matched = 0;
    for b in &s.cal_batches {
        for x in &b.imu {
            total += 1;
            if let Some(m) = by_slot.get(&u64::from(x.seq)) {
                if s.cal.apply_accel(m.accel) == x.accel
                    && s.cal.apply_gyro(m.gyro, m.temp) == x.gyro
                    && Some(i32::from(m.temp)) == x.temp
                {
                    matched += 1;
                }
            }
        }
    }
    let _ = writeln!(
        r.text,
        "\n## Calibration round trip\n\n{}calibrated IMU samples streamed after the upload: {total}; equal to the uploaded correction applied to the model's sample of the same slot: {matched}\n",
        s.cal_report
    );
    if !s.persisted {
        r.fail("the calibration written to flash was not read back with source Flash".into());
    }
    if total == 0 || matched != total {
        r.fail(format!(
            "calibration not applied as uploaded: {matched} of {total} streamed samples match"
        ));
    }
}
