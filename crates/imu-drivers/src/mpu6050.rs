//! MPU-6050 register layer: addresses, typed configuration, chip identification, decoding and
//! unit conversion. Everything here is pure (no I/O); the blocking and async drivers in
//! [`crate::blocking`] and [`crate::asynch`] execute the same sequences on a bus.
//!
//! References (InvenSense documents, cited by section throughout):
//! - "MPU-6000 and MPU-6050 Register Map and Descriptions", RM-MPU-6000A-00 rev 4.2 (RM).
//! - "MPU-6000 and MPU-6050 Product Specification", PS-MPU-6000A-00 rev 3.4 (PS).
//! - "MPU-6500 Register Map and Descriptions", RM-MPU-6500A-00 rev 2.1 (RM-6500), for clones.

pub mod reg;
pub mod registers;

/// Delay after DEVICE_RESET before the registers are written again, in ms. PS 6.3 gives a
/// 100 ms start-up time for register read/write; RM 4.28 notes the reset bit self-clears.
pub const RESET_DELAY_MS: u32 = 100;
/// Settling time after switching self-test on or off, in ms (PS 6.1 lists a 50 ms gyro
/// start-up; with the 5 Hz DLPF the 19 ms filter delay needs several time constants too).
pub const SELF_TEST_SETTLE_MS: u32 = 250;
/// Samples averaged for each self-test phase.
pub const SELF_TEST_SAMPLES: u32 = 16;

/// Standard gravity in m/s² (CGPM 1901), the "g" of the accelerometer full-scale ranges.
pub const STANDARD_GRAVITY: f32 = 9.806_65;

/// I²C address, selected by the AD0 pin (PS 9.2).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Address {
    /// AD0 low: 0x68.
    #[default]
    Ad0Low,
    /// AD0 high: 0x69.
    Ad0High,
}

impl Address {
    /// The 7-bit address.
    pub const fn addr(self) -> u8 {
        match self {
            Address::Ad0Low => 0x68,
            Address::Ad0High => 0x69,
        }
    }
}

/// Register-compatible family of the chip found; decides the clone differences the driver
/// has to honour (temperature formula, FIFO size, separate accelerometer DLPF, self-test).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Family {
    /// MPU-6050/MPU-6000 register map (RM).
    Mpu6050,
    /// MPU-6500/MPU-9250 register map (RM-6500): ACCEL_CONFIG2, 512-byte FIFO, other temperature scale.
    Mpu6500,
    /// Later InvenSense/TDK parts on the 6500 map with a 326.8 LSB/°C, 25 °C temperature sensor.
    Icm,
}

/// Chip identified by WHO_AM_I (RM 4.32 and the clone data sheets).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ChipId {
    /// Genuine MPU-6050 / MPU-6000: 0x68.
    Mpu6050,
    /// MPU-6500 (sold on many "GY-521 MPU-6050" boards): 0x70.
    Mpu6500,
    /// MPU-9250 (its accel/gyro die is an MPU-6500): 0x71.
    Mpu9250,
    /// Unbranded MPU-9250/6500 variant seen on cheap boards: 0x72.
    Mpu92xxVariant,
    /// MPU-9255: 0x73.
    Mpu9255,
    /// MPU-6515: 0x74.
    Mpu6515,
    /// ICM-20689 (also on boards sold as MPU-6050): 0x98.
    Icm20689,
    /// MPU-6886: 0x19.
    Mpu6886,
    /// ICM-20602: 0x12.
    Icm20602,
    /// ICM-20608-G: 0xAF.
    Icm20608,
}

impl ChipId {
    /// Identify a WHO_AM_I value; `None` for anything not register-compatible.
    pub const fn from_who_am_i(value: u8) -> Option<ChipId> {
        Some(match value {
            0x68 => ChipId::Mpu6050,
            0x70 => ChipId::Mpu6500,
            0x71 => ChipId::Mpu9250,
            0x72 => ChipId::Mpu92xxVariant,
            0x73 => ChipId::Mpu9255,
            0x74 => ChipId::Mpu6515,
            0x98 => ChipId::Icm20689,
            0x19 => ChipId::Mpu6886,
            0x12 => ChipId::Icm20602,
            0xAF => ChipId::Icm20608,
            _ => return None,
        })
    }

