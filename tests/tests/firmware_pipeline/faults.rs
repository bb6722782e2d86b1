//! The firmware's task logic under faults: every sample the parts produced and the host never
//! got is counted once, with its cause, at its place (checked against the models' logs); every
//! stall and loss is named, and the grid survives them.
use super::*;

#[test]
fn a_fifo_overflow_is_counted_exactly_and_marked_as_a_gap() {
    let mut rig = Rig::new();
    rig.run(3000);
    let before = rig.imu_out.len();
    rig.bus.advance_us(150_000);
    rig.next_imu_us = rig.now_us();
    rig.run(500);
    let ev = rig.events();
    let st = rig.dev.status(0, 0);
    assert_eq!(st.fifo_overflows, 1);
    let truth = rig.bus.mpu(|m| m.slots());
    let times: Vec<u64> = rig.imu_out.iter().map(|d| truth[d.k as usize].1).collect();
    let truly = truth_lost(&truth, &times);
    assert!(truly > 140, "{truly}");
    assert_eq!(st.samples_dropped, truly);
    assert_eq!(lost(&ev, Sensor::Imu), truly);
    assert_eq!(
        gap_positions(&ev, Sensor::Imu),
        BTreeSet::from([before as u64])
    );
    assert!(ev.iter().any(|e| matches!(
        e,
        Event::Gap {
            cause: GapCause::FifoOverflow,
            ..
        }
    )));
    // No Allan difference straddles the overflow: the replay split there agrees.
    let t = rig.table(Channel::Gz);
    let r = replay_imu(
        &rig.imu_out,
        Channel::Gz,
        t.pushed,
        &gap_positions(&ev, Sensor::Imu),
        &imu_cal::device::Calibration::identity(),
    );
    assert!(replay::compare(&t, &r).mismatches.is_empty());
}

#[test]
fn a_nack_burst_shorter_than_the_fifo_costs_nothing() {
    let mut rig = Rig::new();
    rig.run(1000);
    let until = rig.bus.now_ns() + 50_000_000;
    rig.bus.with_world(|w| w.nack_until = Some((0x68, until)));
    rig.run(1000);
    let ev = rig.events();
    let st = rig.dev.status(0, 0);
    assert!(st.i2c_errors >= 4, "{}", st.i2c_errors);
    assert_eq!(st.samples_dropped, 0);
    assert_eq!(st.imu, SensorState::Ok);
    assert!(
        !ev.iter().any(|e| matches!(e, Event::SensorLost { .. })),
        "{ev:?}"
    );
    assert!(rig.imu_out.windows(2).all(|w| w[1].k == w[0].k + 1));
}

/// A NACK burst long enough to lose the part (150–900 ms, at any phase): once it ends the
/// part is found on its next tick, so each sensor loses only what the burst spanned (the
/// magnetometer the readings within it, + 2, the bound the emulator's e2e holds; the IMU
/// those plus what its FIFO overflowed with meanwhile, 73 ms), every one counted at its slot,
/// and the failed looks between the back-off's retries are neither errors nor reports.
/// (Looked for on the back-off alone, 50 ms doubling to 400 ms, a part came back up to 400 ms
/// after the burst ended: a 393 ms NACK cost 95 readings where 80 spanned it.)
#[test]
fn a_long_nack_burst_costs_only_what_it_spans() {
    let mut keyed = pico_imu_tests::Keyed::from_clock();
    for i in 0..6 {
        let x = keyed.bits();
        let (phase_us, length_us) = (x % 10_000, 150_000 + (x >> 16) % 750_000);
        let (address, sensor) = if i % 2 == 0 {
            (imu_drivers::qmc5883::QMC5883L_ADDR, Sensor::Mag)
        } else {
            (0x68, Sensor::Imu)
        };
        let ctx = format!("{sensor:?} NACKing {length_us} µs from {phase_us} µs: ");
        let mut rig = Rig::new();
        rig.run(1500);
        rig.bus.advance_us(phase_us);
        let errors_before = rig.dev.status(0, 0).i2c_errors;
        let from = rig.bus.now_ns();
        let until = from + length_us * 1000;
        rig.bus
            .with_world(|w| w.nack_until = Some((address, until)));
        rig.run(1500);
        let ev = rig.events();
        assert!(
            ev.iter()
                .any(|e| matches!(e, Event::SensorLost { sensor: s, .. } if *s == sensor)),
            "{ctx}never lost: {ev:?}"
        );
        let st = rig.dev.status(0, 0);
        assert_eq!(
            (st.imu, st.mag),
            (SensorState::Ok, SensorState::Ok),
            "{ctx}"
        );
        // Failures: one a tick until it is lost (100 ms), then the back-off's retries only.
        let errors = st.i2c_errors - errors_before;
        assert!(errors <= 40, "{ctx}{errors} I2C errors counted");
        let (lost, spanned) = if sensor == Sensor::Mag {
            let (.., missed) = mag_readings_exact(&mut rig, &ctx);
            let slots = rig.bus.mag(|q| q.slots());
            let within = slots
                .iter()
                .filter(|(_, t)| *t >= from && *t < until)
                .count();
            (missed, within as u64 + 2)
        } else {
            let (truth, times) = imu_samples_exact(&mut rig, 0, &ctx);
            let lost = truth_lost(&truth, &times);
            assert_eq!(st.samples_dropped, lost, "{ctx}IMU samples lost");
            let within = truth
                .iter()
                .filter(|(_, t)| *t >= from && *t < until + 73_000_000)
                .count();
            (lost, within as u64 + 2)
        };
        assert!(lost <= spanned, "{ctx}{lost} lost, {spanned} spanned");
    }
}

