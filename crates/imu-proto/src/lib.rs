#![cfg_attr(not(feature = "std"), no_std)]
//! The pico-imu wire protocol, shared by the firmware and the host (`imu-lab`).
//!
//! # Frame format
//!
//! Every message, in both directions, travels as one frame:
//!
//! ```text
//! COBS( version:u8 | postcard(message) | crc32(version | postcard(message)) as u32 LE ) 0x00
//! ```
//!
//! * `version` is [`PROTOCOL_VERSION`]; a frame of another version is rejected, not guessed at.
//! * the message is serialised with postcard (varint integers, zig-zag for signed ones);
//! * the CRC is CRC-32/ISO-HDLC (the Ethernet/zip CRC, `crc::CRC_32_ISO_HDLC`) over the version
//!   byte and the postcard bytes;
//! * COBS (Cheshire & Baker, "Consistent Overhead Byte Stuffing", IEEE/ACM ToN 1999) removes
//!   every zero byte, so a single `0x00` delimits frames and a receiver resynchronises at the
//!   next zero after any corruption.
//!
//! Host → device frames are [`HostFrame`] (a request id and a [`Request`]); device → host
//! frames are [`DeviceMsg`]. A frame that is unknown, truncated, oversized or fails its CRC is
//! rejected with a [`DecodeError`] and counted in [`RxStats`]; no input can panic the decoder
//! (hammered by the proptests in `tests/`).
use serde::{de::DeserializeOwned, Deserialize, Serialize};

mod batch;
/// The CSV recording contract (columns, units, reading, writing, timing).
#[cfg(feature = "std")]
pub mod csv;

pub use heapless::{String, Vec};

/// Wire-format version carried in the first byte of every frame.
pub const PROTOCOL_VERSION: u8 = 3;
/// Largest serialised message (version + postcard + CRC), bytes, before COBS.
pub const MAX_PAYLOAD: usize = 3072;
/// Largest encoded frame, bytes, including the trailing `0x00` delimiter.
pub const MAX_FRAME: usize = cobs::max_encoding_length(MAX_PAYLOAD) + 1;
/// Octave levels in a device Allan table (m = 1, 2, 4, … 2^23).
pub const MAX_LEVELS: usize = 24;
/// IMU samples per [`SampleBatch`] (32 ms of data at 1 kHz).
pub const MAX_BATCH_IMU: usize = 32;
/// Magnetometer samples per [`SampleBatch`].
pub const MAX_BATCH_MAG: usize = 16;
/// Largest calibration blob (`imu_cal::device::encode_blob`), bytes.
pub const MAX_CAL_BLOB: usize = 256;

// The largest sample batch frame fits the payload limit: version + postcard + CRC.
const _: () = assert!(1 + batch::MAX_SAMPLES_POSTCARD + 4 <= MAX_PAYLOAD);

/// One characterised channel of the device.
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Channel {
    Ax,
    Ay,
    Az,
    Gx,
    Gy,
    Gz,
    Mx,
    My,
    Mz,
    Temp,
}

impl Channel {
    /// All channels in wire order (the index used by [`Channel::index`]).
    pub const ALL: [Channel; 10] = [
        Channel::Ax,
        Channel::Ay,
        Channel::Az,
        Channel::Gx,
        Channel::Gy,
        Channel::Gz,
        Channel::Mx,
        Channel::My,
        Channel::Mz,
        Channel::Temp,
    ];

    /// Position in [`Channel::ALL`].
    pub fn index(self) -> usize {
        self as usize
    }

    /// Column name in the CSV contract (`ax` … `mz`, `temp`).
    pub fn name(self) -> &'static str {
        ["ax", "ay", "az", "gx", "gy", "gz", "mx", "my", "mz", "temp"][self as usize]
    }

    /// Contract unit of the channel after applying [`Scales`].
    pub fn unit(self) -> &'static str {
        match self {
            Channel::Ax | Channel::Ay | Channel::Az => "m/s²",
            Channel::Gx | Channel::Gy | Channel::Gz => "deg/s",
            Channel::Mx | Channel::My | Channel::Mz => "µT",
            Channel::Temp => "°C",
        }
    }
}

