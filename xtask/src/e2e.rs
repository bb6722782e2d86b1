//! `cargo xtask e2e`: the firmware on the emulated board, faults injected, everything the device
//! says checked against the models' ground truth (docs/emulator.md, "The end-to-end test").
//!
//! Scenarios:
//! * `faults` (default): both parts' clocks 1.3 % slow and every fault kind the harness has
//!   (NACK bursts, parts unpowered, SDA held with arbitration lost or with a hung START, CPU
//!   stalls that overflow the FIFO, parts that stop producing), then the calibration round trip;
//! * `boot-stall`: the magnetometer never sets DRDY from boot;
//! * `sine`: no faults, a sine on the x gyro (the device's 64-bit squares in the Allan engine);
//! * `orientation`: the board turned through a known trajectory, the device's attitude and
//!   heading against the truth, with the identity calibration and the part's (`orientation.rs`).
use std::borrow::Cow;
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;
use std::time::Instant;

use anyhow::{bail, Result};
use imu_cal::device::Calibration;
use imu_proto::{Event, SampleBatch, Sensor};

use crate::emu::{build_firmware, ensure_sim, out_dir, Sim};
use crate::emu_check;
use crate::run;
mod checks;
mod faults;
mod orientation;
mod session;
use checks::{check_calibration, check_losses, check_stamps, check_tables};
use faults::{check_boot_stall, check_faults};
use session::session;

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

#[derive(Clone, Debug)]
struct Fault {
    /// The emulator's `--fault` spec (its time is replaced by `at_s`).
    spec: Cow<'static, str>,
    kind: Kind,
    sensor: Option<Sensor>,
    at_s: f64,
    /// The fault's own duration, s (0 for a count or until recovered).
    dur_s: f64,
}

