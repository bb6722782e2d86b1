//! Frames: `COBS(version | postcard(message) | CRC-32) 0x00` (crate docs), the encoder the
//! device uses and the reader both sides use.
use serde::{de::DeserializeOwned, Serialize};

use crate::{
    batch, orientation, status, table, AllanTable, BatchWriter, Orientation, SampleBatch, Scales,
    Status, Vec, MAX_ORIENTATIONS,
};

/// Wire-format version carried in the first byte of every frame.
pub const PROTOCOL_VERSION: u8 = 5;
/// Largest serialised message (version + postcard + CRC), bytes, before COBS.
pub const MAX_PAYLOAD: usize = 3072;
/// Largest encoded frame, bytes, including the trailing `0x00` delimiter.
pub const MAX_FRAME: usize = cobs::max_encoding_length(MAX_PAYLOAD) + 1;

// The largest sample batch frame fits the payload limit: version + postcard + CRC.
const _: () = assert!(1 + batch::MAX_SAMPLES_POSTCARD + 4 <= MAX_PAYLOAD);

/// Why a frame could not be encoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum EncodeError {
    /// The message does not fit in [`MAX_PAYLOAD`] or the output buffer.
    TooLarge,
}

/// Why a received frame was rejected.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum DecodeError {
    /// Not valid COBS.
    Cobs,
    /// Shorter than version + CRC.
    TooShort,
    /// Longer than [`MAX_FRAME`] before its delimiter.
    Oversize,
    /// CRC mismatch.
    Crc { expected: u32, found: u32 },
    /// Another protocol version.
    Version(u8),
    /// Valid CRC but not a known message (postcard could not parse it).
    Unknown,
    /// A message parsed but bytes were left over.
    Trailing,
}

impl core::fmt::Display for DecodeError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            DecodeError::Cobs => write!(f, "invalid COBS encoding"),
            DecodeError::TooShort => write!(f, "frame shorter than version + CRC (5 bytes)"),
            DecodeError::Oversize => write!(f, "frame longer than {MAX_FRAME} bytes"),
            DecodeError::Crc { expected, found } => {
                write!(
                    f,
                    "CRC mismatch: frame says {found:#010x}, content gives {expected:#010x}"
                )
            }
            DecodeError::Version(v) => {
                write!(
                    f,
                    "protocol version {v}, this build speaks {PROTOCOL_VERSION}"
                )
            }
            DecodeError::Unknown => write!(f, "unknown or malformed message"),
            DecodeError::Trailing => write!(f, "trailing bytes after the message"),
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for DecodeError {}

impl core::fmt::Display for EncodeError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "message larger than {MAX_PAYLOAD} bytes")
    }
}

#[cfg(feature = "std")]
impl std::error::Error for EncodeError {}

/// COBS-encodes `src` into `dst` (no delimiter); returns the encoded length, or `None` if `dst`
/// is shorter than [`cobs::max_encoding_length`]. Byte-for-byte the output of
/// `cobs::try_encode` (tested); the frame encoder runs the same stuffer with the CRC fused in.
/// Decoding stays with the `cobs` crate.
pub fn cobs_encode(src: &[u8], dst: &mut [u8]) -> Option<usize> {
    if dst.len() < cobs::max_encoding_length(src.len()) {
        return None;
    }
    let mut s = Stuffer::new(dst);
    s.extend::<false>(src, 0);
    s.finish()
}

/// COBS encoder state, fed in slices. It works a run at a time (the bytes up to the next zero
/// or the end of a 254-byte block): one scan, one copy, one code byte. A run that falls outside
/// `dst` is not copied, but the output position still advances, so [`Stuffer::finish`] reports
/// a too-small buffer and nothing can panic (every index written is below the final position).
struct Stuffer<'a> {
    dst: &'a mut [u8],
    /// Where the current block's code byte goes.
    code_at: usize,
    /// Where the next data byte goes; the block holds `out - code_at - 1` data bytes.
    out: usize,
}

/// Data bytes in a full COBS block (code byte 0xFF, no implied zero).
const COBS_BLOCK: usize = 254;

impl<'a> Stuffer<'a> {
    fn new(dst: &'a mut [u8]) -> Self {
        Self {
            dst,
            code_at: 0,
            out: 1,
        }
    }

    #[inline(always)]
    fn put(&mut self, at: usize, b: u8) {
        if let Some(slot) = self.dst.get_mut(at) {
            *slot = b;
        }
    }