/// An MPU-6050 up to 2.5 % off nominal that NACKs, or stalls, for 300–600 ms right after its
/// first samples, before its period is known: the slot after the outage is a guess (the clock
/// can only tell the outage's length to the nominal's ±3 %), so the run after it is a grid of
/// its own. Its period is then measured on that run alone, to the part's, and nothing is lost
/// after the restart. (Continued on the old grid, the instants located before and after the
/// outage gave a period 1.6 % short with a bound of 0.17 %; the line then ran early, and the
/// FIFO was restarted every 0.35 s for seconds, 10 samples lost each time.)
#[test]
fn an_outage_before_the_period_is_known_starts_a_grid_of_its_own() {
    let mut keyed = pico_imu_tests::Keyed::from_clock();
    for _ in 0..10 {
        let x = keyed.bits();
        let off = (0.015 + (x % 1000) as f64 * 1e-5) * if x & 1 << 20 == 0 { 1.0 } else { -1.0 };
        let (start_ms, length_us) = (20 + (x >> 24) % 20, 300_000 + (x >> 32) % 300_000);
        let stall = x & 1 << 21 != 0;
        let ctx = format!(
            "MPU {:+.2} % {} {length_us} µs from {start_ms} ms: ",
            off * 100.0,
            if stall { "stalled" } else { "NACKing" }
        );
        let mut mpu = noisy_mpu();
        mpu.clock_error = off;
        let mut rig = Rig::with(mpu, noisy_qmc());
        rig.run(start_ms);
        let (from, until) = (rig.bus.now_ns(), rig.bus.now_ns() + length_us * 1000);
        if stall {
            rig.bus.mpu(|m| m.stall = Some((from, until)));
        } else {
            rig.bus.with_world(|w| w.nack_until = Some((0x68, until)));
        }
        rig.run(length_us / 1000 + 200);
        let dropped = rig.dev.status(0, 0).samples_dropped;
        let delivered = rig.imu_out.len();
        rig.run(3000);
        let st = rig.dev.status(0, 0);
        assert_eq!(st.imu, SensorState::Ok, "{ctx}");
        assert_eq!(
            st.samples_dropped, dropped,
            "{ctx}samples lost after the restart"
        );
        let after = &rig.imu_out[delivered..];
        assert!(
            after.windows(2).all(|w| w[1].k == w[0].k + 1),
            "{ctx}a gap after the restart"
        );
        let truth = 1e6 / (1.0 + off);
        let period = f64::from(rig.imu_svc.clock().period_ns());
        assert!(
            (period / truth - 1.0).abs() < 50e-6,
            "{ctx}period {period} ns, the part's {truth:.0} ns"
        );
    }
}

