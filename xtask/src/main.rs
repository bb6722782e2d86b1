//! Project automation. `cargo xtask test` runs every test the project has; `cargo xtask demo`
//! runs the main job on the emulated device (or on a real Pico with `--port`).
use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::OnceLock;
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use clap::{Args, Parser, Subcommand};

mod demo_heading;
mod e2e;
mod emu;
mod emu_check;
mod emu_link;
mod firmware;
mod python;
mod serve;

/// Packages that only build for the device (thumbv6m-none-eabi).
const DEVICE_ONLY: &[&str] = &["pico-imu", "rp2040-hal-blocking"];

/// `cargo xtask <command>`: every command and flag declared here, so a misspelled one is
/// refused with clap's message instead of being ignored.
#[derive(Debug, Parser)]
#[command(
    name = "cargo xtask",
    about = "pico-imu project automation",
    bin_name = "cargo xtask"
)]
struct Cli {
    #[command(subcommand)]
    command: Cmd,
}

#[derive(Debug, Subcommand)]
enum Cmd {
    /// Run all host tests, build the firmware, run the emulator tests.
    Test(TestArgs),
    /// End-to-end test on the emulated board.
    E2e(e2e::E2eArgs),
    /// Emulated cycle budget report (out/emu/bench.md).
    BenchEmu(emu::BenchArgs),
    /// The main job: emulated IMU with a hidden effect, device tables, fit, HTML report.
    Demo(emu::DemoArgs),
    /// Release build of the firmware, size report, UF2 (out/pico-imu.uf2).
    Firmware(firmware::FirmwareArgs),
    /// The live page of `imu-lab serve` following the emulated board's 1 kHz stream for an hour
    /// (or `--minutes`): the page's JS heap and DOM, the server's memory (out/serve/soak.md).
    BenchServe(serve::BenchServeArgs),
}

/// `cargo xtask test [CARGO_TEST_ARGS…]`.
#[derive(Debug, Args)]
struct TestArgs {
    /// Passed on to `cargo test` (a test name filter, `--nocapture` after `--`, …); cargo
    /// refuses what it does not know.
    #[arg(trailing_var_arg = true, allow_hyphen_values = true)]
    cargo_test_args: Vec<String>,
}

fn main() -> Result<()> {
    match Cli::parse().command {
        Cmd::Test(a) => test(&a.cargo_test_args),
        Cmd::E2e(a) => e2e::e2e(&a),
        Cmd::BenchEmu(a) => emu::bench(&a),
        Cmd::Demo(a) => demo_heading::demo(&a),
        Cmd::Firmware(a) => firmware::main(&a),
        Cmd::BenchServe(a) => serve::bench(&a),
    }
}

/// The workspace root (the parent of this crate's directory).
pub fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("xtask lives in the workspace")
        .to_path_buf()
}

/// Cargo's target directory for this workspace, as cargo resolves it (`CARGO_TARGET_DIR`,
/// `build.target-dir` in any config file, else `target/` in the workspace root); asked once.
pub fn target_dir() -> Result<PathBuf> {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    if let Some(d) = DIR.get() {
        return Ok(d.clone());
    }
    let mut c = cargo();
    c.current_dir(root());
    let d = target_dir_from(&mut c)?;
    Ok(DIR.get_or_init(|| d).clone())
}

/// The `target_directory` that `cargo metadata` run as `cargo` reports.
pub fn target_dir_from(cargo: &mut Command) -> Result<PathBuf> {
    let shown = "cargo metadata --format-version 1 --no-deps";
    let out = cargo
        .args(["metadata", "--format-version", "1", "--no-deps"])
        .stderr(Stdio::inherit())
        .output()
        .with_context(|| format!("starting {shown}"))?;
    if !out.status.success() {
        bail!("{shown} failed with {}", out.status);
    }
    let meta: serde_json::Value =
        serde_json::from_slice(&out.stdout).with_context(|| format!("reading {shown}"))?;
    let dir = meta
        .get("target_directory")
        .and_then(|d| d.as_str())
        .with_context(|| format!("{shown} names no target_directory"))?;
    Ok(PathBuf::from(dir))
}

/// Run a command in the workspace root, failing with its description if it fails. While it
/// runs, a line every [`PROGRESS_EVERY`] says what is still running and for how long (always,
/// terminal or log: a first run spends minutes in `cargo run --quiet` builds that print nothing).
pub fn run(cmd: &mut Command) -> Result<()> {
    let shown = format!("{cmd:?}");
    eprintln!("xtask: {shown}");
    let label = label(cmd);
    let mut child = cmd
        .current_dir(root())
        .spawn()
        .with_context(|| format!("starting {shown}"))?;
    let status = wait_with_progress(&mut child, &label, PROGRESS_EVERY, &mut progress_line)
        .with_context(|| format!("waiting for {shown}"))?;
    if !status.success() {
        bail!("{shown} failed with {status}");
    }
    Ok(())
}

