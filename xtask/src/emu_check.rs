//! Host-side checks of an emulator run: the exact raw samples the device models served
//! (`sim --served DIR`), replayed through the same fixed-point corrections (`imu-cal`) and the
//! same streaming engine (`allan::DeviceEngine`) as the firmware, compared with the device's
//! Allan tables sum for sum.
use std::path::Path;

use allan::DeviceEngine;
use anyhow::{bail, Context, Result};
use imu_cal::device::Calibration;
use imu_proto::{AllanTable, Channel};

/// One served MPU-6050 sample set: index k (consecutive while nothing is lost), raw counts,
/// emulated time it was served.
#[derive(Clone, Copy, Debug)]
pub struct ImuRaw {
    pub k: u64,
    pub accel: [i16; 3],
    pub temp: i16,
    pub gyro: [i16; 3],
    pub served_ns: f64,
}

/// One served QMC5883L sample.
#[derive(Clone, Copy, Debug)]
pub struct MagRaw {
    pub k: u64,
    pub mag: [i16; 3],
    pub served_ns: f64,
}

fn parse_rows(path: &Path, cols: usize) -> Result<Vec<Vec<f64>>> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let mut rows = Vec::new();
    for (i, line) in text.lines().enumerate().skip(1) {
        if line.trim().is_empty() {
            continue;
        }
        let f: Vec<f64> = line
            .split(',')
            .map(|s| s.trim().parse::<f64>())
            .collect::<Result<_, _>>()
            .with_context(|| format!("{}:{}: not a number in '{line}'", path.display(), i + 1))?;
        if f.len() != cols {
            bail!(
                "{}:{}: {} fields, expected {cols}",
                path.display(),
                i + 1,
                f.len()
            );
        }
        rows.push(f);
    }
    Ok(rows)
}

pub fn read_imu(path: &Path) -> Result<Vec<ImuRaw>> {
    Ok(parse_rows(path, 10)?
        .into_iter()
        .map(|r| ImuRaw {
            k: r[0] as u64,
            accel: [r[2] as i16, r[3] as i16, r[4] as i16],
            temp: r[5] as i16,
            gyro: [r[6] as i16, r[7] as i16, r[8] as i16],
            served_ns: r[9],
        })
        .collect())
}

pub fn read_mag(path: &Path) -> Result<Vec<MagRaw>> {
    Ok(parse_rows(path, 7)?
        .into_iter()
        .map(|r| MagRaw {
            k: r[0] as u64,
            mag: [r[2] as i16, r[3] as i16, r[4] as i16],
            served_ns: r[6],
        })
        .collect())
}

/// Engine input of each channel (the integers the firmware pushes) for one IMU sample.
pub fn imu_inputs(cal: &Calibration, s: &ImuRaw) -> [(Channel, i32); 7] {
    let a = cal.apply_accel(s.accel);
    let g = cal.apply_gyro(s.gyro, s.temp);
    [
        (Channel::ALL[0], a[0]),
        (Channel::ALL[1], a[1]),
        (Channel::ALL[2], a[2]),
        (Channel::ALL[3], g[0]),
        (Channel::ALL[4], g[1]),
        (Channel::ALL[5], g[2]),
        (Channel::ALL[9], s.temp as i32),
    ]
}

/// Replays the first `pushed` served samples of one channel through a fresh engine, marking a
/// gap wherever the model's sample index jumps (a sample was produced but never served), or
/// wherever `late(previous, this)` says the device's own gap rule fires (the magnetometer's:
/// reads more than 1.5 periods apart).
/// Returns the engine and whether the index also jumps right after the last replayed sample: the
/// device may already know of that loss (a lost sensor) or not yet (a sample overwritten after
/// the table was taken); a trailing gap changes no sum, only the gap count.
pub fn replay<T>(
    samples: &[T],
    pushed: u64,
    k_of: impl Fn(&T) -> u64,
    value: impl Fn(&T) -> i32,
    late: impl Fn(&T, &T) -> bool,
) -> (Box<DeviceEngine>, bool) {
    let mut e = Box::new(DeviceEngine::new());
    let mut last: Option<u64> = None;
    let n = (pushed as usize).min(samples.len());
    for (i, s) in samples[..n].iter().enumerate() {
        let k = k_of(s);
        if let Some(l) = last {
            if k != l + 1 || late(&samples[i - 1], s) {
                e.gap();
            }
        }
        last = Some(k);
        e.push(value(s));
    }
    let trailing = matches!((last, samples.get(n)), (Some(l), Some(next)) if k_of(next) != l + 1);
    (e, trailing)
}

/// Outcome of comparing one channel's device table with the host replay.
pub struct ChannelCheck {
    pub channel: Channel,
    pub pushed: u64,
    pub levels_compared: usize,
    pub mismatches: Vec<String>,
    pub host_gaps: u32,
    pub device_gaps: u32,
}

/// Compares one device table with the host replay; `trailing_gap` (from [`replay`]) allows the
/// device to count one gap more than the replay.
pub fn compare(table: &AllanTable, host: &DeviceEngine, trailing_gap: bool) -> ChannelCheck {
    let mut mismatches = Vec::new();
    if host.samples() != table.pushed {
        mismatches.push(format!(
            "pushed: device {} host {}",
            table.pushed,
            host.samples()
        ));
    }
    let host_gaps = host.gaps() + u32::from(trailing_gap);
    if table.gaps != host.gaps() && table.gaps != host_gaps {
        mismatches.push(format!("gaps: device {} host {} (+1 if the device already counts the loss after its last sample)", table.gaps, host.gaps()));
    }
    let mut compared = 0;
    for dl in table.levels.iter() {
        let Some(hl) = host.levels().find(|l| l.m == dl.m) else {
            mismatches.push(format!("m={}: no such level on the host", dl.m));
            continue;
        };
        compared += 1;
        if (hl.n2, hl.sum2, hl.n3, hl.sum3) != (dl.n2, dl.sum2, dl.n3, dl.sum3) {
            mismatches.push(format!(
                "m={}: device n={} Σ²={} n3={} Σ³={}, host n={} Σ²={} n3={} Σ³={}",
                dl.m, dl.n2, dl.sum2, dl.n3, dl.sum3, hl.n2, hl.sum2, hl.n3, hl.sum3
            ));
        }
    }
    ChannelCheck {
        channel: table.channel,
        pushed: table.pushed,
        levels_compared: compared,
        mismatches,
        host_gaps: if table.gaps == host_gaps {
            host_gaps
        } else {
            host.gaps()
        },
        device_gaps: table.gaps,
    }
}

/// Index gaps in a served sequence: (k before, k after, samples lost, served_ns after).
pub fn index_jumps<T>(
    samples: &[T],
    k_of: impl Fn(&T) -> u64,
    t_of: impl Fn(&T) -> f64,
) -> Vec<(u64, u64, u64, f64)> {
    samples
        .windows(2)
        .filter(|w| k_of(&w[1]) != k_of(&w[0]) + 1)
        .map(|w| {
            (
                k_of(&w[0]),
                k_of(&w[1]),
                k_of(&w[1]) - k_of(&w[0]) - 1,
                t_of(&w[1]),
            )
        })
        .collect()
}
