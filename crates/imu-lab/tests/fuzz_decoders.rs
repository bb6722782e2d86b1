//! Fuzzed decoders: everything that parses bytes from outside — the CSV recording reader (and
//! the timing analysis behind it), the COBS/CRC frame decoder and its byte-stream reader, the
//! postcard messages inside valid frames, the TOML calibration file and the device calibration
//! blob — fed mutated copies of the inputs in `tests/fuzz/<target>/` and random bytes. None may
//! panic, and what they accept must survive its own round trip.
//!
//! * Every file of the corpus is replayed on every run (so a crash once found stays a
//!   regression test: add the input that crashed to its target's directory).
//! * Then a bounded proptest per target: [`CASES`] mutations (bit flips, byte inserts, deletes,
//!   duplicated chunks, truncations, splices of two inputs, and for text interesting tokens
//!   such as `NaN`, `1e309`, an empty field, a quote) — about a second each in CI.
//! * `fuzz/` at the top of the repository holds the same targets for cargo-fuzz (nightly,
//!   coverage-guided, for long runs on a developer's machine); its findings go into the same
//!   corpus.
//!
//! `cargo test -p imu-lab --test fuzz_decoders -- --ignored write_corpus` rewrites the corpus'
//! starting inputs (the generated ones; hand-made and found ones are left alone).
use std::path::{Path, PathBuf};

use imu_proto::{
    AllanLevel, AllanTable, CalSource, CalStatus, Channel, Event, ImuSample, MagSample, Reply,
    Request, SampleBatch, Scales, Sensor, StreamMode,
};
use proptest::prelude::*;

/// Mutated inputs per target and run.
const CASES: u32 = 4000;

fn corpus_dir(target: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fuzz")
        .join(target)
}

/// Extension of a file holding many inputs: repeated (u32 LE length, bytes).
const BUNDLE: &str = "bundle";

fn corpus(target: &str) -> Vec<Vec<u8>> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(corpus_dir(target))
        .unwrap_or_else(|e| panic!("corpus of {target}: {e}"))
        .map(|e| e.unwrap().path())
        .collect();
    files.sort();
    assert!(!files.is_empty(), "corpus of {target} is empty");
    let mut out = Vec::new();
    for p in files {
        let bytes = std::fs::read(&p).unwrap();
        if p.extension().is_some_and(|e| e == BUNDLE) {
            let mut rest = bytes.as_slice();
            while rest.len() >= 4 {
                let n = u32::from_le_bytes(rest[..4].try_into().unwrap()) as usize;
                let end = (4 + n).min(rest.len());
                out.push(rest[4..end].to_vec());
                rest = &rest[end..];
            }
        } else {
            out.push(bytes);
        }
    }
    out
}

include!("fuzz/targets.rs");

// ---- mutations ----

#[derive(Debug, Clone)]
enum Mutation {
    Flip(usize, u8),
    Insert(usize, u8),
    Delete(usize),
    Duplicate(usize, usize),
    Truncate(usize),
    Splice(usize, usize),
    Token(usize, usize),
}

/// Tokens that break number and CSV parsers.
const TOKENS: [&str; 14] = [
    "NaN",
    "inf",
    "-inf",
    "1e309",
    "-0",
    "",
    "\"",
    ",",
    "\n",
    "\r\n",
    "\u{feff}",
    "9e15",
    "18446744073709551616",
    "t",
];

fn mutation() -> impl Strategy<Value = Mutation> {
    let pos = any::<usize>();
    prop_oneof![
        (pos, 0u8..8).prop_map(|(p, b)| Mutation::Flip(p, b)),
        (pos, any::<u8>()).prop_map(|(p, b)| Mutation::Insert(p, b)),
        pos.prop_map(Mutation::Delete),
        (pos, 1usize..64).prop_map(|(p, n)| Mutation::Duplicate(p, n)),
        pos.prop_map(Mutation::Truncate),
        (any::<usize>(), pos).prop_map(|(o, p)| Mutation::Splice(o, p)),
        (pos, 0..TOKENS.len()).prop_map(|(p, t)| Mutation::Token(p, t)),
    ]
}

