//! The firmware's task logic (`pico_imu_core::{imu, mag, device}`) against the register-level
//! MPU-6050 and QMC5883L models on the simulated bus: the very code the embassy tasks run,
//! ticked on a simulated clock. The models log every sample they produce, so what the device
//! says (slots, stamps, losses, tables) is checked against their ground truth.
use std::collections::BTreeSet;

use embassy_futures::block_on;
use imu_drivers::asynch::{Mpu6050, Qmc5883};
use imu_drivers::mpu6050::{decode_fifo_frame, Address, FifoFrame, RawSample};
use imu_proto::{
    CalFault, CalProblem, CalSource, Channel, DeviceMsg, Event, FrameReader, GapCause, HostFrame,
    Reply, Request, SampleBatch, Sensor, SensorState, StreamMode, MAX_FRAME,
};
use pico_imu_core::clock::{BusTiming, Stamps, US};
use pico_imu_core::config;
use pico_imu_core::device::Device;
use pico_imu_core::imu::{count_may_be_stale, ImuService};
use pico_imu_core::mag::{MagService, Slots};
use pico_imu_core::msg::{self, FifoFrames, SensorMsg, BURST_MAX};
use pico_imu_core::outbox::FrameSink;
use pico_imu_core::replay;
use pico_imu_core::requests::{PersistRequest, Record};
use pico_imu_core::sensor::Tick;
use pico_imu_core::tables::{TABLE_FRAME_ROOM, TABLE_SPACING_US};
use pico_imu_tests::mpu6050_model::Motion;
use pico_imu_tests::{Mpu6050Model, QmcModel, QmcVariant, SimBus};

/// The same board under faults.
#[path = "firmware_pipeline/faults.rs"]
mod faults;

/// Frames the device sent, with a configurable amount of room.
struct Sink {
    bytes: Vec<u8>,
    room: usize,
}

impl FrameSink for Sink {
    fn room(&self) -> usize {
        self.room
    }
    fn put(&mut self, f: &[u8]) {
        assert!(f.len() <= self.room, "put beyond room");
        // Frames are queued in whole words (zero-padded) so the device's copies are word copies.
        assert_eq!(f.len() % 4, 0, "frame of {} bytes not padded", f.len());
        self.bytes.extend_from_slice(f);
    }
}

impl Sink {
    fn roomy() -> Self {
        Sink {
            bytes: Vec::new(),
            room: 1 << 24,
        }
    }
    fn messages(&mut self) -> Vec<DeviceMsg> {
        let mut rd = FrameReader::<MAX_FRAME>::new();
        let mut out = Vec::new();
        rd.feed::<DeviceMsg>(&self.bytes, |r| out.push(r.expect("device frame decodes")));
        self.bytes.clear();
        out
    }
}

/// Deterministic noise: a 32-bit LCG (Numerical Recipes constants), mapped to ±`amp`.
fn lcg(state: &mut u32, amp: f64) -> f64 {
    *state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
    (f64::from(*state >> 8) / f64::from(1u32 << 24) - 0.5) * 2.0 * amp
}

fn noisy_mpu() -> Mpu6050Model {
    let mut m = Mpu6050Model::new(0x68, 0x68);
    let mut s = 12345u32;
    m.motion = Box::new(move |_| Motion {
        accel_g: [
            lcg(&mut s, 0.01),
            lcg(&mut s, 0.01),
            1.0 + lcg(&mut s, 0.01),
        ],
        gyro_dps: [
            0.5 + lcg(&mut s, 0.3),
            -0.2 + lcg(&mut s, 0.3),
            lcg(&mut s, 0.3),
        ],
        temp_c: 30.0 + lcg(&mut s, 0.2),
    });
    m
}

fn noisy_qmc() -> QmcModel {
    let mut q = QmcModel::new(QmcVariant::L);
    let mut s = 777u32;
    q.field = Box::new(move |_| {
        [
            0.2 + lcg(&mut s, 0.005),
            -0.1 + lcg(&mut s, 0.005),
            0.4 + lcg(&mut s, 0.005),
        ]
    });
    q
}

/// A sample the device was handed, as the sensor task read it.
#[derive(Clone, Copy, Debug)]
struct Delivered {
    k: u32,
    t_us: u64,
    raw: RawSample,
}

/// The board: both sensors on one simulated bus, the two services and the device, run on the
/// tasks' schedule (the magnetometer at the instants its service asks for, the IMU every 10 ms).
struct Rig {
    bus: SimBus,
    imu: Mpu6050<SimBus>,
    mag: Qmc5883<SimBus>,
    imu_svc: ImuService,
    mag_svc: MagService,
    slots: Slots,
    next_imu_us: u64,
    dev: Device,
    sink: Sink,
    /// Every IMU sample handed to the device, in order.
    imu_out: Vec<Delivered>,
    /// Every magnetometer reading handed to the device: (slot, reading).
    mag_out: Vec<(u32, [i16; 3])>,
    /// The next magnetometer tick begins this many µs after its instant (a CPU held up).
    mag_hold_us: u64,
    /// The next magnetometer tick's first transfer starts this many µs after the tick asks
    /// for it (the bus held by an IMU burst).
    mag_bus_hold_us: u64,
    /// The next IMU burst's first transfer has its START held this many µs (a slave holding
    /// SDA): the bus reports it begun where it was asked for.
    imu_start_hang_us: u64,
    /// In the next magnetometer tick, the transfer after the first `.0` starts `.1` µs after
    /// it is asked for (the bus held by an IMU burst, the CPU by other work).
    mag_later_hold: Option<(u32, u64)>,
}

