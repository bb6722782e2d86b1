//! The wire layout of a [`SampleBatch`] (its serde impls) and the postcard bytes of
//! `DeviceMsg::Samples(batch)`, written by hand.
//!
//! # Layout (protocol version 4)
//!
//! `calibrated: bool`, `scales: Scales`, then the IMU samples and the magnetometer samples, each
//! as a length (varint) and that many samples. The first sample of a sensor carries `seq: u32`
//! and `t_us: u64`; every later one carries `seq − previous seq` (u32, wrapping) and
//! `t_us − previous t_us − P` (i64, wrapping, zig-zag), P the nominal period ([`IMU_PERIOD_US`],
//! [`MAG_PERIOD_US`]), then its values (`[i32; 3]`, `[i32; 3]`, `Option<i32>` for the IMU; `[i32; 3]`
//! for the magnetometer). A regular run (consecutive numbers, one period apart) therefore costs
//! two bytes of bookkeeping a sample instead of eight or nine, a third less per IMU sample, and
//! every value still round-trips exactly.
//!
//! # The hand-written encoder
//!
//! The firmware frames a [`SampleBatch`] every 25 ms. Through serde, postcard writes every
//! varint with its own small copy into the output; this writer produces the very same bytes in
//! one straight pass (`crate::wire`, which lists the rules of postcard's wire format).
//!
//! The proptests in `tests/batch.rs` check the bytes against the serde path for arbitrary
//! batches, extreme values included.
use core::fmt;
use core::marker::PhantomData;

use serde::de::{self, Deserialize, Deserializer, SeqAccess, Visitor};
use serde::ser::{Serialize, SerializeSeq, SerializeTuple, Serializer};

use crate::wire::Cursor;
use crate::{
    ImuSample, MagSample, SampleBatch, Scales, Vec, IMU_PERIOD_US, MAG_PERIOD_US, MAX_BATCH_IMU,
    MAX_BATCH_MAG,
};

/// What the wire layout needs of a sample: its bookkeeping and its values.
trait Sample: Copy {
    const PERIOD_US: u64;
    type Values: Serialize + for<'de> Deserialize<'de>;
    fn seq(&self) -> u32;
    fn t_us(&self) -> u64;
    fn values(&self) -> Self::Values;
    fn from_parts(seq: u32, t_us: u64, v: Self::Values) -> Self;
}

impl Sample for ImuSample {
    const PERIOD_US: u64 = IMU_PERIOD_US;
    type Values = ([i32; 3], [i32; 3], Option<i32>);
    fn seq(&self) -> u32 {
        self.seq
    }
    fn t_us(&self) -> u64 {
        self.t_us
    }
    fn values(&self) -> Self::Values {
        (self.accel, self.gyro, self.temp)
    }
    fn from_parts(seq: u32, t_us: u64, (accel, gyro, temp): Self::Values) -> Self {
        ImuSample {
            seq,
            t_us,
            accel,
            gyro,
            temp,
        }
    }
}

impl Sample for MagSample {
    const PERIOD_US: u64 = MAG_PERIOD_US;
    type Values = [i32; 3];
    fn seq(&self) -> u32 {
        self.seq
    }
    fn t_us(&self) -> u64 {
        self.t_us
    }
    fn values(&self) -> Self::Values {
        self.mag
    }
    fn from_parts(seq: u32, t_us: u64, mag: Self::Values) -> Self {
        MagSample { seq, t_us, mag }
    }
}

/// `t − previous − P`, wrapping: the time field of every sample but the first.
fn time_delta<S: Sample>(t: u64, prev: u64) -> i64 {
    t.wrapping_sub(prev).wrapping_sub(S::PERIOD_US) as i64
}

/// One sensor's samples in the delta layout.
struct Run<'a, S>(&'a [S]);