    /// Stuff `src`; with `CRC`, also run `crc` (CRC-32/ISO-HDLC, reflected, not finalised) over
    /// it in the same scan and return it.
    fn extend<const CRC: bool>(&mut self, mut src: &[u8], mut crc: u32) -> u32 {
        while !src.is_empty() {
            let used = self.out - self.code_at - 1;
            if used == COBS_BLOCK {
                // A full block ends without an implied zero, only when more data follows.
                self.put(self.code_at, 0xFF);
                self.code_at = self.out;
                self.out += 1;
                continue;
            }
            let window = &src[..src.len().min(COBS_BLOCK - used)];
            if CRC && self.out + window.len() <= self.dst.len() {
                // The whole window in one scan with the CRC, its zeros turned into code bytes
                // as they come (no block in it can outgrow COBS_BLOCK: the window does not
                // reach past the current block's room, and each zero starts a new one). Per
                // zero, a return to this loop cost ≈ 70 cycles on the M0+.
                self.code_at = crc_cobs_window(window, self.dst, self.out, self.code_at, &mut crc);
                self.out += window.len();
                src = &src[window.len()..];
                continue;
            }
            // The run: the bytes before the first zero of the window, copied to the output.
            let run = match self.dst.get_mut(self.out..self.out + window.len()) {
                Some(d) => {
                    let run = window.iter().position(|&b| b == 0).unwrap_or(window.len());
                    d[..run].copy_from_slice(&window[..run]);
                    run
                }
                // No room for the window: the frame cannot fit (every input byte takes one
                // output byte), `finish` reports it; keep counting.
                None if CRC => crc_run(window, &mut crc),
                None => window.iter().position(|&b| b == 0).unwrap_or(window.len()),
            };
            self.out += run;
            if run < window.len() {
                // The zero ends the block: its code byte says where.
                self.put(self.code_at, (self.out - self.code_at) as u8);
                self.code_at = self.out;
                self.out += 1;
                src = &src[run + 1..];
            } else {
                src = &src[run..];
            }
        }
        crc
    }

    /// Close a frame whose content's (not finalised) CRC is `crc`: the CRC's four bytes, the
    /// last block, the `0x00` delimiter. Its length with the delimiter, or `None` if it did not
    /// fit `dst`.
    fn close(mut self, crc: u32) -> Option<usize> {
        self.extend::<false>(&(!crc).to_le_bytes(), 0);
        let n = self.finish()?;
        *self.dst.get_mut(n)? = 0;
        Some(n + 1)
    }

    /// Close the last block; the encoded length, or `None` if it did not fit `dst`.
    fn finish(&mut self) -> Option<usize> {
        self.put(self.code_at, (self.out - self.code_at) as u8);
        (self.out <= self.dst.len()).then_some(self.out)
    }
}

/// The CRC-32/ISO-HDLC tables, one copy (4 KiB, flash) for every CRC here: entry `b` holds
/// `[T3[b], T2[b], T1[b], T0[b]]`, where `T0` is the `crc` crate's byte table ([`crc_step`],
/// [`crc32`] on received frames) and `T(k+1)[b]` is `Tk[b]` run through one more (zero) byte
/// ("slicing by 4": a word's four bytes take four lookups, [`crc_word`] and the Thumb scan).
/// Interleaved, so one pointer (the entry) reaches all four.
static CRC_SLICES: [[u32; 4]; 256] = crc_slices();

const fn crc_slices() -> [[u32; 4]; 256] {
    let t0: [u32; 256] = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC).table()[0];
    let mut e = [[0u32; 4]; 256];
    let mut b = 0;
    while b < 256 {
        let mut t = t0[b];
        e[b][3] = t;
        let mut k = 2;
        loop {
            t = t0[(t & 0xFF) as usize] ^ (t >> 8);
            e[b][k] = t;
            if k == 0 {
                break;
            }
            k -= 1;
        }
        b += 1;
    }
    e
}

// `crc_step` hard-codes the reflected form with all-ones init and final XOR.
const _: () = assert!(
    crc::CRC_32_ISO_HDLC.refin
        && crc::CRC_32_ISO_HDLC.refout
        && crc::CRC_32_ISO_HDLC.init == u32::MAX
        && crc::CRC_32_ISO_HDLC.xorout == u32::MAX
);

/// One byte into a running (reflected, not finalised) CRC-32/ISO-HDLC.
#[inline(always)]
fn crc_step(crc: u32, b: u8) -> u32 {
    CRC_SLICES[usize::from(crc as u8 ^ b)][3] ^ (crc >> 8)
}

