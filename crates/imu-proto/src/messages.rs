//! The messages: what the host asks ([`HostFrame`]) and what the device sends ([`DeviceMsg`]).
use serde::{Deserialize, Serialize};

use crate::{Channel, Scales, Sensor, String, Vec};

/// Octave levels in a device Allan table (m = 1, 2, 4, … 2^23).
pub const MAX_LEVELS: usize = 24;
/// Most IMU samples in one [`SampleBatch`] (32 ms of data at 1 kHz; the firmware sends 25).
pub const MAX_BATCH_IMU: usize = 32;
/// Magnetometer samples per [`SampleBatch`].
pub const MAX_BATCH_MAG: usize = 16;
/// Largest calibration blob (`imu_cal::device::encode_blob`), bytes.
pub const MAX_CAL_BLOB: usize = 256;

/// One accelerometer + gyroscope + temperature sample from the MPU-6050 FIFO.
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ImuSample {
    /// The sample's slot on the sensor's sample grid since boot: consecutive samples differ by
    /// one, and a jump of `n + 1` means `n` samples were lost (each loss also comes as an
    /// [`Event::Gap`] with its cause).
    pub seq: u32,
    /// When the sensor took the sample, µs since boot, on the sensor's own sample clock
    /// (docs/firmware.md, "Timestamps").
    pub t_us: u64,
    pub accel: [i32; 3],
    pub gyro: [i32; 3],
    /// Die temperature; `None` when the sample carried none (never a made-up number).
    pub temp: Option<i32>,
}

/// One magnetometer sample.
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct MagSample {
    /// Slot on the magnetometer's sample grid (as [`ImuSample::seq`]).
    pub seq: u32,
    /// When the sensor took the sample, µs since boot (as [`ImuSample::t_us`]).
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

/// One octave level of a device Allan table: the streaming engine's exact integer sums
/// ([`allan::stream::LevelSums`], the same type: cluster size `m`, stride, the counts and sums of
/// squared second and third differences of the integer phase, on the wire in that order), from
/// which the host derives the deviation and its bounds (overlapping ADEV `σ² = Σ D2² / (2 n m²)`,
/// NIST SP 1065 eq. 11; bounds from `allan::confidence`).
pub use allan::stream::LevelSums as AllanLevel;

/// The Allan table of one channel, as it stood at its round's snapshot.
///
/// Every table of one round (a `GetTables` request or a periodic round) was taken at the same
/// instant: all ten carry the same `snapshot` and `t_us`. A host combining tables checks that
/// they do.
#[derive(Serialize, Deserialize, Debug, Clone, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct AllanTable {
    pub channel: Channel,
    /// The round this table belongs to (counts up from 1 since boot).
    pub snapshot: u32,
    /// Device time of the round's snapshot, µs since boot.
    pub t_us: u64,
    /// The sample period behind τ = m·τ0: the sensor's own period as the device measured it
    /// (its sample clock), ns.
    pub tau0_ns: u32,
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
    /// Answering on the bus but producing no data (data-ready never set, FIFO not growing);
    /// re-initialised with back-off.
    Stalled,
}

/// Where the corrections in use came from.
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum CalSource {
    /// No stored record: identity corrections.
    Identity,
    /// Loaded from flash at boot or written there on request.
    Flash,
    /// Set by the host, not persisted (lost at reset).
    Host,
}

/// Why a calibration was refused, by the device or by the host (the same checks).
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum CalProblem {
    /// Not a calibration blob: length, magic, CRC or payload.
    Corrupt,
    /// Another blob format version.
    Version(u16),
    /// A coefficient outside the fixed-point range.
    OutOfRange,
    /// A parameter outside its datasheet bound (docs/calibration.md, "Plausibility"): the
    /// calibration file's key (`imu_cal::device::Key` as u8), the index within it (`None` for a
    /// whole-matrix quantity), the value and the bound, in the key's unit.
    Implausible {
        key: u8,
        axis: Option<u8>,
        value: f32,
        lo: f32,
        hi: f32,
    },
    /// Fitted for other full-scale ranges than the firmware uses.
    OtherRanges,
    /// Fitted for other sensor parts than the firmware's, or recording none.
    OtherPart,
}

