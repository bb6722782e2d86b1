//! Device-side corrections: the fixed-point apply path and the calibration blob (`no_std`).
//!
//! # What the firmware calls
//!
//! ```
//! use imu_cal::device::{decode_blob, encode_blob, Calibration};
//! let cal = Calibration::identity();
//! let mut buf = [0u8; imu_cal::device::MAX_BLOB_LEN];
//! let blob = encode_blob(&cal, &mut buf).unwrap();
//! let cal = decode_blob(blob).unwrap();
//! assert_eq!(cal.apply_accel([100, -200, 16384]), [100, -200, 16384]);
//! assert_eq!(cal.apply_gyro([5, 6, 7], 1200), [5, 6, 7]);
//! assert_eq!(cal.apply_mag([-3, 4, 0]), [-3, 4, 0]);
//! ```
//!
//! # Output unit: corrected counts in the sensor's *nominal* LSB
//!
//! Every `apply_*` returns `[i32; 3]` in the same unit as the raw input: counts of the sensor's
//! nominal sensitivity at its configured range (e.g. 16384 LSB/g at ±2 g, 131 LSB/(°/s) at
//! ±250 °/s, 12000 LSB/G for the QMC5883 at ±2 G), rounded to the nearest integer.
//! The output is what an *ideal* sensor with that nominal sensitivity would have reported.
//! Reasons:
//! * the streaming Allan engine (`allan::Engine::push(i32)`) keeps exact integer sums; feeding it
//!   the corrected count keeps that property and the physical scale is one constant per sensor,
//!   applied off the hot path when a table is reported;
//! * the rounding adds a uniform error of variance 1/12 LSB², the same as the ADC's own
//!   quantisation and < 0.1 % of the white-noise variance of the MPU-6050 gyro (≈ 10 LSB rms at
//!   1 kHz) or accelerometer — invisible in the Allan tables;
//! * the corrected scale may exceed the i16 range (gain > 1, offsets), hence i32.
//!
//! # Correction model and Q formats
//!
//! Each sensor is an affine map `out = M · (raw − o)`; the gyro offset also moves with the die
//! temperature: `o(T) = b + k · (T_raw − T_ref)` (the calibration lab's gyro `temperature` effect). The host
//! folds the offset through the matrix once (`c = M·o`, `κ = M·k`), so the device computes
//!
//! ```text
//! out_i = round( Σ_j M_ij · raw_j  −  c_i  −  κ_i · (T_raw − T_ref) )
//! ```
//!
//! | quantity | storage | format | range enforced by [`Calibration::validate`] |
//! |---|---|---|---|
//! | `M_ij` (dimensionless gain) | i32 | Q8.24 (2⁻²⁴) | Σ_j \|M_ij\| < 4 per row |
//! | `c_i` (output LSB)          | i32 | Q20.12 (2⁻¹²) | \|c_i\| < 2¹⁶ LSB |
//! | `κ_i` (output LSB per temperature LSB) | i32 | Q8.24 | \|κ_i\| < 2 |
//! | `T_ref` (temperature LSB)   | i16 | integer | — ; `T_raw − T_ref` is clamped to i16 |
//!
//! # Cost on a Cortex-M0+ (32×32→32 multiplier, no 64-bit multiply)
//!
//! A Q24 coefficient times an i16 sample needs up to 41 bits. Instead of an i64 product
//! (`__aeabi_lmul`, a library call on the M0+), [`mul_q24`] splits the coefficient into its high
//! part `m >> 12` (Q12) and its low 12 bits `m & 0xfff` and forms two 32-bit products whose sums
//! provably fit in i32 under the ranges above: `|raw·(m>>12)| ≤ 2¹⁵·2¹⁴`, `|raw·(m&0xfff)| < 2²⁷`.
//! Per axis: 6 `muls`, shifts and adds; per 3-axis sample: 18 multiplies (24 for the gyro,
//! whose temperature term adds 2 per axis).
//!
//! The firmware applies a [`Prepared`] copy, rebuilt whenever the calibration changes: the
//! coefficients are split once instead of per sample, and a diagonal matrix (the model of Jaime et al.,
//! eq. 1: offset and scale per axis; a bias-only gyro; identity) skips its six zero products. Same
//! results bit for bit (`tests/fixed_point.rs`). Emulated cost of the corrections per 1 kHz
//! sample set (accel + gyro with temperature term, plus the 200 Hz magnetometer): 703 cycles
//! applying `Calibration` directly, 579 prepared with full matrices, 276 with diagonal ones
//! (`cargo xtask bench-emu`, stage "corrections").
//!
//! # Error bound (tested exhaustively in `tests/fixed_point.rs`)
//!
//! Against the exact real-valued correction with the *stored* float parameters:
//! coefficient rounding ≤ 3·2¹⁵·2⁻²⁵ ≈ 0.003 LSB, dropped low-part bits ≤ 2⁻¹² LSB, `c` rounding ≤ 2⁻¹³
//! LSB, final rounding ≤ 0.5 LSB; so the fixed-point output is within 0.51 LSB of the exact value
//! and within 1 LSB of the float correction rounded to the nearest count.
//!
//! # Blob layout (version [`BLOB_VERSION`])
//!
//! ```text
//! offset 0  : b"PCAL"                magic
//! offset 4  : u16 LE                 format version
//! offset 6  : u16 LE                 payload length n
//! offset 8  : n bytes                postcard encoding of `Calibration`
//! offset 8+n: u32 LE                 CRC-32/ISO-HDLC over bytes 0 .. 8+n
//! ```
//!
//! The `Calibration` holds the three corrections and what they were fitted for ([`Fitted`]:
//! the parts, their full-scale ranges and the sensitivities), which [`plausible`] checks the
//! corrections against (the parts' datasheet bounds, docs/calibration.md "Plausibility").
//! Versions 2 (no parts) and 3 (the magnetometer range in gauss) are still read; see
//! [`BLOB_VERSION`].