/// Conversion of wire integers to contract units: `value = lsb × scale` (and `+ temp_offset`
/// for temperature). Sent with every batch so a recording is self-describing.
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Scales {
    /// m/s² per LSB.
    pub accel: f32,
    /// deg/s per LSB.
    pub gyro: f32,
    /// µT per LSB.
    pub mag: f32,
    /// °C per LSB.
    pub temp: f32,
    /// °C added after scaling the temperature.
    pub temp_offset: f32,
}

impl Scales {
    /// Scale of one channel (contract unit per LSB).
    pub fn of(&self, ch: Channel) -> f32 {
        match ch {
            Channel::Ax | Channel::Ay | Channel::Az => self.accel,
            Channel::Gx | Channel::Gy | Channel::Gz => self.gyro,
            Channel::Mx | Channel::My | Channel::Mz => self.mag,
            Channel::Temp => self.temp,
        }
    }
}

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

/// Why a frame could not be encoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum EncodeError {
    /// The message does not fit in [`MAX_PAYLOAD`] or the output buffer.
    TooLarge,
}

/// Why a received frame was rejected.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum DecodeError {
    /// Not valid COBS.
    Cobs,
    /// Shorter than version + CRC.
    TooShort,
    /// Longer than [`MAX_FRAME`] before its delimiter.
    Oversize,
    /// CRC mismatch.
    Crc { expected: u32, found: u32 },
    /// Another protocol version.
    Version(u8),
    /// Valid CRC but not a known message (postcard could not parse it).
    Unknown,
    /// A message parsed but bytes were left over.
    Trailing,
}

impl core::fmt::Display for DecodeError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            DecodeError::Cobs => write!(f, "invalid COBS encoding"),
            DecodeError::TooShort => write!(f, "frame shorter than version + CRC (5 bytes)"),
            DecodeError::Oversize => write!(f, "frame longer than {MAX_FRAME} bytes"),
            DecodeError::Crc { expected, found } => {
                write!(
                    f,
                    "CRC mismatch: frame says {found:#010x}, content gives {expected:#010x}"
                )
            }
            DecodeError::Version(v) => {
                write!(
                    f,
                    "protocol version {v}, this build speaks {PROTOCOL_VERSION}"
                )
            }
            DecodeError::Unknown => write!(f, "unknown or malformed message"),
            DecodeError::Trailing => write!(f, "trailing bytes after the message"),
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for DecodeError {}

impl core::fmt::Display for EncodeError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "message larger than {MAX_PAYLOAD} bytes")
    }
}

#[cfg(feature = "std")]
impl std::error::Error for EncodeError {}

/// COBS-encodes `src` into `dst` (no delimiter); returns the encoded length, or `None` if `dst`
/// is shorter than [`cobs::max_encoding_length`]. Byte-for-byte the output of
/// `cobs::try_encode` (tested); the frame encoder runs the same stuffer with the CRC fused in.
/// Decoding stays with the `cobs` crate.
pub fn cobs_encode(src: &[u8], dst: &mut [u8]) -> Option<usize> {
    if dst.len() < cobs::max_encoding_length(src.len()) {
        return None;
    }
    let mut s = Stuffer::new(dst);
    s.extend::<false>(src, 0);
    s.finish()
}

/// COBS encoder state, fed in slices. It works a run at a time (the bytes up to the next zero
/// or the end of a 254-byte block): one scan, one copy, one code byte. A run that falls outside
/// `dst` is not copied, but the output position still advances, so [`Stuffer::finish`] reports
/// a too-small buffer and nothing can panic (every index written is below the final position).
struct Stuffer<'a> {
    dst: &'a mut [u8],
    /// Where the current block's code byte goes.
    code_at: usize,
    /// Where the next data byte goes; the block holds `out - code_at - 1` data bytes.
    out: usize,
}

/// Data bytes in a full COBS block (code byte 0xFF, no implied zero).
const COBS_BLOCK: usize = 254;

impl<'a> Stuffer<'a> {
    fn new(dst: &'a mut [u8]) -> Self {
        Self {
            dst,
            code_at: 0,
            out: 1,
        }
    }

    #[inline(always)]
    fn put(&mut self, at: usize, b: u8) {
        if let Some(slot) = self.dst.get_mut(at) {
            *slot = b;
        }
    }

