//! The calibration blob: round trip, and every kind of corruption gives its own clear error.
use imu_cal::device::*;

/// A plausible calibration fitted for an MPU-6050 at ±4 g, ±250 °/s and a QMC5883L at ±2 G.
fn sample() -> Calibration {
    let m = [
        [1.01, 0.002, -0.001],
        [0.003, 0.98, 0.0],
        [-0.01, 0.004, 1.02],
    ];
    // The accelerometer's model is lower-triangular.
    let lower = [[1.01, 0.0, 0.0], [0.003, 0.98, 0.0], [-0.01, 0.004, 1.02]];
    let acc = Affine::from_float(Sensor::Accel, lower, [120.5, -340.25, 800.0]).unwrap();
    let gyr =
        GyroCorrection::from_float(m, [-210.0, 38.0, 242.0], [0.01, -0.02, 0.005], -2300).unwrap();
    let mag = Affine::from_float(Sensor::Mag, m, [-927.3, -56.4, 167.7]).unwrap();
    let fitted = Fitted::new(
        ImuPart::Mpu6050,
        MagPart::Qmc5883l,
        [8192.0 / 9.80665, 131.0, 120.0],
    )
    .unwrap();
    Calibration::fitted(acc, gyr, mag, fitted).unwrap()
}

#[test]
fn round_trip() {
    let cal = sample();
    let mut buf = [0u8; MAX_BLOB_LEN];
    let blob = encode_blob(&cal, &mut buf).unwrap().to_vec();
    assert_eq!(&blob[..4], b"PCAL");
    assert_eq!(decode_blob(&blob).unwrap(), cal);
    let mut id = [0u8; MAX_BLOB_LEN];
    let b = encode_blob(&Calibration::identity(), &mut id).unwrap();
    assert_eq!(decode_blob(b).unwrap(), Calibration::identity());
}

#[test]
fn every_single_bit_flip_is_rejected() {
    let mut buf = [0u8; MAX_BLOB_LEN];
    let blob = encode_blob(&sample(), &mut buf).unwrap().to_vec();
    for byte in 0..blob.len() {
        for bit in 0..8 {
            let mut b = blob.clone();
            b[byte] ^= 1 << bit;
            assert!(
                decode_blob(&b).is_err(),
                "flip byte {byte} bit {bit} accepted"
            );
        }
    }
}

#[test]
fn errors_name_the_fault() {
    let mut buf = [0u8; MAX_BLOB_LEN];
    let blob = encode_blob(&sample(), &mut buf).unwrap().to_vec();
    assert_eq!(
        decode_blob(&blob[..5]),
        Err(BlobError::Truncated { len: 5, needed: 12 })
    );
    assert!(matches!(
        decode_blob(&blob[..blob.len() - 1]),
        Err(BlobError::Truncated { .. })
    ));
    let mut b = blob.clone();
    b[0] = b'X';
    assert!(matches!(decode_blob(&b), Err(BlobError::BadMagic { .. })));
    for v in [1u8, 5] {
        let mut b = blob.clone();
        b[4] = v;
        assert_eq!(
            decode_blob(&b),
            Err(BlobError::WrongVersion {
                found: v.into(),
                expected: BLOB_VERSION
            })
        );
    }
    let mut b = blob.clone();
    b[10] ^= 0x40;
    assert!(matches!(
        decode_blob(&b),
        Err(BlobError::CrcMismatch { .. })
    ));
    assert!(format!("{}", decode_blob(&b).unwrap_err()).contains("CRC"));
    // Too small an output buffer.
    let mut small = [0u8; 20];
    assert!(matches!(
        encode_blob(&sample(), &mut small),
        Err(BlobError::BufferTooSmall { .. })
    ));
}

#[test]
fn valid_crc_but_out_of_range_payload_is_rejected() {
    // Hand-build a payload whose matrix row exceeds the fixed-point range, with a correct CRC:
    // the decoder must still refuse it (range validation after the CRC).
    let mut buf = [0u8; MAX_BLOB_LEN];
    let blob = encode_blob(&Calibration::identity(), &mut buf)
        .unwrap()
        .to_vec();
    // Identity payload: first i32 is 1<<24 as a zig-zag varint (5 bytes: 0x80 0x80 0x80 0x10).
    let n = u16::from_le_bytes([blob[6], blob[7]]) as usize;
    let mut payload = blob[8..8 + n].to_vec();
    assert_eq!(&payload[..4], &[0x80, 0x80, 0x80, 0x10]);
    payload[3] = 0x50; // 5<<24: gain 5 > 4
    let mut b = blob[..8].to_vec();
    b.extend_from_slice(&payload);
    let crc = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC).checksum(&b);
    b.extend_from_slice(&crc.to_le_bytes());
    assert_eq!(
        decode_blob(&b),
        Err(BlobError::OutOfRange {
            sensor: Sensor::Accel,
            what: Quantity::MatrixRow,
            axis: 0
        })
    );
}

mod fuzz {
    use super::*;
    use proptest::prelude::*;

    fn with_crc(mut b: Vec<u8>) -> Vec<u8> {
        let crc = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC).checksum(&b);
        b.extend_from_slice(&crc.to_le_bytes());
        b
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(3000))]
        /// Arbitrary bytes never panic the decoder.
        #[test]
        fn arbitrary_bytes_never_panic(b in proptest::collection::vec(any::<u8>(), 0..300)) {
            let _ = decode_blob(&b);
        }

        /// A correct header and CRC around an arbitrary payload: the decoder either refuses it
        /// or returns a calibration that passes validation and whose every apply path is safe
        /// at the input extremes (no overflow panic in this debug build).
        #[test]
        fn arbitrary_payload_with_valid_crc(
            p in proptest::collection::vec(any::<u8>(), 0..240),
            version in 2u16..=BLOB_VERSION,
        ) {
            let mut b = b"PCAL".to_vec();
            b.extend_from_slice(&version.to_le_bytes());
            b.extend_from_slice(&(p.len() as u16).to_le_bytes());
            b.extend_from_slice(&p);
            if let Ok(cal) = decode_blob(&with_crc(b)) {
                prop_assert!(cal.validate().is_ok());
                for v in [i16::MIN, i16::MAX] {
                    let _ = cal.apply_accel([v, -v.saturating_add(1), v]);
                    let _ = cal.apply_gyro([v, v, v], v);
                    let _ = cal.apply_mag([v, v, i16::MIN]);
                }
            }
        }
    }
}