fn mutate(input: &[u8], others: &[Vec<u8>], muts: &[Mutation]) -> Vec<u8> {
    let mut v = input.to_vec();
    for m in muts {
        let at = |p: usize, len: usize| if len == 0 { 0 } else { p % (len + 1) };
        match *m {
            Mutation::Flip(p, b) if !v.is_empty() => {
                let i = p % v.len();
                v[i] ^= 1 << b;
            }
            Mutation::Insert(p, b) => {
                let i = at(p, v.len());
                v.insert(i, b);
            }
            Mutation::Delete(p) if !v.is_empty() => {
                v.remove(p % v.len());
            }
            Mutation::Duplicate(p, n) if !v.is_empty() => {
                let i = p % v.len();
                let chunk: Vec<u8> = v[i..(i + n).min(v.len())].to_vec();
                v.splice(i..i, chunk);
            }
            Mutation::Truncate(p) => {
                let i = at(p, v.len());
                v.truncate(i);
            }
            Mutation::Splice(o, p) => {
                let other = &others[o % others.len()];
                let i = at(p, v.len());
                let j = at(p / 7, other.len());
                v.truncate(i);
                v.extend_from_slice(&other[j..]);
            }
            Mutation::Token(p, t) => {
                let i = at(p, v.len());
                v.splice(i..i, TOKENS[t].bytes());
            }
            _ => {}
        }
        v.truncate(1 << 16);
    }
    v
}

fn input(target: &'static str) -> impl Strategy<Value = Vec<u8>> {
    let c = corpus(target);
    let n = c.len();
    prop_oneof![
        8 => (0..n, prop::collection::vec(mutation(), 1..8))
            .prop_map(move |(i, m)| mutate(&c[i], &c, &m)),
        1 => prop::collection::vec(any::<u8>(), 0..600),
    ]
}

fn config() -> ProptestConfig {
    ProptestConfig {
        cases: CASES,
        // Found inputs go into the corpus by hand (module docs), not into a side file.
        failure_persistence: None,
        ..ProptestConfig::default()
    }
}

macro_rules! fuzz_target {
    ($name:ident, $replay:ident, $dir:literal, $f:ident) => {
        #[test]
        fn $replay() {
            for input in corpus($dir) {
                $f(&input);
            }
        }

        proptest! {
            #![proptest_config(config())]
            #[test]
            fn $name(bytes in input($dir)) {
                $f(&bytes);
            }
        }
    };
}

fuzz_target!(fuzz_csv, replay_csv, "csv", csv_target);
fuzz_target!(fuzz_frame, replay_frame, "frame", frame_target);
fuzz_target!(fuzz_payload, replay_payload, "payload", payload_target);
fuzz_target!(fuzz_calfile, replay_calfile, "calfile", calfile_target);
fuzz_target!(fuzz_blob, replay_blob, "blob", blob_target);

/// The generated frames and payloads decode: the mutations start from inputs that reach the
/// message decoders, not only the CRC check.
#[test]
fn generated_inputs_are_valid_messages() {
    for (dir, wrap) in [("frame", false), ("payload", true)] {
        for e in std::fs::read_dir(corpus_dir(dir)).unwrap() {
            let p = e.unwrap().path();
            let name = p.file_name().unwrap().to_string_lossy().to_string();
            let bytes = std::fs::read(&p).unwrap();
            let mut f = if wrap { framed(&bytes) } else { bytes };
            if name.starts_with("device_") {
                decode::<DeviceMsg>(&mut f).unwrap_or_else(|e| panic!("{dir}/{name}: {e:?}"));
            } else if name.starts_with("host_") {
                decode::<HostFrame>(&mut f).unwrap_or_else(|e| panic!("{dir}/{name}: {e:?}"));
            }
        }
    }
    assert!(decode_blob(&std::fs::read(corpus_dir("blob").join("fitted.bin")).unwrap()).is_ok());
}

// ---- the starting corpus ----

