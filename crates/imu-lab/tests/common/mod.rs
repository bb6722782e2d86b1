//! Helpers shared by the CLI tests (each test binary uses a subset).
#![allow(dead_code)]
use std::ffi::{OsStr, OsString};
use std::process::Output;

use assert_cmd::Command;
use serde_json::Value;

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

/// Runs `imu-lab` with `args`, asserts that it failed, and returns its stderr.
pub fn run_err<I: IntoIterator<Item = S>, S: AsRef<OsStr>>(args: I) -> String {
    let args: Vec<OsString> = args.into_iter().map(|a| a.as_ref().to_owned()).collect();
    let out = run(&args);
    let err = String::from_utf8_lossy(&out.stderr).to_string();
    assert!(!out.status.success(), "{args:?} succeeded: {err}");
    err
}

/// A run's stdout, which must be exactly one JSON object.
pub fn stdout_json(out: &Output) -> Value {
    serde_json::from_slice(&out.stdout).expect("stdout is exactly one JSON object")
}

/// A run's stdout as text.
pub fn stdout_text(out: &Output) -> String {
    String::from_utf8_lossy(&out.stdout).to_string()
}

/// `imu-lab simulate`: 30 min at 100 Hz of a gyro's background noise (quantization, white,
/// flicker, rate random walk) plus `extra`, written to `path`.
pub fn simulate_gyro<S: AsRef<OsStr>>(path: &str, seed: u64, extra: &[S]) {
    let seed = seed.to_string();
    let args: Vec<OsString> = [
        "simulate",
        "--rate",
        "100",
        "--samples",
        "180000",
        "--seed",
        &seed,
        "--quantization",
        "2e-4",
        "--white",
        "5e-3",
        "--flicker",
        "3e-3",
        "--rrw",
        "1e-4",
        "-o",
        path,
    ]
    .iter()
    .map(OsString::from)
    .chain(extra.iter().map(|e| e.as_ref().to_os_string()))
    .collect();
    run_ok(args);
}
