//! The sample path: per burst, in a straight line, fixed-point corrections (`imu_cal::device`)
//! → the Allan engines (`allan::stream`) → the sample batch → one frame per full batch. Nothing
//! on the 1 kHz path allocates, divides or touches floating point: it sums the corrected gyro
//! and accelerometer for the attitude filter ([`crate::ahrs`]). Each magnetometer sample queues
//! one filter update with those sums; the processing task runs the queued updates
//! ([`Pipeline::attitude_step`], integer arithmetic, ≈ 2,900 cycles each with their share of
//! the frame) where their delay does not disturb the sensor tasks (src/main.rs: in line with an
//! IMU burst's processing), and the estimates go out five to a frame.
//!
//! Every sample carries its slot on its sensor's grid; a slot skipped since the previous
//! sample is a loss: counted, split in the engines (no Allan difference straddles it) and
//! reported as an `Event::Gap` with its cause, before the sample.
use imu_cal::device::{Calibration, Prepared};
use imu_drivers::mpu6050::{decode_fifo_frame_of, FifoFrame};
use imu_proto::{
    BatchWriter, DeviceMsg, Event, GapCause, MagSample, Orientation, Scales, Sensor, StreamMode,
    Vec, MAG_PERIOD_US, MAX_ORIENTATIONS,
};

use crate::ahrs::{self, Accum, Ahrs, GyroStep, MAX_SUM};
use crate::clock::{Fine, Stamps, US};
use crate::cycle_marker::{self, Stage};
use crate::engines::{Engines, ImuInputs};
use crate::msg::{FifoFrames, BURST_MAX};
use crate::outbox::{FrameSink, Outbox};

/// IMU bursts per batch frame, in turn: a frame after two bursts, then one after three, so that
/// any ten bursts in a row (100 ms at nominal clocks) carry four batch frames with the samples
/// of ten bursts. Counted in samples instead (a frame every 25), a burst of 11 samples next to
/// one of 9 moved a frame's boundary into the other burst and one 100 ms window in ten carried
/// five frames (docs/benchmarks.md, "Flattening the heaviest windows").
pub const BATCH_BURSTS: [u8; 2] = [2, 3];

/// The attitude estimates go out with the batch frame, right after it (every 2 or 3 bursts,
/// 4 to 6 estimates), so that their frames follow the same turns; with no bursts (the IMU
/// missing) a frame goes out when this many wait: [`MAX_ORIENTATIONS`], all a frame holds.
pub const ORIENTATIONS_MAX_WAIT: usize = MAX_ORIENTATIONS;

/// When the batch goes out: after the bursts of [`BATCH_BURSTS`] in turn. (A batch that would
/// exceed [`imu_proto::MAX_BATCH_IMU`] samples goes out at once, before the sample that does
/// not fit; three bursts of 11 do not fit, a rare event.)
#[derive(Debug, Clone, Copy, Default)]
pub struct BatchTurns {
    bursts: u8,
    long: bool,
}

impl BatchTurns {
    pub const fn new() -> Self {
        Self {
            bursts: 0,
            long: false,
        }
    }

    /// After a burst (an IMU message's samples): whether the batch goes out now.
    pub fn after_burst(&mut self) -> bool {
        self.bursts += 1;
        if self.bursts < BATCH_BURSTS[usize::from(self.long)] {
            return false;
        }
        self.bursts = 0;
        self.long = !self.long;
        true
    }
}

/// What the sample path counts.
#[derive(Debug, Clone, Copy, Default)]
pub struct SampleCounts {
    pub imu_taken: u64,
    pub imu_lost: u64,
    pub mag_taken: u64,
    pub mag_lost: u64,
}

/// One attitude update waiting to run.
#[derive(Debug, Clone, Copy)]
struct Queued {
    acc: Accum,
    mag: Option<[i32; 3]>,
    k: u32,
    t_us: u64,
    imu_period: Fine,
}

