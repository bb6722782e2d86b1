//! The firmware's task logic (`pico_imu_core::sensors` + `pico_imu_core::device`) against the
//! register-level MPU-6050 and QMC5883L models on the simulated bus: the very code the embassy
//! tasks run, ticked on a simulated clock. The Allan tables must equal, bit for bit, a host
//! `allan::stream::DeviceEngine` fed with the samples the models served, corrected by
//! `imu_cal::device` on the host.
use std::cell::RefCell;
use std::rc::Rc;

use allan::stream::{DeviceEngine, LevelSums};
use embassy_futures::block_on;
use imu_drivers::asynch::{Mpu6050, Qmc5883};
use imu_drivers::mpu6050::{Address, RawSample};
use imu_proto::{
    CalFault, CalSource, Channel, DeviceMsg, Event, FrameReader, GapCause, HostFrame, Reply,
    Request, SampleBatch, Sensor, SensorState, StreamMode, MAX_FRAME,
};
use pico_imu_core::device::{Device, SensorMsg, TABLE_FRAME_ROOM};
use pico_imu_core::outbox::FrameSink;
use pico_imu_core::sensors::{self, ImuService, MagService, Slots};
use pico_imu_tests::mpu6050_model::Motion;
use pico_imu_tests::{Mpu6050Model, QmcModel, QmcVariant, SimBus};

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
        assert_eq!(
            f.len() % 4,
            0,
            "frame of {} bytes not padded to a word",
            f.len()
        );
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

/// The board: both sensors on one simulated bus, the two services and the device.
struct Rig {
    bus: SimBus,
    imu: Mpu6050<SimBus>,
    mag: Qmc5883<SimBus>,
    imu_svc: ImuService,
    mag_svc: MagService,
    dev: Device,
    sink: Sink,
    /// Every IMU / magnetometer sample handed to the device, in order.
    served_imu: Rc<RefCell<Vec<RawSample>>>,
    /// (reading, DOR flag: a sample was overwritten before it, a gap).
    served_mag: Vec<([i16; 3], bool)>,
    t_ms: u64,
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

impl Rig {
    fn new() -> Rig {
        let bus = SimBus::new().with_mpu(noisy_mpu()).with_mag(noisy_qmc());
        Rig {
            imu: Mpu6050::new(bus.clone(), Address::Ad0Low),
            mag: Qmc5883::new(bus.clone()),
            bus,
            imu_svc: ImuService::new(),
            mag_svc: MagService::new(),
            dev: Device::new(sensors::scales(), "test"),
            sink: Sink::roomy(),
            served_imu: Rc::new(RefCell::new(Vec::new())),
            served_mag: Vec::new(),
            t_ms: 0,
        }
    }

    fn feed(&mut self, msgs: sensors::Out) {
        for m in msgs {
            match &m {
                SensorMsg::Imu { samples, .. } => {
                    self.served_imu.borrow_mut().extend_from_slice(samples)
                }
                SensorMsg::Mag { xyz, skipped, .. } => self.served_mag.push((*xyz, *skipped)),
                _ => {}
            }
            self.dev.on_sensor(&m, &mut self.sink);
        }
    }

    /// Run `ms` milliseconds of the tasks' schedule: IMU every 10 ms, magnetometer every 5 ms.
    fn run(&mut self, ms: u64) {
        for _ in 0..ms {
            self.bus.advance_us(1000);
            self.t_ms += 1;
            let bus = self.bus.clone();
            let now = move || bus.now_ns() / 1000;
            if self.t_ms.is_multiple_of(5) {
                let mut out = sensors::Out::new();
                block_on(self.mag_svc.tick(
                    &mut self.mag,
                    &mut self.bus.delay(),
                    &now,
                    0,
                    &mut out,
                ));
                self.feed(out);
            }
            if self.t_ms.is_multiple_of(10) {
                let mut out = sensors::Out::new();
                block_on(self.imu_svc.tick(
                    &mut self.imu,
                    &mut self.bus.delay(),
                    &now,
                    0,
                    &mut out,
                ));
                self.feed(out);
            }
        }
    }

    fn request(&mut self, req: Request) -> Reply {
        let persist = self
            .dev
            .handle(HostFrame { id: 42, req }, 0, 0, &mut self.sink);
        assert!(persist.is_none(), "unexpected persist request");
        self.last_reply()
    }