    /// The WHO_AM_I value of this chip.
    pub const fn who_am_i(self) -> u8 {
        match self {
            ChipId::Mpu6050 => 0x68,
            ChipId::Mpu6500 => 0x70,
            ChipId::Mpu9250 => 0x71,
            ChipId::Mpu92xxVariant => 0x72,
            ChipId::Mpu9255 => 0x73,
            ChipId::Mpu6515 => 0x74,
            ChipId::Icm20689 => 0x98,
            ChipId::Mpu6886 => 0x19,
            ChipId::Icm20602 => 0x12,
            ChipId::Icm20608 => 0xAF,
        }
    }

    /// Register family.
    pub const fn family(self) -> Family {
        match self {
            ChipId::Mpu6050 => Family::Mpu6050,
            ChipId::Mpu6500
            | ChipId::Mpu9250
            | ChipId::Mpu92xxVariant
            | ChipId::Mpu9255
            | ChipId::Mpu6515 => Family::Mpu6500,
            ChipId::Icm20689 | ChipId::Mpu6886 | ChipId::Icm20602 | ChipId::Icm20608 => Family::Icm,
        }
    }

    /// FIFO size in bytes: 1024 (RM 4.30) for the MPU-6050, 512 for the MPU-6500 family
    /// (the 512-byte FIFO of the MPU-6500 product specification), 1024 for the ICM parts (their 4 KB variants are
    /// not relied on).
    pub const fn fifo_capacity(self) -> u16 {
        match self.family() {
            Family::Mpu6050 => 1024,
            Family::Mpu6500 => 512,
            Family::Icm => 1024,
        }
    }

    /// Temperature conversion of this chip.
    pub const fn temperature_scale(self) -> TemperatureScale {
        match self.family() {
            // RM 4.18: Temperature in degrees C = (TEMP_OUT Register Value as a signed quantity)/340 + 36.53
            Family::Mpu6050 => TemperatureScale {
                lsb_per_c: 340.0,
                offset_c: 36.53,
            },
            // RM-6500 registers 65-66 (TEMP_OUT): TEMP_degC = TEMP_OUT/Temp_Sensitivity + 21, sensitivity 333.87 LSB/°C (MPU-6500 product specification, temperature sensor table).
            Family::Mpu6500 => TemperatureScale {
                lsb_per_c: 333.87,
                offset_c: 21.0,
            },
            // ICM-20689 / MPU-6886 data sheets: 326.8 LSB/°C, 25 °C at 0 LSB.
            Family::Icm => TemperatureScale {
                lsb_per_c: 326.8,
                offset_c: 25.0,
            },
        }
    }
}

/// Gyroscope full-scale range, GYRO_CONFIG.FS_SEL (RM 4.4).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum GyroRange {
    /// ±250 °/s, 131 LSB/(°/s).
    #[default]
    Dps250 = 0,
    /// ±500 °/s, 65.5 LSB/(°/s).
    Dps500 = 1,
    /// ±1000 °/s, 32.8 LSB/(°/s).
    Dps1000 = 2,
    /// ±2000 °/s, 16.4 LSB/(°/s).
    Dps2000 = 3,
}

impl GyroRange {
    /// Sensitivity in LSB per °/s (PS 6.1, "Sensitivity Scale Factor").
    pub const fn lsb_per_dps(self) -> f32 {
        match self {
            GyroRange::Dps250 => 131.0,
            GyroRange::Dps500 => 65.5,
            GyroRange::Dps1000 => 32.8,
            GyroRange::Dps2000 => 16.4,
        }
    }
}

/// Accelerometer full-scale range, ACCEL_CONFIG.AFS_SEL (RM 4.5).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum AccelRange {
    /// ±2 g, 16384 LSB/g.
    G2 = 0,
    /// ±4 g, 8192 LSB/g.
    #[default]
    G4 = 1,
    /// ±8 g, 4096 LSB/g.
    G8 = 2,
    /// ±16 g, 2048 LSB/g.
    G16 = 3,
}

impl AccelRange {
    /// Sensitivity in LSB per g (PS 6.2).
    pub const fn lsb_per_g(self) -> f32 {
        match self {
            AccelRange::G2 => 16384.0,
            AccelRange::G4 => 8192.0,
            AccelRange::G8 => 4096.0,
            AccelRange::G16 => 2048.0,
        }
    }
}