impl<S: Sample> Serialize for Run<'_, S> {
    fn serialize<Z: Serializer>(&self, z: Z) -> Result<Z::Ok, Z::Error> {
        let mut seq = z.serialize_seq(Some(self.0.len()))?;
        let mut prev: Option<&S> = None;
        for s in self.0 {
            match prev {
                None => seq.serialize_element(&(s.seq(), s.t_us(), s.values()))?,
                Some(p) => seq.serialize_element(&(
                    s.seq().wrapping_sub(p.seq()),
                    time_delta::<S>(s.t_us(), p.t_us()),
                    s.values(),
                ))?,
            }
            prev = Some(s);
        }
        seq.end()
    }
}

/// Reads a [`Run`] back into a `Vec` of at most `N` samples.
struct RunVisitor<S, const N: usize>(PhantomData<S>);

impl<'de, S: Sample, const N: usize> Visitor<'de> for RunVisitor<S, N> {
    type Value = Vec<S, N>;

    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        write!(f, "at most {N} samples")
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut a: A) -> Result<Self::Value, A::Error> {
        let mut out = Vec::new();
        let mut prev: Option<S> = None;
        loop {
            let s = match prev {
                None => match a.next_element::<(u32, u64, S::Values)>()? {
                    Some((seq, t, v)) => S::from_parts(seq, t, v),
                    None => break,
                },
                Some(p) => match a.next_element::<(u32, i64, S::Values)>()? {
                    Some((ds, dt, v)) => S::from_parts(
                        p.seq().wrapping_add(ds),
                        p.t_us().wrapping_add(dt as u64).wrapping_add(S::PERIOD_US),
                        v,
                    ),
                    None => break,
                },
            };
            out.push(s)
                .map_err(|_| de::Error::invalid_length(N + 1, &self))?;
            prev = Some(s);
        }
        Ok(out)
    }
}

struct RunOf<S, const N: usize>(Vec<S, N>);

impl<'de, S: Sample, const N: usize> Deserialize<'de> for RunOf<S, N> {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        d.deserialize_seq(RunVisitor::<S, N>(PhantomData))
            .map(RunOf)
    }
}

impl Serialize for SampleBatch {
    fn serialize<Z: Serializer>(&self, z: Z) -> Result<Z::Ok, Z::Error> {
        let mut t = z.serialize_tuple(4)?;
        t.serialize_element(&self.calibrated)?;
        t.serialize_element(&self.scales)?;
        t.serialize_element(&Run(&self.imu))?;
        t.serialize_element(&Run(&self.mag))?;
        t.end()
    }
}

impl<'de> Deserialize<'de> for SampleBatch {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct BatchVisitor;
        impl<'de> Visitor<'de> for BatchVisitor {
            type Value = SampleBatch;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("a sample batch")
            }
            fn visit_seq<A: SeqAccess<'de>>(self, mut a: A) -> Result<SampleBatch, A::Error> {
                let missing = |i| de::Error::invalid_length(i, &"4 fields");
                let calibrated = a.next_element()?.ok_or_else(|| missing(0))?;
                let scales = a.next_element()?.ok_or_else(|| missing(1))?;
                let imu: RunOf<ImuSample, MAX_BATCH_IMU> =
                    a.next_element()?.ok_or_else(|| missing(2))?;
                let mag: RunOf<MagSample, MAX_BATCH_MAG> =
                    a.next_element()?.ok_or_else(|| missing(3))?;
                Ok(SampleBatch {
                    calibrated,
                    scales,
                    imu: imu.0,
                    mag: mag.0,
                })
            }
        }
        d.deserialize_tuple(4, BatchVisitor)
    }
}

/// Index of `DeviceMsg::Samples` among `DeviceMsg`'s variants (tested against the serde path).
pub(crate) const SAMPLES_VARIANT: u8 = 1;

/// Most bytes of one encoded [`ImuSample`]: seq (5) + t_us (10) + 6 zig-zag `i32` (5 each) +
/// the temperature's `Option` tag and zig-zag `i32`.
const IMU_SAMPLE_MAX: usize = 5 + 10 + 6 * 5 + 1 + 5;
/// Most bytes of one encoded [`MagSample`]: seq (5) + t_us (10) + 3 zig-zag `i32`.
const MAG_SAMPLE_MAX: usize = 5 + 10 + 3 * 5;
/// Most bytes [`write`] produces for a full batch (see `bound`).
pub(crate) const MAX_SAMPLES_POSTCARD: usize =
    1 + 1 + 5 * 4 + 1 + MAX_BATCH_IMU * IMU_SAMPLE_MAX + 1 + MAX_BATCH_MAG * MAG_SAMPLE_MAX;

