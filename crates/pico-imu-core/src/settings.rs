//! The attitude filter's host settings as the device keeps them in flash (a record beside the
//! calibration; src/storage.rs writes and reads it): the codec and its checks, no I/O.
use imu_proto::{MagReference, Vec};

/// The attitude filter's settings a host sets: the declination (0.01°) and the expected field
/// (`None`: learnt by the device).
pub type OrientationSetting = (i16, Option<MagReference>);

/// The settings a device without a stored record uses: no declination, a learnt reference.
pub const DEFAULT_ORIENTATION: OrientationSetting = (0, None);

/// Format of the orientation record.
const ORIENTATION_FORMAT: u8 = 1;

/// The orientation record: its format (1), the declination (i16 LE, 0.01°), then 0 for a learnt
/// reference or 1, the field (u32 LE, nT) and the dip (i16 LE, 0.01°).
pub fn encode_orientation((declination_cdeg, reference): OrientationSetting) -> Vec<u8, 10> {
    let mut v = Vec::new();
    let _ = v.push(ORIENTATION_FORMAT);
    let _ = v.extend_from_slice(&declination_cdeg.to_le_bytes());
    match reference {
        None => {
            let _ = v.push(0);
        }
        Some(r) => {
            let _ = v.push(1);
            let _ = v.extend_from_slice(&r.field_nt.to_le_bytes());
            let _ = v.extend_from_slice(&r.dip_cdeg.to_le_bytes());
        }
    }
    v
}

/// Why an orientation record was not used.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum RecordError {
    /// Another format than [`encode_orientation`]'s (the byte found).
    Format(u8),
    /// Shorter or longer than its format says.
    Length(usize),
    /// A value outside what `SetOrientation` accepts.
    OutOfRange,
}

/// The settings of an orientation record, checked as `SetOrientation` checks them.
pub fn decode_orientation(b: &[u8]) -> Result<OrientationSetting, RecordError> {
    let (&format, rest) = b.split_first().ok_or(RecordError::Length(0))?;
    if format != ORIENTATION_FORMAT {
        return Err(RecordError::Format(format));
    }
    let setting = match rest {
        [d0, d1, 0] => (i16::from_le_bytes([*d0, *d1]), None),
        [d0, d1, 1, f0, f1, f2, f3, p0, p1] => (
            i16::from_le_bytes([*d0, *d1]),
            Some(MagReference {
                field_nt: u32::from_le_bytes([*f0, *f1, *f2, *f3]),
                dip_cdeg: i16::from_le_bytes([*p0, *p1]),
            }),
        ),
        _ => return Err(RecordError::Length(b.len())),
    };
    if orientation_in_range(setting) {
        Ok(setting)
    } else {
        Err(RecordError::OutOfRange)
    }
}

/// What `SetOrientation` accepts: declination within ±180°, field 1–1000 µT, dip within ±90°.
pub(crate) fn orientation_in_range((declination_cdeg, reference): OrientationSetting) -> bool {
    (-18_000..=18_000).contains(&declination_cdeg)
        && reference.is_none_or(|r| {
            (1_000..=1_000_000).contains(&r.field_nt) && (-9_000..=9_000).contains(&r.dip_cdeg)
        })
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// Settings drawn from a generator seeded by the clock (a fresh realisation every run):
    /// every declination and reference `SetOrientation` accepts, and learnt references.
    pub(crate) fn settings(n: usize) -> std::vec::Vec<OrientationSetting> {
        let mut rng = crate::test_util::clock_keyed();
        let mut next = move |lo: i64, hi: i64| lo + (rng() % (hi - lo + 1) as u64) as i64;
        (0..n)
            .map(|_| {
                let decl = next(-18_000, 18_000) as i16;
                let reference = (next(0, 2) > 0).then(|| MagReference {
                    field_nt: next(1_000, 1_000_000) as u32,
                    dip_cdeg: next(-9_000, 9_000) as i16,
                });
                (decl, reference)
            })
            .collect()
    }

    /// The record reads back as written, and a damaged one is refused with its reason.
    #[test]
    fn orientation_records_round_trip_and_bad_ones_are_refused() {
        for s in settings(500) {
            assert_eq!(decode_orientation(&encode_orientation(s)), Ok(s));
        }
        let good = encode_orientation((150, None));
        assert_eq!(decode_orientation(&[]), Err(RecordError::Length(0)));
        assert_eq!(decode_orientation(&good[..3]), Err(RecordError::Length(3)));
        let mut wrong = good.clone();
        wrong[0] = 7;
        assert_eq!(decode_orientation(&wrong), Err(RecordError::Format(7)));
        let far = encode_orientation((18_001, None));
        assert_eq!(decode_orientation(&far), Err(RecordError::OutOfRange));
        let weak = MagReference {
            field_nt: 999,
            dip_cdeg: 0,
        };
        let r = encode_orientation((0, Some(weak)));
        assert_eq!(decode_orientation(&r), Err(RecordError::OutOfRange));
        let mut tail = encode_orientation((0, None));
        let _ = tail.push(0);
        assert_eq!(decode_orientation(&tail), Err(RecordError::Length(5)));
    }
}
