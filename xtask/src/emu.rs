//! The emulator commands: the harness runner shared by `cargo xtask e2e` (src/e2e.rs),
//! `cargo xtask bench-emu` (cycle budget report) and `cargo xtask demo` (the README's main job).
//! The harness itself is `sim/` (Node 20, rp2040js); docs/emulator.md explains it.
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};

use crate::{cargo, progress, progress_line, root, run, wait_with_progress, PROGRESS_EVERY};

/// `node` 20 or newer on PATH.
pub fn node_available() -> bool {
    Command::new("node")
        .arg("-e")
        .arg("process.exit(Number(process.versions.node.split('.')[0]) >= 20 ? 0 : 1)")
        .status()
        .map(|s| s.success())
        .unwrap_or(false)
}

/// Release build of the firmware (`cargo xtask firmware`'s build); returns the ELF path.
pub fn build_firmware() -> Result<PathBuf> {
    crate::firmware::build()
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
    let elf = build_firmware()?;
    let sim = ensure_sim()?;
    run(Command::new("npm")
        .args(["test", "--prefix"])
        .arg(&sim)
        .env("PICO_IMU_ELF", elf))
}

pub fn out_dir(name: &str) -> Result<PathBuf> {
    let d = root().join("out").join(name);
    std::fs::create_dir_all(&d).with_context(|| format!("creating {}", d.display()))?;
    Ok(d)
}

/// The file our emulator child writes its TCP port to, `OUT/port.PID`: named after this
/// process, so that a second run in the same tree (another `cargo xtask test`) can never hand us
/// its port. Removed when dropped (the run ended, successfully or not); files of runs whose
/// process is gone (killed before they could remove theirs) are removed when a new one is made.
pub struct PortFile {
    path: PathBuf,
}

impl PortFile {
    pub fn new(out: &Path) -> PortFile {
        remove_stale_port_files(out);
        let path = out.join(format!("port.{}", std::process::id()));
        let _ = std::fs::remove_file(&path);
        PortFile { path }
    }

    pub fn path(&self) -> &Path {
        &self.path
    }
}

impl Drop for PortFile {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.path);
    }
}

/// Removes `port.PID` files in `out` whose process no longer runs.
pub fn remove_stale_port_files(out: &Path) {
    let Ok(entries) = std::fs::read_dir(out) else {
        return;
    };
    for e in entries.flatten() {
        let name = e.file_name();
        let Some(pid) = name
            .to_str()
            .and_then(|n| n.strip_prefix("port."))
            .and_then(|p| p.parse::<u32>().ok())
        else {
            continue;
        };
        if !process_alive(pid) {
            let _ = std::fs::remove_file(e.path());
        }
    }
}

/// Whether a process with this id runs. Where that cannot be asked cheaply the answer is yes,
/// so a file is never taken from a live run.
fn process_alive(pid: u32) -> bool {
    if pid == std::process::id() {
        return true;
    }
    if cfg!(target_os = "linux") {
        Path::new("/proc").join(pid.to_string()).exists()
    } else if cfg!(unix) {
        Command::new("kill")
            .args(["-0", &pid.to_string()])
            .stderr(Stdio::null())
            .status()
            .map(|s| s.success())
            .unwrap_or(true)
    } else {
        true
    }
}

/// A running emulator with its USB port on TCP. Dropping it stops the emulator if it still runs
/// and removes its port file.
pub struct Sim {
    child: Child,
    pub port: u16,
    port_file: PortFile,
}

