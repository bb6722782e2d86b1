//! The human-editable calibration file (TOML) and its conversion to the device blob.
//!
//! Parameters are in the CSV contract's physical units; each section also says how many raw
//! LSB make one unit at the device's configured range, which is what turns the physical
//! correction into the raw-count correction of [`crate::device`]:
//! if `raw = s·a` (s in LSB per unit) and `a_cal = M·(a − o)`, the device output in nominal
//! LSB is `s·a_cal = M·(raw − s·o)`. Defaults are the configuration of Jaime et al. (MPU-6050 ±4 g and
//! ±250 °/s, QMC5883 ±2 G).
//!
//! ```toml
//! version = 1
//! [accel]                  # a_cal = T·K·(a − offset)
//! part = "MPU-6050"        # the part whose datasheet bounds apply (optional, this default)
//! lsb_per_unit = 835.3     # LSB per m/s² (8192 LSB/g at ±4 g)
//! offset = [0.0, 0.0, 0.0] # m/s²
//! scale = [1.0, 1.0, 1.0]
//! misalignment_deg = [0.0, 0.0, 0.0]
//! [gyro]                   # ω_cal = T_g·K_g·(ω − bias − temp_coeff·(T − temp_ref))
//! part = "MPU-6050"        # optional; must be the accelerometer's
//! lsb_per_unit = 131.0     # LSB per deg/s (±250 °/s)
//! bias = [0.0, 0.0, 0.0]   # deg/s
//! temp_coeff = [0.0, 0.0, 0.0]  # deg/s per °C
//! temp_ref = 25.0          # °C
//! temp_lsb_per_c = 340.0   # MPU-6050: T = raw/340 + 36.53 °C
//! temp_offset_c = 36.53
//! scale = [1.0, 1.0, 1.0]  # optional (gyro_rot)
//! misalignment_deg = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0]  # optional (gyro_rot)
//! [mag]                    # m_cal = soft_iron·(m − hard_iron)
//! part = "QMC5883L"        # optional, this default; or "HMC5883L" (GN = 1: 10.9 LSB per µT)
//! lsb_per_unit = 120.0     # LSB per µT (QMC5883 ±2 G: 12000 LSB/G)
//! hard_iron = [0.0, 0.0, 0.0]   # µT
//! soft_iron = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
//! ```
//!
//! Every `lsb_per_unit` must be the part's nominal sensitivity at one of its ranges (within
//! 1 %), which is how the blob records the ranges, and every parameter must lie within its
//! datasheet bound ([`crate::device::plausible`]); a file without `part` keys (written before
//! they existed) is read as MPU-6050 + QMC5883L, the parts the firmware drives.
use crate::accel::correction_matrix;
use crate::device::plausible::{self, Physical};
use crate::device::{
    Affine, BlobError, Calibration, Fitted, GyroCorrection, ImuPart, Key, MagPart, Sensor,
};
use crate::lab::{CalError, Params};
use serde::{Deserialize, Serialize};

/// The calibration file format version.
pub const FILE_VERSION: u32 = 1;

/// Accelerometer section.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AccelSection {
    /// The part (`"MPU-6050"`); absent in files written before it existed: the default.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub part: Option<ImuPart>,
    /// Raw LSB per m/s².
    pub lsb_per_unit: f64,
    /// m/s².
    pub offset: [f64; 3],
    /// Dimensionless.
    pub scale: [f64; 3],
    /// Degrees (lower-triangular T; see `accel`).
    pub misalignment_deg: [f64; 3],
}