/// Digital low-pass filter, CONFIG.DLPF_CFG (RM 4.3 table). Bandwidths are accel / gyro.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Dlpf {
    /// 260 Hz / 256 Hz, gyro output rate 8 kHz.
    Hz260 = 0,
    /// 184 Hz / 188 Hz.
    Hz184 = 1,
    /// 94 Hz / 98 Hz.
    Hz94 = 2,
    /// 44 Hz / 42 Hz.
    Hz44 = 3,
    /// 21 Hz / 20 Hz.
    Hz21 = 4,
    /// 10 Hz / 10 Hz.
    Hz10 = 5,
    /// 5 Hz / 5 Hz (delay 19.0 / 18.6 ms): the configuration Jaime et al. use
    /// ("Caracterización y calibración de unidades de medición inercial de bajo costo").
    #[default]
    Hz5 = 6,
}

impl Dlpf {
    /// Gyroscope output rate in Hz that SMPLRT_DIV divides (RM 4.2: 8 kHz when DLPF_CFG = 0 or 7,
    /// otherwise 1 kHz).
    pub const fn gyro_output_rate_hz(self) -> u32 {
        match self {
            Dlpf::Hz260 => 8000,
            _ => 1000,
        }
    }
    /// MPU-6500 family ACCEL_CONFIG2 with the nearest bandwidth (RM-6500 register 29 ACCEL_CONFIG 2, A_DLPF_CFG table:
    /// 0 = 218 Hz, 1 = 218 Hz, 2 = 99 Hz, 3 = 44.8 Hz, 4 = 21.2 Hz, 5 = 10.2 Hz, 6 = 5.05 Hz);
    /// ACCEL_FCHOICE_B = 0 so the filter is in use.
    pub const fn accel_config2(self) -> registers::AccelConfig2 {
        registers::AccelConfig2 {
            accel_fchoice_b: false,
            a_dlpf_cfg: self as u8,
        }
    }
}

/// Which measurements each FIFO frame holds (RM 4.6; order in the FIFO is by register
/// address: accel, temperature, gyro — RM 4.31).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum FifoFrame {
    /// 12-byte frames: accel X/Y/Z, gyro X/Y/Z.
    #[default]
    AccelGyro,
    /// 14-byte frames: accel X/Y/Z, temperature, gyro X/Y/Z.
    AccelTempGyro,
}

impl FifoFrame {
    /// Bytes per frame.
    pub const fn bytes(self) -> usize {
        match self {
            FifoFrame::AccelGyro => 12,
            FifoFrame::AccelTempGyro => 14,
        }
    }
    /// FIFO_EN for frames of this layout.
    pub const fn fifo_en(self) -> registers::FifoEn {
        registers::FifoEn {
            temp: matches!(self, FifoFrame::AccelTempGyro),
            xg: true,
            yg: true,
            zg: true,
            accel: true,
            slv2: false,
            slv1: false,
            slv0: false,
        }
    }
}

/// Interrupt pin configuration (RM 4.14, 4.15).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct InterruptConfig {
    /// Raise INT when a sample is ready (DATA_RDY_EN).
    pub data_ready: bool,
    /// Raise INT on FIFO overflow (FIFO_OFLOW_EN).
    pub fifo_overflow: bool,
    /// INT active low instead of high.
    pub active_low: bool,
    /// INT open drain instead of push-pull.
    pub open_drain: bool,
    /// Hold INT until the status is cleared instead of a 50 µs pulse.
    pub latch: bool,
    /// Clear the status by any read instead of only by reading INT_STATUS.
    pub clear_on_any_read: bool,
}

impl Default for InterruptConfig {
    /// Data-ready on a 50 µs active-high push-pull pulse, cleared by reading INT_STATUS.
    fn default() -> Self {
        InterruptConfig {
            data_ready: true,
            fifo_overflow: false,
            active_low: false,
            open_drain: false,
            latch: false,
            clear_on_any_read: false,
        }
    }
}

impl InterruptConfig {
    /// INT_PIN_CFG.
    pub const fn pin_cfg(&self) -> registers::IntPinCfg {
        registers::IntPinCfg {
            active_low: self.active_low,
            open_drain: self.open_drain,
            latch: self.latch,
            clear_on_any_read: self.clear_on_any_read,
            fsync_active_low: false,
            fsync_int: false,
            i2c_bypass: false,
        }
    }
    /// INT_ENABLE.
    pub const fn enable(&self) -> registers::IntEnable {
        registers::IntEnable {
            fifo_overflow: self.fifo_overflow,
            i2c_master: false,
            data_ready: self.data_ready,
        }
    }
}