impl Rig {
    fn new() -> Rig {
        Rig::with(noisy_mpu(), noisy_qmc())
    }

    fn with(mpu: Mpu6050Model, qmc: QmcModel) -> Rig {
        let bus = SimBus::new().with_mpu(mpu).with_mag(qmc);
        Rig {
            imu: Mpu6050::new(bus.clone(), Address::Ad0Low),
            mag: Qmc5883::new(bus.clone()),
            bus,
            imu_svc: ImuService::new(BusTiming::from_hz(0)),
            mag_svc: MagService::new(BusTiming::from_hz(0)),
            slots: Slots::new(5000, 2750),
            next_imu_us: 10_000,
            dev: Device::new(config::scales(), "test"),
            sink: Sink::roomy(),
            imu_out: Vec::new(),
            mag_out: Vec::new(),
            mag_hold_us: 0,
            mag_bus_hold_us: 0,
            imu_start_hang_us: 0,
            mag_later_hold: None,
        }
    }

    fn now_us(&self) -> u64 {
        self.bus.now_ns() / 1000
    }

    fn feed(&mut self, msgs: msg::Out) {
        for m in msgs {
            match &m {
                SensorMsg::Imu { stamps, frames, .. } => {
                    // The frames travel as the part sent them; decoded here as the driver does.
                    let fb = frames.layout.bytes();
                    for (i, f) in frames.as_bytes().chunks_exact(fb).enumerate() {
                        self.imu_out.push(Delivered {
                            k: stamps.k0 + i as u32,
                            t_us: stamps.us(i as u32),
                            raw: decode_fifo_frame(f, frames.layout).expect("a whole frame"),
                        });
                    }
                }
                SensorMsg::Mag { stamps, xyz, .. } => self.mag_out.push((stamps.k0, *xyz)),
                _ => {}
            }
            self.dev.on_sensor(&m, &mut self.sink);
        }
    }

    /// Run `ms` milliseconds of the tasks' schedule.
    fn run(&mut self, ms: u64) {
        let end = self.now_us() + ms * 1000;
        loop {
            let now = self.now_us();
            let t_mag = match self.mag_svc.next_poll_us() {
                Some(t) => t.max(now),
                None => self.slots.next_after(now),
            };
            let t = t_mag.min(self.next_imu_us);
            if t >= end {
                let d = end.saturating_sub(self.now_us());
                self.bus.advance_us(d);
                return;
            }
            self.bus.advance_us(t.saturating_sub(now));
            let bus = self.bus.clone();
            let clock = move || bus.now_ns() / 1000;
            let mut out = msg::Out::new();
            if t == t_mag {
                self.bus.advance_us(std::mem::take(&mut self.mag_hold_us));
                self.bus
                    .hold_next_us(std::mem::take(&mut self.mag_bus_hold_us));
                if self.mag_svc.wants_recovery(t) {
                    self.mag_svc.recovered();
                }
                if let Some((skip, us)) = self.mag_later_hold.take() {
                    self.bus.hold_later_us(skip, us);
                }
                block_on(self.mag_svc.tick(&mut Tick::new(
                    &mut self.mag,
                    &mut self.bus.delay(),
                    &clock,
                    &mut out,
                )));
                // A tick with fewer transfers does not pass its hold on.
                self.bus.with_world(|w| w.hold_later = None);
            } else {
                self.next_imu_us += 10_000;
                self.bus
                    .hang_next_us(std::mem::take(&mut self.imu_start_hang_us));
                if self.imu_svc.wants_recovery(t) {
                    self.imu_svc.recovered();
                }
                block_on(self.imu_svc.tick(&mut Tick::new(
                    &mut self.imu,
                    &mut self.bus.delay(),
                    &clock,
                    &mut out,
                )));
            }
            self.feed(out);
        }
    }

    fn request(&mut self, req: Request) -> Reply {
        let now = self.now_us();
        let persist = self
            .dev
            .handle(HostFrame { id: 42, req }, now, 0, &mut self.sink);
        assert!(persist.is_none(), "unexpected persist request");
        self.sink
            .messages()
            .into_iter()
            .rev()
            .find_map(|m| match m {
                DeviceMsg::Reply { id: 42, reply } => Some(reply),
                _ => None,
            })
            .expect("a reply to request 42")
    }

    fn events(&mut self) -> Vec<Event> {
        self.sink
            .messages()
            .into_iter()
            .filter_map(|m| match m {
                DeviceMsg::Event(e) => Some(e),
                _ => None,
            })
            .collect()
    }

    fn table(&mut self, ch: Channel) -> imu_proto::AllanTable {
        let now = self.now_us();
        self.dev.table(ch, now)
    }
}

/// Sums of a table, level by level.
fn sums(t: &imu_proto::AllanTable) -> Vec<(u32, u32, u64, u128, u64, u128)> {
    t.levels
        .iter()
        .map(|l| (l.m, l.stride, l.n2, l.sum2, l.n3, l.sum3))
        .collect()
}

/// The delivered IMU samples replayed through the host replay with `splits`.
fn replay_imu(
    d: &[Delivered],
    ch: Channel,
    pushed: u64,
    splits: &BTreeSet<u64>,
    cal: &imu_cal::device::Calibration,
) -> replay::Replay {
    replay::replay::<allan::DeviceEngine, _>(
        d,
        pushed,
        |x| u64::from(x.k),
        |x| {
            let i = replay::imu_inputs(cal, x.raw.accel, x.raw.gyro, x.raw.temp);
            replay::channel_input(ch, Some(&i), None).unwrap_or(0)
        },
        splits,
    )
}

