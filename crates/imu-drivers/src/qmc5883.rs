//! QMC5883L / QMC5883P register layer (pure, no I/O) and chip detection constants.
//!
//! References:
//! - QST "QMC5883L 3-Axis Magnetic Sensor" datasheet rev C (2016) (QMC-L), sections 9.1 (register
//!   map) and 9.2 (register definitions).
//! - QST "QMC5883P 3-Axis Magnetic Sensor" datasheet rev A (QMC-P), register map and its
//!   set-up example.
//! - Honeywell HMC5883L datasheet (2013), register map table 2 (identification registers 10-12).

pub mod registers;

use registers::{Control1L, Control1P, Control2L, Control2P, ModeP, RangeP};

/// QMC5883L 7-bit I²C address (QMC-L 9.1, register map).
pub const QMC5883L_ADDR: u8 = 0x0D;
/// QMC5883P 7-bit I²C address (QMC-P register map).
pub const QMC5883P_ADDR: u8 = 0x2C;
/// HMC5883L 7-bit I²C address (HMC5883L "I2C interface").
pub const HMC5883L_ADDR: u8 = 0x1E;

/// QMC5883L registers (QMC-L 9.1, register map).
pub mod reg_l {
    /// X LSB; X, Y, Z follow little-endian up to 0x05.
    pub const DATA_X_LSB: u8 = 0x00;
    /// Status: DRDY (bit 0), OVL (bit 1), DOR (bit 2).
    pub const STATUS: u8 = 0x06;
    /// Temperature LSB (0x08 MSB), 100 LSB/°C, offset not calibrated.
    pub const TEMP_LSB: u8 = 0x07;
    /// Control 1: `OSR[7:6]` `RNG[5:4]` `ODR[3:2]` `MODE[1:0]`.
    pub const CONTROL1: u8 = 0x09;
    /// Control 2: SOFT_RST (bit 7), ROL_PNT (bit 6), INT_ENB (bit 0).
    pub const CONTROL2: u8 = 0x0A;
    /// SET/RESET period (FBR); datasheet recommends 0x01.
    pub const SET_RESET_PERIOD: u8 = 0x0B;
    /// Chip id, reads 0xFF.
    pub const CHIP_ID: u8 = 0x0D;
    /// Expected CHIP_ID value.
    pub const CHIP_ID_VALUE: u8 = 0xFF;

    /// Every register above by name: the one register table of the QMC5883L. The chip models
    /// (tests/src/qmc5883_model.rs, sim/src/devices/qmc5883l.js) are checked against it.
    pub const TABLE: &[(&str, u8)] = &[
        ("DATA_X_LSB", DATA_X_LSB),
        ("STATUS", STATUS),
        ("TEMP_LSB", TEMP_LSB),
        ("CONTROL1", CONTROL1),
        ("CONTROL2", CONTROL2),
        ("SET_RESET_PERIOD", SET_RESET_PERIOD),
        ("CHIP_ID", CHIP_ID),
    ];
}

/// QMC5883P registers (QMC-P register map).
pub mod reg_p {
    /// Chip id, reads 0x80.
    pub const CHIP_ID: u8 = 0x00;
    /// Expected CHIP_ID value.
    pub const CHIP_ID_VALUE: u8 = 0x80;
    /// X LSB; X, Y, Z follow little-endian up to 0x06.
    pub const DATA_X_LSB: u8 = 0x01;
    /// Status: DRDY (bit 0), OVFL (bit 1).
    pub const STATUS: u8 = 0x09;
    /// Control 1: `OSR2[7:6]` (down-sampling) `OSR1[5:4]` `ODR[3:2]` `MODE[1:0]`.
    pub const CONTROL1: u8 = 0x0A;
    /// Control 2: SOFT_RST (bit 7), SELF_TEST (bit 6), `RNG[3:2]`, SET_RESET `mode[1:0]`.
    pub const CONTROL2: u8 = 0x0B;
    /// Axis sign definition register; the datasheet's continuous-mode example (QMC-P 7.2)
    /// writes 0x06.
    pub const AXIS_SIGN: u8 = 0x29;
    /// Value the datasheet example writes to [`AXIS_SIGN`].
    pub const AXIS_SIGN_VALUE: u8 = 0x06;

