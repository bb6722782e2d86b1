//! No panic path from host input or bus data: the device state machine is hammered with random
//! host frames (decoded or not) and random sensor data, and the fault state machine is checked
//! step by step.
use imu_drivers::mpu6050::{FifoFrame, RawSample};
use imu_proto::{Event, FrameReader, GapCause, HostFrame, Sensor, SensorState, MAX_FRAME};
use pico_imu_core::clock::{Fine, Stamps, US};
use pico_imu_core::config;
use pico_imu_core::device::Device;
use pico_imu_core::health::{Health, LOSE_AFTER_US, RETRY_FIRST_MS, RETRY_MAX_MS, STALL_AFTER_US};
use pico_imu_core::msg::{FifoFrames, Report, SensorMsg, BURST_MAX};
use pico_imu_core::outbox::FrameSink;
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

/// The FIFO frames of `v` as the part sends them (with the temperature or without), the count
/// claiming `extra` frames more than were written (even past the buffer).
fn fifo_frames(v: &[RawSample], temp: bool, extra: usize) -> FifoFrames {
    let layout = if temp {
        FifoFrame::AccelTempGyro
    } else {
        FifoFrame::AccelGyro
    };
    let mut f = FifoFrames::of(layout, v);
    f.n += extra;
    f
}

fn cause() -> impl Strategy<Value = Option<GapCause>> {
    proptest::option::of(prop_oneof![
        Just(GapCause::FifoOverflow),
        Just(GapCause::SensorFault),
        Just(GapCause::BusFault),
        Just(GapCause::Stalled),
        Just(GapCause::Overwritten),
        Just(GapCause::Paused),
    ])
}

fn stamps() -> impl Strategy<Value = Stamps> {
    (any::<u32>(), any::<u64>(), 0u64..(10_000 * US).raw()).prop_map(|(k0, t0, period)| Stamps {
        k0,
        t0: Fine::from_raw(t0 >> 1),
        period: Fine::from_raw(period),
    })
}