fn batch() -> SampleBatch {
    let mut b = SampleBatch {
        calibrated: false,
        scales: Scales {
            accel: 0.000598,
            gyro: 0.0076336,
            mag: 0.0333,
            temp: 1.0 / 340.0,
            temp_offset: 36.53,
        },
        imu: imu_proto::Vec::new(),
        mag: imu_proto::Vec::new(),
    };
    for k in 0..5u32 {
        let gap = if k == 3 { 32 } else { 0 };
        b.imu
            .push(ImuSample {
                seq: 100 + k + gap,
                t_us: 1_000_000 + 1000 * u64::from(k + gap),
                accel: [12, -812, 15032],
                gyro: [-447, 156, -86 + k as i32],
                temp: Some(-1500),
            })
            .unwrap();
    }
    b.mag
        .push(MagSample {
            seq: 7,
            t_us: 1_000_500,
            mag: [-4096, 300, 32767],
        })
        .unwrap();
    b
}

fn messages() -> (Vec<DeviceMsg>, Vec<HostFrame>) {
    let level = AllanLevel {
        m: 16,
        stride: 2,
        n2: 1000,
        sum2: 123_456_789_012_345,
        n3: 990,
        sum3: 99,
    };
    let mut levels = imu_proto::Vec::new();
    levels.push(level).unwrap();
    let table = AllanTable {
        channel: Channel::Gz,
        snapshot: 3,
        t_us: 2_000_000,
        tau0_ns: 1_000_000,
        scale: 0.0076336,
        pushed: 1_000_000,
        gaps: 2,
        levels,
    };
    let mut blob = imu_proto::Vec::new();
    let mut buf = [0u8; 512];
    let cal = CalFile::default().to_device().unwrap();
    blob.extend_from_slice(encode_blob(&cal, &mut buf).unwrap())
        .unwrap();
    let dev = vec![
        DeviceMsg::Samples(batch()),
        DeviceMsg::Table(table),
        DeviceMsg::Event(Event::SensorLost {
            sensor: Sensor::Mag,
            t_us: 5,
        }),
        DeviceMsg::Reply {
            id: 3,
            reply: Reply::Calibration {
                blob: blob.clone(),
                status: CalStatus {
                    source: CalSource::Flash,
                    fault: None,
                },
            },
        },
        DeviceMsg::Reply {
            id: 4,
            reply: Reply::Ok,
        },
        DeviceMsg::Orientation(
            [imu_proto::AhrsState::Tracking, imu_proto::AhrsState::MagDip]
                .iter()
                .enumerate()
                .map(|(i, &state)| imu_proto::Orientation {
                    seq: 100 + i as u32,
                    t_us: 500_000 + 5_000 * i as u64,
                    q: [0.9, 0.1, -0.2, 0.3],
                    roll_deg: 12.5,
                    pitch_deg: -3.25,
                    heading_deg: 271.0,
                    state,
                })
                .collect(),
        ),
    ];
    let host = vec![
        HostFrame {
            id: 1,
            req: Request::SetCalibration {
                blob,
                persist: true,
            },
        },
        HostFrame {
            id: 2,
            req: Request::SetMode(StreamMode::Raw),
        },
        HostFrame {
            id: 3,
            req: Request::SetIntervals {
                status_ms: 1000,
                tables_ms: 0,
            },
        },
        HostFrame {
            id: 4,
            req: Request::SetOrientation {
                declination_cdeg: -350,
                reference: Some(imu_proto::MagReference {
                    field_nt: 48_000,
                    dip_cdeg: 6_000,
                }),
            },
        },
    ];
    (dev, host)
}

