//! The per-sample pipeline and the host request handling, as one state machine owned by the
//! processing task.
//!
//! Per IMU sample, in a straight line: fixed-point correction (`imu_cal::device`) → one
//! `push` per channel into the streaming Allan engines (`allan::stream`) → append to the
//! sample batch → when the batch is full, one frame to the outbox. The magnetometer path is the
//! same at 200 Hz. Nothing on this path allocates, divides or touches floating point.
//!
//! Gaps (FIFO overflow, a lost sensor, a pause for a flash write) call `gap()` on the
//! affected engines, so no Allan difference ever straddles missing data.
use allan::stream::{DeviceEngine, LevelSums, MagEngine};
use imu_cal::device::{decode_blob, encode_blob, BlobError, Calibration, Prepared, MAX_BLOB_LEN};
use imu_drivers::mpu6050::RawSample;
use imu_proto::{
    AllanLevel, AllanTable, CalFault, CalSource, CalStatus, Channel, DeviceMsg, DeviceMsgRef,
    ErrorCode, Event, GapCause, HostFrame, Identity, ImuSample, MagSample, Reply, Request,
    SampleBatch, Scales, Sensor, SensorState, Status, StreamMode, Vec, MAX_CAL_BLOB,
    PROTOCOL_VERSION,
};

use crate::outbox::{FrameSink, Outbox, Sent};
use crate::stage::{self, Stage};

/// IMU output data rate, Hz (MPU-6050: 1 kHz gyro rate with the DLPF on, SMPLRT_DIV = 0).
pub const IMU_RATE_HZ: u32 = 1000;
/// IMU sample period, µs.
pub const IMU_PERIOD_US: u64 = 1_000_000 / IMU_RATE_HZ as u64;
/// Magnetometer output data rate, Hz (QMC5883L ODR = 200 Hz).
pub const MAG_RATE_HZ: u32 = 200;
/// Magnetometer sample period, µs.
pub const MAG_PERIOD_US: u64 = 1_000_000 / MAG_RATE_HZ as u64;
/// Channels with an Allan engine (ax ay az gx gy gz mx my mz temp).
pub const CHANNELS: usize = 10;
/// Allan engine overlap factor and levels (must match `allan::stream::DeviceEngine` for the
/// 1 kHz channels and `allan::stream::MagEngine` for the 200 Hz magnetometer: both reach
/// τ ≈ 2.3–2.9 h).
pub const ALLAN_OVERLAP: u8 = 8;
pub const ALLAN_LEVELS: u8 = 24;
pub const ALLAN_LEVELS_MAG: u8 = 22;

/// Largest burst one [`SensorMsg::Imu`] carries: a 10 ms burst holds 10 frames (13 when it
/// falls back to its timer), so 16 covers it in one I2C transfer.
pub const BURST_MAX: usize = 16;

/// What the sensor tasks tell the processing task.
#[derive(Debug, Clone)]
#[allow(clippy::large_enum_variant)] // no heap: the burst travels inline through the channel
pub enum SensorMsg {
    /// FIFO frames in arrival order; `t_us` is the time of the last one (µs since boot).
    Imu {
        t_us: u64,
        samples: Vec<RawSample, BURST_MAX>,
    },
    /// The FIFO overflowed and was reset; about `lost` samples are gone.
    ImuOverflow { t_us: u64, lost: u32 },
    /// One magnetometer reading; `skipped`: the sensor overwrote at least one unread sample
    /// before this one (QMC5883L DOR), a gap in the 200 Hz series.
    Mag {
        t_us: u64,
        xyz: [i16; 3],
        skipped: bool,
    },
    /// A failed transfer, a loss, a recovery or a return.
    Fault(Fault),
    /// Sampling resumed after a pause (flash write): a gap in every channel.
    Resumed { t_us: u64 },
}

/// A sensor task's fault report.
#[derive(Debug, Clone, Copy)]
pub struct Fault {
    pub sensor: imu_proto::Sensor,
    /// Failed I2C transfers since the last report.
    pub i2c_errors: u32,
    /// Bus recoveries performed since the last report.
    pub recoveries: u32,
    /// Health after this report.
    pub state: SensorState,
    /// Lost/back event to forward to the host.
    pub event: Option<Event>,
    /// Samples not taken during an outage that ended now.
    pub lost: u32,
}