/// CRC-32/ISO-HDLC of `bytes` (`crc::CRC_32_ISO_HDLC`'s checksum; tested against it).
fn crc32(bytes: &[u8]) -> u32 {
    !bytes.iter().fold(u32::MAX, |c, &b| crc_step(c, b))
}

/// The bytes of `window` before its first zero (all of them if it has none), running `crc`
/// over them and the zero. Its own function so that, on the M0+, the loop keeps the pointer,
/// the CRC and the table in registers.
#[inline(never)]
fn crc_run(window: &[u8], crc: &mut u32) -> usize {
    let mut c = *crc;
    let mut run = window.len();
    for (i, &b) in window.iter().enumerate() {
        c = crc_step(c, b);
        if b == 0 {
            run = i;
            break;
        }
    }
    *crc = c;
    run
}

/// Four bytes (`w`, little-endian) into a running (reflected, not finalised) CRC-32/ISO-HDLC:
/// what four [`crc_step`]s do (the Thumb routine's word step, in Rust).
#[cfg(any(test, not(all(target_arch = "arm", feature = "thumb-asm"))))]
#[inline(always)]
fn crc_word(crc: u32, w: u32) -> u32 {
    let x = crc ^ w;
    CRC_SLICES[(x & 0xFF) as usize][0]
        ^ CRC_SLICES[((x >> 8) & 0xFF) as usize][1]
        ^ CRC_SLICES[((x >> 16) & 0xFF) as usize][2]
        ^ CRC_SLICES[(x >> 24) as usize][3]
}

/// COBS-stuff `window` into `buf` from index `out` (`buf` holds at least
/// `out + window.len()` bytes; the current block's code byte goes at `code_at < out`), running
/// `crc` (reflected, not finalised) over every byte: a non-zero byte is copied to its place; a
/// zero's place becomes the next block's code byte, and the current block's code byte gets its
/// distance. Returns where the open block's code byte goes. The caller keeps every block within
/// [`COBS_BLOCK`] data bytes (so each distance fits a byte). Four bytes at a time, the CRC by
/// [`crc_word`], as the Thumb routine does (so the host tests check its table and arithmetic).
#[cfg(not(all(target_arch = "arm", feature = "thumb-asm")))]
#[inline(never)]
fn crc_cobs_window(
    window: &[u8],
    buf: &mut [u8],
    out: usize,
    code_at: usize,
    crc: &mut u32,
) -> usize {
    let mut c = *crc;
    let mut code_at = code_at;
    let mut at = out;
    let mut stuff = |b: u8, at: usize| {
        if b == 0 {
            buf[code_at] = (at - code_at) as u8;
            code_at = at;
        } else {
            buf[at] = b;
        }
    };
    let (words, rest) = window.as_chunks::<4>();
    for w in words {
        for &b in w {
            stuff(b, at);
            at += 1;
        }
        c = crc_word(c, u32::from_le_bytes(*w));
    }
    for &b in rest {
        stuff(b, at);
        at += 1;
        c = crc_step(c, b);
    }
    *crc = c;
    code_at
}

/// What [`crc_cobs_window`]'s Thumb routine reads and leaves: the running CRC, the open
/// block's code byte, the table.
#[cfg(all(target_arch = "arm", feature = "thumb-asm"))]
#[repr(C)]
struct Scan {
    crc: u32,
    code: *mut u8,
    slices: *const [u32; 4],
}

#[cfg(all(target_arch = "arm", feature = "thumb-asm"))]
extern "C" {
    /// Stuff `n > 0` bytes from `src` to `dst` (`dst` − 1 or earlier holds the open block's
    /// code byte, at `scan.code`), running `scan.crc` over them; leaves the CRC and the open
    /// block's code byte in `scan`.
    fn pico_imu_crc_cobs(src: *const u8, dst: *mut u8, n: usize, scan: *mut Scan);
}

