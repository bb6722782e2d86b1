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
//! # The register layer
//! Every configuration register is a type with the datasheet's fields; what a driver writes is
//! its [`register::Register::write_bytes`]: address, then value.
//! ```
//! use imu_drivers::mpu6050::registers::{GyroConfig, PwrMgmt1};
//! use imu_drivers::mpu6050::{ChipId, Config, GyroRange};
//! use imu_drivers::qmc5883::registers::Control1L;
//! use imu_drivers::register::Register;
//!
//! // GYRO_CONFIG (0x1B): FS_SEL in bits 4:3, ±2000 °/s is 3; with the self-test bits 7:5.
//! assert_eq!(GyroConfig::range(GyroRange::Dps2000).write_bytes(), [0x1B, 0b0001_1000]);
//! assert_eq!(GyroConfig::self_test(GyroRange::Dps250).bits(), 0b1110_0000);
//! // A byte read back names its fields: PWR_MGMT_1 = 0x40 after power-on is SLEEP.
//! let p = PwrMgmt1::from_bits(0x40);
//! assert!(p.sleep && !p.device_reset && p.clksel == 0);
//! // The configuration of Jaime et al. as `init` writes it: SMPLRT_DIV 0 (1 kHz), DLPF_CFG 6
//! // (5 Hz), ±250 °/s, ±4 g, in one burst from 0x19; a 6500-family clone also gets ACCEL_CONFIG2.
//! let (burst, len) = Config::default().config_burst(ChipId::Mpu6050);
//! assert_eq!(&burst[..len], [0x19, 0x00, 0x06, 0x00, 0x08]);
//! let (burst, len) = Config::default().config_burst(ChipId::Mpu6500);
//! assert_eq!(&burst[..len], [0x19, 0x00, 0x06, 0x00, 0x08, 0x06]);
//! // QMC5883L CONTROL1: OSR 512, ±2 G, 200 Hz, continuous.
//! let c1 = imu_drivers::qmc5883::Config::default().control1_l().unwrap();
//! assert_eq!(c1.write_bytes(), [0x09, 0b0000_1101]);
//! assert_eq!(Control1L::from_bits(0b0000_1101), c1);
//! ```
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