fn gap_positions(events: &[Event], sensor: Sensor) -> BTreeSet<u64> {
    events
        .iter()
        .filter_map(|e| match e {
            Event::Gap { sensor: s, at, .. } if *s == sensor => Some(*at),
            _ => None,
        })
        .collect()
}

/// Σ lost of the sensor's Gap events.
fn lost(events: &[Event], sensor: Sensor) -> u64 {
    events
        .iter()
        .map(|e| match e {
            Event::Gap {
                sensor: s, lost, ..
            } if *s == sensor => u64::from(*lost),
            _ => 0,
        })
        .sum()
}

/// The model's slots of the delivered samples' neighbours: Σ of the jumps between delivered
/// slots, i.e. the ground truth of what was lost between the first and the last delivered.
fn truth_lost(slots: &[(u64, u64)], delivered_t_ns: &[u64]) -> u64 {
    let by_t: std::collections::BTreeMap<u64, u64> = slots.iter().map(|(s, t)| (*t, *s)).collect();
    let s: Vec<u64> = delivered_t_ns.iter().map(|t| by_t[t]).collect();
    s.windows(2).map(|w| w[1] - w[0] - 1).sum()
}

#[test]
fn device_tables_equal_the_host_replay_of_the_delivered_samples_bit_for_bit() {
    let mut rig = Rig::new();
    rig.run(3000);
    let t = rig.table(Channel::Gz);
    // The IMU engines take samples in pairs: with no gap, an odd last sample waits for its
    // pair, so exactly the even part of what was delivered has been pushed.
    assert_eq!(t.pushed, rig.imu_out.len() as u64 & !1);
    assert!(
        rig.imu_out.len() > 2800,
        "{} IMU samples",
        rig.imu_out.len()
    );
    assert!(rig.mag_out.len() > 550, "{} readings", rig.mag_out.len());
    let cal = imu_cal::device::Calibration::identity();
    let none = BTreeSet::new();
    for ch in [
        Channel::Ax,
        Channel::Az,
        Channel::Gx,
        Channel::Gz,
        Channel::Temp,
    ] {
        let t = rig.table(ch);
        let r = replay_imu(&rig.imu_out, ch, t.pushed, &none, &cal);
        let c = replay::compare(&t, &r);
        assert!(c.mismatches.is_empty(), "{ch:?}: {:?}", c.mismatches);
        assert!(c.levels_compared >= 10);
    }
    let t = rig.table(Channel::My);
    let r = replay::replay::<allan::MagEngine, _>(
        &rig.mag_out,
        t.pushed,
        |x| u64::from(x.0),
        |x| cal.apply_mag(x.1)[1],
        &none,
    );
    let c = replay::compare(&t, &r);
    assert!(c.mismatches.is_empty(), "{:?}", c.mismatches);
    assert_eq!(t.gaps, 0);
}

/// The samples' slots are the models' grid positions, their stamps the instants the models
/// sampled them (the simulated bus takes no time: the latch is the transfer's start), and the
/// measured periods those of the parts' clocks, here 1.3 % slow.
#[test]
fn slots_and_stamps_follow_the_parts_own_clocks() {
    let mut mpu = noisy_mpu();
    mpu.clock_error = -0.013;
    let mut qmc = noisy_qmc();
    qmc.clock_error = -0.013;
    let mut rig = Rig::with(mpu, qmc);
    rig.run(12_000);
    let truth = rig.bus.mpu(|m| m.slots());
    let log = rig.bus.mpu(|m| m.log.clone());
    let mut errs = Vec::new();
    for d in &rig.imu_out {
        let (slot, t_ns) = truth[d.k as usize];
        assert_eq!(slot, u64::from(d.k), "grid position");
        let raw = log[d.k as usize].1;
        assert_eq!(d.raw.accel, [raw[0], raw[1], raw[2]], "slot {}", d.k);
        if t_ns > 5_000_000_000 {
            errs.push(d.t_us as f64 - t_ns as f64 * 1e-3);
        }
    }
    let worst = errs.iter().fold(0.0f64, |a, e| a.max(e.abs()));
    assert!(worst < 10.0, "IMU stamps off by up to {worst} µs after 5 s");
    let st = rig.dev.status(0, 0);
    assert!(
        st.imu_period_ns.abs_diff(1_013_171) <= 1,
        "{}",
        st.imu_period_ns
    );
    // The magnetometer's guard looks (clock/sample_clock.rs) make the period be measured again
    // when a sample is found before the predicted interval, so after 12 s it has settled to
    // within 10 ppm (50 ns) rather than 1 ns.
    assert!(
        st.mag_period_ns.abs_diff(5_065_856) <= 50,
        "{}",
        st.mag_period_ns
    );
    // The magnetometer: every reading is the model's measurement of the same slot.
    let mlog = rig.bus.mag(|q| q.log.clone());
    for (k, xyz) in &rig.mag_out {
        assert_eq!(mlog[*k as usize].1, *xyz, "slot {k}");
    }
    assert_eq!((st.samples_dropped, st.mag_dropped), (0, 0));
}