/// [`crc_cobs_window`] in Thumb code for the Cortex-M0+ (`pico_imu_crc_cobs` below): the
/// bytes up to the source's first word boundary one at a time, then a word at a time (one
/// load, a test for a zero byte, four byte stores, the CRC by [`CRC_SLICES`]), the rest one at
/// a time. ≈ 47 cycles a word without a zero byte, ≈ 75 with one, against 16 a byte (18 a
/// zero) one at a time. The same results as the portable loop (the host tests run that one;
/// crates/imu-proto/thumb-check runs this one against the `crc` crate and a plain COBS on the
/// emulated RP2040, and the emulator's end-to-end test checks every frame's CRC and COBS).
#[cfg(all(target_arch = "arm", feature = "thumb-asm"))]
#[inline(never)]
fn crc_cobs_window(
    window: &[u8],
    buf: &mut [u8],
    out: usize,
    code_at: usize,
    crc: &mut u32,
) -> usize {
    let n = window.len();
    if n == 0 {
        return code_at;
    }
    // Both bounds checked here, once: the routine writes `buf[out .. out + n]` and
    // `buf[code_at]` with code_at < out + n (the first is given, each later one is a zero's
    // place).
    let dst = &mut buf[..out + n];
    assert!(code_at < out);
    let base = dst.as_mut_ptr();
    let mut scan = Scan {
        crc: *crc,
        code: base.wrapping_add(code_at),
        slices: CRC_SLICES.as_ptr(),
    };
    // SAFETY: the routine reads `window[..n]`, writes `dst[out .. out + n]` and the code bytes
    // at `scan.code` (`dst[code_at]` or the place of a zero of this window), all within `dst`
    // (cut to out + n above), reads the 4 KiB table through `scan.slices`, and follows the
    // AAPCS (r4–r7, r8, r10, r11 restored).
    unsafe { pico_imu_crc_cobs(window.as_ptr(), base.add(out), n, &mut scan) };
    *crc = scan.crc;
    (scan.code as usize) - (base as usize)
}