    /// Every register above by name: the one register table of the QMC5883P.
    pub const TABLE: &[(&str, u8)] = &[
        ("CHIP_ID", CHIP_ID),
        ("DATA_X_LSB", DATA_X_LSB),
        ("STATUS", STATUS),
        ("CONTROL1", CONTROL1),
        ("CONTROL2", CONTROL2),
        ("AXIS_SIGN", AXIS_SIGN),
    ];
}

/// HMC5883L identification registers A/B/C (10..12) read 'H', '4', '3'.
pub mod reg_hmc {
    /// Identification register A.
    pub const ID_A: u8 = 10;
    /// Expected bytes.
    pub const ID_VALUE: [u8; 3] = *b"H43";
}

/// The status register's bits (same positions on L and P; DOR exists only on the L).
pub mod status_bits {
    /// Data ready.
    pub const DRDY: u8 = 1 << 0;
    /// Overflow: a channel exceeded the range.
    pub const OVL: u8 = 1 << 1;
    /// Data skipped: a measurement was overwritten before being read (QMC5883L only).
    pub const DOR: u8 = 1 << 2;
}

/// Soft-reset recovery time in ms (the QMC-L power-on time is 350 µs; 1 ms margin,
/// and QMC-P gives no figure, so the same is used).
pub const SOFT_RESET_DELAY_MS: u32 = 1;

/// Which magnetometer answered (see [`crate::blocking::Qmc5883::detect`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Chip {
    /// QMC5883L at 0x0D, CHIP_ID 0xFF.
    Qmc5883L,
    /// QMC5883P at 0x2C, CHIP_ID 0x80.
    Qmc5883P,
    /// HMC5883L at 0x1E (detected only; not driven by this crate).
    Hmc5883L,
    /// Nothing recognised answered.
    None,
}

/// Variant driven by [`crate::blocking::Qmc5883`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Variant {
    /// QMC5883L.
    #[default]
    L,
    /// QMC5883P.
    P,
}

impl Variant {
    /// 7-bit address.
    pub const fn addr(self) -> u8 {
        match self {
            Variant::L => QMC5883L_ADDR,
            Variant::P => QMC5883P_ADDR,
        }
    }
    /// Register and value that identify the chip.
    pub const fn chip_id(self) -> (u8, u8) {
        match self {
            Variant::L => (reg_l::CHIP_ID, reg_l::CHIP_ID_VALUE),
            Variant::P => (reg_p::CHIP_ID, reg_p::CHIP_ID_VALUE),
        }
    }
    /// Status register.
    pub const fn status_reg(self) -> u8 {
        match self {
            Variant::L => reg_l::STATUS,
            Variant::P => reg_p::STATUS,
        }
    }
    /// First data register.
    pub const fn data_reg(self) -> u8 {
        match self {
            Variant::L => reg_l::DATA_X_LSB,
            Variant::P => reg_p::DATA_X_LSB,
        }
    }
    /// The detect result for this variant.
    pub const fn chip(self) -> Chip {
        match self {
            Variant::L => Chip::Qmc5883L,
            Variant::P => Chip::Qmc5883P,
        }
    }
}

/// Full-scale range.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Range {
    /// ±2 G (L: 12000 LSB/G; P: 15000 LSB/G).
    #[default]
    G2,
    /// ±8 G (L: 3000 LSB/G; P: 3750 LSB/G).
    G8,
    /// ±12 G, QMC5883P only (2500 LSB/G).
    G12,
    /// ±30 G, QMC5883P only (1000 LSB/G).
    G30,
}

impl Range {
    /// Sensitivity in LSB per gauss (QMC-L and QMC-P specification tables, "Sensitivity"/"Field Resolution");
    /// `None` if the variant lacks the range.
    pub const fn lsb_per_gauss(self, v: Variant) -> Option<f32> {
        match (v, self) {
            (Variant::L, Range::G2) => Some(12000.0),
            (Variant::L, Range::G8) => Some(3000.0),
            (Variant::L, _) => None,
            (Variant::P, Range::G2) => Some(15000.0),
            (Variant::P, Range::G8) => Some(3750.0),
            (Variant::P, Range::G12) => Some(2500.0),
            (Variant::P, Range::G30) => Some(1000.0),
        }
    }
}