/// In the steady state each burst is one transfer (the FIFO count, then the frames the IMU's
/// clock says have landed), whatever the part's clock error: about one transaction per 10 ms,
/// where counting first and reading after takes two, and every sample still delivered once, in
/// its own slot.
#[test]
fn a_steady_burst_reads_the_count_and_the_frames_in_one_transfer() {
    let mut keyed = pico_imu_tests::Keyed::from_clock();
    for _ in 0..4 {
        let x = keyed.bits();
        let error = ((x % 3001) as f64 - 1500.0) * 1e-5;
        let mut mpu = noisy_mpu();
        mpu.clock_error = error;
        let mut rig = Rig::with(mpu, noisy_qmc());
        rig.run(2000);
        let (t0, n0) = (rig.bus.mpu(|m| m.transactions), rig.imu_out.len());
        rig.run(1000);
        let transfers = rig.bus.mpu(|m| m.transactions) - t0;
        assert!(
            (99..=103).contains(&transfers),
            "clock error {error}: {transfers} transactions in 1 s"
        );
        let got = rig.imu_out.len() - n0;
        let expected = 1000.0 * (1.0 + error);
        assert!(
            (got as f64 - expected).abs() <= 12.0,
            "clock error {error}: {got} samples in 1 s"
        );
        let truth = rig.bus.mpu(|m| m.slots());
        let log = rig.bus.mpu(|m| m.log.clone());
        assert!(rig.imu_out.windows(2).all(|w| w[1].k == w[0].k + 1));
        for d in &rig.imu_out {
            assert_eq!(truth[d.k as usize].0, u64::from(d.k));
            let raw = log[d.k as usize].1;
            assert_eq!(d.raw.gyro, [raw[4], raw[5], raw[6]], "slot {}", d.k);
        }
        assert_eq!(rig.dev.status(0, 0).samples_dropped, 0);
    }
}

/// The IMU engines take samples in pairs: the odd one out of a burst waits for the next burst,
/// is left out of `pushed` meanwhile, and is pushed before a split (it came before the gap).
#[test]
fn an_unpaired_imu_sample_waits_for_the_next_burst_and_precedes_a_split() {
    let mut dev = Device::new(config::scales(), "test");
    let mut sink = Sink::roomy();
    let mut state = 7u32;
    let mut served: Vec<i16> = Vec::new();
    let mut burst = |k0: u32, n: usize, after, served: &mut Vec<i16>| {
        let mut v = imu_proto::Vec::<RawSample, BURST_MAX>::new();
        for _ in 0..n {
            let g = (lcg(&mut state, 300.0)) as i16;
            served.push(g);
            let _ = v.push(RawSample {
                accel: [0, 0, 8192],
                temp: Some(100),
                gyro: [0, 0, g],
            });
        }
        SensorMsg::Imu {
            stamps: Stamps {
                k0,
                t0: u64::from(k0) * 1000 * US,
                period: 1000 * US,
            },
            frames: FifoFrames::of(FifoFrame::AccelTempGyro, &v),
            after,
        }
    };
    let replay = |parts: &[&[i16]]| {
        let mut e = allan::DeviceEngine::new();
        for (k, part) in parts.iter().enumerate() {
            if k > 0 {
                e.gap();
            }
            part.iter().for_each(|&g| e.push(i32::from(g)));
        }
        e.levels()
            .filter(|l| l.n2 > 0)
            .map(|l| (l.m, l.stride, l.n2, l.sum2, l.n3, l.sum3))
            .collect::<Vec<_>>()
    };
    // 5 + 6 + 8 samples: 4, then 10, then 18 pushed.
    let mut k = 0;
    for (n, pushed) in [(5, 4), (6, 10), (8, 18)] {
        let msg = burst(k, n, None, &mut served);
        k += n as u32;
        dev.on_sensor(&msg, &mut sink);
        assert_eq!(dev.table(Channel::Gz, 0).pushed, pushed, "after {n} more");
    }
    assert_eq!(sums(&dev.table(Channel::Gz, 0)), replay(&[&served[..18]]));
    // 50 slots later: a loss of 50, split after all 19 (the waiting one included).
    let msg = burst(k + 50, 8, Some(GapCause::FifoOverflow), &mut served);
    dev.on_sensor(&msg, &mut sink);
    let t = dev.table(Channel::Gz, 0);
    assert_eq!((t.pushed, t.gaps), (27, 1));
    let events: Vec<Event> = sink
        .messages()
        .into_iter()
        .filter_map(|m| match m {
            DeviceMsg::Event(e) => Some(e),
            _ => None,
        })
        .collect();
    assert_eq!(
        events,
        vec![Event::Gap {
            sensor: Sensor::Imu,
            at: 19,
            cause: GapCause::FifoOverflow,
            lost: 50,
            t_us: u64::from(k + 50) * 1000,
        }]
    );
    assert_eq!(sums(&t), replay(&[&served[..19], &served[19..]]));
    assert_eq!(dev.status(0, 0).samples_dropped, 50);
}

#[test]
fn every_delivered_sample_reaches_the_host_once_in_order() {
    let mut rig = Rig::new();
    rig.run(2000);
    rig.dev.flush(&mut rig.sink);
    let batches: Vec<SampleBatch> = rig
        .sink
        .messages()
        .into_iter()
        .filter_map(|m| match m {
            DeviceMsg::Samples(b) => Some(b),
            _ => None,
        })
        .collect();
    let imu: Vec<_> = batches.iter().flat_map(|b| b.imu.iter().copied()).collect();
    assert_eq!(imu.len(), rig.imu_out.len());
    for (s, d) in imu.iter().zip(&rig.imu_out) {
        assert_eq!(s.seq, d.k, "the slot on the grid");
        assert_eq!(s.t_us, d.t_us);
        // Identity calibration: the corrected counts are the raw counts.
        assert_eq!(s.gyro, d.raw.gyro.map(i32::from));
        assert_eq!(s.temp, d.raw.temp.map(i32::from));
    }
    assert!(imu.windows(2).all(|w| w[1].seq == w[0].seq + 1));
    assert!(imu.windows(2).all(|w| w[1].t_us > w[0].t_us));
    let st = rig.dev.status(0, 0);
    assert_eq!(
        (st.samples_taken, st.samples_dropped, st.fifo_overflows),
        (imu.len() as u64, 0, 0)
    );
    assert_eq!((st.imu, st.mag), (SensorState::Ok, SensorState::Ok));
    assert!(st
        .temp_milli_c
        .is_some_and(|t| (29_000..31_000).contains(&t)));
}

