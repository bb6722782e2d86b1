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
mod batch;
mod contract;
/// The CSV recording contract (columns, units, reading, writing, timing).
#[cfg(feature = "std")]
pub mod csv;
mod framing;
mod messages;
mod status;
/// The hand-written postcard bytes of an Allan table, whole or a level at a time.
pub mod table;
mod wire;

pub use contract::*;
pub use framing::*;
pub use heapless::{String, Vec};
pub use messages::*;