/// A calibration the host asked to persist; the firmware pauses sampling, writes it and
/// reports back through [`Device::persisted`].
#[derive(Debug, Clone)]
pub struct PersistRequest {
    pub id: u16,
    pub blob: Vec<u8, MAX_CAL_BLOB>,
}

/// Counters reported in [`Status`].
#[derive(Debug, Clone, Copy, Default)]
pub struct Counters {
    pub samples_taken: u64,
    pub samples_dropped: u64,
    pub mag_samples: u64,
    pub fifo_overflows: u32,
    pub i2c_errors: u32,
    pub bus_recoveries: u32,
    pub frames_rejected: u32,
}

/// The Allan engines: the seven 1 kHz channels (ax ay az gx gy gz temp, in that order) and the
/// three 200 Hz magnetometer channels, each sized for the same reach in seconds.
struct Engines {
    imu: [DeviceEngine; 7],
    mag: [MagEngine; 3],
    /// The last IMU sample of a burst that did not complete a pair: it waits for the first of
    /// the next burst, so the IMU engines take every sample in pairs (`push_pair`, two samples
    /// in one hand-scheduled Thumb call) and their counts stay even. Not yet pushed: a table's
    /// `pushed` leaves it out, and a split pushes it first (it came before the gap).
    imu_pending: Option<ImuInputs>,
}

/// The seven IMU engines' inputs for one sample: corrected accel, gyro and the raw temperature.
type ImuInputs = ([i32; 3], [i32; 3], i32);

/// Bytes of Allan state on the device: the ten engines (size_of on the target, checked against
/// the 32 KiB budget at compile time).
pub const ALLAN_STATE_BYTES: usize = core::mem::size_of::<Engines>();
const _: () = assert!(ALLAN_STATE_BYTES <= 32 * 1024, "Allan state over 32 KiB");

/// One channel's engine, whichever its configuration.
#[derive(Clone, Copy)]
enum EngineRef<'a> {
    Imu(&'a DeviceEngine),
    Mag(&'a MagEngine),
}

impl<'a> EngineRef<'a> {
    fn samples(self) -> u64 {
        match self {
            EngineRef::Imu(e) => e.samples(),
            EngineRef::Mag(e) => e.samples(),
        }
    }

    fn gaps(self) -> u32 {
        match self {
            EngineRef::Imu(e) => e.gaps(),
            EngineRef::Mag(e) => e.gaps(),
        }
    }

    fn levels(self) -> impl Iterator<Item = LevelSums> + 'a {
        (0..usize::from(ALLAN_LEVELS)).map_while(move |k| match self {
            EngineRef::Imu(e) => e.level(k),
            EngineRef::Mag(e) => e.level(k),
        })
    }
}

impl Engines {
    fn new() -> Self {
        Engines {
            imu: core::array::from_fn(|_| DeviceEngine::new()),
            mag: core::array::from_fn(|_| MagEngine::new()),
            imu_pending: None,
        }
    }

    /// Push a burst of IMU samples, in pairs (see `imu_pending`).
    fn push_imu(&mut self, burst: &[ImuInputs]) {
        let mut rest = burst;
        if let Some(first) = self.imu_pending.take() {
            match rest.split_first() {
                Some((second, tail)) => {
                    self.push_imu_pair(&first, second);
                    rest = tail;
                }
                None => {
                    self.imu_pending = Some(first);
                    return;
                }
            }
        }
        let mut pairs = rest.chunks_exact(2);
        for pair in &mut pairs {
            self.push_imu_pair(&pair[0], &pair[1]);
        }
        if let [last] = pairs.remainder() {
            self.imu_pending = Some(*last);
        }
    }

    fn push_imu_one(&mut self, (accel, gyro, temp): &ImuInputs) {
        let [ax, ay, az, gx, gy, gz, t] = &mut self.imu;
        ax.push(accel[0]);
        ay.push(accel[1]);
        az.push(accel[2]);
        gx.push(gyro[0]);
        gy.push(gyro[1]);
        gz.push(gyro[2]);
        t.push(*temp);
    }

