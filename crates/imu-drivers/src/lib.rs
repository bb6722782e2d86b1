//! MPU-6050 and QMC5883L/QMC5883P drivers on embedded-hal 1.0, blocking and async.
//!
//! ```text
//! imu_drivers::mpu6050   register layer: reg (addresses), registers (typed), Config (+ enums), ChipId, RawSample, Scale, Error
//! imu_drivers::qmc5883   register layer: reg_l/reg_p (addresses), registers (typed), Config (+ enums), Chip, Variant, MagSample, Error
//! imu_drivers::blocking  Mpu6050<I2C>, Qmc5883<I2C> over embedded_hal::i2c::I2c
//! imu_drivers::asynch    Mpu6050<I2C>, Qmc5883<I2C> over embedded_hal_async::i2c::I2c (same methods, async)
//! imu_drivers::recovery  recover_bus(): 9 SCL pulses + STOP for a stuck SDA
//! ```
//!
//! The two driver flavours are one source text expanded twice (see `sequences.rs`), so every
//! sequence is written once; all register values come from the pure register layer.
//!
//! # MPU-6050
//! ```
//! use embedded_hal_async::{delay::DelayNs, i2c::I2c};
//! use imu_drivers::asynch::Mpu6050;
//! use imu_drivers::mpu6050::{self, Address, Config, RawSample};
//!
//! async fn stream<I: I2c, D: DelayNs>(i2c: I, mut delay: D) -> Result<(), mpu6050::Error<I::Error>> {
//!     let mut imu = Mpu6050::new(i2c, Address::Ad0Low);
//!     // The default: ±250 °/s, ±4 g, 5 Hz DLPF, 1 kHz, FIFO accel + gyro.
//!     let _chip = imu.init(&mut delay, &Config::default()).await?;
//!     let one: RawSample = imu.read_all().await?; // one 14-byte burst
//!     let mut frames = [RawSample::default(); 32];
//!     loop {
//!         match imu.read_fifo(&mut frames).await {
//!             // whole frames only; SI units via the scale of the applied configuration
//!             Ok(n) => {
//!                 for f in &frames[..n] {
//!                     let _si = imu.scale().convert(f); // m/s², °/s, °C
//!                 }
//!             }
//!             Err(mpu6050::Error::FifoOverflow) => imu.reset_fifo().await?,
//!             Err(e) => return Err(e),
//!         }
//!         delay.delay_ms(10).await;
//!         # let _ = one; break Ok(());
//!     }
//! }
//! ```
//! Other methods: `probe`, `who_am_i`, `int_status`, `read_if_ready` (NotReady when
//! DATA_RDY is clear), `fifo_count`, `self_test(&mut delay)`, `chip`, `config`, `release`.
//! The blocking flavour, `imu_drivers::blocking::Mpu6050`, has the same methods without `.await`.
//!
//! # QMC5883L / QMC5883P
//! ```
//! use embedded_hal::{delay::DelayNs, i2c::I2c};
//! use imu_drivers::blocking::Qmc5883;
//! use imu_drivers::qmc5883::{self, Chip, Config, Variant};
//!
//! fn field<I: I2c, D: DelayNs>(mut i2c: I, mut delay: D) -> Result<[f32; 3], qmc5883::Error<I::Error>> {
//!     let variant = match Qmc5883::detect(&mut i2c) {
//!         Chip::Qmc5883P => Variant::P,
//!         _ => Variant::L,
//!     };
//!     let mut mag = Qmc5883::new_variant(i2c, variant); // or Qmc5883::new(i2c) for the L
//!     mag.init(&mut delay, &Config::default())?; // default: ±2 G, 200 Hz, OSR 512, continuous
//!     loop {
//!         match mag.read() {
//!             Ok(s) => return Ok(mag.microtesla(&s)), // s: MagSample { xyz, temp, overflow, skipped }
//!             Err(qmc5883::Error::NotReady) => delay.delay_ms(1),
//!             Err(e) => return Err(e),
//!         }
//!     }
//! }
//! ```
//!
//! No method panics on any byte returned by the bus; unknown identities give
//! `Error::WrongChip { found }`.
#![cfg_attr(not(feature = "std"), no_std)]
#![deny(missing_docs)]

pub mod mpu6050;
pub mod qmc5883;
pub mod recovery;
pub mod register;
mod sequences;

/// Blocking drivers over `embedded_hal::i2c::I2c` and `embedded_hal::delay::DelayNs`.
pub mod blocking {
    crate::sequences::drivers!(; ; embedded_hal::i2c::I2c; embedded_hal::delay::DelayNs);
}

/// Async drivers over `embedded_hal_async::i2c::I2c` and `embedded_hal_async::delay::DelayNs`.
pub mod asynch {
    crate::sequences::drivers!(async; await; embedded_hal_async::i2c::I2c; embedded_hal_async::delay::DelayNs);
}
