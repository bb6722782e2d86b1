//! Physical plausibility of a correction: every bound from the part's datasheet with a stated
//! margin ([`BOUNDS`]), checked by the host on the calibration file's own numbers
//! ([`crate::file::CalFile::to_device`]) and by the host and the device on the stored blob
//! ([`super::decode_blob`]), with the same function ([`check`]). A refusal
//! ([`Refusal`]) names the calibration file's key, the axis, the value and the bound.
//!
//! No `std`: Newton's square root and Jacobi rotations instead of a linear-algebra library.
use serde::{Deserialize, Serialize};

use super::{BlobError, Calibration};

/// Standard gravity, m/s² per g (the accelerometer's nominal sensitivities are per g).
pub const G0: f64 = 9.80665;

/// The accelerometer + gyroscope part a calibration was fitted for.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum ImuPart {
    /// InvenSense MPU-6050 (PS-MPU-6000A-00 rev 3.4).
    #[serde(rename = "MPU-6050")]
    Mpu6050,
}

/// The magnetometer part a calibration was fitted for. The firmware drives the QMC5883L; the
/// lab also fits recordings of the HMC5883L (a file then names it, and a device refuses it as
/// fitted for another part). New parts are appended: the blob stores the variant's index.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum MagPart {
    /// QST QMC5883L (datasheet rev C).
    #[serde(rename = "QMC5883L")]
    Qmc5883l,
    /// Honeywell HMC5883L (datasheet form 900405 rev E).
    #[serde(rename = "HMC5883L")]
    Hmc5883l,
}

impl ImuPart {
    /// The part's name as written in the calibration file.
    pub const fn name(self) -> &'static str {
        match self {
            ImuPart::Mpu6050 => "MPU-6050",
        }
    }
    /// Accelerometer full-scale ranges (g) and nominal sensitivities (LSB/g)
    /// (PS-MPU-6000A-00 rev 3.4, §6.2, AFS_SEL = 0…3).
    pub const fn accel_ranges(self) -> [(u16, f64); 4] {
        [(2, 16384.0), (4, 8192.0), (8, 4096.0), (16, 2048.0)]
    }
    /// Gyroscope full-scale ranges (deg/s) and nominal sensitivities (LSB per deg/s)
    /// (PS-MPU-6000A-00 rev 3.4, §6.1, FS_SEL = 0…3).
    pub const fn gyro_ranges(self) -> [(u16, f64); 4] {
        [(250, 131.0), (500, 65.5), (1000, 32.8), (2000, 16.4)]
    }
    /// Temperature sensor sensitivity, LSB/°C (PS-MPU-6000A-00 rev 3.4, §6.3).
    pub const fn temp_lsb_per_c(self) -> f64 {
        340.0
    }
}

impl MagPart {
    /// Every magnetometer part, in the order of their blob index.
    pub const ALL: [MagPart; 2] = [MagPart::Qmc5883l, MagPart::Hmc5883l];

    /// The part's name as written in the calibration file.
    pub const fn name(self) -> &'static str {
        match self {
            MagPart::Qmc5883l => "QMC5883L",
            MagPart::Hmc5883l => "HMC5883L",
        }
    }
    /// The part named `name` (as in the calibration file, any case).
    pub fn from_name(name: &str) -> Option<MagPart> {
        MagPart::ALL
            .into_iter()
            .find(|p| p.name().eq_ignore_ascii_case(name.trim()))
    }
    /// Field ranges (µT) and nominal sensitivities (LSB/G): QMC5883L datasheet rev C,
    /// specifications (RNG = ±2 G, ±8 G); HMC5883L datasheet rev E, table 9 (GN = 0…7:
    /// ±0.88 G … ±8.1 G).
    pub const fn ranges(self) -> &'static [(u16, f64)] {
        match self {
            MagPart::Qmc5883l => &[(200, 12000.0), (800, 3000.0)],
            MagPart::Hmc5883l => &[
                (88, 1370.0),
                (130, 1090.0),
                (190, 820.0),
                (250, 660.0),
                (400, 440.0),
                (470, 390.0),
                (560, 330.0),
                (810, 230.0),
            ],
        }
    }
    /// The sensitivity (LSB per µT) at the part's power-on range (QMC5883L: ±2 G; HMC5883L:
    /// GN = 1, ±1.3 G).
    pub fn default_lsb_per_ut(self) -> f64 {
        let i = match self {
            MagPart::Qmc5883l => 0,
            MagPart::Hmc5883l => 1,
        };
        self.ranges()[i].1 / 100.0
    }
}

/// The full-scale ranges a calibration was fitted for: accelerometer ±g, gyroscope ±deg/s,
/// magnetometer ±µT (blob version 4; version 3 stored gauss).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Ranges {
    pub accel_g: u16,
    pub gyro_dps: u16,
    pub mag_ut: u16,
}

impl Ranges {
    /// The magnetometer's range in gauss, as the datasheets state it.
    pub fn mag_gauss(&self) -> f64 {
        f64::from(self.mag_ut) / 100.0
    }
}