/// The sample path's state.
pub struct Pipeline {
    /// The calibration as stored and reported.
    pub(crate) cal: Calibration,
    /// The same, prepared for the per-sample path (split coefficients, diagonal fast path).
    fast: Prepared,
    pub(crate) engines: Engines,
    pub(crate) scales: Scales,
    pub(crate) mode: StreamMode,
    /// The batch being assembled, in its wire form (each sample encoded as it comes).
    batch: BatchWriter,
    /// When it goes out.
    batch_turns: BatchTurns,
    /// The slot expected next on each sensor's grid (`None` before its first sample).
    next_k: [Option<u32>; 2],
    /// The latest raw temperature, for the gyro's temperature term and the status.
    pub(crate) last_temp: Option<i16>,
    pub(crate) counts: SampleCounts,
    /// The attitude filter and the 1 kHz path's sums for its next update.
    pub(crate) ahrs: Ahrs,
    acc: Accum,
    /// Estimates not sent yet.
    orient: Vec<Orientation, MAX_ORIENTATIONS>,
    /// Updates waiting to run: the sums, the magnetometer sample (none for an update without
    /// it), its slot, the instant the sums end at, the IMU period.
    queued: heapless::Deque<Queued, 8>,
    /// The IMU's period ([`Fine`], 0: not known yet) and the stamp of its latest sample, µs.
    imu_period: Fine,
    imu_t_us: u64,
    /// The gyro's step per unit of the IMU's period ([`Fine`]): [`GyroStep`]'s Q46 is
    /// `period · this >> 32`.
    gyro_step_per_fine: i32,
}

/// The IMU's period taken before its clock knows it: 1 ms.
const NOMINAL_IMU_PERIOD: Fine = crate::clock::fine(1000);

impl Pipeline {
    pub fn new(scales: Scales) -> Self {
        Pipeline {
            cal: Calibration::identity(),
            fast: Prepared::new(&Calibration::identity()),
            engines: Engines::new(),
            scales,
            mode: StreamMode::Calibrated,
            batch: BatchWriter::new(),
            batch_turns: BatchTurns::new(),
            next_k: [None; 2],
            last_temp: None,
            counts: SampleCounts::default(),
            ahrs: Ahrs::new(),
            acc: Accum::default(),
            orient: Vec::new(),
            queued: heapless::Deque::new(),
            imu_period: Fine::ZERO,
            imu_t_us: 0,
            // ½ · rad per count per second · 2^46 (Q46) per Fine (2^-16 µs), times 2^32.
            gyro_step_per_fine: libm::round(
                0.5 * f64::from(scales.gyro).to_radians() * 1e-6 / US.raw() as f64
                    * (1u64 << 46) as f64
                    * (1u64 << 32) as f64,
            ) as i32,
        }
    }

    /// New corrections: the attitude filter starts again (a learnt field reference too: the
    /// magnetometer's correction changes what |B| reads).
    pub(crate) fn set_cal(&mut self, cal: Calibration) {
        self.cal = cal;
        self.fast = Prepared::new(&cal);
        self.ahrs.reset();
        self.acc = Accum::default();
        self.queued.clear();
    }

    /// Queue one attitude update with the IMU sums so far (emptied) and, at a magnetometer
    /// sample, its corrected reading. A full queue (the task has not run them) folds the sums
    /// into the next update instead: no rotation is lost, an estimate is.
    fn queue_attitude(&mut self, mag: Option<[i32; 3]>, k: u32) {
        let q = Queued {
            acc: self.acc,
            mag,
            k,
            t_us: self.imu_t_us,
            imu_period: self.imu_period,
        };
        if self.queued.push_back(q).is_ok() {
            self.acc = Accum::default();
        }
    }

    /// Whether the queue of attitude updates is full.
    pub fn attitude_backlog(&self) -> bool {
        self.queued.is_full()
    }

    /// Whether attitude updates wait to run.
    pub fn attitude_pending(&self) -> bool {
        !self.queued.is_empty()
    }

