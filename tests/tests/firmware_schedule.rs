//! The firmware's schedule (`pico_imu_core::schedule`): the magnetometer's ticks and the IMU
//! bursts they start, with the parts' clocks off by up to ±1.3 %; the housekeeping tick's status
//! frames and table rounds; the status log's throttle.
use imu_proto::{CalSource, CalStatus, SensorState, Status, StreamMode, MAG_PERIOD_US};
use pico_imu_core::schedule::{
    imu_fallback_at, Housekeeping, MagTicks, StatusLog, IMU_FALLBACK_US, IMU_RETRY_US,
    MAG_MSGS_PER_TICK, MAG_SLOT_OFFSET_US, MAG_TICKS_PER_SLOT, STATUS_LOG_EVERY, TICK_JITTER_US,
    TICK_MS,
};
use proptest::prelude::*;

/// Slot capacity of the firmware's magnetometer channel (`msg::Out`).
fn capacity() -> usize {
    pico_imu_core::msg::Out::new().capacity()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    /// A magnetometer whose clock is off by `ppm` (within ±1.3 %), its sample instants predicted
    /// from tick `lost_from` to `lost_to` not known (the sensor missing: the task's own grid):
    /// every second tick starts an IMU burst, so bursts come every two of the ticks' periods;
    /// a message waits in its slot for MAG_TICKS_PER_SLOT ticks at most, and a slot never
    /// overflows.
    #[test]
    fn mag_ticks_and_bursts(
        ppm in -13_000i64..=13_000,
        phase_us in 0u64..MAG_PERIOD_US,
        lost_from in 0u32..400,
        lost_len in 0u32..200,
        per_tick in proptest::collection::vec(0usize..=MAG_MSGS_PER_TICK, 600),
    ) {
        let cap = capacity();
        let period = MAG_PERIOD_US as i64 * (1_000_000 + ppm) / 1_000_000;
        let mut turns = MagTicks::new();
        let now_at_start = 1_000_000u64;
        let mut now = now_at_start;
        let mut len = 0usize;
        // The tick of the oldest message waiting in the slot.
        let mut oldest: Option<u32> = None;
        let mut last_burst: Option<u64> = None;
        let mut bursts = 0u32;
        // Whether the last three ticks came at predicted instants (or on the grid).
        let mut sources = [false; 3];
        for (k, &add) in per_tick.iter().enumerate() {
            let k = k as u32;
            let known = !(lost_from..lost_from + lost_len).contains(&k);
            // The service predicts the sensor's first sample instant after now.
            let predicted = known.then(|| {
                let p = period as u64;
                let t0 = now_at_start + phase_us;
                t0 + (now.saturating_sub(t0) / p + 1) * p
            });
            let at = turns.next_at(predicted, now);
            prop_assert!(at > now, "tick {k}: {at} µs is not after {now} µs");
            if let Some(t) = predicted {
                prop_assert_eq!(at, t, "tick {}: not at the predicted instant", k);
            } else {
                // The task's own grid: 5 ms apart, 2.75 ms past whole multiples, never on a
                // whole millisecond.
                prop_assert_eq!(at % MAG_PERIOD_US, MAG_SLOT_OFFSET_US % MAG_PERIOD_US);
                prop_assert!(at - now <= MAG_PERIOD_US);
                prop_assert_ne!(at % 1000, 0);
            }
            now = at;
            sources = [sources[1], sources[2], predicted.is_some()];
            if turns.fresh() {
                len = 0;
            }
            len += add;
            if add > 0 {
                oldest.get_or_insert(k);
            }
            prop_assert!(len <= cap, "tick {k}: {len} messages in a slot of {cap}");
            let next = turns.done(len, cap);
            prop_assert_eq!(next.burst, (k + 1).is_multiple_of(2), "tick {}", k);
            if next.burst {
                bursts += 1;
                if let Some(b) = last_burst {
                    // Three ticks from one source: two of its periods to the µs; where the
                    // source changes, two of the longer period at most.
                    let gap = now - b;
                    match (sources[0] == sources[1] && sources[1] == sources[2], sources[2]) {
                        (true, true) => prop_assert_eq!(gap, 2 * period as u64),
                        (true, false) => prop_assert_eq!(gap, 2 * MAG_PERIOD_US),
                        _ => prop_assert!(
                            gap <= 2 * (period as u64).max(MAG_PERIOD_US),
                            "bursts {} µs apart", gap
                        ),
                    }
                }
                last_burst = Some(now);
            }
            if next.hand_over {
                prop_assert!(len > 0, "an empty slot handed over");
                oldest = None;
            } else {
                prop_assert!(len + MAG_MSGS_PER_TICK <= cap, "the next tick might not fit");
            }
            if let Some(o) = oldest {
                prop_assert!(
                    k - o < MAG_TICKS_PER_SLOT - 1,
                    "tick {}: a message of tick {} still waits", k, o
                );
            }
            prop_assert_eq!(turns.fresh(), next.hand_over);
        }
        prop_assert_eq!(bursts, per_tick.len() as u32 / 2);
    }

    /// The fallback burst: odd (never on a whole millisecond), the fallback interval after the
    /// last burst to the µs, or the retry interval after a failed one.
    #[test]
    fn imu_fallback(last in 0u64..(1 << 50), retrying: bool) {
        let at = imu_fallback_at(last, retrying);
        let wait = if retrying { IMU_RETRY_US } else { IMU_FALLBACK_US };
        prop_assert_eq!(at % 2, 1);
        prop_assert!(at - last == wait || at - last == wait + 1);
    }

    /// The housekeeping tick, its ticks late by up to `late_us` (a busy executor), with status
    /// and table intervals from the host, and table rounds that take `round_ticks` ticks to
    /// send: a status frame every `status_ms` (never more than [`TICK_JITTER_US`] sooner, at
    /// most a tick later, and every `status_ms / TICK_MS` ticks exactly for whole ticks); a round
    /// never on a status frame's tick unless every tick has one, never while one is being sent,
    /// never sooner than `tables_ms` after the last, and at most two ticks after it is due.
    #[test]
    fn status_and_table_rounds(
        status_ms in prop_oneof![Just(0u32), 1u32..=300, (1u32..=50).prop_map(|k| 100 * k)],
        tables_ms in prop_oneof![Just(0u32), 1u32..=300, (1u32..=100).prop_map(|k| 100 * k)],
        round_ticks in 0u32..40,
        late_us in proptest::collection::vec(0u64..3_000, 1_500),
        mag_ok in any::<bool>(),
    ) {
        let start = 123_456u64;
        let mut h = Housekeeping::new(start);
        let (mut last_status, mut last_tables) = (start, start);
        let mut last_status_tick = 0usize;
        let mut pending_until: Option<usize> = None;
        let mut due_since: Option<usize> = None;
        for (k, late) in late_us.iter().enumerate() {
            let now = start + (k as u64 + 1) * TICK_MS * 1000 + late;
            let pending = pending_until.is_some_and(|e| k < e);
            let plan = h.on_tick(now, status_ms, tables_ms, pending, mag_ok);
            prop_assert_eq!(plan.table_turn, !mag_ok);
            let status_due =
                status_ms > 0 && now + TICK_JITTER_US - last_status >= u64::from(status_ms) * 1000;
            prop_assert_eq!(plan.status, status_due, "tick {}", k);
            if plan.status {
                prop_assert!(now - last_status < u64::from(status_ms) * 1000 + TICK_MS * 1000 + 3_000);
                // An interval of whole ticks spans exactly that many, however late each tick.
                if u64::from(status_ms) % TICK_MS == 0 {
                    let ticks = (u64::from(status_ms) / TICK_MS) as usize;
                    prop_assert_eq!(k + 1 - last_status_tick, ticks, "tick {}", k);
                }
                last_status = now;
                last_status_tick = k + 1;
            }
            let tables_due = tables_ms > 0 && !pending
                && now + TICK_JITTER_US - last_tables >= u64::from(tables_ms) * 1000;
            if tables_due {
                due_since.get_or_insert(k);
            }
            if plan.tables {
                prop_assert!(tables_due, "tick {}: a round before it is due or while one is sent", k);
                prop_assert!(
                    !plan.status
                        || u64::from(status_ms) * 1000 <= TICK_MS * 1000 + TICK_JITTER_US + 3_000,
                    "tick {}: a round on a status frame's tick", k
                );
                last_tables = now;
                pending_until = Some(k + 1 + round_ticks as usize);
                due_since = None;
            } else if let Some(d) = due_since {
                prop_assert!(k - d < 2, "tick {}: a round due since tick {} not started", k, d);
            }
        }
    }
}