/// What a calibration was fitted for: the parts, their ranges and the sensitivities (LSB per
/// m/s², per deg/s, per µT) the file converted with. Recorded in the blob.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Fitted {
    pub imu: ImuPart,
    pub mag: MagPart,
    pub ranges: Ranges,
    pub lsb_per_unit: [f32; 3],
    /// The parts were not recorded (a version-2 blob) and are taken to be the firmware's.
    #[serde(skip)]
    pub parts_assumed: bool,
}

/// Relative tolerance between a sensitivity and the part's nominal one at a range (rounding of
/// the nominal values, e.g. the gyro's 32.8 for 32.768).
pub const LSB_MATCH: f64 = 0.01;

fn range_of(lsb: f64, table: &[(u16, f64)]) -> Option<u16> {
    table
        .iter()
        .find(|(_, nominal)| (lsb / nominal - 1.0).abs() <= LSB_MATCH)
        .map(|(r, _)| *r)
}

impl Fitted {
    /// The ranges of `imu` and `mag` whose nominal sensitivities `lsb_per_unit` matches (within
    /// [`LSB_MATCH`]); [`BlobError::NoRange`] names the key of the one that matches none.
    pub fn new(imu: ImuPart, mag: MagPart, lsb_per_unit: [f32; 3]) -> Result<Fitted, BlobError> {
        let [a, g, m] = lsb_per_unit;
        let no = |key, value| BlobError::NoRange { key, value };
        let accel_g =
            range_of(f64::from(a) * G0, &imu.accel_ranges()).ok_or(no(Key::AccelLsbPerUnit, a))?;
        let gyro_dps =
            range_of(f64::from(g), &imu.gyro_ranges()).ok_or(no(Key::GyroLsbPerUnit, g))?;
        let mag_ut =
            range_of(f64::from(m) * 100.0, mag.ranges()).ok_or(no(Key::MagLsbPerUnit, m))?;
        Ok(Fitted {
            imu,
            mag,
            ranges: Ranges {
                accel_g,
                gyro_dps,
                mag_ut,
            },
            lsb_per_unit,
            parts_assumed: false,
        })
    }

    /// The magnetometer's full scale, µT.
    pub fn mag_range_ut(&self) -> f64 {
        f64::from(self.ranges.mag_ut)
    }
}

/// A key of the calibration file (`imu_cal::file`) a bound applies to. The discriminant is what
/// the wire carries (`imu_proto::CalProblem::Implausible`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum Key {
    AccelLsbPerUnit = 0,
    GyroLsbPerUnit = 1,
    MagLsbPerUnit = 2,
    AccelScale = 3,
    AccelOffset = 4,
    AccelMisalignment = 5,
    /// Entries above the diagonal of the accelerometer matrix: the file's model has none.
    AccelUpper = 6,
    GyroScale = 7,
    GyroBias = 8,
    GyroTempCoeff = 9,
    GyroMisalignment = 10,
    GyroTempLsbPerC = 11,
    /// The condition number of the soft-iron matrix (σ_max/σ_min).
    MagSoftIronCondition = 12,
    /// A singular value of the soft-iron matrix (its gain along a principal axis).
    MagSoftIronGain = 13,
    MagHardIron = 14,
    /// An entry of the soft-iron matrix (the axis is the row-major index, shown as `[i][j]`).
    MagSoftIron = 15,
    /// The determinant of the soft-iron matrix: negative for a mirrored frame.
    MagSoftIronDeterminant = 16,
    /// The temperature the gyro's bias was fitted at.
    GyroTempRef = 17,
    /// The temperature the MPU-6050's sensor reads as 0 LSB.
    GyroTempOffset = 18,
}

impl Key {
    /// Every key, by discriminant.
    pub const ALL: [Key; 19] = [
        Key::AccelLsbPerUnit,
        Key::GyroLsbPerUnit,
        Key::MagLsbPerUnit,
        Key::AccelScale,
        Key::AccelOffset,
        Key::AccelMisalignment,
        Key::AccelUpper,
        Key::GyroScale,
        Key::GyroBias,
        Key::GyroTempCoeff,
        Key::GyroMisalignment,
        Key::GyroTempLsbPerC,
        Key::MagSoftIronCondition,
        Key::MagSoftIronGain,
        Key::MagHardIron,
        Key::MagSoftIron,
        Key::MagSoftIronDeterminant,
        Key::GyroTempRef,
        Key::GyroTempOffset,
    ];

    /// The key of a wire discriminant.
    pub fn from_u8(v: u8) -> Option<Key> {
        Key::ALL.get(usize::from(v)).copied()
    }

