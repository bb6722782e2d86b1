//! What the two sensor services ([`crate::imu`], [`crate::mag`]) share: where the part is
//! (its [`Phase`]), its sample grid and clock, its health and the failures counted since the
//! last report, the report itself, and the (re)start of a part in step with its old grid.
use embedded_hal_async::delay::DelayNs;
use imu_proto::{Event, GapCause, Sensor, SensorState};

use crate::bus::Failure;
use crate::clock::{self, fine, whole_us, BusTiming, Fine, SampleClock};
use crate::health::{Health, STALL_AFTER_US};
use crate::msg::{Out, Report, SensorMsg};

/// Time to set up a transfer after a wait, before its first bit.
pub const SETUP: Fine = fine(150);
/// Margin around the latch of a part's waking write (an interrupt-driven transfer: its latch
/// varies by this beyond the clock's own uncertainty).
pub const WRITE_MARGIN: Fine = fine(120);

/// How much longer than its bits a transfer may take (set-up, the task being polled late) before
/// it counts as held on the bus.
pub const HELD_MARGIN: Fine = fine(1500);

/// Where a service is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Phase {
    /// Never initialised (boot), or its configuration is gone: initialise.
    Init,
    /// Delivering samples.
    Running,
    /// Not answering: probe with back-off.
    Lost,
    /// Answering, no data: wait for it, re-initialise with back-off.
    Stalled,
}

/// A sensor service's shared state.
pub struct Core {
    sensor: Sensor,
    pub clock: SampleClock,
    pub health: Health,
    pub timing: BusTiming,
    pub phase: Phase,
    /// Slot of the next sample to deliver.
    pub next_k: u32,
    /// The part (or its FIFO) was (re)started: the first slot of its new run; nothing delivered
    /// since, so `next_k − 1` is not a sample of this run.
    pub fresh: bool,
    /// The cause of the discontinuity before the next samples delivered.
    pub after: Option<GapCause>,
    /// When data last came (or the run started), µs.
    pub last_growth_us: u64,
    /// Run a bus recovery before the next tick.
    recovery: bool,
    errors: u32,
    bus_faults: u32,
    /// FIFO overflows since the last report.
    pub overflows: u32,
    /// The state the last report carried.
    reported: SensorState,
}

/// How much earlier than the instant it should start a placed transfer (a probe) must be begun:
/// the latency between the end of a wait and the transfer's first bit (the task's wake-up, the
/// bus lock, the transfer's set-up), learnt from every placed transfer by halving the residual
/// each time. Without it a probe lands that much after the middle of the clock's interval and
/// cuts it far from the half; with it probes halve the interval and so are needed rarely.
///
/// A transfer that starts later than aimed is latency not learnt yet, or a wait that ended
/// while another task held the CPU (a processing poll of up to ≈ 0.5 ms): only up to
/// [`Lead::STEP`] of the lateness is learnt from one transfer. (Learnt whole, one wait held up
/// by a processing poll made the lead ≈ 100 µs too long, and the magnetometer's next probes
/// latched before its interval, narrowing nothing, until the lead came back by halves:
/// docs/benchmarks.md, "The frame scan a word at a time, a burst's buffer kept, and the lead's
/// step".) A transfer that starts early always means a lead too long, and is learnt whole.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Lead(Fine);

impl Lead {
    /// The largest lead learnt (a wait that ended late by more is an outlier, not latency).
    pub const MAX: Fine = fine(200);
    /// The most of a late start one transfer teaches: the lead grows by at most half this.
    pub const STEP: Fine = fine(16);

    pub const fn new() -> Self {
        Lead(Fine::ZERO)
    }

    /// When to begin a transfer that should start at `start`.
    pub fn begin(&self, start: Fine) -> Fine {
        start.saturating_sub(self.0)
    }

    /// A transfer meant to start at `aimed` (begun at [`Lead::begin`] of it) started at
    /// `started`.
    pub fn learn(&mut self, aimed: Fine, started: Fine) {
        let residual = started.since(aimed).min(Self::STEP.raw() as i64);
        let lead = (self.0.raw() as i64 + residual / 2).clamp(0, Self::MAX.raw() as i64);
        self.0 = Fine::from_raw(lead as u64);
    }

    pub fn get(&self) -> Fine {
        self.0
    }
}

impl Core {
    /// A service of `sensor`, whose nominal sample period is `nominal_us`, over a bus timed as
    /// `timing`.
    pub const fn new(sensor: Sensor, nominal_us: u32, timing: BusTiming) -> Self {
        Core {
            sensor,
            // The IMU counts its samples in its FIFO; the magnetometer's are numbered by the
            // clock.
            clock: match sensor {
                Sensor::Imu => SampleClock::new(nominal_us).counted(),
                Sensor::Mag => SampleClock::new(nominal_us),
            },
            health: Health::new(sensor),
            timing,
            phase: Phase::Init,
            next_k: 0,
            fresh: true,
            after: None,
            last_growth_us: 0,
            recovery: false,
            errors: 0,
            bus_faults: 0,
            overflows: 0,
            reported: SensorState::Unknown,
        }
    }