/// A CPU held up for 150 ms: the FIFO overflows; the device restarts it at a known slot and
/// counts exactly the samples that never reached it.
/// NACKs for 50 ms: the transfers are retried on the next ticks; the FIFO holds 73 ms, so not a
/// sample is lost and the sensor is never declared lost.
/// Unpowered for 200 ms: lost after the retries, back from its power-on state (asleep,
/// configuration gone) and re-initialised in step with its old grid: the slots and the loss
/// count match the model's, and the grid continues.
/// A part that answers but stops producing: named within 50 ms, re-initialised with back-off,
/// its recovery reported, the stalled slots counted.
#[test]
fn persisting_a_calibration_waits_for_the_flash_write() {
    let mut dev = Device::new(config::scales(), "test");
    let mut sink = Sink::roomy();
    let mut buf = [0u8; imu_cal::device::MAX_BLOB_LEN];
    let blob = imu_cal::device::encode_blob(&imu_cal::device::Calibration::identity(), &mut buf)
        .unwrap()
        .to_vec();
    let req = Request::SetCalibration {
        blob: imu_proto::Vec::from_slice(&blob).unwrap(),
        persist: true,
    };
    let p = dev
        .handle(HostFrame { id: 7, req }, 0, 0, &mut sink)
        .expect("a persist request");
    assert_eq!((p.id, p.record), (7, Record::Calibration));
    assert!(sink.messages().is_empty(), "no reply before the write");
    dev.persisted(&p, true, &mut sink);
    assert_eq!(
        sink.messages(),
        vec![DeviceMsg::Reply {
            id: 7,
            reply: Reply::Ok
        }]
    );
    assert_eq!(dev.cal_status().source, CalSource::Flash);
    dev.persisted(&PersistRequest { id: 8, ..p }, false, &mut sink);
    assert_eq!(
        sink.messages(),
        vec![DeviceMsg::Reply {
            id: 8,
            reply: Reply::Error(imu_proto::ErrorCode::FlashWrite)
        }]
    );
    assert_eq!(dev.cal_status().fault, Some(CalFault::Flash));
}

#[test]
fn a_bad_stored_or_uploaded_calibration_leaves_identity_in_use() {
    let mut dev = Device::new(config::scales(), "test");
    let mut buf = [0u8; imu_cal::device::MAX_BLOB_LEN];
    let good = imu_cal::device::encode_blob(&imu_cal::device::Calibration::identity(), &mut buf)
        .unwrap()
        .to_vec();
    let mut corrupt = good.clone();
    let last = corrupt.len() - 1;
    corrupt[last] ^= 0x55;
    dev.load_stored(Some(&corrupt));
    assert_eq!(dev.cal_status().source, CalSource::Identity);
    assert_eq!(
        dev.cal_status().fault,
        Some(CalFault::Rejected(CalProblem::Corrupt))
    );
    let mut old = good.clone();
    old[4] = 0; // format version 0 (little-endian u16 at offset 4)
    dev.load_stored(Some(&old));
    assert_eq!(
        dev.cal_status().fault,
        Some(CalFault::Rejected(CalProblem::Version(0)))
    );
    let mut sink = Sink::roomy();
    let req = Request::SetCalibration {
        blob: imu_proto::Vec::from_slice(&corrupt).unwrap(),
        persist: true,
    };
    assert!(
        dev.handle(HostFrame { id: 1, req }, 0, 0, &mut sink)
            .is_none(),
        "nothing written"
    );
    assert_eq!(
        sink.messages(),
        vec![DeviceMsg::Reply {
            id: 1,
            reply: Reply::Error(imu_proto::ErrorCode::BadCalibration(CalProblem::Corrupt))
        }]
    );
}

#[test]
fn raw_mode_streams_counts_and_off_mode_streams_nothing() {
    let mut rig = Rig::new();
    assert_eq!(rig.request(Request::SetMode(StreamMode::Raw)), Reply::Ok);
    rig.run(300);
    rig.dev.flush(&mut rig.sink);
    let raw: Vec<SampleBatch> = rig
        .sink
        .messages()
        .into_iter()
        .filter_map(|m| match m {
            DeviceMsg::Samples(b) => Some(b),
            _ => None,
        })
        .collect();
    assert!(!raw.is_empty() && raw.iter().all(|b| !b.calibrated));
    assert_eq!(rig.request(Request::SetMode(StreamMode::Off)), Reply::Ok);
    rig.run(300);
    rig.dev.flush(&mut rig.sink);
    assert!(!rig
        .sink
        .messages()
        .iter()
        .any(|m| matches!(m, DeviceMsg::Samples(_))));
    // Sampling and the Allan engines go on regardless of the streaming mode.
    assert!(rig.dev.status(0, 0).samples_taken > 400);
}

