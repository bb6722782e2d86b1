//! Writes the benchmark inputs of docs/benchmarks.md, reproducibly (xorshift32 from a fixed start):
//!
//! * `gen_rate f64 FILE N` — N little-endian f64 rate samples (white noise plus a slow
//!   square-wave bias, deg/s-like magnitudes), for `oadev_file` and AllanTools;
//! * `gen_rate csv FILE N` — the same shape as integer counts in a one-column CSV (`gz`), for
//!   `imu-lab adev --bounded`.
use std::io::{BufWriter, Write};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let (Some(kind), Some(path), Some(n)) = (
        args.get(1),
        args.get(2),
        args.get(3).and_then(|n| n.parse::<u64>().ok()),
    ) else {
        eprintln!("usage: gen_rate f64|csv FILE N");
        std::process::exit(2);
    };
    let mut out =
        BufWriter::with_capacity(1 << 20, std::fs::File::create(path).expect("create output"));
    let mut s = 0x9e37_79b9u32;
    let mut next = move || {
        s ^= s << 13;
        s ^= s >> 17;
        s ^= s << 5;
        s
    };
    if kind == "csv" {
        writeln!(out, "gz").unwrap();
    }
    for i in 0..n {
        // Sum of 4 uniforms ≈ Gaussian, ±512 counts, plus a ±8-count bias switching every 100 s.
        let noise: i64 = (0..4).map(|_| (next() >> 22) as i64 - 512).sum::<i64>() / 2;
        let bias = if (i / 100_000).is_multiple_of(2) {
            8
        } else {
            -8
        };
        let v = noise + bias;
        match kind.as_str() {
            "f64" => out
                .write_all(&(v as f64 * 0.0076336).to_le_bytes())
                .unwrap(),
            _ => writeln!(out, "{v}").unwrap(),
        }
    }
    out.flush().unwrap();
}