const fn f(spec: &'static str, kind: Kind, sensor: Option<Sensor>, at_s: f64, dur_s: f64) -> Fault {
    Fault {
        spec: Cow::Borrowed(spec),
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

/// A schedule of faults of every kind in [`FAULTS`] drawn from `seed`: random kinds, sensors,
/// durations and counts, one at a time from 3 s on, each 1.2–2.5 s after the last one ended,
/// up to 3 s before `seconds`. The listed schedule tests every kind where it was placed; this
/// one tests them where nobody placed them (the fault handling must not depend on a fault's
/// length, its order or its phase).
fn random_faults(seed: u64, seconds: f64) -> Vec<Fault> {
    // SplitMix64 (the same draws for the same SEED: the CI runs and docs/firmware.md name
    // schedules by it, so swapping the generator, e.g. for imu_sim::Rng, would re-draw them).
    let mut state = seed;
    let mut next = move || {
        state = state.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = state;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
    };
    let mut out = Vec::new();
    let mut at = 3.0 + next();
    loop {
        let (part, sensor) = if next() < 0.5 {
            ("mpu", MPU)
        } else {
            ("qmc", QMC)
        };
        let which = (next() * 8.0) as u32;
        let draw = next();
        // A duration in whole ms between the bounds given in ms.
        let ms = |lo: f64, hi: f64| (lo + (hi - lo) * draw).round();
        let (spec, kind, sensor, dur_s) = match which {
            0 => {
                let d = ms(5.0, 80.0);
                (format!("nack:{part}@0s:{d}ms"), Kind::Nack, sensor, d / 1e3)
            }
            1 => {
                let n = 1 + (draw * 6.0) as u32;
                (format!("nack:{part}@0s:{n}"), Kind::NackCount, sensor, 0.0)
            }
            2 => {
                let d = ms(50.0, 2500.0);
                (
                    format!("vanish:{part}@0s:{d}ms"),
                    Kind::Vanish,
                    sensor,
                    d / 1e3,
                )
            }
            3 => {
                let d = ms(60.0, 1500.0);
                (
                    format!("stall:{part}@0s:{d}ms"),
                    Kind::Stall,
                    sensor,
                    d / 1e3,
                )
            }
            4 => {
                let d = ms(5.0, 60.0);
                (format!("stuck@0s:{d}ms"), Kind::Stuck, None, d / 1e3)
            }
            5 => ("stuck@0s".to_string(), Kind::Stuck, None, 0.0),
            6 => {
                let d = ms(5.0, 60.0);
                (format!("hang@0s:{d}ms"), Kind::Hang, None, d / 1e3)
            }
            _ => {
                let d = ms(20.0, 600.0);
                (format!("overflow@0s:{d}ms"), Kind::Cpu, None, d / 1e3)
            }
        };
        if at + dur_s + 3.0 > seconds {
            return out;
        }
        out.push(Fault {
            spec: Cow::Owned(spec),
            kind,
            sensor,
            at_s: (at * 1e4).round() / 1e4,
            dur_s,
        });
        at += dur_s + 1.2 + 1.3 * next();
    }
}

/// A fault from its emulator spec (`nack:mpu@5s:30ms`, `nack:qmc@5s:3`, `vanish:mpu@8s:200ms`,
/// `stall:qmc@20s:1s`, `stuck@25s`, `stuck@12s:50ms`, `hang@14s:50ms`, `overflow@16s:150ms`).
fn parse_fault(spec: &str) -> Result<Fault> {
    let bad = || {
        anyhow::anyhow!("--fault {spec}: not a fault the checks know (e.g. nack:mpu@5s:30ms, stall:qmc@20s:1s, stuck@25s, hang@14s:50ms, overflow@16s:150ms)")
    };
    let (head, rest) = spec.split_once('@').ok_or_else(bad)?;
    let (at, arg) = match rest.split_once(':') {
        Some((at, arg)) => (at, Some(arg)),
        None => (rest, None),
    };
    let secs = |t: &str| -> Result<f64> {
        let v = match t.strip_suffix("ms") {
            Some(ms) => ms.parse::<f64>().map(|x| x / 1e3),
            None => t.strip_suffix('s').ok_or_else(bad)?.parse::<f64>(),
        };
        v.ok()
            .filter(|x| x.is_finite() && *x >= 0.0)
            .ok_or_else(bad)
    };
    let at_s = secs(at)?;
    let (name, sensor) = match head.split_once(':') {
        Some((name, "mpu")) => (name, MPU),
        Some((name, "qmc")) => (name, QMC),
        Some(_) => return Err(bad()),
        None => (head, None),
    };
    let count = arg.is_some_and(|a| a.bytes().all(|b| b.is_ascii_digit()));
    let dur_s = match arg {
        Some(a) if !count => secs(a)?,
        _ => 0.0,
    };
    let kind = match (name, sensor.is_some(), count) {
        ("nack", true, true) => Kind::NackCount,
        ("nack", true, false) if arg.is_some() => Kind::Nack,
        ("vanish", true, false) if arg.is_some() => Kind::Vanish,
        ("stall", true, false) => Kind::Stall,
        ("stuck", false, false) => Kind::Stuck,
        ("hang", false, false) if arg.is_some() => Kind::Hang,
        ("overflow", false, false) if arg.is_some() => Kind::Cpu,
        _ => return Err(bad()),
    };
    Ok(Fault {
        spec: Cow::Owned(spec.to_string()),
        kind,
        sensor,
        at_s,
        dur_s,
    })
}

/// The parts' clocks in the default scenario: both 1.3 % slow.
const SLOW_CLOCKS: &str = "mpu:-1.3%,qmc:-1.3%";

/// Stamp error goal after the clocks have settled, µs rms.
const STAMP_RMS_GOAL_US: f64 = 20.0;
/// From when stamps are held to the goal, s of emulated time.
const STAMPS_FROM_S: f64 = 10.0;
/// A stall must be named within this long, s.
const STALL_REPORT_S: f64 = 0.050;

/// The fault's `--fault` spec for the emulator with its time moved to `at_s`.
fn spec_at(spec: &str, at_s: f64) -> String {
    match spec.split_once('@') {
        Some((head, rest)) => {
            let tail = rest.find('s').map_or("", |i| &rest[i + 1..]);
            format!("{head}@{at_s}s{tail}")
        }
        None => spec.to_string(),
    }
}

/// The scenarios of `cargo xtask e2e --scenario`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Scenario {
    /// The six faults, one at a time, with both parts' clocks 1.3 % slow (40 s).
    Faults,
    /// A sine on the gyro, no faults (20 s).
    Sine,
    /// The magnetometer stalled from boot (3 s).
    BootStall,
    /// The board turned through the standard trajectory twice, identity calibration then the
    /// part's: attitude and heading against the truth.
    Orientation,
}

impl Scenario {
    /// The name on the command line and in the output folder and report.
    pub fn name(self) -> &'static str {
        match self {
            Scenario::Faults => "faults",
            Scenario::Sine => "sine",
            Scenario::BootStall => "boot-stall",
            Scenario::Orientation => "orientation",
        }
    }
}

