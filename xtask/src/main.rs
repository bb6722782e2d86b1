//! Project automation. `cargo xtask test` runs every test the project has; `cargo xtask demo`
//! runs the main job on the emulated device (or on a real Pico with `--port`).
use std::path::{Path, PathBuf};
use std::process::Command;

use anyhow::{bail, Context, Result};

mod e2e;
mod emu;
mod emu_check;
mod emu_link;
mod firmware;

/// Packages that only build for the device (thumbv6m-none-eabi).
const DEVICE_ONLY: &[&str] = &["pico-imu", "rp2040-hal-blocking"];

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (cmd, rest) = args
        .split_first()
        .map(|(c, r)| (c.as_str(), r))
        .unwrap_or(("help", &[]));
    match cmd {
        "test" => test(rest),
        "e2e" => e2e::e2e(rest),
        "bench-emu" => emu::bench(rest),
        "demo" => emu::demo(rest),
        "firmware" => firmware::main(rest),
        "help" | "--help" | "-h" => {
            println!("cargo xtask <command>\n\n  test    run all host tests, build the firmware, run the emulator tests\n  e2e [--scenario faults|boot-stall|sine]  end-to-end test on the emulated board\n  bench-emu  emulated cycle budget report (out/emu/bench.md)\n  firmware  release build of the firmware, size report, UF2 (out/pico-imu.uf2)\n  demo [--port PORT]  the main job: emulated IMU with a hidden effect, device tables, fit, HTML report");
            Ok(())
        }
        other => bail!("unknown xtask command `{other}` (try `cargo xtask help`)"),
    }
}

/// The workspace root (the parent of this crate's directory).
pub fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("xtask lives in the workspace")
        .to_path_buf()
}

/// Run a command in the workspace root, failing with its description if it fails.
pub fn run(cmd: &mut Command) -> Result<()> {
    let shown = format!("{cmd:?}");
    eprintln!("xtask: {shown}");
    let status = cmd
        .current_dir(root())
        .status()
        .with_context(|| format!("starting {shown}"))?;
    if !status.success() {
        bail!("{shown} failed with {status}");
    }
    Ok(())
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
    if emu::node_available() {
        for scenario in ["faults", "boot-stall", "sine"] {
            e2e::e2e(&["--scenario".to_string(), scenario.to_string()])?;
        }
        emu::harness_tests()
    } else {
        eprintln!(
            "xtask: node >= 20 not found: emulator end-to-end test and harness tests skipped"
        );
        Ok(())
    }
}