    /// Run the oldest queued attitude update (integer arithmetic, ≈ 2,350 cycles on the M0+);
    /// its estimate is streamed (not in mode `Off`), with the next batch frame or when
    /// [`ORIENTATIONS_MAX_WAIT`] wait. Returns whether more wait.
    pub fn attitude_step(&mut self, outbox: &mut Outbox, sink: &mut impl FrameSink) -> bool {
        // Worked on in place and dropped after: popped by value, the 64-byte entry was copied
        // byte by byte (≈ 270 cycles an update).
        let Some(q) = self.queued.front_mut() else {
            return false;
        };
        cycle_marker::enter(Stage::Ahrs);
        let period = if q.imu_period == Fine::ZERO || q.imu_period.raw() > i32::MAX as u64 {
            NOMINAL_IMU_PERIOD
        } else {
            q.imu_period
        };
        let step = GyroStep(ahrs::fixed::mul_shr(
            period.raw() as i32,
            self.gyro_step_per_fine,
            32,
        ));
        let dt_us = match q.mag {
            Some(_) => MAG_PERIOD_US as u32,
            None => ((u64::from(q.acc.n) * period.raw()) >> crate::clock::FINE_BITS) as u32,
        };
        let att = self.ahrs.update(&mut q.acc, step, q.mag.as_ref(), dt_us);
        let (k, t_us, with_mag) = (q.k, q.t_us, q.mag.is_some());
        self.queued.pop_front();
        cycle_marker::enter(Stage::Usb);
        if let (Some(a), true, false) = (att, with_mag, self.mode == StreamMode::Off) {
            let _ = self.orient.push(Orientation {
                seq: k,
                t_us,
                q: a.q,
                roll_deg: a.roll_deg,
                pitch_deg: a.pitch_deg,
                heading_deg: a.heading_deg,
                state: a.state,
            });
            if self.orient.len() >= ORIENTATIONS_MAX_WAIT {
                self.send_orientations(outbox, sink);
            }
        }
        cycle_marker::leave();
        !self.queued.is_empty()
    }

    /// A discontinuity before slot `k` of `sensor`: the slots skipped since the last sample are
    /// lost; split the engines and report (also with nothing lost, when `cause` is given).
    fn discontinuity(
        &mut self,
        sensor: Sensor,
        k: u32,
        t_us: u64,
        cause: Option<GapCause>,
        outbox: &mut Outbox,
        sink: &mut impl FrameSink,
    ) {
        let i = sensor as usize;
        let lost = self.next_k[i].map_or(0, |e| k.wrapping_sub(e));
        // A slot behind the expected one is not a loss (nothing skipped); it cannot happen with
        // a monotonic grid, and is not counted.
        let lost = if lost >= 1 << 31 { 0 } else { lost };
        if lost == 0 && cause.is_none() {
            return;
        }
        match sensor {
            Sensor::Imu => self.counts.imu_lost += u64::from(lost),
            Sensor::Mag => self.counts.mag_lost += u64::from(lost),
        }
        let cause = cause.unwrap_or(match sensor {
            Sensor::Imu => GapCause::SensorFault,
            Sensor::Mag => GapCause::Overwritten,
        });
        // No Allan difference may straddle the discontinuity. A split of an empty segment
        // (nothing pushed since the last one) changes nothing: the loss is then reported at the
        // same position as that split.
        let at = self
            .engines
            .split(sensor)
            .unwrap_or_else(|| self.engines.pushed(sensor));
        outbox.send(
            &DeviceMsg::Event(Event::Gap {
                sensor,
                at,
                cause,
                lost,
                t_us,
            }),
            sink,
        );
    }