/// Why the stored calibration is not in use.
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum CalFault {
    /// The flash could not be read or written.
    Flash,
    /// The stored record was refused.
    Rejected(CalProblem),
}

/// Calibration state.
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq)]
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
    /// IMU samples lost: slots of the IMU's sample grid between delivered samples (FIFO
    /// contents discarded, outages, stalls, bursts abandoned on a bus fault, pauses). The sum of
    /// the `lost` of every IMU [`Event::Gap`].
    pub samples_dropped: u64,
    /// Magnetometer samples read.
    pub mag_samples: u64,
    /// Magnetometer samples lost (overwritten before they were read, outages, stalls).
    pub mag_dropped: u64,
    pub fifo_overflows: u32,
    pub i2c_errors: u32,
    /// Transfers that lost arbitration (SDA held) or hung until the deadline.
    pub bus_faults: u32,
    pub bus_recoveries: u32,
    /// Host frames rejected (corrupt, unknown, oversized).
    pub frames_rejected: u32,
    /// Device frames not sent because the host was not reading.
    pub frames_unsent: u32,
    /// CPU busy time over the last status interval, ‰.
    pub cpu_load_permille: u16,
    /// Latest die temperature, m°C (`None` before the first sample that carried one).
    pub temp_milli_c: Option<i32>,
    pub imu: SensorState,
    pub mag: SensorState,
    /// The sensors' sample periods as their sample clocks measure them, ns (0: not yet).
    pub imu_period_ns: u32,
    pub mag_period_ns: u32,
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

/// What kind of bus fault ended a transfer.
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum BusFault {
    /// The START lost arbitration: a slave holds SDA low.
    ArbitrationLost,
    /// The transfer did not finish before its deadline (a hung START or a stretched clock).
    Timeout,
}

/// An asynchronous event worth a line in the host's log.
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Event {
    /// The sensor stopped answering for longer than the retries cover.
    SensorLost { sensor: Sensor, t_us: u64 },
    /// The sensor delivers samples again after a loss or a stall.
    SensorBack {
        sensor: Sensor,
        t_us: u64,
        down_us: u64,
    },
    /// The sensor answers but has produced no sample since `since_us` (data-ready never set,
    /// FIFO count not growing).
    SensorStalled {
        sensor: Sensor,
        t_us: u64,
        since_us: u64,
    },
    /// A transfer ended by a bus fault; the bus is recovered (9 SCL pulses and a STOP) before
    /// the next one.
    BusFault { t_us: u64, fault: BusFault },
    /// A bus recovery ran: `pulses` SCL pulses were clocked; SDA was free at the end or not.
    BusRecovered {
        t_us: u64,
        pulses: u8,
        sda_released: bool,
    },
    /// The sensor's series has a discontinuity before the next sample: `lost` samples of its
    /// grid (maybe 0) did not reach the host, for `cause`. The Allan engines were split there:
    /// no difference straddles the position `at`, the number of samples pushed into each of the
    /// sensor's engines (since boot or the last Allan reset) before the split. A host that
    /// replays the same samples applies the same splits and gets the same sums, bit for bit.
    Gap {
        sensor: Sensor,
        at: u64,
        cause: GapCause,
        lost: u32,
        /// Device time of the first sample after the gap (its stamp), µs.
        t_us: u64,
    },
}

/// Why samples were lost or a series split (see [`Event::Gap`]).
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum GapCause {
    /// The MPU-6050 FIFO overflowed; its contents were discarded by a reset.
    FifoOverflow,
    /// The sensor stopped answering (or lost its configuration and was re-initialised).
    SensorFault,
    /// A bus fault (arbitration lost, a hung transfer) cost samples.
    BusFault,
    /// The sensor produced no data for a while.
    Stalled,
    /// The magnetometer overwrote samples that were not read in time.
    Overwritten,
    /// Sampling paused (a flash write).
    Paused,
}