/// MPU-6050 configuration. [`Config::default`] is the configuration of Jaime et al.: ±250 °/s, ±4 g,
/// DLPF_CFG 6 (5 Hz), SMPLRT_DIV 0 → 1 kHz, FIFO with accel + gyro, data-ready interrupt.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Config {
    /// Gyroscope range.
    pub gyro_range: GyroRange,
    /// Accelerometer range.
    pub accel_range: AccelRange,
    /// Low-pass filter.
    pub dlpf: Dlpf,
    /// Sample rate = gyro output rate / (1 + divider) (RM 4.2).
    pub sample_rate_divider: u8,
    /// FIFO contents, or `None` to leave the FIFO off.
    pub fifo: Option<FifoFrame>,
    /// Interrupt pin.
    pub interrupt: InterruptConfig,
}

impl Default for Config {
    fn default() -> Self {
        Config {
            gyro_range: GyroRange::Dps250,
            accel_range: AccelRange::G4,
            dlpf: Dlpf::Hz5,
            sample_rate_divider: 0,
            fifo: Some(FifoFrame::AccelGyro),
            interrupt: InterruptConfig::default(),
        }
    }
}

impl Config {
    /// Sample rate in Hz (RM 4.2: Sample Rate = Gyroscope Output Rate / (1 + SMPLRT_DIV)).
    pub fn sample_rate_hz(&self) -> f32 {
        self.dlpf.gyro_output_rate_hz() as f32 / (1.0 + self.sample_rate_divider as f32)
    }

    /// The burst written from SMPLRT_DIV (0x19) upward: SMPLRT_DIV, CONFIG, GYRO_CONFIG,
    /// ACCEL_CONFIG and, on the 6500 family, ACCEL_CONFIG2. Returns the buffer (register
    /// address first) and its used length.
    pub fn config_burst(&self, chip: ChipId) -> ([u8; 6], usize) {
        let mut b = [
            reg::SMPLRT_DIV,
            self.smplrt_div().bits(),
            self.config_reg().bits(),
            GyroConfig::range(self.gyro_range).bits(),
            AccelConfig::range(self.accel_range).bits(),
            self.dlpf.accel_config2().bits(),
        ];
        let len = match chip.family() {
            Family::Mpu6050 => 5,
            Family::Mpu6500 | Family::Icm => 6,
        };
        if len == 5 {
            b[5] = 0;
        }
        (b, len)
    }

    /// SMPLRT_DIV.
    pub const fn smplrt_div(&self) -> registers::SmplrtDiv {
        registers::SmplrtDiv {
            divider: self.sample_rate_divider,
        }
    }

    /// CONFIG: the low-pass filter, FSYNC off.
    pub const fn config_reg(&self) -> registers::ConfigReg {
        registers::ConfigReg {
            ext_sync_set: 0,
            dlpf_cfg: self.dlpf as u8,
        }
    }

    /// INT_ENABLE: the interrupt configuration, plus FIFO_OFLOW_EN whenever the FIFO is on, so
    /// that INT_STATUS.FIFO_OFLOW_INT reports an overflow (RM 4.15/4.16).
    pub const fn int_enable(&self) -> registers::IntEnable {
        let mut e = self.interrupt.enable();
        e.fifo_overflow |= self.fifo.is_some();
        e
    }

    /// Conversion factors for this configuration on `chip`.
    pub const fn scale(&self, chip: ChipId) -> Scale {
        Scale {
            accel_lsb_per_g: self.accel_range.lsb_per_g(),
            gyro_lsb_per_dps: self.gyro_range.lsb_per_dps(),
            temperature: chip.temperature_scale(),
        }
    }
}

/// Temperature sensor transfer function: °C = raw / `lsb_per_c` + `offset_c`.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct TemperatureScale {
    /// Sensitivity in LSB/°C.
    pub lsb_per_c: f32,
    /// Temperature at raw 0, in °C.
    pub offset_c: f32,
}

/// Raw counts to physical units.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Scale {
    /// Accelerometer sensitivity, LSB/g.
    pub accel_lsb_per_g: f32,
    /// Gyroscope sensitivity, LSB/(°/s).
    pub gyro_lsb_per_dps: f32,
    /// Temperature sensor transfer function.
    pub temperature: TemperatureScale,
}