    fn push_imu_pair(&mut self, (a0, g0, t0): &ImuInputs, (a1, g1, t1): &ImuInputs) {
        let [ax, ay, az, gx, gy, gz, t] = &mut self.imu;
        ax.push_pair(a0[0], a1[0]);
        ay.push_pair(a0[1], a1[1]);
        az.push_pair(a0[2], a1[2]);
        gx.push_pair(g0[0], g1[0]);
        gy.push_pair(g0[1], g1[1]);
        gz.push_pair(g0[2], g1[2]);
        t.push_pair(*t0, *t1);
    }

    fn of(&self, ch: Channel) -> EngineRef<'_> {
        match ch {
            Channel::Mx => EngineRef::Mag(&self.mag[0]),
            Channel::My => EngineRef::Mag(&self.mag[1]),
            Channel::Mz => EngineRef::Mag(&self.mag[2]),
            Channel::Ax => EngineRef::Imu(&self.imu[0]),
            Channel::Ay => EngineRef::Imu(&self.imu[1]),
            Channel::Az => EngineRef::Imu(&self.imu[2]),
            Channel::Gx => EngineRef::Imu(&self.imu[3]),
            Channel::Gy => EngineRef::Imu(&self.imu[4]),
            Channel::Gz => EngineRef::Imu(&self.imu[5]),
            Channel::Temp => EngineRef::Imu(&self.imu[6]),
        }
    }

    /// Split a sensor's engines; returns the split position (samples pushed) when the split
    /// counted, i.e. when the segment it closed was not empty.
    fn split(&mut self, sensor: Sensor) -> Option<u64> {
        let (before, after, at) = match sensor {
            Sensor::Imu => {
                if let Some(last) = self.imu_pending.take() {
                    self.push_imu_one(&last);
                }
                let before = self.imu[0].gaps();
                self.imu.iter_mut().for_each(DeviceEngine::gap);
                (before, self.imu[0].gaps(), self.imu[0].samples())
            }
            Sensor::Mag => {
                let before = self.mag[0].gaps();
                self.mag.iter_mut().for_each(MagEngine::gap);
                (before, self.mag[0].gaps(), self.mag[0].samples())
            }
        };
        (after != before).then_some(at)
    }

    fn reset(&mut self) {
        // A waiting sample was taken before the reset: forgotten with the rest.
        self.imu_pending = None;
        self.imu.iter_mut().for_each(DeviceEngine::reset);
        self.mag.iter_mut().for_each(MagEngine::reset);
    }
}

/// The device state machine.
pub struct Device {
    /// The calibration as stored and reported; set only through [`Device::set_cal`].
    cal: Calibration,
    /// The same, prepared for the per-sample path (split coefficients, diagonal fast path).
    fast: Prepared,
    cal_status: CalStatus,
    engines: Engines,
    scales: Scales,
    mode: StreamMode,
    status_ms: u32,
    tables_ms: u32,
    batch: SampleBatch,
    imu_seq: u32,
    mag_seq: u32,
    pub counters: Counters,
    imu_state: SensorState,
    mag_state: SensorState,
    last_temp: Option<i16>,
    /// Read time of the last magnetometer sample, µs.
    last_mag_us: Option<u64>,
    /// Stamp of the last IMU sample, µs (stamps never go backwards).
    last_imu_us: Option<u64>,
    /// Next channel of a table round in progress.
    table_next: Option<usize>,
    /// The table being computed: a snapshot of the engine's sums and the rows done so far.
    building: Option<(Vec<LevelSums, { imu_proto::MAX_LEVELS }>, AllanTable)>,
    outbox: Outbox,
    firmware: &'static str,
}

impl Device {
    /// A device with identity corrections, streaming calibrated samples, status every 1 s and
    /// tables every 10 s. `scales` converts corrected counts to contract units.
    pub fn new(scales: Scales, firmware: &'static str) -> Self {
        Self {
            cal: Calibration::identity(),
            fast: Prepared::new(&Calibration::identity()),
            cal_status: CalStatus {
                source: CalSource::Identity,
                fault: None,
            },
            engines: Engines::new(),
            scales,
            mode: StreamMode::Calibrated,
            status_ms: 1000,
            tables_ms: 10_000,
            batch: SampleBatch {
                calibrated: true,
                scales,
                imu: Vec::new(),
                mag: Vec::new(),
            },
            imu_seq: 0,
            mag_seq: 0,
            counters: Counters::default(),
            imu_state: SensorState::Unknown,
            mag_state: SensorState::Unknown,
            last_temp: None,
            last_mag_us: None,
            last_imu_us: None,
            table_next: None,
            building: None,
            outbox: Outbox::new(),
            firmware,
        }
    }

