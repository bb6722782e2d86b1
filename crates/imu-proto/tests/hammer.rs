//! The decoder hammered with random bytes, truncations and bit flips: it must never panic,
//! must reject every damaged frame it cannot prove intact, and must resynchronise on the next
//! good frame.
use imu_proto::*;
use proptest::prelude::*;

mod common;
use common::{batch_of, imu_sample, same_batch};

fn frame<T: serde::Serialize>(msg: &T) -> std::vec::Vec<u8> {
    let mut enc = FrameEncoder::new();
    let mut out = std::vec![0u8; MAX_FRAME];
    let n = enc.encode(msg, &mut out).unwrap();
    out.truncate(n);
    out
}

fn arb_request() -> impl Strategy<Value = Request> {
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
            proptest::collection::vec(any::<u8>(), 0..=MAX_CAL_BLOB),
            any::<bool>()
        )
            .prop_map(|(b, persist)| {
                Request::SetCalibration {
                    blob: Vec::from_slice(&b).unwrap(),
                    persist,
                }
            }),
    ]
}

fn arb_batch() -> impl Strategy<Value = SampleBatch> {
    let imu = (
        any::<u32>(),
        any::<u64>(),
        any::<[i32; 3]>(),
        any::<[i32; 3]>(),
        proptest::option::of(any::<i32>()),
    )
        .prop_map(imu_sample);
    let mag = (any::<u32>(), any::<u64>(), any::<[i32; 3]>())
        .prop_map(|(seq, t_us, mag)| MagSample { seq, t_us, mag });
    (
        any::<bool>(),
        proptest::collection::vec(imu, 0..=MAX_BATCH_IMU),
        proptest::collection::vec(mag, 0..=MAX_BATCH_MAG),
        any::<[f32; 5]>(),
    )
        .prop_map(|(calibrated, imu, mag, s)| batch_of(calibrated, &imu, &mag, s))
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]

    #[test]
    fn random_bytes_never_panic_and_never_pass_as_a_frame(bytes in proptest::collection::vec(any::<u8>(), 0..4096)) {
        let mut rd = FrameReader::<MAX_FRAME>::new();
        let mut oks = 0u32;
        rd.feed::<HostFrame>(&bytes, |r| if r.is_ok() { oks += 1 });
        rd.feed::<DeviceMsg>(&[0], |r| if r.is_ok() { oks += 1 });
        // A random frame passes only if its CRC-32 matches by chance (2^-32 per frame) and it
        // also parses; over 2000 cases of ≲ 4096 bytes the expected count is ~1e-3.
        prop_assert_eq!(oks, 0);
        let s = rd.stats();
        prop_assert_eq!(s.ok, 0);
    }

    #[test]
    fn requests_round_trip(id in any::<u16>(), req in arb_request()) {
        let m = HostFrame { id, req };
        let mut f = frame(&m);
        f.pop();
        prop_assert_eq!(decode::<HostFrame>(&mut f), Ok(m));
    }

    #[test]
    fn batches_round_trip(b in arb_batch()) {
        let mut f = frame(&DeviceMsg::Samples(b.clone()));
        f.pop();
        match decode::<DeviceMsg>(&mut f) {
            Ok(DeviceMsg::Samples(got)) => prop_assert!(same_batch(&got, &b)),
            other => prop_assert!(false, "decoded {:?}", other),
        }
    }

    #[test]
    fn every_truncation_is_rejected(req in arb_request(), cut_frac in 0.0f64..1.0) {
        let mut f = frame(&HostFrame { id: 1, req });
        f.pop();
        let cut = ((f.len() as f64) * cut_frac) as usize; // 0 ..= len-1: always a strict prefix
        let mut t = f[..cut].to_vec();
        let r = decode::<HostFrame>(&mut t);
        prop_assert!(r.is_err(), "a {}-byte prefix of a {}-byte frame decoded: {:?}", cut, f.len(), r);
    }

    #[test]
    fn every_single_bit_flip_is_rejected_and_the_stream_resynchronises(
        b in arb_batch(), pos_frac in 0.0f64..1.0, bit in 0u8..8
    ) {
        let msg = DeviceMsg::Samples(b.clone());
        let good = frame(&msg);
        let mut bad = good.clone();
        let pos = ((good.len() - 1) as f64 * pos_frac) as usize; // never the delimiter itself
        bad[pos] ^= 1 << bit;
        let mut rd = FrameReader::<MAX_FRAME>::new();
        let mut out = std::vec::Vec::new();
        rd.feed::<DeviceMsg>(&bad, |r| out.push(r));
        rd.feed::<DeviceMsg>(&good, |r| out.push(r));
        // CRC-32 detects every single-bit error (Koopman & Chakravarty 2004); a flip that makes
        // a zero splits the frame in two, both of which must be rejected too.
        let n_bad = out.len() - 1;
        for r in &out[..n_bad] {
            prop_assert!(r.is_err(), "damaged frame accepted: {:?}", r);
        }
        match out.last() {
            Some(Ok(DeviceMsg::Samples(got))) => prop_assert!(same_batch(got, &b)),
            other => prop_assert!(false, "good frame after a bad one not read: {:?}", other),
        }
        prop_assert_eq!(rd.stats().rejected() as usize, n_bad);
    }
}