impl Scale {
    /// Acceleration in m/s²: raw / (LSB/g) × g₀.
    pub fn accel_ms2(&self, raw: [i16; 3]) -> [f32; 3] {
        raw.map(|r| r as f32 / self.accel_lsb_per_g * STANDARD_GRAVITY)
    }
    /// Angular rate in °/s: raw / (LSB/(°/s)).
    pub fn gyro_dps(&self, raw: [i16; 3]) -> [f32; 3] {
        raw.map(|r| r as f32 / self.gyro_lsb_per_dps)
    }
    /// Temperature in °C (RM 4.18 for the MPU-6050; see [`ChipId::temperature_scale`]).
    pub fn temperature_c(&self, raw: i16) -> f32 {
        raw as f32 / self.temperature.lsb_per_c + self.temperature.offset_c
    }
    /// Convert a whole sample.
    pub fn convert(&self, s: &RawSample) -> Sample {
        Sample {
            accel_ms2: self.accel_ms2(s.accel),
            gyro_dps: self.gyro_dps(s.gyro),
            temperature_c: s.temp.map(|t| self.temperature_c(t)),
        }
    }
}

/// One sample in raw counts, all axes from the same sampling instant.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct RawSample {
    /// Accelerometer X, Y, Z.
    pub accel: [i16; 3],
    /// Temperature; `None` for FIFO frames that do not carry it.
    pub temp: Option<i16>,
    /// Gyroscope X, Y, Z.
    pub gyro: [i16; 3],
}

/// One sample in physical units.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Sample {
    /// Acceleration, m/s².
    pub accel_ms2: [f32; 3],
    /// Angular rate, °/s.
    pub gyro_dps: [f32; 3],
    /// Die temperature, °C.
    pub temperature_c: Option<f32>,
}

#[inline(always)]
fn be(b: &[u8], i: usize) -> i16 {
    // Callers pass fixed-size arrays whose length covers i + 1. Written as shift-or of the
    // two bytes: `from_be_bytes` becomes a byte swap of a word on the M0+ (two instructions
    // more per value, and more registers live across a FIFO frame).
    ((u16::from(b[i]) << 8) | u16::from(b[i + 1])) as i16
}

/// Decode the 14 bytes read from ACCEL_XOUT_H (RM 4.17-4.19, big-endian).
pub fn decode_measurements(b: &[u8; 14]) -> RawSample {
    RawSample {
        accel: [be(b, 0), be(b, 2), be(b, 4)],
        temp: Some(be(b, 6)),
        gyro: [be(b, 8), be(b, 10), be(b, 12)],
    }
}

/// Decode one FIFO frame; returns `None` if `b` is shorter than the frame.
pub fn decode_fifo_frame(b: &[u8], frame: FifoFrame) -> Option<RawSample> {
    let b: &[u8] = b.get(..frame.bytes())?;
    let accel = [be(b, 0), be(b, 2), be(b, 4)];
    Some(match frame {
        FifoFrame::AccelGyro => RawSample {
            accel,
            temp: None,
            gyro: [be(b, 6), be(b, 8), be(b, 10)],
        },
        FifoFrame::AccelTempGyro => RawSample {
            accel,
            temp: Some(be(b, 6)),
            gyro: [be(b, 8), be(b, 10), be(b, 12)],
        },
    })
}

/// Decode one FIFO frame of `N` bytes: 14 (accel, temperature, gyro) or 12 (accel, gyro;
/// [`FifoFrame::bytes`]); any other `N` panics. For a caller that knows the layout at compile
/// time: fixed offsets, no length check, the values straight into registers when inlined.
#[inline(always)]
pub fn decode_fifo_frame_of<const N: usize>(b: &[u8; N]) -> RawSample {
    assert!(N == 12 || N == 14, "FIFO frames are 12 or 14 bytes");
    let accel = [be(b, 0), be(b, 2), be(b, 4)];
    let (temp, g) = if N == 14 {
        (Some(be(b, 6)), 8)
    } else {
        (None, 6)
    };
    RawSample {
        accel,
        temp,
        gyro: [be(b, g), be(b, g + 2), be(b, g + 4)],
    }
}

/// FIFO_COUNT decode: high byte first (RM 4.30). The 6500 family uses 13 bits, the
/// MPU-6050 never exceeds 1024, so the top three bits are masked.
pub fn decode_fifo_count(b: [u8; 2]) -> u16 {
    u16::from_be_bytes(b) & 0x1FFF
}