// Registers: r0 = source, r1 = destination (past the word loop's start: their ends, with r2 a
// negative index counting up to zero), r3 = CRC, r4 = table, r8 = the open block's code byte,
// r10 = 0x0101_0101, r11 = 0x8080_8080 and r12 = 0xFF0 in the word loop, r5–r7 scratch.
#[cfg(all(target_arch = "arm", feature = "thumb-asm"))]
core::arch::global_asm!(
    ".pushsection .text.pico_imu_crc_cobs,\"ax\",%progbits",
    ".p2align 2",
    ".global pico_imu_crc_cobs",
    ".type pico_imu_crc_cobs,%function",
    ".thumb_func",
    "pico_imu_crc_cobs:",
    "    push {{r4, r5, r6, r7, lr}}",
    "    mov r4, r8",
    "    mov r5, r10",
    "    mov r6, r11",
    "    push {{r3, r4, r5, r6}}",
    "    ldr r4, [r3, #4]",
    "    mov r8, r4",
    "    ldr r4, [r3, #8]",
    "    ldr r3, [r3]",
    // The head: min(n, bytes to the source's next word boundary), one at a time.
    "    negs r5, r0",
    "    lsls r5, r5, #30",
    "    lsrs r5, r5, #30",
    "    cmp r5, r2",
    "    bls 1f",
    "    movs r5, r2",
    "1:",
    "    subs r6, r2, r5",
    "    push {{r6}}",
    "    movs r2, r5",
    "    beq 2f",
    "    bl pico_imu_crc_cobs_bytes",
    "2:",
    "    pop {{r2}}",
    // The words: r6 = their bytes, the tail's count kept on the stack.
    "    lsrs r6, r2, #2",
    "    beq 8f",
    "    lsls r6, r6, #2",
    "    subs r2, r2, r6",
    "    push {{r2}}",
    "    movs r5, #1",
    "    lsls r7, r5, #8",
    "    orrs r5, r7",
    "    lsls r7, r5, #16",
    "    orrs r5, r7",
    "    mov r10, r5",
    "    lsls r5, r5, #7",
    "    mov r11, r5",
    "    movs r5, #0xFF",
    "    lsls r5, r5, #4",
    "    mov r12, r5",
    "    adds r0, r0, r6",
    "    adds r1, r1, r6",
    "    negs r2, r6",
    // A word: a zero byte in it iff (v − 0x01…01) & !v & 0x80…80 ≠ 0.
    "4:",
    "    ldr r5, [r0, r2]",
    "    mov r6, r10",
    "    subs r6, r5, r6",
    "    bics r6, r5",
    "    mov r7, r11",
    "    tst r6, r7",
    "    bne 6f",
    "    adds r6, r1, r2",
    "    strb r5, [r6]",
    "    lsrs r7, r5, #8",
    "    strb r7, [r6, #1]",
    "    lsrs r7, r5, #16",
    "    strb r7, [r6, #2]",
    "    lsrs r7, r5, #24",
    "    strb r7, [r6, #3]",
    // The CRC of the word: x = v ^ crc, T3[x0] ^ T2[x1] ^ T1[x2] ^ T0[x3] (each entry 16 bytes).
    "5:",
    "    eors r5, r3",
    "    mov r7, r12",
    "    lsls r6, r5, #24",
    "    lsrs r6, r6, #20",
    "    ldr r3, [r4, r6]",
    "    lsrs r6, r5, #4",
    "    ands r6, r7",
    "    adds r6, r6, r4",
    "    ldr r6, [r6, #4]",
    "    eors r3, r6",
    "    lsrs r6, r5, #12",
    "    ands r6, r7",
    "    adds r6, r6, r4",
    "    ldr r6, [r6, #8]",
    "    eors r3, r6",
    "    lsrs r6, r5, #24",
    "    lsls r6, r6, #4",
    "    adds r6, r6, r4",
    "    ldr r6, [r6, #12]",
    "    eors r3, r6",
    "    adds r2, #4",
    "    bne 4b",
    "    pop {{r2}}",
    // The tail: the last 0–3 bytes, one at a time.
    "8:",
    "    cmp r2, #0",
    "    beq 9f",
    "    bl pico_imu_crc_cobs_bytes",
    "9:",
    "    pop {{r0, r4, r5, r6}}",
    "    str r3, [r0]",
    "    mov r3, r8",
    "    str r3, [r0, #4]",
    "    mov r8, r4",
    "    mov r10, r5",
    "    mov r11, r6",
    "    pop {{r4, r5, r6, r7, pc}}",
    // A word with a zero byte: each byte stored, or (a zero) its place made the next block's
    // code byte and the open block's code byte given the distance; r2 and r3 lent for it.
    "6:",
    "    push {{r2, r3}}",
    "    adds r6, r1, r2",
    "    lsls r7, r5, #24",
    "    lsrs r7, r7, #24",
    "    beq 40f",
    "    strb r7, [r6]",
    "41:",
    "    lsls r7, r5, #16",
    "    lsrs r7, r7, #24",
    "    beq 42f",
    "    strb r7, [r6, #1]",
    "43:",
    "    lsls r7, r5, #8",
    "    lsrs r7, r7, #24",
    "    beq 44f",
    "    strb r7, [r6, #2]",
    "45:",
    "    lsrs r7, r5, #24",
    "    beq 46f",
    "    strb r7, [r6, #3]",
    "47:",
    "    pop {{r2, r3}}",
    "    b 5b",
    "40:",
    "    adds r2, r6, #0",
    "    b 48f",
    "42:",
    "    adds r2, r6, #1",
    "    b 48f",
    "44:",
    "    adds r2, r6, #2",
    "    b 48f",
    "46:",
    "    adds r2, r6, #3",
    // r2 = the zero's place: the open block's code byte gets the distance, and r2 is the next.
    "48:",
    "    mov r3, r8",
    "    subs r7, r2, r3",
    "    strb r7, [r3]",
    "    mov r8, r2",
    "    subs r2, r2, r6",
    "    beq 41b",
    "    cmp r2, #2",
    "    blo 43b",
    "    beq 45b",
    "    b 47b",
    ".size pico_imu_crc_cobs, . - pico_imu_crc_cobs",
    // r2 > 0 bytes from r0 to r1, one at a time (r0, r1 advanced, r2 = 0; r5–r7 clobbered).
    ".p2align 2",
    ".type pico_imu_crc_cobs_bytes,%function",
    ".thumb_func",
    "pico_imu_crc_cobs_bytes:",
    "10:",
    "    ldrb r5, [r0]",
    "    adds r0, #1",
    "    cmp r5, #0",
    "    bne 11f",
    "    mov r6, r8",
    "    subs r7, r1, r6",
    "    strb r7, [r6]",
    "    mov r8, r1",
    "    b 12f",
    "11:",
    "    strb r5, [r1]",
    "12:",
    "    eors r5, r3",
    "    lsls r5, r5, #24",
    "    lsrs r5, r5, #20",
    "    adds r5, r5, r4",
    "    ldr r5, [r5, #12]",
    "    lsrs r3, r3, #8",
    "    eors r3, r5",
    "    adds r1, #1",
    "    subs r2, #1",
    "    bne 10b",
    "    bx lr",
    ".size pico_imu_crc_cobs_bytes, . - pico_imu_crc_cobs_bytes",
    ".popsection",
);

/// `content` (version byte + postcard) → `COBS(content | crc32 LE) 0x00` in `out`, in one scan
/// of `content` that updates the CRC and finds the zeros COBS replaces. Returns the frame
/// length (delimiter included).
fn frame(content: &[u8], out: &mut [u8]) -> Result<usize, EncodeError> {
    let mut s = Stuffer::new(out);
    let crc = s.extend::<true>(content, u32::MAX);
    s.close(crc).ok_or(EncodeError::TooLarge)
}