// Fixed 3×3 index arithmetic reads closer to the equations than iterator chains.
#![allow(clippy::needless_range_loop)]

use serde::{Deserialize, Serialize};

mod blob;
pub mod plausible;
mod prepared;
pub use blob::{decode_blob, encode_blob, BLOB_MAGIC, BLOB_VERSION, MAX_BLOB_LEN};
pub use plausible::{Fitted, ImuPart, Key, MagPart, Ranges, Refusal};
pub use prepared::Prepared;

/// Why a blob or a parameter set was rejected. Each variant says what and where.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum BlobError {
    /// Fewer bytes than the 12-byte header + CRC, or than the header's payload length.
    Truncated { len: usize, needed: usize },
    /// The first four bytes are not `b"PCAL"`.
    BadMagic { found: [u8; 4] },
    /// A blob written by another format version.
    WrongVersion { found: u16, expected: u16 },
    /// The stored CRC does not match the bytes.
    CrcMismatch { stored: u32, computed: u32 },
    /// The payload is not a valid postcard `Calibration` (or has trailing bytes).
    Malformed,
    /// A coefficient is outside the range the fixed-point path supports (see the module docs).
    OutOfRange {
        sensor: Sensor,
        what: Quantity,
        axis: u8,
    },
    /// The output buffer given to [`encode_blob`] is too small.
    BufferTooSmall { len: usize },
    /// A parameter outside its datasheet bound ([`plausible::BOUNDS`]): the file key, axis,
    /// value and bound.
    Implausible(Refusal),
    /// A sensitivity (LSB per unit) that matches none of the part's ranges, or not its
    /// temperature sensitivity.
    NoRange { key: Key, value: f32 },
    /// A correction other than identity that does not record the parts and ranges it was
    /// fitted for.
    NotFitted,
}

/// Which sensor a [`BlobError::OutOfRange`] refers to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Sensor {
    Accel,
    Gyro,
    Mag,
}