/// A failed FIFO read (a NACK burst at any phase, of any length under the FIFO's span) moves no
/// stamp: the samples read after it are stamped as the part sampled them, as before it.
#[test]
fn a_failed_fifo_read_moves_no_stamp() {
    let mut keyed = pico_imu_tests::Keyed::from_clock();
    for _ in 0..6 {
        let x = keyed.bits();
        let (phase_us, length_us) = (x % 10_000, 2_000 + (x >> 20) % 38_000);
        let mut rig = Rig::new();
        rig.run(5000);
        rig.bus.advance_us(phase_us);
        let until = rig.bus.now_ns() + length_us * 1000;
        rig.bus.with_world(|w| w.nack_until = Some((0x68, until)));
        rig.run(1000);
        let truth = rig.bus.mpu(|m| m.slots());
        let st = rig.dev.status(0, 0);
        assert!(
            st.i2c_errors >= 1,
            "a NACK of {length_us} µs at {phase_us} µs"
        );
        assert_eq!(st.samples_dropped, 0);
        let worst = rig
            .imu_out
            .iter()
            .filter(|d| truth[d.k as usize].1 > 4_500_000_000)
            .map(|d| (d.t_us as f64 - truth[d.k as usize].1 as f64 * 1e-3).abs())
            .fold(0.0f64, f64::max);
        assert!(
            worst < 10.0,
            "a NACK of {length_us} µs at {phase_us} µs: stamps off by up to {worst} µs"
        );
    }
}

#[test]
fn a_power_cycled_sensor_is_reinitialised_on_its_old_grid_and_the_loss_counted() {
    let mut rig = Rig::new();
    rig.run(1000);
    rig.bus.mpu(|m| m.present = false);
    rig.run(200);
    // Power comes back: the chip restarts from its power-on state; keep its sample log.
    let log = rig.bus.mpu(|m| std::mem::take(&mut m.log));
    let mut fresh = noisy_mpu();
    fresh.log = log;
    rig.bus.with_world(|w| w.mpu = Some(fresh));
    rig.run(1500);
    let ev = rig.events();
    let st = rig.dev.status(0, 0);
    assert_eq!(st.imu, SensorState::Ok);
    assert!(ev.iter().any(|e| matches!(
        e,
        Event::SensorLost {
            sensor: Sensor::Imu,
            ..
        }
    )));
    assert!(ev.iter().any(|e| matches!(
        e,
        Event::SensorBack {
            sensor: Sensor::Imu,
            ..
        }
    )));
    let truth = rig.bus.mpu(|m| m.slots());
    let times: Vec<u64> = rig
        .imu_out
        .iter()
        .map(|d| truth.iter().find(|(s, _)| *s == u64::from(d.k)).unwrap().1)
        .collect();
    let truly = truth_lost(&truth, &times);
    assert!(truly > 250, "{truly}");
    assert_eq!(st.samples_dropped, truly);
    // The values of each delivered slot are the model's: the re-initialised part is on the
    // old grid.
    let log = rig.bus.mpu(|m| m.log.clone());
    for d in rig.imu_out.iter().step_by(97) {
        let i = truth
            .iter()
            .position(|(s, _)| *s == u64::from(d.k))
            .unwrap();
        assert_eq!(d.raw.gyro, [log[i].1[4], log[i].1[5], log[i].1[6]]);
    }
}

/// When the device first named `sensor` stalled, ns.
fn stalled_at(ev: &[Event], sensor: Sensor) -> Option<u64> {
    ev.iter().find_map(|e| match e {
        Event::SensorStalled {
            sensor: s, t_us, ..
        } if *s == sensor => Some(*t_us * 1000),
        _ => None,
    })
}

#[test]
fn a_stalled_sensor_is_named_within_50_ms_and_its_recovery_reported() {
    let mut rig = Rig::new();
    rig.run(2000);
    let from = rig.bus.now_ns();
    rig.bus.mag(|q| q.stall = Some((from, from + 300_000_000)));
    rig.run(1000);
    let ev = rig.events();
    let at = stalled_at(&ev, Sensor::Mag).expect("SensorStalled");
    assert!(
        at - from <= 50_000_000,
        "named {} ms after",
        (at - from) / 1_000_000
    );
    assert!(ev.iter().any(|e| matches!(
        e,
        Event::SensorBack {
            sensor: Sensor::Mag,
            ..
        }
    )));
    let st = rig.dev.status(0, 0);
    assert_eq!(st.mag, SensorState::Ok);
    // ≈ 60 slots of 5 ms in the 300 ms stall, counted from the slots.
    assert!((58..=62).contains(&st.mag_dropped), "{}", st.mag_dropped);
    assert_eq!(lost(&ev, Sensor::Mag), st.mag_dropped);
}

