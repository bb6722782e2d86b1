//! The QMC5883L service: one reading per tick, at the instant the part's [`SampleClock`] says
//! its next sample has landed.
//!
//! * **Timing**: each tick's status poll is latched just after the predicted landing of the next
//!   sample (`t̂ + hi`, the late end of the clock's uncertainty, plus [`POLL_MARGIN`]), so it
//!   finds DRDY set. While the clock's uncertainty is wide, the poll is latched at the predicted
//!   instant instead: DRDY set or clear there halves the uncertainty (a clear one is polled again
//!   at the late end). The reading's slot is the newest sample instant before its data read; when
//!   that read came too close to an instant to tell, the status is polled once more after it
//!   (DRDY set again: the read was the sample before).
//! * **Losses**: readings are slots of the grid; slots skipped (the part overwrote them before
//!   they were read: DOR) are counted by the processing task from the slot numbers.
//! * **Faults** as for the IMU ([`crate::imu`]): retries, loss after
//!   [`crate::health::LOSE_AFTER_US`], configuration read back before a re-initialisation,
//!   restart in step with the old grid (the CONTROL1 write one period before a predicted
//!   instant), a stall (no DRDY for [`crate::health::STALL_AFTER_US`]) reported and re-initialised
//!   with back-off.
use embedded_hal_async::delay::DelayNs;
use embedded_hal_async::i2c::I2c;
use imu_drivers::asynch::Qmc5883;
use imu_drivers::qmc5883 as qmc;
use imu_proto::{Event, GapCause, Sensor, SensorState, MAG_PERIOD_US};

use crate::bus::{Failure, TransferTime};
use crate::clock::{self, fine, whole_us, BusTiming, Fine, SampleClock, US};
use crate::config::mag_config;
use crate::health::{Health, STALL_AFTER_US};
use crate::msg::{Out, Report, SensorMsg};

/// How long after the late end of the clock's uncertainty a poll is latched.
pub const POLL_MARGIN: u64 = 20 * US;
/// Margin around a sample instant within which a read's side is uncertain (beyond the clock's
/// own interval).
const READ_MARGIN: u64 = 10 * US;
/// Shortest wait between two status polls of one tick.
const REPOLL_MIN: u64 = 100 * US;
/// Status polls in one tick (the first and its re-polls).
const POLLS: u32 = 4;
/// Time to set up a transfer after a wait, before its first bit.
const SETUP: u64 = 150 * US;
/// Margin around the waking write's latch (interrupt-driven transfer).
const WRITE_MARGIN: u64 = 120 * US;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Phase {
    Init,
    Running,
    Lost,
    Stalled,
}

/// The magnetometer side.
pub struct MagService {
    clock: SampleClock,
    health: Health,
    timing: BusTiming,
    phase: Phase,
    /// Slot of the next sample to read.
    next_k: u32,
    /// No reading since the part was started: `next_k − 1` is not a sample of this run.
    fresh: bool,
    after: Option<GapCause>,
    last_growth_us: u64,
    recovery: bool,
    errors: u32,
    bus_faults: u32,
    /// The state the last report carried.
    reported: SensorState,
    /// When the next tick should start, µs (`None`: the caller's own schedule).
    next_poll_us: Option<u64>,
}

impl MagService {
    pub const fn new(timing: BusTiming) -> Self {
        Self {
            clock: SampleClock::new(MAG_PERIOD_US as u32),
            health: Health::new(Sensor::Mag),
            timing,
            phase: Phase::Init,
            next_k: 0,
            fresh: true,
            after: None,
            last_growth_us: 0,
            recovery: false,
            errors: 0,
            bus_faults: 0,
            reported: SensorState::Unknown,
            next_poll_us: None,
        }
    }

    pub fn state(&self) -> SensorState {
        self.health.state()
    }

    /// The magnetometer's sample clock.
    pub fn clock(&self) -> &SampleClock {
        &self.clock
    }