/// Output data rate.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Odr {
    /// 10 Hz.
    Hz10 = 0,
    /// 50 Hz.
    Hz50 = 1,
    /// 100 Hz.
    Hz100 = 2,
    /// 200 Hz (the default).
    #[default]
    Hz200 = 3,
}

impl Odr {
    /// Rate in Hz.
    pub const fn hz(self) -> u32 {
        match self {
            Odr::Hz10 => 10,
            Odr::Hz50 => 50,
            Odr::Hz100 => 100,
            Odr::Hz200 => 200,
        }
    }
}

/// Over-sampling ratio, most filtering first. On the QMC5883P it maps onto OSR1 (8, 4, 2, 1).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Osr {
    /// L: 512, P: OSR1 = 8 (the maximum of each; the default).
    #[default]
    Max = 0,
    /// L: 256, P: 4.
    High = 1,
    /// L: 128, P: 2.
    Low = 2,
    /// L: 64, P: 1.
    Min = 3,
}

/// Operating mode.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Mode {
    /// Standby (L) / suspend (P).
    Standby,
    /// Continuous measurement at the ODR (the default).
    #[default]
    Continuous,
}

/// Magnetometer configuration. The default is that of Jaime et al.: ±2 G, 200 Hz, maximum oversampling,
/// continuous, SET/RESET period 0x01, DRDY pin enabled.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Config {
    /// Range.
    pub range: Range,
    /// Output data rate.
    pub odr: Odr,
    /// Over-sampling.
    pub osr: Osr,
    /// Mode.
    pub mode: Mode,
    /// QMC5883L SET/RESET period register 0x0B (QMC-L 9.2, SET/RESET period register 0BH: "recommended ... 0x01"). Unused on the P.
    pub set_reset_period: u8,
    /// QMC5883L: drive the DRDY pin (INT_ENB = 0). Unused on the P (no pin).
    pub drdy_pin: bool,
    /// QMC5883L: pointer roll-over (ROL_PNT, QMC-L 9.2 control register 2: "the I2C data
    /// pointer automatically rolls between 00H ~ 06H"), so one 7-byte read from the status
    /// register 06H returns the status and then the data 00H–05H: a measurement is read in one
    /// transfer, and no sample can land (and be overwritten unseen) between a status read and
    /// the data read. The die temperature is then not read. Unused on the P.
    pub roll_over: bool,
}

impl Default for Config {
    fn default() -> Self {
        Config {
            range: Range::G2,
            odr: Odr::Hz200,
            osr: Osr::Max,
            mode: Mode::Continuous,
            set_reset_period: 0x01,
            drdy_pin: true,
            roll_over: false,
        }
    }
}

impl Config {
    /// QMC5883L CONTROL1 (0x09): `OSR[7:6]` `RNG[5:4]` `ODR[3:2]` `MODE[1:0]` (QMC-L 9.2, control register 1).
    /// `None` if the range is not available on the L.
    pub const fn control1_l(&self) -> Option<Control1L> {
        let rng = match self.range {
            Range::G2 => Control1L::RNG_2G,
            Range::G8 => Control1L::RNG_8G,
            _ => return None,
        };
        let mode = match self.mode {
            Mode::Standby => Control1L::MODE_STANDBY,
            Mode::Continuous => Control1L::MODE_CONTINUOUS,
        };
        Some(Control1L {
            osr: self.osr,
            rng,
            odr: self.odr,
            mode,
        })
    }

    /// QMC5883L CONTROL2 (0x0A): INT_ENB in bit 0, ROL_PNT in bit 6, soft reset off.
    pub const fn control2_l(&self) -> Control2L {
        Control2L {
            soft_reset: false,
            roll_over: self.roll_over,
            drdy_pin_off: !self.drdy_pin,
        }
    }

    /// QMC5883L SET/RESET period (0x0B).
    pub const fn set_reset_period_l(&self) -> registers::SetResetPeriod {
        registers::SetResetPeriod {
            fbr: self.set_reset_period,
        }
    }