/// Byte strings with long non-zero runs and zeros placed around the 254-byte block boundary.
fn cobs_input() -> impl Strategy<Value = std::vec::Vec<u8>> {
    prop_oneof![
        proptest::collection::vec(any::<u8>(), 0..700),
        proptest::collection::vec(1u8..=255, 250..260),
        (0usize..600, 0usize..600).prop_map(|(n, z)| {
            let mut v = std::vec![0x5Au8; n];
            if z < n {
                v[z] = 0;
            }
            v
        }),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]

    /// The firmware's COBS encoder writes exactly what the `cobs` crate writes, and it decodes back.
    #[test]
    fn cobs_encode_matches_the_cobs_crate(src in cobs_input()) {
        let mut ours = std::vec![0u8; cobs::max_encoding_length(src.len())];
        let n = cobs_encode(&src, &mut ours).expect("room");
        let mut theirs = std::vec![0u8; cobs::max_encoding_length(src.len())];
        let m = cobs::try_encode(&src, &mut theirs).expect("room");
        prop_assert_eq!(&ours[..n], &theirs[..m]);
        let mut back = ours[..n].to_vec();
        let k = cobs::decode_in_place(&mut back).expect("decodes");
        prop_assert_eq!(&back[..k], &src[..]);
    }
}

/// Content for the fused CRC and COBS scan: as for `cobs_input`, plus zero-heavy strings (a
/// zero every few bytes, as in sample batches) and long runs of zeros.
fn frame_content() -> impl Strategy<Value = std::vec::Vec<u8>> {
    prop_oneof![
        cobs_input(),
        proptest::collection::vec(prop_oneof![3 => 1u8..=255, 1 => Just(0u8)], 0..900),
        (0usize..600).prop_map(|n| std::vec![0u8; n]),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(1000))]

    /// The frame encoder's one scan (CRC, zeros turned into code bytes as they come), fed the
    /// content in random pieces, writes what the `crc` and `cobs` crates make of
    /// `version | content | CRC-32 LE`, then the delimiter.
    #[test]
    fn the_fused_crc_and_cobs_scan_matches_the_crates(
        content in frame_content(),
        cuts in proptest::collection::vec(0usize..900, 0..6),
    ) {
        let mut b = FrameBuilder::<4096>::new();
        b.start();
        let mut cuts: std::vec::Vec<usize> =
            cuts.into_iter().map(|c| c.min(content.len())).collect();
        cuts.sort_unstable();
        let mut from = 0;
        for c in cuts.into_iter().chain([content.len()]) {
            b.push(&content[from..c]);
            from = c;
        }
        let ours = b.finish(1).expect("room").to_vec();
        let mut payload = std::vec![PROTOCOL_VERSION];
        payload.extend_from_slice(&content);
        let crc = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC).checksum(&payload);
        payload.extend_from_slice(&crc.to_le_bytes());
        let mut theirs = std::vec![0u8; cobs::max_encoding_length(payload.len())];
        let m = cobs::try_encode(&payload, &mut theirs).expect("room");
        theirs.truncate(m);
        theirs.push(0);
        prop_assert_eq!(ours, theirs);
    }
}

#[test]
fn cobs_encode_refuses_a_short_buffer_instead_of_panicking() {
    let src = [1u8; 300];
    let mut dst = [0u8; 301];
    assert_eq!(cobs_encode(&src, &mut dst), None);
    let mut dst = [0u8; 302];
    assert_eq!(cobs_encode(&src, &mut dst), Some(302));
}