impl<const CHECKED: bool> Cursor<'_, CHECKED> {
    fn scales(&mut self, s: &Scales) {
        self.f32(s.accel);
        self.f32(s.gyro);
        self.f32(s.mag);
        self.f32(s.temp);
        self.f32(s.temp_offset);
    }

    /// The bookkeeping of a sample: absolute for the first of its run, else the differences.
    #[inline(always)]
    fn head<S: Sample>(&mut self, s: &S, prev: Option<&S>) {
        self.head_of::<S>(s.seq(), s.t_us(), prev.map(|p| (p.seq(), p.t_us())));
    }

    /// [`Cursor::head`] from the parts: this sample's `seq` and `t_us`, the previous one's.
    #[inline(always)]
    fn head_of<S: Sample>(&mut self, seq: u32, t_us: u64, prev: Option<(u32, u64)>) {
        match prev {
            None => {
                self.varint(seq);
                self.varint_u64(t_us);
            }
            Some((p_seq, p_t)) => {
                self.varint(seq.wrapping_sub(p_seq));
                self.zigzag_i64(time_delta::<S>(t_us, p_t));
            }
        }
    }

    /// An `i64` zig-zag varint; the common case (a difference that fits i32) in 32 bits: the
    /// zig-zag of such a value is the same number in 32 or 64 bits.
    #[inline(always)]
    fn zigzag_i64(&mut self, n: i64) {
        match i32::try_from(n) {
            Ok(small) => self.zigzag(small),
            Err(_) => self.varint_u64_long(((n << 1) ^ (n >> 63)) as u64),
        }
    }

    fn imu(&mut self, s: &ImuSample, prev: Option<&ImuSample>) {
        self.head(s, prev);
        self.imu_values(&s.accel, &s.gyro, s.temp);
    }

    /// An IMU sample's values (after its bookkeeping).
    #[inline(always)]
    fn imu_values(&mut self, accel: &[i32; 3], gyro: &[i32; 3], temp: Option<i32>) {
        let [ax, ay, az] = *accel;
        let [gx, gy, gz] = *gyro;
        self.zigzag(ax);
        self.zigzag(ay);
        self.zigzag(az);
        self.zigzag(gx);
        self.zigzag(gy);
        self.zigzag(gz);
        // `Option`: a 0 byte for `None`, a 1 byte and the value for `Some` (`Cursor::option`'s
        // form, written out: on this per-sample path LLVM lays out the match tighter than the
        // helper's closure; docs/benchmarks.md).
        match temp {
            Some(t) => {
                self.byte(1);
                self.zigzag(t);
            }
            None => self.byte(0),
        }
    }

    fn mag(&mut self, s: &MagSample, prev: Option<&MagSample>) {
        self.head(s, prev);
        let [x, y, z] = s.mag;
        self.zigzag(x);
        self.zigzag(y);
        self.zigzag(z);
    }
}

/// Write the postcard encoding of `DeviceMsg::Samples(batch)` into `buf`; returns its length,
/// or `None` if `buf` is too small (a buffer of [`MAX_SAMPLES_POSTCARD`] bytes always suffices).
pub fn write(batch: &SampleBatch, buf: &mut [u8]) -> Option<usize> {
    if bound(batch) <= buf.len() {
        Some(write_with(Cursor::<false> { buf, pos: 0 }, batch))
    } else {
        let len = buf.len();
        Some(write_with(Cursor::<true> { buf, pos: 0 }, batch)).filter(|&n| n <= len)
    }
}

/// The longest encoding of a batch with as many samples as `batch`: variant, bool, 5 × f32,
/// two one-byte lengths (both capacities are below 128) and each sample at its longest.
fn bound(batch: &SampleBatch) -> usize {
    1 + 1 + 5 * 4 + 1 + batch.imu.len() * IMU_SAMPLE_MAX + 1 + batch.mag.len() * MAG_SAMPLE_MAX
}