fn sensor_msg() -> impl Strategy<Value = SensorMsg> {
    prop_oneof![
        (
            stamps(),
            proptest::collection::vec(raw(), 0..=BURST_MAX),
            any::<bool>(),
            0usize..4,
            cause()
        )
            .prop_map(|(stamps, v, temp, extra, after)| SensorMsg::Imu {
                stamps,
                frames: fifo_frames(&v, temp, extra),
                after,
            }),
        (stamps(), any::<[i16; 3]>(), cause()).prop_map(|(stamps, xyz, after)| SensorMsg::Mag {
            stamps,
            xyz,
            after
        }),
        (any::<u32>(), any::<u32>(), any::<bool>()).prop_map(|(e, b, imu)| {
            SensorMsg::Report(Report {
                sensor: if imu { Sensor::Imu } else { Sensor::Mag },
                state: SensorState::Stalled,
                i2c_errors: e,
                bus_faults: b,
                fifo_overflows: e,
                period_ns: b,
                event: None,
            })
        }),
        (any::<u64>(), any::<u8>(), any::<bool>()).prop_map(|(t_us, pulses, sda_released)| {
            SensorMsg::BusRecovered {
                t_us,
                pulses,
                sda_released,
            }
        }),
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
        let mut dev = Device::new(config::scales(), "test");
        let mut sink = CountSink { frames: 0, room: 1 << 20 };
        for (i, req) in reqs.into_iter().enumerate() {
            let before = sink.frames;
            if let Some(p) = dev.handle(HostFrame { id: i as u16, req }, 0, 0, &mut sink) {
                prop_assert_eq!(sink.frames, before, "no reply before the flash write");
                dev.persisted(&p, i % 2 == 0, &mut sink);
            }
            prop_assert_eq!(sink.frames, before + 1);
        }
    }

    /// Random bytes from the host, through the firmware's frame reader into the device: every
    /// decoded request is answered, nothing panics.
    #[test]
    fn random_host_bytes_never_panic_the_device(bytes in proptest::collection::vec(any::<u8>(), 0..2048)) {
        let mut dev = Device::new(config::scales(), "test");
        let mut sink = CountSink { frames: 0, room: 1 << 20 };
        let mut rd = FrameReader::<512>::new();
        let mut handled = 0;
        for &b in &bytes {
            match rd.push::<HostFrame>(b) {
                Some(Ok(f)) => {
                    handled += 1;
                    if let Some(p) = dev.handle(f, 0, 0, &mut sink) {
                        dev.persisted(&p, true, &mut sink);
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
        let mut dev = Device::new(config::scales(), "test");
        let mut sink = CountSink { frames: 0, room };
        for m in &msgs {
            dev.on_sensor(m, &mut sink);
        }
        dev.flush(&mut sink);
        dev.start_tables(0);
        for i in 0..12u64 {
            dev.tables_step(i * 100_000, &mut sink);
        }
        let st = dev.status(u64::MAX, 1000);
        // The counters are the sums of what was reported, never wrapped.
        prop_assert!(st.samples_taken <= 40 * BURST_MAX as u64);
        for ch in imu_proto::Channel::ALL {
            let t = dev.table(ch, 0);
            prop_assert!(t.levels.iter().all(|l| l.n2 > 0));
        }
    }
}

/// Failures for less than LOSE_AFTER_US are retried, not a loss; longer ones are, and the
/// retries back off from 50 ms to 400 ms; delivering again reports the time out.
#[test]
fn a_sensor_is_lost_only_after_failing_for_a_while_and_back_when_it_delivers() {
    let mut h = Health::new(Sensor::Imu);
    assert_eq!(h.delivering(1_000), None);
    assert_eq!(h.state(), SensorState::Ok);
    // Failures for 90 ms and a success: a glitch, not a loss.
    assert_eq!(h.failed(2_000), None);
    assert_eq!(h.failed(92_000), None);
    h.answered();
    assert_eq!(h.failed(100_000), None);
    assert_eq!(h.failed(100_000 + LOSE_AFTER_US - 1), None);
    let t0 = 100_000 + LOSE_AFTER_US;
    assert_eq!(
        h.failed(t0),
        Some(Event::SensorLost {
            sensor: Sensor::Imu,
            t_us: t0
        })
    );
    assert_eq!(h.state(), SensorState::Missing);
    // First retry after 50 ms, then 100, 200, 400, 400 ms (capped).
    assert!(!h.retry_due(t0 + RETRY_FIRST_MS * 1000 - 1));
    let mut t = t0 + RETRY_FIRST_MS * 1000;
    let mut waits = Vec::new();
    for _ in 0..4 {
        assert!(h.retry_due(t));
        h.retried(t);
        assert_eq!(h.failed(t), None, "a failed retry is not a new loss");
        let mut w = 1;
        while !h.retry_due(t + w * 1000) {
            w += 1;
        }
        waits.push(w);
        t += w * 1000;
    }
    assert_eq!(waits, vec![100, 200, RETRY_MAX_MS, RETRY_MAX_MS]);
    // Answering is not yet delivering: the state changes with the first sample.
    h.answered();
    assert_eq!(h.state(), SensorState::Missing);
    assert_eq!(
        h.delivering(t),
        Some(Event::SensorBack {
            sensor: Sensor::Imu,
            t_us: t,
            down_us: t - 100_000
        })
    );
    assert_eq!(h.state(), SensorState::Ok);
}

#[test]
fn a_stall_is_reported_once_and_its_end_as_a_return() {
    let mut h = Health::new(Sensor::Mag);
    h.delivering(1_000);
    let t = 1_000 + STALL_AFTER_US;
    assert_eq!(
        h.stalled(t, 1_000),
        Some(Event::SensorStalled {
            sensor: Sensor::Mag,
            t_us: t,
            since_us: 1_000
        })
    );
    assert_eq!(h.stalled(t + 5_000, 1_000), None);
    assert_eq!(h.state(), SensorState::Stalled);
    assert!(h.retry_due(t + RETRY_FIRST_MS * 1000));
    assert!(matches!(
        h.delivering(t + 300_000),
        Some(Event::SensorBack { down_us, .. }) if down_us == t + 300_000 - 1_000
    ));
}

#[test]
fn a_sensor_absent_at_boot_is_lost_on_its_first_failure() {
    let mut h = Health::new(Sensor::Mag);
    assert_eq!(
        h.failed(7),
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
