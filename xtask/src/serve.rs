//! The browser tests of `imu-lab serve` (web/test, `node --test`): the pages driven in Debian's
//! headless Chromium by playwright-core, which downloads no browser. Skipped, with a line saying
//! so, where there is no Chromium (`.ci/run` installs Debian's `chromium` package).
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use anyhow::{bail, Context, Result};

use crate::emu::{node_available, out_dir};
use crate::{cargo, root, run};

/// Where the browser is looked for: `$CHROMIUM`, else Debian's `/usr/bin/chromium`.
fn chromium_path() -> PathBuf {
    std::env::var_os("CHROMIUM")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from("/usr/bin/chromium"))
}

/// The browser, when it is there.
pub fn chromium() -> Option<PathBuf> {
    let p = chromium_path();
    p.exists().then_some(p)
}

/// `npm ci` in web/ unless playwright-core is already there; returns web/.
pub fn ensure_web() -> Result<PathBuf> {
    let web = root().join("web");
    if !web.join("node_modules/playwright-core").exists() {
        run(Command::new("npm")
            .args(["ci", "--no-audit", "--no-fund", "--prefix"])
            .arg(&web))?;
    }
    Ok(web)
}

/// Builds `imu-lab` (the test profile's build, already there after `cargo test`) and returns
/// the executable cargo reports.
pub fn imu_lab_bin() -> Result<PathBuf> {
    let out = cargo()
        .current_dir(root())
        .args([
            "build",
            "--target",
            "host-tuple",
            "-p",
            "imu-lab",
            "--bin",
            "imu-lab",
            "--message-format",
            "json-render-diagnostics",
        ])
        .stderr(Stdio::inherit())
        .output()
        .context("starting cargo build -p imu-lab")?;
    if !out.status.success() {
        bail!("cargo build -p imu-lab failed with {}", out.status);
    }
    String::from_utf8_lossy(&out.stdout)
        .lines()
        .rev()
        .filter_map(|l| serde_json::from_str::<serde_json::Value>(l).ok())
        .find_map(|v| v.get("executable")?.as_str().map(PathBuf::from))
        .context("cargo build -p imu-lab reported no executable")
}

/// The test files of web/test (`*.test.mjs`), in name order.
fn test_files(web: &Path, only: &[&str]) -> Result<Vec<PathBuf>> {
    let dir = web.join("test");
    let mut v: Vec<PathBuf> = std::fs::read_dir(&dir)
        .with_context(|| format!("reading {}", dir.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            p.file_name()
                .and_then(|n| n.to_str())
                .is_some_and(|n| n.ends_with(".test.mjs") && only.iter().any(|o| n.starts_with(o)))
        })
        .collect();
    v.sort();
    Ok(v)
}

/// Runs the browser tests whose file names start with one of `only` (e.g. `noise_lab`), with
/// `env` added (the live tests get the emulator's port). Screenshots go to out/serve.
pub fn browser_tests(only: &[&str], env: &[(&str, String)]) -> Result<()> {
    let Some(chrome) = chromium() else {
        eprintln!(
            "xtask: no Chromium at {} ($CHROMIUM, else /usr/bin/chromium): the browser tests \
             of imu-lab serve ({}) skipped; install Debian's chromium package to run them",
            chromium_path().display(),
            only.join(", ")
        );
        return Ok(());
    };
    if !node_available() {
        eprintln!("xtask: node >= 20 not found: the browser tests of imu-lab serve skipped");
        return Ok(());
    }
    let web = ensure_web()?;
    let bin = imu_lab_bin()?;
    let files = test_files(&web, only)?;
    if files.is_empty() {
        bail!("no browser test in {} matches {only:?}", web.display());
    }
    let mut c = Command::new("node");
    c.args(["--test", "--test-concurrency=1"])
        .args(&files)
        .env("IMU_LAB_BIN", bin)
        .env("CHROMIUM", chrome)
        .env("SERVE_TEST_OUT", out_dir("serve")?);
    for (k, v) in env {
        c.env(k, v);
    }
    run(&mut c)
}

/// `cargo xtask bench-serve`: the live page's memory over a long run (web/bench/live_soak.mjs).
#[derive(Debug, Clone, clap::Args)]
pub struct BenchServeArgs {
    /// How long the page follows the stream: at least this many minutes of wall time and of
    /// the device's 1 kHz stream (the emulated board runs faster or slower than real time with
    /// the machine's load: the soak lasts until both have passed).
    #[arg(long, default_value_t = 60.0)]
    pub minutes: f64,
    /// Minutes of the device's stream, when they should differ from --minutes of wall time.
    #[arg(long)]
    pub device_minutes: Option<f64>,
    /// Minutes between two rows of the table.
    #[arg(long, default_value_t = 2.0)]
    pub every: f64,
}

/// The soak: the emulated Pico (1 kHz IMU, 200 Hz magnetometer) turned through the standard
/// trajectory, `imu-lab serve` on it (the test build `cargo xtask test` uses), and the page in
/// headless Chromium, measured every `--every` minutes; the table goes to stdout and to
/// out/serve/soak.md.
pub fn bench(args: &BenchServeArgs) -> Result<()> {
    if !(args.minutes > 0.0 && args.minutes.is_finite() && args.every > 0.0) {
        bail!(
            "--minutes {} --every {}: give positive numbers of minutes",
            args.minutes,
            args.every
        );
    }
    let Some(chrome) = chromium() else {
        bail!(
            "no Chromium at {} ($CHROMIUM, else /usr/bin/chromium): install Debian's chromium \
             package",
            chromium_path().display()
        );
    };
    let web = ensure_web()?;
    let out = out_dir("serve")?;
    let elf = crate::emu::build_firmware()?;
    let bin = imu_lab_bin()?;
    let stream = out.join("soak-stream.csv");
    run(Command::new(&bin)
        .args([
            "simulate",
            "--trajectory",
            "standard",
            "--part",
            "hard-iron",
        ])
        .args(["--rate", "1000", "--samples", "128000", "--seed", "3"])
        .arg("--output")
        .arg(&stream))?;
    // the emulator may run slower than real time: room for three times the soak
    let seconds =
        (args.minutes.max(args.device_minutes.unwrap_or(0.0)) * 60.0 * 3.0 + 600.0).round();
    let sim = crate::emu::Sim::start(
        &elf,
        &[
            "--seconds".into(),
            format!("{seconds}"),
            "--stream".into(),
            stream.display().to_string(),
            "--log".into(),
            out.join("soak-firmware.log").display().to_string(),
            "--quiet".into(),
        ],
        &out,
    )?;
    let port = format!("tcp:127.0.0.1:{}", sim.port);
    let report = out.join("soak.md");
    let file =
        std::fs::File::create(&report).with_context(|| format!("creating {}", report.display()))?;
    run(Command::new("node")
        .arg(web.join("bench/live_soak.mjs"))
        .args([
            port,
            format!("{}", args.minutes),
            format!("{}", args.every * 60.0),
            format!("{}", args.device_minutes.unwrap_or(args.minutes)),
        ])
        .env("IMU_LAB_BIN", bin)
        .env("CHROMIUM", chrome)
        .stdout(file))?;
    print!(
        "{}",
        std::fs::read_to_string(&report)
            .with_context(|| format!("reading {}", report.display()))?
    );
    drop(sim);
    Ok(())
}
