//! A sensor's fault state: when it counts as lost or stalled, when to retry, and the events
//! reported to the host. Pure logic over timestamps (µs), host-tested.
//!
//! Policy:
//! * a failed transfer is retried on the next tick, after a bus recovery if the bus was at
//!   fault; only when transfers have kept failing for [`LOSE_AFTER_US`] is the sensor `Missing`
//!   (`SensorLost`). A NACK burst shorter than that costs no data at all: the MPU-6050 keeps
//!   sampling into its FIFO, and the magnetometer's unread samples are counted as lost;
//! * a sensor that answers but has delivered no sample for [`STALL_AFTER_US`] is `Stalled`
//!   (`SensorStalled`), so a stall is reported within 50 ms of its start;
//! * while missing or stalled, a retry (identity and configuration read back, re-initialisation
//!   if the configuration is gone; for a stall, re-initialisation) is due every
//!   [`RETRY_FIRST_MS`], doubling up to [`RETRY_MAX_MS`]; a missing part is also looked for
//!   (its identity read) on every tick in between, which counts only a bus fault, so that one
//!   back from a NACK burst loses no more than the burst spanned (the services decide that);
//! * the first sample delivered after a loss or a stall reports how long the sensor was out
//!   (`SensorBack`). Nothing here resets the device.
use imu_proto::{Event, Sensor, SensorState};

/// Failing transfers for this long make the sensor `Missing`, µs.
pub const LOSE_AFTER_US: u64 = 100_000;
/// No sample for this long (while the sensor answers) makes it `Stalled`, µs.
pub const STALL_AFTER_US: u64 = 40_000;
/// First retry delay after a loss or a stall, ms.
pub const RETRY_FIRST_MS: u64 = 50;
/// Longest retry delay, ms.
pub const RETRY_MAX_MS: u64 = 400;

/// Health of one sensor.
#[derive(Debug, Clone, Copy)]
pub struct Health {
    sensor: Sensor,
    state: SensorState,
    /// Start of the current run of failed transfers.
    failing_since: Option<u64>,
    /// When the sensor went missing or stalled.
    out_since: u64,
    retry_at: u64,
    retry_ms: u64,
}

impl Health {
    pub const fn new(sensor: Sensor) -> Self {
        Self {
            sensor,
            state: SensorState::Unknown,
            failing_since: None,
            out_since: 0,
            retry_at: 0,
            retry_ms: RETRY_FIRST_MS,
        }
    }

    pub fn state(&self) -> SensorState {
        self.state
    }

    /// A transfer failed since the sensor last answered (and it is not lost yet).
    pub fn failing(&self) -> bool {
        self.failing_since.is_some()
    }

    /// A transfer succeeded: the run of failures is over (the state does not change until
    /// samples are delivered).
    pub fn answered(&mut self) {
        self.failing_since = None;
    }

    /// Samples were delivered at `t_us`. Returns `SensorBack` after a loss or a stall.
    pub fn delivering(&mut self, t_us: u64) -> Option<Event> {
        self.failing_since = None;
        self.retry_ms = RETRY_FIRST_MS;
        let was = core::mem::replace(&mut self.state, SensorState::Ok);
        matches!(was, SensorState::Missing | SensorState::Stalled).then(|| Event::SensorBack {
            sensor: self.sensor,
            t_us,
            down_us: t_us.saturating_sub(self.out_since),
        })
    }

    /// A transfer failed at `t_us`. Returns `SensorLost` when this failure makes the sensor
    /// missing: after [`LOSE_AFTER_US`] of failures, or at once for a sensor never seen.
    pub fn failed(&mut self, t_us: u64) -> Option<Event> {
        let since = *self.failing_since.get_or_insert(t_us);
        let lose = match self.state {
            SensorState::Unknown => true,
            SensorState::Ok | SensorState::Stalled => t_us.saturating_sub(since) >= LOSE_AFTER_US,
            SensorState::Missing => false,
        };
        if !lose {
            return None;
        }
        self.went_out(SensorState::Missing, since, t_us);
        Some(Event::SensorLost {
            sensor: self.sensor,
            t_us,
        })
    }

    /// The sensor answers but has delivered nothing since `since_us`. Returns `SensorStalled`
    /// the first time.
    pub fn stalled(&mut self, t_us: u64, since_us: u64) -> Option<Event> {
        if matches!(self.state, SensorState::Stalled | SensorState::Missing) {
            return None;
        }
        self.went_out(SensorState::Stalled, since_us, t_us);
        Some(Event::SensorStalled {
            sensor: self.sensor,
            t_us,
            since_us,
        })
    }

    /// The sensor went out (`state`: missing or stalled) at `since`, found at `t_us`: the first
    /// retry is [`RETRY_FIRST_MS`] later.
    fn went_out(&mut self, state: SensorState, since: u64, t_us: u64) {
        self.state = state;
        self.out_since = since;
        self.retry_ms = RETRY_FIRST_MS;
        self.retry_at = t_us.saturating_add(RETRY_FIRST_MS * 1000);
    }

    /// While missing or stalled: is a retry due at `t_us`?
    pub fn retry_due(&self, t_us: u64) -> bool {
        matches!(self.state, SensorState::Missing | SensorState::Stalled) && t_us >= self.retry_at
    }

    /// A retry was made at `t_us` and did not bring the samples back: back off.
    pub fn retried(&mut self, t_us: u64) {
        self.retry_ms = (self.retry_ms * 2).min(RETRY_MAX_MS);
        self.retry_at = t_us.saturating_add(self.retry_ms * 1000);
    }

    /// When the sensor went out (missing or stalled), µs.
    pub fn out_since(&self) -> u64 {
        self.out_since
    }
}
