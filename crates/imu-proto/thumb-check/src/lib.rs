//! Differential test of imu-proto's frame scan in Thumb code (`pico_imu_crc_cobs` in
//! crates/imu-proto/src/framing.rs: the CRC-32 four bytes at a time, COBS as the bytes come)
//! against references that share nothing with it: the `crc` crate's CRC-32/ISO-HDLC and a
//! plain COBS encoder written here.
//!
//! Each case is a frame's content drawn at random — its length (0 to 1,000 bytes: shorter
//! than a word, across COBS's 254-byte blocks), its bytes (zeros from never to always, the
//! bytes 0x01, 0x80 and 0xFF that sit at the edges of the routine's zero-byte test), where it
//! starts in memory (every word alignment) and the pieces it is pushed in — framed with
//! [`FrameBuilder`] and compared byte for byte with `COBS(version | content | CRC LE) 0x00`.
//! The edges the routine has (alignments of a piece's start, a zero in each byte of a word, a
//! full COBS block inside a word run) are counted, so a run that never reached one fails.
#![no_std]

use imu_proto::{FrameBuilder, PROTOCOL_VERSION};
use thumb_check_rt::Rng;

/// Frames compared in a run.
pub const CASES: u32 = 4_000;
/// The generator's seed.
pub const SEED: u32 = 0x6672_616d;
pub use thumb_check_rt::{DONE, RUNNING};

/// Edge counters ([`Report::edges`]).
pub mod edge {
    /// Pieces of at least 8 bytes starting at an address ≡ k (mod 4), k = 0…3 (indices 0–3).
    pub const ALIGN: usize = 0;
    /// Words of the content (at a multiple of 4 in memory) with a zero in byte k and none
    /// before it, k = 0…3 (indices 4–7).
    pub const ZERO_AT: usize = 4;
    /// Contents with a run of at least 254 non-zero bytes (a full COBS block).
    pub const FULL_BLOCK: usize = 8;
    /// Words with no zero byte but bytes 0x01 or 0x80 (where a zero test on words can err).
    pub const NEAR_ZERO: usize = 9;
    /// How many.
    pub const COUNT: usize = 10;
}

/// What the run leaves for the emulator test (`#[repr(C)]`, u32 words).
#[repr(C)]
pub struct Report {
    pub state: u32,
    pub cases: u32,
    pub bytes: u32,
    pub mismatches: u32,
    /// The first mismatch: its case, content length, first differing frame index.
    pub first_case: u32,
    pub first_len: u32,
    pub first_at: u32,
    pub edges: [u32; edge::COUNT],
    /// A panic's line (0: none).
    pub panic_line: u32,
}

impl Report {
    pub const fn new() -> Self {
        Self {
            state: 0,
            cases: 0,
            bytes: 0,
            mismatches: 0,
            first_case: 0,
            first_len: 0,
            first_at: 0,
            edges: [0; edge::COUNT],
            panic_line: 0,
        }
    }
}

impl Default for Report {
    fn default() -> Self {
        Self::new()
    }
}

/// Longest content.
const MAX_CONTENT: usize = 1000;
/// Frame buffer: the longest frame (version, content, CRC, COBS's code bytes, delimiter).
const FRAME_BUF: usize = 1100;

/// `COBS(payload) 0x00` into `out`; its length. The textbook encoder: a code byte per block,
/// a block ending at a zero or after 254 data bytes (no block after a full one at the end).
fn reference_cobs(payload: &[u8], out: &mut [u8]) -> usize {
    let mut code_at = 0;
    let mut n = 1;
    for (i, &b) in payload.iter().enumerate() {
        if b == 0 {
            out[code_at] = (n - code_at) as u8;
            code_at = n;
            n += 1;
        } else {
            out[n] = b;
            n += 1;
            if n - code_at == 255 && i + 1 < payload.len() {
                out[code_at] = 0xFF;
                code_at = n;
                n += 1;
            }
        }
    }
    out[code_at] = (n - code_at) as u8;
    out[n] = 0;
    n + 1
}

