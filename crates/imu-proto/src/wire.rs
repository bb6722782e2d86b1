//! A writer of postcard's wire format (<https://postcard.jamesmunns.com/wire-format>) by hand,
//! for the device's two frequent messages (sample batches, `batch.rs`; Allan tables,
//! `table.rs`): the same bytes as the serde path in one straight pass, each varint in 32-bit
//! arithmetic wherever its value allows (the M0+ has no 64-bit shifts).
//!
//! * an enum variant is its index as a varint;
//! * a struct is its fields in declaration order, nothing around them;
//! * `bool` is one byte 0/1, `f32` its four bytes little-endian, an `Option` a 0/1 byte before
//!   its value;
//! * `u32`/`u64`/`u128`/`usize` are LEB128 varints (7 bits a byte, least significant group
//!   first, the high bit set on every byte but the last); `i32` is zig-zag mapped first
//!   (`(n << 1) ^ (n >> 31)`);
//! * a `heapless::Vec` is its length (varint) followed by its elements; an array is its
//!   elements alone.

/// Output cursor. `CHECKED`: a byte past the end of `buf` is not stored, but still counted, so
/// a buffer that was too small shows as `pos > buf.len()` at the end (no check can panic).
/// Unchecked: the caller has made sure `buf` holds the longest encoding of what it writes (the
/// batch writer checks its bound first), so no byte can fall past the end and none is compared
/// (≈ 70 cycles per sample set less on the M0+, `cargo xtask bench-emu`).
pub(crate) struct Cursor<'a, const CHECKED: bool> {
    pub(crate) buf: &'a mut [u8],
    pub(crate) pos: usize,
}

impl<const CHECKED: bool> Cursor<'_, CHECKED> {
    #[inline(always)]
    pub(crate) fn byte(&mut self, b: u8) {
        if CHECKED {
            if let Some(slot) = self.buf.get_mut(self.pos) {
                *slot = b;
            }
        } else {
            debug_assert!(self.pos < self.buf.len());
            // SAFETY: an unchecked cursor is made only for a message whose longest encoding
            // (its writer's bound, tested to be exact) fits `buf`, and every byte written is
            // part of that encoding, so `pos < buf.len()` here.
            unsafe { *self.buf.get_unchecked_mut(self.pos) = b };
        }
        self.pos += 1;
    }

    #[inline(always)]
    pub(crate) fn varint(&mut self, mut v: u32) {
        while v >= 0x80 {
            self.byte(v as u8 | 0x80);
            v >>= 7;
        }
        self.byte(v as u8);
    }

    /// A `u64` varint with 32-bit arithmetic wherever the value allows (the M0+ has no 64-bit
    /// shifts); the common case (below 2^32 µs, 71 minutes of uptime) inline.
    #[inline(always)]
    pub(crate) fn varint_u64(&mut self, v: u64) {
        match u32::try_from(v) {
            Ok(small) => self.varint(small),
            Err(_) => self.varint_u64_long(v),
        }
    }

    /// `v` ≥ 2^32: the low 28 bits make the first four bytes, all with the high bit set.
    #[inline(never)]
    pub(crate) fn varint_u64_long(&mut self, v: u64) {
        let lo = v as u32;
        self.byte(lo as u8 | 0x80);
        self.byte((lo >> 7) as u8 | 0x80);
        self.byte((lo >> 14) as u8 | 0x80);
        self.byte((lo >> 21) as u8 | 0x80);
        let rest = v >> 28;
        match u32::try_from(rest) {
            Ok(small) => self.varint(small),
            Err(_) => self.varint_wide(rest.into()),
        }
    }

    /// An `Option`: a 0 byte for `None`, a 1 byte and then the value (written by `write`) for
    /// `Some`.
    #[inline(always)]
    pub(crate) fn option<T>(&mut self, v: Option<T>, write: impl FnOnce(&mut Self, T)) {
        match v {
            Some(x) => {
                self.byte(1);
                write(self, x);
            }
            None => self.byte(0),
        }
    }

    #[inline(always)]
    pub(crate) fn zigzag(&mut self, n: i32) {
        self.varint(((n << 1) ^ (n >> 31)) as u32);
    }

    /// An `f32`'s four bytes, least significant first, cut from its bits by shifts: from
    /// `to_le_bytes`, the compiler copied a row of them with a byte-wise `memcpy` (≈ 270 cycles
    /// per attitude estimate on the M0+).
    #[inline(always)]
    pub(crate) fn f32(&mut self, x: f32) {
        let b = x.to_bits();
        self.byte(b as u8);
        self.byte((b >> 8) as u8);
        self.byte((b >> 16) as u8);
        self.byte((b >> 24) as u8);
    }

    /// A `u128` varint; a value below 2^64 as a `u64` (32-bit steps where it allows).
    pub(crate) fn varint_u128(&mut self, v: u128) {
        match u64::try_from(v) {
            Ok(v) => self.varint_u64(v),
            Err(_) => self.varint_wide(v),
        }
    }

    /// Any varint, in 128-bit steps: the rare values at or above 2^60.
    #[inline(never)]
    fn varint_wide(&mut self, mut rest: u128) {
        while rest >= 0x80 {
            self.byte(rest as u8 | 0x80);
            rest >>= 7;
        }
        self.byte(rest as u8);
    }
}

/// Write a message's bytes with `write` through a checked cursor on `buf`: their length, or
/// `None` if `buf` is too small for them.
pub(crate) fn write_checked(
    buf: &mut [u8],
    write: impl FnOnce(&mut Cursor<'_, true>),
) -> Option<usize> {
    let len = buf.len();
    let mut c = Cursor::<true> { buf, pos: 0 };
    write(&mut c);
    Some(c.pos).filter(|&n| n <= len)
}