    fn set_cal(&mut self, cal: Calibration) {
        self.cal = cal;
        self.fast = Prepared::new(&cal);
    }

    /// Use a blob read from flash at boot; a bad one is reported and identity kept.
    pub fn load_stored(&mut self, blob: Option<&[u8]>) {
        match blob.map(decode_blob) {
            None => {
                self.cal_status = CalStatus {
                    source: CalSource::Identity,
                    fault: None,
                }
            }
            Some(Ok(cal)) => {
                self.set_cal(cal);
                self.cal_status = CalStatus {
                    source: CalSource::Flash,
                    fault: None,
                };
            }
            Some(Err(e)) => {
                self.set_cal(Calibration::identity());
                self.cal_status = CalStatus {
                    source: CalSource::Identity,
                    fault: Some(cal_fault(e)),
                };
            }
        }
    }

    /// The flash could not be read at boot.
    pub fn flash_unreadable(&mut self) {
        self.cal_status = CalStatus {
            source: CalSource::Identity,
            fault: Some(CalFault::Flash),
        };
    }

    pub fn cal_status(&self) -> CalStatus {
        self.cal_status
    }

    pub fn mode(&self) -> StreamMode {
        self.mode
    }

    /// Status frame interval, ms (0 = off).
    pub fn status_interval_ms(&self) -> u32 {
        self.status_ms
    }

    /// Table round interval, ms (0 = off).
    pub fn tables_interval_ms(&self) -> u32 {
        self.tables_ms
    }

    /// Frames dropped because the host was not reading.
    pub fn frames_unsent(&self) -> u32 {
        self.outbox.unsent
    }

    /// Feed one sensor message through the pipeline.
    pub fn on_sensor(&mut self, msg: &SensorMsg, sink: &mut impl FrameSink) {
        match msg {
            SensorMsg::Imu { t_us, samples } => self.imu_burst(samples, *t_us, sink),
            SensorMsg::ImuOverflow { t_us, lost } => {
                self.counters.fifo_overflows = self.counters.fifo_overflows.saturating_add(1);
                self.counters.samples_dropped = self
                    .counters
                    .samples_dropped
                    .saturating_add(u64::from(*lost));
                self.split(Sensor::Imu, GapCause::FifoOverflow, sink);
                self.send(
                    &DeviceMsg::Event(Event::FifoOverflow {
                        t_us: *t_us,
                        lost: *lost,
                    }),
                    sink,
                );
            }
            SensorMsg::Mag { t_us, xyz, skipped } => {
                // A gap when the chip says it overwrote a sample (DOR), or when more than 1.5
                // periods passed since the last reading: reads land 0–2 ms after their slot
                // (DRDY re-polls), so consecutive samples are 3–7 ms apart and a missed one makes
                // it ≥ 8 ms, whatever the cause — including a failed read that cleared DOR before
                // the firmware saw it. A delayed read that lost nothing is split too: a needless
                // gap costs a few terms, a missed one would bias the tables silently.
                let late = self
                    .last_mag_us
                    .is_some_and(|l| t_us.saturating_sub(l) > MAG_PERIOD_US * 3 / 2);
                self.last_mag_us = Some(*t_us);
                if *skipped {
                    self.split(Sensor::Mag, GapCause::Overwritten, sink);
                } else if late {
                    self.split(Sensor::Mag, GapCause::Late, sink);
                }
                self.mag_sample(*xyz, *t_us, sink)
            }
            SensorMsg::Fault(f) => {
                self.counters.i2c_errors = self.counters.i2c_errors.saturating_add(f.i2c_errors);
                self.counters.bus_recoveries =
                    self.counters.bus_recoveries.saturating_add(f.recoveries);
                match f.sensor {
                    Sensor::Imu => self.imu_state = f.state,
                    Sensor::Mag => self.mag_state = f.state,
                }
                if f.state != SensorState::Ok {
                    self.split(f.sensor, GapCause::SensorFault, sink);
                }
                if f.sensor == imu_proto::Sensor::Imu {
                    self.counters.samples_dropped = self
                        .counters
                        .samples_dropped
                        .saturating_add(u64::from(f.lost));
                }
                if let Some(e) = f.event {
                    self.send(&DeviceMsg::Event(e), sink);
                }
            }
            SensorMsg::Resumed { .. } => {
                self.split(Sensor::Imu, GapCause::Paused, sink);
                self.split(Sensor::Mag, GapCause::Paused, sink);
            }
        }
    }

