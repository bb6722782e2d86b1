//! What the sensor tasks tell the processing task.
use imu_drivers::mpu6050::{FifoFrame, RawSample};
use imu_proto::{Event, GapCause, Sensor, SensorState};

use crate::clock::Stamps;

/// Most FIFO frames one [`SensorMsg::Imu`] carries: a 10 ms burst holds 10 frames (more after a
/// delay), read in one I2C transfer of at most 16.
pub const BURST_MAX: usize = 16;

/// Bytes of the longest FIFO frame (accelerometer, temperature, gyro: [`FifoFrame::bytes`]).
pub const FIFO_FRAME_MAX: usize = 14;

/// One burst's FIFO frames as the part sent them (big-endian values in the configured
/// `layout`), read straight into the message and decoded only where their values are used
/// (the corrections; a decoded copy of each frame cost ≈ 130 cycles on the M0+).
///
/// `#[repr(C)]`: `count` lies directly before `bytes`, so that a FIFO count and the frames
/// read after it in one transfer land in one run of memory (one DMA channel on the device).
#[derive(Debug, Clone)]
#[repr(C)]
pub struct FifoFrames {
    pub layout: FifoFrame,
    /// Frames in `bytes` (at most [`BURST_MAX`]).
    pub n: usize,
    /// The FIFO count's two bytes as read with the frames (when they were).
    pub count: [u8; 2],
    pub bytes: [u8; BURST_MAX * FIFO_FRAME_MAX],
}

impl FifoFrames {
    /// No frames yet, in `layout`.
    pub const fn new(layout: FifoFrame) -> Self {
        Self {
            layout,
            n: 0,
            count: [0; 2],
            bytes: [0; BURST_MAX * FIFO_FRAME_MAX],
        }
    }

    /// The frames the part would send for `samples` (at most [`BURST_MAX`]) in `layout`:
    /// big-endian values, the temperature (0 for `None`) only in the 14-byte layout. For tests
    /// and replays; the device reads them from the FIFO.
    pub fn of(layout: FifoFrame, samples: &[RawSample]) -> Self {
        let mut f = Self::new(layout);
        for (bytes, s) in f.bytes.chunks_exact_mut(layout.bytes()).zip(samples) {
            let temp = (layout == FifoFrame::AccelTempGyro).then_some(s.temp.unwrap_or(0));
            let values = s.accel.into_iter().chain(temp).chain(s.gyro);
            for (b, x) in bytes.chunks_exact_mut(2).zip(values) {
                b.copy_from_slice(&x.to_be_bytes());
            }
            f.n += 1;
        }
        f
    }

    /// The frames' bytes.
    pub fn as_bytes(&self) -> &[u8] {
        &self.bytes[..self.n.min(BURST_MAX) * self.layout.bytes()]
    }

    /// The frames of the 14-byte layout ([`FifoFrame::AccelTempGyro`]), whatever `layout`
    /// says. Cut from the whole buffer, whose length is a constant, then taken to `n`: no
    /// division by 14 at run time (a library call on the M0+, ≈ 120 cycles a burst).
    pub fn frames_14(&self) -> &[[u8; FIFO_FRAME_MAX]] {
        let (all, _) = self.bytes.as_chunks::<FIFO_FRAME_MAX>();
        &all[..self.n.min(BURST_MAX)]
    }
}

/// One sensor task's message.
#[derive(Debug, Clone)]
#[allow(clippy::large_enum_variant)] // no heap: the burst travels inline through the channel
pub enum SensorMsg {
    /// FIFO frames in arrival order: sample `i` is slot `stamps.k0 + i` of the IMU's grid.
    /// `after`: a discontinuity of that cause comes before the first of them (the slots between
    /// the previous burst and this one are the samples it cost, maybe none).
    Imu {
        stamps: Stamps,
        frames: FifoFrames,
        after: Option<GapCause>,
    },
    /// One magnetometer reading, slot `stamps.k0` of its grid; `after` as for `Imu`.
    Mag {
        stamps: Stamps,
        xyz: [i16; 3],
        after: Option<GapCause>,
    },
    /// A sensor service's state, counters and events.
    Report(Report),
    /// The bus was recovered (SCL clocked, STOP) before a sensor's transfer.
    BusRecovered {
        t_us: u64,
        pulses: u8,
        sda_released: bool,
    },
}