/// What one counted FIFO read moved (`read_counted_fifo_raw`): the FIFO count, latched at the
/// start of the transfer; the frames read after it; and how many of those the count covers
/// (whole frames the FIFO held at the count). Frames read beyond the count came from an
/// empty FIFO, or in part from a sample that landed while they were read.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CountedFrames {
    /// FIFO_COUNT, bytes.
    pub count: u16,
    /// Frames read after the count.
    pub read: usize,
    /// Of those, the whole frames the count covers (the first `covered` are valid).
    pub covered: usize,
}

impl CountedFrames {
    /// Every frame read was in the FIFO at the count: the FIFO is still aligned.
    pub fn whole(&self) -> bool {
        self.covered == self.read
    }
}

pub use registers::IntStatus;
use registers::{AccelConfig, GyroConfig};

use crate::register::Register;

/// Result of the self-test: change of the self-test response (output with self-test on minus
/// output with it off) from the factory value, in percent, per axis, with the pass window of
/// the chip family. MPU-6050 (RM 4.1, PS 6.1/6.2): within ±14 %. MPU-6500 family (InvenSense
/// AN-MPU-6500A-02, "Accelerometer and Gyroscope Self-Test Implementation"): gyro ratio > 0.5
/// (change > −50 %), accel ratio in 0.5..1.5 (change within ±50 %).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SelfTestReport {
    /// Gyroscope X, Y, Z change from factory trim, %.
    pub gyro_change_pct: [f32; 3],
    /// Accelerometer X, Y, Z change from factory trim, %.
    pub accel_change_pct: [f32; 3],
    /// Pass window of the gyro change, % (low, high).
    pub gyro_limits_pct: [f32; 2],
    /// Pass window of the accel change, % (low, high).
    pub accel_limits_pct: [f32; 2],
}

/// Pass limit of the MPU-6050 self-test change from factory trim, % (PS 6.1 and 6.2 tables).
pub const SELF_TEST_LIMIT_PCT: f32 = 14.0;

impl SelfTestReport {
    /// `true` when all six axes are inside their pass windows (NaN fails).
    pub fn passed(&self) -> bool {
        let inside = |c: &f32, [lo, hi]: [f32; 2]| *c >= lo && *c <= hi;
        self.gyro_change_pct
            .iter()
            .all(|c| inside(c, self.gyro_limits_pct))
            && self
                .accel_change_pct
                .iter()
                .all(|c| inside(c, self.accel_limits_pct))
    }
}

/// Factory-trim codes decoded from SELF_TEST_X..SELF_TEST_A (RM 4.1): 5-bit gyro codes in
/// bits 4:0 of SELF_TEST_X/Y/Z; 5-bit accel codes = bits 7:5 of SELF_TEST_X/Y/Z (high 3 bits)
/// and the 2-bit pairs of SELF_TEST_A (5:4 for X, 3:2 for Y, 1:0 for Z).
pub fn decode_trim_codes(b: [u8; 4]) -> ([u8; 3], [u8; 3]) {
    let g = [b[0] & 0x1F, b[1] & 0x1F, b[2] & 0x1F];
    let a = [
        ((b[0] >> 5) << 2) | ((b[3] >> 4) & 0x03),
        ((b[1] >> 5) << 2) | ((b[3] >> 2) & 0x03),
        ((b[2] >> 5) << 2) | (b[3] & 0x03),
    ];
    (g, a)
}

/// Gyro factory trim in LSB (RM 4.1): FT = 25·131·1.046^(code−1), negated for Y, 0 for code 0.
pub fn gyro_factory_trim(code: u8, axis: usize) -> f32 {
    if code == 0 {
        return 0.0;
    }
    let ft = 25.0 * 131.0 * libm::powf(1.046, code as f32 - 1.0);
    if axis == 1 {
        -ft
    } else {
        ft
    }
}

/// Accel factory trim in LSB (RM 4.1): FT = 4096·0.34·(0.92/0.34)^((code−1)/(2⁵−2)), 0 for code 0.
pub fn accel_factory_trim(code: u8) -> f32 {
    if code == 0 {
        return 0.0;
    }
    4096.0 * 0.34 * libm::powf(0.92 / 0.34, (code as f32 - 1.0) / 30.0)
}

