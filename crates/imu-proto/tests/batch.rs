//! The hand-written sample-batch encoder (`FrameEncoder::encode_samples`) against the serde path
//! (`FrameEncoder::encode(&DeviceMsg::Samples(..))`): the same bytes for any batch, extreme
//! values included, and frames the host decoder reads back.
use imu_proto::*;
use proptest::prelude::*;

mod common;
use common::{batch_of, imu_sample, same_batch};

fn serde_frame(b: &SampleBatch) -> std::vec::Vec<u8> {
    let mut out = std::vec![0u8; MAX_FRAME];
    let n = FrameEncoder::new()
        .encode(&DeviceMsg::Samples(b.clone()), &mut out)
        .unwrap();
    out.truncate(n);
    out
}

fn direct_frame(b: &SampleBatch) -> std::vec::Vec<u8> {
    let mut out = std::vec![0u8; MAX_FRAME];
    let n = FrameEncoder::new().encode_samples(b, &mut out).unwrap();
    out.truncate(n);
    out
}

/// Integers weighted towards the varint boundaries and the extremes.
fn arb_i32() -> impl Strategy<Value = i32> {
    prop_oneof![
        any::<i32>(),
        Just(i32::MIN),
        Just(i32::MAX),
        Just(0),
        Just(-1),
        (0u32..31).prop_flat_map(|k| prop_oneof![Just(1i32 << k), Just(-(1i32 << k))]),
        (1u32..31).prop_map(|k| (1i32 << k) - 1),
    ]
}

fn arb_u32() -> impl Strategy<Value = u32> {
    prop_oneof![
        any::<u32>(),
        Just(u32::MAX),
        Just(0),
        (0u32..32).prop_map(|k| 1u32 << k),
        (1u32..32).prop_map(|k| (1u32 << k) - 1),
    ]
}

fn arb_u64() -> impl Strategy<Value = u64> {
    prop_oneof![
        any::<u64>(),
        Just(u64::MAX),
        Just(0),
        Just(u64::from(u32::MAX)),
        (0u32..64).prop_map(|k| 1u64 << k),
        (1u32..64).prop_map(|k| (1u64 << k) - 1),
        // Device uptimes: minutes to days in µs.
        0u64..(1 << 40),
    ]
}

fn arb_f32() -> impl Strategy<Value = f32> {
    prop_oneof![
        any::<f32>(),
        Just(f32::NAN),
        Just(-f32::NAN),
        Just(f32::INFINITY),
        Just(f32::NEG_INFINITY),
        Just(0.0),
        Just(-0.0),
        Just(f32::MIN_POSITIVE),
        any::<u32>().prop_map(f32::from_bits),
    ]
}

fn arb_batch() -> impl Strategy<Value = SampleBatch> {
    let imu = (
        arb_u32(),
        arb_u64(),
        [arb_i32(), arb_i32(), arb_i32()],
        [arb_i32(), arb_i32(), arb_i32()],
        arb_i32(),
    )
        .prop_map(imu_sample);
    let mag = (arb_u32(), arb_u64(), [arb_i32(), arb_i32(), arb_i32()])
        .prop_map(|(seq, t_us, mag)| MagSample { seq, t_us, mag });
    (
        any::<bool>(),
        proptest::collection::vec(imu, 0..=MAX_BATCH_IMU),
        proptest::collection::vec(mag, 0..=MAX_BATCH_MAG),
        [arb_f32(), arb_f32(), arb_f32(), arb_f32(), arb_f32()],
    )
        .prop_map(|(calibrated, imu, mag, s)| batch_of(calibrated, &imu, &mag, s))
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(3000))]

    #[test]
    fn encode_samples_writes_the_serde_paths_bytes_and_the_host_reads_them(b in arb_batch()) {
        let direct = direct_frame(&b);
        prop_assert_eq!(&direct, &serde_frame(&b));
        let mut rd = FrameReader::<MAX_FRAME>::new();
        let mut got = std::vec::Vec::new();
        rd.feed::<DeviceMsg>(&direct, |r| got.push(r));
        prop_assert_eq!(got.len(), 1);
        match got.pop().unwrap() {
            Ok(DeviceMsg::Samples(back)) => prop_assert!(same_batch(&back, &b)),
            other => prop_assert!(false, "decoded {:?}", other),
        }
    }

    /// Every output buffer shorter than the frame is refused with an error, never a panic and
    /// never a partial length; the exact size works.
    #[test]
    fn a_short_output_buffer_is_an_error(b in arb_batch(), cut in 0.0f64..1.0) {
        let full = direct_frame(&b);
        let short = (full.len() as f64 * cut) as usize;
        let mut out = std::vec![0u8; short];
        prop_assert_eq!(
            FrameEncoder::new().encode_samples(&b, &mut out),
            Err(EncodeError::TooLarge)
        );
        let mut out = std::vec![0u8; full.len()];
        prop_assert_eq!(FrameEncoder::new().encode_samples(&b, &mut out), Ok(full.len()));
        prop_assert_eq!(out, full);
    }
}