/// Which quantity a [`BlobError::OutOfRange`] refers to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Quantity {
    /// A row of the matrix `M` (Σ|M_ij| ≥ 4).
    MatrixRow,
    /// A folded offset `c_i` (|c_i| ≥ 2¹⁶ LSB).
    Offset,
    /// A temperature coefficient `κ_i` (|κ_i| ≥ 2, or not finite).
    TempCoef,
    /// A non-finite float parameter.
    NotFinite,
    /// The gyro's reference temperature in raw counts (`temp_ref − temp_offset_c` times the
    /// sensitivity: outside i16).
    TempRef,
}

impl Sensor {
    /// The calibration file's keys for the matrix and for the offset of this sensor.
    pub const fn keys(self) -> (&'static str, &'static str) {
        match self {
            Sensor::Accel => ("accel.scale and accel.misalignment_deg", "accel.offset"),
            Sensor::Gyro => ("gyro.scale and gyro.misalignment_deg", "gyro.bias"),
            Sensor::Mag => ("mag.soft_iron", "mag.hard_iron"),
        }
    }
}

impl core::fmt::Display for BlobError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            BlobError::Truncated { len, needed } => {
                write!(f, "calibration blob truncated: {len} bytes, need {needed}")
            }
            BlobError::BadMagic { found } => {
                write!(f, "calibration blob: bad magic {found:02x?}, expected \"PCAL\"")
            }
            BlobError::WrongVersion { found, expected } => write!(
                f,
                "calibration blob version {found} not supported (this build reads versions 2 to {expected})"
            ),
            BlobError::CrcMismatch { stored, computed } => write!(
                f,
                "calibration blob corrupt: CRC stored {stored:#010x}, computed {computed:#010x}"
            ),
            BlobError::Malformed => write!(f, "calibration blob payload is not a valid calibration"),
            BlobError::OutOfRange { sensor, what, axis } => {
                let (matrix, offset) = sensor.keys();
                match what {
                    Quantity::MatrixRow => write!(
                        f,
                        "{matrix}: row {axis} of the matrix sums to 4 or more in magnitude, beyond the device's fixed point"
                    ),
                    Quantity::Offset => write!(
                        f,
                        "{offset}[{axis}]: the offset through the matrix is 2¹⁶ LSB or more, beyond the device's fixed point"
                    ),
                    Quantity::TempCoef => write!(
                        f,
                        "gyro.temp_coeff[{axis}]: not a finite number, or 2 LSB per LSB of temperature or more through the matrix, beyond the device's fixed point"
                    ),
                    Quantity::NotFinite => write!(
                        f,
                        "{matrix} or {offset}: a value on axis {axis} is not a finite number"
                    ),
                    Quantity::TempRef => write!(
                        f,
                        "gyro.temp_ref − gyro.temp_offset_c is beyond the ±32767 LSB of the device's raw reference temperature"
                    ),
                }
            }
            BlobError::BufferTooSmall { len } => {
                write!(f, "buffer of {len} bytes too small for a calibration blob")
            }
            BlobError::Implausible(r) => write!(f, "{r}"),
            BlobError::NoRange { key, value } => write!(
                f,
                "{} = {}{} is none of the sensitivities of the part's ranges (see docs/calibration.md, \"Plausibility\")",
                key.name(),
                plausible::Num(f64::from(*value)),
                key.unit()
            ),
            BlobError::NotFitted => write!(
                f,
                "the calibration does not record the parts and ranges it was fitted for"
            ),
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for BlobError {}

/// Fractional bits of the matrix and temperature coefficients (Q8.24).
pub const COEF_FRAC_BITS: u32 = 24;
/// Fractional bits of the folded offsets `c` (Q20.12, output LSB).
pub const OFFSET_FRAC_BITS: u32 = 12;
/// Bound on Σ_j |M_ij| for each row (keeps every intermediate sum inside i32).
pub const MAX_ROW_GAIN: f64 = 4.0;
/// Bound on |c_i| in output LSB.
pub const MAX_OFFSET_LSB: f64 = 65536.0;
/// Bound on |κ_i| in output LSB per temperature LSB.
pub const MAX_TEMP_COEF: f64 = 2.0;