    /// Stuff `src`; with `CRC`, also run `crc` (CRC-32/ISO-HDLC, reflected, not finalised) over
    /// it in the same scan and return it.
    fn extend<const CRC: bool>(&mut self, mut src: &[u8], mut crc: u32) -> u32 {
        while !src.is_empty() {
            let used = self.out - self.code_at - 1;
            if used == COBS_BLOCK {
                // A full block ends without an implied zero, only when more data follows.
                self.put(self.code_at, 0xFF);
                self.code_at = self.out;
                self.out += 1;
                continue;
            }
            let window = &src[..src.len().min(COBS_BLOCK - used)];
            // The run: the bytes before the first zero of the window, copied to the output.
            let run = match self.dst.get_mut(self.out..self.out + window.len()) {
                // The CRC scan copies as it goes (a separate `copy_from_slice` of the run
                // cost ≈ 180 cycles per sample set on the M0+: short, unaligned copies).
                Some(d) if CRC => crc_copy_run(window, d, &mut crc),
                Some(d) => {
                    let run = window.iter().position(|&b| b == 0).unwrap_or(window.len());
                    d[..run].copy_from_slice(&window[..run]);
                    run
                }
                // No room for the window: the frame cannot fit (every input byte takes one
                // output byte), `finish` reports it; keep counting.
                None if CRC => crc_run(window, &mut crc),
                None => window.iter().position(|&b| b == 0).unwrap_or(window.len()),
            };
            self.out += run;
            if run < window.len() {
                // The zero ends the block: its code byte says where.
                self.put(self.code_at, (self.out - self.code_at) as u8);
                self.code_at = self.out;
                self.out += 1;
                src = &src[run + 1..];
            } else {
                src = &src[run..];
            }
        }
        crc
    }

    /// Close the last block; the encoded length, or `None` if it did not fit `dst`.
    fn finish(mut self) -> Option<usize> {
        self.put(self.code_at, (self.out - self.code_at) as u8);
        (self.out <= self.dst.len()).then_some(self.out)
    }
}

/// The CRC-32/ISO-HDLC byte table (1 KiB, flash) generated by the `crc` crate: one copy, for
/// the fused pass of [`frame`] and for [`crc32`] on received frames.
static CRC_TABLE: [u32; 256] = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC).table()[0];
// `crc_step` hard-codes the reflected form with all-ones init and final XOR.
const _: () = assert!(
    crc::CRC_32_ISO_HDLC.refin
        && crc::CRC_32_ISO_HDLC.refout
        && crc::CRC_32_ISO_HDLC.init == u32::MAX
        && crc::CRC_32_ISO_HDLC.xorout == u32::MAX
);

/// One byte into a running (reflected, not finalised) CRC-32/ISO-HDLC.
#[inline(always)]
fn crc_step(crc: u32, b: u8) -> u32 {
    CRC_TABLE[usize::from(crc as u8 ^ b)] ^ (crc >> 8)
}

/// CRC-32/ISO-HDLC of `bytes` (`crc::CRC_32_ISO_HDLC`'s checksum; tested against it).
fn crc32(bytes: &[u8]) -> u32 {
    !bytes.iter().fold(u32::MAX, |c, &b| crc_step(c, b))
}

/// The bytes of `window` before its first zero (all of them if it has none), running `crc`
/// over them and the zero. Its own function so that, on the M0+, the loop keeps the pointer,
/// the CRC and the table in registers.
#[inline(never)]
fn crc_run(window: &[u8], crc: &mut u32) -> usize {
    let mut c = *crc;
    let mut run = window.len();
    for (i, &b) in window.iter().enumerate() {
        c = crc_step(c, b);
        if b == 0 {
            run = i;
            break;
        }
    }
    *crc = c;
    run
}

/// [`crc_run`] that also copies the bytes before the zero into `dst` (at least as long as
/// `window`).
#[inline(never)]
fn crc_copy_run(window: &[u8], dst: &mut [u8], crc: &mut u32) -> usize {
    let mut c = *crc;
    let mut run = window.len();
    for (i, (&b, d)) in window.iter().zip(dst.iter_mut()).enumerate() {
        c = crc_step(c, b);
        if b == 0 {
            run = i;
            break;
        }
        *d = b;
    }
    *crc = c;
    run
}

