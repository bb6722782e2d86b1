//! No panic path from host input or bus data: the device state machine is hammered with random
//! host frames (decoded or not) and random sensor data, and the fault state machine is checked
//! step by step.
use imu_drivers::mpu6050::RawSample;
use imu_proto::{Event, FrameReader, HostFrame, Sensor, SensorState, MAX_FRAME};
use pico_imu_core::device::{Device, SensorMsg};
use pico_imu_core::health::{Health, ERRORS_TO_LOSE, RETRY_FIRST_MS, RETRY_MAX_MS};
use pico_imu_core::outbox::FrameSink;
use pico_imu_core::sensors;
use proptest::prelude::*;

struct CountSink {
    frames: usize,
    room: usize,
}

impl FrameSink for CountSink {
    fn room(&self) -> usize {
        self.room
    }
    fn put(&mut self, f: &[u8]) {
        assert!(f.len() <= self.room);
        assert_eq!(
            f.last(),
            Some(&0),
            "every queued frame ends with its delimiter"
        );
        self.frames += 1;
    }
}

fn raw() -> impl Strategy<Value = RawSample> {
    (
        any::<[i16; 3]>(),
        proptest::option::of(any::<i16>()),
        any::<[i16; 3]>(),
    )
        .prop_map(|(accel, temp, gyro)| RawSample { accel, temp, gyro })
}

fn sensor_msg() -> impl Strategy<Value = SensorMsg> {
    prop_oneof![
        (
            any::<u64>(),
            proptest::collection::vec(raw(), 0..=pico_imu_core::device::BURST_MAX)
        )
            .prop_map(|(t_us, v)| {
                SensorMsg::Imu {
                    t_us,
                    samples: imu_proto::Vec::from_slice(&v).unwrap(),
                }
            }),
        (any::<u64>(), any::<u32>()).prop_map(|(t_us, lost)| SensorMsg::ImuOverflow { t_us, lost }),
        (any::<u64>(), any::<[i16; 3]>(), any::<bool>())
            .prop_map(|(t_us, xyz, skipped)| SensorMsg::Mag { t_us, xyz, skipped }),
        any::<u64>().prop_map(|t_us| SensorMsg::Resumed { t_us }),
    ]
}

fn request() -> impl Strategy<Value = imu_proto::Request> {
    use imu_proto::{Request, StreamMode};
    prop_oneof![
        Just(Request::Identify),
        Just(Request::GetStatus),
        Just(Request::GetCalibration),
        Just(Request::ResetAllan),
        Just(Request::GetTables),
        (any::<u32>(), any::<u32>()).prop_map(|(s, t)| Request::SetIntervals {
            status_ms: s,
            tables_ms: t
        }),
        prop_oneof![
            Just(StreamMode::Off),
            Just(StreamMode::Raw),
            Just(StreamMode::Calibrated)
        ]
        .prop_map(Request::SetMode),
        (
            proptest::collection::vec(any::<u8>(), 0..=imu_proto::MAX_CAL_BLOB),
            any::<bool>()
        )
            .prop_map(|(b, persist)| Request::SetCalibration {
                blob: imu_proto::Vec::from_slice(&b).unwrap(),
                persist
            }),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(300))]

    /// Every well-formed request, in any order and with any arguments, gets exactly one reply
    /// (a persisted calibration after its write) and never panics.
    #[test]
    fn any_request_sequence_is_answered(reqs in proptest::collection::vec(request(), 1..30)) {
        let mut dev = Device::new(sensors::scales(), "test");
        let mut sink = CountSink { frames: 0, room: 1 << 20 };
        for (i, req) in reqs.into_iter().enumerate() {
            let before = sink.frames;
            if let Some(p) = dev.handle(HostFrame { id: i as u16, req }, 0, 0, &mut sink) {
                prop_assert_eq!(sink.frames, before, "no reply before the flash write");
                dev.persisted(p.id, i % 2 == 0, &mut sink);
            }
            prop_assert_eq!(sink.frames, before + 1);
        }
    }

    /// Random bytes from the host, through the firmware's frame reader into the device: every
    /// decoded request is answered, nothing panics.
    #[test]
    fn random_host_bytes_never_panic_the_device(bytes in proptest::collection::vec(any::<u8>(), 0..2048)) {
        let mut dev = Device::new(sensors::scales(), "test");
        let mut sink = CountSink { frames: 0, room: 1 << 20 };
        let mut rd = FrameReader::<512>::new();
        let mut handled = 0;
        for &b in &bytes {
            match rd.push::<HostFrame>(b) {
                Some(Ok(f)) => {
                    handled += 1;
                    if let Some(p) = dev.handle(f, 0, 0, &mut sink) {
                        dev.persisted(p.id, true, &mut sink);
                    }
                }
                Some(Err(_)) => dev.rejected_frame(),
                None => {}
            }
        }
        prop_assert_eq!(dev.status(0, 0).frames_rejected, rd.stats().rejected());
        prop_assert!(sink.frames >= handled);
    }

    /// Any sequence of sensor data (extreme counts, missing temperature, absurd timestamps)
    /// goes through the pipeline, tables and status without a panic, with and without room.
    #[test]
    fn random_sensor_data_never_panics_the_pipeline(
        msgs in proptest::collection::vec(sensor_msg(), 0..40), room in prop_oneof![Just(0usize), Just(1usize << 20)]
    ) {
        let mut dev = Device::new(sensors::scales(), "test");
        let mut sink = CountSink { frames: 0, room };
        for m in &msgs {
            dev.on_sensor(m, &mut sink);
        }
        dev.flush(&mut sink);
        dev.start_tables();
        for _ in 0..10 {
            dev.tables_step(&mut sink);
        }
        let _ = dev.status(u64::MAX, 1000);
        for ch in imu_proto::Channel::ALL {
            let t = dev.table(ch);
            for l in &t.levels {
                prop_assert!(l.dev.is_finite() && l.lo.is_finite() && l.hi.is_finite(), "{:?}", l);
            }
        }
    }
}

