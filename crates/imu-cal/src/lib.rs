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
//!   sensors' overflow values, excluded before fitting; `session` (`std`) — one run of the
//!   calibration lab on a recording's columns (what `imu-lab calibrate` and
//!   `pico_imu.calibrate` run) with its JSON object and the calibration file's update.
//!
//! ```
//! use imu_cal::device::{
//!     decode_blob, encode_blob, Affine, BlobError, Calibration, Fitted, GyroCorrection, ImuPart,
//!     MagPart, Sensor, MAX_BLOB_LEN,
//! };
//!
//! // A magnetometer with a hard-iron offset of (120, −40, 15) LSB and an X gain 2 % low:
//! // out = diag(1/0.98, 1, 1)·(raw − offset), in the part's nominal LSB.
//! let gain = [[1.0 / 0.98, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
//! let mag = Affine::from_float(Sensor::Mag, gain, [120.0, -40.0, 15.0]).unwrap();
//! // Fitted for an MPU-6050 at ±2 g and ±250 °/s and a QMC5883L at ±2 G (LSB per m/s², per
//! // deg/s and per µT): a correction records the parts and ranges it is for.
//! let parts = Fitted::new(ImuPart::Mpu6050, MagPart::Qmc5883l, [16384.0 / 9.80665, 131.0, 120.0])
//!     .unwrap();
//! let cal = Calibration::fitted(Affine::IDENTITY, GyroCorrection::IDENTITY, mag, parts).unwrap();
//! // The part reports (1100, 460, −285) for a field of (1000, 500, −300) LSB: 980 / 0.98 = 1000.
//! assert_eq!(cal.apply_mag([1100, 460, -285]), [1000, 500, -300]);
//!
//! // The device stores it as a CRC-checked blob; one changed byte is refused.
//! let mut buf = [0u8; MAX_BLOB_LEN];
//! let blob = encode_blob(&cal, &mut buf).unwrap().to_vec();
//! assert_eq!(decode_blob(&blob).unwrap().apply_mag([1100, 460, -285]), [1000, 500, -300]);
//! let mut bad = blob.clone();
//! bad[20] ^= 1;
//! assert!(matches!(decode_blob(&bad), Err(BlobError::CrcMismatch { .. })));
//! ```
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
pub mod session;
#[cfg(feature = "std")]
pub mod solve;
