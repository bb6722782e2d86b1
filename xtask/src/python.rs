//! `cargo xtask test`'s Python step: the `pico_imu` package (python/) built from source in
//! release, once, into the workspace's target directory, installed in a venv there, and its
//! pytest suite run against AllanTools from PyPI, the `imu-lab` binary the host tests built and
//! the firmware on the emulated board (`PICO_IMU_ELF`, `PICO_IMU_SIM`).
use std::path::{Path, PathBuf};
use std::process::Command;

use anyhow::{bail, Context, Result};

use crate::{root, run, target_dir};

/// The build backend, the test runner, the reference the drop-in is compared with (pinned so a
/// new release cannot move the test) and matplotlib for `Table.plot`.
const TEST_PACKAGES: &[&str] = &[
    "maturin>=1.9,<2",
    "pytest>=7",
    "allantools==2024.6",
    "matplotlib>=3.5",
];

/// Creates (or reuses) the venv, installs the test packages and `pip install ./python`, then
/// runs `python -m pytest python/tests`. Without a Python ≥ 3.9 it says so and skips.
pub fn test() -> Result<()> {
    let Some(python) = interpreter() else {
        eprintln!(
            "xtask: python3 >= 3.9 with venv not found: the pico_imu package's tests skipped"
        );
        return Ok(());
    };
    let venv = target_dir()?.join("python-venv");
    let bin = venv.join("bin");
    if !bin.join("python").exists() {
        run(Command::new(&python).args(["-m", "venv"]).arg(&venv))?;
    }
    let pip = |args: &[&str]| -> Result<()> {
        let mut c = Command::new(bin.join("python"));
        c.args([
            "-m",
            "pip",
            "install",
            "--quiet",
            "--disable-pip-version-check",
        ])
        .args(args);
        run(&mut c)
    };
    pip(TEST_PACKAGES)?;
    // The README's `pip install ./python`, with the venv's maturin (no second download) on PATH
    // for the build backend; cargo builds into the workspace's target directory.
    let path = std::env::join_paths(std::iter::once(bin.clone()).chain(std::env::split_paths(
        &std::env::var_os("PATH").unwrap_or_default(),
    )))?;
    let mut c = Command::new(bin.join("python"));
    c.args([
        "-m",
        "pip",
        "install",
        "--quiet",
        "--disable-pip-version-check",
        "--no-build-isolation",
        "--force-reinstall",
        "--no-deps",
        "./python",
    ])
    .env("PATH", &path)
    .env("CARGO_TARGET_DIR", target_dir()?);
    run(&mut c)?;
    let mut c = Command::new(bin.join("python"));
    c.args(["-m", "pytest", "-q", "python/tests"])
        .env("IMU_LAB", imu_lab()?)
        .env("PATH", &path);
    // `pico_imu.Device`'s tests (test_device.py) run the firmware's release ELF on the emulated
    // board: both are provided where node is there (CI), and the tests skip without them.
    if crate::emu::node_available() {
        c.env("PICO_IMU_ELF", crate::emu::build_firmware()?)
            .env("PICO_IMU_SIM", crate::emu::ensure_sim()?);
    } else {
        eprintln!("xtask: node >= 20 not found: the pico_imu device tests will be skipped");
    }
    run(&mut c)
}

/// `python3` when it is 3.9 or newer and has the venv module.
fn interpreter() -> Option<PathBuf> {
    let ok = Command::new("python3")
        .args([
            "-c",
            "import sys, venv, ensurepip; sys.exit(0 if sys.version_info >= (3, 9) else 1)",
        ])
        .status()
        .map(|s| s.success())
        .unwrap_or(false);
    ok.then(|| PathBuf::from("python3"))
}

/// The host `imu-lab` binary (built first when needed): the tests compare tables with its
/// `--json`.
fn imu_lab() -> Result<PathBuf> {
    run(crate::cargo().args([
        "build",
        "--quiet",
        "-p",
        "imu-lab",
        "--target",
        "host-tuple",
    ]))?;
    let host = host_triple()?;
    let exe = target_dir()?.join(host).join("debug").join("imu-lab");
    if !Path::new(&exe).exists() {
        bail!("{} missing after building imu-lab", exe.display());
    }
    Ok(exe)
}

/// The host's target triple, from `rustc -vV`.
fn host_triple() -> Result<String> {
    let out = Command::new(std::env::var("RUSTC").unwrap_or_else(|_| "rustc".into()))
        .arg("-vV")
        .current_dir(root())
        .output()
        .context("starting rustc -vV")?;
    String::from_utf8_lossy(&out.stdout)
        .lines()
        .find_map(|l| l.strip_prefix("host: ").map(str::to_string))
        .context("rustc -vV names no host")
}
