//! The emulator commands: `cargo xtask e2e` (end-to-end test on the emulated board),
//! `cargo xtask bench-emu` (cycle budget report) and `cargo xtask demo` (the README's main job).
//! The harness itself is `sim/` (Node 20, rp2040js); docs/emulator.md explains it.
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use imu_cal::device::{encode_blob, Affine, Calibration, GyroCorrection, Sensor as CalSensor};
use imu_proto::{Channel, Reply, Request, StreamMode, Vec as HVec};

use crate::emu_check::{self, ChannelCheck};
use crate::emu_link::Link;
use crate::{cargo, root, run};

/// The firmware ELF `cargo build --release` produces.
pub fn firmware_elf() -> PathBuf {
    root().join("target/thumbv6m-none-eabi/release/pico-imu")
}

/// `node` 20 or newer on PATH.
pub fn node_available() -> bool {
    Command::new("node")
        .arg("-e")
        .arg("process.exit(Number(process.versions.node.split('.')[0]) >= 20 ? 0 : 1)")
        .status()
        .map(|s| s.success())
        .unwrap_or(false)
}

fn build_firmware() -> Result<PathBuf> {
    run(cargo().args(["build", "--release", "-p", "pico-imu"]))?;
    let elf = firmware_elf();
    if !elf.exists() {
        bail!("the firmware build did not produce {}", elf.display());
    }
    Ok(elf)
}

/// `npm ci` in sim/ unless node_modules is already there.
fn ensure_sim() -> Result<PathBuf> {
    if !node_available() {
        bail!("node >= 20 is needed for the emulator (sim/): install Node.js 20");
    }
    let sim = root().join("sim");
    if !sim.join("node_modules/rp2040js").exists() {
        run(Command::new("npm")
            .args(["ci", "--no-audit", "--no-fund", "--prefix"])
            .arg(&sim))?;
    }
    Ok(sim)
}

/// The emulator harness's own tests (`npm test` in sim/: the chip models, the rp2040js patches,
/// the profiler; the two that boot the firmware use the release ELF, built first).
pub fn harness_tests() -> Result<()> {
    build_firmware()?;
    let sim = ensure_sim()?;
    run(Command::new("npm")
        .args(["test", "--prefix"])
        .arg(&sim)
        .env("PICO_IMU_ELF", firmware_elf()))
}

fn out_dir(name: &str) -> Result<PathBuf> {
    let d = root().join("out").join(name);
    std::fs::create_dir_all(&d).with_context(|| format!("creating {}", d.display()))?;
    Ok(d)
}

/// Where our emulator child writes its TCP port: named after this process, so that a second
/// run in the same tree (another `cargo xtask test`) can never hand us its port.
fn port_file(out: &Path) -> PathBuf {
    out.join(format!("port.{}", std::process::id()))
}

fn arg_value(args: &[String], name: &str) -> Option<String> {
    args.iter()
        .position(|a| a == name)
        .and_then(|i| args.get(i + 1).cloned())
}

/// A running emulator with its USB port on TCP.
struct Sim {
    child: Child,
    port: u16,
}

impl Sim {
    fn start(elf: &Path, args: &[String], port_file: &Path) -> Result<Sim> {
        let _ = std::fs::remove_file(port_file);
        let sim = ensure_sim()?;
        let mut cmd = Command::new("node");
        cmd.arg(sim.join("src/cli.js"))
            .arg("run")
            .arg("--elf")
            .arg(elf)
            .arg("--port-file")
            .arg(port_file)
            .args(args);
        eprintln!("xtask: {cmd:?}");
        let child = cmd
            .current_dir(root())
            .stdin(Stdio::null())
            .spawn()
            .context("starting node sim/src/cli.js")?;
        let mut sim = Sim { child, port: 0 };
        let start = Instant::now();
        loop {
            if let Ok(s) = std::fs::read_to_string(port_file) {
                if let Ok(p) = s.trim().parse() {
                    sim.port = p;
                    return Ok(sim);
                }
            }
            if let Some(status) = sim.child.try_wait()? {
                bail!(
                    "the emulator exited before opening its USB port ({status}); its log is above"
                );
            }
            if start.elapsed() > Duration::from_secs(600) {
                bail!("the emulator did not open its USB port within 600 s");
            }
            std::thread::sleep(Duration::from_millis(100));
        }
    }

