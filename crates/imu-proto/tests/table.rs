//! The hand-written Allan-table encoder (`FrameEncoder::encode_table`) against the serde path
//! (`FrameEncoder::encode(&DeviceMsg::Table(..))`): the same bytes for any table, extreme and
//! varint-boundary values included, and frames the host decoder reads back.
use imu_proto::*;
use proptest::prelude::*;

mod common;
use common::{arb_bits, frame_with};

fn frame_of(t: &AllanTable, direct: bool) -> Result<std::vec::Vec<u8>, EncodeError> {
    if direct {
        frame_with(|e, out| e.encode_table(t, out))
    } else {
        frame_with(|e, out| e.encode(&DeviceMsg::Table(t.clone()), out))
    }
}

fn arb_level() -> impl Strategy<Value = AllanLevel> {
    (
        arb_bits(32),
        arb_bits(32),
        arb_bits(64),
        arb_bits(128),
        arb_bits(64),
        arb_bits(128),
    )
        .prop_map(|(m, stride, n2, sum2, n3, sum3)| AllanLevel {
            m: m as u32,
            stride: stride as u32,
            n2: n2 as u64,
            sum2,
            n3: n3 as u64,
            sum3,
        })
}

fn arb_table() -> impl Strategy<Value = AllanTable> {
    (
        0..Channel::ALL.len(),
        arb_bits(32),
        arb_bits(64),
        arb_bits(32),
        prop_oneof![any::<f32>(), Just(0.0f32), Just(1e-9f32), Just(f32::NAN)],
        arb_bits(64),
        arb_bits(32),
        prop::collection::vec(arb_level(), 0..=MAX_LEVELS),
    )
        .prop_map(
            |(c, snapshot, t_us, tau0_ns, scale, pushed, gaps, levels)| AllanTable {
                channel: Channel::ALL[c],
                snapshot: snapshot as u32,
                t_us: t_us as u64,
                tau0_ns: tau0_ns as u32,
                scale,
                pushed: pushed as u64,
                gaps: gaps as u32,
                levels: levels.into_iter().collect(),
            },
        )
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]
    #[test]
    fn encode_table_writes_the_serde_paths_bytes_and_the_host_reads_them(t in arb_table()) {
        let serde = frame_of(&t, false);
        let direct = frame_of(&t, true);
        prop_assert_eq!(&direct, &serde);
        let mut bytes = direct.unwrap();
        bytes.pop(); // the delimiter
        match decode::<DeviceMsg>(&mut bytes).unwrap() {
            DeviceMsg::Table(back) => {
                prop_assert_eq!(back.levels, t.levels);
                prop_assert_eq!((back.channel, back.pushed, back.gaps), (t.channel, t.pushed, t.gaps));
                prop_assert_eq!(back.scale.to_bits(), t.scale.to_bits());
            }
            other => prop_assert!(false, "decoded {:?}", other),
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(500))]
    /// A table framed a few levels at a time (`FrameBuilder`, the parts of `table`), with the
    /// builder reused from a previous frame: the same frame as `encode_table`, padded with zero
    /// bytes to the alignment asked for.
    #[test]
    fn a_table_framed_in_pieces_is_the_whole_tables_frame(
        t in arb_table(),
        before in arb_table(),
        per_piece in 1usize..6,
        align in 1usize..9,
    ) {
        let whole = frame_of(&t, true).unwrap();
        let mut b = FrameBuilder::<{ 4 * 1024 }>::new();
        // A frame built before and never finished, or finished: nothing of it is left.
        b.start();
        let mut buf = [0u8; table::LEVEL_MAX];
        let n = table::write_head(&before, before.levels.len(), &mut buf).unwrap();
        b.push(&buf[..n]);
        b.start();
        let mut head = [0u8; table::HEAD_MAX];
        let n = table::write_head(&t, t.levels.len(), &mut head).unwrap();
        b.push(&head[..n]);
        for piece in t.levels.chunks(per_piece) {
            for l in piece {
                let n = table::write_level(l, &mut buf).unwrap();
                b.push(&buf[..n]);
            }
        }
        let framed = b.finish(align).unwrap();
        prop_assert_eq!(&framed[..whole.len()], &whole[..]);
        prop_assert_eq!(framed.len(), whole.len().next_multiple_of(align));
        prop_assert!(framed[whole.len()..].iter().all(|&x| x == 0));
    }
}

/// A builder too small for the frame says so, never panics.
#[test]
fn a_frame_builder_too_small_is_an_error() {
    let t = AllanTable {
        channel: Channel::Gx,
        snapshot: 1,
        t_us: 1,
        tau0_ns: 1_000_000,
        scale: 1.0,
        pushed: 100,
        gaps: 0,
        levels: (0..5)
            .map(|k| AllanLevel {
                m: 1 << k,
                stride: 1,
                n2: 90,
                sum2: 1 << 50,
                n3: 80,
                sum3: 1 << 51,
            })
            .collect(),
    };
    let whole = frame_of(&t, true).unwrap();
    let mut b = FrameBuilder::<64>::new();
    b.start();
    let mut buf = [0u8; table::LEVEL_MAX];
    let n = table::write_head(&t, t.levels.len(), &mut buf).unwrap();
    b.push(&buf[..n]);
    for l in &t.levels {
        let n = table::write_level(l, &mut buf).unwrap();
        b.push(&buf[..n]);
    }
    assert!(whole.len() > 64);
    assert_eq!(b.finish(4), Err(EncodeError::TooLarge));
}

/// Every channel, each at its own variant index; and a buffer one byte short fails, not
/// truncates.
#[test]
fn every_channel_and_a_short_buffer() {
    for ch in Channel::ALL {
        let t = AllanTable {
            channel: ch,
            snapshot: 3,
            t_us: 10_000_123,
            tau0_ns: 1_000_000,
            scale: 0.061,
            pushed: 9_000,
            gaps: 1,
            levels: (0..20)
                .map(|k| AllanLevel {
                    m: 1 << k,
                    stride: (1u32 << k).div_ceil(8),
                    n2: 9_000 - (2 << k).min(9_000),
                    sum2: 1u128 << (40 + 3 * k),
                    n3: 9_000 - (3 << k).min(9_000),
                    sum3: (1u128 << (41 + 3 * k)) - 1,
                })
                .collect(),
        };
        let direct = frame_of(&t, true).unwrap();
        assert_eq!(direct, frame_of(&t, false).unwrap(), "{ch:?}");
        let mut out = std::vec![0u8; direct.len() - 1];
        assert_eq!(
            FrameEncoder::new().encode_table(&t, &mut out),
            Err(EncodeError::TooLarge)
        );
    }
}