/// Gyroscope section.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GyroSection {
    /// The part (`"MPU-6050"`, the accelerometer's); absent: the accelerometer's or the default.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub part: Option<ImuPart>,
    /// Raw LSB per deg/s.
    pub lsb_per_unit: f64,
    /// deg/s at `temp_ref`.
    pub bias: [f64; 3],
    /// deg/s per °C.
    pub temp_coeff: [f64; 3],
    /// °C.
    pub temp_ref: f64,
    /// Temperature sensor LSB per °C.
    pub temp_lsb_per_c: f64,
    /// Temperature at raw 0 (°C).
    pub temp_offset_c: f64,
    /// Gyro scale factors (dimensionless; `gyro_rot`), 1 when absent.
    #[serde(default = "unit_scale")]
    pub scale: [f64; 3],
    /// Gyro non-orthogonality γ₁…γ₆ (deg; `gyro_rot`), 0 when absent.
    #[serde(default)]
    pub misalignment_deg: [f64; 6],
}

fn unit_scale() -> [f64; 3] {
    [1.0; 3]
}

/// Magnetometer section.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MagSection {
    /// The part (`"QMC5883L"` or `"HMC5883L"`); absent: the firmware's, the QMC5883L.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub part: Option<MagPart>,
    /// Raw LSB per µT.
    pub lsb_per_unit: f64,
    /// µT.
    pub hard_iron: [f64; 3],
    /// Dimensionless, applied after the hard iron.
    pub soft_iron: [[f64; 3]; 3],
}

/// The whole file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CalFile {
    /// Must be [`FILE_VERSION`].
    pub version: u32,
    /// Accelerometer.
    pub accel: AccelSection,
    /// Gyroscope.
    pub gyro: GyroSection,
    /// Magnetometer.
    pub mag: MagSection,
}

impl Default for CalFile {
    fn default() -> Self {
        CalFile {
            version: FILE_VERSION,
            accel: AccelSection {
                part: Some(ImuPart::Mpu6050),
                lsb_per_unit: 8192.0 / crate::accel::G_STANDARD,
                offset: [0.0; 3],
                scale: [1.0; 3],
                misalignment_deg: [0.0; 3],
            },
            gyro: GyroSection {
                part: Some(ImuPart::Mpu6050),
                lsb_per_unit: 131.0,
                bias: [0.0; 3],
                temp_coeff: [0.0; 3],
                temp_ref: 25.0,
                temp_lsb_per_c: 340.0,
                temp_offset_c: 36.53,
                scale: [1.0; 3],
                misalignment_deg: [0.0; 6],
            },
            mag: MagSection {
                part: Some(MagPart::Qmc5883l),
                lsb_per_unit: 120.0,
                hard_iron: [0.0; 3],
                soft_iron: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            },
        }
    }
}

impl CalFile {
    /// Parse a TOML calibration file; errors name the field and line.
    pub fn from_toml(text: &str) -> Result<CalFile, CalError> {
        let f: CalFile =
            toml::from_str(text).map_err(|e| CalError::Input(format!("calibration file: {e}")))?;
        if f.version != FILE_VERSION {
            return Err(CalError::Input(format!(
                "calibration file version {} not supported (expected {FILE_VERSION})",
                f.version
            )));
        }
        Ok(f)
    }

    /// Write as TOML.
    pub fn to_toml(&self) -> String {
        let body = toml::to_string(self).unwrap_or_else(|e| format!("# error: {e}\n"));
        format!(
            "# pico-imu calibration file (units: m/s², deg/s, µT, °C; see docs/calibration.md)\n{body}"
        )
    }

    /// Put the fitted parameters of one sensor into the file (effects absent from the fit are
    /// reset to identity, so the file always describes exactly the last fitted model).
    /// `"gyro"` sets bias and temperature; `"gyro-rot"` sets the gyro scale and misalignment.
    pub fn set(&mut self, sensor: &str, p: &Params) -> Result<(), CalError> {
        // A file without parts (older than them) names the ones it is read as from now on.
        let (imu, mag) = self.parts();
        self.accel.part = Some(imu);
        self.gyro.part = Some(imu);
        self.mag.part = Some(mag);
        match sensor {
            "accel" => {
                self.accel.offset = p.offset.unwrap_or([0.0; 3]);
                self.accel.scale = p.scale.unwrap_or([1.0; 3]);
                self.accel.misalignment_deg = p.misalignment_deg.unwrap_or([0.0; 3]);
            }
            "gyro" => {
                self.gyro.bias = p.bias.unwrap_or([0.0; 3]);
                self.gyro.temp_coeff = p.temp_coeff.unwrap_or([0.0; 3]);
                if let Some(t) = p.temp_ref {
                    self.gyro.temp_ref = t;
                }
            }
            "gyro-rot" => {
                self.gyro.scale = p.scale.unwrap_or([1.0; 3]);
                self.gyro.misalignment_deg = p.gyro_misalignment_deg.unwrap_or([0.0; 6]);
            }
            "mag" => {
                self.mag.hard_iron = p.hard_iron.unwrap_or([0.0; 3]);
                self.mag.soft_iron =
                    p.soft_iron
                        .unwrap_or([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]);
            }
            other => return Err(CalError::Input(format!("unknown sensor '{other}'"))),
        }
        Ok(())
    }