    /// Waits for the emulator to finish its run; fails if it reported a firmware stop.
    fn wait(mut self, what: &str) -> Result<()> {
        let status = self.child.wait()?;
        if !status.success() {
            bail!(
                "the emulator failed during {what} ({status}): see the decoded firmware log above"
            );
        }
        Ok(())
    }

    fn kill(mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }

    /// After the host link was dropped: give a `--exit-on-disconnect` run time to write its log
    /// and reports, then kill it.
    fn finish_after_error(mut self) {
        let start = Instant::now();
        while start.elapsed() < Duration::from_secs(30) {
            if let Ok(Some(_)) = self.child.try_wait() {
                return;
            }
            std::thread::sleep(Duration::from_millis(100));
        }
        self.kill();
    }
}

/// `cargo xtask bench-emu [--seconds S]`: cycle budget report in out/emu-bench.md.
pub fn bench(args: &[String]) -> Result<()> {
    let elf = build_firmware()?;
    let sim = ensure_sim()?;
    let seconds = arg_value(args, "--seconds").unwrap_or_else(|| "3".into());
    let out = out_dir("emu")?;
    run(Command::new("node")
        .arg(sim.join("src/cli.js"))
        .args(["bench", "--quiet", "--seconds", &seconds, "--elf"])
        .arg(&elf)
        .arg("--report")
        .arg(out.join("bench.md"))
        .arg("--json")
        .arg(out.join("bench.json")))?;
    eprintln!("xtask: wrote {}", out.join("bench.md").display());
    Ok(())
}

/// The faults the end-to-end test injects: (spec, start s, window s in which recovery must happen).
const E2E_FAULTS: &[(&str, f64, f64)] = &[
    ("nack:mpu@6s:3", 6.0, 0.5),
    ("nack:qmc@8s:3", 8.0, 0.5),
    ("vanish:mpu@12s:2s", 12.0, 3.0),
    ("vanish:qmc@20s:2s", 20.0, 3.0),
    ("stuck@28s", 28.0, 1.0),
    ("overflow@36s:120ms", 36.0, 0.6),
];

/// A calibration far enough from identity that its effect on every channel is visible.
fn test_calibration() -> Result<Calibration> {
    let m = [[1.02, 0.01, 0.0], [0.0, 0.98, -0.02], [0.005, 0.0, 1.01]];
    let accel = Affine::from_float(CalSensor::Accel, m, [12.0, -30.0, 250.0])
        .map_err(|e| anyhow::anyhow!("{e:?}"))?;
    let gyro = GyroCorrection::from_float(m, [-40.0, 25.0, 13.0], [0.01, -0.02, 0.0], -3000)
        .map_err(|e| anyhow::anyhow!("{e:?}"))?;
    let mag = Affine::from_float(CalSensor::Mag, m, [100.0, -200.0, 50.0])
        .map_err(|e| anyhow::anyhow!("{e:?}"))?;
    Calibration::new(accel, gyro, mag).map_err(|e| anyhow::anyhow!("{e:?}"))
}