    /// The calibration file's key (`section.name`), with what is checked for the whole-matrix
    /// quantities.
    pub const fn name(self) -> &'static str {
        match self {
            Key::AccelLsbPerUnit => "accel.lsb_per_unit",
            Key::GyroLsbPerUnit => "gyro.lsb_per_unit",
            Key::MagLsbPerUnit => "mag.lsb_per_unit",
            Key::AccelScale => "accel.scale",
            Key::AccelOffset => "accel.offset",
            Key::AccelMisalignment => "accel.misalignment_deg",
            Key::AccelUpper => "accel matrix above the diagonal (none in the file's model)",
            Key::GyroScale => "gyro.scale",
            Key::GyroBias => "gyro.bias",
            Key::GyroTempCoeff => "gyro.temp_coeff",
            Key::GyroMisalignment => "gyro.misalignment_deg",
            Key::GyroTempLsbPerC => "gyro.temp_lsb_per_c",
            Key::MagSoftIronCondition => "mag.soft_iron condition number",
            Key::MagSoftIronGain => "mag.soft_iron singular value",
            Key::MagHardIron => "mag.hard_iron",
            Key::MagSoftIron => "mag.soft_iron",
            Key::MagSoftIronDeterminant => "mag.soft_iron determinant",
            Key::GyroTempRef => "gyro.temp_ref",
            Key::GyroTempOffset => "gyro.temp_offset_c",
        }
    }

    /// The unit of the key's values ("" for dimensionless).
    pub const fn unit(self) -> &'static str {
        match self {
            Key::AccelLsbPerUnit => " LSB per m/s²",
            Key::GyroLsbPerUnit => " LSB per deg/s",
            Key::MagLsbPerUnit => " LSB per µT",
            Key::AccelOffset => " m/s²",
            Key::AccelMisalignment | Key::GyroMisalignment => "°",
            Key::GyroBias => " deg/s",
            Key::GyroTempCoeff => " deg/s per °C",
            Key::GyroTempLsbPerC => " LSB/°C",
            Key::MagHardIron => " µT",
            Key::GyroTempRef | Key::GyroTempOffset => " °C",
            Key::AccelScale
            | Key::AccelUpper
            | Key::GyroScale
            | Key::MagSoftIronCondition
            | Key::MagSoftIronGain
            | Key::MagSoftIron
            | Key::MagSoftIronDeterminant => "",
        }
    }
}

/// A parameter outside its bound: the file key, the axis (`None` for a whole-matrix quantity),
/// the value and the bound, in the key's unit ([`Key::unit`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Refusal {
    pub key: Key,
    pub axis: Option<u8>,
    pub value: f64,
    pub lo: f64,
    pub hi: f64,
}

impl core::fmt::Display for Refusal {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        let u = self.key.unit();
        f.write_str(self.key.name())?;
        match self.axis {
            Some(a) if self.key == Key::MagSoftIron => write!(f, "[{}][{}]", a / 3, a % 3)?,
            Some(a) => write!(f, "[{a}]")?,
            None => {}
        }
        write!(f, " = {}{u} is outside ", Num(self.value))?;
        if self.lo == -self.hi {
            write!(f, "±{}{u}", Num(self.hi))
        } else {
            write!(f, "{}–{}{u}", Num(self.lo), Num(self.hi))
        }
    }
}

/// A number with four significant digits, trailing zeros dropped (`1.9`, `0.91`, `3.438`,
/// `∞`), without `std`.
pub struct Num(pub f64);

impl core::fmt::Display for Num {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        let x = self.0;
        if x.is_nan() {
            return f.write_str("NaN");
        }
        if x.is_infinite() {
            return f.write_str(if x > 0.0 { "∞" } else { "−∞" });
        }
        let a = if x < 0.0 { -x } else { x };
        if a >= 1e6 || (a != 0.0 && a < 1e-6) {
            // Four significant digits in scientific form (`1e30`, `−2.5e-9`).
            let mut buf = Buf([0; 48], 0);
            core::fmt::write(&mut buf, format_args!("{a:.3e}"))?;
            let s = buf.as_str();
            let (mantissa, exp) = s.split_once('e').unwrap_or((s, "0"));
            let mantissa = mantissa.trim_end_matches('0').trim_end_matches('.');
            let sign = if x < 0.0 { "−" } else { "" };
            return write!(f, "{sign}{mantissa}e{exp}");
        }
        let decimals = if a == 0.0 || a >= 1000.0 {
            0
        } else if a >= 100.0 {
            1
        } else if a >= 10.0 {
            2
        } else if a >= 1.0 {
            3
        } else if a >= 0.1 {
            4
        } else if a >= 0.01 {
            5
        } else {
            6
        };
        let mut buf = Buf([0; 48], 0);
        core::fmt::write(&mut buf, format_args!("{x:.decimals$}"))?;
        let mut s = buf.as_str();
        if s.contains('.') {
            s = s.trim_end_matches('0').trim_end_matches('.');
        }
        if s == "-0" {
            s = "0";
        }
        match s.strip_prefix('-') {
            Some(rest) => write!(f, "−{rest}"),
            None => f.write_str(s),
        }
    }
}

struct Buf([u8; 48], usize);

