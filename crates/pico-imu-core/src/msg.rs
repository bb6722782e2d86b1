//! What the sensor tasks tell the processing task.
use imu_drivers::mpu6050::{FifoFrame, RawSample};
use imu_proto::{Event, GapCause, Sensor, SensorState, Vec};

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

/// The messages of one tick of a sensor task (a few bursts or readings and their reports).
pub type Out = Vec<SensorMsg, 6>;

#[cfg(test)]
mod tests {
    use super::*;

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
}
