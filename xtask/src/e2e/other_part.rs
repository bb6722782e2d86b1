//! `cargo xtask e2e --scenario other-part`: the IMU model answers WHO_AM_I as an MPU-6500
//! (0x70, as on many boards sold as "GY-521 MPU-6050"). The firmware runs it, and refuses a
//! calibration fitted for the MPU-6050 (`CalProblem::OtherPart`), keeping identity; identity
//! corrections, which record no part, are taken.
use std::fmt::Write as _;
use std::time::{Duration, Instant};

use anyhow::{bail, Result};
use imu_cal::device::{encode_blob, Calibration};
use imu_proto::{CalProblem, CalSource, ErrorCode, Reply, Request, SensorState, Vec as HVec};

use super::session::test_calibration;
use crate::emu::{build_firmware, ensure_sim, out_dir, Sim};
use crate::emu_link::Link;

/// What the model says it is.
const WHO_AM_I: &str = "0x70";
/// Emulated seconds the device runs.
const SECONDS: f64 = 3.0;

/// `cargo xtask e2e --scenario other-part [--out DIR]`.
pub fn other_part(args: &super::E2eArgs) -> Result<()> {
    let wall = Instant::now();
    let elf = build_firmware()?;
    let sim_dir = ensure_sim()?;
    let out = out_dir(args.out.as_deref().unwrap_or("e2e-other-part"))?;
    let stream = out.join("stream.csv");
    crate::run(
        std::process::Command::new("node")
            .arg(sim_dir.join("src/cli.js"))
            .args(["gen-stream", "--seed", "7", "--seconds"])
            .arg(format!("{}", SECONDS + 60.0))
            .arg("--out")
            .arg(&stream),
    )?;
    let sim_args: Vec<String> = vec![
        "--seconds".into(),
        format!("{}", SECONDS + 60.0),
        "--stream".into(),
        stream.display().to_string(),
        "--mpu-who-am-i".into(),
        WHO_AM_I.into(),
        "--log".into(),
        out.join("firmware.log").display().to_string(),
        "--quiet".into(),
        "--exit-on-disconnect".into(),
    ];
    let sim = Sim::start(&elf, &sim_args, &out)?;
    let text = match session(sim.port) {
        Ok(t) => t,
        Err(e) => {
            sim.finish_after_error();
            return Err(e);
        }
    };
    sim.wait("the other-part run")?;
    let report = format!(
        "# End-to-end emulator test: scenario `other-part`\n\nThe IMU model answers WHO_AM_I = {WHO_AM_I} (MPU-6500).\n\n{text}\nwall time: {:.1} s\n",
        wall.elapsed().as_secs_f64()
    );
    std::fs::write(out.join("report.md"), &report)?;
    println!("{report}");
    println!(
        "end-to-end test `other-part` passed ({:.1} s wall); report in {}",
        wall.elapsed().as_secs_f64(),
        out.join("report.md").display()
    );
    Ok(())
}

fn session(port: u16) -> Result<String> {
    let long = Duration::from_secs(300);
    let mut text = String::new();
    let mut link = Link::connect(port, Duration::from_secs(30))?;
    // The IMU identified itself at its initialisation: wait until it delivers.
    link.wait_until(long, "the IMU to run", |g| {
        g.statuses
            .last()
            .is_some_and(|s| s.imu == SensorState::Ok && s.samples_taken > 0)
    })?;
    let fitted = test_calibration()?;
    let mut buf = [0u8; 256];
    let blob = encode_blob(&fitted, &mut buf).map_err(|e| anyhow::anyhow!("{e:?}"))?;
    let r = link.request(
        Request::SetCalibration {
            blob: HVec::from_slice(blob).map_err(|_| anyhow::anyhow!("blob too large"))?,
            persist: true,
        },
        long,
    )?;
    writeln!(
        text,
        "SetCalibration (fitted for the MPU-6050, persist) → {r:?}"
    )?;
    if r != Reply::Error(ErrorCode::BadCalibration(CalProblem::OtherPart)) {
        bail!("a calibration for the MPU-6050 on an MPU-6500 answered {r:?}, not BadCalibration(OtherPart)");
    }
    match link.request(Request::GetCalibration, long)? {
        Reply::Calibration { status, .. } => {
            writeln!(text, "GetCalibration → {status:?}")?;
            if status.source != CalSource::Identity {
                bail!("after the refusal the device uses {status:?}, not identity");
            }
        }
        other => bail!("GetCalibration answered {other:?}"),
    }
    let blob =
        encode_blob(&Calibration::identity(), &mut buf).map_err(|e| anyhow::anyhow!("{e:?}"))?;
    let r = link.request(
        Request::SetCalibration {
            blob: HVec::from_slice(blob).map_err(|_| anyhow::anyhow!("blob too large"))?,
            persist: false,
        },
        long,
    )?;
    writeln!(text, "SetCalibration (identity) → {r:?}")?;
    if r != Reply::Ok {
        bail!("identity corrections on an MPU-6500 answered {r:?}");
    }
    Ok(text)
}