/// An IMU stall that begins anywhere between two FIFO reads, even right after the frames one
/// of them counts: named within 50 ms of its start, re-initialised once, the stalled slots
/// counted exactly, and the grid unmoved (every delivered slot holds the model's sample).
#[test]
fn an_imu_stall_at_any_phase_is_named_in_time_counted_exactly_and_keeps_the_grid() {
    for step in 0..14u64 {
        let mut rig = Rig::new();
        rig.run(1500);
        let from = rig.bus.now_ns() + step * 730_000;
        rig.bus.mpu(|m| m.stall = Some((from, from + 200_000_000)));
        rig.run(1000);
        let ev = rig.events();
        let named = stalled_at(&ev, Sensor::Imu)
            .unwrap_or_else(|| panic!("phase {step}: no SensorStalled"));
        assert!(
            named.saturating_sub(from) <= 50_000_000,
            "phase {step}: named {} µs after the stall began",
            named.saturating_sub(from) / 1000
        );
        let (truth, times) = imu_samples_exact(&mut rig, 0, &format!("phase {step}: "));
        let st = rig.dev.status(0, 0);
        assert_eq!(st.imu, SensorState::Ok, "phase {step}");
        assert_eq!(
            st.samples_dropped,
            truth_lost(&truth, &times),
            "phase {step}: lost"
        );
    }
}

/// An IMU stall too short to be named but spanning a burst (12–39 ms, at any phase, the
/// part's clock up to 0.6 % off; longer than two count reads can be apart, 10 ms plus a
/// probe's wait of up to ≈ 1.4 ms): the FIFO then holds the samples after it right behind those
/// before, where counting frames cannot see the slots skipped between. The clock can: frames
/// behind its newest slot after a read that found none or was late too. They are numbered
/// back from that slot and the skipped ones counted exactly, every delivered slot the model's.
/// (Counted as contiguous, a 45 ms stall at 0.25 s left every later sample 45 slots off and the
/// clock's interval a period wide for the rest of the run: `cargo xtask e2e --scenario faults
/// --fault stall:mpu@0.253s:45ms --clock mpu:+1.71%,qmc:+1.70%`.) A stall
/// between two reads leaves the burst holding the skip misnumbered: no count can place it
/// (one of 11.014 ms between reads 11.05 ms apart had the frame after it numbered as the
/// slot after the first read, the losses still counted exactly).
#[test]
fn an_imu_stall_too_short_to_name_is_counted_exactly() {
    let mut keyed = pico_imu_tests::Keyed::from_clock();
    for _ in 0..12 {
        let x = keyed.bits();
        let (phase_us, length_us) = (x % 10_000, 12_000 + (x >> 16) % 27_000);
        let off = ((x >> 32) % 1200) as f64 * 1e-5 - 0.006;
        let ctx = format!(
            "a {length_us} µs stall {phase_us} µs into a burst, the part {:+.3} %: ",
            off * 100.0
        );
        let mut mpu = noisy_mpu();
        mpu.clock_error = off;
        let mut rig = Rig::with(mpu, noisy_qmc());
        rig.run(1500);
        let from = rig.bus.now_ns() + phase_us * 1000;
        rig.bus
            .mpu(|m| m.stall = Some((from, from + length_us * 1000)));
        rig.run(1000);
        let (truth, times) = imu_samples_exact(&mut rig, 0, &ctx);
        let st = rig.dev.status(0, 0);
        assert_eq!(st.imu, SensorState::Ok, "{ctx}");
        let truly = truth_lost(&truth, &times);
        assert!(truly + 2 >= length_us / 1100, "{ctx}{truly} slots skipped");
        assert_eq!(st.samples_dropped, truly, "{ctx}lost");
    }
}