    /// When the next tick should start, µs since boot (`None`: no grid yet, or the part is out:
    /// use the caller's own schedule).
    pub fn next_poll_us(&self) -> Option<u64> {
        self.next_poll_us
    }

    pub fn wants_recovery(&self, t_us: u64) -> bool {
        self.recovery || (self.phase == Phase::Lost && self.health.retry_due(t_us))
    }

    pub fn recovered(&mut self) {
        self.recovery = false;
    }

    /// After a pause (flash write): the samples missed meanwhile are counted as lost to it.
    pub fn resume(&mut self) {
        if self.phase == Phase::Running {
            self.after.get_or_insert(GapCause::Paused);
        }
    }

    /// One tick at `now()` µs.
    pub async fn tick<I, D>(
        &mut self,
        mag: &mut Qmc5883<I>,
        delay: &mut D,
        now: &impl Fn() -> u64,
        out: &mut Out,
    ) where
        I: I2c + TransferTime,
        D: DelayNs,
    {
        let t = now();
        self.next_poll_us = None;
        match self.phase {
            Phase::Init => self.init(mag, delay, now, GapCause::SensorFault, out).await,
            Phase::Lost if self.health.retry_due(t) => {
                self.health.retried(t);
                let intact = match mag.chip_id().await {
                    Ok(id) if id == mag.variant().chip_id().1 => mag.config_intact().await,
                    Ok(found) => Err(qmc::Error::WrongChip { found }),
                    Err(e) => Err(e),
                };
                match intact {
                    Ok(true) => {
                        self.health.answered();
                        self.after.get_or_insert(GapCause::SensorFault);
                        self.phase = Phase::Running;
                        self.last_growth_us = t;
                    }
                    Ok(false) => {
                        self.health.answered();
                        self.init(mag, delay, now, GapCause::SensorFault, out).await;
                    }
                    Err(e) => self.failed(&e, t, out),
                }
            }
            Phase::Lost => {}
            Phase::Stalled if self.health.retry_due(t) => {
                self.health.retried(t);
                self.init(mag, delay, now, GapCause::Stalled, out).await;
                if self.phase == Phase::Running {
                    self.phase = Phase::Stalled;
                }
            }
            Phase::Running | Phase::Stalled => self.read(mag, delay, now, out).await,
        }
        if self.errors | self.bus_faults != 0 || self.reported != self.health.state() {
            self.report(None, out);
        }
        if self.next_poll_us.is_none() && matches!(self.phase, Phase::Running | Phase::Stalled) {
            self.schedule(now());
        }
    }

    async fn init<I, D>(
        &mut self,
        mag: &mut Qmc5883<I>,
        delay: &mut D,
        now: &impl Fn() -> u64,
        cause: GapCause,
        out: &mut Out,
    ) where
        I: I2c + TransferTime,
        D: DelayNs,
    {
        if let Err(e) = mag.prepare(delay, &mag_config()).await {
            self.failed(&e, now(), out);
            return;
        }
        self.health.answered();
        let period = self.clock.period();
        let latch = self.timing.latch(0, clock::WRITE_DATA_BIT);
        let keep = self.clock.known();
        if keep {
            let earliest = fine(now()) + SETUP + latch + period;
            let k = self
                .clock
                .newest_at(earliest, 0)
                .unwrap_or(self.next_k)
                .wrapping_add(1);
            delay_until(delay, now, self.clock.time(k) - period - latch).await;
        }
        if let Err(e) = mag.start().await {
            self.failed(&e, now(), out);
            return;
        }
        let first = self
            .timing
            .latch(mag.bus().last_start(), clock::WRITE_DATA_BIT)
            + period;
        if keep {
            let k = self.clock.nearest(first);
            self.clock.start(k, first, true, WRITE_MARGIN);
            self.next_k = k;
            self.after.get_or_insert(cause);
        } else {
            self.clock.start(0, first, false, 0);
            self.next_k = 0;
        }
        self.fresh = true;
        self.last_growth_us = now();
        self.phase = Phase::Running;
        self.schedule(now());
    }

