//! The MPU-6050 service: what the IMU task does on each tick, generic over the bus and the delay
//! so the same code runs on the device and against the register-level model in the host tests.
//!
//! * **Samples**: the FIFO is drained in bursts; every frame gets its slot `k` on the part's
//!   sample grid by counting (consecutive frames are consecutive slots), and its time from the
//!   IMU's [`SampleClock`], which each FIFO-count read also feeds (docs/firmware.md,
//!   "Timestamps"). When the clock asks for it, the count read is placed so that it halves the
//!   clock's uncertainty.
//! * **Losses** are slots without a delivered sample. Whenever the FIFO's contents cannot be
//!   trusted (an overflow, a burst abandoned on a bus fault, a stall, a pause, an outage) the
//!   FIFO is restarted with its re-enabling write timed halfway between two sample instants, so
//!   the slot of the first frame after it is known exactly; the processing task counts the
//!   slots in between.
//! * **Faults**: a failed transfer is retried on the next tick (after a bus recovery for a bus
//!   fault), so a NACK burst shorter than the FIFO's span costs nothing; after
//!   [`crate::health::LOSE_AFTER_US`] of failures the sensor is lost and probed with back-off:
//!   when it answers, its configuration is read back and the part re-initialised only if that is
//!   gone. A re-initialisation starts the part's clock in step with its old grid (the waking
//!   write timed one period before a predicted sample instant), so the grid and the stamps
//!   continue across the outage. No data for [`crate::health::STALL_AFTER_US`] while the part
//!   answers is a stall: reported, and re-initialised with back-off until data comes back.
use embedded_hal_async::delay::DelayNs;
use embedded_hal_async::i2c::I2c;
use imu_drivers::asynch::Mpu6050;
use imu_drivers::mpu6050 as mpu;
use imu_proto::{Event, GapCause, Sensor, SensorState, Vec, IMU_PERIOD_US};

use crate::bus::{Failure, TransferTime};
use crate::clock::{self, fine, whole_us, BusTiming, Fine, SampleClock, US};
use crate::config::imu_config;
use crate::health::{Health, STALL_AFTER_US};
use crate::msg::{Out, Report, SensorMsg, BURST_MAX};
use crate::stage::{self, Stage};

/// Bytes of one FIFO frame (accel, temperature, gyro).
const FRAME: u16 = 14;
/// Time to set up a transfer after a wait, before its first bit.
const SETUP: u64 = 150 * US;
/// How far ahead a burst may wait for a probe instant (the burst must be done before the next
/// magnetometer read, 5 ms after the one that started it).
const PROBE_WAIT: u64 = 1200 * US;
/// Margin around a predicted sample instant within which the side of a write is uncertain
/// (beyond the clock's own interval): the latch of an interrupt-driven write varies by this.
const WRITE_MARGIN: u64 = 120 * US;
/// Messages kept free in a tick's output for reports.
const REPORT_ROOM: usize = 3;

/// Where the service is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Phase {
    /// Never initialised (boot), or its configuration is gone: initialise.
    Init,
    /// Draining the FIFO.
    Running,
    /// Not answering: probe with back-off.
    Lost,
    /// Answering, no data: wait for it, re-initialise with back-off.
    Stalled,
}

/// The IMU side.
pub struct ImuService {
    clock: SampleClock,
    health: Health,
    timing: BusTiming,
    phase: Phase,
    /// Slot of the oldest frame in the FIFO (the next to read).
    next_k: u32,
    /// The FIFO restarted or the part re-initialised: the first slot of its new run; no frame
    /// read since (the count cannot say sample `next_k − 1` was produced).
    fresh: bool,
    /// The cause of the discontinuity before the next frames delivered.
    after: Option<GapCause>,
    /// When the FIFO count last grew (or the run started), µs.
    last_growth_us: u64,
    /// A FIFO read was abandoned part-way: the frames in the FIFO are not aligned.
    misaligned: bool,
    /// Run a bus recovery before the next tick.
    recovery: bool,
    errors: u32,
    bus_faults: u32,
    /// The state the last report carried.
    reported: SensorState,
    overflows: u32,
    capacity: u16,
}

impl ImuService {
    /// A service for transfers timed as `timing` (the latch instants of the clock's
    /// observations).
    pub const fn new(timing: BusTiming) -> Self {
        Self {
            clock: SampleClock::new(IMU_PERIOD_US as u32),
            health: Health::new(Sensor::Imu),
            timing,
            phase: Phase::Init,
            next_k: 0,
            fresh: true,
            after: None,
            last_growth_us: 0,
            misaligned: false,
            recovery: false,
            errors: 0,
            bus_faults: 0,
            reported: SensorState::Unknown,
            overflows: 0,
            capacity: 1024,
        }
    }