impl Sim {
    /// Starts `node sim/src/cli.js run` on `elf` with `args`, its port file in `out`, and waits
    /// for it to open its USB port.
    pub fn start(elf: &Path, args: &[String], out: &Path) -> Result<Sim> {
        let port_file = PortFile::new(out);
        let sim = ensure_sim()?;
        let mut cmd = Command::new("node");
        cmd.arg(sim.join("src/cli.js"))
            .arg("run")
            .arg("--elf")
            .arg(elf)
            .arg("--port-file")
            .arg(port_file.path())
            .args(args);
        eprintln!("xtask: {cmd:?}");
        let child = cmd
            .current_dir(root())
            .stdin(Stdio::null())
            .spawn()
            .context("starting node sim/src/cli.js")?;
        let mut sim = Sim {
            child,
            port: 0,
            port_file,
        };
        let start = Instant::now();
        let mut next_note = PROGRESS_EVERY;
        loop {
            if let Ok(s) = std::fs::read_to_string(sim.port_file.path()) {
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
            if start.elapsed() >= next_note {
                progress_line(progress(
                    "booting the emulated board (the USB port opens after boot)",
                    start.elapsed(),
                ));
                next_note += PROGRESS_EVERY;
            }
            std::thread::sleep(Duration::from_millis(100));
        }
    }

    /// Waits for the emulator to finish its run; fails if it reported a firmware stop.
    pub fn wait(mut self, what: &str) -> Result<()> {
        let status = wait_with_progress(
            &mut self.child,
            &format!("waiting for the emulator to finish {what}"),
            PROGRESS_EVERY,
            &mut progress_line,
        )?;
        if !status.success() {
            bail!(
                "the emulator failed during {what} ({status}): see the decoded firmware log above"
            );
        }
        Ok(())
    }

    /// After the host link was dropped: give a `--exit-on-disconnect` run time to write its log
    /// and reports; dropping it then kills it if it has not finished.
    pub fn finish_after_error(mut self) {
        let start = Instant::now();
        while start.elapsed() < Duration::from_secs(30) {
            if let Ok(Some(_)) = self.child.try_wait() {
                return;
            }
            std::thread::sleep(Duration::from_millis(100));
        }
    }
}

impl Drop for Sim {
    fn drop(&mut self) {
        if let Ok(None) = self.child.try_wait() {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}

/// `cargo xtask bench-emu [--seconds S] [--warmup S] [--seed N] [--clock mpu:±P%,qmc:±P%]`:
/// cycle budget report in out/emu/bench.md (the warm-up before the windows, the stream's seed
/// and the parts' oscillator errors as for the emulator's `run`; the goal is checked with the
/// defaults: 1 s, nominal parts).
#[derive(Debug, Clone, clap::Args)]
pub struct BenchArgs {
    /// Emulated time measured, as the emulator reads it (seconds, or with a unit: `1500ms`).
    #[arg(long, value_name = "S", default_value = "12")]
    pub seconds: String,
    /// Emulated time run before the measured windows (the emulator's default: 1 s).
    #[arg(long, value_name = "S")]
    pub warmup: Option<String>,
    /// Seed of the emulated sensors' stream.
    #[arg(long, value_name = "N")]
    pub seed: Option<u64>,
    /// The parts' oscillator errors, e.g. `mpu:+1.3%,qmc:+1.3%` (default: nominal).
    #[arg(long, value_name = "mpu:±P%,qmc:±P%", allow_hyphen_values = true)]
    pub clock: Option<String>,
}

/// Runs the emulator's cycle budget report (see [`BenchArgs`]).
pub fn bench(args: &BenchArgs) -> Result<()> {
    let elf = build_firmware()?;
    let sim = ensure_sim()?;
    let seconds = &args.seconds;
    let out = out_dir("emu")?;
    let mut node = Command::new("node");
    node.arg(sim.join("src/cli.js"))
        .args(["bench", "--quiet", "--seconds", seconds]);
    let opts = [
        ("--warmup", args.warmup.clone()),
        ("--seed", args.seed.map(|s| s.to_string())),
        ("--clock", args.clock.clone()),
    ];
    for (opt, v) in opts {
        if let Some(v) = v {
            node.args([opt, &v]);
        }
    }
    run(node
        .arg("--elf")
        .arg(&elf)
        .arg("--report")
        .arg(out.join("bench.md"))
        .arg("--json")
        .arg(out.join("bench.json")))?;
    eprintln!("xtask: wrote {}", out.join("bench.md").display());
    Ok(())
}

/// `imu-lab` from this workspace (release build), run in the workspace root.
pub(crate) fn imu_lab() -> Command {
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
#[derive(Debug, Clone, clap::Args)]
pub struct DemoArgs {
    /// A real Pico W running the firmware (e.g. /dev/ttyACM0) instead of the emulated board.
    #[arg(long)]
    pub port: Option<String>,
    /// Seconds recorded.
    #[arg(long, value_name = "S", default_value_t = 60.0)]
    pub seconds: f64,
    /// Show it in the browser instead: `imu-lab serve` on the (emulated) device — its status,
    /// its own Allan tables round by round, the decimated stream; record from the page and open
    /// the recording in the noise lab. Serves http://127.0.0.1:8750/ until Ctrl-C.
    #[arg(long)]
    pub serve: bool,
}

/// Runs the noise part of the demo (see [`DemoArgs`]); returns the firmware it ran in the
/// emulator (`None` on a real device).
pub fn demo(args: &DemoArgs) -> Result<Option<PathBuf>> {
    let out = out_dir("demo")?;
    let seconds = args.seconds;
    if let Some(port) = &args.port {
        eprintln!("xtask: demo on the device at {port} (flash it first: cargo run --release)");
        if args.serve {
            serve_page(port, &out)?;
            return Ok(None);
        }
        demo_flow(port, seconds, &out)?;
        return Ok(None);
    }
    let elf = build_firmware()?;
    ensure_sim()?;
    if args.serve {
        // the page for as long as it is open: ten minutes of stream, which the emulator loops
        let sim = start_demo_board(&elf, 570.0, &out)?;
        serve_page(&format!("tcp:127.0.0.1:{}", sim.port), &out)?;
        return Ok(None);
    }
    let sim = start_demo_board(&elf, seconds, &out)?;
    let port = format!("tcp:127.0.0.1:{}", sim.port);
    // Dropping the emulator at the end of the flow, or on its error, stops it.
    demo_flow(&port, seconds, &out)?;
    Ok(Some(elf))
}

/// `imu-lab serve --port PORT` in the foreground until Ctrl-C, recordings into `out`.
fn serve_page(port: &str, out: &Path) -> Result<()> {
    eprintln!(
        "xtask: the page: http://127.0.0.1:8750/ (Ctrl-C ends the demo); recordings go to {}",
        out.display()
    );
    run(imu_lab()
        .args([
            "serve",
            "--port",
            port,
            "--listen",
            "127.0.0.1:8750",
            "--record-dir",
        ])
        .arg(out))
}

/// The demo's emulated board: gyro noise inside the five-term model simulated for `seconds`
/// (+30 s), the firmware running on it with the MPU-6050's low-pass filter as the hidden effect.
fn start_demo_board(elf: &Path, seconds: f64, out: &Path) -> Result<Sim> {
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
    Sim::start(
        elf,
        &[
            "--seconds".into(),
            format!("{}", seconds + 3600.0),
            "--stream".into(),
            stream.display().to_string(),
            "--log".into(),
            out.join("firmware.log").display().to_string(),
            "--quiet".into(),
        ],
        out,
    )
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

#[cfg(test)]
mod tests {
    use super::*;

    fn scratch(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("xtask-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    /// Port files of finished processes go; those of running ones and other files stay.
    #[test]
    fn stale_port_files_are_removed_live_ones_kept() {
        let d = scratch("ports");
        let mut gone = Command::new("true").spawn().unwrap();
        let dead = gone.id();
        gone.wait().unwrap();
        let mut running = Command::new("sleep").arg("5").spawn().unwrap();
        for f in [
            format!("port.{dead}"),
            format!("port.{}", running.id()),
            "port.x".into(),
            "stream.csv".into(),
        ] {
            std::fs::write(d.join(f), "1\n").unwrap();
        }
        let ours = PortFile::new(&d);
        std::fs::write(ours.path(), "4242\n").unwrap();
        let mut left: Vec<String> = std::fs::read_dir(&d)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        left.sort();
        let mut want = vec![
            format!("port.{}", running.id()),
            format!("port.{}", std::process::id()),
            "port.x".to_string(),
            "stream.csv".to_string(),
        ];
        want.sort();
        assert_eq!(left, want);
        drop(ours);
        assert!(!d.join(format!("port.{}", std::process::id())).exists());
        let _ = running.kill();
        let _ = running.wait();
        let _ = std::fs::remove_dir_all(&d);
    }
}