    /// The next tick: the first poll's latch just after the late end of the uncertainty about
    /// the next sample's landing, or at the predicted landing itself when the uncertainty is
    /// wide (a probe). A landing already past (samples missed, a stall) gives way to the next
    /// one predicted after `now_us`.
    fn schedule(&mut self, now_us: u64) {
        let latch = self.timing.latch(0, clock::READ_FIRST_BIT);
        let offset = if self.clock.probe_after(0).is_some() {
            0
        } else {
            (self.clock.width() / 2 + POLL_MARGIN) as i64
        };
        let due = self.clock.time(self.next_k).wrapping_add(offset as u64);
        let earliest = fine(now_us) + SETUP + latch;
        let at = if due >= earliest {
            due
        } else {
            self.clock.instant_after(earliest, offset)
        };
        self.next_poll_us = Some(whole_us(at - latch));
    }

    /// Poll the status (again, up to [`POLLS`] times) and read the sample when DRDY is set.
    async fn read<I, D>(
        &mut self,
        mag: &mut Qmc5883<I>,
        delay: &mut D,
        now: &impl Fn() -> u64,
        out: &mut Out,
    ) where
        I: I2c + TransferTime,
        D: DelayNs,
    {
        let status_latch = self.timing.latch(0, clock::READ_FIRST_BIT);
        // A "not yet" seen this tick, kept to be trusted if a later poll finds the sample (the
        // part is producing, so the phase was late, not the part stalled).
        let mut not_yet: Option<Fine> = None;
        for poll in 0..POLLS {
            let status = mag.status().await;
            let t = now();
            let status = match status {
                Ok(s) => s,
                Err(e) => {
                    self.failed(&e, t, out);
                    return;
                }
            };
            self.health.answered();
            let tau = self
                .timing
                .latch(mag.bus().last_start(), clock::READ_FIRST_BIT);
            if !status.ready {
                if !self.fresh {
                    // Sample `next_k` not yet landed: a lower bound, unless the part stalled.
                    self.clock
                        .observe(tau, self.next_k.wrapping_sub(1), true, false);
                }
                not_yet = Some(tau);
                if t.saturating_sub(self.last_growth_us) >= STALL_AFTER_US {
                    if let Some(e) = self.health.stalled(t, self.last_growth_us) {
                        self.phase = Phase::Stalled;
                        self.report(Some(e), out);
                    }
                    return;
                }
                if poll + 1 == POLLS {
                    return;
                }
                // Poll again at the late end of the uncertainty (or a little later).
                let late = self.clock.time(self.next_k) + self.clock.width() / 2 + POLL_MARGIN;
                let at = late.max(tau + REPOLL_MIN);
                delay_until(delay, now, at - status_latch).await;
                continue;
            }
            if let Some(before) = not_yet {
                if !self.fresh {
                    self.clock
                        .observe(before, self.next_k.wrapping_sub(1), true, true);
                }
            }
            self.clock.observe(tau, self.next_k, false, false);
            let xyz = match mag.read_data().await {
                Ok(xyz) => xyz,
                Err(e) => {
                    self.failed(&e, now(), out);
                    return;
                }
            };
            let t_data = self
                .timing
                .latch(mag.bus().last_start(), clock::READ_FIRST_BIT);
            // The slot read. DOR clear: one sample landed since the last read, the next one due,
            // unless the clock says the grid has moved on past it (a part that produced nothing
            // for a while). DOR set (samples overwritten unread): the newest landed before the
            // data read, by the clock.
            let by_clock = self.clock.newest_at(t_data, READ_MARGIN);
            let later = |k: u32| k.wrapping_sub(self.next_k).wrapping_sub(1) < 1 << 31;
            let k = if !status.skipped {
                match by_clock {
                    Some(k) if later(k) => k,
                    Some(_) => self.next_k,
                    // Too close to an instant `j` to tell `j − 1` from `j`: only if both are past
                    // the one due does it matter.
                    None if later(self.clock.nearest(t_data).wrapping_sub(1)) => {
                        self.resolve(mag, delay, now, t_data).await
                    }
                    None => self.next_k,
                }
            } else {
                let k = match by_clock {
                    Some(k) => k,
                    None => self.resolve(mag, delay, now, t_data).await,
                };
                // Never an older slot than the next one due (the sample just read is new).
                if self.fresh || k.wrapping_sub(self.next_k) < 1 << 31 {
                    k
                } else {
                    self.next_k
                }
            };
            let _ = out.push(SensorMsg::Mag {
                stamps: self.clock.stamps(k, 1),
                xyz,
                after: self.after.take(),
            });
            self.next_k = k.wrapping_add(1);
            self.fresh = false;
            self.last_growth_us = t;
            if self.phase == Phase::Stalled {
                self.phase = Phase::Running;
            }
            if let Some(e) = self.health.delivering(t) {
                self.report(Some(e), out);
            }
            return;
        }
    }