    /// Split one sensor's series in its Allan engines, and tell the host where (in samples
    /// pushed), so a replay of the same samples can split at the same place. A split of an empty
    /// segment changes nothing and is not reported.
    fn split(&mut self, sensor: Sensor, cause: GapCause, sink: &mut impl FrameSink) {
        if let Some(at) = self.engines.split(sensor) {
            self.send(&DeviceMsg::Event(Event::Gap { sensor, at, cause }), sink);
        }
    }

    /// The per-sample path for one FIFO burst. Sample `i` of `n` is stamped
    /// `t_read − (n−1−i)·1 ms`: the FIFO is paced by the sensor's own clock, so the
    /// timestamps are reconstructed from the read time (docs/firmware.md).
    fn imu_burst(&mut self, samples: &[RawSample], t_read_us: u64, sink: &mut impl FrameSink) {
        // Three passes over the burst, one per budget stage (docs/emulator.md, cycle markers):
        // corrections, Allan update, framing. Each sample still goes through all three in order.
        // A `Vec`, not a zeroed array: nothing to clear before it is filled.
        let mut fixed: Vec<ImuInputs, BURST_MAX> = Vec::new();
        let samples = &samples[..samples.len().min(BURST_MAX)];
        stage::enter(Stage::Corrections);
        for s in samples {
            let temp = s.temp.or(self.last_temp).unwrap_or(0);
            self.last_temp = Some(temp);
            // At most BURST_MAX samples (cut above): never full.
            let _ = fixed.push((
                self.fast.apply_accel(s.accel),
                self.fast.apply_gyro(s.gyro, temp),
                i32::from(temp),
            ));
        }
        stage::enter(Stage::Allan);
        self.engines.push_imu(&fixed);
        stage::enter(Stage::Usb);
        let n = samples.len() as u32;
        let raw = self.mode == StreamMode::Raw;
        for (i, (s, (accel, gyro, temp))) in samples.iter().zip(&fixed).enumerate() {
            let seq = self.imu_seq;
            self.imu_seq = self.imu_seq.wrapping_add(1);
            self.counters.samples_taken += 1;
            // The read-time estimate is late by the burst's transfer time (up to ≈ 2 ms), which
            // varies from burst to burst: the first stamp of a burst can fall before the last
            // one of the previous burst. Stamps are kept increasing (1 µs after the previous).
            // In u32 (at most BURST_MAX − 1 periods): a u64 multiply is a library call here.
            let back = (n - 1 - i as u32) * IMU_PERIOD_US as u32;
            let nominal = t_read_us.saturating_sub(u64::from(back));
            let t_us = match self.last_imu_us {
                Some(last) if nominal <= last => last + 1,
                _ => nominal,
            };
            self.last_imu_us = Some(t_us);
            if self.mode == StreamMode::Off {
                continue;
            }
            let out = ImuSample {
                seq,
                t_us,
                accel: if raw { s.accel.map(i32::from) } else { *accel },
                gyro: if raw { s.gyro.map(i32::from) } else { *gyro },
                temp: *temp,
            };
            if self.batch.imu.push(out).is_err() {
                self.flush(sink);
                // The batch was just emptied, so this cannot fail; ignore rather than panic.
                let _ = self.batch.imu.push(out);
            }
            if self.batch.imu.is_full() {
                self.flush(sink);
            }
        }
        stage::leave();
    }