    /// Name the magnetometer part; a sensitivity that is none of its ranges' becomes the one
    /// of its power-on range ([`MagPart::default_lsb_per_ut`]). One that is not a number stays,
    /// for [`CalFile::to_device`] to refuse by name.
    pub fn set_mag_part(&mut self, part: MagPart) {
        self.mag.part = Some(part);
        let l = self.mag.lsb_per_unit * 100.0;
        if l.is_finite()
            && !part
                .ranges()
                .iter()
                .any(|(_, nominal)| (l / nominal - 1.0).abs() <= plausible::LSB_MATCH)
        {
            self.mag.lsb_per_unit = part.default_lsb_per_ut();
        }
    }

    /// The parts the file is for: its `part` keys, or the defaults (MPU-6050, QMC5883L) where
    /// absent; the gyro's is the accelerometer's (one die).
    pub fn parts(&self) -> (ImuPart, MagPart) {
        (
            self.accel
                .part
                .or(self.gyro.part)
                .unwrap_or(ImuPart::Mpu6050),
            self.mag.part.unwrap_or(MagPart::Qmc5883l),
        )
    }

    /// The file's parameters as the plausibility check takes them.
    pub fn physical(&self) -> Physical {
        Physical {
            accel_scale: self.accel.scale,
            accel_offset: self.accel.offset,
            accel_misalignment_deg: self.accel.misalignment_deg,
            accel_upper: [0.0; 3],
            gyro_scale: self.gyro.scale,
            gyro_bias: self.gyro.bias,
            gyro_temp_coeff: self.gyro.temp_coeff,
            gyro_misalignment_deg: self.gyro.misalignment_deg,
            gyro_temp_c: Some(plausible::TempScale {
                reference: self.gyro.temp_ref,
                offset: self.gyro.temp_offset_c,
            }),
            soft_iron: self.mag.soft_iron,
            hard_iron: self.mag.hard_iron,
        }
    }

    /// Convert to the device's fixed-point corrections (module docs). Checks, in order: the
    /// sensitivities against the parts' ranges ([`BlobError::NoRange`]), the file's own
    /// parameters against the datasheet bounds ([`BlobError::Implausible`], naming the key,
    /// axis, value and bound), the fixed-point ranges, and the bounds again on what the
    /// device will hold (as the device does).
    pub fn to_device(&self) -> Result<Calibration, BlobError> {
        self.convert(true)
    }

    /// The blob the device stores (`device::encode_blob`) for this file, after every check of
    /// [`CalFile::to_device`]: what `imu-lab device calibrate --upload` and `pico_imu`'s
    /// `Device.upload` send.
    pub fn to_blob(&self) -> Result<Vec<u8>, BlobError> {
        let cal = self.to_device()?;
        let mut buf = [0u8; crate::device::MAX_BLOB_LEN];
        Ok(crate::device::encode_blob(&cal, &mut buf)?.to_vec())
    }

    /// [`CalFile::to_device`] without the datasheet bounds (the sensitivities and the
    /// fixed-point ranges are still checked): for tests and tools that need a blob the device
    /// must refuse.
    pub fn to_device_unchecked(&self) -> Result<Calibration, BlobError> {
        self.convert(false)
    }