/// Change from factory trim in % (RM 4.1): 100·(STR − FT)/FT. A zero trim gives NaN, which
/// [`SelfTestReport::passed`] treats as a failure.
pub fn change_from_trim_pct(self_test_response: f32, factory_trim: f32) -> f32 {
    if factory_trim == 0.0 {
        return f32::NAN;
    }
    100.0 * (self_test_response - factory_trim) / factory_trim
}

/// Build the report from the averaged outputs with self-test on and off (taken at
/// ±250 °/s and ±8 g as RM 4.1 requires) and the four SELF_TEST registers.
pub fn self_test_report(
    on_accel: [f32; 3],
    on_gyro: [f32; 3],
    off_accel: [f32; 3],
    off_gyro: [f32; 3],
    trim_regs: [u8; 4],
) -> SelfTestReport {
    let (gc, ac) = decode_trim_codes(trim_regs);
    let mut g = [0.0; 3];
    let mut a = [0.0; 3];
    for i in 0..3 {
        g[i] = change_from_trim_pct(on_gyro[i] - off_gyro[i], gyro_factory_trim(gc[i], i));
        a[i] = change_from_trim_pct(on_accel[i] - off_accel[i], accel_factory_trim(ac[i]));
    }
    SelfTestReport {
        gyro_change_pct: g,
        accel_change_pct: a,
        gyro_limits_pct: [-SELF_TEST_LIMIT_PCT, SELF_TEST_LIMIT_PCT],
        accel_limits_pct: [-SELF_TEST_LIMIT_PCT, SELF_TEST_LIMIT_PCT],
    }
}

/// MPU-6500-family factory self-test value in LSB (AN-MPU-6500A-02; RM-6500 registers 0-2
/// and 13-15): ST_OTP = (2620 / 2^FS)·1.01^(code−1) with FS = 0 (±250 °/s, ±2 g), 0 for code 0.
pub fn otp_6500(code: u8) -> f32 {
    if code == 0 {
        return 0.0;
    }
    2620.0 * libm::powf(1.01, code as f32 - 1.0)
}

/// Build the MPU-6500-family report from the averaged outputs with self-test on and off
/// (taken at ±250 °/s and ±2 g) and the SELF_TEST_X/Y/Z_GYRO (0x00-0x02) and
/// SELF_TEST_X/Y/Z_ACCEL (0x0D-0x0F) codes. A code of 0 gives NaN (fails): the application
/// note's absolute fallback limits for blank OTP are not applied.
pub fn self_test_report_6500(
    on_accel: [f32; 3],
    on_gyro: [f32; 3],
    off_accel: [f32; 3],
    off_gyro: [f32; 3],
    gyro_codes: [u8; 3],
    accel_codes: [u8; 3],
) -> SelfTestReport {
    let mut g = [0.0; 3];
    let mut a = [0.0; 3];
    for i in 0..3 {
        g[i] = change_from_trim_pct(on_gyro[i] - off_gyro[i], otp_6500(gyro_codes[i]));
        a[i] = change_from_trim_pct(on_accel[i] - off_accel[i], otp_6500(accel_codes[i]));
    }
    SelfTestReport {
        gyro_change_pct: g,
        accel_change_pct: a,
        gyro_limits_pct: [-50.0, f32::INFINITY],
        accel_limits_pct: [-50.0, 50.0],
    }
}

/// MPU-6050 driver error.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Error<E> {
    /// The I²C bus failed (NACK, arbitration loss, ...).
    Bus(E),
    /// WHO_AM_I held a value that is neither an MPU-6050 nor a known compatible clone.
    WrongChip {
        /// The WHO_AM_I byte read.
        found: u8,
    },
    /// INT_STATUS.FIFO_OFLOW_INT was set: frames were lost and the frame alignment of the
    /// FIFO is gone. Call `reset_fifo()`.
    FifoOverflow,
    /// No new sample is available (DATA_RDY_INT clear).
    NotReady,
    /// The operation needs something the configuration leaves off (e.g. `read_fifo` with
    /// the FIFO disabled) or the driver has not been initialised.
    NotConfigured,
    /// The chip found has no self-test this driver knows (the ICM parts keep theirs elsewhere).
    SelfTestUnsupported,
}

impl<E> From<E> for Error<E> {
    fn from(e: E) -> Self {
        Error::Bus(e)
    }
}