impl Buf {
    fn as_str(&self) -> &str {
        core::str::from_utf8(&self.0[..self.1]).unwrap_or("?")
    }
}

impl core::fmt::Write for Buf {
    fn write_str(&mut self, s: &str) -> core::fmt::Result {
        let end = self.1 + s.len();
        if end > self.0.len() {
            return Err(core::fmt::Error);
        }
        self.0[self.1..end].copy_from_slice(s.as_bytes());
        self.1 = end;
        Ok(())
    }
}

/// One bound: the key and axes it applies to, the datasheet figure behind it and its source,
/// the margin, and the bound itself (`lo`–`hi`, in the key's unit).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Bound {
    pub key: Key,
    /// The axes the row applies to (e.g. `[true, true, false]` for x and y).
    pub axes: [bool; 3],
    /// The datasheet figure, in words with its unit.
    pub datasheet: &'static str,
    /// Where the figure is stated.
    pub source: &'static str,
    /// The margin applied, in words.
    pub margin: &'static str,
    pub lo: f64,
    pub hi: f64,
}

/// The margin on the MPU-6050's tolerances (docs/calibration.md, "Plausibility"): the
/// datasheet's figures are for a genuine part at 25 °C; temperature alone adds as much again,
/// and a calibration also absorbs board stress and the register-compatible parts sold as
/// MPU-6050.
pub const MPU_MARGIN: f64 = 3.0;
/// The strongest geomagnetic field at the Earth's surface (≈ 66 µT near the south magnetic
/// pole), rounded up, µT.
pub const F_MAX_UT: f64 = 70.0;
/// Largest condition number of the soft-iron matrix.
pub const SOFT_IRON_CONDITION: f64 = 3.0;
/// Largest singular value (gain) of the soft-iron matrix; the least is `F_MAX_UT / range`.
pub const SOFT_IRON_GAIN_MAX: f64 = 3.0;

const PS_MPU_ACCEL: &str = "PS-MPU-6000A-00 rev 3.4, §6.2";
const PS_MPU_GYRO: &str = "PS-MPU-6000A-00 rev 3.4, §6.1";
const PS_MPU_TEMP: &str = "PS-MPU-6000A-00 rev 3.4, §6.3";
/// The temperature the MPU-6050's sensor reads as 0 LSB, °C: −521 LSB at 35 °C at 340 LSB/°C
/// (PS-MPU-6000A-00 rev 3.4, §6.3), 36.53 °C as the register map states it.
pub const TEMP_OFFSET_C: f64 = 36.53;
/// The margin on the temperature sensor's offset, °C: the datasheet states none; 10 °C is
/// 3,400 LSB, far beyond a trim and well short of a wrong unit or sign.
const TEMP_OFFSET_MARGIN_C: f64 = 10.0;
/// 2 % cross-axis sensitivity as an angle, degrees (2 % = 0.02 rad = 1.146°).
const CROSS_AXIS_DEG: f64 = 0.02 * 180.0 / core::f64::consts::PI;
const XYZ: [bool; 3] = [true; 3];
/// A single value (no axis).
const SCALAR: [bool; 3] = [true, false, false];