/// `round(x · 2^frac)` without `std` (`f64::round` is not in `core`).
fn to_fixed(x: f64, frac: u32) -> i32 {
    let v = x * (1u64 << frac) as f64;
    let r = if v >= 0.0 { v + 0.5 } else { v - 0.5 };
    r as i32
}

/// `x · m` with `m` in Q8.24 and `x` in i16 range, returned in Q12 (truncated toward −∞ by
/// 2⁻¹² at most). Uses only 32×32→32 multiplies: see the module docs for the overflow bound.
#[inline(always)]
fn mul_q24(x: i32, m: i32) -> (i32, i32) {
    // High part: Q12 product; low part: Q24 product of the low 12 bits (0..4095).
    (x * (m >> 12), x * (m & 0xfff))
}

/// One sensor's affine correction in fixed point: `out = M·raw − c` (module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Affine {
    /// `M` in Q8.24.
    m: [[i32; 3]; 3],
    /// `c = M·o` in Q20.12 output LSB.
    c: [i32; 3],
}

impl Affine {
    /// No correction.
    pub const IDENTITY: Affine = Affine {
        m: [
            [1 << COEF_FRAC_BITS, 0, 0],
            [0, 1 << COEF_FRAC_BITS, 0],
            [0, 0, 1 << COEF_FRAC_BITS],
        ],
        c: [0; 3],
    };

    /// Build from the float correction `out = matrix · (raw − offset)` with `offset` in raw LSB.
    pub fn from_float(
        sensor: Sensor,
        matrix: [[f64; 3]; 3],
        offset: [f64; 3],
    ) -> Result<Affine, BlobError> {
        let mut out = Affine::IDENTITY;
        for i in 0..3 {
            let mut c = 0.0;
            for j in 0..3 {
                if !matrix[i][j].is_finite() || !offset[j].is_finite() {
                    return Err(BlobError::OutOfRange {
                        sensor,
                        what: Quantity::NotFinite,
                        axis: i as u8,
                    });
                }
                out.m[i][j] = to_fixed(matrix[i][j], COEF_FRAC_BITS);
                c += matrix[i][j] * offset[j];
            }
            if c.is_nan() || c.abs() >= MAX_OFFSET_LSB {
                return Err(BlobError::OutOfRange {
                    sensor,
                    what: Quantity::Offset,
                    axis: i as u8,
                });
            }
            out.c[i] = to_fixed(c, OFFSET_FRAC_BITS);
        }
        out.validate(sensor)?;
        Ok(out)
    }

    /// The stored matrix as floats (exact: every Q24 value is a representable f64).
    pub fn matrix(&self) -> [[f64; 3]; 3] {
        let s = 1.0 / (1u64 << COEF_FRAC_BITS) as f64;
        self.m.map(|r| r.map(|v| v as f64 * s))
    }

    /// The stored folded offset `c = M·o` in output LSB (exact).
    pub fn folded_offset(&self) -> [f64; 3] {
        let s = 1.0 / (1u64 << OFFSET_FRAC_BITS) as f64;
        self.c.map(|v| v as f64 * s)
    }

    fn validate(&self, sensor: Sensor) -> Result<(), BlobError> {
        let max_row = (MAX_ROW_GAIN * (1u64 << COEF_FRAC_BITS) as f64) as i64;
        let max_c = (MAX_OFFSET_LSB * (1u64 << OFFSET_FRAC_BITS) as f64) as i64;
        for i in 0..3 {
            let row: i64 = self.m[i].iter().map(|&v| (v as i64).abs()).sum();
            if row >= max_row {
                return Err(BlobError::OutOfRange {
                    sensor,
                    what: Quantity::MatrixRow,
                    axis: i as u8,
                });
            }
            if (self.c[i] as i64).abs() >= max_c {
                return Err(BlobError::OutOfRange {
                    sensor,
                    what: Quantity::Offset,
                    axis: i as u8,
                });
            }
        }
        Ok(())
    }