/// `cargo xtask e2e [--scenario faults|boot-stall|sine|orientation] [--seconds S] [--shift-ms MS] [--out DIR] [--clock CLOCKS]`.
#[derive(Debug, Clone, clap::Args)]
pub struct E2eArgs {
    /// Which scenario to run.
    #[arg(long, value_enum, default_value_t = Scenario::Faults)]
    pub scenario: Scenario,
    /// Emulated seconds (default: the scenario's own: faults 40, sine 20, boot-stall 3).
    #[arg(long, value_name = "S")]
    pub seconds: Option<f64>,
    /// Move every fault of the scenario later by MS milliseconds (0 to 1000): the firmware's
    /// fault handling must not depend on where in its cycle of bus transfers and ticks a
    /// fault begins.
    #[arg(long, value_name = "MS", default_value_t = 0.0)]
    pub shift_ms: f64,
    /// With the faults scenario: a random schedule of its fault kinds drawn from SEED (kinds,
    /// sensors, durations, counts, gaps) instead of the listed one; the report lists it.
    #[arg(long, value_name = "SEED", conflicts_with = "fault")]
    pub faults_seed: Option<u64>,
    /// With the faults scenario: this fault instead of the listed ones (repeat for more), in
    /// the emulator's form, e.g. `--fault stall:mpu@3.5s:1247ms --fault hang@6.1s:44ms`: to
    /// run one fault alone, or again a schedule that failed.
    #[arg(long, value_name = "SPEC")]
    pub fault: Vec<String>,
    /// Output folder under out/ (default: e2e-SCENARIO).
    #[arg(long, value_name = "DIR")]
    pub out: Option<String>,
    /// The parts' clock errors instead of the scenario's own (faults: both 1.3 % slow), as the
    /// emulator takes them, e.g. `mpu:+1.3%,qmc:+1.3%`.
    #[arg(long, value_name = "CLOCKS")]
    pub clock: Option<String>,
}

impl E2eArgs {
    /// `scenario` with every other flag at its default.
    pub fn scenario(scenario: Scenario) -> Self {
        E2eArgs {
            scenario,
            seconds: None,
            shift_ms: 0.0,
            faults_seed: None,
            fault: Vec::new(),
            out: None,
            clock: None,
        }
    }
}

