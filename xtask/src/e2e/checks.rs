//! The device's tables, losses, stamps and calibrated samples checked against the host replay
//! and the models' ground truth.
use std::collections::{BTreeMap, BTreeSet};
use std::fmt::Write as _;

use anyhow::Result;
use imu_cal::device::Calibration;
use imu_proto::{Channel, Event, GapCause, Sensor};
use pico_imu_core::replay::{self, ChannelCheck};

use super::*;
use crate::emu_check::{ImuRaw, MagRaw};

/// The device's split positions and losses per sensor, from its `Gap` events: `at` → (lost,
/// causes).
fn gaps(events: &[Event], sensor: Sensor) -> BTreeMap<u64, (u64, Vec<GapCause>)> {
    let mut m: BTreeMap<u64, (u64, Vec<GapCause>)> = BTreeMap::new();
    for e in events {
        if let Event::Gap {
            sensor: s,
            at,
            cause,
            lost,
            ..
        } = e
        {
            if *s == sensor {
                let x = m.entry(*at).or_default();
                x.0 += u64::from(*lost);
                x.1.push(*cause);
            }
        }
    }
    m
}

/// The ten tables bit for bit against the host replay, and one snapshot for all.
pub(super) fn check_tables(
    s: &Session,
    imu: &[ImuRaw],
    mag: &[MagRaw],
    r: &mut Report,
) -> Result<()> {
    let identity = Calibration::identity();
    let splits: [BTreeSet<u64>; 2] = [
        gaps(&s.events, Sensor::Imu).keys().copied().collect(),
        gaps(&s.events, Sensor::Mag).keys().copied().collect(),
    ];
    let mut checks: Vec<ChannelCheck> = Vec::new();
    for (idx, table) in &s.tables {
        let ch = Channel::ALL[*idx];
        let rep = if ch.sensor() == Sensor::Mag {
            replay::replay::<allan::MagEngine, _>(
                mag,
                table.pushed,
                |x| x.k,
                |x| replay::channel_input(ch, None, Some(&identity.apply_mag(x.mag))).unwrap_or(0),
                &splits[1],
            )
        } else {
            replay::replay::<allan::DeviceEngine, _>(
                imu,
                table.pushed,
                |x| x.k,
                |x| {
                    let i = replay::imu_inputs(&identity, x.accel, x.gyro, Some(x.temp));
                    replay::channel_input(ch, Some(&i), None).unwrap_or(0)
                },
                &splits[0],
            )
        };
        checks.push(replay::compare(table, &rep));
    }
    r.text.push_str("## Allan tables: device vs host replay of the served samples\n\n| channel | pushed | gaps (device/host) | levels compared | result |\n|---|---|---|---|---|\n");
    for c in &checks {
        let ok = c.mismatches.is_empty() && c.levels_compared > 0;
        writeln!(
            r.text,
            "| {} | {} | {}/{} | {} | {} |",
            c.channel.name(),
            c.pushed,
            c.device_gaps,
            c.host_gaps,
            c.levels_compared,
            if ok {
                "bit-exact".to_string()
            } else {
                c.mismatches.join("; ")
            }
        )?;
        if !ok {
            r.fail(format!(
                "{}: {}",
                c.channel.name(),
                c.mismatches.first().cloned().unwrap_or("no levels".into())
            ));
        }
    }
    if checks.len() != Channel::ALL.len() {
        r.fail(format!(
            "only {} of {} tables",
            checks.len(),
            Channel::ALL.len()
        ));
    }
    // One instant: one round, one time; every IMU channel the same count, every magnetometer
    // channel too.
    let rounds: BTreeSet<(u32, u64)> = s.tables.values().map(|t| (t.snapshot, t.t_us)).collect();
    let pushed = |sensor: Sensor| -> BTreeSet<u64> {
        s.tables
            .values()
            .filter(|t| t.channel.sensor() == sensor)
            .map(|t| t.pushed)
            .collect()
    };
    let consistent = rounds.len() == 1
        && rounds.iter().all(|(n, _)| *n == s.snapshot)
        && pushed(Sensor::Imu).len() == 1
        && pushed(Sensor::Mag).len() == 1;
    writeln!(
        r.text,
        "\nSnapshot: round(s) {rounds:?}, IMU pushed {:?}, magnetometer pushed {:?}: {}\n",
        pushed(Sensor::Imu),
        pushed(Sensor::Mag),
        if consistent {
            "one instant"
        } else {
            "NOT consistent"
        }
    )?;
    if !consistent {
        r.fail("the tables of one GetTables answer are not one snapshot".into());
    }
    Ok(())
}