/// `content` (version byte + postcard) → `COBS(content | crc32 LE) 0x00` in `out`, in one scan
/// of `content` that updates the CRC and finds the zeros COBS replaces. Returns the frame
/// length (delimiter included).
fn frame(content: &[u8], out: &mut [u8]) -> Result<usize, EncodeError> {
    let mut s = Stuffer::new(out);
    let crc = !s.extend::<true>(content, u32::MAX);
    s.extend::<false>(&crc.to_le_bytes(), 0);
    let n = s.finish().ok_or(EncodeError::TooLarge)?;
    *out.get_mut(n).ok_or(EncodeError::TooLarge)? = 0;
    Ok(n + 1)
}

/// Serialises messages into frames; owns the scratch buffer for the un-stuffed payload.
pub struct FrameEncoder {
    scratch: [u8; MAX_PAYLOAD],
}

impl Default for FrameEncoder {
    fn default() -> Self {
        Self::new()
    }
}

impl FrameEncoder {
    pub const fn new() -> Self {
        Self {
            scratch: [0; MAX_PAYLOAD],
        }
    }

    /// Encode `msg` as one complete frame (trailing `0x00` included) into `out`; returns its
    /// length. `out` of [`MAX_FRAME`] bytes always suffices for a message within
    /// [`MAX_PAYLOAD`].
    pub fn encode<T: Serialize>(&mut self, msg: &T, out: &mut [u8]) -> Result<usize, EncodeError> {
        self.scratch[0] = PROTOCOL_VERSION;
        let body = postcard::to_slice(msg, &mut self.scratch[1..MAX_PAYLOAD - 4])
            .map_err(|_| EncodeError::TooLarge)?
            .len();
        frame(&self.scratch[..1 + body], out)
    }

    /// Encode `DeviceMsg::Samples(batch)` as one frame into `out`, byte for byte what
    /// [`FrameEncoder::encode`] writes for it (tested), without serde: the firmware's per-batch
    /// framing path (`batch.rs` writes the postcard bytes). `out` of [`MAX_FRAME`] bytes always
    /// suffices; a shorter one that cannot hold the frame gives [`EncodeError::TooLarge`].
    pub fn encode_samples(
        &mut self,
        batch: &SampleBatch,
        out: &mut [u8],
    ) -> Result<usize, EncodeError> {
        self.scratch[0] = PROTOCOL_VERSION;
        let body = batch::write(batch, &mut self.scratch[1..MAX_PAYLOAD - 4])
            .ok_or(EncodeError::TooLarge)?;
        frame(&self.scratch[..1 + body], out)
    }

    /// Encode into a fresh `Vec` (host convenience).
    #[cfg(feature = "std")]
    pub fn encode_vec<T: Serialize>(&mut self, msg: &T) -> Result<std::vec::Vec<u8>, EncodeError> {
        let mut out = std::vec![0u8; MAX_FRAME];
        let n = self.encode(msg, &mut out)?;
        out.truncate(n);
        Ok(out)
    }
}

/// Decode one frame's COBS bytes (without the `0x00` delimiter), in place.
pub fn decode<T: DeserializeOwned>(frame: &mut [u8]) -> Result<T, DecodeError> {
    if frame.len() > MAX_FRAME {
        return Err(DecodeError::Oversize);
    }
    if frame.contains(&0) {
        return Err(DecodeError::Cobs);
    }
    let n = cobs::decode_in_place(frame).map_err(|_| DecodeError::Cobs)?;
    let payload = frame.get(..n).ok_or(DecodeError::Cobs)?;
    if payload.len() < 5 {
        return Err(DecodeError::TooShort);
    }
    let (content, crc_bytes) = payload.split_at(payload.len() - 4);
    let found = u32::from_le_bytes([crc_bytes[0], crc_bytes[1], crc_bytes[2], crc_bytes[3]]);
    let expected = crc32(content);
    if expected != found {
        return Err(DecodeError::Crc { expected, found });
    }
    if content[0] != PROTOCOL_VERSION {
        return Err(DecodeError::Version(content[0]));
    }
    let (msg, rest) =
        postcard::take_from_bytes::<T>(&content[1..]).map_err(|_| DecodeError::Unknown)?;
    if !rest.is_empty() {
        return Err(DecodeError::Trailing);
    }
    Ok(msg)
}