/// Runs one end-to-end scenario (see [`E2eArgs`]).
pub fn e2e(args: &E2eArgs) -> Result<()> {
    let scenario = args.scenario.name();
    let (default_s, faults, clock, sine, stall_from_boot): (f64, &[Fault], Option<&str>, _, bool) =
        match args.scenario {
            Scenario::Faults => (40.0, FAULTS, Some(SLOW_CLOCKS), None, false),
            Scenario::Sine => (20.0, &[], None, Some("3,3"), false),
            Scenario::BootStall => (3.0, &[], None, None, true),
            Scenario::Orientation => {
                if let Some(c) = &args.clock {
                    bail!(
                        "--clock {c}: the orientation scenario runs both parts at nominal clocks"
                    );
                }
                return orientation::orientation(args);
            }
        };
    let clock = args.clock.as_deref().or(clock);
    let seconds: f64 = args.seconds.unwrap_or(default_s);
    let shift_ms = args.shift_ms;
    if !(0.0..=1000.0).contains(&shift_ms) {
        bail!("--shift-ms {shift_ms}: from 0 to 1000 ms");
    }
    let drawn;
    if (args.faults_seed.is_some() || !args.fault.is_empty()) && args.scenario != Scenario::Faults {
        bail!("--faults-seed, --fault: only the faults scenario has faults");
    }
    let faults = match args.faults_seed {
        Some(seed) => {
            drawn = random_faults(seed, seconds);
            &drawn[..]
        }
        None if !args.fault.is_empty() => {
            drawn = args
                .fault
                .iter()
                .map(|s| parse_fault(s))
                .collect::<Result<Vec<_>>>()?;
            &drawn[..]
        }
        None => faults,
    };
    let faults: Vec<Fault> = faults
        .iter()
        .cloned()
        .map(|mut x| {
            x.at_s += shift_ms / 1000.0;
            x
        })
        .collect();
    // A fault asked for by name must fit the run (the listed ones are cut to a shorter one).
    if let Some(x) = faults
        .iter()
        .find(|x| !args.fault.is_empty() && x.at_s + x.dur_s + 1.0 >= seconds)
    {
        bail!(
            "--fault {}: ends at {:.3} s, not 1 s before the run's end ({seconds} s; --seconds)",
            x.spec,
            x.at_s + x.dur_s
        );
    }
    let faults: Vec<Fault> = faults
        .into_iter()
        .filter(|x| x.at_s + x.dur_s + 1.0 < seconds)
        .collect();
    let wall = Instant::now();
    let elf = build_firmware()?;
    let sim_dir = ensure_sim()?;
    let out = out_dir(
        &args
            .out
            .clone()
            .unwrap_or_else(|| format!("e2e-{scenario}")),
    )?;
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
        sim_args.push(spec_at(&x.spec, x.at_s));
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
        "# End-to-end emulator test: scenario `{scenario}`\n\n{seconds} s of emulated time, firmware {}{}{}\n",
        elf.display(),
        clock.map(|c| format!(", part clocks {c}")).unwrap_or_default(),
        if shift_ms > 0.0 {
            format!(", every fault {shift_ms} ms later than listed")
        } else {
            String::new()
        }
    )?;
    if args.faults_seed.is_some() || !args.fault.is_empty() {
        writeln!(
            r.text,
            "Faults{}: {}\n",
            args.faults_seed
                .map(|seed| format!(" drawn from seed {seed}"))
                .unwrap_or_default(),
            faults
                .iter()
                .map(|x| format!("`{}`", spec_at(&x.spec, x.at_s)))
                .collect::<Vec<_>>()
                .join(", ")
        )?;
    }
    if stall_from_boot {
        check_boot_stall(&session, &mut r);
    } else {
        check_tables(&session, &imu, &mag, &mut r)?;
        check_losses(&session, &imu, &mag, &faults, &mut r);
        check_stamps(&session, &imu, &mag, &mut r);
        check_faults(&session, &imu, &mag, &faults, &mut r);
        check_calibration(&session, &imu, &mut r);
    }
    r.finish(scenario, &out, wall)
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
    /// The wall time, the report written to `out/report.md` and printed, and the verdict: an
    /// error listing the failures, or a line saying where the report is.
    fn finish(mut self, scenario: &str, out: &std::path::Path, wall: Instant) -> Result<()> {
        writeln!(
            self.text,
            "\nwall time: {:.1} s",
            wall.elapsed().as_secs_f64()
        )?;
        std::fs::write(out.join("report.md"), &self.text)?;
        println!("{}", self.text);
        if !self.failures.is_empty() {
            bail!(
                "end-to-end test `{scenario}` FAILED:\n  {}",
                self.failures.join("\n  ")
            );
        }
        println!(
            "end-to-end test `{scenario}` passed ({:.1} s wall); report in {}",
            wall.elapsed().as_secs_f64(),
            out.join("report.md").display()
        );
        Ok(())
    }
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
