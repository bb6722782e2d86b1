//! The hand-written sample-batch encoder (`FrameEncoder::encode_samples`) against the serde path
//! (`FrameEncoder::encode(&DeviceMsg::Samples(..))`): the same bytes for any batch, extreme
//! values included, and frames the host decoder reads back.
use imu_proto::*;
use proptest::prelude::*;

mod common;
use common::{batch_of, frame_with, imu_sample, same_batch};

fn serde_frame(b: &SampleBatch) -> std::vec::Vec<u8> {
    frame_with(|e, out| e.encode(&DeviceMsg::Samples(b.clone()), out)).unwrap()
}

fn direct_frame(b: &SampleBatch) -> std::vec::Vec<u8> {
    frame_with(|e, out| e.encode_samples(b, out)).unwrap()
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
        proptest::option::of(arb_i32()),
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
            temp: Some(-65),               // 01 81 01
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
        0x01, 0x81, 0x01,
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

/// Batches as the device makes them: consecutive sequence numbers (sometimes a jump, a gap),
/// times one period apart with a little jitter (sometimes a long pause or a step backwards).
fn arb_regular_batch() -> impl Strategy<Value = SampleBatch> {
    let step = prop_oneof![
        8 => (Just(1u32), -3i64..=3),
        1 => (2u32..100_000, 0i64..10_000_000),
        1 => (Just(1u32), -2_000i64..0),
    ];
    (
        arb_u32(),
        0u64..(1 << 40),
        proptest::collection::vec((step.clone(), arb_i32()), 0..=MAX_BATCH_IMU),
        proptest::collection::vec((step, arb_i32()), 0..=MAX_BATCH_MAG),
    )
        .prop_map(|(seq0, t0, imu_steps, mag_steps)| {
            let (mut seq, mut t) = (seq0, t0);
            let imu: std::vec::Vec<ImuSample> = imu_steps
                .iter()
                .map(|&((ds, jitter), v)| {
                    seq = seq.wrapping_add(ds);
                    t = t.wrapping_add(1_000).wrapping_add(jitter as u64);
                    imu_sample((
                        seq,
                        t,
                        [v, v.wrapping_neg(), 7],
                        [v / 3, 0, -1],
                        Some(v ^ 5),
                    ))
                })
                .collect();
            let (mut seq, mut t) = (seq0 / 5, t0);
            let mag: std::vec::Vec<MagSample> = mag_steps
                .iter()
                .map(|&((ds, jitter), v)| {
                    seq = seq.wrapping_add(ds);
                    t = t.wrapping_add(5_000).wrapping_add(jitter as u64);
                    MagSample {
                        seq,
                        t_us: t,
                        mag: [v, 1, v.wrapping_neg()],
                    }
                })
                .collect();
            batch_of(true, &imu, &mag, [1.0, 0.5, 0.25, 2.0, -1.0])
        })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]

    /// The delta layout on realistic runs: the same bytes both ways, and every sample back.
    #[test]
    fn regular_runs_round_trip_through_the_delta_layout(b in arb_regular_batch()) {
        let direct = direct_frame(&b);
        prop_assert_eq!(&direct, &serde_frame(&b));
        let mut rd = FrameReader::<MAX_FRAME>::new();
        let mut got = std::vec::Vec::new();
        rd.feed::<DeviceMsg>(&direct, |r| got.push(r));
        match got.pop() {
            Some(Ok(DeviceMsg::Samples(back))) => prop_assert_eq!(back, b),
            other => prop_assert!(false, "decoded {:?}", other),
        }
    }
}

