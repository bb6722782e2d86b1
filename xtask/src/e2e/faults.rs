//! Per fault: what the device reported, what it lost and how soon it named a stall.
use std::collections::BTreeMap;
use std::fmt::Write as _;

use imu_proto::{Event, Sensor, SensorState};

use super::*;
use crate::emu_check::{ImuRaw, MagRaw};

/// A held START the device notices: longer than a transfer's deadline (then abandoned as a
/// timeout) counted from that transfer's start, which may come up to a magnetometer tick
/// (5 ms) after the hold began, s.
const HANG_NOTICED_S: f64 = pico_imu_core::bus::TRANSFER_TIMEOUT_US as f64 * 1e-6 + 0.006;
/// The longest IMU NACK whose samples the FIFO keeps (73 frames, less a burst interval of
/// 10.2 ms and a margin), s.
const NACK_NO_OVERFLOW_S: f64 = 0.060;

/// Per fault: what the device reported and what it lost (the fault table of docs/firmware.md),
/// stalls named in time, NACK bursts cheap.
pub(super) fn check_faults(
    s: &Session,
    imu: &[ImuRaw],
    mag: &[MagRaw],
    faults: &[Fault],
    r: &mut Report,
) {
    r.text.push_str("\n## Faults: what the device reported, what was lost\n\n| fault | reported by the device | IMU samples lost (cause) | magnetometer samples lost (cause) | model: IMU / magnetometer slots lost |\n|---|---|---|---|---|\n");
    let imu_slots: Vec<u64> = imu.iter().map(|x| x.slot).collect();
    let mag_slots: Vec<u64> = mag.iter().map(|x| x.slot).collect();
    for (i, x) in faults.iter().enumerate() {
        let from = x.at_s;
        // Up to the next fault, and no further than 3 s after this one ended (what the session
        // does after the faults, e.g. pausing for a flash write, is no fault's).
        let until = faults
            .get(i + 1)
            .map_or(f64::INFINITY, |n| n.at_s)
            .min(x.at_s + x.dur_s + 3.0);
        let in_window = |t_us: u64| {
            let t = t_us as f64 * 1e-6;
            t >= from && t < until
        };
        let mut reported: Vec<String> = Vec::new();
        let mut lost = [BTreeMap::<String, u64>::new(), BTreeMap::new()];
        let mut stalled_at = None;
        for e in &s.all_events {
            let (t, text) = match e {
                Event::SensorLost { sensor, t_us } => (*t_us, format!("SensorLost({sensor:?})")),
                Event::SensorBack {
                    sensor,
                    t_us,
                    down_us,
                } => (
                    *t_us,
                    format!(
                        "SensorBack({sensor:?}, down {:.0} ms)",
                        *down_us as f64 * 1e-3
                    ),
                ),
                Event::SensorStalled {
                    sensor,
                    t_us,
                    since_us,
                } => {
                    // Its own window: another fault that begins meanwhile does not end it.
                    let t = *t_us as f64 * 1e-6;
                    let own = t >= from && t < from + x.dur_s + 3.0;
                    if Some(*sensor) == x.sensor && own && stalled_at.is_none() {
                        stalled_at = Some((*t_us, *since_us));
                    }
                    (*t_us, format!("SensorStalled({sensor:?})"))
                }
                Event::BusFault { t_us, fault } => (*t_us, format!("BusFault({fault:?})")),
                Event::BusRecovered {
                    t_us, sda_released, ..
                } => (
                    *t_us,
                    format!(
                        "BusRecovered({})",
                        if *sda_released {
                            "SDA free"
                        } else {
                            "SDA held"
                        }
                    ),
                ),
                Event::Gap {
                    sensor,
                    cause,
                    lost: n,
                    t_us,
                    ..
                } => {
                    if in_window(*t_us) && *n > 0 {
                        *lost[*sensor as usize]
                            .entry(format!("{cause:?}"))
                            .or_default() += u64::from(*n);
                    }
                    continue;
                }
            };
            if in_window(t) && !reported.contains(&text) {
                reported.push(text);
            }
        }
        let model = |slots: &[u64], served: &dyn Fn(usize) -> f64| -> u64 {
            slots
                .windows(2)
                .enumerate()
                .filter(|(i, _)| {
                    let t = served(i + 1) * 1e-9;
                    t >= from && t < until
                })
                .map(|(_, w)| w[1].saturating_sub(w[0] + 1))
                .sum()
        };
        let mi = model(&imu_slots, &|i| imu[i].served_ns);
        let mm = model(&mag_slots, &|i| mag[i].served_ns);
        let show = |m: &BTreeMap<String, u64>| {
            if m.is_empty() {
                "0".to_string()
            } else {
                m.iter()
                    .map(|(c, n)| format!("{n} ({c})"))
                    .collect::<Vec<_>>()
                    .join(", ")
            }
        };
        let _ = writeln!(
            r.text,
            "| `{}` | {} | {} | {} | {mi} / {mm} |",
            spec_at(&x.spec, x.at_s),
            if reported.is_empty() {
                "nothing".to_string()
            } else {
                reported.join(", ")
            },
            show(&lost[0]),
            show(&lost[1])
        );
        if x.kind == Kind::Stall {
            // Timed from the stall's start, or from when the device started the part if that
            // came later (a stall from before its first sample: the device cannot know sooner).
            let named_after = |t: u64, since: u64| t as f64 * 1e-6 - from.max(since as f64 * 1e-6);
            match stalled_at {
                Some((t, since)) if named_after(t, since) <= STALL_REPORT_S => {}
                Some((t, since)) => r.fail(format!(
                    "`{}`: stall named {:.1} ms after it began (goal ≤ {:.0} ms)",
                    spec_at(&x.spec, x.at_s),
                    named_after(t, since) * 1e3,
                    STALL_REPORT_S * 1e3
                )),
                None => r.fail(format!(
                    "`{}`: the stall was never reported",
                    spec_at(&x.spec, x.at_s)
                )),
            }
        }
        // A held bus is a bus fault: reported as one, with its recovery; it may cost the
        // magnetometer the samples it overwrote meanwhile, never the IMU's FIFO while the hold,
        // a burst interval (10 ms) and the recovery's ticks fit in its 73 ms. A START held
        // for less than a transfer's deadline only delays that transfer: the device cannot
        // tell it from a slow one.
        // (Unless a CPU stall overlaps it: the overflow is then that one's.)
        let cpu_meanwhile = faults
            .iter()
            .any(|y| y.kind == Kind::Cpu && y.at_s < until && y.at_s + y.dur_s.max(0.1) > from);
        if matches!(x.kind, Kind::Stuck | Kind::Hang) && x.dur_s <= 0.05 {
            if let Some(n) = lost[0].get("FifoOverflow").filter(|_| !cpu_meanwhile) {
                r.fail(format!(
                    "`{}`: a held bus cost {n} IMU samples as a FIFO overflow (its FIFO holds 73 ms)",
                    spec_at(&x.spec, x.at_s)
                ));
            }
            let noticed = x.kind == Kind::Stuck || x.dur_s > HANG_NOTICED_S;
            if noticed && !reported.iter().any(|e| e.starts_with("BusFault")) {
                r.fail(format!(
                    "`{}`: no BusFault reported",
                    spec_at(&x.spec, x.at_s)
                ));
            }
        }
        // Without an overflow of the IMU's FIFO (73 frames), a NACK costs its own length: the
        // part's samples within it (its period from the samples served), + 2.
        if x.kind == Kind::Nack && (x.sensor == Some(Sensor::Mag) || x.dur_s <= NACK_NO_OVERFLOW_S)
        {
            let (sensor_lost, period) = match x.sensor {
                Some(Sensor::Mag) => (
                    mm,
                    served_period_s(mag.iter().map(|m| (m.slot, m.t_ns)), 5e-3),
                ),
                _ => (
                    mi,
                    served_period_s(imu.iter().map(|m| (m.slot, m.t_ns)), 1e-3),
                ),
            };
            let bound = (x.dur_s / period).ceil() as u64 + 2;
            if sensor_lost > bound {
                r.fail(format!(
                    "`{}`: {sensor_lost} samples lost, more than the fault's {:.0} ms + 2 samples ({bound})",
                    spec_at(&x.spec, x.at_s),
                    x.dur_s * 1e3
                ));
            }
        }
    }
}

