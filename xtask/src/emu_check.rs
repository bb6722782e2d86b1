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

pub fn read_imu(path: &Path) -> Result<Vec<ImuRaw>> {
    let cols = [
        "k",
        "slot",
        "t_ns",
        "ax",
        "ay",
        "az",
        "temp",
        "gx",
        "gy",
        "gz",
        "served_ns",
    ];
    Ok(parse_rows(path, &cols)?
        .into_iter()
        .map(|r| ImuRaw {
            k: r[0] as u64,
            slot: r[1] as u64,
            t_ns: r[2],
            accel: [r[3] as i16, r[4] as i16, r[5] as i16],
            temp: r[6] as i16,
            gyro: [r[7] as i16, r[8] as i16, r[9] as i16],
            served_ns: r[10],
        })
        .collect())
}

pub fn read_mag(path: &Path) -> Result<Vec<MagRaw>> {
    let cols = ["k", "slot", "t_ns", "mx", "my", "mz", "served_ns"];
    Ok(parse_rows(path, &cols)?
        .into_iter()
        .map(|r| MagRaw {
            k: r[0] as u64,
            slot: r[1] as u64,
            t_ns: r[2],
            mag: [r[3] as i16, r[4] as i16, r[5] as i16],
            served_ns: r[6],
        })
        .collect())
}
