//! When each burst of work runs: the instants the firmware's tasks wait for and the turns they
//! take, decided here (host-tested) so that `src/main.rs` only waits and hands over.
//!
//! * the magnetometer task ticks at the instants its sample clock predicts, or on a 5 ms grid
//!   of its own while it has none ([`MagTicks::next_at`]); every second tick starts an IMU burst
//!   (the bus is then free for ≈ 4.5 ms), and its messages are handed to the processing task
//!   every [`MAG_TICKS_PER_SLOT`] ticks ([`MagTicks::done`]);
//! * the IMU task starts a burst on that signal, or at [`imu_fallback_at`] when the
//!   magnetometer task stops ticking (a flash-write pause, a transfer running into its deadline)
//!   or a failed transfer is to be retried;
//! * the 100 ms housekeeping tick decides the status frame, its log line, and the start of a
//!   table round ([`Housekeeping::on_tick`]); the round's steps are spaced by
//!   [`crate::tables`].
use imu_proto::{SensorState, Status, MAG_PERIOD_US};

use crate::mag::Slots;

/// Timer slots sit 250 µs off whole milliseconds. On silicon this changes nothing; in rp2040js
/// 1.4.1 an alarm that falls on the very instant the harness starts a CPU stall (its faults are
/// scheduled on whole seconds) was lost and the firmware slept for ever (docs/firmware.md).
pub const IMU_SLOT_OFFSET_US: u64 = 250;
/// Until the magnetometer service knows the sensor's phase (at boot, while it is out), its ticks
/// come on a 5 ms grid, 2.75 ms past whole multiples.
pub const MAG_SLOT_OFFSET_US: u64 = IMU_SLOT_OFFSET_US + MAG_PERIOD_US / 2;
/// The IMU FIFO is drained every 10 ms (≈ 10 frames of 14 bytes, ≈ 3.3 ms of bus time at
/// 400 kHz; the 1024-byte FIFO holds 73 ms), right after every second magnetometer tick. Only if
/// the magnetometer task stops ticking does a burst come this long after the previous one, well
/// within the FIFO's 73 ms.
pub const IMU_FALLBACK_US: u64 = 50_000;
/// Magnetometer ticks whose messages share one slot of its channel: the processing task wakes
/// once per 20 ms for the magnetometer (docs/benchmarks.md has the cost). Events carry their own
/// time, so a report waiting up to 20 ms in the slot is still dated when it happened.
pub const MAG_TICKS_PER_SLOT: u32 = 4;
/// Messages a magnetometer tick adds to its slot at most (a reading, a loss report, a state
/// change): a slot with less room than this is handed over at once.
pub const MAG_MSGS_PER_TICK: usize = 3;
/// Housekeeping period, ms.
pub const TICK_MS: u64 = 100;
/// How much earlier than its interval a status frame or a table round may come, µs: more than
/// a tick's lateness varies (without it, a status frame due every ten ticks slipped to the
/// eleventh whenever its tick was a few µs less late than the last one's).
pub const TICK_JITTER_US: u64 = 5_000;
/// Status frames between two status lines in the defmt log when nothing changed.
pub const STATUS_LOG_EVERY: u32 = 10;

/// After a burst whose transfer failed (a NACK, a held or stuck bus), the IMU is tried again
/// this soon, µs, if no magnetometer tick starts a burst first: not only a tick later, up to
/// 10 ms on. The FIFO's 73 ms (72 with the part's clock 1 % fast) then hold the samples left
/// from before the fault (up to a burst's 10 ms), the fault, and the wait for the retry: a
/// 52 ms NACK with the MPU-6050 0.81 % fast overflowed it (73 samples lost) when the retry
/// waited for the next burst's tick.
pub const IMU_RETRY_US: u64 = 4_000;

/// The instant of the IMU task's fallback burst after the burst at `last_burst_us`, `retrying`
/// a failed transfer or not: odd, so never on a whole millisecond (see
/// [`IMU_SLOT_OFFSET_US`]), with no 64-bit division.
pub fn imu_fallback_at(last_burst_us: u64, retrying: bool) -> u64 {
    let wait = if retrying {
        IMU_RETRY_US
    } else {
        IMU_FALLBACK_US
    };
    (last_burst_us + wait) | 1
}

/// What follows a magnetometer tick.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct AfterMag {
    /// The IMU task may start a burst now.
    pub burst: bool,
    /// The slot's messages go to the processing task now.
    pub hand_over: bool,
}

/// The magnetometer task's turns.
pub struct MagTicks {
    slots: Slots,
    ticks: u32,
    fresh: bool,
}

impl Default for MagTicks {
    fn default() -> Self {
        Self::new()
    }
}

impl MagTicks {
    pub const fn new() -> Self {
        Self {
            slots: Slots::new(MAG_PERIOD_US, MAG_SLOT_OFFSET_US),
            ticks: 0,
            fresh: true,
        }
    }