/// Every IMU sample the rig delivered from the `from`th on is the model's sample of its slot;
/// returns the model's slots and when it sampled each one delivered (for [`truth_lost`]).
/// `ctx` prefixes the messages.
fn imu_samples_exact(rig: &mut Rig, from: usize, ctx: &str) -> (Vec<(u64, u64)>, Vec<u64>) {
    let truth = rig.bus.mpu(|m| m.slots());
    let log = rig.bus.mpu(|m| m.log.clone());
    let times = rig.imu_out[from..]
        .iter()
        .map(|d| {
            let i = truth
                .iter()
                .position(|(s, _)| *s == u64::from(d.k))
                .unwrap_or_else(|| panic!("{ctx}slot {} was never produced", d.k));
            assert_eq!(
                d.raw.gyro,
                [log[i].1[4], log[i].1[5], log[i].1[6]],
                "{ctx}slot {} is not the model's sample",
                d.k
            );
            truth[i].1
        })
        .collect();
    (truth, times)
}

/// IMU bursts whose first transfer has its START held 2–24 ms (a slave holding SDA; within
/// the firmware's 25 ms deadline, the FIFO holds 73 ms) at random phases: the count that
/// transfer latched at its end and the frames read right after it are whole, so nothing is
/// lost or taken for an overflow, and every slot delivered holds the model's sample. (Taken
/// for a count made stale by the hold, the emulator's 21 ms hang cost a FIFO's frames that had
/// been read whole.)
#[test]
fn an_imu_burst_held_before_its_start_loses_nothing() {
    let mut keyed = pico_imu_tests::Keyed::from_clock();
    for _ in 0..4 {
        let mut rig = Rig::new();
        rig.run(2000);
        let from = rig.imu_out.len();
        for _ in 0..30 {
            rig.imu_start_hang_us = 2_000 + keyed.bits() % 22_000;
            rig.run(100 + keyed.bits() % 200);
        }
        rig.run(200);
        let st = rig.dev.status(0, 0);
        assert_eq!(st.fifo_overflows, 0, "a held START taken for an overflow");
        assert_eq!(st.samples_dropped, 0, "samples lost to held STARTs");
        imu_samples_exact(&mut rig, from, "");
    }
}

/// A magnetometer missing at boot, or gone right after its first waking write (before its
/// first sample), found 0.2–1 s later: reported, and its readings numbered from its first
/// sample (the models count slots from a part's first sample; the grid that write implied
/// was never the part's).
#[test]
fn a_missing_magnetometer_at_boot_is_reported_and_found_later() {
    let mut keyed = pico_imu_tests::Keyed::from_clock();
    for i in 0..6 {
        let mut rig = Rig::new();
        if i % 2 == 1 {
            // Started by 8 ms (its first tick, a reset), its first sample due at 13 ms.
            rig.run(10);
            assert!(rig.mag_svc.clock().known(), "not started by 10 ms");
        }
        rig.bus.mag(|q| q.present = false);
        rig.run(200 + keyed.bits() % 800);
        assert_eq!(rig.dev.status(0, 0).mag, SensorState::Missing);
        assert_eq!(rig.dev.status(0, 0).imu, SensorState::Ok);
        // Power comes back: the chip from its power-on state.
        rig.bus.with_world(|w| w.mag = Some(noisy_qmc()));
        rig.run(800);
        assert_eq!(rig.dev.status(0, 0).mag, SensorState::Ok);
        assert!(rig.dev.status(0, 0).mag_samples > 50);
        let (first, ..) = mag_readings_exact(&mut rig, "");
        assert!(first <= 2, "the first reading numbered {first}");
    }
}

/// An MPU-6050 that stalls before its first sample, for 0.2–1.2 s: named, and once it
/// produces, its samples are numbered from its first (the models count slots so), each the
/// model's sample, none counted lost. (Numbered on the grid its waking write implied, they
/// were hundreds of slots off; restarting its FIFO instead needed a phase known better than a
/// period, and the part stayed stalled.)
#[test]
fn an_imu_stalled_from_its_start_is_numbered_from_its_first_sample() {
    let mut keyed = pico_imu_tests::Keyed::from_clock();
    for _ in 0..4 {
        let mut rig = Rig::new();
        let until = 200_000_000 + (keyed.bits() % 1000) * 1_000_000;
        rig.bus.mpu(|m| m.stall = Some((0, until)));
        rig.run(until / 1_000_000 + 1500);
        let ev = rig.events();
        assert!(stalled_at(&ev, Sensor::Imu).is_some(), "no SensorStalled");
        let st = rig.dev.status(0, 0);
        assert_eq!(st.imu, SensorState::Ok);
        assert!(!rig.imu_out.is_empty(), "nothing delivered after the stall");
        let (truth, times) = imu_samples_exact(&mut rig, 0, "");
        assert_eq!(st.samples_dropped, truth_lost(&truth, &times), "lost");
    }
}