    pub fn state(&self) -> SensorState {
        self.health.state()
    }

    /// The IMU's sample clock.
    pub fn clock(&self) -> &SampleClock {
        &self.clock
    }

    /// The bus needs recovering before the next tick (a bus fault, or a retry of a lost sensor).
    pub fn wants_recovery(&self, t_us: u64) -> bool {
        self.recovery || (self.phase == Phase::Lost && self.health.retry_due(t_us))
    }

    /// The caller recovered the bus.
    pub fn recovered(&mut self) {
        self.recovery = false;
    }

    /// After a pause (flash write): the FIFO's contents are not delivered; restart it.
    pub async fn resume<I, D>(
        &mut self,
        imu: &mut Mpu6050<I>,
        delay: &mut D,
        now: &impl Fn() -> u64,
        out: &mut Out,
    ) where
        I: I2c + TransferTime,
        D: DelayNs,
    {
        if self.phase == Phase::Running {
            self.restart_fifo(imu, delay, now, GapCause::Paused, out)
                .await;
        }
    }

    /// One service tick at `now()` µs.
    pub async fn tick<I, D>(
        &mut self,
        imu: &mut Mpu6050<I>,
        delay: &mut D,
        now: &impl Fn() -> u64,
        out: &mut Out,
    ) where
        I: I2c + TransferTime,
        D: DelayNs,
    {
        let t = now();
        match self.phase {
            Phase::Init => self.init(imu, delay, now, GapCause::SensorFault, out).await,
            Phase::Lost if self.health.retry_due(t) => self.retry_lost(imu, delay, now, out).await,
            Phase::Lost => {}
            Phase::Stalled if self.health.retry_due(t) => {
                self.health.retried(t);
                self.init(imu, delay, now, GapCause::Stalled, out).await;
                // Still stalled until data comes.
                self.phase = Phase::Stalled;
            }
            Phase::Running | Phase::Stalled => {
                if self.misaligned {
                    self.restart_fifo(imu, delay, now, GapCause::BusFault, out)
                        .await;
                } else {
                    self.drain(imu, delay, now, out).await;
                }
            }
        }
        self.flush_report(now(), None, out);
    }

    /// Identify, configure and start the part. A part that had a grid is started in step with
    /// it; its first sample is then the slot it lands on, and the slots since the last frame
    /// delivered are lost (`cause`).
    async fn init<I, D>(
        &mut self,
        imu: &mut Mpu6050<I>,
        delay: &mut D,
        now: &impl Fn() -> u64,
        cause: GapCause,
        out: &mut Out,
    ) where
        I: I2c + TransferTime,
        D: DelayNs,
    {
        if let Err(e) = imu.prepare(delay, &imu_config()).await {
            self.failed(&e, now(), out);
            return;
        }
        self.health.answered();
        self.capacity = imu.fifo_capacity().unwrap_or(1024);
        let period = self.clock.period();
        let latch = self.timing.latch(0, clock::WRITE_DATA_BIT);
        let keep = self.clock.known();
        let mut planned = 0;
        if keep {
            // The waking write's latch one period before a predicted instant.
            let earliest = fine(now()) + SETUP + latch + period;
            planned = self
                .clock
                .newest_at(earliest, 0)
                .unwrap_or(self.next_k)
                .wrapping_add(1);
            let start = self.clock.time(planned) - period - latch;
            delay_until(delay, now, start).await;
        }
        if let Err(e) = imu.start().await {
            self.failed(&e, now(), out);
            return;
        }
        let first = self
            .timing
            .latch(imu.bus().last_start(), clock::WRITE_DATA_BIT)
            + period;
        if keep {
            let k = self.clock.nearest(first);
            self.clock.start(k, first, true, WRITE_MARGIN);
            self.next_k = k;
            self.after.get_or_insert(cause);
            let _ = planned;
        } else {
            self.clock.start(0, first, false, 0);
            self.next_k = 0;
        }
        self.fresh = true;
        self.misaligned = false;
        self.last_growth_us = now();
        self.phase = Phase::Running;
    }

    /// A lost sensor's retry (the caller recovered the bus first): identity, then the
    /// configuration read back; re-initialise only if that is gone.
    async fn retry_lost<I, D>(
        &mut self,
        imu: &mut Mpu6050<I>,
        delay: &mut D,
        now: &impl Fn() -> u64,
        out: &mut Out,
    ) where
        I: I2c + TransferTime,
        D: DelayNs,
    {
        let t = now();
        self.health.retried(t);
        let intact = match imu.probe().await {
            Ok(_) => imu.config_intact().await,
            Err(e) => Err(e),
        };
        match intact {
            Ok(true) => {
                // It kept sampling: what the FIFO holds now is judged by its count (an overflow
                // restarts it, counting the slots exactly).
                self.health.answered();
                self.after.get_or_insert(GapCause::SensorFault);
                self.phase = Phase::Running;
                self.last_growth_us = t;
                self.drain(imu, delay, now, out).await;
            }
            Ok(false) => {
                self.health.answered();
                self.init(imu, delay, now, GapCause::SensorFault, out).await;
            }
            Err(e) => self.failed(&e, t, out),
        }
    }