/// Ground truth per pushed position: the slots skipped before served sample `i` (the i-th
/// sample pushed), for `i ≥ 1`.
fn truth_jumps(slots: &[u64], pushed: u64) -> BTreeMap<u64, u64> {
    slots
        .windows(2)
        .enumerate()
        .take(pushed.saturating_sub(1) as usize)
        .filter(|(_, w)| w[1] != w[0] + 1)
        .map(|(i, w)| ((i + 1) as u64, w[1].saturating_sub(w[0] + 1)))
        .collect()
}

/// Every loss the device reported equals the models' ground truth, position by position.
pub(super) fn check_losses(
    s: &Session,
    imu: &[ImuRaw],
    mag: &[MagRaw],
    faults: &[Fault],
    r: &mut Report,
) {
    r.text.push_str("## Losses: device vs the models' ground truth\n\n| sensor | samples pushed | lost (device Gap events) | lost (model: slots never served) | per position | status counter |\n|---|---|---|---|---|---|\n");
    for (sensor, slots, counter) in [
        (
            Sensor::Imu,
            imu.iter().map(|x| x.slot).collect::<Vec<_>>(),
            s.status.samples_dropped,
        ),
        (
            Sensor::Mag,
            mag.iter().map(|x| x.slot).collect::<Vec<_>>(),
            s.status.mag_dropped,
        ),
    ] {
        let ch = if sensor == Sensor::Imu {
            Channel::Ax
        } else {
            Channel::Mx
        };
        let pushed = s.tables.get(&ch.index()).map_or(0, |t| t.pushed);
        let truth = truth_jumps(&slots, pushed);
        let device: BTreeMap<u64, u64> = gaps(&s.events, sensor)
            .into_iter()
            .filter(|(at, (lost, _))| *at < pushed && *lost > 0)
            .map(|(at, (lost, _))| (at, lost))
            .collect();
        let (t_sum, d_sum): (u64, u64) = (truth.values().sum(), device.values().sum());
        let mismatched: Vec<String> = truth
            .keys()
            .chain(device.keys())
            .collect::<BTreeSet<_>>()
            .into_iter()
            .filter(|at| truth.get(at) != device.get(at))
            .take(5)
            .map(|at| {
                format!(
                    "at {at}: device {:?}, model {:?}",
                    device.get(at),
                    truth.get(at)
                )
            })
            .collect();
        // The device's own counter equals the sum of its Gap events so far.
        let all: u64 = gaps(&s.events, sensor).values().map(|v| v.0).sum();
        let _ = writeln!(
            r.text,
            "| {sensor:?} | {pushed} | {d_sum} | {t_sum} | {} | {counter} (events {all}) |",
            if mismatched.is_empty() {
                "equal".to_string()
            } else {
                mismatched.join("; ")
            }
        );
        if !mismatched.is_empty() || d_sum != t_sum {
            r.fail(format!(
                "{sensor:?}: device reports {d_sum} samples lost, the model {t_sum}: {}",
                mismatched.join("; ")
            ));
        }
        if counter != all {
            r.fail(format!(
                "{sensor:?}: status counter {counter} differs from its Gap events' sum {all}"
            ));
        }
        // Losses only where a fault was.
        let served_ns: Vec<f64> = if sensor == Sensor::Imu {
            imu.iter().map(|x| x.served_ns).collect()
        } else {
            mag.iter().map(|x| x.served_ns).collect()
        };
        for (at, lost) in &truth {
            let t = served_ns[*at as usize] * 1e-9;
            let inside = faults
                .iter()
                .any(|x| t >= x.at_s && t <= x.at_s + x.dur_s + 3.0);
            if !inside {
                r.fail(format!(
                    "{sensor:?}: {lost} samples lost at {t:.3} s, outside every fault"
                ));
            }
        }
    }
}

