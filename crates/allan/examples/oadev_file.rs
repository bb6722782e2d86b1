//! Octave OADEV of a raw little-endian f64 file (one rate sample per 8 bytes): the program
//! docs/benchmarks.md times against AllanTools on the same file.
//!
//! `cargo run --release -p allan --features std --target host-tuple --example oadev_file -- FILE RATE_HZ`
use allan::{deviation, Stat, TauSet};
use std::io::Read;

/// The samples of a raw little-endian f64 file, read in 1 MiB pieces straight into the
/// sample vector (no second copy of the file in memory; a trailing partial sample is ignored).
fn read_f64(path: &str) -> std::io::Result<Vec<f64>> {
    let mut file = std::fs::File::open(path)?;
    let mut y = Vec::with_capacity(file.metadata()?.len() as usize / 8);
    let mut piece = Vec::with_capacity(1 << 20);
    loop {
        piece.clear();
        if (&mut file).take(1 << 20).read_to_end(&mut piece)? == 0 {
            return Ok(y);
        }
        y.extend(
            piece
                .chunks_exact(8)
                .map(|c| f64::from_le_bytes(c.try_into().unwrap())),
        );
    }
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let (Some(path), Some(rate)) = (args.get(1), args.get(2).and_then(|r| r.parse::<f64>().ok()))
    else {
        eprintln!("usage: oadev_file FILE RATE_HZ");
        std::process::exit(2);
    };
    let y = read_f64(path).unwrap_or_else(|e| {
        eprintln!("{path}: {e}");
        std::process::exit(1);
    });
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
