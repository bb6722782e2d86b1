//! Host-side checks of an emulator run: the exact raw samples the device models served
//! (`sim --served DIR`), replayed through the same fixed-point corrections (`imu-cal`) and the
//! same streaming engine (`allan::DeviceEngine`) as the firmware, compared with the device's
//! Allan tables sum for sum.
use std::path::Path;

use anyhow::{bail, Context, Result};

/// One served MPU-6050 sample set: index k (consecutive while nothing is lost), its slot on the
/// part's sample grid (the ground truth of losses, see sim's `SlotGrid`), the instant the part
/// sampled it, raw counts, emulated time it was served.
#[derive(Clone, Copy, Debug)]
pub struct ImuRaw {
    pub k: u64,
    pub slot: u64,
    pub t_ns: f64,
    pub accel: [i16; 3],
    pub temp: i16,
    pub gyro: [i16; 3],
    pub served_ns: f64,
}

/// One served QMC5883L sample.
#[derive(Clone, Copy, Debug)]
pub struct MagRaw {
    pub k: u64,
    pub slot: u64,
    pub t_ns: f64,
    pub mag: [i16; 3],
    pub served_ns: f64,
}

/// The rows of a served-samples CSV as the values of the named columns, in that order.
fn parse_rows(path: &Path, want: &[&str]) -> Result<Vec<Vec<f64>>> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let mut lines = text.lines().enumerate();
    let header: Vec<&str> = lines
        .next()
        .map(|(_, l)| l.split(',').map(str::trim).collect())
        .unwrap_or_default();
    let cols: Vec<usize> = want
        .iter()
        .map(|w| {
            header.iter().position(|h| h == w).with_context(|| {
                format!(
                    "{}: no column `{w}` in the header ({})",
                    path.display(),
                    header.join(",")
                )
            })
        })
        .collect::<Result<_>>()?;
    let mut rows = Vec::new();
    for (i, line) in lines {
        if line.trim().is_empty() {
            continue;
        }
        let f: Vec<f64> = line
            .split(',')
            .map(|s| s.trim().parse::<f64>())
            .collect::<Result<_, _>>()
            .with_context(|| format!("{}:{}: not a number in '{line}'", path.display(), i + 1))?;
        if f.len() != header.len() {
            bail!(
                "{}:{}: {} fields, the header has {}",
                path.display(),
                i + 1,
                f.len(),
                header.len()
            );
        }
        rows.push(cols.iter().map(|&c| f[c]).collect());
    }
    Ok(rows)
}

/// The columns every served row carries besides its raw counts.
struct Stamp {
    k: u64,
    slot: u64,
    t_ns: f64,
    served_ns: f64,
}

/// The rows of a served-samples CSV, each built from its stamp and the named count columns (in
/// that order).
fn read_served<T>(
    path: &Path,
    counts: &[&str],
    row: impl Fn(Stamp, &[f64]) -> T,
) -> Result<Vec<T>> {
    let cols: Vec<&str> = ["k", "slot", "t_ns", "served_ns"]
        .into_iter()
        .chain(counts.iter().copied())
        .collect();
    Ok(parse_rows(path, &cols)?
        .into_iter()
        .map(|r| {
            let stamp = Stamp {
                k: r[0] as u64,
                slot: r[1] as u64,
                t_ns: r[2],
                served_ns: r[3],
            };
            row(stamp, &r[4..])
        })
        .collect())
}

/// Three raw counts (one per axis) from the values of their columns.
fn axes(c: &[f64]) -> [i16; 3] {
    [c[0] as i16, c[1] as i16, c[2] as i16]
}

pub fn read_imu(path: &Path) -> Result<Vec<ImuRaw>> {
    let counts = ["ax", "ay", "az", "temp", "gx", "gy", "gz"];
    read_served(path, &counts, |s, c| ImuRaw {
        k: s.k,
        slot: s.slot,
        t_ns: s.t_ns,
        accel: axes(&c[0..3]),
        temp: c[3] as i16,
        gyro: axes(&c[4..7]),
        served_ns: s.served_ns,
    })
}

pub fn read_mag(path: &Path) -> Result<Vec<MagRaw>> {
    read_served(path, &["mx", "my", "mz"], |s, c| MagRaw {
        k: s.k,
        slot: s.slot,
        t_ns: s.t_ns,
        mag: axes(c),
        served_ns: s.served_ns,
    })
}
