// The fuzz targets, shared by the stable harness (crates/imu-lab/tests/fuzz_decoders.rs) and
// cargo-fuzz (fuzz/fuzz_targets/*.rs), which both `include!` this file: each target must return
// without panicking whatever the bytes, and what a decoder accepts must survive its own round
// trip.
use imu_cal::device::{decode_blob, encode_blob};
use imu_cal::file::CalFile;
use imu_proto::csv::{self as contract, ReadOptions};
use imu_proto::{
    cobs_encode, decode, DeviceMsg, FrameEncoder, FrameReader, HostFrame, MAX_FRAME, MAX_PAYLOAD,
    PROTOCOL_VERSION,
};

/// The CSV reader on a file's bytes, as every subcommand opens it, then the timing analysis
/// of its `t` column.
pub fn csv_target(bytes: &[u8]) {
    for skip in [0usize, 1] {
        let opts = ReadOptions {
            skip_lines: skip,
            renames: vec![("x".into(), "gx".into())],
        };
        let Ok(mut r) = contract::Reader::new(bytes, "fuzz.csv", &opts) else {
            continue;
        };
        let Ok(names) = r.select(&["gx"], &["temp", "ax"]) else {
            continue;
        };
        let mut row = vec![0.0; names.len()];
        let ti = names.iter().position(|n| n == "t");
        let gi = names.iter().position(|n| n == "gap_before");
        let (mut t, mut g) = (Vec::new(), Vec::new());
        while let Ok(true) = r.next_row(&mut row) {
            for (n, v) in names.iter().zip(&row) {
                assert!(v.is_finite() || (n == "temp" && v.is_nan()), "{n} = {v}");
            }
            if let Some(i) = ti {
                t.push(row[i]);
            }
            if let Some(i) = gi {
                assert!(row[i] >= 0.0 && row[i].fract() == 0.0);
                g.push(row[i]);
            }
        }
        if !t.is_empty() {
            if let Ok(tm) = contract::timing(&t, gi.map(|_| g.as_slice())) {
                let segs = tm.segments();
                assert_eq!(segs.first().map(|s| s.start), Some(0));
                assert_eq!(segs.last().map(|s| s.end), Some(t.len()));
                assert!(tm.period_s > 0.0 && tm.period_s.is_finite(), "{tm:?}");
                let _ = tm.describe();
            }
        }
    }
}

/// Encode `msg`; Err when the encoder refuses it.
pub fn encode<T: serde::Serialize>(msg: &T) -> Result<Vec<u8>, String> {
    FrameEncoder::new()
        .encode_vec(msg)
        .map_err(|e| format!("{e:?}"))
}

/// Decoding, re-encoding and decoding again gives the same bytes (f32 NaN compares unequal,
/// bytes do not).
fn stable<T: serde::Serialize + serde::de::DeserializeOwned>(msg: &T) {
    let a = encode(msg).expect("a decoded message encodes again");
    let mut f = a.clone();
    f.pop();
    let back: T = decode(&mut f).expect("a re-encoded message decodes");
    assert_eq!(encode(&back).unwrap(), a, "round trip changed the bytes");
}

/// One frame's bytes (delimiter excluded) through the in-place decoder for both directions,
/// and the same bytes as a stream through the incremental reader.
pub fn frame_target(bytes: &[u8]) {
    let mut f = bytes.to_vec();
    if let Ok(m) = decode::<DeviceMsg>(&mut f) {
        stable(&m);
    }
    let mut f = bytes.to_vec();
    if let Ok(m) = decode::<HostFrame>(&mut f) {
        stable(&m);
    }
    let mut r = FrameReader::<{ MAX_FRAME }>::new();
    for &b in bytes.iter().chain(&[0]) {
        if let Some(Ok(m)) = r.push::<DeviceMsg>(b) {
            stable(&m);
        }
    }
    let s = r.stats();
    assert!(s.ok + s.rejected() <= bytes.len() as u32 + 1);
}

/// Wrap postcard bytes in a valid frame (version, CRC-32/ISO-HDLC, COBS), so that mutations
/// reach the message decoders instead of failing the CRC.
pub fn framed(payload: &[u8]) -> Vec<u8> {
    let mut content = vec![PROTOCOL_VERSION];
    content.extend_from_slice(&payload[..payload.len().min(MAX_PAYLOAD - 5)]);
    let crc = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC).checksum(&content);
    content.extend_from_slice(&crc.to_le_bytes());
    let mut out = vec![0u8; MAX_FRAME];
    let n = cobs_encode(&content, &mut out).expect("fits");
    out.truncate(n);
    out
}

pub fn payload_target(bytes: &[u8]) {
    frame_target(&framed(bytes));
}

/// The TOML calibration file: parsed, converted for the device, written and parsed again.
pub fn calfile_target(bytes: &[u8]) {
    let text = String::from_utf8_lossy(bytes);
    if let Ok(f) = CalFile::from_toml(&text) {
        let _ = f.to_device();
        let again = CalFile::from_toml(&f.to_toml()).expect("a written file reads back");
        assert_eq!(again.to_toml(), f.to_toml());
    }
}

/// The device calibration blob: decoded, and a decoded blob encodes to one that decodes.
pub fn blob_target(bytes: &[u8]) {
    if let Ok(cal) = decode_blob(bytes) {
        let mut buf = [0u8; 512];
        let b = encode_blob(&cal, &mut buf).expect("a decoded calibration encodes");
        let again = decode_blob(b).expect("and decodes");
        let mut buf2 = [0u8; 512];
        assert_eq!(encode_blob(&again, &mut buf2).unwrap(), b);
    }
}