    fn last_reply(&mut self) -> Reply {
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
}

fn host_engine(values: impl IntoIterator<Item = i32>) -> DeviceEngine {
    let mut e = DeviceEngine::new();
    for v in values {
        e.push(v);
    }
    e
}

fn sums(t: &imu_proto::AllanTable) -> Vec<(u32, u32, u64, u128, u64, u128)> {
    t.levels
        .iter()
        .map(|l| (l.m, l.stride, l.n2, l.sum2, l.n3, l.sum3))
        .collect()
}

fn engine_sums(e: &DeviceEngine) -> Vec<(u32, u32, u64, u128, u64, u128)> {
    e.levels()
        .filter(|l: &LevelSums| l.n2 > 0)
        .map(|l| (l.m, l.stride, l.n2, l.sum2, l.n3, l.sum3))
        .collect()
}

#[test]
fn device_tables_equal_the_host_engine_on_the_served_samples_bit_for_bit() {
    let mut rig = Rig::new();
    rig.run(3000);
    let served = rig.served_imu.borrow().clone();
    // The IMU engines take samples in pairs: with no gap, an odd last sample still waits for
    // its pair, so exactly the even part of what was served has been pushed.
    let pushed = served.len() & !1;
    assert_eq!(rig.dev.table(Channel::Gz).pushed, pushed as u64);
    let served_pushed = &served[..pushed];
    // 3 s at 1 kHz less the 100 ms reset wait of init and the last partial burst.
    assert!(
        served.len() > 2800,
        "only {} IMU samples served",
        served.len()
    );
    assert!(
        rig.served_mag.len() > 550,
        "only {} magnetometer samples",
        rig.served_mag.len()
    );
    let cal = imu_cal::device::Calibration::identity();
    for (k, ch) in [Channel::Gx, Channel::Gy, Channel::Gz]
        .into_iter()
        .enumerate()
    {
        let host = host_engine(
            served_pushed
                .iter()
                .map(|s| cal.apply_gyro(s.gyro, s.temp.unwrap())[k]),
        );
        assert_eq!(sums(&rig.dev.table(ch)), engine_sums(&host), "{ch:?}");
    }
    let host = host_engine(served_pushed.iter().map(|s| cal.apply_accel(s.accel)[2]));
    assert_eq!(sums(&rig.dev.table(Channel::Az)), engine_sums(&host));
    let host = host_engine(served_pushed.iter().map(|s| i32::from(s.temp.unwrap())));
    assert_eq!(sums(&rig.dev.table(Channel::Temp)), engine_sums(&host));
    // The magnetometer engine marks a gap where the chip reported an overwritten sample.
    let mut host = DeviceEngine::new();
    for (m, skipped) in &rig.served_mag {
        if *skipped {
            host.gap();
        }
        host.push(cal.apply_mag(*m)[1]);
    }
    assert_eq!(sums(&rig.dev.table(Channel::My)), engine_sums(&host));
    assert_eq!(rig.dev.table(Channel::Gz).gaps, 0);
}

/// The IMU engines take samples in pairs: the odd one out of a burst waits for the next burst,
/// is left out of `pushed` meanwhile, and is pushed before a split (it came before the gap).
#[test]
fn an_unpaired_imu_sample_waits_for_the_next_burst_and_precedes_a_split() {
    let mut dev = Device::new(sensors::scales(), "test");
    let mut sink = Sink::roomy();
    let mut state = 7u32;
    let mut served: Vec<i16> = Vec::new();
    let mut burst = |n: usize, t_us: u64, served: &mut Vec<i16>| {
        let mut v = imu_proto::Vec::<RawSample, { pico_imu_core::device::BURST_MAX }>::new();
        for _ in 0..n {
            let g = (lcg(&mut state, 300.0)) as i16;
            served.push(g);
            let _ = v.push(RawSample {
                accel: [0, 0, 8192],
                temp: Some(100),
                gyro: [0, 0, g],
            });
        }
        SensorMsg::Imu { t_us, samples: v }
    };
    let replay = |parts: &[&[i16]]| {
        let mut e = DeviceEngine::new();
        for (k, part) in parts.iter().enumerate() {
            if k > 0 {
                e.gap();
            }
            part.iter().for_each(|&g| e.push(i32::from(g)));
        }
        e
    };
    // 5 + 6 + 8 samples: 4, then 10, then 18 pushed (the 5th waited for the second burst's
    // first, the 19th waits still).
    let mut t_us = 10_000;
    for (n, pushed) in [(5, 4), (6, 10), (8, 18)] {
        let msg = burst(n, t_us, &mut served);
        dev.on_sensor(&msg, &mut sink);
        t_us += 10_000;
        assert_eq!(dev.table(Channel::Gz).pushed, pushed, "after {n} more");
    }
    assert_eq!(served.len(), 19);
    assert_eq!(
        sums(&dev.table(Channel::Gz)),
        engine_sums(&replay(&[&served[..18]]))
    );
    // An overflow splits the series after all 19, the waiting one included.
    dev.on_sensor(&SensorMsg::ImuOverflow { t_us, lost: 50 }, &mut sink);
    let t = dev.table(Channel::Gz);
    assert_eq!((t.pushed, t.gaps), (19, 1));
    let gaps: Vec<u64> = sink
        .messages()
        .into_iter()
        .filter_map(|m| match m {
            DeviceMsg::Event(Event::Gap {
                sensor: Sensor::Imu,
                at,
                ..
            }) => Some(at),
            _ => None,
        })
        .collect();
    assert_eq!(gaps, vec![19]);
    let msg = burst(8, t_us + 60_000, &mut served);
    dev.on_sensor(&msg, &mut sink);
    assert_eq!(
        sums(&dev.table(Channel::Gz)),
        engine_sums(&replay(&[&served[..19], &served[19..]]))
    );
    assert_eq!(dev.table(Channel::Gz).pushed, 27);
}

#[test]
fn every_served_sample_reaches_the_host_once_in_order() {
    let mut rig = Rig::new();
    rig.run(2000);
    rig.dev.flush(&mut rig.sink);
    let served = rig.served_imu.borrow().clone();
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
    assert_eq!(imu.len(), served.len());
    for (k, (s, raw)) in imu.iter().zip(&served).enumerate() {
        assert_eq!(s.seq, k as u32, "sequence numbers are contiguous");
        // Identity calibration: the corrected counts are the raw counts.
        assert_eq!(s.gyro, raw.gyro.map(i32::from));
        assert_eq!(s.accel, raw.accel.map(i32::from));
    }
    // Timestamps advance by the 1 ms sample period, across bursts too (each tick's bursts are
    // stamped back from the read that emptied the FIFO; the simulated bus takes no time, so the
    // spacing is exact here).
    let worst = imu
        .windows(2)
        .map(|w| w[1].t_us.abs_diff(w[0].t_us + 1000))
        .max()
        .unwrap();
    assert_eq!(worst, 0, "timestamp spacing off by up to {worst} µs");
    let st = rig.dev.status(0, 0);
    assert_eq!(
        (st.samples_taken, st.samples_dropped, st.fifo_overflows),
        (served.len() as u64, 0, 0)
    );
    assert_eq!((st.imu, st.mag), (SensorState::Ok, SensorState::Ok));
}

#[test]
fn an_uploaded_calibration_is_applied_to_samples_and_tables() {
    let mut rig = Rig::new();
    let file = imu_cal::file::CalFile::from_toml(
        "version = 1
[accel]
lsb_per_unit = 835.3
offset = [0.0, 0.0, 0.0]
scale = [1.0, 1.0, 1.0]
misalignment_deg = [0.0, 0.0, 0.0]
[gyro]
lsb_per_unit = 131.0
bias = [0.5, -0.2, 0.0]
temp_coeff = [0.01, 0.0, 0.0]
temp_ref = 25.0
temp_lsb_per_c = 340.0
temp_offset_c = 36.53
[mag]
lsb_per_unit = 120.0
hard_iron = [0.0, 0.0, 0.0]
soft_iron = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
",
    )
    .expect("calibration file parses");
    let cal = file.to_device().expect("representable on the device");
    let mut buf = [0u8; imu_cal::device::MAX_BLOB_LEN];
    let blob = imu_cal::device::encode_blob(&cal, &mut buf)
        .unwrap()
        .to_vec();
    let reply = rig.request(Request::SetCalibration {
        blob: imu_proto::Vec::from_slice(&blob).unwrap(),
        persist: false,
    });
    assert_eq!(reply, Reply::Ok);
    assert_eq!(rig.dev.cal_status().source, CalSource::Host);
    rig.run(1500);
    let served = rig.served_imu.borrow().clone();
    let host = host_engine(
        served
            .iter()
            .map(|s| cal.apply_gyro(s.gyro, s.temp.unwrap())[0]),
    );
    assert_eq!(sums(&rig.dev.table(Channel::Gx)), engine_sums(&host));
    // The 0.5 deg/s bias (65.5 LSB) is gone from gx: the model's mean rate is 0.5 deg/s.
    rig.dev.flush(&mut rig.sink);
    let gx: Vec<f64> = rig
        .sink
        .messages()
        .into_iter()
        .filter_map(|m| {
            if let DeviceMsg::Samples(b) = m {
                Some(b)
            } else {
                None
            }
        })
        .flat_map(|b| {
            b.imu
                .iter()
                .map(|s| f64::from(s.gyro[0]))
                .collect::<Vec<_>>()
        })
        .collect();
    let mean_dps = gx.iter().sum::<f64>() / gx.len() as f64 / 131.0;
    // 30 °C vs T_ref 25 °C adds 0.05 deg/s of temperature term; noise ±0.3 deg/s uniform over
    // ~1400 samples gives a standard error of ≈ 0.005 deg/s: allow 0.1 deg/s.
    assert!(
        mean_dps.abs() < 0.1,
        "mean gx after correction {mean_dps} deg/s"
    );
    // Read back: the blob the device holds is the one uploaded.
    match rig.request(Request::GetCalibration) {
        Reply::Calibration { blob: got, status } => {
            assert_eq!(got.as_slice(), blob.as_slice());
            assert_eq!(status.source, CalSource::Host);
        }
        other => panic!("{other:?}"),
    }
}

#[test]
fn a_fifo_overflow_is_counted_and_marked_as_a_gap() {
    let mut rig = Rig::new();
    rig.run(1000);
    let before = rig.served_imu.borrow().len();
    // Stall 150 ms without servicing: the 73-frame FIFO overflows.
    rig.bus.advance_us(150_000);
    rig.run(500);
    let st = rig.dev.status(0, 0);
    assert_eq!(st.fifo_overflows, 1);
    // ≈150 − 73 frames lost, estimated from the elapsed time (±10 for the burst phase).
    assert!(
        (60..=100).contains(&st.samples_dropped),
        "dropped {}",
        st.samples_dropped
    );
    let t = rig.dev.table(Channel::Gz);
    assert_eq!(t.gaps, 1);
    // The host engine with a gap at the same place gives the same sums: no difference
    // straddles the overflow.
    let served = rig.served_imu.borrow().clone();
    let mut host = DeviceEngine::new();
    for (i, s) in served.iter().enumerate() {
        if i == before {
            host.gap();
        }
        host.push(i32::from(s.gyro[2]));
    }
    assert_eq!(sums(&t), engine_sums(&host));
    let events: Vec<Event> = rig
        .sink
        .messages()
        .into_iter()
        .filter_map(|m| {
            if let DeviceMsg::Event(e) = m {
                Some(e)
            } else {
                None
            }
        })
        .collect();
    assert!(
        events
            .iter()
            .any(|e| matches!(e, Event::FifoOverflow { .. })),
        "{events:?}"
    );
    // The split is reported where it was made, in samples pushed: a host replay needs nothing
    // else to mirror it.
    let imu_splits: Vec<(u64, GapCause)> = events
        .iter()
        .filter_map(|e| match e {
            Event::Gap {
                sensor: Sensor::Imu,
                at,
                cause,
            } => Some((*at, *cause)),
            _ => None,
        })
        .collect();
    assert_eq!(
        imu_splits,
        vec![(before as u64, GapCause::FifoOverflow)],
        "{events:?}"
    );
}

#[test]
fn a_vanished_sensor_is_reported_retried_and_resumed_without_reset() {
    let mut rig = Rig::new();
    rig.run(500);
    let taken_before = rig.dev.status(0, 0).samples_taken;
    rig.bus.mpu(|m| m.present = false);
    rig.run(2000);
    assert_eq!(rig.dev.status(0, 0).imu, SensorState::Missing);
    // Power comes back: the chip restarts from its power-on state (asleep, FIFO off).
    rig.bus.with_world(|w| w.mpu = Some(noisy_mpu()));
    rig.run(1000);
    let st = rig.dev.status(0, 0);
    assert_eq!(st.imu, SensorState::Ok);
    assert!(
        st.samples_taken > taken_before + 500,
        "sampling resumed: {}",
        st.samples_taken
    );
    assert!(st.i2c_errors >= 3);
    let events: Vec<Event> = rig
        .sink
        .messages()
        .into_iter()
        .filter_map(|m| {
            if let DeviceMsg::Event(e) = m {
                Some(e)
            } else {
                None
            }
        })
        .collect();
    let lost = events.iter().find(|e| {
        matches!(
            e,
            Event::SensorLost {
                sensor: Sensor::Imu,
                ..
            }
        )
    });
    let back = events.iter().find_map(|e| match e {
        Event::SensorBack {
            sensor: Sensor::Imu,
            down_us,
            ..
        } => Some(*down_us),
        _ => None,
    });
    assert!(lost.is_some(), "{events:?}");
    // Down about 2 s (+ up to one retry interval, 400 ms, + the 100 ms reset wait).
    let down = back.expect("SensorBack event");
    assert!((1_900_000..=2_600_000).contains(&down), "down {down} µs");
    assert_eq!(st.samples_dropped, down / 1000);
    // The engines kept their sums (no reset) and marked the outage as a gap.
    assert_eq!(rig.dev.table(Channel::Ax).gaps, 1);
    assert_eq!(rig.dev.table(Channel::Ax).pushed, st.samples_taken);
}

#[test]
fn a_missing_magnetometer_at_boot_is_reported_and_found_later() {
    let mut rig = Rig::new();
    rig.bus.mag(|q| q.present = false);
    rig.run(300);
    assert_eq!(rig.dev.status(0, 0).mag, SensorState::Missing);
    assert_eq!(rig.dev.status(0, 0).imu, SensorState::Ok);
    rig.bus.mag(|q| q.present = true);
    rig.run(600);
    assert_eq!(rig.dev.status(0, 0).mag, SensorState::Ok);
    assert!(rig.dev.status(0, 0).mag_samples > 50);
}

#[test]
fn persisting_a_calibration_waits_for_the_flash_write() {
    let mut dev = Device::new(sensors::scales(), "test");
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
    assert_eq!(p.id, 7);
    assert!(sink.messages().is_empty(), "no reply before the write");
    dev.persisted(7, true, &mut sink);
    assert_eq!(
        sink.messages(),
        vec![DeviceMsg::Reply {
            id: 7,
            reply: Reply::Ok
        }]
    );
    assert_eq!(dev.cal_status().source, CalSource::Flash);
    dev.persisted(8, false, &mut sink);
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
    let mut dev = Device::new(sensors::scales(), "test");
    let mut buf = [0u8; imu_cal::device::MAX_BLOB_LEN];
    let good = imu_cal::device::encode_blob(&imu_cal::device::Calibration::identity(), &mut buf)
        .unwrap()
        .to_vec();
    let mut corrupt = good.clone();
    let last = corrupt.len() - 1;
    corrupt[last] ^= 0x55;
    dev.load_stored(Some(&corrupt));
    assert_eq!(dev.cal_status().source, CalSource::Identity);
    assert_eq!(dev.cal_status().fault, Some(CalFault::Corrupt));
    let mut old = good.clone();
    old[4] = 0; // format version 0 (little-endian u16 at offset 4)
    dev.load_stored(Some(&old));
    assert_eq!(dev.cal_status().fault, Some(CalFault::OldVersion(0)));
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
            reply: Reply::Error(imu_proto::ErrorCode::BadCalibration)
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
        .filter_map(|m| {
            if let DeviceMsg::Samples(b) = m {
                Some(b)
            } else {
                None
            }
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

#[test]
fn a_full_queue_drops_and_counts_frames_and_tables_wait_for_room() {
    let mut rig = Rig::new();
    rig.sink.room = 100; // smaller than a sample batch frame
    rig.run(500);
    let st = rig.dev.status(0, 0);
    // One batch frame per MAX_BATCH_IMU samples (1 ms each), all dropped.
    let batches = 500 / imu_proto::MAX_BATCH_IMU as u32;
    assert!(
        st.frames_unsent >= batches - 1,
        "unsent {}",
        st.frames_unsent
    );
    // Small event frames fit; no sample batch does.
    assert!(!rig
        .sink
        .messages()
        .iter()
        .any(|m| matches!(m, DeviceMsg::Samples(_))));
    rig.dev.start_tables();
    for _ in 0..50 {
        assert!(
            rig.dev.tables_step(&mut rig.sink).is_none(),
            "no table without room"
        );
    }
    assert!(rig.dev.tables_pending());
    rig.sink.room = TABLE_FRAME_ROOM;
    let mut sent = Vec::new();
    let mut steps = 0;
    while rig.dev.tables_pending() && steps < 1000 {
        steps += 1;
        if let Some(t) = rig.dev.tables_step(&mut rig.sink) {
            // Built a few rows per step, the table equals the one computed at once.
            assert_eq!(t, rig.dev.table(t.channel));
            sent.push(t.channel);
        }
    }
    assert_eq!(sent, Channel::ALL.to_vec());
    // 500 ms of data: 9 levels (IMU) or 6 (magnetometer) at ROWS_PER_STEP = 2 a step, plus the
    // 50 rows done while waiting for room; never a whole table in one step.
    assert!(steps >= 10, "{steps} steps");
}

#[test]
fn a_table_is_a_snapshot_even_when_samples_arrive_while_it_is_built() {
    let mut rig = Rig::new();
    rig.run(2000);
    rig.dev.start_tables();
    let want = rig.dev.table(Channel::Ax);
    assert!(rig.dev.tables_step(&mut rig.sink).is_none()); // the first rows only
    rig.run(20); // more samples arrive
    let mut got = None;
    for _ in 0..20 {
        if let Some(t) = rig.dev.tables_step(&mut rig.sink) {
            got = Some(t);
            break;
        }
    }
    assert_eq!(got.expect("the ax table"), want);
}

#[test]
fn table_rows_carry_consistent_deviations_and_bounds() {
    let mut rig = Rig::new();
    rig.run(3000);
    let t = rig.dev.table(Channel::Gx);
    assert_eq!(t.tau0_us, 1000);
    for l in &t.levels {
        // The row's deviation is the one its sums give (σ² = Σ D2² / (2 n m²)), to f32.
        let s = LevelSums {
            m: l.m,
            stride: l.stride,
            n2: l.n2,
            sum2: l.sum2,
            n3: l.n3,
            sum3: l.sum3,
        };
        let dev = s.oadev(f64::from(t.scale)).unwrap();
        assert!((f64::from(l.dev) - dev).abs() <= 1e-6 * dev, "m = {}", l.m);
        assert!(
            l.lo < l.dev && l.dev < l.hi,
            "m = {}: {} ∉ ({}, {})",
            l.m,
            l.dev,
            l.lo,
            l.hi
        );
        assert!((f64::from(l.tau_s) / (f64::from(l.m) * 1e-3) - 1.0).abs() < 1e-6);
        // f32 τ
    }
    // White noise (uniform ±0.3 deg/s, σ = 0.173 deg/s, quantised at 1/131 deg/s): ADEV at
    // τ0 is σ (seed eq. 7 for white noise): 0.173 deg/s within 5 %.
    let d0 = f64::from(t.levels[0].dev);
    assert!(
        (d0 - 0.3 / 3f64.sqrt()).abs() < 0.05 * 0.173,
        "ADEV(τ0) = {d0} deg/s"
    );
}

#[test]
fn after_a_magnetometer_loss_sampling_resumes_at_the_full_rate() {
    let mut rig = Rig::new();
    rig.run(1000);
    rig.bus.mag(|q| q.present = false);
    rig.run(30);
    rig.bus.mag(|q| q.present = true);
    rig.run(500);
    let before = rig.dev.status(0, 0).mag_samples;
    rig.run(1000);
    let per_s = rig.dev.status(0, 0).mag_samples - before;
    eprintln!("{per_s} magnetometer samples in the second after recovery");
    // 200 Hz: 200 ± 1 (tick phase) samples in one second.
    assert!(
        (199..=201).contains(&per_s),
        "{per_s} samples/s after recovery"
    );
}

#[test]
fn a_late_magnetometer_sample_is_a_gap_even_without_the_overwrite_flag() {
    let mut dev = Device::new(sensors::scales(), "test");
    let mut sink = Sink::roomy();
    let mut t = 1_000;
    for k in 0..20u64 {
        // Regular reads 5 ms apart with 0–2 ms of jitter, then one 10 ms hole at k = 10.
        t += if k == 10 { 10_000 } else { 5_000 };
        let jitter = (k * 700) % 2000;
        let msg = SensorMsg::Mag {
            t_us: t + jitter,
            xyz: [k as i16, 0, 0],
            skipped: false,
        };
        dev.on_sensor(&msg, &mut sink);
    }
    assert_eq!(dev.table(Channel::Mx).gaps, 1);
    assert_eq!(dev.table(Channel::Mx).pushed, 20);
}

#[test]
fn the_allan_state_fits_its_32_kib_budget() {
    use allan::stream::MagEngine;
    let bytes = pico_imu_core::device::ALLAN_STATE_BYTES;
    // The engines and the IMU sample that waits for its pair (seven i32 inputs and a tag).
    let pending = core::mem::size_of::<Option<([i32; 3], [i32; 3], i32)>>();
    let parts =
        7 * core::mem::size_of::<DeviceEngine>() + 3 * core::mem::size_of::<MagEngine>() + pending;
    println!(
        "Allan state: {bytes} B (7 × {} B at 1 kHz + 3 × {} B for the magnetometer + {pending} B)",
        core::mem::size_of::<DeviceEngine>(),
        core::mem::size_of::<MagEngine>()
    );
    assert_eq!(bytes, parts);
    assert!(bytes <= 32 * 1024, "{bytes} B");
}

#[test]
fn imu_stamps_always_increase_even_when_a_burst_is_read_early() {
    let mut dev = Device::new(sensors::scales(), "test");
    let mut sink = Sink::roomy();
    let burst = |n: usize| {
        let mut v = imu_proto::Vec::<RawSample, { pico_imu_core::device::BURST_MAX }>::new();
        for k in 0..n {
            let _ = v.push(RawSample {
                accel: [k as i16, 0, 8192],
                temp: Some(100),
                gyro: [0, 0, k as i16],
            });
        }
        v
    };
    // Burst 1 read at 10 ms: 6, 7, 8, 9, 10 ms. Burst 2 read at 13.9 ms, i.e. 1.1 ms earlier
    // than its 5 samples allow: nominally 9.9, 10.9, 11.9, 12.9, 13.9 ms.
    for t_us in [10_000, 13_900] {
        dev.on_sensor(
            &SensorMsg::Imu {
                t_us,
                samples: burst(5),
            },
            &mut sink,
        );
    }
    dev.flush(&mut sink);
    let stamps: Vec<u64> = sink
        .messages()
        .into_iter()
        .filter_map(|m| match m {
            DeviceMsg::Samples(b) => Some(b.imu.iter().map(|s| s.t_us).collect::<Vec<_>>()),
            _ => None,
        })
        .flatten()
        .collect();
    assert_eq!(
        stamps,
        vec![6_000, 7_000, 8_000, 9_000, 10_000, 10_001, 10_900, 11_900, 12_900, 13_900]
    );
}

/// Drives the magnetometer service for `ticks` ticks, either at the times it asks for
/// (`follow`) or on a fixed 5 ms grid; returns (readings, status polls, sensor measurements).
fn mag_poll_run(follow: bool, ticks: usize) -> (u64, u64, u64) {
    let bus = SimBus::new().with_mag(noisy_qmc());
    let mut mag = Qmc5883::new(bus.clone());
    let mut svc = MagService::new();
    let clock = bus.clone();
    let now = move || clock.now_ns() / 1000;
    let mut readings = 0;
    let mut next_grid = 5_000;
    for _ in 0..ticks {
        let at = match (follow, svc.next_poll_us()) {
            (true, Some(t)) => t,
            _ => next_grid,
        };
        while next_grid <= at {
            next_grid += 5_000;
        }
        bus.advance_us(at.saturating_sub(now()));
        let mut out = sensors::Out::new();
        block_on(svc.tick(&mut mag, &mut bus.delay(), &now, 0, &mut out));
        for m in &out {
            if let SensorMsg::Mag { skipped, .. } = m {
                assert!(!skipped, "a sample was overwritten");
                readings += 1;
            }
        }
    }
    let (polls, made) = bus.mag(|q| (q.status_reads, q.measurements));
    (readings, polls, made)
}

#[test]
fn the_magnetometer_poll_follows_the_sensor_phase() {
    // Initialised on the 5 ms grid, the sensor's samples land about 1 ms after each grid tick
    // (soft reset and configuration time), so on the grid every reading needs re-polls.
    let (grid_reads, grid_polls, grid_made) = mag_poll_run(false, 400);
    eprintln!("grid: {grid_reads} readings, {grid_polls} status polls, {grid_made} measurements");
    assert!(
        grid_polls >= 3 * grid_reads,
        "the scenario has a phase to find"
    );
    // Following the phase: after the first reading, one poll per reading plus one creep
    // re-poll every 25 readings; still every sample read.
    let (reads, polls, made) = mag_poll_run(true, 400);
    eprintln!("following: {reads} readings, {polls} status polls, {made} measurements");
    assert!(reads + 2 >= made, "{reads} readings of {made} measurements");
    assert!(
        polls * 100 <= reads * 110,
        "{polls} status polls for {reads} readings"
    );
}

/// The sensor tasks' slots: the incremental step (one addition) must give exactly what the
/// division gives, for a task that keeps up, one that wakes late inside the next period, and
/// one that misses whole periods (those slots are skipped, not caught up).
#[test]
fn task_slots_match_the_division_and_skip_missed_ones() {
    let by_division = |now: u64| (now.saturating_sub(250) / 5000 + 1) * 5000 + 250;
    let mut slots = Slots::new(5000, 250);
    assert_eq!(slots.next_after(0), 5250);
    assert_eq!(slots.next_after(5250), 10_250); // woke on time
    assert_eq!(slots.next_after(10_900), 15_250); // woke 650 µs late
    assert_eq!(slots.next_after(15_250 + 4_999), 20_250); // 1 µs before the next slot
    assert_eq!(slots.next_after(20_250 + 12_000), 35_250); // two slots missed: skipped
    assert_eq!(slots.next_after(35_000), 35_250); // asked before the last slot passed
    let mut now = 40_250;
    for step in [1u64, 4_999, 5_000, 7_777, 13, 23_456, 5_001, 0, 9_999] {
        now += step;
        assert_eq!(slots.next_after(now), by_division(now), "now = {now} µs");
    }
}

/// A stall between the FIFO-count transfer and the data transfer: the count (taken before it)
/// cannot show the overflow the stall causes, and the frames read after it would be
/// misaligned. The tick must see that the count is stale and handle it as an overflow (the
/// end-to-end test's 120 ms stall once fell exactly there).
#[test]
fn an_overflow_between_the_count_and_the_data_transfers_is_caught() {
    let mut rig = Rig::new();
    rig.run(1000);
    assert_eq!(rig.dev.status(0, 0).fifo_overflows, 0);
    // One IMU tick whose third clock read (the one right after the count transfer) comes
    // 120 ms later: the bus model advances, so the FIFO really overflows in between.
    rig.bus.advance_us(2000);
    let calls = std::cell::Cell::new(0);
    let bus = rig.bus.clone();
    let now = move || {
        calls.set(calls.get() + 1);
        if calls.get() == 3 {
            bus.advance_us(120_000);
        }
        bus.now_ns() / 1000
    };
    let mut out = sensors::Out::new();
    block_on(
        rig.imu_svc
            .tick(&mut rig.imu, &mut rig.bus.delay(), &now, 0, &mut out),
    );
    assert!(
        out.iter()
            .any(|m| matches!(m, SensorMsg::ImuOverflow { lost, .. } if *lost >= 40)),
        "no overflow reported: {out:?}"
    );
    assert!(
        !out.iter().any(|m| matches!(m, SensorMsg::Imu { .. })),
        "frames read after a stale count: {out:?}"
    );
    rig.feed(out);
    rig.run(200);
    let st = rig.dev.status(0, 0);
    assert_eq!(st.fifo_overflows, 1);
    assert_eq!(rig.dev.table(Channel::Gz).gaps, 1);
}