/// The generated starting inputs (see the module docs for how to rewrite them).
#[test]
#[ignore]
fn write_corpus() {
    let put = |target: &str, name: &str, bytes: &[u8]| {
        let d = corpus_dir(target);
        std::fs::create_dir_all(&d).unwrap();
        std::fs::write(d.join(name), bytes).unwrap();
    };
    // CSV: the contract with gaps and a missing temperature, a raw file with metadata lines,
    // BOM + CRLF + blanks, bursty host stamps, quoting.
    let mut w = contract::Writer::new(
        Vec::new(),
        &contract::HEADER,
        contract::WriteOptions {
            time_decimals: Some(6),
            f32_values: true,
        },
    )
    .unwrap();
    for i in 0..12 {
        let gap = if i == 7 { 32.0 } else { 0.0 };
        let t = 1.0 + 0.001 * (i as f64 + if i >= 7 { 32.0 } else { 0.0 });
        let temp = if i % 5 == 4 { None } else { Some(25.5) };
        w.row(&[
            Some(t),
            Some(gap),
            Some(0.1),
            Some(-0.2),
            Some(9.8),
            Some(0.01 * i as f64),
            Some(-0.02),
            Some(0.03),
            Some(20.0),
            Some(-3.0),
            Some(40.0),
            temp,
        ])
        .unwrap();
    }
    put("csv", "contract.csv", &w.finish().unwrap());
    put(
        "csv",
        "raw_metadata.csv",
        b"Fs,100\nax,ay,az,gx,gy,gz\n-12,-812,15032,-447,156,-86\n-10,-815,15030,-446,155,-85\n",
    );
    put(
        "csv",
        "bom_crlf.csv",
        "\u{feff} t , gx ,temp\r\n0.00, 1.5,\r\n0.01 ,2.5, 25\r\n0.02,3.5,25.1\r\n".as_bytes(),
    );
    put(
        "csv",
        "bursty.csv",
        b"t,x\n0.0000,1\n0.0009,2\n0.0018,3\n0.0440,4\n0.0449,5\n0.0458,6\n0.0900,7\n0.0909,8\n",
    );
    put(
        "csv",
        "quoted.csv",
        b"\"t\",\"gx\",note\n0,1,\"a, b\"\n0.01,2,\"\"\"q\"\"\"\n0.02,3,x\n",
    );
    let (dev, host) = messages();
    for (i, m) in dev.iter().enumerate() {
        let f = encode(m).unwrap();
        put("frame", &format!("device_{i}.bin"), &f[..f.len() - 1]);
        put("payload", &format!("device_{i}.bin"), &postcard_of(m));
    }
    for (i, m) in host.iter().enumerate() {
        let f = encode(m).unwrap();
        put("frame", &format!("host_{i}.bin"), &f[..f.len() - 1]);
        put("payload", &format!("host_{i}.bin"), &postcard_of(m));
    }
    let f = CalFile::default();
    put("calfile", "default.toml", f.to_toml().as_bytes());
    let mut g = f.clone();
    g.accel.offset = [0.1, -0.2, 0.3];
    g.gyro.misalignment_deg = [0.1, -0.2, 0.3, 0.4, -0.5, 0.6];
    g.mag.soft_iron = [[1.1, 0.05, 0.0], [0.05, 0.9, 0.02], [0.0, 0.02, 1.0]];
    put("calfile", "fitted.toml", g.to_toml().as_bytes());
    let mut buf = [0u8; 512];
    put(
        "blob",
        "default.bin",
        encode_blob(&f.to_device().unwrap(), &mut buf).unwrap(),
    );
    put(
        "blob",
        "fitted.bin",
        encode_blob(&g.to_device().unwrap(), &mut buf).unwrap(),
    );
}

/// Bundle the smallest inputs of a cargo-fuzz corpus (`fuzz/corpus/<target>`, after
/// `cargo fuzz cmin`) into `tests/fuzz/<target>/libfuzzer.bundle`, at most 64 KiB each:
/// `cargo test -p imu-lab --test fuzz_decoders -- --ignored bundle_libfuzzer_corpus`.
#[test]
#[ignore]
fn bundle_libfuzzer_corpus() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fuzz/corpus");
    for target in ["csv", "frame", "payload", "calfile", "blob"] {
        let Ok(dir) = std::fs::read_dir(root.join(target)) else {
            continue;
        };
        let mut inputs: Vec<Vec<u8>> = dir
            .map(|e| std::fs::read(e.unwrap().path()).unwrap())
            .collect();
        inputs.sort_by(|a, b| a.len().cmp(&b.len()).then(a.cmp(b)));
        let mut out = Vec::new();
        for i in inputs {
            if out.len() + 4 + i.len() > 64 << 10 {
                break;
            }
            out.extend_from_slice(&(i.len() as u32).to_le_bytes());
            out.extend_from_slice(&i);
        }
        std::fs::write(corpus_dir(target).join(format!("libfuzzer.{BUNDLE}")), out).unwrap();
    }
}

/// The postcard bytes of a message: its frame's content between the version byte and the CRC.
fn postcard_of<T: serde::Serialize>(m: &T) -> Vec<u8> {
    let mut f = encode(m).unwrap();
    f.pop();
    let n = cobs::decode_in_place(&mut f).unwrap();
    f[1..n - 4].to_vec()
}