/// The bytes of `batch` through `c`; returns how many were written (or counted).
fn write_with<const CHECKED: bool>(mut c: Cursor<'_, CHECKED>, batch: &SampleBatch) -> usize {
    c.byte(SAMPLES_VARIANT);
    c.byte(u8::from(batch.calibrated));
    c.scales(&batch.scales);
    c.varint(batch.imu.len() as u32);
    let mut prev = None;
    for s in &batch.imu {
        c.imu(s, prev);
        prev = Some(s);
    }
    c.varint(batch.mag.len() as u32);
    let mut prev = None;
    for s in &batch.mag {
        c.mag(s, prev);
        prev = Some(s);
    }
    c.pos
}

/// Where the first IMU sample's bytes go in a [`BatchWriter`]'s content: the version byte,
/// the variant, `calibrated`, the five scales and the IMU count (one byte: below 128).
const IMU_AT: usize = 1 + 1 + 1 + 5 * 4 + 1;
const _: () = assert!(MAX_BATCH_IMU < 128 && MAX_BATCH_MAG < 128);

/// Bytes of a [`BatchWriter`]'s content at its longest: the version byte and the longest
/// postcard bytes of a full batch.
const WRITER_BYTES: usize = 1 + MAX_SAMPLES_POSTCARD;

/// A `DeviceMsg::Samples` batch written in its wire form as the samples arrive: each IMU sample
/// is encoded once, straight into the frame's content (version byte and postcard bytes),
/// instead of being kept as an [`ImuSample`] and encoded when the batch is sent. The header
/// (`calibrated`, the scales, the count) and the magnetometer's few samples are written when
/// the batch is finished. The bytes are those of [`write`] for the same samples (proptested in
/// `tests/batch.rs`), so the wire format is the one documented in docs/protocol.md.
#[repr(C, align(4))]
pub struct BatchWriter {
    /// The content: bytes `..IMU_AT` written by [`BatchWriter::finish`], the IMU samples' bytes
    /// from `IMU_AT` to `end`.
    buf: [u8; WRITER_BYTES],
    end: usize,
    imu: usize,
    /// The previous IMU sample's `seq` and `t_us` (the next one is written as differences).
    prev: (u32, u64),
    mag: Vec<MagSample, MAX_BATCH_MAG>,
}

impl Default for BatchWriter {
    fn default() -> Self {
        Self::new()
    }
}

impl BatchWriter {
    pub const fn new() -> Self {
        Self {
            buf: [0; WRITER_BYTES],
            end: IMU_AT,
            imu: 0,
            prev: (0, 0),
            mag: Vec::new(),
        }
    }

    /// IMU samples in the batch.
    pub fn imu_len(&self) -> usize {
        self.imu
    }

    /// Magnetometer samples in the batch.
    pub fn mag_len(&self) -> usize {
        self.mag.len()
    }

    pub fn is_empty(&self) -> bool {
        self.imu == 0 && self.mag.is_empty()
    }

    /// Forget the samples: the next batch starts empty.
    pub fn clear(&mut self) {
        self.end = IMU_AT;
        self.imu = 0;
        self.mag.clear();
    }

    /// Append an IMU sample (the fields of [`ImuSample`]); `false` (nothing written) if the
    /// batch already holds [`MAX_BATCH_IMU`].
    #[inline(always)]
    pub fn push_imu(
        &mut self,
        seq: u32,
        t_us: u64,
        accel: &[i32; 3],
        gyro: &[i32; 3],
        temp: Option<i32>,
    ) -> bool {
        if self.imu >= MAX_BATCH_IMU {
            return false;
        }
        let prev = (self.imu > 0).then_some(self.prev);
        // Unchecked: `end` ≤ IMU_AT + imu · IMU_SAMPLE_MAX with imu < MAX_BATCH_IMU, so this
        // sample's longest encoding ends within `buf` (WRITER_BYTES covers the whole batch).
        let mut c = Cursor::<false> {
            buf: &mut self.buf,
            pos: self.end,
        };
        c.head_of::<ImuSample>(seq, t_us, prev);
        c.imu_values(accel, gyro, temp);
        self.end = c.pos;
        self.imu += 1;
        self.prev = (seq, t_us);
        true
    }