/// The bounds with a fixed value, one row per key and axes. The magnetometer's depend on its
/// range and are computed in [`mag_bounds`] from [`F_MAX_UT`], [`SOFT_IRON_CONDITION`] and
/// [`SOFT_IRON_GAIN_MAX`].
pub const BOUNDS: [Bound; 11] = [
    Bound {
        key: Key::AccelScale,
        axes: XYZ,
        datasheet: "sensitivity initial calibration tolerance ±3 %",
        source: PS_MPU_ACCEL,
        margin: "×3",
        lo: 1.0 - MPU_MARGIN * 0.03,
        hi: 1.0 + MPU_MARGIN * 0.03,
    },
    Bound {
        key: Key::AccelOffset,
        axes: [true, true, false],
        datasheet: "zero-g initial calibration tolerance ±50 mg (X, Y)",
        source: PS_MPU_ACCEL,
        margin: "×3",
        lo: -MPU_MARGIN * 0.050 * G0,
        hi: MPU_MARGIN * 0.050 * G0,
    },
    Bound {
        key: Key::AccelOffset,
        axes: [false, false, true],
        datasheet: "zero-g initial calibration tolerance ±80 mg (Z)",
        source: PS_MPU_ACCEL,
        margin: "×3",
        lo: -MPU_MARGIN * 0.080 * G0,
        hi: MPU_MARGIN * 0.080 * G0,
    },
    Bound {
        key: Key::AccelMisalignment,
        axes: XYZ,
        datasheet: "cross-axis sensitivity ±2 % (1.146°)",
        source: PS_MPU_ACCEL,
        margin: "×3",
        lo: -MPU_MARGIN * CROSS_AXIS_DEG,
        hi: MPU_MARGIN * CROSS_AXIS_DEG,
    },
    Bound {
        key: Key::GyroScale,
        axes: XYZ,
        datasheet: "sensitivity scale factor tolerance ±3 %",
        source: PS_MPU_GYRO,
        margin: "×3",
        lo: 1.0 - MPU_MARGIN * 0.03,
        hi: 1.0 + MPU_MARGIN * 0.03,
    },
    Bound {
        key: Key::GyroBias,
        axes: XYZ,
        datasheet: "initial ZRO tolerance ±20 deg/s",
        source: PS_MPU_GYRO,
        margin: "×3",
        lo: -MPU_MARGIN * 20.0,
        hi: MPU_MARGIN * 20.0,
    },
    Bound {
        key: Key::GyroTempCoeff,
        axes: XYZ,
        datasheet: "ZRO variation over −40…+85 °C ±20 deg/s (0.16 deg/s per °C)",
        source: PS_MPU_GYRO,
        margin: "×3",
        lo: -MPU_MARGIN * 20.0 / 125.0,
        hi: MPU_MARGIN * 20.0 / 125.0,
    },
    Bound {
        key: Key::GyroMisalignment,
        axes: XYZ,
        datasheet: "cross-axis sensitivity ±2 % (1.146°)",
        source: PS_MPU_GYRO,
        margin: "×3",
        lo: -MPU_MARGIN * CROSS_AXIS_DEG,
        hi: MPU_MARGIN * CROSS_AXIS_DEG,
    },
    Bound {
        key: Key::GyroTempRef,
        axes: SCALAR,
        datasheet: "temperature sensor range −40…+85 °C",
        source: PS_MPU_TEMP,
        margin: "none",
        lo: -40.0,
        hi: 85.0,
    },
    Bound {
        key: Key::GyroTempOffset,
        axes: SCALAR,
        datasheet:
            "room-temperature offset −521 LSB at 35 °C (36.53 °C at 0 LSB; no tolerance stated)",
        source: PS_MPU_TEMP,
        margin: "±10 °C",
        lo: TEMP_OFFSET_C - TEMP_OFFSET_MARGIN_C,
        hi: TEMP_OFFSET_C + TEMP_OFFSET_MARGIN_C,
    },
    Bound {
        key: Key::AccelUpper,
        axes: XYZ,
        datasheet: "— (the file's accelerometer model is lower-triangular)",
        source: "docs/calibration.md §2",
        margin: "none",
        lo: 0.0,
        hi: 0.0,
    },
];

/// The fixed bound of `key` on `axis` ([`BOUNDS`]).
fn fixed(key: Key, axis: usize) -> (f64, f64) {
    BOUNDS
        .iter()
        .find(|b| b.key == key && b.axes.get(axis.min(2)).copied().unwrap_or(false))
        .map(|b| (b.lo, b.hi))
        .unwrap_or((0.0, 0.0))
}

/// The magnetometer's bounds at a field range of `range_ut` µT: the soft-iron gain
/// `F_MAX_UT/range`–`SOFT_IRON_GAIN_MAX` (the strongest geomagnetic field along the most
/// attenuated axis must stay within the range), and the condition number 1–
/// `SOFT_IRON_CONDITION`.
pub fn mag_bounds(range_ut: f64) -> ((f64, f64), (f64, f64)) {
    (
        (F_MAX_UT / range_ut, SOFT_IRON_GAIN_MAX),
        (1.0, SOFT_IRON_CONDITION),
    )
}

/// A correction in the calibration file's parameters and units, as checked: from the file
/// itself on the host, recovered from the fixed-point blob on the host and on the device.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Physical {
    pub accel_scale: [f64; 3],
    /// m/s².
    pub accel_offset: [f64; 3],
    /// Degrees, the file's three (below the diagonal: (1,0), (2,0), (2,1)).
    pub accel_misalignment_deg: [f64; 3],
    /// The matrix above the diagonal ((0,1), (0,2), (1,2)), dimensionless.
    pub accel_upper: [f64; 3],
    pub gyro_scale: [f64; 3],
    /// deg/s.
    pub gyro_bias: [f64; 3],
    /// deg/s per °C.
    pub gyro_temp_coeff: [f64; 3],
    /// Degrees, the file's six γ₁…γ₆.
    pub gyro_misalignment_deg: [f64; 6],
    /// °C: the temperature the bias was fitted at, and the temperature the sensor reads as
    /// 0 LSB: the file's (checked on the host). `None` from a blob, which holds the reference
    /// in raw counts (an i16 by construction) and not the offset the file read it with.
    pub gyro_temp_c: Option<TempScale>,
    /// Dimensionless.
    pub soft_iron: [[f64; 3]; 3],
    /// µT.
    pub hard_iron: [f64; 3],
}

/// The gyro's temperature reference and the sensor's offset, °C (the file's `gyro.temp_ref`
/// and `gyro.temp_offset_c`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TempScale {
    pub reference: f64,
    pub offset: f64,
}