    /// QMC5883P CONTROL1 (0x0A): OSR2 = 0 (no down-sampling) `[7:6]`, OSR1 `[5:4]`, ODR `[3:2]`,
    /// MODE `[1:0]` with 0b11 = continuous, 0b00 = suspend (QMC-P register map).
    pub const fn control1_p(&self) -> Control1P {
        Control1P {
            osr2: 0,
            osr1: self.osr,
            odr: self.odr,
            mode: match self.mode {
                Mode::Standby => ModeP::Suspend,
                Mode::Continuous => ModeP::Continuous,
            },
        }
    }

    /// QMC5883P CONTROL2 (0x0B): RNG `[3:2]` (0 = ±30 G, 1 = ±12 G, 2 = ±8 G, 3 = ±2 G),
    /// SET/RESET mode `[1:0]` = 0 (set and reset on).
    pub const fn control2_p(&self) -> Control2P {
        Control2P {
            soft_reset: false,
            self_test: false,
            range: match self.range {
                Range::G30 => RangeP::G30,
                Range::G12 => RangeP::G12,
                Range::G8 => RangeP::G8,
                Range::G2 => RangeP::G2,
            },
            set_reset: 0,
        }
    }
}

/// One magnetometer sample in raw counts.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct MagSample {
    /// X, Y, Z.
    pub xyz: [i16; 3],
    /// QMC5883L relative temperature (100 LSB/°C, uncalibrated offset); `None` on the P.
    pub temp: Option<i16>,
    /// OVL: a channel exceeded the range; the values are not valid field readings.
    pub overflow: bool,
    /// DOR: at least one measurement was skipped (not read in time). Always false on the P.
    pub skipped: bool,
}

/// Status register flags.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Status {
    /// DRDY.
    pub ready: bool,
    /// OVL / OVFL.
    pub overflow: bool,
    /// DOR (L only).
    pub skipped: bool,
}

impl Status {
    /// Decode the status byte of `v`.
    pub const fn from_bits(b: u8, v: Variant) -> Self {
        Status {
            ready: b & status_bits::DRDY != 0,
            overflow: b & status_bits::OVL != 0,
            skipped: matches!(v, Variant::L) && b & status_bits::DOR != 0,
        }
    }
}

/// Decode 6 little-endian data bytes (X, Y, Z).
pub fn decode_xyz(b: [u8; 6]) -> [i16; 3] {
    [
        i16::from_le_bytes([b[0], b[1]]),
        i16::from_le_bytes([b[2], b[3]]),
        i16::from_le_bytes([b[4], b[5]]),
    ]
}

/// QMC5883L temperature sensitivity, LSB/°C (QMC-L 9.2, temperature output registers: 100 LSB/°C; offset uncalibrated).
pub const TEMP_LSB_PER_C: f32 = 100.0;

/// Raw counts to microtesla: raw / (LSB/G) × 100 µT/G.
pub fn to_microtesla(xyz: [i16; 3], lsb_per_gauss: f32) -> [f32; 3] {
    xyz.map(|r| r as f32 / lsb_per_gauss * 100.0)
}

/// Magnetometer driver error.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Error<E> {
    /// The I²C bus failed.
    Bus(E),
    /// The chip-id register held another value.
    WrongChip {
        /// The byte read.
        found: u8,
    },
    /// DRDY was clear: no new measurement.
    NotReady,
    /// The configuration asks for something the variant lacks (e.g. ±30 G on the L).
    InvalidConfig,
}

impl<E> From<E> for Error<E> {
    fn from(e: E) -> Self {
        Error::Bus(e)
    }
}

impl<E: core::fmt::Debug> core::fmt::Display for Error<E> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Error::Bus(e) => write!(f, "QMC5883: I2C bus error: {e:?}"),
            Error::WrongChip { found } => {
                write!(f, "QMC5883: chip-id register read 0x{found:02X}")
            }
            Error::NotReady => write!(f, "QMC5883: no new measurement (DRDY clear)"),
            Error::InvalidConfig => write!(f, "QMC5883: range not available on this variant"),
        }
    }
}

impl<E: core::fmt::Debug> core::error::Error for Error<E> {}
