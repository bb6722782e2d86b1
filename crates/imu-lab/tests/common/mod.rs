//! Helpers shared by the CLI tests (each test binary uses a subset).
#![allow(dead_code)]
use std::ffi::OsStr;
use std::process::Output;

use assert_cmd::Command;

/// The real MPU-6050 recording: raw counts, 4 metadata lines, 100 Hz.
pub fn static_449s() -> String {
    format!(
        "{}/../allan/tests/data/mpu6050_static_449s.csv",
        env!("CARGO_MANIFEST_DIR")
    )
}

/// The documented flags that read its gz column in deg/s (±250 °/s: 1/131 deg/s per LSB).
pub const GZ_RAW: [&str; 10] = [
    "--column",
    "gz",
    "--skip-lines",
    "4",
    "--rate",
    "100",
    "--scale",
    "0.0076336",
    "--unit",
    "deg/s",
];

/// Runs `imu-lab` with `args`.
pub fn run<I: IntoIterator<Item = S>, S: AsRef<OsStr>>(args: I) -> Output {
    Command::cargo_bin("imu-lab")
        .unwrap()
        .args(args)
        .output()
        .unwrap()
}

/// Runs `imu-lab` with `args` and asserts that it succeeded (stderr shown otherwise).
pub fn run_ok<I: IntoIterator<Item = S>, S: AsRef<OsStr>>(args: I) -> Output {
    let out = run(args);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    out
}