/// The part's sample period, s, from its first and last samples served (slot, instant in ns);
/// `nominal` without two.
fn served_period_s(served: impl Iterator<Item = (u64, f64)>, nominal: f64) -> f64 {
    let mut ends = None;
    for (slot, t) in served {
        let (first, _) = *ends.get_or_insert(((slot, t), (slot, t)));
        ends = Some((first, (slot, t)));
    }
    // A period that is not a positive number (instants out of order) would make the bound
    // infinite, which every loss passes: the nominal then.
    match ends {
        Some(((k0, t0), (k1, t1))) if k1 > k0 => Some((t1 - t0) * 1e-9 / (k1 - k0) as f64),
        _ => None,
    }
    .filter(|p| p.is_finite() && *p > 0.0)
    .unwrap_or(nominal)
}

/// A magnetometer that never produces: named within 50 ms of its start, status not "Ok".
pub(super) fn check_boot_stall(s: &Session, r: &mut Report) {
    let stalled = s.all_events.iter().chain(&s.events).find_map(|e| match e {
        Event::SensorStalled {
            sensor: Sensor::Mag,
            t_us,
            since_us,
        } => Some((*t_us, *since_us)),
        _ => None,
    });
    let _ = writeln!(
        r.text,
        "## Magnetometer stalled from boot\n\nSensorStalled: {stalled:?}; status: magnetometer {:?}, IMU {:?}, {} IMU samples\n",
        s.status.mag, s.status.imu, s.status.samples_taken
    );
    match stalled {
        Some((t, since)) if t.saturating_sub(since) as f64 * 1e-6 <= STALL_REPORT_S => {}
        Some((t, since)) => r.fail(format!(
            "the stall was named {:.1} ms after the part started",
            t.saturating_sub(since) as f64 * 1e-3
        )),
        None => r.fail("a magnetometer that never produced was not reported stalled".into()),
    }
    if s.status.mag != SensorState::Stalled {
        r.fail(format!(
            "status says the magnetometer is {:?}",
            s.status.mag
        ));
    }
    if s.status.imu != SensorState::Ok || s.status.samples_taken == 0 {
        r.fail("the IMU did not run beside the stalled magnetometer".into());
    }
}