/// Counts of received frames by outcome.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct RxStats {
    pub ok: u32,
    pub cobs: u32,
    pub too_short: u32,
    pub oversize: u32,
    pub crc: u32,
    pub version: u32,
    pub unknown: u32,
    pub trailing: u32,
}

impl RxStats {
    /// All rejected frames.
    pub fn rejected(&self) -> u32 {
        self.cobs
            .saturating_add(self.too_short)
            .saturating_add(self.oversize)
            .saturating_add(self.crc)
            .saturating_add(self.version)
            .saturating_add(self.unknown)
            .saturating_add(self.trailing)
    }

    fn count(&mut self, r: &Result<(), DecodeError>) {
        let c = match r {
            Ok(()) => &mut self.ok,
            Err(DecodeError::Cobs) => &mut self.cobs,
            Err(DecodeError::TooShort) => &mut self.too_short,
            Err(DecodeError::Oversize) => &mut self.oversize,
            Err(DecodeError::Crc { .. }) => &mut self.crc,
            Err(DecodeError::Version(_)) => &mut self.version,
            Err(DecodeError::Unknown) => &mut self.unknown,
            Err(DecodeError::Trailing) => &mut self.trailing,
        };
        *c = c.saturating_add(1);
    }
}

/// Splits a byte stream at `0x00` delimiters and decodes each frame; bytes of an oversized frame
/// are discarded up to the next delimiter. `N` is the largest frame accepted (COBS bytes).
pub struct FrameReader<const N: usize> {
    buf: [u8; N],
    len: usize,
    overflow: bool,
    stats: RxStats,
}

impl<const N: usize> Default for FrameReader<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> FrameReader<N> {
    pub const fn new() -> Self {
        Self {
            buf: [0; N],
            len: 0,
            overflow: false,
            stats: RxStats {
                ok: 0,
                cobs: 0,
                too_short: 0,
                oversize: 0,
                crc: 0,
                version: 0,
                unknown: 0,
                trailing: 0,
            },
        }
    }

    /// Counters so far.
    pub fn stats(&self) -> RxStats {
        self.stats
    }

    /// Bytes buffered towards the next frame.
    pub fn pending(&self) -> usize {
        self.len
    }

    /// Feed one byte; returns a decoded message (or the reason the frame was rejected) when the
    /// byte ends a frame. Empty frames (consecutive delimiters) are skipped silently.
    pub fn push<T: DeserializeOwned>(&mut self, byte: u8) -> Option<Result<T, DecodeError>> {
        if byte != 0 {
            if self.len < N {
                self.buf[self.len] = byte;
                self.len += 1;
            } else {
                self.overflow = true;
            }
            return None;
        }
        let result = if self.overflow {
            Err(DecodeError::Oversize)
        } else if self.len == 0 {
            return None;
        } else {
            decode::<T>(&mut self.buf[..self.len])
        };
        self.len = 0;
        self.overflow = false;
        self.stats
            .count(&result.as_ref().map(|_| ()).map_err(|e| *e));
        Some(result)
    }

    /// Feed a slice, calling `f` for every completed frame.
    pub fn feed<T: DeserializeOwned>(
        &mut self,
        data: &[u8],
        mut f: impl FnMut(Result<T, DecodeError>),
    ) {
        for &b in data {
            if let Some(r) = self.push::<T>(b) {
                f(r);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The table-driven CRC gives CRC-32/ISO-HDLC: the catalogue's check value, and the `crc`
    /// crate's checksum for every prefix of a byte string with zeros and 0xFF in it.
    #[test]
    fn crc32_is_crc_32_iso_hdlc() {
        assert_eq!(crc32(b"123456789"), crc::CRC_32_ISO_HDLC.check);
        assert_eq!(crc32(b""), 0);
        let reference = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC);
        let bytes: [u8; 300] = core::array::from_fn(|i| (i * 37 % 256) as u8);
        for n in 0..bytes.len() {
            assert_eq!(crc32(&bytes[..n]), reference.checksum(&bytes[..n]), "{n}");
        }
    }
}