/// How often a long child is reported as still running.
pub const PROGRESS_EVERY: Duration = Duration::from_secs(10);

/// Prints a progress line on stderr. On a terminal the line is cleared first, so the line does
/// not land after cargo's own progress bar (which cargo redraws below it).
pub fn progress_line(line: String) {
    if std::io::stderr().is_terminal() {
        eprintln!("\r\x1b[K{line}");
    } else {
        eprintln!("{line}");
    }
}

/// Waits for `child`, handing `say` a line "xtask: still LABEL (N s)…" every `every`.
pub fn wait_with_progress(
    child: &mut Child,
    label: &str,
    every: Duration,
    say: &mut dyn FnMut(String),
) -> std::io::Result<ExitStatus> {
    let start = Instant::now();
    let mut next = every;
    loop {
        if let Some(status) = child.try_wait()? {
            return Ok(status);
        }
        let elapsed = start.elapsed();
        if elapsed >= next {
            say(progress(label, elapsed));
            next += every;
        }
        std::thread::sleep(Duration::from_millis(50).min(every));
    }
}

/// The progress line for `label` after `elapsed`.
pub fn progress(label: &str, elapsed: Duration) -> String {
    format!("xtask: still {label} ({:.0} s)…", elapsed.as_secs_f64())
}

/// What a command is doing, in words: `cargo build -p pico-imu` → "building pico-imu",
/// `cargo run -p imu-lab -- fit …` → "running imu-lab fit (cargo builds it first when needed)",
/// other programs → "running PROGRAM FIRST-ARG".
pub fn label(cmd: &Command) -> String {
    let prog = Path::new(cmd.get_program())
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let args: Vec<String> = cmd
        .get_args()
        .map(|a| a.to_string_lossy().into_owned())
        .collect();
    let after = |flag: &str| {
        args.iter()
            .position(|a| a == flag)
            .and_then(|i| args.get(i + 1))
            .cloned()
    };
    if prog == "cargo" {
        let package = after("-p").or_else(|| after("--package"));
        match (args.first().map(String::as_str), package) {
            (Some("build"), Some(p)) => return format!("building {p}"),
            (Some("run"), Some(p)) => {
                let sub = after("--").map(|s| format!(" {s}")).unwrap_or_default();
                return format!("running {p}{sub} (cargo builds it first when needed)");
            }
            (Some("test"), _) => return "building and running the host tests".into(),
            _ => {}
        }
    }
    if prog == "node" && args.first().is_some_and(|a| a.ends_with("cli.js")) {
        let sub = args.get(1).map(|s| format!(" {s}")).unwrap_or_default();
        return format!("running the emulator (sim/src/cli.js{sub})");
    }
    let first = args
        .iter()
        .find(|a| !a.starts_with('-'))
        .and_then(|a| Path::new(a).file_name())
        .map(|a| format!(" {}", a.to_string_lossy()))
        .unwrap_or_default();
    format!("running {prog}{first}")
}
pub fn cargo() -> Command {
    Command::new(std::env::var("CARGO").unwrap_or_else(|_| "cargo".into()))
}