#[test]
fn a_sensor_is_lost_after_three_consecutive_errors_and_back_on_the_first_success() {
    let mut h = Health::new(Sensor::Imu);
    assert_eq!(h.ok(1_000), None);
    assert_eq!(h.state(), SensorState::Ok);
    // Two errors and a success: a glitch, not a loss.
    assert_eq!(h.error(2_000), None);
    assert_eq!(h.error(3_000), None);
    assert_eq!(h.ok(4_000), None);
    for k in 0..ERRORS_TO_LOSE - 1 {
        assert_eq!(h.error(5_000 + u64::from(k)), None);
    }
    assert_eq!(
        h.error(10_000),
        Some(Event::SensorLost {
            sensor: Sensor::Imu,
            t_us: 10_000
        })
    );
    assert_eq!(h.state(), SensorState::Missing);
    // First retry after 50 ms, then 100, 200, 400, 400 ms (capped).
    assert!(!h.retry_due(10_000 + RETRY_FIRST_MS * 1000 - 1));
    assert!(h.retry_due(10_000 + RETRY_FIRST_MS * 1000));
    let mut t = 10_000 + RETRY_FIRST_MS * 1000;
    let mut waits = Vec::new();
    for _ in 0..4 {
        assert_eq!(h.error(t), None, "a failed retry is not a new loss");
        let w = h.retry_in_us(t);
        waits.push(w / 1000);
        t += w;
    }
    assert_eq!(waits, vec![100, 200, RETRY_MAX_MS, RETRY_MAX_MS]);
    assert_eq!(
        h.ok(t),
        Some(Event::SensorBack {
            sensor: Sensor::Imu,
            t_us: t,
            down_us: t - 10_000
        })
    );
    assert_eq!(h.state(), SensorState::Ok);
}

#[test]
fn a_sensor_absent_at_boot_is_lost_on_its_first_failure() {
    let mut h = Health::new(Sensor::Mag);
    assert_eq!(
        h.error(7),
        Some(Event::SensorLost {
            sensor: Sensor::Mag,
            t_us: 7
        })
    );
}

#[test]
fn oversized_and_garbage_host_frames_are_counted_not_fatal() {
    let mut rd = FrameReader::<512>::new();
    let mut errors = 0;
    for b in std::iter::repeat_n(0x41u8, 5000).chain([0u8, 1, 2, 3, 0]) {
        if let Some(r) = rd.push::<HostFrame>(b) {
            assert!(r.is_err());
            errors += 1;
        }
    }
    assert_eq!(errors, 2);
    assert_eq!(rd.stats().oversize, 1);
    let _ = MAX_FRAME;
}