    fn mag_sample(&mut self, xyz: [i16; 3], t_us: u64, sink: &mut impl FrameSink) {
        stage::enter(Stage::Corrections);
        let mag = self.fast.apply_mag(xyz);
        stage::enter(Stage::Allan);
        for (e, &v) in self.engines.mag.iter_mut().zip(&mag) {
            e.push(v);
        }
        stage::enter(Stage::Usb);
        let seq = self.mag_seq;
        self.mag_seq = self.mag_seq.wrapping_add(1);
        self.counters.mag_samples += 1;
        if self.mode != StreamMode::Off {
            let out = MagSample {
                seq,
                t_us,
                mag: if self.mode == StreamMode::Raw {
                    xyz.map(i32::from)
                } else {
                    mag
                },
            };
            if self.batch.mag.push(out).is_err() {
                self.flush(sink);
                let _ = self.batch.mag.push(out);
            }
            if self.batch.mag.is_full() {
                self.flush(sink);
            }
        }
        stage::leave();
    }

    /// Send the batch assembled so far (if any).
    pub fn flush(&mut self, sink: &mut impl FrameSink) {
        if self.batch.imu.is_empty() && self.batch.mag.is_empty() {
            return;
        }
        self.batch.calibrated = self.mode != StreamMode::Raw;
        self.batch.scales = self.scales;
        // Framed in place (no copy of the batch into a `DeviceMsg`), then emptied.
        self.outbox.send_samples(&self.batch, sink);
        self.batch.imu.clear();
        self.batch.mag.clear();
    }

    fn send(&mut self, msg: &DeviceMsg, sink: &mut impl FrameSink) -> Sent {
        self.outbox.send(msg, sink)
    }

    /// Counters and health now.
    pub fn status(&self, uptime_us: u64, cpu_load_permille: u16) -> Status {
        let s = self.scales;
        let temp_milli_c = self
            .last_temp
            .map(|t| ((f32::from(t) * s.temp + s.temp_offset) * 1000.0) as i32)
            .unwrap_or(i32::MIN);
        Status {
            uptime_us,
            samples_taken: self.counters.samples_taken,
            samples_dropped: self.counters.samples_dropped,
            mag_samples: self.counters.mag_samples,
            fifo_overflows: self.counters.fifo_overflows,
            i2c_errors: self.counters.i2c_errors,
            bus_recoveries: self.counters.bus_recoveries,
            frames_rejected: self.counters.frames_rejected,
            frames_unsent: self.outbox.unsent,
            cpu_load_permille,
            temp_milli_c,
            imu: self.imu_state,
            mag: self.mag_state,
            cal: self.cal_status,
            mode: self.mode,
        }
    }

    /// Send a status frame.
    pub fn send_status(
        &mut self,
        uptime_us: u64,
        cpu_load_permille: u16,
        sink: &mut impl FrameSink,
    ) -> Sent {
        let st = self.status(uptime_us, cpu_load_permille);
        self.outbox.send(&DeviceMsgRef::Status(&st), sink)
    }

    /// Whether the magnetometer is delivering samples (table work is then scheduled right
    /// after its reads; see `process_task`).
    pub fn mag_ok(&self) -> bool {
        self.mag_state == SensorState::Ok
    }

    /// Start a round of table frames (one per channel, sent by [`Device::tables_step`]).
    /// A round in progress is not restarted.
    pub fn start_tables(&mut self) {
        if self.table_next.is_none() {
            self.table_next = Some(0);
        }
    }

    /// Whether a table round is in progress.
    pub fn tables_pending(&self) -> bool {
        self.table_next.is_some()
    }

    /// Advance the table round by at most [`ROWS_PER_STEP`] rows; when a table is complete and
    /// the queue has room for it, send it and return it (for the defmt log). Tables wait for
    /// room rather than being dropped. A row costs ≈ 0.33 ms of M0+ time (soft-float square
    /// roots), a whole table ≈ 4.7 ms (measured in the emulator), more than a magnetometer
    /// period: computed in one go, it made the magnetometer miss samples. The sums are
    /// snapshotted when a table starts, so each table is one instant's state.
    pub fn tables_step(&mut self, sink: &mut impl FrameSink) -> Option<AllanTable> {
        let c = self.table_next?;
        if self.building.is_none() {
            let ch = Channel::ALL[c];
            let e = self.engines.of(ch);
            let (tau0_us, scale) = self.tau0_scale(ch);
            let snap = e.levels().filter(|l| l.n2 > 0).collect();
            let head = AllanTable {
                channel: ch,
                tau0_us,
                scale,
                pushed: e.samples(),
                gaps: e.gaps(),
                levels: Vec::new(),
            };
            self.building = Some((snap, head));
        }
        let (snap, t) = self.building.as_mut()?;
        for l in snap.iter().skip(t.levels.len()).take(ROWS_PER_STEP) {
            let _ = t.levels.push(level_row(l, t.tau0_us, t.scale));
        }
        if t.levels.len() < snap.len() || sink.room() < TABLE_FRAME_ROOM {
            return None;
        }
        let (_, t) = self.building.take()?;
        self.outbox.send(&DeviceMsgRef::Table(&t), sink);
        self.table_next = if c + 1 < CHANNELS { Some(c + 1) } else { None };
        Some(t)
    }

