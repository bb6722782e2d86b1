//! IMU calibration: models of the deterministic sensor errors, their fitting (host, `std`
//! feature) and the fixed-point corrections the device applies (`no_std` core).
//!
//! * [`device`] — `no_std`: the versioned, CRC-checked calibration blob and the per-sample
//!   fixed-point apply path the firmware calls (issue 4 §4, consumed by the firmware of issue 6).
//! * `file` (`std`) — the human-editable TOML calibration file and its conversion to the blob.
//! * `accel`, `gyro`, `mag`, `lab` (`std`) — models as sets of named effects, their fits, the
//!   residuals, the noise floor and the diagnosis of the missing effect.
#![cfg_attr(not(feature = "std"), no_std)]
#![forbid(unsafe_code)]

pub mod device;