    /// The instant of the next tick: `predicted_us`, the service's prediction of the sensor's
    /// next sample, or while it has none the first slot of the task's own grid after `now_us`.
    pub fn next_at(&mut self, predicted_us: Option<u64>, now_us: u64) -> u64 {
        match predicted_us {
            Some(t) => t,
            None => self.slots.next_after(now_us),
        }
    }

    /// Whether this tick starts a new slot (its old messages, already handed over, are cleared).
    pub fn fresh(&self) -> bool {
        self.fresh
    }

    /// After a tick that left `len` messages in a slot of `capacity`: every second tick
    /// (reading or not, so bursts keep their 10 ms with the magnetometer missing too) lets the
    /// IMU task burst; the slot is handed over every [`MAG_TICKS_PER_SLOT`] ticks, or sooner
    /// when another tick's messages might not fit, and never empty.
    pub fn done(&mut self, len: usize, capacity: usize) -> AfterMag {
        self.ticks = self.ticks.wrapping_add(1);
        let due = self.ticks.is_multiple_of(MAG_TICKS_PER_SLOT);
        self.fresh = len > 0 && (due || len + MAG_MSGS_PER_TICK > capacity);
        AfterMag {
            burst: self.ticks.is_multiple_of(2),
            hand_over: self.fresh,
        }
    }
}

/// What the housekeeping tick does.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TickPlan {
    /// Send a status frame (whether it is logged too is [`StatusLog`]'s, once it is built).
    pub status: bool,
    /// Start a table round (take its snapshot).
    pub tables: bool,
    /// The processing task may run a table step on this tick (it otherwise runs them right
    /// after a magnetometer reading, which cannot then hold up the next one): only without a
    /// working magnetometer.
    pub table_turn: bool,
}

/// The housekeeping tick's decisions.
pub struct Housekeeping {
    last_status_us: u64,
    last_tables_us: u64,
    /// A round was due on the previous tick but gave way to its status frame.
    deferred: bool,
}

impl Housekeeping {
    /// Intervals are counted from `now_us`.
    pub const fn new(now_us: u64) -> Self {
        Self {
            last_status_us: now_us,
            last_tables_us: now_us,
            deferred: false,
        }
    }

    /// The tick at `now_us` with status frames every `status_ms` and table rounds every
    /// `tables_ms` (0: off), `tables_pending` while a round is still being sent, and `mag_ok`
    /// while the magnetometer delivers. A round's snapshot waits for the next tick rather than
    /// share one with a status frame, one tick at most (with a status frame on every tick, the
    /// two then share it); a round in progress is not replaced.
    pub fn on_tick(
        &mut self,
        now_us: u64,
        status_ms: u32,
        tables_ms: u32,
        tables_pending: bool,
        mag_ok: bool,
    ) -> TickPlan {
        // Ticks come a little late by varying amounts (a busy executor): an interval counts as
        // elapsed up to TICK_JITTER_US early, so that it spans the same number of ticks each
        // time instead of slipping a tick now and then.
        let elapsed = |since: u64, ms: u32| {
            ms > 0 && (now_us + TICK_JITTER_US).saturating_sub(since) >= u64::from(ms) * 1000
        };
        let status = elapsed(self.last_status_us, status_ms);
        if status {
            self.last_status_us = now_us;
        }
        let due = !tables_pending && elapsed(self.last_tables_us, tables_ms);
        let tables = due && (!status || self.deferred);
        self.deferred = due && !tables;
        if tables {
            self.last_tables_us = now_us;
        }
        TickPlan {
            status,
            tables,
            table_turn: !mag_ok,
        }
    }
}

/// When the status frame is also logged: at once when a count or state it reports changed (a
/// loss, an overflow, a bus error, a sensor's state), otherwise every [`STATUS_LOG_EVERY`]
/// frames, and then not while a table round is being sent (its first frame after the round):
/// a defmt line with a dozen fields costs as much CPU as the status frame itself (≈ 5,900
/// cycles), so a quiet device logs it rarely and not in the windows that carry a round's
/// snapshot and frames; the host gets every frame. Before the first line the reference
/// is a device with nothing lost and both sensors delivering: a healthy start is logged with the
/// tenth frame, anything else at once.
pub struct StatusLog {
    last: (u64, u64, u32, u32, u32, SensorState, SensorState),
    quiet: u32,
}

impl Default for StatusLog {
    fn default() -> Self {
        Self {
            last: (0, 0, 0, 0, 0, SensorState::Ok, SensorState::Ok),
            quiet: 0,
        }
    }
}

impl StatusLog {
    /// Whether the status frame `st` (just sent) is logged; `round`: a table round is being
    /// sent.
    pub fn due(&mut self, st: &Status, round: bool) -> bool {
        let key = (
            st.samples_dropped,
            st.mag_dropped,
            st.fifo_overflows,
            st.i2c_errors,
            st.bus_faults,
            st.imu,
            st.mag,
        );
        self.quiet += 1;
        if self.last == key && (self.quiet < STATUS_LOG_EVERY || round) {
            return false;
        }
        self.last = key;
        self.quiet = 0;
        true
    }
}