fn test(extra: &[String]) -> Result<()> {
    let mut c = cargo();
    c.args(["test", "--workspace", "--target", "host-tuple"]);
    for p in DEVICE_ONLY {
        c.args(["--exclude", p]);
    }
    c.args(extra);
    run(&mut c)?;
    // imu-lab serve's noise lab in headless Chromium (skipped without one)
    serve::browser_tests(&["vendor", "noise_lab"], &[])?;
    python::test()?;
    if emu::node_available() {
        for scenario in [
            e2e::Scenario::Faults,
            e2e::Scenario::BootStall,
            e2e::Scenario::Sine,
            e2e::Scenario::Orientation,
        ] {
            e2e::e2e(&e2e::E2eArgs::scenario(scenario))?;
        }
        // The fault scenario again with every fault later by a few ms: where in the firmware's
        // cycle of transfers a fault begins must not matter (these two shifts once put a CPU
        // stall between a magnetometer read and its processing, misdated as a held bus).
        for shift_ms in [3.3, 13.4] {
            e2e::e2e(&e2e::E2eArgs {
                shift_ms,
                out: Some(format!("e2e-faults-shift-{shift_ms}")),
                ..e2e::E2eArgs::scenario(e2e::Scenario::Faults)
            })?;
        }
        // And with the parts' clocks off the other way and further: with the MPU-6050 2 %
        // fast, restarts held up by the bus once added their phases and numbered a restarted
        // part's samples a slot off (this shift showed it every time).
        e2e::e2e(&e2e::E2eArgs {
            shift_ms: 15.0,
            clock: Some("mpu:+2%,qmc:-2%".into()),
            out: Some("e2e-faults-fast-mpu".into()),
            ..e2e::E2eArgs::scenario(e2e::Scenario::Faults)
        })?;
        // Schedules drawn by `--faults-seed` (other lengths, orders and phases of the same
        // kinds) that each found a fault of their own: a 1.25 s MPU-6050 stall restarted on the
        // neighbouring slot (1009), a magnetometer read the bus held for 22 ms taken as read at
        // its start (1000), a read abandoned at its deadline that the controller still made
        // when the bus freed, its sample never delivered (2014), an IMU burst whose START the
        // bus held for 21 ms taken for a stale count, a FIFO's frames read whole dropped
        // (3026), an IMU burst whose START was freed just before its deadline cut off while its
        // frames were moving (30063), a 52 ms NACK of a fast MPU-6050 whose retry waited for the
        // next burst's tick, its FIFO overflowing (43017).
        for (seed, clock) in [
            (1009, "mpu:-1.28%,qmc:-0.05%"),
            (1000, "mpu:+1.11%,qmc:+0.68%"),
            (2014, "mpu:-0.74%,qmc:-0.41%"),
            (3026, "mpu:+0.15%,qmc:+1.59%"),
            (30063, "mpu:+1.87%,qmc:+1.81%"),
            (43017, "mpu:+0.81%,qmc:-1.69%"),
        ] {
            e2e::e2e(&e2e::E2eArgs {
                faults_seed: Some(seed),
                clock: Some(clock.into()),
                out: Some(format!("e2e-faults-seed-{seed}")),
                ..e2e::E2eArgs::scenario(e2e::Scenario::Faults)
            })?;
        }
        // Single faults, each (its run's name, the fault, the part clocks, the seconds) once
        // found to do harm:
        for (out, fault, clock, seconds) in [
            // A part whose clock the bursts' cadence leaves nearly still (the MPU-6050 0.01 %
            // slow, counted every 10.12 ms after a magnetometer 1.23 % slow): its clock's
            // interval, cut to a period about its middle before a count bounded it, lost the
            // part's phase at start-up, its period came out 700 ppm off, and the samples after
            // this 1.3 s stall were numbered a slot off (a drawn schedule, seed 42022).
            (
                "e2e-faults-still-phase",
                "stall:mpu@3.9799s:1310ms",
                Some("mpu:-0.01%,qmc:-1.23%"),
                8.0,
            ),
            // A magnetometer NACKing long enough to be lost (393 ms, its clock 1.26 % fast):
            // looked for on the back-off's retries alone, it came back 76 ms after the NACKs
            // ended, 15 readings more than the burst spanned (a fault drawn at random in the
            // first 0.6 s).
            (
                "e2e-faults-long-nack",
                "nack:qmc@0.3321s:393ms",
                Some("mpu:-1.74%,qmc:+1.26%"),
                14.0,
            ),
            // Faults from boot, before a part's first sample: its grid is then the one its
            // first samples set, not the one its waking write implied (numbered on that one,
            // every sample was hundreds of slots off, and the MPU-6050 restarted its FIFO in
            // vain).
            ("e2e-faults-boot-0", "stall:mpu@0.1s:500ms", None, 14.0),
            ("e2e-faults-boot-1", "vanish:qmc@0.01s:400ms", None, 14.0),
        ] {
            e2e::e2e(&e2e::E2eArgs {
                fault: vec![fault.into()],
                clock: clock.map(Into::into),
                seconds: Some(seconds),
                out: Some(out.into()),
                ..e2e::E2eArgs::scenario(e2e::Scenario::Faults)
            })?;
        }
        // The Thumb differential tests' programs, for sim/test/thumb-diff.test.js and
        // sim/test/frame-thumb.test.js.
        for (package, var) in [
            ("allan-thumb-check", "PICO_IMU_THUMB_CHECK_ELF"),
            ("imu-proto-thumb-check", "PICO_IMU_FRAME_CHECK_ELF"),
        ] {
            run(cargo().args(["build", "--release", "-p", package]))?;
            let elf = target_dir()?
                .join("thumbv6m-none-eabi/release")
                .join(package);
            std::env::set_var(var, elf);
        }
        emu::harness_tests()?;
        serve_live_test()
    } else {
        eprintln!(
            "xtask: node >= 20 not found: emulator end-to-end test and harness tests skipped"
        );
        Ok(())
    }
}