/// Stamp errors against the models' sample instants, matched by slot (and checked by value).
pub(super) fn check_stamps(s: &Session, imu: &[ImuRaw], mag: &[MagRaw], r: &mut Report) {
    r.text.push_str("\n## Timestamps: device stamps vs the instants the models sampled\n\n| sensor | samples compared | mean (fixed latency) | rms about the mean | largest | value mismatches | stamps going back |\n|---|---|---|---|---|---|---|\n");
    let imu_by_slot: BTreeMap<u64, &ImuRaw> = imu.iter().map(|x| (x.slot, x)).collect();
    let mag_by_slot: BTreeMap<u64, &MagRaw> = mag.iter().map(|x| (x.slot, x)).collect();
    for sensor in [Sensor::Imu, Sensor::Mag] {
        let mut errs = Vec::new();
        let mut wrong = 0usize;
        let mut back = 0usize;
        let mut last: Option<u64> = None;
        let samples: Vec<(u32, u64, Option<bool>)> = s
            .batches
            .iter()
            .filter(|b| b.calibrated)
            .flat_map(|b| -> Vec<(u32, u64, Option<bool>)> {
                if sensor == Sensor::Imu {
                    b.imu
                        .iter()
                        .map(|x| {
                            let same = imu_by_slot.get(&u64::from(x.seq)).map(|m| {
                                m.accel.map(i32::from) == x.accel && m.gyro.map(i32::from) == x.gyro
                            });
                            (x.seq, x.t_us, same)
                        })
                        .collect()
                } else {
                    b.mag
                        .iter()
                        .map(|x| {
                            let same = mag_by_slot
                                .get(&u64::from(x.seq))
                                .map(|m| m.mag.map(i32::from) == x.mag);
                            (x.seq, x.t_us, same)
                        })
                        .collect()
                }
            })
            .collect();
        for (seq, t_us, same) in &samples {
            if last.is_some_and(|l| *t_us <= l) {
                back += 1;
            }
            last = Some(*t_us);
            match same {
                Some(true) => {}
                _ => {
                    wrong += 1;
                    continue;
                }
            }
            let t_ns = match sensor {
                Sensor::Imu => imu_by_slot[&u64::from(*seq)].t_ns,
                Sensor::Mag => mag_by_slot[&u64::from(*seq)].t_ns,
            };
            if t_ns * 1e-9 >= STAMPS_FROM_S {
                errs.push(*t_us as f64 - t_ns * 1e-3);
            }
        }
        let n = errs.len().max(1) as f64;
        let mean = errs.iter().sum::<f64>() / n;
        let rms = (errs.iter().map(|e| (e - mean).powi(2)).sum::<f64>() / n).sqrt();
        let max = errs.iter().map(|e| (e - mean).abs()).fold(0.0, f64::max);
        let _ = writeln!(
            r.text,
            "| {sensor:?} | {} | {mean:+.1} µs | {rms:.1} µs | {max:.1} µs | {wrong} of {} | {back} |",
            errs.len(),
            samples.len()
        );
        if errs.is_empty() {
            r.fail(format!("{sensor:?}: no stamps to compare"));
        }
        if rms > STAMP_RMS_GOAL_US {
            r.fail(format!(
                "{sensor:?}: stamp error {rms:.1} µs rms after {STAMPS_FROM_S} s (goal ≤ {STAMP_RMS_GOAL_US} µs)"
            ));
        }
        if wrong > 0 {
            r.fail(format!(
                "{sensor:?}: {wrong} streamed samples are not the model's sample of the same slot"
            ));
        }
        if back > 0 {
            r.fail(format!(
                "{sensor:?}: {back} stamps not after the previous one"
            ));
        }
    }
    let _ = writeln!(
        r.text,
        "\nMeasured periods (status): IMU {} ns, magnetometer {} ns.",
        s.status.imu_period_ns, s.status.mag_period_ns
    );
}

/// Every calibrated IMU sample streamed after the upload is the uploaded correction applied to
/// the model's sample of the same slot.
pub(super) fn check_calibration(s: &Session, imu: &[ImuRaw], r: &mut Report) {
    let by_slot: BTreeMap<u64, &ImuRaw> = imu.iter().map(|x| (x.slot, x)).collect();
    let mut total = 0;
    let mut matched = 0;
    for b in &s.cal_batches {
        for x in &b.imu {
            total += 1;
            if let Some(m) = by_slot.get(&u64::from(x.seq)) {
                if s.cal.apply_accel(m.accel) == x.accel
                    && s.cal.apply_gyro(m.gyro, m.temp) == x.gyro
                    && Some(i32::from(m.temp)) == x.temp
                {
                    matched += 1;
                }
            }
        }
    }
    let _ = writeln!(
        r.text,
        "\n## Calibration round trip\n\n{}calibrated IMU samples streamed after the upload: {total}; equal to the uploaded correction applied to the model's sample of the same slot: {matched}\n",
        s.cal_report
    );
    if !s.persisted {
        r.fail("the calibration written to flash was not read back with source Flash".into());
    }
    if total == 0 || matched != total {
        r.fail(format!(
            "calibration not applied as uploaded: {matched} of {total} streamed samples match"
        ));
    }
}