/// A frame built a piece at a time, in its own buffer of `N` bytes: each piece of the content
/// (the postcard bytes of one message, in order) is checksummed and stuffed as it comes, so a
/// long message (an Allan table) can be framed over several calls, with other frames encoded
/// in between. [`FrameBuilder::finish`] closes it: the same bytes as [`FrameEncoder`] writes for
/// the whole message (tested).
#[repr(C, align(4))]
pub struct FrameBuilder<const N: usize> {
    /// Word-aligned, so the finished frame is copied out a word at a time.
    buf: [u8; N],
    /// Where the current COBS block's code byte goes.
    code_at: usize,
    /// Where the next stuffed byte goes (past `N`: the frame does not fit).
    out: usize,
    /// The running CRC of the content so far.
    crc: u32,
}

impl<const N: usize> Default for FrameBuilder<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> FrameBuilder<N> {
    pub const fn new() -> Self {
        Self {
            buf: [0; N],
            code_at: 0,
            out: 1,
            crc: u32::MAX,
        }
    }

    /// Start a new frame (the version byte); whatever was built before is forgotten.
    pub fn start(&mut self) {
        self.code_at = 0;
        self.out = 1;
        self.crc = u32::MAX;
        self.push(&[PROTOCOL_VERSION]);
    }

    /// Append the next postcard bytes of the message.
    pub fn push(&mut self, bytes: &[u8]) {
        let crc = self.crc;
        let mut s = self.stuffer();
        let crc = s.extend::<true>(bytes, crc);
        (self.code_at, self.out) = (s.code_at, s.out);
        self.crc = crc;
    }

    /// The COBS state where the last piece left it.
    fn stuffer(&mut self) -> Stuffer<'_> {
        Stuffer {
            dst: &mut self.buf,
            code_at: self.code_at,
            out: self.out,
        }
    }

    /// Close the frame (CRC, last code byte, the `0x00` delimiter) and pad it with zero bytes
    /// (empty frames, which every reader skips) to a multiple of `align` bytes; the frame, or
    /// [`EncodeError::TooLarge`] if it did not fit the buffer. The builder must be started again
    /// before the next frame.
    pub fn finish(&mut self, align: usize) -> Result<&[u8], EncodeError> {
        let crc = self.crc;
        let n = self.stuffer().close(crc).ok_or(EncodeError::TooLarge)?;
        let padded = n.next_multiple_of(align.max(1));
        let frame = self.buf.get_mut(..padded).ok_or(EncodeError::TooLarge)?;
        frame[n..].fill(0);
        Ok(frame)
    }
}

/// Serialises messages into frames; owns the scratch buffer for the un-stuffed payload.
pub struct FrameEncoder {
    scratch: [u8; MAX_PAYLOAD],
}

impl Default for FrameEncoder {
    fn default() -> Self {
        Self::new()
    }
}

impl FrameEncoder {
    pub const fn new() -> Self {
        Self {
            scratch: [0; MAX_PAYLOAD],
        }
    }

    /// Encode `msg` as one complete frame (trailing `0x00` included) into `out`; returns its
    /// length. `out` of [`MAX_FRAME`] bytes always suffices for a message within
    /// [`MAX_PAYLOAD`].
    pub fn encode<T: Serialize>(&mut self, msg: &T, out: &mut [u8]) -> Result<usize, EncodeError> {
        self.scratch[0] = PROTOCOL_VERSION;
        let body = postcard::to_slice(msg, &mut self.scratch[1..MAX_PAYLOAD - 4])
            .map_err(|_| EncodeError::TooLarge)?
            .len();
        frame(&self.scratch[..1 + body], out)
    }

    /// Encode `DeviceMsg::Samples(batch)` as one frame into `out`, byte for byte what
    /// [`FrameEncoder::encode`] writes for it (tested), without serde: the firmware's per-batch
    /// framing path (`batch.rs` writes the postcard bytes). `out` of [`MAX_FRAME`] bytes always
    /// suffices; a shorter one that cannot hold the frame gives [`EncodeError::TooLarge`].
    pub fn encode_samples(
        &mut self,
        batch: &SampleBatch,
        out: &mut [u8],
    ) -> Result<usize, EncodeError> {
        self.encode_by(out, |buf| batch::write(batch, buf))
    }