    /// A data read latched too close to a sample instant `j` to tell whether it read `j − 1`
    /// or `j`: poll once more after the instant. DRDY set again means `j` landed after the
    /// read (the read was `j − 1`); clear means the read took `j`.
    async fn resolve<I, D>(
        &mut self,
        mag: &mut Qmc5883<I>,
        delay: &mut D,
        now: &impl Fn() -> u64,
        t_data: Fine,
    ) -> u32
    where
        I: I2c + TransferTime,
        D: DelayNs,
    {
        let j = self.clock.nearest(t_data);
        let latch = self.timing.latch(0, clock::READ_FIRST_BIT);
        let after = self.clock.time(j) + self.clock.width() / 2 + POLL_MARGIN;
        delay_until(delay, now, after - latch).await;
        match mag.status().await {
            Ok(s) if s.ready => j.wrapping_sub(1),
            _ => j,
        }
    }

    fn failed<E: embedded_hal::i2c::Error>(&mut self, e: &qmc::Error<E>, t: u64, out: &mut Out) {
        let failure = match e {
            qmc::Error::Bus(b) => Failure::of(b),
            _ => Failure::Other,
        };
        self.errors += 1;
        if let Some(fault) = failure.bus_fault() {
            self.bus_faults += 1;
            self.recovery = true;
            self.report(Some(Event::BusFault { t_us: t, fault }), out);
        }
        if let Some(lost) = self.health.failed(t) {
            self.phase = Phase::Lost;
            self.report(Some(lost), out);
        }
    }

    fn report(&mut self, event: Option<Event>, out: &mut Out) {
        self.reported = self.health.state();
        let r = Report {
            sensor: Sensor::Mag,
            state: self.health.state(),
            i2c_errors: core::mem::take(&mut self.errors),
            bus_faults: core::mem::take(&mut self.bus_faults),
            fifo_overflows: 0,
            period_ns: self.clock.period_ns(),
            event,
        };
        let _ = out.push(SensorMsg::Report(r));
    }
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

/// A task's fixed slots: `offset_us` past each multiple of `period_us` since boot (the
/// magnetometer task's schedule while its sensor has no grid). A slot that has already passed is
/// skipped, not caught up.
#[derive(Debug, Clone, Copy)]
pub struct Slots {
    period_us: u64,
    offset_us: u64,
    /// The slot returned last (0: none yet).
    last_us: u64,
}

impl Slots {
    pub const fn new(period_us: u64, offset_us: u64) -> Self {
        Self {
            period_us,
            offset_us,
            last_us: 0,
        }
    }

    /// The first slot after `now_us`. When the previous slot has passed and the one after it
    /// has not (a task that kept up), that is one addition; otherwise a 64-bit division.
    pub fn next_after(&mut self, now_us: u64) -> u64 {
        let following = self.last_us + self.period_us;
        self.last_us = if self.last_us != 0 && self.last_us <= now_us && now_us < following {
            following
        } else {
            let k = now_us.saturating_sub(self.offset_us) / self.period_us + 1;
            k * self.period_us + self.offset_us
        };
        self.last_us
    }
}