/// The live page's browser tests against the emulated board (web/test/live.test.mjs), turned
/// through the simulator's calibration run (`imu_sim::trajectory::Trajectory::calibration`:
/// eight poses held 5 s around the standard run's turns) by a part with hard and soft iron and
/// an accelerometer offset and scale drawn at random (printed, and handed to the test as its
/// truth, with the part's hard iron): the magnetometer wizard needs the field in many
/// directions, the accelerometer's the poses; the stream loops.
fn serve_live_test() -> Result<()> {
    if serve::chromium().is_none() {
        return serve::browser_tests(&["live"], &[]);
    }
    let out = emu::out_dir("serve")?;
    let elf = emu::build_firmware()?;
    let stream = out.join("live-stream.csv");
    let (offset, scale) = accel_errors();
    let truth = format!(
        r#"{{"offset":[{},{},{}],"scale":[{},{},{}]}}"#,
        offset[0], offset[1], offset[2], scale[0], scale[1], scale[2]
    );
    eprintln!("xtask: the emulated accelerometer's errors (the live test's truth): {truth}");
    // the binary the browser tests use (the test build), not a release build of its own
    run(Command::new(serve::imu_lab_bin()?)
        .args([
            "simulate",
            "--trajectory",
            "calibration",
            "--part",
            "hard-iron",
        ])
        .arg(format!(
            "--accel-offset={},{},{}",
            offset[0], offset[1], offset[2]
        ))
        .arg(format!(
            "--accel-scale={},{},{}",
            scale[0], scale[1], scale[2]
        ))
        .args(["--rate", "1000", "--samples", "80500", "--seed", "7"])
        .arg("--output")
        .arg(&stream))?;
    let sim = emu::Sim::start(
        &elf,
        &[
            "--seconds".into(),
            "3600".into(),
            "--stream".into(),
            stream.display().to_string(),
            "--log".into(),
            out.join("live-firmware.log").display().to_string(),
            "--quiet".into(),
        ],
        &out,
    )?;
    let port = format!("tcp:127.0.0.1:{}", sim.port);
    // the hard-iron part (imu_sim::trajectory::Part::hard_iron): its hard iron (µT), soft
    // iron, the place's field (µT, dip in degrees: the level turn's in-plane centre holds the
    // soft iron's coupling of the vertical field) and its gyro bias (deg/s)
    let mag_truth = r#"{"hard_iron":[18.0,-12.0,12.0],"soft_iron":[[1.05,0.02,0.0],[0.02,0.97,0.01],[0.0,0.01,1.0]],"field_ut":50.0,"dip_deg":60.0,"gyro_bias":[0.4,-0.3,0.2]}"#.to_string();
    serve::browser_tests(
        &["live"],
        &[
            ("IMU_LIVE_PORT", port),
            ("IMU_LIVE_ACCEL_TRUTH", truth),
            ("IMU_LIVE_MAG_TRUTH", mag_truth),
        ],
    )
}