impl<E: core::fmt::Debug> core::fmt::Display for Error<E> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Error::Bus(e) => write!(f, "MPU-6050: I2C bus error: {e:?}"),
            Error::WrongChip { found } => write!(
                f,
                "MPU-6050: WHO_AM_I (0x75) read 0x{found:02X}, not an MPU-6050 or known clone"
            ),
            Error::FifoOverflow => {
                write!(f, "MPU-6050: FIFO overflowed, frames lost; reset the FIFO")
            }
            Error::NotReady => write!(f, "MPU-6050: no new sample (DATA_RDY clear)"),
            Error::NotConfigured => write!(f, "MPU-6050: driver not initialised or FIFO disabled"),
            Error::SelfTestUnsupported => {
                write!(
                    f,
                    "MPU-6050: no known factory self-test for this chip (ICM parts)"
                )
            }
        }
    }
}

impl<E: core::fmt::Debug> core::error::Error for Error<E> {}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn factory_trim_formulas() {
        // RM 4.1 at code 1: 25·131 = 3275 LSB (negated for Y); 4096·0.34 = 1392.64 LSB.
        assert_eq!(gyro_factory_trim(1, 0), 3275.0);
        assert_eq!(gyro_factory_trim(1, 1), -3275.0);
        assert_eq!(gyro_factory_trim(0, 2), 0.0);
        assert!((accel_factory_trim(1) - 1392.64).abs() < 1e-3);
        // Code 31: (0.92/0.34)^(30/30) → 4096·0.92 = 3768.32 LSB (f32 powf: tolerance 0.01 LSB).
        assert!((accel_factory_trim(31) - 3768.32).abs() < 0.01);
        // Code 11: 3275·1.046^10 = 5134.855 LSB (double precision; f32 tolerance 0.05 LSB).
        assert!((gyro_factory_trim(11, 0) - 5134.855).abs() < 0.05);
    }

    #[test]
    fn trim_code_bit_layout() {
        // XA_TEST = SELF_TEST_X[7:5] << 2 | SELF_TEST_A[5:4]; XG_TEST = SELF_TEST_X[4:0].
        let (g, a) = decode_trim_codes([0b101_10011, 0b010_00001, 0b111_11111, 0b00_11_01_10]);
        assert_eq!(g, [0b10011, 0b00001, 0b11111]);
        assert_eq!(a, [0b10111, 0b01001, 0b11110]);
    }

    #[test]
    fn zero_trim_fails_the_test() {
        let r = self_test_report([0.0; 3], [0.0; 3], [0.0; 3], [0.0; 3], [0; 4]);
        assert!(r.gyro_change_pct[0].is_nan());
        assert!(!r.passed());
    }

    #[test]
    fn who_am_i_round_trip() {
        for v in 0..=255u8 {
            if let Some(c) = ChipId::from_who_am_i(v) {
                assert_eq!(c.who_am_i(), v);
            }
        }
        assert_eq!(ChipId::from_who_am_i(0x68), Some(ChipId::Mpu6050));
        assert_eq!(ChipId::from_who_am_i(0x34), None);
    }

    /// The fixed-size decode gives what the layout-checked one gives, for both layouts and
    /// bytes from a generator seeded by the clock (every run a different realisation).
    #[test]
    fn fixed_size_fifo_decode_matches_the_checked_one() {
        extern crate std;
        let mut x = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(1, |d| d.as_nanos() as u64)
            | 1;
        for _ in 0..2000 {
            let b: [u8; 14] = core::array::from_fn(|_| {
                x ^= x << 13;
                x ^= x >> 7;
                x ^= x << 17;
                x as u8
            });
            let with_temp = decode_fifo_frame(&b, FifoFrame::AccelTempGyro);
            assert_eq!(Some(decode_fifo_frame_of(&b)), with_temp, "{b:02x?}");
            let b12: &[u8; 12] = b[..12].try_into().unwrap();
            let without = decode_fifo_frame(b12, FifoFrame::AccelGyro);
            assert_eq!(Some(decode_fifo_frame_of(b12)), without, "{b:02x?}");
        }
    }

    #[test]
    fn sample_rates() {
        let mut c = Config::default();
        assert_eq!(c.sample_rate_hz(), 1000.0);
        c.dlpf = Dlpf::Hz260;
        assert_eq!(c.sample_rate_hz(), 8000.0);
        c.sample_rate_divider = 255;
        assert_eq!(c.sample_rate_hz(), 31.25);
    }
}