    /// The bus needs recovering before the next tick (a bus fault, or a retry of a lost sensor).
    pub fn wants_recovery(&self, t_us: u64) -> bool {
        self.recovery || (self.phase == Phase::Lost && self.health.retry_due(t_us))
    }

    /// The caller recovered the bus.
    pub fn recovered(&mut self) {
        self.recovery = false;
    }

    /// A transfer that started at `start` went through: the sensor answers. Returns the instant
    /// its byte at `bit` was latched (the time of what it read).
    pub fn answered(&mut self, start: Fine, bit: u64) -> Fine {
        self.health.answered();
        self.timing.latch(start, bit)
    }

    /// Whether a transfer of `bits` SCL periods that started at `start`, seen done at `end_us`,
    /// was held on the bus: it took more than [`HELD_MARGIN`] beyond its bits (a START that could
    /// not be sent while a slave held SDA, a slave stretching SCL), so when its bytes moved is not
    /// known from its start.
    pub fn held(&self, start: Fine, bits: u64, end_us: u64) -> bool {
        fine(end_us).wrapping_sub(start) > self.timing.duration(bits) + HELD_MARGIN
    }

    /// A transfer failed at `t` (`failure`: what the bus said): counted; a bus fault asks for a
    /// recovery and is reported; failures for long enough lose the sensor.
    pub fn failed(&mut self, failure: Failure, t: u64, out: &mut Out) {
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

    /// A look for a lost part at `t`: whether it is a retry the back-off timed (then counted
    /// as one, and the next backed off).
    pub fn look_due(&mut self, t: u64) -> bool {
        let due = self.health.retry_due(t);
        if due {
            self.health.retried(t);
        }
        due
    }

    /// A lost part looked for at `t` answered with its configuration intact: it runs again,
    /// the slots since its last sample lost to the fault.
    pub fn found_intact(&mut self, t: u64) {
        self.health.answered();
        self.after.get_or_insert(GapCause::SensorFault);
        self.phase = Phase::Running;
        self.last_growth_us = t;
    }

    /// A look for a lost part failed at `t`: counted like any failure when it was a retry the
    /// back-off timed (`due`) or the bus's fault, not when the part just did not answer (it is
    /// known lost; looked for on every tick, each such look would be an error and a report).
    pub fn look_failed(&mut self, failure: Failure, due: bool, t: u64, out: &mut Out) {
        if due || failure.bus_fault().is_some() {
            self.failed(failure, t, out);
        }
    }

    /// No data at `t`: after [`STALL_AFTER_US`] without any the part is stalled (reported the
    /// first time). Returns whether it is.
    pub fn no_data(&mut self, t: u64, out: &mut Out) -> bool {
        if t.saturating_sub(self.last_growth_us) < STALL_AFTER_US {
            return false;
        }
        if let Some(e) = self.health.stalled(t, self.last_growth_us) {
            self.phase = Phase::Stalled;
            self.report(Some(e), out);
        }
        true
    }

    /// Queue a report with `event`; it carries the counters since the previous one.
    pub fn report(&mut self, event: Option<Event>, out: &mut Out) {
        self.reported = self.health.state();
        let r = Report {
            sensor: self.sensor,
            state: self.health.state(),
            i2c_errors: core::mem::take(&mut self.errors),
            bus_faults: core::mem::take(&mut self.bus_faults),
            fifo_overflows: core::mem::take(&mut self.overflows),
            period_ns: self.clock.period_ns(),
            event,
        };
        let _ = out.push(SensorMsg::Report(r));
    }

    /// A report of the counters if any changed, or the state, since the last one.
    pub fn flush_report(&mut self, out: &mut Out) {
        if self.errors | self.bus_faults | self.overflows != 0
            || self.reported != self.health.state()
        {
            self.report(None, out);
        }
    }

    /// Before the write that wakes the part: a part with a grid is restarted in step with it,
    /// so wait until that write's latch falls one period before a predicted sample instant
    /// (its first sample then lands on that instant). Without a grid, at once.
    pub async fn wait_to_start<D: DelayNs>(&self, delay: &mut D, now: &dyn Fn() -> u64) {
        if !self.clock.known() {
            return;
        }
        let period = self.clock.period();
        let latch = self.timing.latch(Fine::ZERO, clock::WRITE_DATA_BIT);
        let earliest = fine(now()) + SETUP + latch + period;
        let mut planned = self
            .clock
            .newest_at(earliest, Fine::ZERO)
            .unwrap_or(self.next_k)
            .wrapping_add(1);
        // Aimed at the part's first grid (the line may sit off it after a restart held up).
        if self.clock.origin_time(planned) < earliest {
            planned = planned.wrapping_add(1);
        }
        delay_until(delay, now, self.clock.origin_time(planned) - period - latch).await;
    }

    /// The waking write's transfer started at `start`: the part samples from one period after
    /// its latch. A part that had a grid, and was seen producing on it, continues it (the
    /// slots since the last delivered sample are lost to `cause`); otherwise a new grid starts
    /// at the next slot due (0 at the first start). (A grid only implied by a waking write,
    /// the part stalled or gone before its first sample, is not the part's: continued, the
    /// emulator's magnetometer, gone from 10 ms after boot to 0.79 s, had every reading
    /// numbered 154 slots on.)
    pub fn started(&mut self, start: Fine, cause: GapCause, now_us: u64) {
        let first = self.timing.latch(start, clock::WRITE_DATA_BIT) + self.clock.period();
        if self.clock.known() && self.clock.confirmed() {
            let k = self.clock.origin_nearest(first);
            self.clock.start(k, first, true, WRITE_MARGIN);
            self.next_k = k;
            self.after.get_or_insert(cause);
        } else {
            self.clock.start(self.next_k, first, false, Fine::ZERO);
        }
        self.fresh = true;
        self.last_growth_us = now_us;
        self.phase = Phase::Running;
    }
}

/// One tick's context: the sensor's driver, the delay, the µs clock and the tick's output.
pub struct Tick<'a, S, D> {
    pub dev: &'a mut S,
    pub delay: &'a mut D,
    pub now: &'a dyn Fn() -> u64,
    pub out: &'a mut Out,
}