    /// Frame the batch `batch` has written as its samples came ([`BatchWriter`]), with
    /// `calibrated` and `scales`, into `out`: byte for byte what
    /// [`FrameEncoder::encode_samples`] writes for the same samples (tested). The samples stay
    /// in `batch` until it is cleared.
    pub fn encode_batch(
        &mut self,
        batch: &mut BatchWriter,
        calibrated: bool,
        scales: &Scales,
        out: &mut [u8],
    ) -> Result<usize, EncodeError> {
        frame(batch.finish(PROTOCOL_VERSION, calibrated, scales), out)
    }

    /// Encode `DeviceMsg::Table(table)` as one frame into `out`, byte for byte what
    /// [`FrameEncoder::encode`] writes for it (tested), without serde: the firmware's table
    /// path (`table.rs` writes the postcard bytes).
    pub fn encode_table(
        &mut self,
        table: &AllanTable,
        out: &mut [u8],
    ) -> Result<usize, EncodeError> {
        self.encode_by(out, |buf| table::write(table, buf))
    }

    /// Encode `DeviceMsg::Status(status)` as one frame into `out`, byte for byte what
    /// [`FrameEncoder::encode`] writes for it (tested), without serde: the firmware's status
    /// frame (`status.rs` writes the postcard bytes).
    pub fn encode_status(&mut self, status: &Status, out: &mut [u8]) -> Result<usize, EncodeError> {
        self.encode_by(out, |buf| status::write(status, buf))
    }

    /// Encode `DeviceMsg::Orientation(list)` as one frame into `out`, byte for byte what
    /// [`FrameEncoder::encode`] writes for it (tested), without serde: the firmware's attitude
    /// frames (`orientation.rs` writes the postcard bytes).
    pub fn encode_orientations(
        &mut self,
        list: &Vec<Orientation, MAX_ORIENTATIONS>,
        out: &mut [u8],
    ) -> Result<usize, EncodeError> {
        self.encode_by(out, |buf| orientation::write(list, buf))
    }

    /// One frame whose postcard bytes `write` puts into the buffer it is given (returning
    /// their length, `None` if they do not fit).
    #[inline(always)]
    fn encode_by(
        &mut self,
        out: &mut [u8],
        write: impl FnOnce(&mut [u8]) -> Option<usize>,
    ) -> Result<usize, EncodeError> {
        self.scratch[0] = PROTOCOL_VERSION;
        let body = write(&mut self.scratch[1..MAX_PAYLOAD - 4]).ok_or(EncodeError::TooLarge)?;
        frame(&self.scratch[..1 + body], out)
    }

    /// Encode into a fresh `Vec` (host convenience).
    #[cfg(feature = "std")]
    pub fn encode_vec<T: Serialize>(&mut self, msg: &T) -> Result<std::vec::Vec<u8>, EncodeError> {
        let mut out = std::vec![0u8; MAX_FRAME];
        let n = self.encode(msg, &mut out)?;
        out.truncate(n);
        Ok(out)
    }
}

/// Decode one frame's COBS bytes (without the `0x00` delimiter), in place.
pub fn decode<T: DeserializeOwned>(frame: &mut [u8]) -> Result<T, DecodeError> {
    if frame.len() > MAX_FRAME {
        return Err(DecodeError::Oversize);
    }
    if frame.contains(&0) {
        return Err(DecodeError::Cobs);
    }
    let n = cobs::decode_in_place(frame).map_err(|_| DecodeError::Cobs)?;
    let payload = frame.get(..n).ok_or(DecodeError::Cobs)?;
    if payload.len() < 5 {
        return Err(DecodeError::TooShort);
    }
    let (content, crc_bytes) = payload.split_at(payload.len() - 4);
    let found = u32::from_le_bytes([crc_bytes[0], crc_bytes[1], crc_bytes[2], crc_bytes[3]]);
    let expected = crc32(content);
    if expected != found {
        return Err(DecodeError::Crc { expected, found });
    }
    if content[0] != PROTOCOL_VERSION {
        return Err(DecodeError::Version(content[0]));
    }
    let (msg, rest) =
        postcard::take_from_bytes::<T>(&content[1..]).map_err(|_| DecodeError::Unknown)?;
    if !rest.is_empty() {
        return Err(DecodeError::Trailing);
    }
    Ok(msg)
}

/// Counts of received frames by outcome.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct RxStats {
    pub ok: u32,
    pub cobs: u32,
    pub too_short: u32,
    pub oversize: u32,
    pub crc: u32,
    pub version: u32,
    pub unknown: u32,
    pub trailing: u32,
}

impl RxStats {
    /// All rejected frames.
    pub fn rejected(&self) -> u32 {
        self.cobs
            .saturating_add(self.too_short)
            .saturating_add(self.oversize)
            .saturating_add(self.crc)
            .saturating_add(self.version)
            .saturating_add(self.unknown)
            .saturating_add(self.trailing)
    }

