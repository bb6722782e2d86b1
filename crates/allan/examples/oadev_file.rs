//! Octave OADEV of a raw little-endian f64 file (one rate sample per 8 bytes): the program
//! docs/benchmarks.md times against AllanTools on the same file.
//!
//! `cargo run --release -p allan --features std --target host-tuple --example oadev_file -- FILE RATE_HZ`
use allan::{deviation, Stat, TauSet};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let (Some(path), Some(rate)) = (args.get(1), args.get(2).and_then(|r| r.parse::<f64>().ok()))
    else {
        eprintln!("usage: oadev_file FILE RATE_HZ");
        std::process::exit(2);
    };
    let bytes = std::fs::read(path).unwrap_or_else(|e| {
        eprintln!("{path}: {e}");
        std::process::exit(1);
    });
    let y: Vec<f64> = bytes
        .chunks_exact(8)
        .map(|c| f64::from_le_bytes(c.try_into().unwrap()))
        .collect();
    drop(bytes);
    let t = std::time::Instant::now();
    match deviation(&y, 1.0 / rate, Stat::Oadev, &TauSet::Octave) {
        Ok(rows) => {
            eprintln!(
                "{} samples, {} rows in {:.3} s",
                y.len(),
                rows.len(),
                t.elapsed().as_secs_f64()
            );
            for r in rows {
                println!("{:.6e} {:.10e} {}", r.tau, r.dev, r.n);
            }
        }
        Err(e) => {
            eprintln!("{path}: {e}");
            std::process::exit(1);
        }
    }
}