/// `GetTables` takes one snapshot of all ten engines: its tables carry the round and the
/// instant, and samples that arrive while they are sent change none of them. The frames are
/// spaced out, wait for room, and are never dropped.
#[test]
fn get_tables_answers_one_snapshot_spaced_out_and_waiting_for_room() {
    let mut rig = Rig::new();
    rig.run(2000);
    let want: Vec<_> = Channel::ALL.iter().map(|c| rig.table(*c)).collect();
    let Reply::Tables { snapshot } = rig.request(Request::GetTables) else {
        panic!("GetTables")
    };
    let mut got = Vec::new();
    let mut now = rig.now_us();
    rig.sink.room = 100;
    assert!(rig.dev.tables_step(now, &mut rig.sink).is_none(), "no room");
    rig.sink.room = TABLE_FRAME_ROOM;
    while rig.dev.tables_pending() {
        rig.run(10); // samples keep arriving
        now = rig.now_us();
        if rig.dev.tables_step(now, &mut rig.sink).is_some() {
            let again = rig.dev.tables_step(now, &mut rig.sink);
            assert!(again.is_none(), "two tables within {TABLE_SPACING_US} µs");
        }
        for m in rig.sink.messages() {
            if let DeviceMsg::Table(t) = m {
                got.push(t);
            }
        }
    }
    assert_eq!(got.len(), Channel::ALL.len());
    for (g, w) in got.iter().zip(&want) {
        assert_eq!(g.snapshot, snapshot);
        assert_eq!(g.t_us, got[0].t_us);
        assert_eq!(sums(g), sums(w), "{:?}", g.channel);
        assert_eq!(g.pushed, w.pushed);
    }
}

/// A table round beside the 1 s status frames: every table still arrives, whole and from the
/// round's snapshot, and none is queued within a spacing of a status frame, before or after it
/// (the two never share 100 ms of CPU).
#[test]
fn table_steps_keep_clear_of_the_status_frames() {
    let mut rig = Rig::new();
    rig.run(2000);
    let Reply::Tables { snapshot } = rig.request(Request::GetTables) else {
        panic!("GetTables")
    };
    let mut statuses = Vec::new();
    let mut queued = Vec::new();
    let mut got = 0;
    let mut next_status = rig.now_us() + 30_000;
    while rig.dev.tables_pending() {
        rig.run(10);
        let now = rig.now_us();
        assert!(now < 60_000_000, "the round did not end");
        if now >= next_status {
            rig.dev.send_status(now, 0, &mut rig.sink);
            statuses.push(now);
            next_status = now + 1_000_000;
        }
        if rig.dev.tables_step(now, &mut rig.sink).is_some() {
            queued.push(now);
        }
        for m in rig.sink.messages() {
            if let DeviceMsg::Table(t) = m {
                assert_eq!(t.snapshot, snapshot);
                got += 1;
            }
        }
    }
    assert_eq!(got, Channel::ALL.len());
    assert!(statuses.len() >= 2, "{} status frames", statuses.len());
    for t in &queued {
        for s in &statuses {
            assert!(
                t.abs_diff(*s) >= TABLE_SPACING_US,
                "table at {t} µs, status at {s} µs"
            );
        }
    }
}

/// A stall between the FIFO-count transfer and the data transfer: the count (taken before it)
/// cannot show the overflow the stall causes, and the frames read after it would be
/// misaligned; the count is then treated as stale.
/// The magnetometer's reads come just after its samples land, one status poll per reading once
/// the clock has settled.
#[test]
fn the_magnetometer_is_polled_once_per_reading_once_settled() {
    let mut rig = Rig::new();
    rig.run(3000);
    let polls0 = rig.bus.mag(|q| q.status_reads);
    let n0 = rig.mag_out.len();
    rig.run(2000);
    let polls = rig.bus.mag(|q| q.status_reads) - polls0;
    let n = (rig.mag_out.len() - n0) as u64;
    assert!(n >= 398, "{n} readings in 2 s");
    assert!(polls <= n + n / 10, "{polls} status polls for {n} readings");
}

/// Once its clock is located, a magnetometer reading is one transfer (the status and, after a
/// repeated START, the data) but for its guard looks and probes, whatever the part's clock
/// error, and every reading is still the model's measurement of its slot, none lost.
#[test]
fn a_settled_magnetometer_reading_is_one_transfer() {
    let mut keyed = pico_imu_tests::Keyed::from_clock();
    for _ in 0..4 {
        let x = keyed.bits();
        let error = ((x % 3001) as f64 - 1500.0) * 1e-5;
        let mut qmc = noisy_qmc();
        qmc.clock_error = error;
        let mut rig = Rig::with(noisy_mpu(), qmc);
        rig.run(3000);
        let (t0, n0) = (rig.bus.mag(|q| q.transactions), rig.mag_out.len());
        rig.run(2000);
        let transfers = rig.bus.mag(|q| q.transactions) - t0;
        let n = (rig.mag_out.len() - n0) as u64;
        assert!(n >= 390, "clock error {error}: {n} readings in 2 s");
        // Two a reading without it; a guard look (one in 16) and a probe still take more.
        assert!(
            transfers <= n + n / 3,
            "clock error {error}: {transfers} transfers for {n} readings"
        );
        let mlog = rig.bus.mag(|q| q.log.clone());
        for (k, xyz) in &rig.mag_out {
            assert_eq!(mlog[*k as usize].1, *xyz, "clock error {error}: slot {k}");
        }
        assert_eq!(rig.dev.status(0, 0).mag_dropped, 0, "clock error {error}");
    }
}