/// Matrix positions of the gyro's γ₁…γ₆ (`gyro_rot::correction_matrix`: entry (i, j) is
/// γ·s_j).
pub const GYRO_ANGLE_AT: [(usize, usize); 6] = [(0, 1), (0, 2), (1, 0), (1, 2), (2, 0), (2, 1)];
/// Matrix positions of the accelerometer's three angles (`accel::correction_matrix`:
/// T·K, T lower-triangular).
pub const ACCEL_ANGLE_AT: [(usize, usize); 3] = [(1, 0), (2, 0), (2, 1)];
const ACCEL_UPPER_AT: [(usize, usize); 3] = [(0, 1), (0, 2), (1, 2)];
const DEG: f64 = 180.0 / core::f64::consts::PI;

impl Physical {
    /// Recover the file's parameters from a fitted calibration's fixed-point corrections: the
    /// scales are the diagonal, an angle an off-diagonal entry over its column's scale, the
    /// offsets `M⁻¹·c` over the sensitivity, the temperature coefficients `M⁻¹·κ` times the
    /// part's temperature sensitivity over the gyro's. A singular matrix gives non-finite
    /// offsets, which the scale or soft-iron checks refuse first.
    pub fn of(cal: &Calibration, fitted: &Fitted) -> Physical {
        let [la, lg, lm] = fitted.lsb_per_unit.map(f64::from);
        let a = cal.accel().matrix();
        let g = cal.gyro().affine().matrix();
        let s = cal.mag().matrix();
        let ratio = |m: &[[f64; 3]; 3], (i, j): (usize, usize)| m[i][j] / m[j][j] * DEG;
        let t_lsb = fitted.imu.temp_lsb_per_c();
        Physical {
            accel_scale: [a[0][0], a[1][1], a[2][2]],
            accel_offset: solve(&a, cal.accel().folded_offset()).map(|o| o / la),
            accel_misalignment_deg: ACCEL_ANGLE_AT.map(|p| ratio(&a, p)),
            accel_upper: ACCEL_UPPER_AT.map(|(i, j)| a[i][j]),
            gyro_scale: [g[0][0], g[1][1], g[2][2]],
            gyro_bias: solve(&g, cal.gyro().affine().folded_offset()).map(|b| b / lg),
            gyro_temp_coeff: solve(&g, cal.gyro().kappa()).map(|k| k * t_lsb / lg),
            gyro_misalignment_deg: GYRO_ANGLE_AT.map(|p| ratio(&g, p)),
            gyro_temp_c: None,
            soft_iron: s,
            hard_iron: solve(&s, cal.mag().folded_offset()).map(|h| h / lm),
        }
    }
}

/// `Err` naming the first parameter outside its bound, in this order: accelerometer scale,
/// angles, offset; gyro scale, angles, temperature offset and reference (the file's only),
/// bias, temperature coefficient; soft-iron entries (finite), condition, gains and determinant, hard iron
/// (scales and conditioning first: the others are only meaningful, and only finite, for a
/// well-conditioned matrix). NaN is outside every bound.
pub fn check(p: &Physical, fitted: &Fitted) -> Result<(), Refusal> {
    let within = |key: Key, axis: Option<usize>, value: f64, (lo, hi): (f64, f64)| {
        if lo <= value && value <= hi {
            Ok(())
        } else {
            Err(Refusal {
                key,
                axis: axis.map(|a| a as u8),
                value,
                lo,
                hi,
            })
        }
    };
    let each = |key: Key, values: &[f64]| {
        values
            .iter()
            .enumerate()
            .try_for_each(|(i, &v)| within(key, Some(i), v, fixed(key, i)))
    };
    each(Key::AccelScale, &p.accel_scale)?;
    each(Key::AccelMisalignment, &p.accel_misalignment_deg)?;
    each(Key::AccelUpper, &p.accel_upper)?;
    each(Key::AccelOffset, &p.accel_offset)?;
    each(Key::GyroScale, &p.gyro_scale)?;
    each(Key::GyroMisalignment, &p.gyro_misalignment_deg)?;
    if let Some(t) = p.gyro_temp_c {
        let scalar = |key: Key, value: f64| within(key, None, value, fixed(key, 0));
        scalar(Key::GyroTempOffset, t.offset)?;
        scalar(Key::GyroTempRef, t.reference)?;
    }
    each(Key::GyroBias, &p.gyro_bias)?;
    each(Key::GyroTempCoeff, &p.gyro_temp_coeff)?;

    let range = fitted.mag_range_ut();
    let (gain, condition) = mag_bounds(range);
    // A non-finite entry first: the singular values of such a matrix mean nothing (NaN passes
    // through `min`, `max` and the square root as a number). Every entry of a matrix lies
    // within ± its largest singular value, so the gain bound is the entries' too.
    for (i, &v) in p.soft_iron.iter().flatten().enumerate() {
        if !v.is_finite() {
            within(Key::MagSoftIron, Some(i), v, (-gain.1, gain.1))?;
        }
    }
    let (smin2, smax2) = singular_values_squared(&p.soft_iron);
    let (smin, smax) = (sqrt(smin2), sqrt(smax2));
    let cond = if smin > 0.0 {
        smax / smin
    } else {
        f64::INFINITY
    };
    within(Key::MagSoftIronCondition, None, cond, condition)?;
    within(Key::MagSoftIronGain, None, smin, gain)?;
    within(Key::MagSoftIronGain, None, smax, gain)?;
    // Gains within their bound still allow a mirrored frame (a negative determinant: an axis
    // flipped or two swapped), which no distortion of a right-handed part's field produces.
    let det = determinant(&p.soft_iron);
    within(
        Key::MagSoftIronDeterminant,
        None,
        det,
        (gain.0 * gain.0 * gain.0, gain.1 * gain.1 * gain.1),
    )?;
    // The raw reading of the strongest geomagnetic field on axis i is at most
    // |h_i| + F_max·‖row i of S⁻¹‖: it must stay within the range.
    let inv = inverse(&p.soft_iron);
    for (i, &h) in p.hard_iron.iter().enumerate() {
        let row = sqrt(inv[i].iter().map(|v| v * v).sum());
        let b = range - F_MAX_UT * row;
        within(Key::MagHardIron, Some(i), h, (-b, b))?;
    }
    Ok(())
}

