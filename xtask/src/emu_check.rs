//! Host-side checks of an emulator run: the exact raw samples the device models served
//! (`sim --served DIR`), replayed through the same fixed-point corrections (`imu-cal`) and the
//! same streaming engine (`allan::DeviceEngine`) as the firmware, compared with the device's
//! Allan tables sum for sum.
use std::collections::BTreeSet;
use std::path::Path;

use allan::{Engine, LevelSums};
use anyhow::{bail, Context, Result};
use imu_cal::device::Calibration;
use imu_proto::{AllanTable, Channel};

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

/// An engine configuration the firmware uses (`DeviceEngine` at 1 kHz, `MagEngine` at 200 Hz).
pub trait ReplayEngine {
    fn fresh() -> Box<Self>;
    fn push(&mut self, v: i32);
    fn gap(&mut self);
    fn result(&self) -> EngineState;
}

/// Every configuration of the firmware's engine (`DeviceEngine`, `MagEngine`) replays alike.
impl<const P: usize, const L: usize, const R: usize, const S: usize> ReplayEngine
    for Engine<P, L, R, S>
{
    fn fresh() -> Box<Self> {
        Box::new(Self::new())
    }
    fn push(&mut self, v: i32) {
        Engine::push(self, v)
    }
    fn gap(&mut self) {
        Engine::gap(self)
    }
    fn result(&self) -> EngineState {
        EngineState {
            samples: self.samples(),
            gaps: self.gaps(),
            levels: self.levels().collect(),
        }
    }
}

/// What an engine holds after a replay.
#[derive(Debug, PartialEq, Eq)]
pub struct EngineState {
    pub samples: u64,
    pub gaps: u32,
    pub levels: Vec<LevelSums>,
}

/// The host replay of one channel.
pub struct Replay {
    pub engine: EngineState,
    /// The device also split the series right after the last replayed sample. It may have done
    /// so before or after the table was taken; a trailing split changes no sum, only the count.
    pub trailing_split: bool,
    /// Losses the device did not split at: (samples pushed before the loss, k before, k after).
    pub unsplit_losses: Vec<(u64, u64, u64)>,
}

/// Replays the first `pushed` served samples of one channel through a fresh engine, splitting
/// the series exactly where the device said it did (`splits`: the `at` of its `Event::Gap`s for
/// this sensor, in samples pushed). Every loss in the served sequence (the model's sample index
/// jumps: a sample was produced but never served) must be one of those splits; one that is not is
/// reported in [`Replay::unsplit_losses`], because the device's tables would then straddle
/// missing data. Splits without a loss are allowed (the firmware splits a late read even when
/// nothing was lost: a needless split costs a few terms, a missed one biases the tables).
pub fn replay<E: ReplayEngine + ?Sized, T>(
    samples: &[T],
    pushed: u64,
    k_of: impl Fn(&T) -> u64,
    value: impl Fn(&T) -> i32,
    splits: &BTreeSet<u64>,
) -> Replay {
    let mut engine = E::fresh();
    let mut unsplit_losses = Vec::new();
    let n = (pushed as usize).min(samples.len());
    for (i, s) in samples[..n].iter().enumerate() {
        let at = i as u64;
        if i > 0 {
            let (k0, k1) = (k_of(&samples[i - 1]), k_of(s));
            let split = splits.contains(&at);
            if k1 != k0 + 1 && !split {
                unsplit_losses.push((at, k0, k1));
            }
            if split {
                engine.gap();
            }
        }
        engine.push(value(s));
    }
    Replay {
        engine: engine.result(),
        trailing_split: n > 0 && splits.contains(&(n as u64)),
        unsplit_losses,
    }
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

/// Compares one device table with the host replay, sum for sum and count for count.
pub fn compare(table: &AllanTable, replay: &Replay) -> ChannelCheck {
    let host = &replay.engine;
    let mut mismatches = Vec::new();
    if host.samples != table.pushed {
        mismatches.push(format!(
            "pushed: device {} host {}",
            table.pushed, host.samples
        ));
    }
    for (at, k0, k1) in &replay.unsplit_losses {
        mismatches.push(format!(
            "samples {}..{} were lost before pushed sample {at} and the device did not split there",
            k0 + 1,
            k1
        ));
    }
    let host_gaps = host.gaps + u32::from(replay.trailing_split);
    if table.gaps != host.gaps && table.gaps != host_gaps {
        mismatches.push(format!(
            "gaps: device {} host {}{}",
            table.gaps,
            host.gaps,
            if replay.trailing_split {
                " (+1 trailing split)"
            } else {
                ""
            }
        ));
    }
    let mut compared = 0;
    for dl in table.levels.iter() {
        let Some(hl) = host.levels.iter().find(|l| l.m == dl.m) else {
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
            host.gaps
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

#[cfg(test)]
mod tests {
    use super::*;
    use allan::DeviceEngine;

    fn engine_with(values: &[i32], gaps_before: &[usize]) -> EngineState {
        let mut e = DeviceEngine::new();
        for (i, &v) in values.iter().enumerate() {
            if gaps_before.contains(&i) {
                e.gap();
            }
            e.push(v);
        }
        e.result()
    }

    fn sums(e: &EngineState) -> Vec<(u64, u128, u64, u128)> {
        e.levels
            .iter()
            .map(|l| (l.n2, l.sum2, l.n3, l.sum3))
            .collect()
    }

    // (k, value): sample 40 and 41 were lost between pushed samples 39 and 40.
    fn served() -> Vec<(u64, i32)> {
        (0..100u64)
            .filter(|k| !(40..42).contains(k))
            .map(|k| (k, ((k * 7919) % 201) as i32 - 100))
            .collect()
    }

    #[test]
    fn the_replay_splits_where_the_device_said_and_nowhere_else() {
        let s = served();
        // The device split at the loss and once more (a late read) at pushed sample 70.
        let splits: BTreeSet<u64> = [40, 70].into();
        let r = replay::<DeviceEngine, _>(&s, 90, |x| x.0, |x| x.1, &splits);
        assert!(r.unsplit_losses.is_empty());
        assert!(!r.trailing_split);
        let values: Vec<i32> = s[..90].iter().map(|x| x.1).collect();
        assert_eq!(sums(&r.engine), sums(&engine_with(&values, &[40, 70])));
        assert_eq!(r.engine.gaps, 2);
        // Splitting elsewhere gives other sums: the comparison can fail.
        assert_ne!(sums(&r.engine), sums(&engine_with(&values, &[40, 71])));
    }

    #[test]
    fn a_loss_the_device_did_not_split_at_is_reported() {
        let s = served();
        let r = replay::<DeviceEngine, _>(&s, 90, |x| x.0, |x| x.1, &BTreeSet::from([70]));
        assert_eq!(r.unsplit_losses, vec![(40, 39, 42)]);
    }

    #[test]
    fn a_split_after_the_last_replayed_sample_is_trailing() {
        let s = served();
        let r = replay::<DeviceEngine, _>(&s, 40, |x| x.0, |x| x.1, &BTreeSet::from([40]));
        assert!(r.trailing_split && r.unsplit_losses.is_empty());
        assert_eq!(r.engine.gaps, 0);
    }
}
