//! The hand-written status encoder (`FrameEncoder::encode_status`) against the serde path
//! (`FrameEncoder::encode(&DeviceMsg::Status(..))`): the same bytes for any status, every enum
//! variant and varint-boundary values included, and frames the host decoder reads back.
use imu_proto::*;
use proptest::prelude::*;

mod common;
use common::{arb_bits, frame_with};

fn frame_of(s: &Status, direct: bool) -> Result<std::vec::Vec<u8>, EncodeError> {
    if direct {
        frame_with(|e, out| e.encode_status(s, out))
    } else {
        frame_with(|e, out| e.encode(&DeviceMsg::Status(*s), out))
    }
}

fn arb_state() -> impl Strategy<Value = SensorState> {
    prop::sample::select(vec![
        SensorState::Unknown,
        SensorState::Ok,
        SensorState::Missing,
        SensorState::Stalled,
    ])
}

fn arb_problem() -> impl Strategy<Value = CalProblem> {
    let f32s = || {
        // Not NaN: the decoded status is compared with the original.
        prop_oneof![
            -3e38f32..3e38,
            Just(f32::INFINITY),
            Just(f32::NEG_INFINITY),
            Just(0.0f32),
            -1e4f32..1e4
        ]
    };
    prop_oneof![
        Just(CalProblem::Corrupt),
        arb_bits(16).prop_map(|v| CalProblem::Version(v as u16)),
        Just(CalProblem::OutOfRange),
        (
            any::<u8>(),
            prop::option::of(any::<u8>()),
            f32s(),
            f32s(),
            f32s()
        )
            .prop_map(|(key, axis, value, lo, hi)| CalProblem::Implausible {
                key,
                axis,
                value,
                lo,
                hi
            }),
        Just(CalProblem::OtherRanges),
        Just(CalProblem::OtherPart),
    ]
}

fn arb_cal() -> impl Strategy<Value = CalStatus> {
    (
        prop::sample::select(vec![CalSource::Identity, CalSource::Flash, CalSource::Host]),
        prop::option::of(prop_oneof![
            Just(CalFault::Flash),
            arb_problem().prop_map(CalFault::Rejected),
        ]),
    )
        .prop_map(|(source, fault)| CalStatus { source, fault })
}

prop_compose! {
    fn arb_status()(
        counts in prop::array::uniform5(arb_bits(64)),
        counters in prop::array::uniform6(arb_bits(32)),
        cpu in arb_bits(16),
        temp in prop::option::of(prop_oneof![any::<i32>(), Just(i32::MIN), Just(i32::MAX), -64i32..64]),
        imu in arb_state(),
        mag in arb_state(),
        periods in prop::array::uniform2(arb_bits(32)),
        cal in arb_cal(),
        mode in prop::sample::select(vec![StreamMode::Off, StreamMode::Calibrated, StreamMode::Raw]),
    ) -> Status {
        Status {
            uptime_us: counts[0] as u64,
            samples_taken: counts[1] as u64,
            samples_dropped: counts[2] as u64,
            mag_samples: counts[3] as u64,
            mag_dropped: counts[4] as u64,
            fifo_overflows: counters[0] as u32,
            i2c_errors: counters[1] as u32,
            bus_faults: counters[2] as u32,
            bus_recoveries: counters[3] as u32,
            frames_rejected: counters[4] as u32,
            frames_unsent: counters[5] as u32,
            cpu_load_permille: cpu as u16,
            temp_milli_c: temp,
            imu,
            mag,
            imu_period_ns: periods[0] as u32,
            mag_period_ns: periods[1] as u32,
            cal,
            mode,
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(3000))]
    #[test]
    fn encode_status_writes_the_serde_paths_bytes_and_the_host_reads_them(s in arb_status()) {
        let serde = frame_of(&s, false);
        let direct = frame_of(&s, true);
        prop_assert_eq!(&direct, &serde);
        let mut bytes = direct.unwrap();
        bytes.pop(); // the delimiter
        prop_assert_eq!(decode::<DeviceMsg>(&mut bytes).unwrap(), DeviceMsg::Status(s));
    }
}

/// An output buffer too small for the frame is an error, never a panic.
#[test]
fn a_buffer_too_small_is_an_error() {
    let s = Status {
        uptime_us: u64::MAX,
        samples_taken: u64::MAX,
        samples_dropped: u64::MAX,
        mag_samples: u64::MAX,
        mag_dropped: u64::MAX,
        fifo_overflows: u32::MAX,
        i2c_errors: u32::MAX,
        bus_faults: u32::MAX,
        bus_recoveries: u32::MAX,
        frames_rejected: u32::MAX,
        frames_unsent: u32::MAX,
        cpu_load_permille: u16::MAX,
        temp_milli_c: Some(i32::MIN),
        imu: SensorState::Stalled,
        mag: SensorState::Missing,
        imu_period_ns: u32::MAX,
        mag_period_ns: u32::MAX,
        cal: CalStatus {
            source: CalSource::Host,
            fault: Some(CalFault::Rejected(CalProblem::Version(u16::MAX))),
        },
        mode: StreamMode::Raw,
    };
    let whole = frame_of(&s, true).unwrap();
    let mut enc = FrameEncoder::new();
    for len in 0..whole.len() {
        let mut out = vec![0u8; len];
        assert!(enc.encode_status(&s, &mut out).is_err(), "{len} bytes");
    }
}
