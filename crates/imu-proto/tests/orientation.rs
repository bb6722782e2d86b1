//! The hand-written attitude-frame encoder (`FrameEncoder::encode_orientations`) against the
//! serde path (`FrameEncoder::encode(&DeviceMsg::Orientation(..))`): the same bytes for any
//! list, every state and varint-boundary values included, and frames the host decoder reads
//! back.
use imu_proto::*;
use proptest::prelude::*;

mod common;
use common::{arb_bits, frame_with};

fn frame_of(
    list: &Vec<Orientation, MAX_ORIENTATIONS>,
    direct: bool,
) -> Result<std::vec::Vec<u8>, EncodeError> {
    if direct {
        frame_with(|e, out| e.encode_orientations(list, out))
    } else {
        frame_with(|e, out| e.encode(&DeviceMsg::Orientation(list.clone()), out))
    }
}

fn arb_f32() -> impl Strategy<Value = f32> {
    // Not NaN: the decoded list is compared with the original.
    prop_oneof![
        -1f32..1.0,
        -180f32..360.0,
        -3e38f32..3e38,
        Just(0.0f32),
        Just(-0.0f32),
        Just(f32::INFINITY),
        Just(f32::MIN_POSITIVE / 2.0),
    ]
}

fn arb_orientation() -> impl Strategy<Value = Orientation> {
    (
        arb_bits(32),
        arb_bits(64),
        prop::array::uniform4(arb_f32()),
        prop::array::uniform3(arb_f32()),
        prop::sample::select(vec![
            AhrsState::Converging,
            AhrsState::Tracking,
            AhrsState::MagField,
            AhrsState::MagDip,
        ]),
    )
        .prop_map(|(seq, t_us, q, a, state)| Orientation {
            seq: seq as u32,
            t_us: t_us as u64,
            q,
            roll_deg: a[0],
            pitch_deg: a[1],
            heading_deg: a[2],
            state,
        })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]
    #[test]
    fn encode_orientations_writes_the_serde_paths_bytes_and_the_host_reads_them(
        list in prop::collection::vec(arb_orientation(), 0..=MAX_ORIENTATIONS)
    ) {
        let list: Vec<Orientation, MAX_ORIENTATIONS> = list.into_iter().collect();
        let serde = frame_of(&list, false);
        let direct = frame_of(&list, true);
        prop_assert_eq!(&direct, &serde);
        let mut bytes = direct.unwrap();
        bytes.pop(); // the delimiter
        prop_assert_eq!(decode::<DeviceMsg>(&mut bytes).unwrap(), DeviceMsg::Orientation(list));
    }
}

/// An output buffer too small for the frame is an error, never a panic.
#[test]
fn a_buffer_too_small_is_an_error() {
    let o = Orientation {
        seq: u32::MAX,
        t_us: u64::MAX,
        q: [1.0, -0.5, 0.25, f32::MAX],
        roll_deg: -180.0,
        pitch_deg: 90.0,
        heading_deg: 359.9,
        state: AhrsState::MagDip,
    };
    let list: Vec<Orientation, MAX_ORIENTATIONS> =
        core::iter::repeat_n(o, MAX_ORIENTATIONS).collect();
    let whole = frame_of(&list, true).unwrap();
    let mut enc = FrameEncoder::new();
    for len in 0..whole.len() {
        let mut out = vec![0u8; len];
        assert!(
            enc.encode_orientations(&list, &mut out).is_err(),
            "{len} bytes"
        );
    }
}
