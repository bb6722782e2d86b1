//! Sensor fault state machine: when a sensor counts as lost, when to retry (with bus recovery),
//! and the events reported to the host. Pure logic over timestamps, so it is host-tested.
//!
//! Policy: [`ERRORS_TO_LOSE`] consecutive failed transfers mark the sensor `Missing` (one NACK
//! from a glitch does not). While missing, a retry (bus recovery + re-initialisation) is due
//! every [`RETRY_FIRST_MS`], doubling up to [`RETRY_MAX_MS`], so a sensor that comes back is
//! found within `RETRY_MAX_MS` and an absent one costs the bus little. The first good transfer
//! after a loss reports how long the sensor was down. Nothing here resets the device.
use imu_proto::{Event, Sensor, SensorState};

/// Consecutive failed transfers before a sensor is declared missing.
pub const ERRORS_TO_LOSE: u32 = 3;
/// First retry delay after a loss, ms.
pub const RETRY_FIRST_MS: u64 = 50;
/// Longest retry delay, ms.
pub const RETRY_MAX_MS: u64 = 400;

/// Health of one sensor.
#[derive(Debug, Clone, Copy)]
pub struct Health {
    sensor: Sensor,
    state: SensorState,
    consecutive: u32,
    down_since_us: u64,
    retry_at_us: u64,
    retry_ms: u64,
}

impl Health {
    pub const fn new(sensor: Sensor) -> Self {
        Self {
            sensor,
            state: SensorState::Unknown,
            consecutive: 0,
            down_since_us: 0,
            retry_at_us: 0,
            retry_ms: RETRY_FIRST_MS,
        }
    }

    pub fn state(&self) -> SensorState {
        self.state
    }

    /// A transfer (or an initialisation) succeeded at `t_us`. Returns `SensorBack` after a loss.
    pub fn ok(&mut self, t_us: u64) -> Option<Event> {
        self.consecutive = 0;
        self.retry_ms = RETRY_FIRST_MS;
        let was = core::mem::replace(&mut self.state, SensorState::Ok);
        (was == SensorState::Missing).then(|| Event::SensorBack {
            sensor: self.sensor,
            t_us,
            down_us: t_us.saturating_sub(self.down_since_us),
        })
    }

    /// A transfer failed at `t_us`. Returns `SensorLost` when this failure marks the loss.
    /// A sensor that was never seen (`Unknown`, at boot) is lost on its first failure.
    pub fn error(&mut self, t_us: u64) -> Option<Event> {
        self.consecutive = self.consecutive.saturating_add(1);
        let lose = match self.state {
            SensorState::Unknown => true,
            SensorState::Ok => self.consecutive >= ERRORS_TO_LOSE,
            SensorState::Missing => {
                // A failed retry: back off.
                self.retry_ms = (self.retry_ms * 2).min(RETRY_MAX_MS);
                self.retry_at_us = t_us.saturating_add(self.retry_ms * 1000);
                false
            }
        };
        if !lose {
            return None;
        }
        self.state = SensorState::Missing;
        self.down_since_us = t_us;
        self.retry_ms = RETRY_FIRST_MS;
        self.retry_at_us = t_us.saturating_add(RETRY_FIRST_MS * 1000);
        Some(Event::SensorLost {
            sensor: self.sensor,
            t_us,
        })
    }

    /// While missing: is a retry (bus recovery + re-init) due at `t_us`?
    pub fn retry_due(&self, t_us: u64) -> bool {
        self.state == SensorState::Missing && t_us >= self.retry_at_us
    }

    /// µs until the next retry is due (0 if due or not missing).
    pub fn retry_in_us(&self, t_us: u64) -> u64 {
        if self.state == SensorState::Missing {
            self.retry_at_us.saturating_sub(t_us)
        } else {
            0
        }
    }
}