    fn tau0_scale(&self, ch: Channel) -> (u32, f32) {
        match ch {
            Channel::Mx | Channel::My | Channel::Mz => (MAG_PERIOD_US as u32, self.scales.mag),
            _ => (IMU_PERIOD_US as u32, self.scales.of(ch)),
        }
    }

    /// The Allan table of one channel computed at once (tests, and the rows' reference): the
    /// engine's exact sums plus the deviation and its 68.3 % bounds in contract units
    /// ([`level_row`]).
    pub fn table(&self, ch: Channel) -> AllanTable {
        let e = self.engines.of(ch);
        let (tau0_us, scale) = self.tau0_scale(ch);
        let mut levels = Vec::new();
        for l in e.levels().filter(|l| l.n2 > 0) {
            let _ = levels.push(level_row(&l, tau0_us, scale));
        }
        AllanTable {
            channel: ch,
            tau0_us,
            scale,
            pushed: e.samples(),
            gaps: e.gaps(),
            levels,
        }
    }

    /// Who we are.
    pub fn identity(&self) -> Identity {
        Identity {
            protocol: PROTOCOL_VERSION,
            firmware: imu_proto::String::try_from(self.firmware).unwrap_or_default(),
            board: imu_proto::String::try_from("Raspberry Pi Pico W").unwrap_or_default(),
            imu_rate_hz: IMU_RATE_HZ as u16,
            mag_rate_hz: MAG_RATE_HZ as u16,
            allan_overlap: ALLAN_OVERLAP,
            allan_levels: ALLAN_LEVELS,
            allan_levels_mag: ALLAN_LEVELS_MAG,
        }
    }

    /// Handle one host request. Returns a [`PersistRequest`] when the calibration must be
    /// written to flash (the reply then comes from [`Device::persisted`]).
    pub fn handle(
        &mut self,
        frame: HostFrame,
        uptime_us: u64,
        cpu: u16,
        sink: &mut impl FrameSink,
    ) -> Option<PersistRequest> {
        let id = frame.id;
        let reply = match frame.req {
            Request::Identify => Reply::Identity(self.identity()),
            Request::GetStatus => Reply::Status(self.status(uptime_us, cpu)),
            Request::GetCalibration => {
                let mut buf = [0u8; MAX_BLOB_LEN];
                match encode_blob(&self.cal, &mut buf) {
                    Ok(b) => Reply::Calibration {
                        blob: Vec::from_slice(b).unwrap_or_default(),
                        status: self.cal_status,
                    },
                    Err(_) => Reply::Error(ErrorCode::BadCalibration),
                }
            }
            Request::SetCalibration { blob, persist } => match decode_blob(&blob) {
                Ok(cal) => {
                    self.set_cal(cal);
                    self.cal_status = CalStatus {
                        source: CalSource::Host,
                        fault: None,
                    };
                    // New corrections change the engines' input: old sums would mix scales.
                    self.reset_allan();
                    if persist {
                        return Some(PersistRequest { id, blob });
                    }
                    Reply::Ok
                }
                Err(_) => Reply::Error(ErrorCode::BadCalibration),
            },
            Request::ResetAllan => {
                self.reset_allan();
                Reply::Ok
            }
            Request::SetMode(m) => {
                self.flush(sink);
                self.mode = m;
                Reply::Ok
            }
            Request::SetIntervals {
                status_ms,
                tables_ms,
            } => {
                self.status_ms = status_ms;
                self.tables_ms = tables_ms;
                Reply::Ok
            }
            Request::GetTables => {
                self.start_tables();
                Reply::Ok
            }
        };
        self.send(&DeviceMsg::Reply { id, reply }, sink);
        None
    }

