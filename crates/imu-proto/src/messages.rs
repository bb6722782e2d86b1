//! The messages: what the host asks ([`HostFrame`]) and what the device sends ([`DeviceMsg`]).
use serde::{Deserialize, Serialize};

use crate::{Channel, Scales, String, Vec};

/// Octave levels in a device Allan table (m = 1, 2, 4, … 2^23).
pub const MAX_LEVELS: usize = 24;
/// IMU samples per [`SampleBatch`] (32 ms of data at 1 kHz).
pub const MAX_BATCH_IMU: usize = 32;
/// Magnetometer samples per [`SampleBatch`].
pub const MAX_BATCH_MAG: usize = 16;
/// Largest calibration blob (`imu_cal::device::encode_blob`), bytes.
pub const MAX_CAL_BLOB: usize = 256;

/// One accelerometer + gyroscope + temperature sample from the MPU-6050 FIFO.
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ImuSample {
    /// Sample number since boot (or since the last Allan reset); a jump is a gap.
    pub seq: u32,
    /// Device time of the sample, µs since boot (see docs/firmware.md for how it is assigned).
    pub t_us: u64,
    pub accel: [i32; 3],
    pub gyro: [i32; 3],
    pub temp: i32,
}

/// One magnetometer sample.
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct MagSample {
    pub seq: u32,
    /// Device time of the read, µs since boot.
    pub t_us: u64,
    pub mag: [i32; 3],
}

/// A batch of samples, calibrated (fixed-point corrected) or raw counts.
///
/// On the wire each sample after the first of its sensor carries its sequence number and time
/// as differences from the previous sample's (the time minus the nominal period), so a regular
/// run costs two bytes a sample instead of eight or nine (`batch.rs` has the layout; serde
/// `Serialize`/`Deserialize` are implemented there).
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SampleBatch {
    /// `true`: corrected values (the very integers the Allan engines eat); `false`: raw counts.
    pub calibrated: bool,
    pub scales: Scales,
    pub imu: Vec<ImuSample, MAX_BATCH_IMU>,
    pub mag: Vec<MagSample, MAX_BATCH_MAG>,
}

/// One octave level of a device Allan table: the exact integer sums of the streaming engine and
/// the deviation derived from them (seed eq. 9 with overlapping clusters; IEEE Std 1139-2008).
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct AllanLevel {
    /// Cluster size (samples); τ = m·τ0.
    pub m: u32,
    /// Spacing of the second differences that were summed (1 = fully overlapping).
    pub stride: u32,
    /// Number of second differences summed.
    pub n2: u64,
    /// Σ (θ[k+2m] − 2θ[k+m] + θ[k])², θ the integer phase (cumulative sum of the samples).
    pub sum2: u128,
    /// Number of third differences summed.
    pub n3: u64,
    /// Σ (θ[k+3m] − 3θ[k+2m] + 3θ[k+m] − θ[k])².
    pub sum3: u128,
    /// τ, s.
    pub tau_s: f32,
    /// Overlapping Allan deviation in the channel's contract unit.
    pub dev: f32,
    /// Equivalent degrees of freedom behind the bounds (Greenhall & Riley 2003).
    pub edf: f32,
    /// 68.3 % lower and upper bounds of `dev`, same unit.
    pub lo: f32,
    pub hi: f32,
}

/// The Allan table of one channel.
#[derive(Serialize, Deserialize, Debug, Clone, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct AllanTable {
    pub channel: Channel,
    /// Sample period, µs.
    pub tau0_us: u32,
    /// Contract unit per LSB of the integers the engine ate.
    pub scale: f32,
    /// Samples pushed since the last reset.
    pub pushed: u64,
    /// Gaps marked since the last reset.
    pub gaps: u32,
    pub levels: Vec<AllanLevel, MAX_LEVELS>,
}

/// What the device streams besides tables and status.
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum StreamMode {
    /// No sample batches (tables and status only).
    Off,
    /// Corrected fixed-point samples.
    Calibrated,
    /// Raw sensor counts.
    Raw,
}

/// Health of one sensor.
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum SensorState {
    /// Not probed yet.
    Unknown,
    /// Delivering samples.
    Ok,
    /// Not answering; retrying with bus recovery.
    Missing,
}

/// Which sensor an event is about.
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Sensor {
    Imu,
    Mag,
}

/// Where the corrections in use came from.
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum CalSource {
    /// No stored record: identity corrections.
    Identity,
    /// Loaded from flash at boot or written there on request.
    Flash,
    /// Set by the host, not (yet) persisted.
    Host,
}

/// Why the stored calibration was not used.
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum CalFault {
    /// The record failed its checksum or could not be parsed.
    Corrupt,
    /// The record has another format version (carried).
    OldVersion(u8),
    /// The flash could not be read or written.
    Flash,
}

/// Calibration state.
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct CalStatus {
    pub source: CalSource,
    /// The last problem met with the stored record, if any (identity is used meanwhile).
    pub fault: Option<CalFault>,
}