/// `x` with `m·x = b` (Cramer's rule; non-finite for a singular `m`).
fn solve(m: &[[f64; 3]; 3], b: [f64; 3]) -> [f64; 3] {
    let inv = inverse(m);
    [0, 1, 2].map(|i| (0..3).map(|j| inv[i][j] * b[j]).sum())
}

/// `det m`.
fn determinant(m: &[[f64; 3]; 3]) -> f64 {
    m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
        - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
        + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
}

/// `m⁻¹` by the adjugate (non-finite entries for a singular `m`).
fn inverse(m: &[[f64; 3]; 3]) -> [[f64; 3]; 3] {
    let c = |i: usize, j: usize| {
        let (r0, r1) = ((i + 1) % 3, (i + 2) % 3);
        let (c0, c1) = ((j + 1) % 3, (j + 2) % 3);
        m[r0][c0] * m[r1][c1] - m[r0][c1] * m[r1][c0]
    };
    let det = m[0][0] * c(0, 0) + m[0][1] * c(0, 1) + m[0][2] * c(0, 2);
    let mut out = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            // The cofactor of (j, i), transposed.
            out[i][j] = c(j, i) / det;
        }
    }
    out
}

/// `√x` for x ≥ 0 without `std` (Newton's iteration from an exponent-halved start; 8 steps
/// reach f64 precision for the matrices checked here); ∞ for ∞, 0 for anything not positive.
fn sqrt(x: f64) -> f64 {
    if !(x > 0.0) {
        return 0.0;
    }
    if x.is_infinite() {
        return x;
    }
    let mut r = f64::from_bits((x.to_bits() >> 1) + (0x3ff << 51));
    for _ in 0..8 {
        r = 0.5 * (r + x / r);
    }
    r
}

/// The least and greatest squared singular values of `m`: the extreme eigenvalues of the
/// symmetric `MᵀM`, by cyclic Jacobi rotations (Golub & Van Loan, §8.5; 3×3 converges to
/// f64 precision in a few sweeps; at most 16 are run).
fn singular_values_squared(m: &[[f64; 3]; 3]) -> (f64, f64) {
    let mut a = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            a[i][j] = (0..3).map(|k| m[k][i] * m[k][j]).sum();
        }
    }
    for _ in 0..16 {
        let off = a[0][1] * a[0][1] + a[0][2] * a[0][2] + a[1][2] * a[1][2];
        let diag = a[0][0] * a[0][0] + a[1][1] * a[1][1] + a[2][2] * a[2][2];
        if !(off > 1e-30 * diag) {
            break;
        }
        for (p, q) in [(0, 1), (0, 2), (1, 2)] {
            if a[p][q] == 0.0 {
                continue;
            }
            let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
            let t = theta.signum() / (theta.abs() + sqrt(theta * theta + 1.0));
            let c = 1.0 / sqrt(t * t + 1.0);
            let s = t * c;
            for k in 0..3 {
                let (akp, akq) = (a[k][p], a[k][q]);
                a[k][p] = c * akp - s * akq;
                a[k][q] = s * akp + c * akq;
            }
            for k in 0..3 {
                let (apk, aqk) = (a[p][k], a[q][k]);
                a[p][k] = c * apk - s * aqk;
                a[q][k] = s * apk + c * aqk;
            }
        }
    }
    let d = [a[0][0], a[1][1], a[2][2]];
    (
        d.iter().copied().fold(f64::INFINITY, f64::min).max(0.0),
        d.iter().copied().fold(f64::NEG_INFINITY, f64::max),
    )
}