    /// The per-sample path for one FIFO burst: frame `i` is slot `stamps.k0 + i`.
    pub fn imu_burst(
        &mut self,
        frames: &FifoFrames,
        stamps: &Stamps,
        after: Option<GapCause>,
        outbox: &mut Outbox,
        sink: &mut impl FrameSink,
    ) {
        match frames.layout {
            FifoFrame::AccelTempGyro => {
                self.imu_frames(frames.frames_14(), true, stamps, after, outbox, sink)
            }
            FifoFrame::AccelGyro => {
                self.imu_frames_12(frames.as_bytes(), stamps, after, outbox, sink)
            }
        }
    }

    /// Frames without the temperature (not the firmware's layout): moved into the 14-byte
    /// layout, so that one copy of the sample path serves both (with a copy per layout, the
    /// corrections were no longer inlined into it: ≈ 50 cycles per ms on the M0+).
    #[cold]
    #[inline(never)]
    fn imu_frames_12(
        &mut self,
        bytes: &[u8],
        stamps: &Stamps,
        after: Option<GapCause>,
        outbox: &mut Outbox,
        sink: &mut impl FrameSink,
    ) {
        let mut wide = [[0u8; 14]; BURST_MAX];
        let mut n = 0;
        for (w, f) in wide.iter_mut().zip(bytes.as_chunks::<12>().0) {
            w[..6].copy_from_slice(&f[..6]);
            w[8..].copy_from_slice(&f[6..]);
            n += 1;
        }
        self.imu_frames(&wide[..n], false, stamps, after, outbox, sink)
    }

    /// [`Pipeline::imu_burst`] for 14-byte frames (accelerometer, temperature, gyro), each
    /// decoded where its values are used; `temp`: whether the temperature is the part's (else
    /// it is `None`). One copy, out of line: called from two places and inlined into both,
    /// the corrections inside it were not inlined any more.
    #[inline(never)]
    fn imu_frames(
        &mut self,
        frames: &[[u8; 14]],
        temp: bool,
        stamps: &Stamps,
        after: Option<GapCause>,
        outbox: &mut Outbox,
        sink: &mut impl FrameSink,
    ) {
        let samples = &frames[..frames.len().min(BURST_MAX)];
        if samples.is_empty() {
            return;
        }
        if after.is_some() || self.next_k[0] != Some(stamps.k0) {
            self.discontinuity(Sensor::Imu, stamps.k0, stamps.us(0), after, outbox, sink);
        }
        // Three passes over the burst, one per budget stage (docs/emulator.md, cycle markers):
        // corrections, Allan update, framing. Each sample still goes through all three in order.
        // A `Vec`, not a zeroed array: nothing to clear before it is filled.
        let mut fixed: Vec<ImuInputs, BURST_MAX> = Vec::new();
        cycle_marker::enter(Stage::Corrections);
        for f in samples {
            let mut s = decode_fifo_frame_of(f);
            if !temp {
                s.temp = None;
            }
            // The gyro's temperature term needs a temperature: the latest one known; before the
            // first, none (the reference temperature: no correction).
            if s.temp.is_some() {
                self.last_temp = s.temp;
            }
            let accel = self.fast.apply_accel(s.accel);
            let gyro = self.fast.apply_gyro_opt(s.gyro, self.last_temp);
            // At most BURST_MAX samples (cut above): never full.
            let _ = fixed.push((accel, gyro, s.temp.map(i32::from)));
        }
        // The attitude sums, three at a time so they stay in the M0+'s eight low registers (in
        // the loop above, with the corrections' state, they went through the stack: ≈ 60
        // cycles a sample against ≈ 25).
        let (mut a, mut g) = ([0i32; 3], [0i32; 3]);
        for (x, _, _) in &fixed {
            a = [a[0] + x[0], a[1] + x[1], a[2] + x[2]];
        }
        for (_, x, _) in &fixed {
            g = [g[0] + x[0], g[1] + x[1], g[2] + x[2]];
        }
        self.acc.add_sums(&a, &g, fixed.len() as u32);
        self.imu_period = stamps.period;
        self.imu_t_us = stamps.us(samples.len() as u32 - 1);
        // No magnetometer update for 100 ms (sensor missing or stalled): one without it, so
        // the sums stay bounded and the attitude follows the gyro and gravity.
        if self.acc.n >= MAX_SUM {
            self.queue_attitude(None, 0);
        }
        cycle_marker::enter(Stage::Allan);
        self.engines.push_imu(&fixed);
        cycle_marker::enter(Stage::Usb);
        let n = samples.len() as u32;
        self.counts.imu_taken += u64::from(n);
        self.next_k[0] = Some(stamps.k0.wrapping_add(n));
        if self.mode != StreamMode::Off {
            let raw = self.mode == StreamMode::Raw;
            let mut seq = stamps.k0;
            for ((f, (accel, gyro, temp)), t_us) in samples.iter().zip(&fixed).zip(stamps.iter_us())
            {
                let decoded;
                let (accel, gyro) = if raw {
                    let s = decode_fifo_frame_of(f);
                    decoded = (s.accel.map(i32::from), s.gyro.map(i32::from));
                    (&decoded.0, &decoded.1)
                } else {
                    (accel, gyro)
                };
                // Encoded straight into the batch's frame content.
                if !self.batch.push_imu(seq, t_us, accel, gyro, *temp) {
                    self.flush(outbox, sink);
                    // The batch was just emptied, so this cannot fail; ignore rather than panic.
                    let _ = self.batch.push_imu(seq, t_us, accel, gyro, *temp);
                }
                seq = seq.wrapping_add(1);
            }
            if self.batch_turns.after_burst() {
                self.flush(outbox, sink);
                self.send_orientations(outbox, sink);
            }
        }
        cycle_marker::leave();
    }

