//! The emulator commands: the harness runner shared by `cargo xtask e2e` (src/e2e.rs),
//! `cargo xtask bench-emu` (cycle budget report) and `cargo xtask demo` (the README's main job).
//! The harness itself is `sim/` (Node 20, rp2040js); docs/emulator.md explains it.
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};

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

pub fn build_firmware() -> Result<PathBuf> {
    run(cargo().args(["build", "--release", "-p", "pico-imu"]))?;
    let elf = firmware_elf();
    if !elf.exists() {
        bail!("the firmware build did not produce {}", elf.display());
    }
    Ok(elf)
}

/// `npm ci` in sim/ unless node_modules is already there.
pub fn ensure_sim() -> Result<PathBuf> {
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

pub fn out_dir(name: &str) -> Result<PathBuf> {
    let d = root().join("out").join(name);
    std::fs::create_dir_all(&d).with_context(|| format!("creating {}", d.display()))?;
    Ok(d)
}

/// Where our emulator child writes its TCP port: named after this process, so that a second
/// run in the same tree (another `cargo xtask test`) can never hand us its port.
pub fn port_file(out: &Path) -> PathBuf {
    out.join(format!("port.{}", std::process::id()))
}

pub fn arg_value(args: &[String], name: &str) -> Option<String> {
    args.iter()
        .position(|a| a == name)
        .and_then(|i| args.get(i + 1).cloned())
}

/// A running emulator with its USB port on TCP.
pub struct Sim {
    child: Child,
    pub port: u16,
}

impl Sim {
    pub fn start(elf: &Path, args: &[String], port_file: &Path) -> Result<Sim> {
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
    pub fn wait(mut self, what: &str) -> Result<()> {
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
    pub fn finish_after_error(mut self) {
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
    let seconds = arg_value(args, "--seconds").unwrap_or_else(|| "12".into());
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
    // The lab's walk: fit, diagnose, add the effect it names, refit until adequate; imu-lab
    // prints the step table and writes the report with every step.
    run(imu_lab()
        .arg("fit")
        .arg(&recording)
        .args(["--column", "gx", "--auto", "--report"])
        .arg(&report))?;
    eprintln!("xtask: demo report written to {}", report.display());
    Ok(())
}