impl<'a, S, D> Tick<'a, S, D> {
    pub fn new(
        dev: &'a mut S,
        delay: &'a mut D,
        now: &'a dyn Fn() -> u64,
        out: &'a mut Out,
    ) -> Self {
        Tick {
            dev,
            delay,
            now,
            out,
        }
    }
}

/// Sleep until the [`Fine`] instant `t` (at once if it has passed).
pub async fn delay_until<D: DelayNs>(delay: &mut D, now: &dyn Fn() -> u64, t: Fine) {
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
    use crate::clock::US;

    /// Transfers that start a fixed latency after their wait ends: within a few transfers they
    /// start where they are aimed, to well under a µs; a latency that changes is followed; a
    /// wait that ended absurdly late moves the lead by at most half a step, one that ended
    /// absurdly early takes it to zero.
    #[test]
    fn the_lead_learns_the_latency_and_placed_transfers_land_where_aimed() {
        let mut lead = Lead::default();
        let mut aimed = fine(1_000_000);
        let mut run = |lead: &mut Lead, latency: Fine, n: usize| {
            let mut miss = Fine::ZERO;
            for _ in 0..n {
                let started = lead.begin(aimed) + latency;
                miss = started.abs_diff(aimed);
                lead.learn(aimed, started);
                aimed += fine(10_000);
            }
            miss
        };
        assert_eq!(
            run(&mut lead, 11 * US, 1),
            11 * US,
            "the first lands a latency late"
        );
        assert!(run(&mut lead, 11 * US, 7) < US / 8);
        assert!(lead.get().abs_diff(11 * US) < US / 8);
        assert!(run(&mut lead, 30 * US, 10) < US / 8);
        let before = lead.get();
        lead.learn(aimed, aimed + fine(10_000));
        assert_eq!(lead.get(), before + Lead::STEP / 2);
        lead.learn(aimed, aimed - fine(10_000));
        assert_eq!(lead.get(), Fine::ZERO);
        // Up to the bound, a step at a time.
        for _ in 0..40 {
            lead.learn(aimed, aimed + fine(10_000));
        }
        assert_eq!(lead.get(), Lead::MAX);
    }

    /// A placed transfer whose wait ended while the CPU was held (drawn: 50–450 µs late, at a
    /// drawn latency and a drawn moment of a run; a fresh draw each run, its key printed)
    /// leaves the next transfers within half a step of their aim, and the one after that closer
    /// still.
    #[test]
    fn a_wait_held_up_by_other_work_barely_moves_the_lead() {
        let mut draw = crate::test_util::clock_keyed();
        let mut next = |n: u32| (draw() % u64::from(n)) as u32;
        for _ in 0..200 {
            let latency = fine(u64::from(5 + next(40)));
            let mut lead = Lead::default();
            let mut aimed = fine(1_000_000);
            for _ in 0..(10 + next(20)) {
                lead.learn(aimed, lead.begin(aimed) + latency);
                aimed += fine(5_000);
            }
            let held = fine(u64::from(50 + next(400)));
            lead.learn(aimed, lead.begin(aimed) + latency + held);
            aimed += fine(5_000);
            let miss = |lead: &Lead| (lead.begin(aimed) + latency).abs_diff(aimed);
            assert!(
                miss(&lead) <= Lead::STEP / 2 + US,
                "{:?} after {held:?}",
                miss(&lead)
            );
            let first = miss(&lead);
            lead.learn(aimed, lead.begin(aimed) + latency);
            assert!(miss(&lead) <= first / 2 + US / 8);
        }
    }
}