    /// One magnetometer sample, slot `k`, taken at `t_us`.
    pub fn mag_sample(
        &mut self,
        k: u32,
        t_us: u64,
        xyz: [i16; 3],
        after: Option<GapCause>,
        outbox: &mut Outbox,
        sink: &mut impl FrameSink,
    ) {
        if after.is_some() || self.next_k[1] != Some(k) {
            self.discontinuity(Sensor::Mag, k, t_us, after, outbox, sink);
        }
        cycle_marker::enter(Stage::Corrections);
        let mag = self.fast.apply_mag(xyz);
        cycle_marker::enter(Stage::Allan);
        self.engines.push_mag(&mag);
        self.queue_attitude(Some(mag), k);
        cycle_marker::enter(Stage::Usb);
        self.counts.mag_taken += 1;
        self.next_k[1] = Some(k.wrapping_add(1));
        if self.mode != StreamMode::Off {
            let out = MagSample {
                seq: k,
                t_us,
                mag: if self.mode == StreamMode::Raw {
                    xyz.map(i32::from)
                } else {
                    mag
                },
            };
            if !self.batch.push_mag(out) {
                self.flush(outbox, sink);
                let _ = self.batch.push_mag(out);
            }
            if self.batch.mag_full() {
                self.flush(outbox, sink);
            }
        }
        cycle_marker::leave();
    }

    /// Send the attitude estimates waiting (if any).
    fn send_orientations(&mut self, outbox: &mut Outbox, sink: &mut impl FrameSink) {
        if self.orient.is_empty() {
            return;
        }
        outbox.send_orientations(&self.orient, sink);
        self.orient.clear();
    }

    /// Send the batch assembled so far (if any).
    pub fn flush(&mut self, outbox: &mut Outbox, sink: &mut impl FrameSink) {
        if self.batch.is_empty() {
            return;
        }
        let calibrated = self.mode != StreamMode::Raw;
        outbox.send_batch(&mut self.batch, calibrated, &self.scales, sink);
        self.batch.clear();
    }