/// A status frame with `dropped` samples lost and the IMU in state `imu`; the fields the log
/// does not compare change every frame.
fn status(dropped: u64, imu: SensorState) -> Status {
    static FRAME: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
    let n = FRAME.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    Status {
        uptime_us: n * 1_000_000,
        samples_taken: n * 1000,
        samples_dropped: dropped,
        mag_samples: n * 200,
        mag_dropped: 0,
        fifo_overflows: 0,
        i2c_errors: 0,
        bus_faults: 0,
        bus_recoveries: 0,
        frames_rejected: 0,
        frames_unsent: 0,
        cpu_load_permille: 49,
        temp_milli_c: Some(25_000 + n as i32),
        imu,
        mag: SensorState::Ok,
        imu_period_ns: 1_000_000,
        mag_period_ns: 5_000_000,
        cal: CalStatus {
            source: CalSource::Identity,
            fault: None,
        },
        mode: StreamMode::Calibrated,
    }
}

/// The status log: a quiet device every STATUS_LOG_EVERY-th frame; a change at once; the
/// reference before the first line is a healthy device (its first frame not logged).
#[test]
fn status_log_throttle() {
    let mut log = StatusLog::default();
    let quiet = status(0, SensorState::Ok);
    let logged: Vec<bool> = (0..25).map(|_| log.due(&quiet, false)).collect();
    let want: Vec<bool> = (1..=25).map(|i| i % STATUS_LOG_EVERY == 0).collect();
    assert_eq!(logged, want);
    // A loss: logged at once, then quiet again for STATUS_LOG_EVERY - 1 frames.
    assert!(log.due(&status(3, SensorState::Ok), false));
    for _ in 1..STATUS_LOG_EVERY {
        assert!(!log.due(&status(3, SensorState::Ok), false));
    }
    assert!(log.due(&status(3, SensorState::Ok), false));
    // A state change is a change too, and so is the way back.
    assert!(log.due(&status(3, SensorState::Missing), false));
    assert!(log.due(&status(3, SensorState::Ok), false));
    // Anything but healthy at the start is logged with the first frame.
    assert!(StatusLog::default().due(&status(0, SensorState::Missing), false));
    // A quiet line due while a table round is being sent waits for the first frame after it;
    // a change does not wait.
    let mut log = StatusLog::default();
    for _ in 1..STATUS_LOG_EVERY {
        assert!(!log.due(&quiet, false));
    }
    for _ in 0..7 {
        assert!(!log.due(&quiet, true));
    }
    assert!(log.due(&quiet, false));
    assert!(!log.due(&quiet, false));
    assert!(log.due(&status(1, SensorState::Ok), true));
}
