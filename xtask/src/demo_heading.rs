//! The demo's heading part (`cargo xtask demo`): what the magnetometer's calibration buys in
//! degrees of heading, on the emulated board turned through a known trajectory by a part with
//! hard iron (`imu-lab simulate --trajectory standard --part hard-iron`: 25 µT of hard iron, a
//! mild soft iron, a gyro bias).
//!
//! One raw recording of the trajectory (`imu-lab record --raw`), the magnetometer's hard and
//! soft iron fitted on it (`imu-lab calibrate mag`), then `imu-lab heading` on the same
//! recording: the tilt-compensated heading with the identity and with the fitted calibration,
//! against the simulator's truth → "heading error before → after". Then the device's own
//! estimate: the fitted calibration uploaded (RAM only), a calibrated recording, and the
//! device's heading column against the truth (`imu-lab heading --device`).
use std::path::Path;

use anyhow::Result;

use crate::emu::{imu_lab, out_dir, Sim};
use crate::run;

/// `cargo xtask demo`: the noise lab's walk (`emu::demo`), then, on the emulator, the heading.
pub fn demo(args: &crate::emu::DemoArgs) -> Result<()> {
    if args.serve {
        // the page until Ctrl-C: the heading is not part of it
        return crate::emu::demo(args).map(|_| ());
    }
    match crate::emu::demo(args)? {
        // Heading before → after calibration, on a second emulated board turned through a
        // known trajectory (its truth is what the heading is judged against).
        Some(elf) => heading_demo(&elf, &out_dir("demo")?),
        None => {
            eprintln!(
                "xtask: the heading part of the demo needs a known trajectory: emulator only"
            );
            Ok(())
        }
    }
}

/// The trajectory's length, s (`imu_sim::trajectory::Trajectory::standard`).
fn period() -> f64 {
    imu_sim::trajectory::Trajectory::standard().duration()
}

pub fn heading_demo(elf: &Path, out: &Path) -> Result<()> {
    let stream = out.join("heading-stream.csv");
    let seconds = period();
    run(imu_lab()
        .args([
            "simulate",
            "--trajectory",
            "standard",
            "--part",
            "hard-iron",
        ])
        .args(["--rate", "1000", "--seed", "7", "--samples"])
        .arg(format!("{}", (seconds * 1000.0) as u64))
        .arg("--output")
        .arg(&stream))?;
    let sim = Sim::start(
        elf,
        &[
            "--seconds".into(),
            "3600".into(),
            "--stream".into(),
            stream.display().to_string(),
            "--log".into(),
            out.join("heading-firmware.log").display().to_string(),
            "--quiet".into(),
        ],
        out,
    )?;
    let port = format!("tcp:127.0.0.1:{}", sim.port);
    let raw = out.join("heading-raw.csv");
    let cal = out.join("heading-cal.toml");
    let _ = std::fs::remove_file(&cal);
    run(imu_lab()
        .args(["record", "--port", &port, "--raw", "--seconds"])
        .arg(format!("{seconds}"))
        .arg("--out")
        .arg(&raw))?;
    run(imu_lab()
        .args(["calibrate", "mag"])
        .arg(&raw)
        .args(["--model", "hard_iron,soft_iron", "--out"])
        .arg(&cal))?;
    // The device's own attitude filter, before (the raw recording's estimates ran on the
    // identity calibration) and after the fitted calibration is uploaded; then `imu-lab
    // heading` judges both, the lab's heading and the device's, against the truth.
    let calibrated = out.join("heading-calibrated.csv");
    run(imu_lab()
        .args([
            "device",
            "--port",
            &port,
            "calibrate",
            "--no-persist",
            "--upload",
        ])
        .arg(&cal))?;
    run(imu_lab()
        .args(["record", "--port", &port, "--seconds"])
        .arg(format!("{seconds}"))
        .arg("--out")
        .arg(&calibrated))?;
    run(imu_lab()
        .arg("heading")
        .arg(&raw)
        .arg("--device")
        .arg(&calibrated)
        .arg("--cal")
        .arg(&cal)
        .arg("--truth")
        .arg(&stream))?;
    drop(sim);
    Ok(())
}