    fn count(&mut self, r: &Result<(), DecodeError>) {
        let c = match r {
            Ok(()) => &mut self.ok,
            Err(DecodeError::Cobs) => &mut self.cobs,
            Err(DecodeError::TooShort) => &mut self.too_short,
            Err(DecodeError::Oversize) => &mut self.oversize,
            Err(DecodeError::Crc { .. }) => &mut self.crc,
            Err(DecodeError::Version(_)) => &mut self.version,
            Err(DecodeError::Unknown) => &mut self.unknown,
            Err(DecodeError::Trailing) => &mut self.trailing,
        };
        *c = c.saturating_add(1);
    }
}

/// Splits a byte stream at `0x00` delimiters and decodes each frame; bytes of an oversized frame
/// are discarded up to the next delimiter. `N` is the largest frame accepted (COBS bytes).
pub struct FrameReader<const N: usize> {
    buf: [u8; N],
    len: usize,
    overflow: bool,
    stats: RxStats,
}

impl<const N: usize> Default for FrameReader<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> FrameReader<N> {
    pub const fn new() -> Self {
        Self {
            buf: [0; N],
            len: 0,
            overflow: false,
            stats: RxStats {
                ok: 0,
                cobs: 0,
                too_short: 0,
                oversize: 0,
                crc: 0,
                version: 0,
                unknown: 0,
                trailing: 0,
            },
        }
    }

    /// Counters so far.
    pub fn stats(&self) -> RxStats {
        self.stats
    }

    /// Bytes buffered towards the next frame.
    pub fn pending(&self) -> usize {
        self.len
    }

    /// Feed one byte; returns a decoded message (or the reason the frame was rejected) when the
    /// byte ends a frame. Empty frames (consecutive delimiters) are skipped silently.
    pub fn push<T: DeserializeOwned>(&mut self, byte: u8) -> Option<Result<T, DecodeError>> {
        if byte != 0 {
            if self.len < N {
                self.buf[self.len] = byte;
                self.len += 1;
            } else {
                self.overflow = true;
            }
            return None;
        }
        let result = if self.overflow {
            Err(DecodeError::Oversize)
        } else if self.len == 0 {
            return None;
        } else {
            decode::<T>(&mut self.buf[..self.len])
        };
        self.len = 0;
        self.overflow = false;
        self.stats
            .count(&result.as_ref().map(|_| ()).map_err(|e| *e));
        Some(result)
    }

    /// Feed a slice, calling `f` for every completed frame.
    pub fn feed<T: DeserializeOwned>(
        &mut self,
        data: &[u8],
        mut f: impl FnMut(Result<T, DecodeError>),
    ) {
        for &b in data {
            if let Some(r) = self.push::<T>(b) {
                f(r);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The table-driven CRC gives CRC-32/ISO-HDLC: the catalogue's check value, and the `crc`
    /// crate's checksum for every prefix of a byte string with zeros and 0xFF in it.
    #[test]
    fn crc32_is_crc_32_iso_hdlc() {
        assert_eq!(crc32(b"123456789"), crc::CRC_32_ISO_HDLC.check);
        assert_eq!(crc32(b""), 0);
        let reference = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC);
        let bytes: [u8; 300] = core::array::from_fn(|i| (i * 37 % 256) as u8);
        for n in 0..bytes.len() {
            assert_eq!(crc32(&bytes[..n]), reference.checksum(&bytes[..n]), "{n}");
        }
    }

    /// A word through the sliced table is its four bytes one at a time, for every value of
    /// each byte against a spread of running CRCs and other bytes (an xorshift's, keyed by the
    /// clock each run; the key is printed).
    #[test]
    fn crc_word_is_four_crc_steps() {
        extern crate std;
        let key = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(1, |d| d.as_nanos() as u64)
            | 1;
        std::println!("generator key {key:#x}");
        let mut r = key;
        let mut next = || {
            r ^= r << 13;
            r ^= r >> 7;
            r ^= r << 17;
            r as u32
        };
        for lane in 0..4 {
            for b in 0..=255u32 {
                let crc = next();
                let w = (next() & !(0xFF << (8 * lane))) | (b << (8 * lane));
                let bytewise = w.to_le_bytes().iter().fold(crc, |c, &x| crc_step(c, x));
                assert_eq!(
                    crc_word(crc, w),
                    bytewise,
                    "crc {crc:#010x}, word {w:#010x}"
                );
            }
        }
    }
}