    /// Forget the Allan state (new corrections, or the host asked). The grids go on: slot
    /// numbers and loss accounting are not the engines'.
    pub fn reset_allan(&mut self) {
        self.engines.reset();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use imu_proto::FrameReader;

    use crate::test_util::{clock_keyed, Sink};

    /// Ten FIFO frames without the temperature (12 bytes each, big-endian as the part sends
    /// them): at rest, `gyro_z` counts about z.
    fn burst(k0: u32, gyro_z: i16) -> (FifoFrames, Stamps) {
        let mut v = FifoFrames::new(FifoFrame::AccelGyro);
        let values: [i16; 6] = [0, 0, 8192, 0, 0, gyro_z];
        for f in v.bytes.chunks_exact_mut(12).take(10) {
            for (b, x) in f.chunks_exact_mut(2).zip(values) {
                b.copy_from_slice(&x.to_be_bytes());
            }
        }
        v.n = 10;
        let stamps = Stamps {
            k0,
            t0: u64::from(k0) * 1000 * US,
            period: 1000 * US,
        };
        (v, stamps)
    }

    /// A pipeline whose filter has had all but the last of the updates its start averages (at
    /// rest, z up, the tests' field): its next update starts it, without an estimate.
    fn primed() -> Pipeline {
        let mut p = Pipeline::new(crate::config::scales());
        for _ in 1..ahrs::START_UPDATES {
            let mut acc = Accum::default();
            acc.add_sums(&[0, 0, 5 * 8192], &[0, 0, 0], 5);
            let att = p
                .ahrs
                .update(&mut acc, GyroStep(0), Some(&[3000, 0, -5000]), 5000);
            assert!(att.is_none());
        }
        p
    }

    /// FIFO frames go into the batch as the part sent them (raw mode): every value of both
    /// layouts decoded from its big-endian bytes (random values, a fresh realisation each run),
    /// the temperature only from the 14-byte layout, one slot per frame.
    #[test]
    fn raw_frames_reach_the_batch_decoded() {
        let mut rng = clock_keyed();
        let mut next = move || rng() as i16;
        for layout in [FifoFrame::AccelTempGyro, FifoFrame::AccelGyro] {
            let mut p = Pipeline::new(crate::config::scales());
            p.mode = StreamMode::Raw;
            let mut out = Outbox::new();
            let mut sink = Sink(std::vec::Vec::new());
            let fb = layout.bytes();
            let mut frames = FifoFrames::new(layout);
            frames.n = BURST_MAX;
            let values: std::vec::Vec<std::vec::Vec<i16>> = (0..frames.n)
                .map(|_| (0..fb / 2).map(|_| next()).collect())
                .collect();
            for (f, v) in frames.bytes.chunks_exact_mut(fb).zip(&values) {
                for (b, x) in f.chunks_exact_mut(2).zip(v) {
                    b.copy_from_slice(&x.to_be_bytes());
                }
            }
            let stamps = Stamps {
                k0: 40,
                t0: 40_000 * US,
                period: 1000 * US,
            };
            p.imu_burst(&frames, &stamps, None, &mut out, &mut sink);
            p.flush(&mut out, &mut sink);
            let mut reader = FrameReader::<4096>::new();
            let mut got = std::vec::Vec::new();
            reader.feed::<DeviceMsg>(&sink.0, |m| {
                if let Ok(DeviceMsg::Samples(b)) = m {
                    got.extend(b.imu);
                }
            });
            assert_eq!(got.len(), values.len(), "{layout:?}");
            for (k, (s, v)) in got.iter().zip(&values).enumerate() {
                let v: std::vec::Vec<i32> = v.iter().map(|&x| i32::from(x)).collect();
                let (temp, g) = match layout {
                    FifoFrame::AccelTempGyro => (Some(v[3]), 4),
                    FifoFrame::AccelGyro => (None, 3),
                };
                assert_eq!(s.seq, 40 + k as u32);
                assert_eq!(s.accel[..], v[..3], "{layout:?} frame {k}");
                assert_eq!(s.gyro[..], v[g..g + 3], "{layout:?} frame {k}");
                assert_eq!(s.temp, temp, "{layout:?} frame {k}");
            }
        }
    }

    /// Magnetometer samples queue updates; stepping runs them and their estimates wait for the
    /// next batch frame; a full queue keeps the gyro's sums for the next update (no rotation
    /// lost).
    #[test]
    fn updates_queue_run_and_fold_when_full() {
        let mut p = primed();
        let mut out = Outbox::new();
        let mut sink = Sink(std::vec::Vec::new());
        let (b, st) = burst(0, 0);
        p.imu_burst(&b, &st, None, &mut out, &mut sink);
        for k in 0..12u32 {
            p.mag_sample(
                k,
                1000 + 5000 * u64::from(k),
                [3000, 0, -5000],
                None,
                &mut out,
                &mut sink,
            );
            let (b, st) = burst(10 + 10 * k, 131);
            p.imu_burst(&b, &st, None, &mut out, &mut sink);
        }
        // Eight queued (samples 0 … 7), the sums of the five bursts since kept.
        assert!(p.attitude_backlog());
        assert_eq!(p.acc.n, 50);
        assert_eq!(p.acc.gyro[2], 50 * 131);
        let mut steps = 0;
        while p.attitude_step(&mut out, &mut sink) {
            steps += 1;
        }
        assert_eq!(steps + 1, 8);
        let estimates = |sink: &Sink| {
            let mut reader = FrameReader::<4096>::new();
            let mut estimates = std::vec::Vec::new();
            for &byte in &sink.0 {
                if let Some(Ok(DeviceMsg::Orientation(o))) = reader.push::<DeviceMsg>(byte) {
                    estimates.extend(o);
                }
            }
            estimates
        };
        // The first update starts the filter (no estimate); seven more wait for the batch.
        assert!(estimates(&sink).is_empty());
        // 13 bursts so far: turns after bursts 2, 5, 7, 10 and 12; the next after 15.
        let (b, st) = burst(130, 131);
        p.imu_burst(&b, &st, None, &mut out, &mut sink);
        assert!(estimates(&sink).is_empty(), "after burst 14");
        let (b, st) = burst(140, 131);
        p.imu_burst(&b, &st, None, &mut out, &mut sink);
        let got = estimates(&sink);
        assert_eq!(got.len(), 7, "{got:?}");
        assert!(got.windows(2).all(|w| w[1].seq == w[0].seq + 1));
    }

    /// Without a batch turn (the IMU's sums given directly) the estimates go out when a
    /// frame's worth waits.
    #[test]
    fn estimates_go_out_without_turns_when_a_frame_is_full() {
        let mut p = primed();
        let mut out = Outbox::new();
        let mut sink = Sink(std::vec::Vec::new());
        let mut frames = 0;
        let mut reader = FrameReader::<4096>::new();
        p.imu_period = 1000 * US;
        // The first update starts the filter and gives no estimate.
        for k in 0..=(3 * ORIENTATIONS_MAX_WAIT) as u32 {
            p.acc.add_sums(&[0, 0, 5 * 8192], &[0, 0, 0], 5);
            p.mag_sample(
                k,
                5000 * u64::from(k),
                [3000, 0, -5000],
                None,
                &mut out,
                &mut sink,
            );
            while p.attitude_step(&mut out, &mut sink) {}
            for &byte in &std::mem::take(&mut sink.0) {
                if let Some(Ok(DeviceMsg::Orientation(o))) = reader.push::<DeviceMsg>(byte) {
                    assert_eq!(o.len(), ORIENTATIONS_MAX_WAIT, "estimate {k}");
                    frames += 1;
                }
            }
        }
        assert_eq!(frames, 3);
    }

    /// The batch turns: after 2 bursts, then 3, in turn, from any start: any ten bursts in a
    /// row hold four turns, and the bursts between two turns alternate between 2 and 3.
    #[test]
    fn batch_turns_hold_four_in_any_ten_bursts() {
        let mut rng = clock_keyed();
        for _ in 0..50 {
            let n = 20 + (rng() % 2000) as usize;
            let mut t = BatchTurns::new();
            let turns: std::vec::Vec<bool> = (0..n).map(|_| t.after_burst()).collect();
            for (i, w) in turns.windows(10).enumerate() {
                let c = w.iter().filter(|&&b| b).count();
                assert_eq!(c, 4, "bursts {i}..{}: {c} turns", i + 10);
            }
            let at: std::vec::Vec<usize> = (0..n).filter(|&i| turns[i]).collect();
            assert_eq!(at[0], 1, "the first turn after two bursts");
            for (j, g) in at.windows(2).map(|w| w[1] - w[0]).enumerate() {
                assert_eq!(g, if j % 2 == 0 { 3 } else { 2 }, "turn {j}");
            }
        }
    }

    /// Bursts of 8 to 12 samples (random): every sample reaches a batch frame once and in
    /// order, a batch frame goes out exactly at the turns, and the attitude estimates follow
    /// it; a batch that would pass 32 samples goes out at once, 32 in it.
    #[test]
    fn batches_follow_the_burst_turns() {
        let mut rng = clock_keyed();
        let mut next = move |m: u64| rng() % m;
        let mut p = primed();
        let mut out = Outbox::new();
        let mut sink = Sink(std::vec::Vec::new());
        let mut turns = BatchTurns::new();
        let mut reader = FrameReader::<4096>::new();
        let (mut k, mut seqs, mut mag_k) = (0u32, std::vec::Vec::new(), 0u32);
        // IMU samples in the batch.
        let mut held = 0;
        for b in 0..200 {
            let n = 8 + next(5) as usize;
            let mut frames = FifoFrames::new(FifoFrame::AccelTempGyro);
            frames.n = n;
            // At rest, z up: the filter's estimates need gravity.
            for f in frames.bytes.chunks_exact_mut(14).take(n) {
                f[4..6].copy_from_slice(&8192i16.to_be_bytes());
            }
            let stamps = Stamps {
                k0: k,
                t0: u64::from(k) * 1000 * US,
                period: 1000 * US,
            };
            k += n as u32;
            p.imu_burst(&frames, &stamps, None, &mut out, &mut sink);
            let turn = turns.after_burst();
            held += n;
            let full = held > imu_proto::MAX_BATCH_IMU;
            if full {
                held -= imu_proto::MAX_BATCH_IMU;
            }
            if turn {
                held = 0;
            }
            // Two magnetometer samples a burst, their updates run after it.
            for _ in 0..2 {
                p.mag_sample(
                    mag_k,
                    5000 * u64::from(mag_k),
                    [3000, 0, -5000],
                    None,
                    &mut out,
                    &mut sink,
                );
                mag_k += 1;
            }
            while p.attitude_step(&mut out, &mut sink) {}
            let mut kinds = std::vec::Vec::new();
            for &byte in &std::mem::take(&mut sink.0) {
                match reader.push::<DeviceMsg>(byte) {
                    Some(Ok(DeviceMsg::Samples(s))) => {
                        assert!(s.imu.len() <= imu_proto::MAX_BATCH_IMU);
                        seqs.extend(s.imu.iter().map(|s| s.seq));
                        kinds.push('b');
                    }
                    Some(Ok(DeviceMsg::Orientation(_))) => kinds.push('o'),
                    _ => {}
                }
            }
            // The filter's first updates give no estimate: the first turns may carry none.
            let mut want: std::vec::Vec<char> = match turn {
                false => vec![],
                true if b < 2 && kinds.len() == usize::from(full) + 1 => vec!['b'],
                true => vec!['b', 'o'],
            };
            if full {
                want.insert(0, 'b');
            }
            assert_eq!(kinds, want, "burst {b}");
        }
        p.flush(&mut out, &mut sink);
        reader.feed::<DeviceMsg>(&sink.0, |m| {
            if let Ok(DeviceMsg::Samples(s)) = m {
                seqs.extend(s.imu.iter().map(|s| s.seq));
            }
        });
        assert_eq!(seqs, (0..k).collect::<std::vec::Vec<u32>>());
    }
}