    /// Append a magnetometer sample; `false` (nothing kept) if the batch already holds
    /// [`MAX_BATCH_MAG`].
    pub fn push_mag(&mut self, s: MagSample) -> bool {
        self.mag.push(s).is_ok()
    }

    /// Whether no further magnetometer sample fits.
    pub fn mag_full(&self) -> bool {
        self.mag.is_full()
    }

    /// The frame content of `DeviceMsg::Samples` with these samples, `calibrated` and `scales`:
    /// the version byte, then the postcard bytes [`write`] produces for the same batch. The
    /// samples stay until [`BatchWriter::clear`].
    pub fn finish(&mut self, version: u8, calibrated: bool, scales: &Scales) -> &[u8] {
        let mut c = Cursor::<false> {
            buf: &mut self.buf,
            pos: 0,
        };
        c.byte(version);
        c.byte(SAMPLES_VARIANT);
        c.byte(u8::from(calibrated));
        c.scales(scales);
        c.byte(self.imu as u8);
        debug_assert_eq!(c.pos, IMU_AT);
        // The magnetometer's run after the IMU's: its count (one byte) and at most
        // MAX_BATCH_MAG samples at their longest, within WRITER_BYTES.
        c.pos = self.end;
        c.byte(self.mag.len() as u8);
        let mut prev = None;
        for s in &self.mag {
            c.mag(s, prev);
            prev = Some(s);
        }
        let n = c.pos;
        &self.buf[..n]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The bound is exact: every field at its longest encoding fills it to the byte. The
    /// first sample of each sensor has the largest absolute `seq` and `t_us`; the later ones
    /// alternate half a range away, so every difference is at its longest too.
    #[test]
    fn the_longest_batch_fills_the_bound_exactly() {
        let imu = |k: usize| ImuSample {
            seq: u32::MAX.wrapping_add((k as u32) << 31),
            t_us: u64::MAX.wrapping_add((k as u64) << 63),
            accel: [i32::MIN; 3],
            gyro: [i32::MAX; 3],
            temp: Some(i32::MIN),
        };
        let mag = |k: usize| MagSample {
            seq: u32::MAX.wrapping_add((k as u32) << 31),
            t_us: u64::MAX.wrapping_add((k as u64) << 63),
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
            imu: (0..MAX_BATCH_IMU).map(imu).collect(),
            mag: (0..MAX_BATCH_MAG).map(mag).collect(),
        };
        let mut buf = [0u8; MAX_SAMPLES_POSTCARD + 1];
        assert_eq!(write(&batch, &mut buf), Some(MAX_SAMPLES_POSTCARD));
        assert_eq!(
            write(&batch, &mut buf[..MAX_SAMPLES_POSTCARD]),
            Some(MAX_SAMPLES_POSTCARD)
        );
        assert_eq!(write(&batch, &mut buf[..MAX_SAMPLES_POSTCARD - 1]), None);
        assert_eq!(bound(&batch), MAX_SAMPLES_POSTCARD);

        // The unchecked cursor relies on `bound` for every batch size: the longest samples
        // fill it exactly, and one byte less goes through the checked cursor and fails.
        for (n_imu, n_mag) in [(0, 0), (1, 0), (0, 1), (7, 3), (MAX_BATCH_IMU, 1)] {
            let part = SampleBatch {
                imu: (0..n_imu).map(imu).collect(),
                mag: (0..n_mag).map(mag).collect(),
                ..batch.clone()
            };
            let n = bound(&part);
            assert_eq!(
                write(&part, &mut buf[..n]),
                Some(n),
                "{n_imu} + {n_mag} samples"
            );
            assert_eq!(
                write(&part, &mut buf[..n - 1]),
                None,
                "{n_imu} + {n_mag} samples"
            );
        }
    }
}