#[test]
fn a_count_made_stale_by_a_hold_up_is_an_overflow() {
    assert!(!count_may_be_stale(140, 300, 1024));
    assert!(count_may_be_stale(140, 80_000, 1024));
    // Within two frames of the 512-byte FIFO of the 6500 family.
    assert!(count_may_be_stale(500, 300, 512));
    assert!(!count_may_be_stale(476, 0, 512));
}

/// Every magnetometer reading the rig delivered is the model's measurement of its slot, and the
/// device counted exactly the slots between the first and the last reading that it did not
/// deliver; returns (first slot, last slot, slots delivered, slots missed). `ctx` prefixes the
/// messages.
fn mag_readings_exact(rig: &mut Rig, ctx: &str) -> (u64, u64, BTreeSet<u64>, u64) {
    let (log, slots) = rig.bus.mag(|q| (q.log.clone(), q.slots()));
    for (k, xyz) in &rig.mag_out {
        let i = slots
            .iter()
            .position(|(s, _)| *s == u64::from(*k))
            .unwrap_or_else(|| panic!("{ctx}slot {k} was never measured"));
        assert_eq!(log[i].1, *xyz, "{ctx}slot {k}");
    }
    let first = u64::from(rig.mag_out[0].0);
    let last = u64::from(rig.mag_out.last().unwrap().0);
    let delivered: BTreeSet<u64> = rig.mag_out.iter().map(|(k, _)| u64::from(*k)).collect();
    let missed = (first..=last).filter(|k| !delivered.contains(k)).count() as u64;
    assert_eq!(rig.dev.status(0, 0).mag_dropped, missed, "{ctx}lost");
    (first, last, delivered, missed)
}

/// A magnetometer byte on the bus: 9 SCL periods at 400 kHz, ns.
const MAG_BYTE_NS: u64 = 22_500;

/// The rig with the magnetometer's bytes taking [`MAG_BYTE_NS`] each, and a service that knows
/// it.
fn rig_with_timed_bytes() -> Rig {
    let mut rig = Rig::new();
    rig.bus.mag(|q| q.byte_ns = MAG_BYTE_NS);
    rig.mag_svc = MagService::new(BusTiming::from_hz(400_000));
    rig
}

/// A magnetometer tick begun late by up to two periods (the CPU held up), or its first transfer
/// held back as long (the bus held by an IMU burst), at any phase of the part's grid and often
/// by about one period, on a bus whose bytes take time: a look may then meet a landing among or
/// near its data bytes (the data torn, or a new sample's), whatever the clock planned. Every
/// reading is still the model's measurement of its slot, every measurement not delivered is
/// counted lost, once, and every measurement the reader was served whole (its bytes read after
/// DRDY was seen) is delivered.
#[test]
fn a_magnetometer_tick_begun_late_keeps_every_reading_in_its_slot_and_counts_every_loss() {
    let mut keyed = pico_imu_tests::Keyed::from_clock();
    for _ in 0..4 {
        let mut rig = rig_with_timed_bytes();
        rig.run(3000);
        for i in 0..120 {
            // Half of them around one period, where the look meets the next landing; every
            // other one the CPU held before the tick, else the bus before its first transfer.
            let x = keyed.bits();
            let hold = if i % 2 == 0 {
                x % 10_000
            } else {
                4_400 + x % 700
            };
            if i % 4 < 2 {
                rig.mag_hold_us = hold;
            } else {
                rig.mag_bus_hold_us = hold;
            }
            rig.run(37 + keyed.bits() % 40);
        }
        rig.run(300);
        let (first, last, delivered, missed) = mag_readings_exact(&mut rig, "");
        // A hold-up of up to two periods costs at most three slots.
        assert!(missed <= 3 * 120, "{missed} lost");
        let slots = rig.bus.mag(|q| q.slots());
        // Every measurement the reader was served whole (its bytes read after DRDY was seen)
        // is delivered, also when a landing fell near a look's data bytes.
        let served: BTreeSet<u64> = rig
            .bus
            .mag(|q| q.served.clone())
            .into_iter()
            .map(|i| slots[i].0)
            .filter(|k| (first..=last).contains(k))
            .collect();
        let dropped: Vec<&u64> = served.difference(&delivered).collect();
        assert!(dropped.is_empty(), "served and not delivered: {dropped:?}");
    }
}

