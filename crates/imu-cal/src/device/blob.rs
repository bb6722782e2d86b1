//! The calibration blob: the bytes the host sends and the device persists (layout in the
//! module docs of [`super`]).
use serde::Deserialize;

use super::plausible::{Fitted, ImuPart, MagPart};
use super::{Affine, BlobError, Calibration, GyroCorrection};

/// Magic bytes at the start of every calibration blob.
pub const BLOB_MAGIC: [u8; 4] = *b"PCAL";
/// The blob format version this build writes. Version 4 records the parts and ranges
/// ([`Fitted`]), the magnetometer's range in µT; version 3 (the same, that range in gauss) and
/// version 2 (sensitivities only) are still read, a version 2's parts taken to be the MPU-6050
/// and QMC5883L, the only ones a version-2 host wrote blobs for.
pub const BLOB_VERSION: u16 = 4;
/// The oldest version read.
const OLDEST_READ: u16 = 2;
/// Upper bound of an encoded blob (header + worst-case postcard varints + CRC).
/// Payload worst case: three affine parts of 12 i32 varints (≤ 5 bytes each), 3 more i32 and
/// one i16 (≤ 3 bytes) for the gyro temperature term, and what it was fitted for: 1 (option)
/// + 2 parts (1 each) + 3 ranges (u16, ≤ 3 each) + 3 sensitivities (4 each).
pub const MAX_BLOB_LEN: usize = 8 + (3 * 12 * 5 + 3 * 5 + 3) + (1 + 2 + 9 + 12) + 4;

/// The version-2 payload: the corrections and the sensitivities, no parts.
#[derive(Deserialize)]
struct PayloadV2 {
    accel: Affine,
    gyro: GyroCorrection,
    mag: Affine,
    lsb_per_unit: Option<[f32; 3]>,
}

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

/// Decode and validate a blob. Checks, in order: length, magic, version, CRC, payload (and for
/// version 3 that the recorded ranges are the sensitivities'), the fixed-point ranges, the
/// datasheet bounds ([`super::plausible`]).
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
    if !(OLDEST_READ..=BLOB_VERSION).contains(&version) {
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
    let payload = &bytes[8..8 + n];
    let cal = if version >= 3 {
        let mut cal: Calibration = whole(payload)?;
        if version == 3 {
            if let Some(f) = cal.fitted.as_mut() {
                f.ranges.mag_ut = f
                    .ranges
                    .mag_ut
                    .checked_mul(100)
                    .ok_or(BlobError::Malformed)?;
            }
        }
        // The recorded ranges must be the ones the sensitivities give.
        if let Some(f) = cal.fitted_for() {
            let again =
                Fitted::new(f.imu, f.mag, f.lsb_per_unit).map_err(|_| BlobError::Malformed)?;
            if again.ranges != f.ranges {
                return Err(BlobError::Malformed);
            }
        }
        cal
    } else {
        let old: PayloadV2 = whole(payload)?;
        let fitted = match old.lsb_per_unit {
            None => None,
            Some(lsb) => Some(Fitted {
                parts_assumed: true,
                ..Fitted::new(ImuPart::Mpu6050, MagPart::Qmc5883l, lsb)?
            }),
        };
        Calibration::assemble(old.accel, old.gyro, old.mag, fitted)?
    };
    cal.validate()?;
    cal.check_physics()?;
    Ok(cal)
}

/// A postcard value that takes the whole of `payload`.
fn whole<'a, T: Deserialize<'a>>(payload: &'a [u8]) -> Result<T, BlobError> {
    let (v, rest): (T, &[u8]) =
        postcard::take_from_bytes(payload).map_err(|_| BlobError::Malformed)?;
    if !rest.is_empty() {
        return Err(BlobError::Malformed);
    }
    Ok(v)
}