/// Two IMU samples one period apart and two magnetometer samples one period + 3 µs apart:
/// the second of each carries 1 and zig-zag(0) = 0, resp. zig-zag(3) = 6.
#[test]
fn later_samples_carry_differences() {
    let imu = [
        imu_sample((1000, 50_000_000, [1, 2, 3], [4, 5, 6], Some(7))),
        imu_sample((1001, 50_001_000, [1, 2, 3], [4, 5, 6], Some(7))),
    ];
    let mag = [
        MagSample {
            seq: 9,
            t_us: 50_000_500,
            mag: [0, 0, 0],
        },
        MagSample {
            seq: 10,
            t_us: 50_005_503,
            mag: [0, 0, 0],
        },
    ];
    let b = batch_of(false, &imu, &mag, [1.0; 5]);
    let mut out = std::vec![0u8; MAX_FRAME];
    let n = FrameEncoder::new()
        .encode(&DeviceMsg::Samples(b.clone()), &mut out)
        .unwrap();
    let mut body = out[..n - 1].to_vec();
    let k = cobs::decode_in_place(&mut body).unwrap();
    #[rustfmt::skip]
    let expected: &[u8] = &[
        PROTOCOL_VERSION, 0x01, 0x00, // version, Samples, raw
    ];
    assert_eq!(&body[..3], expected);
    // After the 20 bytes of scales: IMU count, sample 0 (seq e8 07, t 80 e1 eb 17, values, the
    // temperature as `Some`: 01 0e), sample 1 (01 00, values).
    let imu_part = &body[23..];
    #[rustfmt::skip]
    let imu_expected: &[u8] = &[
        0x02,
        0xe8, 0x07, 0x80, 0xe1, 0xeb, 0x17, 0x02, 0x04, 0x06, 0x08, 0x0a, 0x0c, 0x01, 0x0e,
        0x01, 0x00, 0x02, 0x04, 0x06, 0x08, 0x0a, 0x0c, 0x01, 0x0e,
        0x02,
        0x09, 0xf4, 0xe4, 0xeb, 0x17, 0x00, 0x00, 0x00,
        0x01, 0x06, 0x00, 0x00, 0x00,
    ];
    assert_eq!(&imu_part[..k - 23 - 4], imu_expected);
    let back: DeviceMsg = decode(&mut out[..n - 1]).unwrap();
    assert_eq!(back, DeviceMsg::Samples(b));
}

/// What a [`BatchWriter`] is fed: IMU and magnetometer samples interleaved in any order, and
/// the points where the batch is sent.
#[derive(Debug, Clone)]
enum Feed {
    Imu(ImuSample),
    Mag(MagSample),
    Send,
}

fn arb_feed() -> impl Strategy<Value = (std::vec::Vec<Feed>, bool, [f32; 5])> {
    let imu = (
        arb_u32(),
        arb_u64(),
        [arb_i32(), arb_i32(), arb_i32()],
        [arb_i32(), arb_i32(), arb_i32()],
        proptest::option::of(arb_i32()),
    )
        .prop_map(|p| Feed::Imu(imu_sample(p)));
    let mag = (arb_u32(), arb_u64(), [arb_i32(), arb_i32(), arb_i32()])
        .prop_map(|(seq, t_us, mag)| Feed::Mag(MagSample { seq, t_us, mag }));
    // Long enough to fill both sensors' runs (32 and 16) now and then between sends.
    let feed = prop_oneof![20 => imu, 4 => mag, 1 => Just(Feed::Send)];
    (
        proptest::collection::vec(feed, 0..120),
        any::<bool>(),
        [arb_f32(), arb_f32(), arb_f32(), arb_f32(), arb_f32()],
    )
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(1000))]

    /// The batch written in its wire form as samples arrive (`BatchWriter`, the firmware's
    /// path) frames byte for byte as the `SampleBatch` of the same samples through
    /// `encode_samples` and through serde, over random samples and batch boundaries; a full
    /// run refuses the next sample and leaves the batch as it was.
    #[test]
    fn the_batch_written_as_samples_arrive_frames_like_the_sample_batch(
        (feed, calibrated, s) in arb_feed()
    ) {
        let mut w = BatchWriter::new();
        let (mut imu, mut mag) = (std::vec::Vec::new(), std::vec::Vec::new());
        let mut enc = FrameEncoder::new();
        let mut out = std::vec![0u8; MAX_FRAME];
        let mut sends = 0;
        for f in feed.iter().chain([&Feed::Send]) {
            match f {
                Feed::Imu(x) => {
                    let took = w.push_imu(x.seq, x.t_us, &x.accel, &x.gyro, x.temp);
                    prop_assert_eq!(took, imu.len() < MAX_BATCH_IMU);
                    if took {
                        imu.push(*x);
                    }
                }
                Feed::Mag(x) => {
                    let took = w.push_mag(*x);
                    prop_assert_eq!(took, mag.len() < MAX_BATCH_MAG);
                    if took {
                        mag.push(*x);
                    }
                }
                Feed::Send => {
                    prop_assert_eq!(w.imu_len(), imu.len());
                    prop_assert_eq!(w.mag_len(), mag.len());
                    prop_assert_eq!(w.is_empty(), imu.is_empty() && mag.is_empty());
                    prop_assert_eq!(w.mag_full(), mag.len() == MAX_BATCH_MAG);
                    let b = batch_of(calibrated, &imu, &mag, s);
                    let n = enc.encode_batch(&mut w, calibrated, &b.scales, &mut out).unwrap();
                    prop_assert_eq!(&out[..n], &direct_frame(&b)[..]);
                    prop_assert_eq!(&out[..n], &serde_frame(&b)[..]);
                    w.clear();
                    imu.clear();
                    mag.clear();
                    sends += 1;
                }
            }
        }
        prop_assert!(sends >= 1);
    }
}