/// A magnetometer tick's later transfers held back (the bus held by an IMU burst, the CPU by
/// other work), up to one and a half periods, after a first transfer begun late at any phase
/// of the part's grid: a data read placed clear of a landing may then meet one among its bytes
/// (delivered torn before it was read again after the landing). Every reading is still the
/// model's measurement of its slot, and every measurement not delivered is counted lost, once.
#[test]
fn a_magnetometer_poll_held_past_the_next_landing_keeps_every_reading_in_its_slot() {
    let mut keyed = pico_imu_tests::Keyed::from_clock();
    for _ in 0..4 {
        let mut rig = rig_with_timed_bytes();
        rig.run(3000);
        for _ in 0..150 {
            let x = keyed.bits();
            rig.mag_hold_us = x % 10_000;
            rig.mag_later_hold = Some((1 + (x >> 20) as u32 % 2, 500 + (x >> 24) % 7_000));
            rig.run(37 + keyed.bits() % 40);
        }
        rig.run(300);
        let (.., missed) = mag_readings_exact(&mut rig, "");
        assert!(missed <= 3 * 150, "{missed} lost");
    }
}

/// A magnetometer power-cycled (gone 60–260 ms), then re-initialised on its old grid with a
/// clock that knows its phase only roughly, its ticks and their later transfers held up at
/// random (up to two periods) while that clock narrows: a data read held up may meet a landing
/// among its bytes while the clock is still wider than "located" (64 µs), where reads were not
/// kept clear of landings, and the poll after it then finds DRDY cleared by its last bytes.
/// Every reading is still the model's measurement of its slot, and every measurement not
/// delivered is counted lost.
#[test]
fn a_restarted_magnetometer_held_up_keeps_every_reading_in_its_slot() {
    let mut keyed = pico_imu_tests::Keyed::from_clock();
    for _ in 0..3 {
        let mut rig = rig_with_timed_bytes();
        rig.run(1500);
        for _ in 0..8 {
            rig.bus.mag(|q| q.present = false);
            rig.run(60 + keyed.bits() % 200);
            // Power comes back: the chip from its power-on state; its measurements logged on.
            let log = rig.bus.mag(|q| std::mem::take(&mut q.log));
            let mut fresh = noisy_qmc();
            fresh.byte_ns = MAG_BYTE_NS;
            fresh.log = log;
            rig.bus.with_world(|w| w.mag = Some(fresh));
            for _ in 0..40 {
                let x = keyed.bits();
                rig.mag_hold_us = x % 10_000;
                rig.mag_later_hold = Some((1 + (x >> 20) as u32 % 2, (x >> 24) % 10_000));
                rig.run(4 + keyed.bits() % 8);
            }
            rig.run(200);
        }
        mag_readings_exact(&mut rig, "");
    }
}

/// The magnetometer's oscillator glitches (a measurement comes 60–200 µs late, the grid goes on
/// from there) on a bus whose bytes take time, so that a look placed after the clock's late end
/// can find the sample not yet there and have it land among its own data bytes (which clear its
/// DRDY unseen): every reading is still the model's measurement of its slot, and every
/// measurement the device did not deliver is counted lost, once (at most the one cleared
/// unseen: a look that took the landing for not yet and polled on would count "not yet" again
/// and again, and the clock would run off).
#[test]
fn a_magnetometer_glitch_keeps_every_reading_in_its_slot_and_counts_every_loss() {
    let mut keyed = pico_imu_tests::Keyed::from_clock();
    for _ in 0..12 {
        let x = keyed.bits();
        let late_ns = 60_000 + x % 140_000;
        let mut rig = rig_with_timed_bytes();
        rig.run(3000);
        let at = rig.bus.now_ns() + (x >> 24) % 5_000_000;
        rig.bus.mag(|q| q.glitch = Some((at, late_ns)));
        rig.run(1500);
        let (.., missed) = mag_readings_exact(&mut rig, &format!("late {late_ns} ns: "));
        assert!(missed <= 2, "late {late_ns} ns: {missed} lost");
    }
}