    /// `M·raw` in Q12 (before the offset), per the split multiply.
    #[inline(always)]
    fn mat_q12(&self, raw: [i16; 3]) -> [i32; 3] {
        let x = [raw[0] as i32, raw[1] as i32, raw[2] as i32];
        let mut out = [0i32; 3];
        for i in 0..3 {
            let (h0, l0) = mul_q24(x[0], self.m[i][0]);
            let (h1, l1) = mul_q24(x[1], self.m[i][1]);
            let (h2, l2) = mul_q24(x[2], self.m[i][2]);
            // |h| ≤ 2^15 · 2^12 · Σ|M| < 2^29; |l0+l1+l2| < 3·2^27.
            out[i] = h0 + h1 + h2 + ((l0 + l1 + l2) >> 12);
        }
        out
    }

    /// Apply to one raw sample: corrected counts (module docs).
    #[inline]
    pub fn apply(&self, raw: [i16; 3]) -> [i32; 3] {
        let q = self.mat_q12(raw);
        [
            round_q12(q[0] - self.c[0]),
            round_q12(q[1] - self.c[1]),
            round_q12(q[2] - self.c[2]),
        ]
    }
}

/// Round a Q12 value to the nearest integer (ties toward +∞).
#[inline(always)]
fn round_q12(v: i32) -> i32 {
    (v + (1 << (OFFSET_FRAC_BITS - 1))) >> OFFSET_FRAC_BITS
}

/// The gyro correction: an [`Affine`] whose offset moves linearly with the die temperature.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct GyroCorrection {
    affine: Affine,
    /// `κ = M·k` in Q8.24 output LSB per temperature LSB.
    kappa: [i32; 3],
    /// Reference temperature in raw temperature LSB.
    t_ref: i16,
}

impl GyroCorrection {
    /// No correction.
    pub const IDENTITY: GyroCorrection = GyroCorrection {
        affine: Affine::IDENTITY,
        kappa: [0; 3],
        t_ref: 0,
    };

    /// Build from `out = matrix · (raw − bias − k·(T_raw − t_ref))`, all in raw LSB
    /// (`k` in gyro LSB per temperature LSB).
    pub fn from_float(
        matrix: [[f64; 3]; 3],
        bias: [f64; 3],
        k: [f64; 3],
        t_ref: i16,
    ) -> Result<GyroCorrection, BlobError> {
        let affine = Affine::from_float(Sensor::Gyro, matrix, bias)?;
        let mut kappa = [0i32; 3];
        for i in 0..3 {
            let mut v = 0.0;
            for j in 0..3 {
                if !k[j].is_finite() {
                    return Err(BlobError::OutOfRange {
                        sensor: Sensor::Gyro,
                        what: Quantity::TempCoef,
                        axis: j as u8,
                    });
                }
                v += matrix[i][j] * k[j];
            }
            if v.is_nan() || v.abs() >= MAX_TEMP_COEF {
                return Err(BlobError::OutOfRange {
                    sensor: Sensor::Gyro,
                    what: Quantity::TempCoef,
                    axis: i as u8,
                });
            }
            kappa[i] = to_fixed(v, COEF_FRAC_BITS);
        }
        let g = GyroCorrection {
            affine,
            kappa,
            t_ref,
        };
        g.validate()?;
        Ok(g)
    }

    /// The underlying affine part.
    pub fn affine(&self) -> &Affine {
        &self.affine
    }

    /// `κ = M·k` as floats (exact), output LSB per temperature LSB.
    pub fn kappa(&self) -> [f64; 3] {
        let s = 1.0 / (1u64 << COEF_FRAC_BITS) as f64;
        self.kappa.map(|v| v as f64 * s)
    }

    /// Reference temperature in raw LSB.
    pub fn t_ref(&self) -> i16 {
        self.t_ref
    }