    /// Drain the FIFO: count, then the frames, in bursts of up to [`BURST_MAX`].
    async fn drain<I, D>(
        &mut self,
        imu: &mut Mpu6050<I>,
        delay: &mut D,
        now: &impl Fn() -> u64,
        out: &mut Out,
    ) where
        I: I2c + TransferTime,
        D: DelayNs,
    {
        // A probe instant shortly ahead: wait for it, so the count read halves the clock's
        // uncertainty about where the samples fall.
        let count_latch = self.timing.latch(0, clock::READ_SECOND_BIT);
        let t0 = fine(now());
        if let Some(p) = self.clock.probe_after(t0 + SETUP + count_latch) {
            if p - t0 < PROBE_WAIT + SETUP + count_latch {
                delay_until(delay, now, p - count_latch).await;
            }
        }
        while out.len() + REPORT_ROOM <= out.capacity() {
            stage::enter(Stage::I2c);
            let count = imu.fifo_count().await;
            let read_at = now();
            stage::leave();
            let count = match count {
                Ok(c) => c,
                Err(e) => {
                    self.failed(&e, read_at, out);
                    return;
                }
            };
            self.health.answered();
            let tau = self
                .timing
                .latch(imu.bus().last_start(), clock::READ_SECOND_BIT);
            if count >= self.capacity
                || count_may_be_stale(count, read_at.saturating_sub(whole_us(tau)), self.capacity)
            {
                self.overflows += 1;
                self.restart_fifo(imu, delay, now, GapCause::FifoOverflow, out)
                    .await;
                return;
            }
            let frames = frames_in(count);
            // Sample `next_k + frames − 1` was produced by the latch, `next_k + frames` not.
            if frames > 0 || !self.fresh {
                let newest = self.next_k.wrapping_add(u32::from(frames)).wrapping_sub(1);
                // A count that crossed 255 between its two bytes is not trusted for timing.
                if count < 256 {
                    self.clock.observe(tau, newest, true, frames > 0);
                }
            }
            if frames == 0 {
                if read_at.saturating_sub(self.last_growth_us) >= STALL_AFTER_US {
                    if let Some(e) = self.health.stalled(read_at, self.last_growth_us) {
                        self.phase = Phase::Stalled;
                        self.report(read_at, Some(e), out);
                    }
                }
                return;
            }
            self.last_growth_us = read_at;
            if self.phase == Phase::Stalled {
                // Data again after a stall: the frames' slots are not known by counting (the
                // part produced nothing for a while); restart the FIFO to know them.
                self.restart_fifo(imu, delay, now, GapCause::Stalled, out)
                    .await;
                return;
            }
            let slot = out.len();
            let _ = out.push(SensorMsg::Imu {
                stamps: Default::default(),
                samples: Vec::new(),
                after: None,
            });
            let Some(SensorMsg::Imu { samples, .. }) = out.last_mut() else {
                return;
            };
            stage::enter(Stage::I2c);
            let r = imu
                .read_fifo_counted_with(count, BURST_MAX, |s| {
                    // At most BURST_MAX frames: never full.
                    let _ = samples.push(s);
                })
                .await;
            stage::leave();
            let n = match r {
                Ok(n) => n,
                Err(e) => {
                    out.truncate(slot);
                    if let mpu::Error::Bus(b) = &e {
                        // Bytes may have moved: the FIFO is no longer aligned.
                        self.misaligned |= Failure::of(b).partial();
                    }
                    self.failed(&e, now(), out);
                    return;
                }
            };
            let stamps = self.clock.stamps(self.next_k, n as u32);
            let after = self.after.take();
            if let Some(SensorMsg::Imu {
                stamps: s,
                after: a,
                ..
            }) = out.last_mut()
            {
                *s = stamps;
                *a = after;
            }
            self.next_k = self.next_k.wrapping_add(n as u32);
            self.fresh = false;
            if let Some(e) = self.health.delivering(read_at) {
                self.report(read_at, Some(e), out);
            }
            if n < BURST_MAX {
                return;
            }
        }
    }