/// The tasks' fallback slots: the incremental step (one addition) gives exactly what the
/// division gives, and missed slots are skipped, not caught up.
#[test]
fn task_slots_match_the_division_and_skip_missed_ones() {
    let div = |now: u64| (now.saturating_sub(250) / 5000 + 1) * 5000 + 250;
    let mut s = Slots::new(5000, 250);
    let mut now = 0;
    for step in [1000, 4000, 5000, 4999, 1, 12_345, 5000, 60_000, 3] {
        now += step;
        assert_eq!(s.next_after(now), div(now), "at {now}");
    }
}

#[test]
fn the_device_refuses_calibrations_for_other_ranges_or_beyond_the_physical_bounds() {
    use imu_cal::file::CalFile;
    use imu_proto::ErrorCode;
    let mut dev = Device::new(config::scales(), "test");
    let mut sink = Sink::roomy();
    let mut buf = [0u8; imu_cal::device::MAX_BLOB_LEN];
    let mut upload = |dev: &mut Device, blob: &[u8]| {
        let req = Request::SetCalibration {
            blob: imu_proto::Vec::from_slice(blob).unwrap(),
            persist: true,
        };
        let persist = dev.handle(HostFrame { id: 3, req }, 0, 0, &mut sink);
        (persist.is_some(), sink.messages().pop())
    };
    // Fitted at the device's ranges: taken (and to be persisted).
    let good = CalFile::default().to_device().unwrap();
    let blob = imu_cal::device::encode_blob(&good, &mut buf)
        .unwrap()
        .to_vec();
    assert_eq!(upload(&mut dev, &blob), (true, None));
    assert_eq!(dev.cal_status().source, CalSource::Host);
    // Fitted with the gyro at ±500 °/s (65.5 LSB per deg/s): refused, nothing written.
    let mut f = CalFile::default();
    f.gyro.lsb_per_unit = 65.5;
    let blob = imu_cal::device::encode_blob(&f.to_device().unwrap(), &mut buf)
        .unwrap()
        .to_vec();
    let refused = |p| {
        Some(DeviceMsg::Reply {
            id: 3,
            reply: Reply::Error(ErrorCode::BadCalibration(p)),
        })
    };
    assert_eq!(
        upload(&mut dev, &blob),
        (false, refused(CalProblem::OtherRanges))
    );
    // Stored at boot: refused the same way, identity in use, the reason in the status.
    dev.load_stored(Some(&blob));
    assert_eq!(dev.cal_status().source, CalSource::Identity);
    assert_eq!(
        dev.cal_status().fault,
        Some(CalFault::Rejected(CalProblem::OtherRanges))
    );
    // Fitted for an HMC5883L (a part the lab knows, not the one this firmware drives): refused
    // as fitted for another part.
    let mut f = CalFile::default();
    f.set_mag_part(imu_cal::device::MagPart::Hmc5883l);
    let blob = imu_cal::device::encode_blob(&f.to_device().unwrap(), &mut buf)
        .unwrap()
        .to_vec();
    assert_eq!(
        upload(&mut dev, &blob),
        (false, refused(CalProblem::OtherPart))
    );
    // A correction recording no parts (a zero accelerometer scale, assembled without them):
    // refused as not fitted for the firmware's parts.
    let zero = imu_cal::device::Affine::from_float(
        imu_cal::device::Sensor::Accel,
        [[0.0; 3]; 3],
        [0.0; 3],
    )
    .unwrap();
    let bad = imu_cal::device::Calibration::new(
        zero,
        imu_cal::device::GyroCorrection::IDENTITY,
        imu_cal::device::Affine::IDENTITY,
    )
    .unwrap();
    let blob = imu_cal::device::encode_blob(&bad, &mut buf)
        .unwrap()
        .to_vec();
    assert_eq!(
        upload(&mut dev, &blob),
        (false, refused(CalProblem::OtherPart))
    );
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(24))]

    /// A parameter beyond its datasheet bound, encoded past the host's checks
    /// (`to_device_unchecked`): the device refuses the upload (nothing to persist) and the
    /// record in flash at boot (identity in use), and its refusal carries the file key, index,
    /// value and bound, which read as the host's own refusal of the file.
    #[test]
    fn the_device_refuses_a_parameter_beyond_its_datasheet_bound(
        which in 0usize..5, axis in 0usize..3, beyond in 0.01f64..2.0, above in proptest::bool::ANY,
    ) {
        use imu_cal::device::{BlobError, Key, Refusal};
        use imu_cal::file::CalFile;
        use imu_proto::ErrorCode;
        let sign = if above { 1.0 } else { -1.0 };
        let mut f = CalFile::default();
        // Centre and half-width of each bound (docs/calibration.md, "Plausibility").
        let (key, centre, half) = match which {
            0 => (Key::AccelScale, 1.0, 0.09),
            1 => (Key::GyroBias, 0.0, 60.0),
            2 => (Key::AccelOffset, 0.0, if axis == 2 { 0.24 * 9.80665 } else { 0.15 * 9.80665 }),
            3 => (Key::GyroScale, 1.0, 0.09),
            _ => (Key::MagHardIron, 0.0, 130.0),
        };
        let value = centre + sign * (1.0 + beyond) * half;
        match key {
            Key::AccelScale => f.accel.scale[axis] = value,
            Key::GyroBias => f.gyro.bias[axis] = value,
            Key::AccelOffset => f.accel.offset[axis] = value,
            Key::GyroScale => f.gyro.scale[axis] = value,
            _ => f.mag.hard_iron[axis] = value,
        }
        let Err(BlobError::Implausible(host)) = f.to_device() else {
            panic!("the host took {key:?}[{axis}] = {value}");
        };
        let cal = f.to_device_unchecked().unwrap();
        let mut buf = [0u8; imu_cal::device::MAX_BLOB_LEN];
        let blob = imu_cal::device::encode_blob(&cal, &mut buf).unwrap().to_vec();
        let mut dev = Device::new(config::scales(), "test");
        let mut sink = Sink::roomy();
        let req = Request::SetCalibration {
            blob: imu_proto::Vec::from_slice(&blob).unwrap(),
            persist: true,
        };
        let persist = dev.handle(HostFrame { id: 5, req }, 0, 0, &mut sink);
        proptest::prop_assert!(persist.is_none(), "nothing to persist");
        let Some(DeviceMsg::Reply { id: 5, reply: Reply::Error(ErrorCode::BadCalibration(p)) }) =
            sink.messages().pop()
        else {
            panic!("no refusal of {key:?}[{axis}] = {value}");
        };
        dev.load_stored(Some(&blob));
        proptest::prop_assert_eq!(dev.cal_status().source, CalSource::Identity);
        proptest::prop_assert_eq!(dev.cal_status().fault, Some(CalFault::Rejected(p)));
        let CalProblem::Implausible { key: k, axis: a, value: v, lo, hi } = p else {
            panic!("{p:?}");
        };
        proptest::prop_assert_eq!((k, a), (key as u8, Some(axis as u8)));
        proptest::prop_assert!((f64::from(v) - value).abs() <= 1e-5 * value.abs().max(1.0), "{v} vs {value}");
        // In words, the device's refusal is the host's: the same key, index, bounds and form.
        // The value is the device's own (checked against the file's just above): it comes from
        // the blob's fixed point in f32, and a value a hair from a rounding boundary of the
        // printed digits (−4.3765 m/s²) prints one digit apart from the file's.
        let words = Refusal { key, axis: a, value: v.into(), lo: lo.into(), hi: hi.into() }.to_string();
        let expected = Refusal { value: v.into(), ..host };
        proptest::prop_assert_eq!(words, expected.to_string());
    }
}