/// A sensor service's report: the state after its tick, what it counted, and an event.
#[derive(Debug, Clone, Copy)]
pub struct Report {
    pub sensor: Sensor,
    pub state: SensorState,
    /// Failed transfers since the last report.
    pub i2c_errors: u32,
    /// Of those, bus faults (arbitration lost, deadline).
    pub bus_faults: u32,
    /// FIFO overflows since the last report.
    pub fifo_overflows: u32,
    /// The sample clock's period, ns (0: not known yet).
    pub period_ns: u32,
    pub event: Option<Event>,
}

/// An [`Out`] had no slot left for a message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct OutFull;

/// Messages an [`Out`] holds.
pub const OUT_CAPACITY: usize = 6;

/// The messages of one tick of a sensor task (a few bursts or readings and their reports),
/// used as a slice of them. Its slots keep what they held when cleared, so a burst's message
/// opened where one was before reuses its 224-byte frame buffer as it is ([`Out::open_burst`]):
/// the frames are read into it and only the first `n` count. (Built anew, the buffer was
/// zeroed on every burst: ≈ 230 cycles.)
#[derive(Debug, Clone)]
pub struct Out {
    slots: [SensorMsg; OUT_CAPACITY],
    len: usize,
}

impl Default for Out {
    fn default() -> Self {
        Self::new()
    }
}

impl Out {
    pub const fn new() -> Self {
        Self {
            slots: [const {
                SensorMsg::BusRecovered {
                    t_us: 0,
                    pulses: 0,
                    sda_released: false,
                }
            }; OUT_CAPACITY],
            len: 0,
        }
    }

    pub const fn capacity(&self) -> usize {
        OUT_CAPACITY
    }

    /// Forget the messages (their slots are kept as they are).
    pub fn clear(&mut self) {
        self.len = 0;
    }

    /// Keep the first `len` messages (all when there are no more).
    pub fn truncate(&mut self, len: usize) {
        self.len = self.len.min(len);
    }

    /// Append `msg`; [`OutFull`] (and `msg` dropped) when the slots are all taken.
    pub fn push(&mut self, msg: SensorMsg) -> Result<(), OutFull> {
        let slot = self.slots.get_mut(self.len).ok_or(OutFull)?;
        *slot = msg;
        self.len += 1;
        Ok(())
    }

    /// Append an IMU burst's message with default stamps, no frames in `layout` and `after`,
    /// before its read, so that the frames are read straight into it (built with defaults and
    /// moved in after, it went through a copy on the stack); its stamps come once the frames
    /// are in. Its frame buffer, or `None` when the slots are all taken. The buffer's bytes are
    /// what the slot held before (only the first `n` frames count).
    pub fn open_burst(
        &mut self,
        layout: FifoFrame,
        after: Option<GapCause>,
    ) -> Option<&mut FifoFrames> {
        let slot = self.slots.get_mut(self.len)?;
        self.len += 1;
        if let SensorMsg::Imu {
            stamps,
            frames,
            after: a,
        } = slot
        {
            *stamps = Stamps::default();
            *a = after;
            frames.layout = layout;
            frames.n = 0;
            frames.count = [0; 2];
        } else {
            *slot = SensorMsg::Imu {
                stamps: Stamps::default(),
                frames: FifoFrames::new(layout),
                after,
            };
        }
        match slot {
            SensorMsg::Imu { frames, .. } => Some(frames),
            _ => None,
        }
    }
}

impl core::ops::Deref for Out {
    type Target = [SensorMsg];
    fn deref(&self) -> &[SensorMsg] {
        &self.slots[..self.len]
    }
}

impl core::ops::DerefMut for Out {
    fn deref_mut(&mut self) -> &mut [SensorMsg] {
        &mut self.slots[..self.len]
    }
}

