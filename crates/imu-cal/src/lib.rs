//! IMU calibration: models of the deterministic sensor errors, their fitting (host, `std`
//! feature) and the fixed-point corrections the device applies (`no_std` core).
//!
//! * [`device`] — `no_std`: the versioned, CRC-checked calibration blob and the per-sample
//!   fixed-point apply path the firmware calls.
//! * `file` (`std`) — the human-editable TOML calibration file and its conversion to the blob.
//! * `accel`, `gyro`, `gyro_rot`, `mag` (`std`) — models as sets of named effects and their fits.
//! * `lab` (`std`) — the robust fit, residuals, the noise floor, the adequacy verdict and the
//!   diagnosis of the missing effect; `solve` (`std`) — Levenberg–Marquardt, uncertainties and
//!   the statistics behind them; `error` (`std`) — the one error type; `sentinel` (`std`) — the
//!   sensors' overflow values, excluded before fitting.
#![cfg_attr(not(feature = "std"), no_std)]
#![forbid(unsafe_code)]
// `!(x > 0.0)` is used on purpose: it is also true for NaN, which must be rejected too.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod device;

#[cfg(feature = "std")]
pub mod accel;
#[cfg(feature = "std")]
pub mod error;
#[cfg(feature = "std")]
pub mod file;
#[cfg(feature = "std")]
pub mod gyro;
#[cfg(feature = "std")]
pub mod gyro_rot;
/// Tilt-compensated heading and what a calibration buys in degrees of it.
#[cfg(feature = "std")]
pub mod heading;
#[cfg(feature = "std")]
pub mod lab;
#[cfg(feature = "std")]
pub mod mag;
#[cfg(feature = "std")]
pub mod sentinel;
#[cfg(feature = "std")]
pub mod solve;
