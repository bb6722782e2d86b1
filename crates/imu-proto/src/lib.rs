#![cfg_attr(not(feature = "std"), no_std)]
//! The pico-imu wire protocol, shared by the firmware and the host (`imu-lab`).
//!
//! # Frame format
//!
//! Every message, in both directions, travels as one frame:
//!
//! ```text
//! COBS( version:u8 | postcard(message) | crc32(version | postcard(message)) as u32 LE ) 0x00
//! ```
//!
//! * `version` is [`PROTOCOL_VERSION`]; a frame of another version is rejected, not guessed at.
//! * the message is serialised with postcard (varint integers, zig-zag for signed ones);
//! * the CRC is CRC-32/ISO-HDLC (the Ethernet/zip CRC, `crc::CRC_32_ISO_HDLC`) over the version
//!   byte and the postcard bytes;
//! * COBS (Cheshire & Baker, "Consistent Overhead Byte Stuffing", IEEE/ACM ToN 1999) removes
//!   every zero byte, so a single `0x00` delimits frames and a receiver resynchronises at the
//!   next zero after any corruption.
//!
//! Host → device frames are [`HostFrame`] (a request id and a [`Request`]); device → host
//! frames are [`DeviceMsg`]. A frame that is unknown, truncated, oversized or fails its CRC is
//! rejected with a [`DecodeError`] and counted in [`RxStats`]; no input can panic the decoder
//! (hammered by the proptests in `tests/`).
//!
//! ```
//! use imu_proto::{DecodeError, FrameEncoder, FrameReader, HostFrame, Request, MAX_FRAME};
//!
//! let msg = HostFrame { id: 7, req: Request::GetStatus };
//! let mut out = [0u8; MAX_FRAME];
//! let n = FrameEncoder::new().encode(&msg, &mut out).unwrap();
//! let frame = &out[..n];
//! // COBS: the one zero byte is the delimiter at the end.
//! assert_eq!(frame.iter().position(|&b| b == 0), Some(n - 1));
//!
//! let mut rx = FrameReader::<MAX_FRAME>::new();
//! let mut got = Vec::new();
//! rx.feed(frame, |r: Result<HostFrame, DecodeError>| got.push(r));
//! assert_eq!(got, [Ok(msg.clone())]);
//!
//! // A flipped bit anywhere in the frame is rejected and counted, never read as a message.
//! for i in 0..n - 1 {
//!     let mut bad = frame.to_vec();
//!     bad[i] ^= 0x10;
//!     let mut got = Vec::new();
//!     rx.feed(&bad, |r: Result<HostFrame, DecodeError>| got.push(r));
//!     assert!(got.iter().all(|r| r.is_err()), "byte {i}: {got:?}");
//! }
//! assert!(rx.stats().rejected() >= (n - 1) as u32);
//! ```
mod batch;
mod contract;
/// The CSV recording contract (columns, units, reading, writing, timing).
#[cfg(feature = "std")]
pub mod csv;
mod framing;
mod messages;
mod orientation;
mod status;
/// The hand-written postcard bytes of an Allan table, whole or a level at a time.
pub mod table;
mod wire;

pub use batch::BatchWriter;
pub use contract::*;
pub use framing::*;
pub use heapless::{String, Vec};
pub use messages::*;
