//! Frame output with a bounded queue: a frame is queued whole or dropped (and counted), never
//! split and never waited for, so a host that stops reading cannot stall the sampling path.
use imu_proto::{
    AllanTable, BatchWriter, DeviceMsg, EncodeError, FrameEncoder, Orientation, Scales, Status,
    Vec, MAX_FRAME, MAX_ORIENTATIONS,
};

/// Where encoded frames go (a byte pipe to the USB task on the device, a `Vec` in tests).
pub trait FrameSink {
    /// Bytes that can be queued now.
    fn room(&self) -> usize;
    /// Queue `frame` (called only when `frame.len() <= room()`).
    fn put(&mut self, frame: &[u8]);
}

/// Result of [`Outbox::send`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Sent {
    Queued(usize),
    /// No room: the frame was dropped and counted.
    Dropped,
    /// The message did not encode (larger than `MAX_PAYLOAD`): a firmware bug, counted.
    TooLarge,
}

/// Frames are queued padded with zero bytes to a multiple of this: empty frames between
/// delimiters, which every reader skips (`imu_proto::FrameReader`). Unaligned copies of the
/// short frames (byte by byte on the M0+) cost ≈ 200 cycles per sample set more.
pub const FRAME_ALIGN: usize = 4;

/// Room for a frame and its padding to a multiple of [`FRAME_ALIGN`] bytes.
const PADDED_FRAME: usize = MAX_FRAME.next_multiple_of(FRAME_ALIGN);

/// The frame buffer, word-aligned: frames are queued in multiples of 4 bytes from here, so the
/// copies into the output pipe and from it into the USB buffers are word copies.
#[repr(C, align(4))]
struct FrameBuf([u8; PADDED_FRAME]);

/// Encoder, frame buffer and drop counter.
pub struct Outbox {
    enc: FrameEncoder,
    buf: FrameBuf,
    /// Frames dropped because the queue was full.
    pub unsent: u32,
}

impl Default for Outbox {
    fn default() -> Self {
        Self::new()
    }
}

impl Outbox {
    pub const fn new() -> Self {
        Self {
            enc: FrameEncoder::new(),
            buf: FrameBuf([0; PADDED_FRAME]),
            unsent: 0,
        }
    }

    /// Encode `msg` (through serde: the rarer messages) and queue it on `sink` if it fits
    /// whole.
    pub fn send(&mut self, msg: &DeviceMsg, sink: &mut impl FrameSink) -> Sent {
        let encoded = self.enc.encode(msg, &mut self.buf.0[..MAX_FRAME]);
        self.queue(encoded, sink)
    }

    /// Frame the batch written in its wire form as the samples came ([`BatchWriter`]; the same
    /// bytes as [`Outbox::send`] of `DeviceMsg::Samples` with those samples, a fraction of the
    /// cycles) and queue it if it fits whole.
    pub fn send_batch(
        &mut self,
        batch: &mut BatchWriter,
        calibrated: bool,
        scales: &Scales,
        sink: &mut impl FrameSink,
    ) -> Sent {
        let encoded =
            self.enc
                .encode_batch(batch, calibrated, scales, &mut self.buf.0[..MAX_FRAME]);
        self.queue(encoded, sink)
    }

    /// Encode `DeviceMsg::Table(table)` with the hand-written table encoder (the same bytes as
    /// [`Outbox::send`]) and queue it if it fits whole.
    pub fn send_table(&mut self, table: &AllanTable, sink: &mut impl FrameSink) -> Sent {
        let encoded = self.enc.encode_table(table, &mut self.buf.0[..MAX_FRAME]);
        self.queue(encoded, sink)
    }

    /// Encode `DeviceMsg::Status(status)` with the hand-written status encoder (the same bytes
    /// as [`Outbox::send`]) and queue it if it fits whole.
    pub fn send_status(&mut self, status: &Status, sink: &mut impl FrameSink) -> Sent {
        let encoded = self.enc.encode_status(status, &mut self.buf.0[..MAX_FRAME]);
        self.queue(encoded, sink)
    }

    /// Encode `DeviceMsg::Orientation(list)` with the hand-written encoder (the same bytes as
    /// [`Outbox::send`]) and queue it if it fits whole.
    pub fn send_orientations(
        &mut self,
        list: &Vec<Orientation, MAX_ORIENTATIONS>,
        sink: &mut impl FrameSink,
    ) -> Sent {
        let encoded = self
            .enc
            .encode_orientations(list, &mut self.buf.0[..MAX_FRAME]);
        self.queue(encoded, sink)
    }

    /// Queue a frame built elsewhere ([`imu_proto::FrameBuilder`], padded to a multiple of
    /// [`FRAME_ALIGN`] bytes) if it fits whole.
    pub fn queue_built(
        &mut self,
        frame: Result<&[u8], EncodeError>,
        sink: &mut impl FrameSink,
    ) -> Sent {
        put_whole(&mut self.unsent, frame, sink)
    }

    /// Queue the frame of `encoded` bytes in the frame buffer, padded.
    fn queue(&mut self, encoded: Result<usize, EncodeError>, sink: &mut impl FrameSink) -> Sent {
        let frame = encoded.map(|n| {
            let padded = n.next_multiple_of(FRAME_ALIGN);
            self.buf.0[n..padded].fill(0);
            &self.buf.0[..padded]
        });
        put_whole(&mut self.unsent, frame, sink)
    }
}

/// Put `frame` on `sink` if it fits whole; otherwise (or if it did not encode) count it in
/// `unsent`.
fn put_whole(
    unsent: &mut u32,
    frame: Result<&[u8], EncodeError>,
    sink: &mut impl FrameSink,
) -> Sent {
    let Ok(frame) = frame else {
        *unsent = unsent.saturating_add(1);
        return Sent::TooLarge;
    };
    if frame.len() > sink.room() {
        *unsent = unsent.saturating_add(1);
        return Sent::Dropped;
    }
    sink.put(frame);
    Sent::Queued(frame.len())
}