/// `cargo xtask e2e [--seconds 60]`: the end-to-end test on the emulated board.
pub fn e2e(args: &[String]) -> Result<()> {
    let seconds: f64 = arg_value(args, "--seconds")
        .map(|s| s.parse())
        .transpose()?
        .unwrap_or(60.0);
    // `--without stuck,overflow` leaves those faults out (for diagnosing one at a time).
    let without: Vec<String> = arg_value(args, "--without")
        .map(|s| s.split(',').map(str::to_string).collect())
        .unwrap_or_default();
    let faults: Vec<(&str, f64, f64)> = E2E_FAULTS
        .iter()
        .copied()
        .filter(|(spec, ..)| !without.iter().any(|w| spec.starts_with(w.as_str())))
        .collect();
    let wall = Instant::now();
    let elf = build_firmware()?;
    let sim_dir = ensure_sim()?;
    // `--out DIR` (under out/): keeps concurrent runs in one tree apart.
    let out = out_dir(&arg_value(args, "--out").unwrap_or_else(|| "e2e".into()))?;
    // The stream: 1 kHz rows in the CSV contract, from the seeded generator.
    let stream = out.join("stream.csv");
    let mut gen = Command::new("node");
    gen.arg(sim_dir.join("src/cli.js"))
        .args(["gen-stream", "--seed", "7", "--seconds"])
        .arg(format!("{}", seconds + 120.0))
        .arg("--out")
        .arg(&stream);
    // `--sine AMP_DPS,FREQ_HZ`: a sine on the x gyro (the scenario that drives the Allan
    // engine's wide squares on the device, see `cargo xtask test`).
    if let Some(sine) = arg_value(args, "--sine") {
        gen.args(["--sine", &sine]);
    }
    run(&mut gen)?;
    let mut sim_args: Vec<String> = vec![
        // The run ends when the test disconnects (--exit-on-disconnect); the limit is a safety net.
        "--seconds".into(),
        format!("{}", seconds + 120.0),
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
    for (spec, ..) in &faults {
        sim_args.push("--fault".into());
        sim_args.push((*spec).into());
    }
    let sim = Sim::start(&elf, &sim_args, &port_file(&out))?;
    let session = match e2e_session(sim.port, seconds) {
        Ok(s) => s,
        Err(e) => {
            sim.finish_after_error();
            let log = out.join("firmware.log");
            let tail = std::fs::read_to_string(&log).unwrap_or_default();
            let tail: Vec<&str> = tail.lines().rev().take(40).collect();
            eprintln!("--- last lines of {} ---", log.display());
            for l in tail.iter().rev() {
                eprintln!("{l}");
            }
            return Err(e);
        }
    };
    let SessionResult {
        tables,
        mut cal_report,
        cal,
        batches,
        link,
        events,
        measured_s,
        persisted,
    } = session;
    drop(link);
    sim.wait("the end-to-end run")?;
    // Host replay over the served samples.
    let imu = emu_check::read_imu(&out.join("mpu_served.csv"))?;
    let mag = emu_check::read_mag(&out.join("qmc_served.csv"))?;
    let identity = Calibration::identity();
    // Where the device split each sensor's series (Event::Gap), in samples pushed.
    let mut splits: [BTreeSet<u64>; 2] = Default::default();
    let mut split_causes: BTreeMap<String, usize> = BTreeMap::new();
    for e in &events {
        if let imu_proto::Event::Gap { sensor, at, cause } = e {
            splits[matches!(sensor, imu_proto::Sensor::Mag) as usize].insert(*at);
            *split_causes
                .entry(format!("{sensor:?}/{cause:?}"))
                .or_default() += 1;
        }
    }
    let mut checks: Vec<ChannelCheck> = Vec::new();
    for (idx, table) in &tables {
        let ch = Channel::ALL[*idx];
        let replay = if (6..9).contains(idx) {
            emu_check::replay::<allan::MagEngine, _>(
                &mag,
                table.pushed,
                |s| s.k,
                |s| identity.apply_mag(s.mag)[idx - 6],
                &splits[1],
            )
        } else {
            let pos = emu_check::imu_inputs(&identity, &imu[0])
                .iter()
                .position(|(c, _)| *c == ch)
                .context("channel")?;
            emu_check::replay::<allan::DeviceEngine, _>(
                &imu,
                table.pushed,
                |s| s.k,
                |s| emu_check::imu_inputs(&identity, s)[pos].1,
                &splits[0],
            )
        };
        checks.push(emu_check::compare(table, &replay));
    }
    // Drops: every jump of the served index must fall inside an injected fault's window.
    let mut report = String::new();
    let mut failures = Vec::new();
    report.push_str(&format!(
        "# End-to-end emulator test\n\n{seconds} s of emulated time, firmware {}\n\n",
        elf.display()
    ));
    report.push_str("## Allan tables: device vs host replay of the served samples\n\n| channel | pushed | gaps (device/host) | levels compared | result |\n|---|---|---|---|---|\n");
    for c in &checks {
        let ok = c.mismatches.is_empty() && c.levels_compared > 0;
        report.push_str(&format!(
            "| {} | {} | {}/{} | {} | {} |\n",
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
        ));
        if !ok {
            failures.push(format!(
                "{}: {}",
                c.channel.name(),
                c.mismatches.first().cloned().unwrap_or("no levels".into())
            ));
        }
    }
    report.push_str(&format!(
        "\nSplits the device reported (Event::Gap, sensor/cause: count): {}\n",
        if split_causes.is_empty() {
            "none".to_string()
        } else {
            split_causes
                .iter()
                .map(|(k, v)| format!("{k}: {v}"))
                .collect::<Vec<_>>()
                .join(", ")
        }
    ));
    if checks.len() != Channel::ALL.len() {
        failures.push(format!(
            "only {} of {} channel tables received",
            checks.len(),
            Channel::ALL.len()
        ));
    }
    report.push_str(&format!(
        "\n## Sample continuity and fault recovery\n\nServed-sample index jumps during the measurement (0 to {measured_s:.3} s of device time, when the tables were requested):\n\n| sensor | lost at (s) | samples lost | inside fault window |\n|---|---|---|---|\n"
    ));
    let in_window = |t_s: f64| faults.iter().any(|(_, at, w)| t_s >= *at && t_s <= at + w);
    for (name, jumps) in [
        (
            "MPU-6050",
            emu_check::index_jumps(&imu, |s| s.k, |s| s.served_ns),
        ),
        (
            "QMC5883L",
            emu_check::index_jumps(&mag, |s| s.k, |s| s.served_ns),
        ),
    ] {
        let mut outside = 0;
        let mut outside_lost = 0;
        for (_, _, lost, t) in jumps.iter().filter(|j| j.3 * 1e-9 < measured_s) {
            let t_s = t * 1e-9;
            let ok = in_window(t_s) || t_s < 0.5;
            if !ok {
                outside += 1;
                outside_lost += lost;
            }
            if ok || outside <= 10 {
                report.push_str(&format!(
                    "| {name} | {t_s:.3} | {lost} | {} |\n",
                    if ok { "yes" } else { "NO" }
                ));
            }
        }
        if outside > 0 {
            report.push_str(&format!(
                "| {name} | … | {outside_lost} in {outside} jumps outside fault windows | NO |\n"
            ));
            failures.push(format!(
                "{name}: {outside_lost} samples lost in {outside} jumps outside any fault window"
            ));
        }
    }
    // Ground truth of the models: slots of each part's sample grid that were never served.
    let truth = |slots: Vec<(u64, f64)>| -> (u64, f64) {
        let lost: u64 = slots.windows(2).map(|w| w[1].0 - w[0].0 - 1).sum();
        (lost, slots.last().map(|s| s.1 * 1e-9).unwrap_or(0.0))
    };
    for (name, (lost, until)) in [
        (
            "MPU-6050",
            truth(imu.iter().map(|s| (s.slot, s.t_ns)).collect()),
        ),
        (
            "QMC5883L",
            truth(mag.iter().map(|s| (s.slot, s.t_ns)).collect()),
        ),
    ] {
        report.push_str(&format!(
            "\n{name}: {lost} slots of its sample grid never served (model ground truth, up to the last served sample, sampled at {until:.3} s)\n"
        ));
    }
    for (spec, at, w) in faults.iter().filter(|f| f.1 + f.2 < measured_s) {
        let after = |t_ns: f64| t_ns * 1e-9 > at + 0.001;
        let resumed = if spec.contains(":qmc") {
            mag.iter().map(|s| s.served_ns).find(|t| after(*t))
        } else {
            imu.iter().map(|s| s.served_ns).find(|t| after(*t))
        }
        .map(|t| t * 1e-9);
        report.push_str(&format!(
            "\nfault `{spec}`: first sample of that sensor served after it at {}\n",
            resumed
                .map(|t| format!("{t:.3} s"))
                .unwrap_or("never".into())
        ));
        if resumed.is_none_or(|t| t > at + w) {
            failures.push(format!("no recovery within {w} s after `{spec}`"));
        }
    }
    let (matched, total) = check_calibrated(&batches, &cal, &imu);
    cal_report.push_str(&format!(
        "calibrated IMU samples streamed after the upload: {total}; equal to the uploaded correction applied to a served raw sample: {matched}\n"
    ));
    if !persisted {
        failures
            .push("the calibration written to flash was not read back with source Flash".into());
    }
    if total == 0 || matched != total {
        failures.push(format!(
            "calibration not applied as uploaded: {matched} of {total} streamed samples match"
        ));
    }
    report.push_str(&format!("\n## Calibration round trip\n\n{cal_report}\n"));
    report.push_str(&format!(
        "\nwall time: {:.1} s\n",
        wall.elapsed().as_secs_f64()
    ));
    std::fs::write(out.join("report.md"), &report)?;
    println!("{report}");
    if !failures.is_empty() {
        bail!("end-to-end test FAILED:\n  {}", failures.join("\n  "));
    }
    println!(
        "end-to-end test passed ({:.1} s wall); report in {}",
        wall.elapsed().as_secs_f64(),
        out.join("report.md").display()
    );
    Ok(())
}

type Tables = std::collections::BTreeMap<usize, imu_proto::AllanTable>;

/// Talks to the emulated device for the whole run: tables at `seconds`, then the calibration
/// round trip. Returns the tables and a description of the round trip.
fn e2e_session(port: u16, seconds: f64) -> Result<SessionResult> {
    let long = Duration::from_secs(300);
    let mut link = Link::connect(port, Duration::from_secs(30))?;
    let id = link.request(Request::Identify, long)?;
    let Reply::Identity(ident) = id else {
        bail!("Identify answered {id:?}")
    };
    eprintln!("xtask: device: {ident:?}");
    let r = link.request(
        Request::SetIntervals {
            status_ms: 1000,
            tables_ms: 0,
        },
        long,
    )?;
    if r != Reply::Ok {
        bail!("SetIntervals answered {r:?}");
    }
    // Let the run reach `seconds` of device uptime, with every fault behind it.
    link.wait_until(
        Duration::from_secs(900),
        "the device's uptime to reach the end of the run",
        |g| {
            g.statuses
                .last()
                .is_some_and(|s| s.uptime_us as f64 * 1e-6 >= seconds - 2.0)
        },
    )?;
    link.got.tables.clear();
    let measured_s = link
        .got
        .statuses
        .last()
        .map(|s| s.uptime_us as f64 * 1e-6)
        .unwrap_or(seconds);
    let r = link.request(Request::GetTables, long)?;
    if r != Reply::Ok {
        bail!("GetTables answered {r:?}");
    }
    link.wait_until(long, "all channel tables", |g| {
        g.tables.len() == Channel::ALL.len()
    })?;
    let tables = std::mem::take(&mut link.got.tables);
    // The split positions count samples since the last Allan reset; the calibration upload
    // below resets the engines, so only the events up to the tables describe them.
    let events = std::mem::take(&mut link.got.events);
    let status = link.request(Request::GetStatus, long)?;
    let mut cal_report = format!("device status after the run: {status:?}\n\n");
    // Calibration round trip: upload, read back, see it applied to the streamed samples.
    let cal = test_calibration()?;
    let mut buf = [0u8; 256];
    let blob = encode_blob(&cal, &mut buf).map_err(|e| anyhow::anyhow!("{e:?}"))?;
    let hblob =
        HVec::from_slice(blob).map_err(|_| anyhow::anyhow!("calibration blob too large"))?;
    let r = link.request(
        Request::SetCalibration {
            blob: hblob.clone(),
            persist: false,
        },
        long,
    )?;
    cal_report.push_str(&format!("SetCalibration → {r:?}\n"));
    if r != Reply::Ok {
        bail!("SetCalibration answered {r:?}");
    }
    let back = link.request(Request::GetCalibration, long)?;
    match &back {
        Reply::Calibration { blob: b, status } => {
            cal_report.push_str(&format!(
                "GetCalibration → {} bytes, {status:?}; equal to the upload: {}\n",
                b.len(),
                *b == hblob
            ));
            if *b != hblob {
                bail!("the calibration read back differs from the one uploaded");
            }
        }
        other => bail!("GetCalibration answered {other:?}"),
    }
    let r = link.request(Request::SetMode(StreamMode::Calibrated), long)?;
    if r != Reply::Ok {
        bail!("SetMode(Calibrated) answered {r:?}");
    }
    link.got.batches.clear();
    // A device whose sampling is stuck sends no batches: note it and go on to the report.
    if let Err(e) = link.wait_until(Duration::from_secs(90), "calibrated sample batches", |g| {
        g.batches.iter().filter(|b| b.calibrated).count() >= 10
    }) {
        cal_report.push_str(&format!("{e:#}\n"));
    }
    // Persisting: the flash write goes through embassy-rp's flash driver and the ROM stub.
    let r = link.request(
        Request::SetCalibration {
            blob: hblob.clone(),
            persist: true,
        },
        long,
    )?;
    cal_report.push_str(&format!("SetCalibration(persist) → {r:?}\n"));
    let back = link.request(Request::GetCalibration, long)?;
    let persisted = matches!(&back, Reply::Calibration { blob: b, status } if *b == hblob && status.source == imu_proto::CalSource::Flash);
    cal_report.push_str(&format!(
        "GetCalibration after persisting → source Flash and same blob: {persisted}\n"
    ));
    let batches: Vec<_> = link
        .got
        .batches
        .iter()
        .filter(|b| b.calibrated)
        .cloned()
        .collect();
    Ok(SessionResult {
        tables,
        cal_report,
        cal,
        batches,
        link,
        events,
        measured_s,
        persisted,
    })
}

struct SessionResult {
    tables: Tables,
    /// Device events up to the tables (before the calibration upload reset the engines).
    events: Vec<imu_proto::Event>,
    cal_report: String,
    cal: Calibration,
    batches: Vec<imu_proto::SampleBatch>,
    link: Link,
    /// Device uptime when the tables were requested, s: the end of the measurement.
    measured_s: f64,
    /// The calibration written to flash was read back with source Flash.
    persisted: bool,
}

/// Every IMU sample in a calibrated batch must be the uploaded calibration applied to a raw
/// sample the model served within 50 ms of the sample's device time. Returns (matched, total).
fn check_calibrated(
    batches: &[imu_proto::SampleBatch],
    cal: &Calibration,
    imu: &[emu_check::ImuRaw],
) -> (usize, usize) {
    let mut matched = 0;
    let mut total = 0;
    for b in batches {
        for s in b.imu.iter() {
            total += 1;
            let t_ns = s.t_us as f64 * 1e3;
            let hit = imu
                .iter()
                .filter(|r| (r.served_ns - t_ns).abs() < 50e6)
                .any(|r| {
                    cal.apply_accel(r.accel) == s.accel
                        && cal.apply_gyro(r.gyro, r.temp) == s.gyro
                        && r.temp as i32 == s.temp
                });
            if hit {
                matched += 1;
            }
        }
    }
    (matched, total)
}

/// `imu-lab` from this workspace (release build), run in the workspace root.
fn imu_lab() -> Command {
    let mut c = cargo();
    c.args([
        "run",
        "--quiet",
        "--release",
        "--target",
        "host-tuple",
        "-p",
        "imu-lab",
        "--",
    ]);
    c
}

/// `cargo xtask demo [--port PORT] [--seconds S]`: the README's main job. Without `--port`:
/// build the firmware, simulate gyro rate noise inside the five-term model (white noise and rate
/// random walk) with `imu-lab simulate`, and run the firmware on the emulated board fed by it.
/// The hidden effect is in the emulated sensor: the MPU-6050's digital low-pass filter, which the
/// firmware enables, correlates the white noise at short τ (a first-order Gauss–Markov process
/// with τ_c = 1/(2π f_c), outside the five-term model). Then the flow below over the emulated USB
/// port. With `--port /dev/ttyACM0`, the
/// same flow on a real Pico running the firmware.
///
/// Flow: `imu-lab device status`; `imu-lab record` S seconds; `imu-lab device tables --fit` (the
/// device's own Allan tables and the five-term fit); `imu-lab fit` on the recording, whose
/// diagnosis names the missing effect; `imu-lab fit --add <it> --report` shows the error
/// falling and writes the HTML report.
pub fn demo(args: &[String]) -> Result<()> {
    let out = out_dir("demo")?;
    let seconds: f64 = arg_value(args, "--seconds")
        .map(|s| s.parse())
        .transpose()
        .context("--seconds")?
        .unwrap_or(60.0);
    if let Some(port) = arg_value(args, "--port") {
        eprintln!("xtask: demo on the device at {port} (flash it first: cargo run --release)");
        return demo_flow(&port, seconds, &out);
    }
    let elf = build_firmware()?;
    ensure_sim()?;
    let stream = out.join("stream.csv");
    let samples = ((seconds + 30.0) * 1000.0) as u64;
    run(imu_lab()
        .args([
            "simulate",
            "--rate",
            "1000",
            "--samples",
            &samples.to_string(),
            "--seed",
            "11",
        ])
        .args(["--columns", "gx,gy,gz", "--white", "0.01", "--rrw", "0.002"])
        .arg("--output")
        .arg(&stream))?;
    let sim = Sim::start(
        &elf,
        &[
            "--seconds".into(),
            format!("{}", seconds + 3600.0),
            "--stream".into(),
            stream.display().to_string(),
            "--log".into(),
            out.join("firmware.log").display().to_string(),
            "--quiet".into(),
        ],
        &port_file(&out),
    )?;
    let port = format!("tcp:127.0.0.1:{}", sim.port);
    let r = demo_flow(&port, seconds, &out);
    sim.kill();
    r
}

fn demo_flow(port: &str, seconds: f64, out: &Path) -> Result<()> {
    let recording = out.join("recording.csv");
    let report = out.join("report.html");
    run(imu_lab().args(["device", "--port", port, "status"]))?;
    run(imu_lab()
        .args([
            "record",
            "--port",
            port,
            "--seconds",
            &seconds.to_string(),
            "--out",
        ])
        .arg(&recording))?;
    run(imu_lab()
        .args([
            "device",
            "--port",
            port,
            "tables",
            "--fit",
            "--channel",
            "gx",
            "--json",
        ])
        .arg(out.join("tables.json")))?;
    // The lab loop: fit, read the diagnosis, add the effect it names, fit again (at most three
    // effects), then write the report with every step.
    let mut added: Vec<String> = Vec::new();
    for _ in 0..3 {
        let mut c = imu_lab();
        c.args(["fit"])
            .arg(&recording)
            .args(["--column", "gx", "--json"]);
        if !added.is_empty() {
            c.args(["--add", &added.join(",")]);
        }
        let shown = format!("{c:?}");
        let fit = c
            .current_dir(root())
            .output()
            .with_context(|| format!("running {shown}"))?;
        if !fit.status.success() {
            bail!("{shown} failed: {}", String::from_utf8_lossy(&fit.stderr));
        }
        let json: serde_json::Value = serde_json::from_slice(&fit.stdout)
            .with_context(|| format!("parsing the JSON of {shown}"))?;
        let diag = json.get("diagnosis");
        let adequate = diag
            .and_then(|d| d.get("adequate"))
            .and_then(|v| v.as_bool())
            .unwrap_or(false);
        let missing = diag
            .and_then(|d| d.get("missing"))
            .and_then(|v| v.as_str())
            .map(str::to_string);
        let model = if added.is_empty() {
            "five-term model".to_string()
        } else {
            format!("model + {}", added.join(" + "))
        };
        match (adequate, missing) {
            (true, _) => {
                eprintln!("xtask: the {model} is adequate");
                break;
            }
            (false, Some(effect)) if !added.contains(&effect) => {
                eprintln!(
                    "xtask: the {model} fails; the diagnosis names the missing effect: {effect}"
                );
                added.push(effect);
            }
            (false, _) => {
                eprintln!("xtask: the {model} fails and the diagnosis names no further effect");
                break;
            }
        }
    }
    let mut c = imu_lab();
    c.args(["fit"])
        .arg(&recording)
        .args(["--column", "gx", "--report"])
        .arg(&report);
    if !added.is_empty() {
        c.args(["--add", &added.join(",")]);
    }
    run(&mut c)?;
    eprintln!("xtask: demo report written to {}", report.display());
    Ok(())
}