/// What the device's attitude filter says about an [`Orientation`] (docs/firmware.md,
/// "Orientation").
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum AhrsState {
    /// Since the start or a new calibration: the estimate is still pulling in.
    Converging,
    /// Tracking; the magnetometer within its expected band.
    Tracking,
    /// |B| outside its band around the expected field strength: a magnetic disturbance; the
    /// heading is held by the gyro alone.
    MagField,
    /// The dip (inclination) outside its band around the expected dip: as `MagField`.
    MagDip,
}

/// One attitude estimate, made at a magnetometer sample (200 Hz).
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Orientation {
    /// The magnetometer sample (its slot, [`MagSample::seq`]) whose update this is.
    pub seq: u32,
    /// The instant the attitude refers to: the stamp of the last IMU sample integrated, µs
    /// since boot.
    pub t_us: u64,
    /// Body (sensor x forward, y left, z up, taken as forward-right-down) → local NED (x
    /// magnetic north), `[w, x, y, z]`, unit norm.
    pub q: [f32; 4],
    /// Aerospace Z-Y-X angles, degrees: roll in (−180, 180], pitch in [−90, 90].
    pub roll_deg: f32,
    pub pitch_deg: f32,
    /// Tilt-compensated heading, degrees in [0, 360): magnetic plus the declination set by
    /// [`Request::SetOrientation`] (true heading when it is the place's declination).
    pub heading_deg: f32,
    pub state: AhrsState,
}

/// Most [`Orientation`]s in one [`DeviceMsg::Orientation`] (the device sends five a frame,
/// every 25 ms).
pub const MAX_ORIENTATIONS: usize = 8;

/// The expected geomagnetic field, against which the device flags a magnetic disturbance.
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct MagReference {
    /// Field strength, nT (as the corrected magnetometer reads it).
    pub field_nt: u32,
    /// Dip (inclination), 0.01°, positive when the field points down.
    pub dip_cdeg: i16,
}

/// The attitude filter's settings in use.
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct OrientationConfig {
    /// Declination, 0.01° (east positive), added to the magnetic heading.
    pub declination_cdeg: i16,
    /// The expected field, `None` while it is being learnt.
    pub reference: Option<MagReference>,
    /// `true`: the reference was learnt by the device (from its first converged second after
    /// the start or a new calibration); `false`: set by the host.
    pub learnt: bool,
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
    /// Take a snapshot of every channel's table now and send them (answered by
    /// [`Reply::Tables`]); a round in progress is abandoned.
    GetTables,
    /// The attitude filter's declination (0.01°, east positive, within ±180°) and expected
    /// field (strength 1–1000 µT, dip within ±90°; `None`: learnt by the device, a reference
    /// already learnt kept). A setting other than the one stored is written to flash (sampling
    /// paused meanwhile, as for a persisted calibration) and used again after a reset.
    /// Answered `Ok`, `Error(OutOfRange)`, or `Error(FlashWrite)` (in use, but not stored).
    SetOrientation {
        declination_cdeg: i16,
        reference: Option<MagReference>,
    },
    /// Answered by [`Reply::Orientation`].
    GetOrientation,
}

/// A request with the id its reply will carry.
#[derive(Serialize, Deserialize, Debug, Clone, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct HostFrame {
    pub id: u16,
    pub req: Request,
}

/// Why a request failed.
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ErrorCode {
    /// The calibration was refused, with the reason.
    BadCalibration(CalProblem),
    /// The flash write failed.
    FlashWrite,
    /// The device cannot take this request now.
    Busy,
    /// A request's value is outside its documented range.
    OutOfRange,
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
    /// `GetTables` started a round: ten `Table` frames with this `snapshot` follow.
    Tables {
        snapshot: u32,
    },
    Orientation(OrientationConfig),
}

/// Device → host message.
#[derive(Serialize, Deserialize, Debug, Clone, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[allow(clippy::large_enum_variant)]
pub enum DeviceMsg {
    Reply {
        id: u16,
        reply: Reply,
    },
    Samples(SampleBatch),
    Table(AllanTable),
    Status(Status),
    Event(Event),
    /// Attitude estimates, oldest first.
    Orientation(Vec<Orientation, MAX_ORIENTATIONS>),
}