    fn convert(&self, check: bool) -> Result<Calibration, BlobError> {
        let (imu, mag_part) = self.parts();
        let lsb = [
            (self.accel.lsb_per_unit, Key::AccelLsbPerUnit),
            (self.gyro.lsb_per_unit, Key::GyroLsbPerUnit),
            (self.mag.lsb_per_unit, Key::MagLsbPerUnit),
        ];
        for (l, key) in lsb {
            if !(l.is_finite() && l > 0.0 && l < f32::MAX as f64) {
                return Err(BlobError::NoRange {
                    key,
                    value: l as f32,
                });
            }
        }
        let fitted = Fitted::new(imu, mag_part, lsb.map(|(l, _)| l as f32))?;
        let t = self.gyro.temp_lsb_per_c;
        if !((t / imu.temp_lsb_per_c() - 1.0).abs() <= plausible::LSB_MATCH) {
            return Err(BlobError::NoRange {
                key: Key::GyroTempLsbPerC,
                value: t as f32,
            });
        }
        if check {
            plausible::check(&self.physical(), &fitted).map_err(BlobError::Implausible)?;
        }
        let a = &self.accel;
        let ap = Params {
            scale: Some(a.scale),
            misalignment_deg: Some(a.misalignment_deg),
            ..Params::default()
        };
        let m = correction_matrix(&ap);
        let am = [
            [m[(0, 0)], m[(0, 1)], m[(0, 2)]],
            [m[(1, 0)], m[(1, 1)], m[(1, 2)]],
            [m[(2, 0)], m[(2, 1)], m[(2, 2)]],
        ];
        let accel = Affine::from_float(Sensor::Accel, am, a.offset.map(|o| o * a.lsb_per_unit))?;
        let g = &self.gyro;
        let t_ref_raw = ((g.temp_ref - g.temp_offset_c) * g.temp_lsb_per_c).round();
        if !(t_ref_raw.abs() <= i16::MAX as f64) {
            return Err(BlobError::OutOfRange {
                sensor: Sensor::Gyro,
                what: crate::device::Quantity::TempRef,
                axis: 0,
            });
        }
        let gm = crate::gyro_rot::correction_matrix(g.scale, g.misalignment_deg);
        let gyro = GyroCorrection::from_float(
            gm,
            g.bias.map(|b| b * g.lsb_per_unit),
            g.temp_coeff.map(|k| k * g.lsb_per_unit / g.temp_lsb_per_c),
            t_ref_raw as i16,
        )?;
        let mg = &self.mag;
        let mag = Affine::from_float(
            Sensor::Mag,
            mg.soft_iron,
            mg.hard_iron.map(|h| h * mg.lsb_per_unit),
        )?;
        if check {
            Calibration::fitted(accel, gyro, mag, fitted)
        } else {
            Calibration::assemble(accel, gyro, mag, Some(fitted))
        }
    }
}
/// The blob to send for a calibration file's `content`: a blob file (`is_blob`, e.g. `.bin`,
/// as `imu-lab device calibrate --download --out` writes) decoded and checked as the device
/// will, or a TOML calibration file converted and checked ([`CalFile::to_blob`]: the datasheet
/// bounds on the file's own numbers, named by key, index, value and bound). `Err` says why it
/// is refused; then nothing is to be sent. `imu-lab device calibrate --upload` and `pico_imu`'s
/// `Device.upload` both call this.
pub fn upload_blob(content: &[u8], is_blob: bool) -> Result<Vec<u8>, String> {
    if is_blob {
        crate::device::decode_blob(content)
            .map_err(|e| format!("refused, nothing uploaded: {e}"))?;
        return Ok(content.to_vec());
    }
    let text = std::str::from_utf8(content)
        .map_err(|e| format!("not a TOML calibration file (not UTF-8 text: {e})"))?;
    let file = CalFile::from_toml(text).map_err(|e| e.to_string())?;
    file.to_blob()
        .map_err(|e| format!("refused, nothing uploaded: {e}"))
}