/// Runs `cases` frames from `seed`, counting into `report`.
pub fn run(report: &mut Report, cases: u32, seed: u32) {
    let crc = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC);
    let mut rng = Rng::new(seed);
    // The content sits at a drawn offset in a word-aligned buffer.
    #[repr(align(4))]
    struct Aligned([u8; MAX_CONTENT + 8]);
    let mut store = Aligned([0; MAX_CONTENT + 8]);
    let mut payload = [0u8; MAX_CONTENT + 5];
    let mut expected = [0u8; FRAME_BUF];
    let mut builder = FrameBuilder::<FRAME_BUF>::new();
    report.state = RUNNING;
    for case in 0..cases {
        let len = match rng.below(4) {
            0 => rng.below(12),
            1 => rng.below(300),
            _ => rng.below(MAX_CONTENT as u32 + 1),
        } as usize;
        // Zeros: never, 1/64, 1/16, 1/4, 1/2, always; the other bytes uniform, or the edge
        // bytes 0x01, 0x80, 0xFF.
        let zeros = [0, 1, 4, 16, 32, 64][rng.below(6) as usize];
        let edgy = rng.below(3) == 0;
        let at = rng.below(4) as usize;
        let content = &mut store.0[at..at + len];
        for b in content.iter_mut() {
            *b = if rng.below(64) < zeros {
                0
            } else if edgy {
                [0x01, 0x80, 0xFF, 0x81][rng.below(4) as usize]
            } else {
                (rng.below(255) + 1) as u8
            };
        }
        let content = &store.0[at..at + len];
        // Edges seen.
        let base = content.as_ptr() as usize;
        for w in content.chunks(4) {
            if w.len() == 4 && (w.as_ptr() as usize).is_multiple_of(4) {
                if let Some(k) = w.iter().position(|&b| b == 0) {
                    report.edges[edge::ZERO_AT + k] += 1;
                } else if w.iter().any(|&b| b == 0x01 || b == 0x80) {
                    report.edges[edge::NEAR_ZERO] += 1;
                }
            }
        }
        if content.split(|&b| b == 0).any(|run| run.len() >= 254) {
            report.edges[edge::FULL_BLOCK] += 1;
        }
        // Pushed in up to four pieces cut at drawn places.
        builder.start();
        let mut cuts = [0usize; 5];
        let pieces = 1 + rng.below(4) as usize;
        for c in cuts.iter_mut().take(pieces).skip(1) {
            *c = rng.below(len as u32 + 1) as usize;
        }
        cuts[pieces] = len;
        cuts[..=pieces].sort_unstable();
        for p in cuts[..=pieces].windows(2) {
            let piece = &content[p[0]..p[1]];
            if piece.len() >= 8 {
                report.edges[edge::ALIGN + (base + p[0]) % 4] += 1;
            }
            builder.push(piece);
        }
        let ours = builder.finish(1);
        // The reference: version | content | CRC-32 LE, stuffed, delimited.
        payload[0] = PROTOCOL_VERSION;
        payload[1..=len].copy_from_slice(content);
        let sum = crc.checksum(&payload[..=len]);
        payload[len + 1..len + 5].copy_from_slice(&sum.to_le_bytes());
        let n = reference_cobs(&payload[..len + 5], &mut expected);
        let differs = match ours {
            Ok(f) if f == &expected[..n] => None,
            Ok(f) => Some(
                f.iter()
                    .zip(&expected[..n])
                    .position(|(a, b)| a != b)
                    .unwrap_or(f.len().min(n)),
            ),
            Err(_) => Some(usize::MAX),
        };
        if let Some(i) = differs {
            if report.mismatches == 0 {
                report.first_case = case;
                report.first_len = len as u32;
                report.first_at = i as u32;
            }
            report.mismatches += 1;
        }
        report.cases += 1;
        report.bytes += len as u32;
    }
    report.state = DONE;
}

#[cfg(test)]
mod tests {
    use super::*;

    /// On the host the portable scan runs: the run agrees, and reaches every edge.
    #[test]
    fn the_portable_scan_agrees_and_every_edge_is_reached() {
        let mut r = Report::new();
        run(&mut r, 1500, SEED);
        assert_eq!(r.state, DONE);
        assert_eq!(
            r.mismatches, 0,
            "first: case {} len {} at {}",
            r.first_case, r.first_len, r.first_at
        );
        for (i, &e) in r.edges.iter().enumerate() {
            assert!(e > 0, "edge {i} not reached");
        }
    }

    /// The reference encoder is COBS: the `cobs` crate's bytes, then the delimiter, for drawn
    /// payloads (lengths across blocks, zeros from never to always).
    #[test]
    fn the_reference_cobs_is_the_cobs_crates() {
        let mut rng = Rng::new(0x5eed_c0b5);
        let mut payload = [0u8; 700];
        let mut ours = [0u8; 720];
        let mut theirs = [0u8; 720];
        for case in 0..3000 {
            let len = rng.below(700) as usize;
            let zeros = [0, 1, 8, 64][case % 4];
            for b in &mut payload[..len] {
                *b = if rng.below(64) < zeros {
                    0
                } else {
                    (rng.below(255) + 1) as u8
                };
            }
            let n = reference_cobs(&payload[..len], &mut ours);
            let m = cobs::try_encode(&payload[..len], &mut theirs).expect("room");
            assert_eq!(&ours[..n - 1], &theirs[..m], "case {case}, {len} bytes");
            assert_eq!(ours[n - 1], 0);
        }
    }
}
