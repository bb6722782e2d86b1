//! Host replay: served samples through the same corrections and Allan engines as the device,
//! split exactly where the device said it split (`Event::Gap`), so that its tables can be
//! checked sum for sum. Used by the host tests (tests/) and by the emulator's end-to-end check
//! (xtask).
use std::collections::BTreeSet;
use std::vec::Vec;
use std::{boxed::Box, format, string::String};

use allan::{Engine, LevelSums};
use imu_cal::device::Calibration;
use imu_proto::{AllanTable, Channel};

use crate::engines::{imu_input, ImuInputs};

/// The engine inputs of one IMU sample, as the device computes them (corrections applied,
/// temperature raw).
pub fn imu_inputs(
    cal: &Calibration,
    accel: [i16; 3],
    gyro: [i16; 3],
    temp: Option<i16>,
) -> ImuInputs {
    let g = match temp {
        Some(t) => cal.apply_gyro(gyro, t),
        None => cal.apply_gyro(gyro, cal.gyro().t_ref()),
    };
    (cal.apply_accel(accel), g, temp.map(i32::from))
}

/// The engine input of channel `ch` for one sample: `imu` for the IMU's channels, `mag` (the
/// corrected magnetometer reading) for the magnetometer's.
pub fn channel_input(ch: Channel, imu: Option<&ImuInputs>, mag: Option<&[i32; 3]>) -> Option<i32> {
    match ch {
        Channel::Mx => mag.map(|m| m[0]),
        Channel::My => mag.map(|m| m[1]),
        Channel::Mz => mag.map(|m| m[2]),
        _ => imu.and_then(|i| imu_input(ch, i)),
    }
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

#[cfg(test)]
mod tests {
    use super::*;
    use allan::DeviceEngine;
    use std::vec;

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