    /// Report the outcome of a [`PersistRequest`].
    pub fn persisted(&mut self, id: u16, ok: bool, sink: &mut impl FrameSink) {
        let reply = if ok {
            self.cal_status = CalStatus {
                source: CalSource::Flash,
                fault: None,
            };
            Reply::Ok
        } else {
            self.cal_status.fault = Some(CalFault::Flash);
            Reply::Error(ErrorCode::FlashWrite)
        };
        self.send(&DeviceMsg::Reply { id, reply }, sink);
    }

    /// A host frame was rejected by the decoder.
    pub fn rejected_frame(&mut self) {
        self.counters.frames_rejected = self.counters.frames_rejected.saturating_add(1);
    }

    /// Forget all Allan state and restart the sample numbering.
    pub fn reset_allan(&mut self) {
        self.engines.reset();
        // A table being computed describes the old state: drop it (the round goes on).
        self.building = None;
        self.imu_seq = 0;
        self.mag_seq = 0;
    }
}

/// Table rows computed per [`Device::tables_step`] call (≈ 0.7 ms of M0+ time).
pub const ROWS_PER_STEP: usize = 2;

/// Queue room a table frame needs (a full table with worst-case varints is < 2.2 KiB).
pub const TABLE_FRAME_ROOM: usize = 2304;

fn cal_fault(e: BlobError) -> CalFault {
    match e {
        BlobError::WrongVersion { found, .. } => CalFault::OldVersion(found.min(255) as u8),
        _ => CalFault::Corrupt,
    }
}

/// One table row from the engine's sums (off the hot path; f64 is soft-float on the M0+, so
/// the bounds use closed forms only):
/// * EDF: the white-FM formula of NIST SP 1065 Table 5 for overlapping ADEV
///   (`allan::ci::edf_simple(0, m, N)`, N the phase points of the level). White FM (angle/
///   velocity random walk) is the noise that dominates an IMU's short τ; the device does not
///   identify the noise type, because the slope of a DLPF-shaped curve misleads the simple
///   identification and Greenhall's general algorithm costs ~0.4 s of M0+ time per table;
/// * χ² quantiles: Wilson & Hilferty (1931), χ²_p(ν) ≈ ν·(1 − 2/(9ν) + z_p·√(2/(9ν)))³ with
///   z = ∓1 for the 68.3 % interval (the quantiles of the normal at 15.87 % and 84.13 %);
/// * bounds: `σ·√(ν/χ²)` (SP 1065 eq. 45).
///
/// The host recomputes exact Greenhall EDFs and χ² quantiles from the same integer sums when
/// it needs them (`imu-lab device tables`).
pub fn level_row(l: &LevelSums, tau0_us: u32, scale: f32) -> AllanLevel {
    let dev = l.oadev(f64::from(scale)).unwrap_or(0.0);
    let edf = allan::ci::edf_simple(0, f64::from(l.m), l.phase_points());
    let edf = if edf.is_finite() && edf > 0.0 {
        edf
    } else {
        1.0
    };
    let (lo, hi) = (
        dev * libm::sqrt(edf / chi2_wh(edf, 1.0)),
        dev * libm::sqrt(edf / chi2_wh(edf, -1.0)),
    );
    AllanLevel {
        m: l.m,
        stride: l.stride,
        n2: l.n2,
        sum2: l.sum2,
        n3: l.n3,
        sum3: l.sum3,
        tau_s: (f64::from(l.m) * f64::from(tau0_us) * 1e-6) as f32,
        dev: dev as f32,
        edf: edf as f32,
        lo: lo as f32,
        hi: hi as f32,
    }
}

/// Wilson–Hilferty approximation of the χ² quantile with `nu` degrees of freedom at the normal
/// quantile `z` (clamped positive for very small ν, where the cube would go negative).
pub fn chi2_wh(nu: f64, z: f64) -> f64 {
    let k = 2.0 / (9.0 * nu);
    let c = 1.0 - k + z * libm::sqrt(k);
    (nu * c * c * c).max(1e-9 * nu)
}
