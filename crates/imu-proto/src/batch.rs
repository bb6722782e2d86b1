//! The postcard bytes of `DeviceMsg::Samples(batch)`, written by hand.
//!
//! The firmware frames a [`SampleBatch`] every 16 ms. Through serde, postcard writes every
//! varint with its own small copy into the output; this writer produces the very same bytes
//! (postcard wire format, <https://postcard.jamesmunns.com/wire-format>) in one straight pass:
//!
//! * an enum variant is its index as a varint (`DeviceMsg::Samples` = 1, one byte);
//! * a struct is its fields in declaration order, nothing around them;
//! * `bool` is one byte 0/1, `f32` its four bytes little-endian;
//! * `u32`/`u64`/`usize` are LEB128 varints (7 bits a byte, least significant group first, the
//!   high bit set on every byte but the last); `i32` is zig-zag mapped first
//!   (`(n << 1) ^ (n >> 31)`);
//! * a `heapless::Vec` is its length (varint) followed by its elements; an array (`[i32; 3]`) is
//!   its elements alone.
//!
//! The proptests in `tests/batch.rs` check the bytes against the serde path for arbitrary
//! batches, extreme values included.
use crate::{ImuSample, MagSample, SampleBatch, Scales, MAX_BATCH_IMU, MAX_BATCH_MAG};

/// Index of `DeviceMsg::Samples` among `DeviceMsg`'s variants (tested against the serde path).
pub(crate) const SAMPLES_VARIANT: u8 = 1;

/// Most bytes of one encoded [`ImuSample`]: seq (5) + t_us (10) + 7 zig-zag `i32` (5 each).
const IMU_SAMPLE_MAX: usize = 5 + 10 + 7 * 5;
/// Most bytes of one encoded [`MagSample`]: seq (5) + t_us (10) + 3 zig-zag `i32`.
const MAG_SAMPLE_MAX: usize = 5 + 10 + 3 * 5;
/// Most bytes [`write`] produces for a full batch: variant, bool, 5 × f32, two one-byte lengths
/// (both capacities are below 128) and the samples.
pub(crate) const MAX_SAMPLES_POSTCARD: usize =
    1 + 1 + 5 * 4 + 1 + MAX_BATCH_IMU * IMU_SAMPLE_MAX + 1 + MAX_BATCH_MAG * MAG_SAMPLE_MAX;

/// Output cursor. A byte past the end of `buf` is not stored, but still counted, so a buffer
/// that was too small shows as `pos > buf.len()` at the end: no check can panic, and the
/// in-range case pays one compare per byte.
struct Cursor<'a> {
    buf: &'a mut [u8],
    pos: usize,
}

impl Cursor<'_> {
    #[inline(always)]
    fn byte(&mut self, b: u8) {
        if let Some(slot) = self.buf.get_mut(self.pos) {
            *slot = b;
        }
        self.pos += 1;
    }

    #[inline(always)]
    fn varint(&mut self, mut v: u32) {
        while v >= 0x80 {
            self.byte(v as u8 | 0x80);
            v >>= 7;
        }
        self.byte(v as u8);
    }

    /// A `u64` varint with 32-bit arithmetic wherever the value allows (the M0+ has no 64-bit
    /// shifts); the common case (below 2^32 µs, 71 minutes of uptime) inline.
    #[inline(always)]
    fn varint_u64(&mut self, v: u64) {
        match u32::try_from(v) {
            Ok(small) => self.varint(small),
            Err(_) => self.varint_u64_long(v),
        }
    }

    /// `v` ≥ 2^32: the low 28 bits make the first four bytes, all with the high bit set.
    #[inline(never)]
    fn varint_u64_long(&mut self, v: u64) {
        let lo = v as u32;
        self.byte(lo as u8 | 0x80);
        self.byte((lo >> 7) as u8 | 0x80);
        self.byte((lo >> 14) as u8 | 0x80);
        self.byte((lo >> 21) as u8 | 0x80);
        let mut rest = v >> 28;
        if let Ok(small) = u32::try_from(rest) {
            return self.varint(small);
        }
        while rest >= 0x80 {
            self.byte(rest as u8 | 0x80);
            rest >>= 7;
        }
        self.byte(rest as u8);
    }

    #[inline(always)]
    fn zigzag(&mut self, n: i32) {
        self.varint(((n << 1) ^ (n >> 31)) as u32);
    }

    fn f32(&mut self, x: f32) {
        for b in x.to_le_bytes() {
            self.byte(b);
        }
    }

    fn scales(&mut self, s: &Scales) {
        self.f32(s.accel);
        self.f32(s.gyro);
        self.f32(s.mag);
        self.f32(s.temp);
        self.f32(s.temp_offset);
    }

    fn imu(&mut self, s: &ImuSample) {
        self.varint(s.seq);
        self.varint_u64(s.t_us);
        let [ax, ay, az] = s.accel;
        let [gx, gy, gz] = s.gyro;
        self.zigzag(ax);
        self.zigzag(ay);
        self.zigzag(az);
        self.zigzag(gx);
        self.zigzag(gy);
        self.zigzag(gz);
        self.zigzag(s.temp);
    }

    fn mag(&mut self, s: &MagSample) {
        self.varint(s.seq);
        self.varint_u64(s.t_us);
        let [x, y, z] = s.mag;
        self.zigzag(x);
        self.zigzag(y);
        self.zigzag(z);
    }
}

/// Write the postcard encoding of `DeviceMsg::Samples(batch)` into `buf`; returns its length,
/// or `None` if `buf` is too small (a buffer of [`MAX_SAMPLES_POSTCARD`] bytes always suffices).
pub fn write(batch: &SampleBatch, buf: &mut [u8]) -> Option<usize> {
    let mut c = Cursor { buf, pos: 0 };
    c.byte(SAMPLES_VARIANT);
    c.byte(u8::from(batch.calibrated));
    c.scales(&batch.scales);
    c.varint(batch.imu.len() as u32);
    for s in &batch.imu {
        c.imu(s);
    }
    c.varint(batch.mag.len() as u32);
    for s in &batch.mag {
        c.mag(s);
    }
    (c.pos <= c.buf.len()).then_some(c.pos)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Vec;

    /// The bound is exact: every field at its longest encoding fills it to the byte.
    #[test]
    fn the_longest_batch_fills_the_bound_exactly() {
        let imu = ImuSample {
            seq: u32::MAX,
            t_us: u64::MAX,
            accel: [i32::MIN; 3],
            gyro: [i32::MAX; 3],
            temp: i32::MIN,
        };
        let mag = MagSample {
            seq: u32::MAX,
            t_us: u64::MAX,
            mag: [i32::MIN, i32::MAX, i32::MIN],
        };
        let batch = SampleBatch {
            calibrated: true,
            scales: Scales {
                accel: 1.0,
                gyro: 1.0,
                mag: 1.0,
                temp: 1.0,
                temp_offset: 0.0,
            },
            imu: Vec::from_slice(&[imu; MAX_BATCH_IMU]).unwrap(),
            mag: Vec::from_slice(&[mag; MAX_BATCH_MAG]).unwrap(),
        };
        let mut buf = [0u8; MAX_SAMPLES_POSTCARD + 1];
        assert_eq!(write(&batch, &mut buf), Some(MAX_SAMPLES_POSTCARD));
        assert_eq!(
            write(&batch, &mut buf[..MAX_SAMPLES_POSTCARD]),
            Some(MAX_SAMPLES_POSTCARD)
        );
        assert_eq!(write(&batch, &mut buf[..MAX_SAMPLES_POSTCARD - 1]), None);
    }
}
