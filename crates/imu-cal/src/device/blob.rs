//! The calibration blob: the bytes the host sends and the device persists (layout in the
//! module docs of [`super`]).
use super::{BlobError, Calibration};

/// Magic bytes at the start of every calibration blob.
pub const BLOB_MAGIC: [u8; 4] = *b"PCAL";
/// The blob format version this build reads and writes.
pub const BLOB_VERSION: u16 = 2;
/// Upper bound of an encoded blob (header + worst-case postcard varints + CRC).
/// Payload worst case: three affine parts of 12 i32 varints (≤ 5 bytes each), 3 more i32 and
/// one i16 (≤ 3 bytes) for the gyro temperature term, the optional sensitivities (1 + 3 × 4).
pub const MAX_BLOB_LEN: usize = 8 + (3 * 12 * 5 + 3 * 5 + 3) + 13 + 4;

const CRC32: crc::Crc<u32> = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC);

/// Encode `cal` into `buf`, returning the used prefix (layout in the module docs).
pub fn encode_blob<'a>(cal: &Calibration, buf: &'a mut [u8]) -> Result<&'a [u8], BlobError> {
    cal.validate()?;
    let len = buf.len();
    if len < 12 {
        return Err(BlobError::BufferTooSmall { len });
    }
    let n = postcard::to_slice(cal, &mut buf[8..len - 4])
        .map_err(|_| BlobError::BufferTooSmall { len })?
        .len();
    buf[0..4].copy_from_slice(&BLOB_MAGIC);
    buf[4..6].copy_from_slice(&BLOB_VERSION.to_le_bytes());
    buf[6..8].copy_from_slice(&(n as u16).to_le_bytes());
    let crc = CRC32.checksum(&buf[..8 + n]);
    buf[8 + n..12 + n].copy_from_slice(&crc.to_le_bytes());
    Ok(&buf[..12 + n])
}

/// Decode and validate a blob. Checks, in order: length, magic, version, CRC, payload, the
/// fixed-point ranges, the physical bounds ([`super::bounds`]).
pub fn decode_blob(bytes: &[u8]) -> Result<Calibration, BlobError> {
    if bytes.len() < 12 {
        return Err(BlobError::Truncated {
            len: bytes.len(),
            needed: 12,
        });
    }
    let magic = [bytes[0], bytes[1], bytes[2], bytes[3]];
    if magic != BLOB_MAGIC {
        return Err(BlobError::BadMagic { found: magic });
    }
    let version = u16::from_le_bytes([bytes[4], bytes[5]]);
    if version != BLOB_VERSION {
        return Err(BlobError::WrongVersion {
            found: version,
            expected: BLOB_VERSION,
        });
    }
    let n = u16::from_le_bytes([bytes[6], bytes[7]]) as usize;
    if bytes.len() < 12 + n {
        return Err(BlobError::Truncated {
            len: bytes.len(),
            needed: 12 + n,
        });
    }
    let stored = u32::from_le_bytes([bytes[8 + n], bytes[9 + n], bytes[10 + n], bytes[11 + n]]);
    let computed = CRC32.checksum(&bytes[..8 + n]);
    if stored != computed {
        return Err(BlobError::CrcMismatch { stored, computed });
    }
    let (cal, rest): (Calibration, &[u8]) =
        postcard::take_from_bytes(&bytes[8..8 + n]).map_err(|_| BlobError::Malformed)?;
    if !rest.is_empty() {
        return Err(BlobError::Malformed);
    }
    cal.validate()?;
    cal.check_physics()?;
    Ok(cal)
}