    /// Empty the FIFO and start it again with the enabling write halfway between two sample
    /// instants: the first frame after it is the first slot after that write, exactly.
    async fn restart_fifo<I, D>(
        &mut self,
        imu: &mut Mpu6050<I>,
        delay: &mut D,
        now: &impl Fn() -> u64,
        cause: GapCause,
        out: &mut Out,
    ) where
        I: I2c + TransferTime,
        D: DelayNs,
    {
        let latch = self.timing.latch(0, clock::WRITE_DATA_BIT);
        for _ in 0..3 {
            if let Err(e) = imu.stop_fifo().await {
                self.failed(&e, now(), out);
                return;
            }
            let target = self.clock.mid_slot_after(fine(now()) + SETUP + latch);
            delay_until(delay, now, target - latch).await;
            if let Err(e) = imu.start_fifo().await {
                self.failed(&e, now(), out);
                return;
            }
            let tau = self
                .timing
                .latch(imu.bus().last_start(), clock::WRITE_DATA_BIT);
            let margin = if self.timing.bit == 0 {
                0
            } else {
                WRITE_MARGIN
            };
            let Some(k) = self.clock.first_after(tau, margin) else {
                // Too close to a sample instant to tell its side (a delayed write): again.
                continue;
            };
            self.health.answered();
            self.next_k = k;
            self.fresh = true;
            self.misaligned = false;
            self.after.get_or_insert(cause);
            self.last_growth_us = now();
            if self.phase == Phase::Stalled {
                self.phase = Phase::Running;
            }
            return;
        }
        // Three writes all uncertain (the clock has no phase yet): the midline's guess.
        let tau = self
            .timing
            .latch(imu.bus().last_start(), clock::WRITE_DATA_BIT);
        self.next_k = self.clock.nearest(tau + self.clock.period() / 2);
        self.fresh = true;
        self.misaligned = false;
        self.after.get_or_insert(cause);
        self.last_growth_us = now();
    }

    /// A transfer failed at `t`.
    fn failed<E: embedded_hal::i2c::Error>(&mut self, e: &mpu::Error<E>, t: u64, out: &mut Out) {
        let failure = match e {
            mpu::Error::Bus(b) => Failure::of(b),
            _ => Failure::Other,
        };
        self.errors += 1;
        if let Some(fault) = failure.bus_fault() {
            self.bus_faults += 1;
            self.recovery = true;
            self.report(t, Some(Event::BusFault { t_us: t, fault }), out);
        }
        if let Some(lost) = self.health.failed(t) {
            self.phase = Phase::Lost;
            self.report(t, Some(lost), out);
        }
    }

    /// Queue a report with `event` (the counters go with the first report of the tick).
    fn report(&mut self, _t: u64, event: Option<Event>, out: &mut Out) {
        self.reported = self.health.state();
        let r = Report {
            sensor: Sensor::Imu,
            state: self.health.state(),
            i2c_errors: core::mem::take(&mut self.errors),
            bus_faults: core::mem::take(&mut self.bus_faults),
            fifo_overflows: core::mem::take(&mut self.overflows),
            period_ns: self.clock.period_ns(),
            event,
        };
        let _ = out.push(SensorMsg::Report(r));
    }

    /// A report of the counters if any changed this tick.
    fn flush_report(&mut self, t: u64, event: Option<Event>, out: &mut Out) {
        if self.errors | self.bus_faults | self.overflows != 0
            || self.reported != self.health.state()
        {
            self.report(t, event, out);
        }
    }
}

/// Whole frames in `count` FIFO bytes: `count / 14` by multiplication (the M0+ has no divide
/// instruction); exact up to 4096 bytes, four times the largest FIFO (tested).
fn frames_in(count: u16) -> u16 {
    ((u32::from(count) * 4682) >> 16) as u16
}

/// Whether the FIFO may have overflowed since `count` was read, `dt_us` ago (the task was held
/// up between the count transfer and the data transfer, e.g. by a stall): the count cannot show
/// such an overflow, and the frames read after it would be misaligned. The FIFO gains at most
/// one frame per 512 µs (1 kHz with margin for the part's clock) plus one in progress.
pub fn count_may_be_stale(count: u16, dt_us: u64, capacity: u16) -> bool {
    u64::from(count) + u64::from(FRAME) * ((dt_us >> 9) + 1) >= u64::from(capacity)
}

/// Sleep until the [`Fine`] instant `t` (at once if it has passed).
async fn delay_until<D: DelayNs>(delay: &mut D, now: &impl Fn() -> u64, t: Fine) {
    let at = whole_us(t);
    let n = now();
    if at > n {
        delay
            .delay_us((at - n).min(u64::from(u32::MAX)) as u32)
            .await;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_by_multiplication_equal_division() {
        for c in 0..=4096 {
            assert_eq!(frames_in(c), c / FRAME, "{c}");
        }
    }
}