/// The bounds as the Markdown table of docs/calibration.md ("Plausibility"), generated here so
/// that a test can check the document against the code.
#[cfg(feature = "std")]
pub fn bounds_table() -> std::string::String {
    use std::fmt::Write;
    let mut s = std::string::String::from(
        "| file key | index | datasheet figure | source | margin | bound |\n|---|---|---|---|---|---|\n",
    );
    let axes = |k: Key, a: [bool; 3]| match a {
        _ if k == Key::GyroMisalignment => "[0]–[5]",
        _ if matches!(k, Key::GyroTempRef | Key::GyroTempOffset) => "—",
        [true, true, true] => "[0]–[2]",
        [true, true, false] => "[0], [1]",
        [false, false, true] => "[2]",
        _ => "?",
    };
    let bound = |lo: f64, hi: f64, u: &str| {
        if lo == -hi {
            format!("±{}{u}", Num(hi))
        } else {
            format!("{}–{}{u}", Num(lo), Num(hi))
        }
    };
    for b in BOUNDS.iter().filter(|b| b.key != Key::AccelUpper) {
        let _ = writeln!(
            s,
            "| `{}` | {} | {} | {} | {} | {} |",
            b.key.name(),
            axes(b.key, b.axes),
            b.datasheet,
            b.source,
            b.margin,
            bound(b.lo, b.hi, b.key.unit())
        );
    }
    let (_, c) = mag_bounds(F_MAX_UT);
    let _ = writeln!(
        s,
        "| `mag.soft_iron` (condition number) | — | — (conditioning) | — | — | {} |",
        bound(c.0, c.1, "")
    );
    // Each magnetometer part at its narrowest and widest range.
    for part in MagPart::ALL {
        let r = part.ranges();
        let (lo, hi) = (f64::from(r[0].0), f64::from(r[r.len() - 1].0));
        let (glo, ghi) = (mag_bounds(lo).0, mag_bounds(hi).0);
        let (name, source) = match part {
            MagPart::Qmc5883l => ("QMC5883L", "QMC5883L datasheet rev C, specifications"),
            MagPart::Hmc5883l => ("HMC5883L", "HMC5883L datasheet rev E, table 9"),
        };
        let gauss = |ut: f64| Num(ut / 100.0);
        let (rl, rh) = (gauss(lo), gauss(hi));
        let _ = writeln!(
            s,
            "| `mag.soft_iron` (singular values) | — | {name} field range ±{rl} G … ±{rh} G | {source} | F_max = {} µT | {} at ±{rl} G, {} at ±{rh} G |",
            Num(F_MAX_UT),
            bound(glo.0, glo.1, ""),
            bound(ghi.0, ghi.1, "")
        );
        let cube = |g: (f64, f64)| (g.0 * g.0 * g.0, g.1 * g.1 * g.1);
        let (dl, dh) = (cube(glo), cube(ghi));
        let _ = writeln!(
            s,
            "| `mag.soft_iron` (determinant) | — | {name}: a right-handed frame (no axis flipped or swapped) | — | the gains' bounds cubed | {} at ±{rl} G, {} at ±{rh} G |",
            bound(dl.0, dl.1, ""),
            bound(dh.0, dh.1, "")
        );
        let _ = writeln!(
            s,
            "| `mag.hard_iron` | [0]–[2] | {name} field range ±{rl} G … ±{rh} G | {source} | range − F_max·‖row of S⁻¹‖ | {} at ±{rl} G, {} at ±{rh} G (S = I) |",
            bound(-(lo - F_MAX_UT), lo - F_MAX_UT, " µT"),
            bound(-(hi - F_MAX_UT), hi - F_MAX_UT, " µT"),
        );
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_are_short_and_signed() {
        let f = |x: f64| {
            let mut b = Buf([0; 48], 0);
            core::fmt::write(&mut b, format_args!("{}", Num(x))).unwrap();
            std::string::String::from(b.as_str())
        };
        assert_eq!(f(1.899_999_976), "1.9");
        assert_eq!(f(0.91), "0.91");
        assert_eq!(f(-1.471_0), "−1.471");
        assert_eq!(f(3.437_746_77), "3.438");
        assert_eq!(f(130.0), "130");
        assert_eq!(f(f64::INFINITY), "∞");
        assert_eq!(f(0.0), "0");
        assert_eq!(f(-0.000_01), "−0.00001");
        assert_eq!(f(1e30), "1e30");
        assert_eq!(f(-2.5e-9), "−2.5e-9");
        assert_eq!(f(123_456.0), "123456");
        assert_eq!(f(1_234_567.0), "1.235e6");
    }

    #[test]
    fn inverse_inverts() {
        let m = [[1.1, 0.05, 0.0], [0.05, 0.9, 0.02], [0.0, 0.02, 1.0]];
        let inv = inverse(&m);
        for i in 0..3 {
            for j in 0..3 {
                let p: f64 = (0..3).map(|k| m[i][k] * inv[k][j]).sum();
                assert!((p - if i == j { 1.0 } else { 0.0 }).abs() < 1e-12);
            }
        }
    }
}