/// A version-2 blob already in flash (sensitivities, no parts) is used when it is within the
/// datasheet bounds, and refused with the parameter named when it is not (the old bounds took
/// a 1.9 scale).
#[test]
fn a_version_2_blob_in_flash_loads_or_is_refused_with_the_reason() {
    use imu_cal::file::CalFile;
    // Version 2's payload was version 3's without the parts and ranges: the corrections, then
    // `Some` (1) and the three f32 sensitivities. At ±4 g, ±250 °/s, ±2 G version 3 has, after
    // its `Some`, the two parts (1 byte each) and the ranges 4, 250, 2 (1 + 2 + 1 varint bytes).
    let v2 = |f: &CalFile| {
        let cal = f.to_device_unchecked().unwrap();
        let mut buf = [0u8; imu_cal::device::MAX_BLOB_LEN];
        let v4 = imu_cal::device::encode_blob(&cal, &mut buf).unwrap();
        let n = u16::from_le_bytes([v4[6], v4[7]]) as usize;
        let payload = &v4[8..8 + n];
        // Some, the two parts, the ranges ±4 g, ±250 deg/s, ±200 µT (varints), then the
        // sensitivities: version 2 keeps the Some and the sensitivities.
        let some = n - (1 + 2 + 5 + 12);
        assert_eq!(&payload[some..some + 8], &[1, 0, 0, 4, 250, 1, 200, 1]);
        let mut b = b"PCAL".to_vec();
        b.extend_from_slice(&2u16.to_le_bytes());
        b.extend_from_slice(&((n - 7) as u16).to_le_bytes());
        b.extend_from_slice(&payload[..=some]);
        b.extend_from_slice(&payload[some + 8..]);
        let crc = crc32(&b);
        b.extend_from_slice(&crc.to_le_bytes());
        b
    };
    let mut dev = Device::new(config::scales(), "test");
    let mut f = CalFile::default();
    f.accel.scale = [1.02, 0.99, 0.98];
    f.gyro.bias = [1.6, -0.3, 0.8];
    dev.load_stored(Some(&v2(&f)));
    assert_eq!(dev.cal_status().source, CalSource::Flash);
    assert_eq!(dev.cal_status().fault, None);
    assert_eq!(dev.calibration().accel(), f.to_device().unwrap().accel());
    f.accel.scale = [1.9, 1.0, 1.0];
    dev.load_stored(Some(&v2(&f)));
    assert_eq!(dev.cal_status().source, CalSource::Identity);
    let Some(CalFault::Rejected(CalProblem::Implausible {
        key, axis, value, ..
    })) = dev.cal_status().fault
    else {
        panic!("{:?}", dev.cal_status());
    };
    assert_eq!(
        (key, axis),
        (imu_cal::device::Key::AccelScale as u8, Some(0))
    );
    assert!((value - 1.9).abs() < 1e-6, "{value}");
}

/// CRC-32/ISO-HDLC (reflected 0x04C11DB7, init and final XOR all ones), bit by bit.
fn crc32(bytes: &[u8]) -> u32 {
    let mut c = !0u32;
    for &b in bytes {
        c ^= u32::from(b);
        for _ in 0..8 {
            c = if c & 1 != 0 {
                (c >> 1) ^ 0xEDB8_8320
            } else {
                c >> 1
            };
        }
    }
    !c
}