    fn validate(&self) -> Result<(), BlobError> {
        self.affine.validate(Sensor::Gyro)?;
        let max = (MAX_TEMP_COEF * (1u64 << COEF_FRAC_BITS) as f64) as i64;
        for (i, &k) in self.kappa.iter().enumerate() {
            if (k as i64).abs() >= max {
                return Err(BlobError::OutOfRange {
                    sensor: Sensor::Gyro,
                    what: Quantity::TempCoef,
                    axis: i as u8,
                });
            }
        }
        Ok(())
    }

    /// `T_raw − T_ref`, clamped to the i16 range (±96 °C on the MPU-6050's 340 LSB/°C scale).
    #[inline(always)]
    pub fn delta_t(&self, temp_raw: i16) -> i32 {
        (temp_raw as i32 - self.t_ref as i32).clamp(i16::MIN as i32, i16::MAX as i32)
    }

    /// Apply to one raw sample and the raw die temperature.
    #[inline]
    pub fn apply(&self, raw: [i16; 3], temp_raw: i16) -> [i32; 3] {
        let q = self.affine.mat_q12(raw);
        let dt = self.delta_t(temp_raw);
        let mut out = [0i32; 3];
        for i in 0..3 {
            let (h, l) = mul_q24(dt, self.kappa[i]);
            // |h| < 2^15·2^13, |c| < 2^28, |q| < 2^29: the sum stays below 2^31.
            let t = h + (l >> 12);
            out[i] = round_q12(q[i] - self.affine.c[i] - t);
        }
        out
    }
}

/// Corrections for every sensor, as stored on the device.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Calibration {
    accel: Affine,
    gyro: GyroCorrection,
    mag: Affine,
    /// The parts, ranges and sensitivities the corrections were fitted for; `None` for
    /// identity (which applies at any range; [`decode_blob`] refuses any other correction
    /// without it).
    fitted: Option<Fitted>,
}

impl Default for Calibration {
    fn default() -> Self {
        Calibration::identity()
    }
}

impl Calibration {
    /// Identity corrections: every `apply_*` returns its input.
    pub const fn identity() -> Calibration {
        Calibration {
            accel: Affine::IDENTITY,
            gyro: GyroCorrection::IDENTITY,
            mag: Affine::IDENTITY,
            fitted: None,
        }
    }

    /// Assemble parts that fit the fixed-point path, with what they were fitted for if known,
    /// without the physical check: for tests and tools that build a blob a device must
    /// refuse. [`Calibration::fitted`] is the checked constructor.
    pub fn assemble(
        accel: Affine,
        gyro: GyroCorrection,
        mag: Affine,
        fitted: Option<Fitted>,
    ) -> Result<Calibration, BlobError> {
        let c = Calibration {
            accel,
            gyro,
            mag,
            fitted,
        };
        c.validate()?;
        Ok(c)
    }

    /// Assemble parts that fit the fixed-point path, recording no parts (no physical check:
    /// such a blob is refused by [`decode_blob`] unless it is identity).
    pub fn new(accel: Affine, gyro: GyroCorrection, mag: Affine) -> Result<Calibration, BlobError> {
        Calibration::assemble(accel, gyro, mag, None)
    }

    /// A calibration fitted for `fitted` (parts, ranges, sensitivities), checked against the
    /// datasheet bounds ([`Calibration::check_physics`]).
    pub fn fitted(
        accel: Affine,
        gyro: GyroCorrection,
        mag: Affine,
        fitted: Fitted,
    ) -> Result<Calibration, BlobError> {
        let c = Calibration::assemble(accel, gyro, mag, Some(fitted))?;
        c.check_physics()?;
        Ok(c)
    }

    /// What the corrections were fitted for (see [`Calibration::fitted`]).
    pub fn fitted_for(&self) -> Option<&Fitted> {
        self.fitted.as_ref()
    }

    /// The sensitivities the corrections were fitted for (LSB per m/s², per deg/s, per µT).
    pub fn lsb_per_unit(&self) -> Option<[f32; 3]> {
        self.fitted.map(|f| f.lsb_per_unit)
    }