impl IntoIterator for Out {
    type Item = SensorMsg;
    type IntoIter = core::iter::Take<core::array::IntoIter<SensorMsg, OUT_CAPACITY>>;
    fn into_iter(self) -> Self::IntoIter {
        self.slots.into_iter().take(self.len)
    }
}

impl<'a> IntoIterator for &'a Out {
    type Item = &'a SensorMsg;
    type IntoIter = core::slice::Iter<'a, SensorMsg>;
    fn into_iter(self) -> Self::IntoIter {
        self.iter()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use imu_proto::Vec;

    /// `frames_14` is the 14-byte frames of `as_bytes`, for every count the message can say,
    /// beyond `BURST_MAX` too (cut there), on frames that differ byte by byte.
    #[test]
    fn frames_14_are_the_bytes_in_frames() {
        for n in 0..=BURST_MAX + 3 {
            let mut f = FifoFrames::new(FifoFrame::AccelTempGyro);
            for (i, b) in f.bytes.iter_mut().enumerate() {
                *b = (i * 7 + 3) as u8;
            }
            f.n = n;
            let want: Vec<[u8; 14], BURST_MAX> = f
                .as_bytes()
                .chunks_exact(14)
                .map(|c| c.try_into().unwrap())
                .collect();
            assert_eq!(f.frames_14(), &want[..], "n = {n}");
            assert_eq!(f.frames_14().len(), n.min(BURST_MAX));
        }
    }

    /// A burst opened where a burst's message was keeps its frame bytes (not cleared again)
    /// but not its count, stamps, layout or cause; opened where another message was, or in a
    /// new `Out`, its frames are zeros. Full, `push` and `open_burst` add nothing.
    #[test]
    fn a_burst_reuses_its_slots_frame_buffer_and_nothing_else() {
        let mut out = Out::new();
        let f = out.open_burst(FifoFrame::AccelTempGyro, None).unwrap();
        assert!(f.bytes.iter().all(|&b| b == 0) && f.n == 0);
        for (i, b) in f.bytes.iter_mut().enumerate() {
            *b = i as u8 | 1;
        }
        (f.n, f.count) = (5, [1, 2]);
        if let Some(SensorMsg::Imu { stamps, .. }) = out.last_mut() {
            stamps.k0 = 7;
        }
        out.clear();
        assert!(out.is_empty());
        let f = out
            .open_burst(FifoFrame::AccelGyro, Some(GapCause::Stalled))
            .unwrap();
        assert_eq!((f.n, f.count, f.layout), (0, [0, 0], FifoFrame::AccelGyro));
        assert!(f.bytes.iter().enumerate().all(|(i, &b)| b == i as u8 | 1));
        match &out[0] {
            SensorMsg::Imu { stamps, after, .. } => {
                assert_eq!(
                    (*stamps, *after),
                    (Stamps::default(), Some(GapCause::Stalled))
                );
            }
            m => panic!("{m:?}"),
        }
        // A reading in that slot: the next burst there starts from zeros.
        out.clear();
        let reading = SensorMsg::Mag {
            stamps: Stamps::default(),
            xyz: [1, 2, 3],
            after: None,
        };
        out.push(reading.clone()).unwrap();
        out.truncate(0);
        assert!(out.is_empty());
        out.push(reading.clone()).unwrap();
        out.clear();
        let f = out.open_burst(FifoFrame::AccelTempGyro, None).unwrap();
        assert!(f.bytes.iter().all(|&b| b == 0));
        for _ in 1..out.capacity() {
            out.push(reading.clone()).unwrap();
        }
        assert_eq!(out.len(), OUT_CAPACITY);
        assert_eq!(out.push(reading), Err(OutFull));
        assert!(out.open_burst(FifoFrame::AccelTempGyro, None).is_none());
        assert_eq!(out.len(), OUT_CAPACITY);
        assert_eq!((&out).into_iter().count(), OUT_CAPACITY);
        out.truncate(2);
        assert_eq!(out.into_iter().count(), 2);
    }
}