/// Device counters and health.
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Status {
    pub uptime_us: u64,
    /// IMU samples read from the FIFO.
    pub samples_taken: u64,
    /// IMU samples lost (FIFO overflows, sensor outages, full internal queues).
    pub samples_dropped: u64,
    pub mag_samples: u64,
    pub fifo_overflows: u32,
    pub i2c_errors: u32,
    pub bus_recoveries: u32,
    /// Host frames rejected (corrupt, unknown, oversized).
    pub frames_rejected: u32,
    /// Device frames not sent because the host was not reading.
    pub frames_unsent: u32,
    /// CPU busy time over the last status interval, ‰.
    pub cpu_load_permille: u16,
    /// Latest die temperature, m°C.
    pub temp_milli_c: i32,
    pub imu: SensorState,
    pub mag: SensorState,
    pub cal: CalStatus,
    pub mode: StreamMode,
}

/// Who the device is.
#[derive(Serialize, Deserialize, Debug, Clone, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Identity {
    pub protocol: u8,
    pub firmware: String<24>,
    pub board: String<24>,
    pub imu_rate_hz: u16,
    pub mag_rate_hz: u16,
    /// Overlap factor P and octave levels L of the streaming Allan engines: `allan_levels` for
    /// the 1 kHz channels, `allan_levels_mag` for the magnetometer.
    pub allan_overlap: u8,
    pub allan_levels: u8,
    pub allan_levels_mag: u8,
}

/// An asynchronous event worth a line in the host's log.
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Event {
    SensorLost {
        sensor: Sensor,
        t_us: u64,
    },
    SensorBack {
        sensor: Sensor,
        t_us: u64,
        down_us: u64,
    },
    FifoOverflow {
        t_us: u64,
        lost: u32,
    },
    /// The sensor's Allan engines were split: no difference straddles the position `at`, the
    /// number of samples pushed into each of its engines (since boot or the last Allan reset)
    /// before the split. A host that replays the same samples applies the same splits and gets
    /// the same sums, bit for bit.
    Gap {
        sensor: Sensor,
        at: u64,
        cause: GapCause,
    },
}

/// Why the device split a sensor's series (see [`Event::Gap`]).
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum GapCause {
    /// The MPU-6050 FIFO overflowed and was reset.
    FifoOverflow,
    /// The sensor stopped answering (or failed a transfer).
    SensorFault,
    /// The QMC5883L overwrote an unread sample (DOR).
    Overwritten,
    /// The magnetometer read came more than 1.5 periods after the previous one.
    Late,
    /// Sampling paused (a flash write).
    Paused,
}

/// Host → device request.
#[derive(Serialize, Deserialize, Debug, Clone, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[allow(clippy::large_enum_variant)] // no heap on the device: the blob is inline by design
pub enum Request {
    Identify,
    GetStatus,
    GetCalibration,
    /// Use this calibration blob; with `persist`, also write it to flash (measurement pauses).
    SetCalibration {
        blob: Vec<u8, MAX_CAL_BLOB>,
        persist: bool,
    },
    ResetAllan,
    SetMode(StreamMode),
    /// Intervals of the unsolicited status and table frames, ms (0 = never).
    SetIntervals {
        status_ms: u32,
        tables_ms: u32,
    },
    /// Send all tables now.
    GetTables,
}

/// A request with the id its reply will carry.
#[derive(Serialize, Deserialize, Debug, Clone, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct HostFrame {
    pub id: u16,
    pub req: Request,
}

/// Why a request failed.
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ErrorCode {
    /// The calibration blob did not decode (bad CRC, version or size).
    BadCalibration,
    /// The flash write failed.
    FlashWrite,
    /// The device cannot take this request now.
    Busy,
}

/// The answer to a [`HostFrame`].
#[derive(Serialize, Deserialize, Debug, Clone, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Reply {
    Ok,
    Identity(Identity),
    Status(Status),
    Calibration {
        blob: Vec<u8, MAX_CAL_BLOB>,
        status: CalStatus,
    },
    Error(ErrorCode),
}

/// Device → host message.
#[derive(Serialize, Deserialize, Debug, Clone, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[allow(clippy::large_enum_variant)]
pub enum DeviceMsg {
    Reply { id: u16, reply: Reply },
    Samples(SampleBatch),
    Table(AllanTable),
    Status(Status),
    Event(Event),
}

/// A borrowed view of [`DeviceMsg`] with the same wire encoding (postcard writes a variant as
/// its index and a reference as its referent), so the device frames a batch or a table without
/// copying it first. The variant order must stay that of [`DeviceMsg`] (tested).
#[derive(Serialize, Debug, Clone, Copy)]
pub enum DeviceMsgRef<'a> {
    Reply { id: u16, reply: &'a Reply },
    Samples(&'a SampleBatch),
    Table(&'a AllanTable),
    Status(&'a Status),
    Event(&'a Event),
}

impl<'a> From<&'a DeviceMsg> for DeviceMsgRef<'a> {
    fn from(m: &'a DeviceMsg) -> Self {
        match m {
            DeviceMsg::Reply { id, reply } => DeviceMsgRef::Reply { id: *id, reply },
            DeviceMsg::Samples(b) => DeviceMsgRef::Samples(b),
            DeviceMsg::Table(t) => DeviceMsgRef::Table(t),
            DeviceMsg::Status(s) => DeviceMsgRef::Status(s),
            DeviceMsg::Event(e) => DeviceMsgRef::Event(e),
        }
    }
}