    /// Whether the corrections were fitted for sensitivities within 1 % of `lsb_per_unit`
    /// (the device's ranges); identity fits any.
    pub fn fits_ranges(&self, lsb_per_unit: [f32; 3]) -> bool {
        self.lsb_per_unit().is_none_or(|have| {
            have.iter()
                .zip(lsb_per_unit)
                .all(|(h, l)| (h / l - 1.0).abs() <= 0.01)
        })
    }

    /// Whether every correction is identity.
    pub fn is_identity(&self) -> bool {
        self.accel == Affine::IDENTITY
            && self.gyro == GyroCorrection::IDENTITY
            && self.mag == Affine::IDENTITY
    }

    /// The datasheet bounds ([`plausible::check`]) on the parameters recovered from the
    /// fixed-point corrections ([`plausible::Physical::of`]); identity passes, any other
    /// correction must record what it was fitted for ([`BlobError::NotFitted`]).
    pub fn check_physics(&self) -> Result<(), BlobError> {
        match &self.fitted {
            None if self.is_identity() => Ok(()),
            None => Err(BlobError::NotFitted),
            Some(f) => plausible::check(&plausible::Physical::of(self, f), f)
                .map_err(BlobError::Implausible),
        }
    }

    /// Check every coefficient against the fixed-point ranges (module docs).
    pub fn validate(&self) -> Result<(), BlobError> {
        self.accel.validate(Sensor::Accel)?;
        self.gyro.validate()?;
        self.mag.validate(Sensor::Mag)
    }

    /// The accelerometer part.
    pub fn accel(&self) -> &Affine {
        &self.accel
    }
    /// The gyroscope part.
    pub fn gyro(&self) -> &GyroCorrection {
        &self.gyro
    }
    /// The magnetometer part.
    pub fn mag(&self) -> &Affine {
        &self.mag
    }

    /// Corrected accelerometer sample, in nominal accelerometer LSB (module docs).
    #[inline]
    pub fn apply_accel(&self, raw: [i16; 3]) -> [i32; 3] {
        self.accel.apply(raw)
    }

    /// Corrected gyroscope sample, in nominal gyro LSB, given the raw die temperature
    /// (MPU-6050 register TEMP_OUT, 340 LSB/°C, 0 LSB = 36.53 °C).
    #[inline]
    pub fn apply_gyro(&self, raw: [i16; 3], temp_raw: i16) -> [i32; 3] {
        self.gyro.apply(raw, temp_raw)
    }

    /// Corrected magnetometer sample, in nominal magnetometer LSB.
    #[inline]
    pub fn apply_mag(&self, raw: [i16; 3]) -> [i32; 3] {
        self.mag.apply(raw)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn identity_is_identity_on_extremes() {
        let c = Calibration::identity();
        for v in [i16::MIN, -1, 0, 1, i16::MAX] {
            assert_eq!(c.apply_accel([v, v, v]), [v as i32; 3]);
            assert_eq!(c.apply_gyro([v, v, v], v), [v as i32; 3]);
            assert_eq!(c.apply_mag([v, 0, v]), [v as i32, 0, v as i32]);
        }
    }

    #[test]
    fn split_multiply_matches_wide_product() {
        // The Q12 result of mul_q24 equals floor(x·m / 2^12) up to the dropped low bits.
        for &m in &[
            1 << 24,
            -(1 << 24) + 12345,
            (1 << 26) - 1,
            -(1 << 26) + 1,
            4095,
            -1,
        ] {
            for &x in &[-32768i32, -1, 0, 1, 32767, 12345] {
                let (h, l) = mul_q24(x, m);
                let got = h as i64 + ((l >> 12) as i64);
                let exact = (x as i64 * m as i64) >> 12;
                assert!(
                    (got - exact).abs() <= 1,
                    "x={x} m={m} got={got} exact={exact}"
                );
            }
        }
    }
}