/// A small batch, byte for byte (the postcard fields worked out by hand, the CRC from the `crc`
/// crate's CRC-32/ISO-HDLC, then COBS).
#[test]
fn a_small_batch_frame_byte_for_byte() {
    let b = SampleBatch {
        calibrated: true,
        scales: Scales {
            accel: 1.0, // 00 00 80 3f
            gyro: -2.0, // 00 00 00 c0
            mag: 0.0,   // 00 00 00 00
            temp: 0.5,  // 00 00 00 3f
            temp_offset: f32::from_bits(0x0102_0304),
        },
        imu: Vec::from_slice(&[ImuSample {
            seq: 300,                      // ac 02
            t_us: 1 << 32,                 // 80 80 80 80 10
            accel: [-1, 1, 64],            // 01 02 80 01
            gyro: [i32::MIN, i32::MAX, 0], // ff ff ff ff 0f, fe ff ff ff 0f, 00
            temp: -65,                     // 81 01
        }])
        .unwrap(),
        mag: Vec::from_slice(&[MagSample {
            seq: 127,          // 7f
            t_us: u64::MAX,    // ff ×9, 01
            mag: [0, -64, 63], // 00 7f 7e
        }])
        .unwrap(),
    };
    #[rustfmt::skip]
    let content: &[u8] = &[
        PROTOCOL_VERSION, 0x01, // version, DeviceMsg::Samples
        0x01, // calibrated
        0x00, 0x00, 0x80, 0x3f, 0x00, 0x00, 0x00, 0xc0, 0x00, 0x00, 0x00, 0x00,
        0x00, 0x00, 0x00, 0x3f, 0x04, 0x03, 0x02, 0x01,
        0x01, // one IMU sample
        0xac, 0x02, 0x80, 0x80, 0x80, 0x80, 0x10,
        0x01, 0x02, 0x80, 0x01,
        0xff, 0xff, 0xff, 0xff, 0x0f, 0xfe, 0xff, 0xff, 0xff, 0x0f, 0x00,
        0x81, 0x01,
        0x01, // one magnetometer sample
        0x7f, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0x01,
        0x00, 0x7f, 0x7e,
    ];
    let crc = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC).checksum(content);
    let mut payload = content.to_vec();
    payload.extend_from_slice(&crc.to_le_bytes());
    let mut expected = std::vec![0u8; cobs::max_encoding_length(payload.len())];
    let n = cobs::try_encode(&payload, &mut expected).unwrap();
    expected.truncate(n);
    expected.push(0);
    assert_eq!(direct_frame(&b), expected);
    assert_eq!(serde_frame(&b), expected);
    // The COBS code bytes are where the zeros were: the first block is the version and the
    // variant, calibrated and the float's first byte is a zero.
    assert_eq!(&expected[..5], &[0x04, PROTOCOL_VERSION, 0x01, 0x01, 0x01]);
}

#[test]
fn an_empty_batch_frames_like_the_serde_path() {
    let b = SampleBatch {
        calibrated: false,
        scales: Scales {
            accel: f32::NAN,
            gyro: f32::INFINITY,
            mag: f32::NEG_INFINITY,
            temp: -0.0,
            temp_offset: f32::MAX,
        },
        imu: Vec::new(),
        mag: Vec::new(),
    };
    assert_eq!(direct_frame(&b), serde_frame(&b));
}