/// An accelerometer offset (0.05–0.3 m/s² a axis, either sign) and scale (1 ± 0.5–3 %), drawn
/// from the clock, rounded to what the stream's flags print.
fn accel_errors() -> ([f64; 3], [f64; 3]) {
    let mut s = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(1, |d| d.as_nanos() as u64)
        | 1;
    let mut u = move || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 11) as f64 / (1u64 << 53) as f64
    };
    let mut signed = |lo: f64, hi: f64| {
        let x = lo + (hi - lo) * u();
        if u() < 0.5 {
            -x
        } else {
            x
        }
    };
    let offset = [0; 3].map(|_| (signed(0.05, 0.3) * 1e4).round() / 1e4);
    let scale = [0; 3].map(|_| ((1.0 + signed(0.005, 0.03)) * 1e5).round() / 1e5);
    (offset, scale)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(line: &str) -> Result<Cmd, clap::Error> {
        Cli::try_parse_from(["cargo-xtask"].into_iter().chain(line.split_whitespace()))
            .map(|c| c.command)
    }

    /// Every command and flag the README, docs/ and .ci/run use keeps its spelling, and a flag
    /// no command declares is refused with clap's message naming it.
    #[test]
    fn every_command_and_flag_parses_and_an_unknown_flag_is_refused() {
        for line in [
            "test",
            "test imu_drivers --nocapture",
            "e2e",
            "e2e --scenario faults --seconds 10 --shift-ms 3.3 --out e2e-x",
            "e2e --scenario faults --clock mpu:+1.3%,qmc:+1.3% --shift-ms 8.9",
            "e2e --scenario boot-stall",
            "e2e --scenario sine",
            "bench-emu --seconds 3 --warmup 0.2 --seed 7 --clock mpu:-1.3%,qmc:+1.3%",
            "demo",
            "demo --port /dev/ttyACM0 --seconds 60",
            "demo --serve",
            "demo --serve --port /dev/ttyACM0",
            "firmware",
            "firmware --no-build",
            "bench-serve --minutes 60 --every 2",
            "bench-serve --minutes 20 --device-minutes 60 --every 2",
        ] {
            parse(line).unwrap_or_else(|e| panic!("`cargo xtask {line}`: {e}"));
        }
        match parse("e2e --scenario boot-stall --shift-ms 13.4").unwrap() {
            Cmd::E2e(a) => {
                assert_eq!(a.scenario, e2e::Scenario::BootStall);
                assert_eq!(a.shift_ms, 13.4);
                assert_eq!(a.seconds, None);
                assert_eq!(a.clock, None);
            }
            other => panic!("{other:?}"),
        }
        match parse("demo --port tcp:127.0.0.1:9000").unwrap() {
            Cmd::Demo(a) => assert_eq!(
                (a.port.as_deref(), a.seconds),
                (Some("tcp:127.0.0.1:9000"), 60.0)
            ),
            other => panic!("{other:?}"),
        }
        match parse("firmware --no-build").unwrap() {
            Cmd::Firmware(a) => assert!(a.no_build),
            other => panic!("{other:?}"),
        }
        for (line, word) in [
            ("demo --nonsense", "--nonsense"),
            ("e2e --scenaro faults", "--scenaro"),
            ("firmware --nobuild", "--nobuild"),
            ("bench-emu --sed 3", "--sed"),
        ] {
            let e = parse(line).expect_err(line);
            assert_eq!(e.kind(), clap::error::ErrorKind::UnknownArgument, "{line}");
            assert!(
                e.to_string()
                    .contains(&format!("unexpected argument '{word}'")),
                "{e}"
            );
        }
        let e = parse("e2e --scenario fault").expect_err("a scenario that does not exist");
        assert_eq!(e.kind(), clap::error::ErrorKind::InvalidValue);
        let e = parse("demo --seconds many").expect_err("seconds that are not a number");
        assert_eq!(e.kind(), clap::error::ErrorKind::ValueValidation);
        assert!(parse("dmeo").is_err());
    }

    #[test]
    fn a_long_child_is_reported_while_it_runs_and_a_quick_one_is_not() {
        let mut lines = Vec::new();
        let mut child = Command::new("sleep").arg("0.5").spawn().unwrap();
        let status = wait_with_progress(
            &mut child,
            "sleeping",
            Duration::from_millis(100),
            &mut |l| lines.push(l),
        )
        .unwrap();
        assert!(status.success());
        // A line at 0.1, 0.2, 0.3, 0.4 s (the last may race the child's exit).
        assert!((3..=5).contains(&lines.len()), "{lines:?}");
        assert!(lines
            .iter()
            .all(|l| l.starts_with("xtask: still sleeping (")));
        let mut lines = Vec::new();
        let mut child = Command::new("true").spawn().unwrap();
        wait_with_progress(&mut child, "x", Duration::from_secs(10), &mut |l| {
            lines.push(l)
        })
        .unwrap();
        assert!(lines.is_empty());
        assert_eq!(
            progress("building imu-lab", Duration::from_millis(40_400)),
            "xtask: still building imu-lab (40 s)…"
        );
    }

    #[test]
    fn commands_are_named_by_what_they_do() {
        let mut c = Command::new("cargo");
        c.args(["build", "--release", "-p", "pico-imu"]);
        assert_eq!(label(&c), "building pico-imu");
        let mut c = Command::new("/usr/bin/cargo");
        c.args(["run", "--quiet", "-p", "imu-lab", "--", "fit", "rec.csv"]);
        assert_eq!(
            label(&c),
            "running imu-lab fit (cargo builds it first when needed)"
        );
        let mut c = Command::new("node");
        c.args(["/w/sim/src/cli.js", "bench", "--quiet"]);
        assert_eq!(label(&c), "running the emulator (sim/src/cli.js bench)");
        let mut c = Command::new("npm");
        c.args(["test", "--prefix", "sim"]);
        assert_eq!(label(&c), "running npm test");
    }
}
