//! The QMC5883L service: one reading per tick, at the instant the part's [`SampleClock`] says
//! its next sample has landed.
//!
//! * **Timing**: each tick's status poll is latched just after the predicted landing of the next
//!   sample (`t̂ + hi`, the late end of the clock's uncertainty, plus [`POLL_MARGIN`]), so it
//!   finds DRDY set; once the clock is located it reads the data in the same transfer, after a
//!   repeated START (one transfer and one wake-up per reading instead of two). While the
//!   clock's uncertainty is wide, the poll is latched at the predicted instant instead (begun
//!   early by the learnt latency, [`Lead`], so that it lands there): DRDY set or clear there
//!   halves the uncertainty (a clear one is polled again at the late end). The reading's slot
//!   is the newest sample instant before its data read; when that read came too close to an
//!   instant to tell, the status is polled once more after it (DRDY set again: the read was the
//!   sample before).
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
use imu_proto::{GapCause, Sensor, SensorState, MAG_PERIOD_US};

use crate::bus::{Failure, TransferTime};
use crate::clock::{self, fine, whole_us, BusTiming, Fine, Fit, SampleClock, Seen};
use crate::config::mag_config;
use crate::msg::{Out, SensorMsg};
use crate::sensor::{delay_until, Core, Lead, Phase, Tick, SETUP};

/// How long after the late end of the clock's uncertainty a poll is latched: beyond the
/// interval's own error, so that a look that also reads the data does not meet the landing
/// (which its data bytes would clear unseen).
pub const POLL_MARGIN: Fine = fine(60);
/// Margin around a sample instant within which a read's side is uncertain (beyond the clock's
/// own interval).
const READ_MARGIN: Fine = fine(10);
/// Shortest wait between two status polls of one tick.
const REPOLL_MIN: Fine = fine(100);
/// Status polls in one tick (the first and its re-polls).
const POLLS: u32 = 4;
/// A look's bits, from its start: the status byte's latch, the first data byte's (after the
/// repeated START and the data registers' address) and the last data byte's.
const LOOK_STATUS_BIT: u64 = clock::READ_FIRST_BIT;
const LOOK_DATA_BIT: u64 = clock::read_bits(1) + clock::READ_FIRST_BIT;
const LOOK_LAST_BIT: u64 = LOOK_DATA_BIT + 9 * 5;
/// How much later than planned a look may start and still be taken as clear of landings
/// without asking the clock ([`MagService::on_plan`]; a quarter period if that is less).
const LOOK_SLACK: Fine = fine(1000);
/// How much earlier than planned it may start ([`POLL_MARGIN`] is 60 µs past the interval's
/// late end; [`READ_MARGIN`] must stay).
const LOOK_EARLY: Fine = fine(20);

/// How a tick's first transfer was planned ([`MagService::schedule`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum FirstRead {
    /// A look after the late end of a located clock's interval, where the sample due has
    /// landed: the status and the data in one transfer, planned to start at this instant.
    Look(Fine),
    /// A probe or a guard: a status read whose start the clock placed (begun early by the
    /// learnt lead, which this read then refines).
    Aimed(Fine),
}

/// The magnetometer side.
pub struct MagService {
    core: Core,
    /// When the next tick should start, µs (`None`: the caller's own schedule).
    next_poll_us: Option<u64>,
    /// How the next tick's first transfer was planned, and where it should start.
    first: Option<FirstRead>,
    /// How much earlier than its target the first status read is begun.
    lead: Lead,
    /// The last reading's data while the part's data registers are known to hold them, DRDY
    /// cleared by reading them (`None` after a failed transfer, a bus recovery or a restart:
    /// a transfer that failed may have read data bytes too). Only then may a look read the data
    /// with the status: one that finds no sample tells from them whether one landed between
    /// the status byte and the data bytes.
    last_xyz: Option<[i16; 3]>,
}

impl MagService {
    pub const fn new(timing: BusTiming) -> Self {
        Self {
            core: Core::new(Sensor::Mag, MAG_PERIOD_US as u32, timing),
            next_poll_us: None,
            first: None,
            lead: Lead::new(),
            last_xyz: None,
        }
    }

    pub fn state(&self) -> SensorState {
        self.core.health.state()
    }

    /// The magnetometer's sample clock.
    pub fn clock(&self) -> &SampleClock {
        &self.core.clock
    }

    /// When the next tick should start, µs since boot (`None`: no grid yet, or the part is out:
    /// use the caller's own schedule).
    pub fn next_poll_us(&self) -> Option<u64> {
        self.next_poll_us
    }

    /// The bus needs recovering before the next tick (a bus fault, or a retry of a lost sensor).
    pub fn wants_recovery(&self, t_us: u64) -> bool {
        self.core.wants_recovery(t_us)
    }

    /// The caller recovered the bus.
    pub fn recovered(&mut self) {
        self.core.recovered();
        self.last_xyz = None;
    }

    /// After a pause (flash write): the samples missed meanwhile are counted as lost to it.
    pub fn resume(&mut self) {
        if self.core.phase == Phase::Running {
            self.core.after.get_or_insert(GapCause::Paused);
        }
    }

    /// One tick at `now()` µs.
    pub async fn tick<I: I2c + TransferTime, D: DelayNs>(
        &mut self,
        cx: &mut Tick<'_, Qmc5883<I>, D>,
    ) {
        let t = (cx.now)();
        self.next_poll_us = None;
        let first = self.first.take();
        let read = match self.core.phase {
            Phase::Init => {
                self.init(cx, GapCause::SensorFault).await;
                false
            }
            Phase::Lost => self.look_for_lost(cx, t).await,
            Phase::Stalled if self.core.health.retry_due(t) => {
                self.init(cx, GapCause::Stalled).await;
                // The back-off counts from the end of the re-initialisation.
                self.core.health.retried((cx.now)());
                if self.core.phase == Phase::Running {
                    self.core.phase = Phase::Stalled;
                }
                false
            }
            Phase::Running | Phase::Stalled => true,
        };
        // One call of the read (a second, for a lost part found, took it out of line: ≈ 20
        // cycles per ms on the M0+).
        if read {
            self.read(cx, first).await;
        }
        self.core.flush_report(cx.out);
        if self.next_poll_us.is_none() && matches!(self.core.phase, Phase::Running | Phase::Stalled)
        {
            self.schedule((cx.now)());
        }
    }

    /// A lost part is looked for on every tick, so that one back from a NACK burst of any
    /// length costs only the burst's samples; the retries the back-off times (a bus recovery
    /// before each, `wants_recovery`) count their failures, the looks in between a bus fault
    /// only. (Looked for on the back-off alone, 50 ms doubling to 400 ms, a 393 ms NACK cost 95
    /// readings where 80 spanned it.) Returns whether it was found with its configuration
    /// intact: its newest reading is then read in the same tick (left for the next, a part back
    /// between two ticks lost one more).
    async fn look_for_lost<I: I2c + TransferTime, D: DelayNs>(
        &mut self,
        cx: &mut Tick<'_, Qmc5883<I>, D>,
        t: u64,
    ) -> bool {
        let due = self.core.look_due(t);
        let intact = match cx.dev.chip_id().await {
            Ok(id) if id == cx.dev.variant().chip_id().1 => cx.dev.config_intact().await,
            Ok(found) => Err(qmc::Error::WrongChip { found }),
            Err(e) => Err(e),
        };
        match intact {
            Ok(true) => {
                self.core.found_intact(t);
                true
            }
            Ok(false) => {
                self.core.health.answered();
                self.init(cx, GapCause::SensorFault).await;
                false
            }
            Err(e) => {
                self.last_xyz = None;
                self.core.look_failed(failure(&e), due, t, cx.out);
                false
            }
        }
    }

    async fn init<I: I2c + TransferTime, D: DelayNs>(
        &mut self,
        cx: &mut Tick<'_, Qmc5883<I>, D>,
        cause: GapCause,
    ) {
        self.last_xyz = None;
        if let Err(e) = cx.dev.prepare(cx.delay, &mag_config()).await {
            self.failed(&e, (cx.now)(), cx.out);
            return;
        }
        self.core.health.answered();
        self.core.wait_to_start(cx.delay, cx.now).await;
        if let Err(e) = cx.dev.start().await {
            self.failed(&e, (cx.now)(), cx.out);
            return;
        }
        self.core
            .started(cx.dev.bus().last_start(), cause, (cx.now)());
        self.schedule((cx.now)());
    }

    /// The next tick: the first poll's latch just after the late end of the uncertainty about
    /// the next sample's landing, or at the predicted landing itself when the uncertainty is
    /// wide (a probe), or before its early end now and then (a guard;
    /// [`SampleClock::poll_offset`]). A landing already past (samples missed, a stall) gives
    /// way to the next one predicted after `now_us`.
    fn schedule(&mut self, now_us: u64) {
        let latch = self.core.timing.latch(Fine::ZERO, clock::READ_FIRST_BIT);
        let offset = self.core.clock.poll_offset(POLL_MARGIN);
        let due = self
            .core
            .clock
            .time(self.core.next_k)
            .wrapping_add_signed(offset);
        let earliest = fine(now_us) + SETUP + latch;
        let at = if due >= earliest {
            due
        } else {
            self.core.clock.instant_after(earliest, offset)
        };
        // A probe or a guard is begun early by the learnt latency between the tick's start and
        // the read's first bit, so that the status is latched where the clock placed it (a
        // probe latched late finds the sample past the late end and narrows nothing). A look
        // after the late end is not: the latency varies with what else runs, and latched
        // early it could meet the landing, which its data read would then clear unseen.
        let start = at - latch;
        let clock = &self.core.clock;
        let located = clock.known() && clock.width() <= clock::LOCKED_WIDTH;
        self.first = if offset <= 0 {
            Some(FirstRead::Aimed(start))
        } else if at == due && located && !self.core.fresh && self.last_xyz.is_some() {
            Some(FirstRead::Look(start))
        } else {
            None
        };
        let begin = if offset <= 0 {
            self.lead.begin(start)
        } else {
            start
        };
        self.next_poll_us = Some(whole_us(begin));
    }

    /// Poll the status (again, up to [`POLLS`] times) and read the sample when DRDY is set. A
    /// planned [`FirstRead::Look`] reads the data with its first status, in one transfer
    /// (`status_and_data`), if it starts where no landing can fall among its bytes: the sample
    /// has landed by the clock, so the data are it when DRDY shows; otherwise they tell whether
    /// a sample landed after the status byte (and was cleared unseen by their read).
    async fn read<I: I2c + TransferTime, D: DelayNs>(
        &mut self,
        cx: &mut Tick<'_, Qmc5883<I>, D>,
        first: Option<FirstRead>,
    ) {
        let look = match first {
            Some(FirstRead::Look(planned)) => Some(planned),
            _ => None,
        };
        let mut aimed = match first {
            Some(FirstRead::Aimed(start)) => Some(start),
            _ => None,
        };
        let status_latch = self.core.timing.latch(Fine::ZERO, clock::READ_FIRST_BIT);
        // A "not yet" seen this tick, kept to be trusted if a later poll finds the sample (the
        // part is producing, so the phase was late, not the part stalled).
        let mut not_yet: Option<Fine> = None;
        for poll in 0..POLLS {
            // Checked again where the look starts: a tick begun late (the bus held by an IMU
            // burst, the CPU stalled) may bring a landing among its bytes.
            let clear = |s: &Self, planned: Fine| {
                let start = fine((cx.now)()) + SETUP;
                s.on_plan(planned, start) || s.look_clear(start)
            };
            let (status, with_status) = if poll == 0 && look.is_some_and(|p| clear(self, p)) {
                match cx.dev.status_and_data().await {
                    Ok((s, xyz)) => (Ok(s), Some(xyz)),
                    Err(e) => (Err(e), None),
                }
            } else {
                (cx.dev.status().await, None)
            };
            let t = (cx.now)();
            let status = match status {
                Ok(s) => s,
                Err(e) => {
                    self.failed(&e, t, cx.out);
                    return;
                }
            };
            let start = cx.dev.bus().last_start();
            // Learnt only from looks that started within the largest lead of their aim: one
            // the bus held back (an IMU burst in progress) says nothing about the latency.
            if let Some(a) = aimed.take() {
                if start.since(a).unsigned_abs() <= Lead::MAX.raw() {
                    self.lead.learn(a, start);
                }
            }
            let tau = self.core.answered(start, clock::READ_FIRST_BIT);
            // A status read the bus held says nothing about when the sample landed.
            let bits = if with_status.is_some() {
                clock::read_bits(1) + clock::read_bits(6)
            } else {
                clock::read_bits(1)
            };
            let timely = !self.core.held(start, bits, t);
            if !status.ready {
                if let Some(xyz) = with_status {
                    if !self.core.fresh && self.last_xyz.is_some_and(|last| last != xyz) {
                        // The data changed after the status said "not yet": a sample landed
                        // after the status byte, before the last data byte, and reading them
                        // cleared its DRDY unseen. Its slot is lost (counted from the next
                        // reading's), its landing located between the two latches.
                        if timely {
                            let clock = &mut self.core.clock;
                            clock.observe(tau, self.core.next_k.wrapping_sub(1), Seen::NextNotYet);
                            let t_last = self.core.timing.latch(start, LOOK_LAST_BIT);
                            clock.observe(t_last, self.core.next_k, Seen::Produced);
                        }
                        self.core.next_k = self.core.next_k.wrapping_add(1);
                        self.last_xyz = Some(xyz);
                        self.core.last_growth_us = t;
                        return;
                    }
                }
                if timely && !self.core.fresh {
                    // Sample `next_k` not yet landed: a lower bound, unless the part stalled.
                    self.core.clock.observe(
                        tau,
                        self.core.next_k.wrapping_sub(1),
                        Seen::NextNotYet,
                    );
                }
                if timely {
                    not_yet = Some(tau);
                }
                if self.core.no_data(t, cx.out) {
                    return;
                }
                if poll + 1 == POLLS {
                    return;
                }
                // Poll again at the late end of the uncertainty (or a little later).
                let late = self.core.clock.time(self.core.next_k)
                    + self.core.clock.width() / 2
                    + POLL_MARGIN;
                let at = late.max(tau + REPOLL_MIN);
                delay_until(cx.delay, cx.now, at - status_latch).await;
                continue;
            }
            if let Some(before) = not_yet {
                if !self.core.fresh {
                    self.core.clock.observe(
                        before,
                        self.core.next_k.wrapping_sub(1),
                        Seen::NextNotYetTrusted,
                    );
                }
            }
            if timely
                && self
                    .core
                    .clock
                    .observe(tau, self.core.next_k, Seen::Produced)
                    == Fit::Early
            {
                // The sample came before the interval allowed: the line ran late, so the period
                // that carried it here is wrong by more than its bound. Measure it again.
                self.core.clock.distrust_period();
            }
            // The data, their latch, and their slot when the clock alone tells it; a look's
            // data not known whole are read again, alone.
            let combined = match with_status {
                // Read with the status, just after it.
                Some(xyz) => {
                    let timing = self.core.timing;
                    let t_data = if timely {
                        timing.latch(start, LOOK_DATA_BIT)
                    } else {
                        self.held_read(cx, start, t, LOOK_DATA_BIT).await
                    };
                    let base = t_data - timing.duration(LOOK_DATA_BIT);
                    let planned = timely && look.is_some_and(|p| self.on_plan(p, start));
                    if planned || self.look_clear(base) {
                        Some((xyz, t_data, Some(self.core.next_k)))
                    } else {
                        self.among_bytes(cx, base)
                            .await
                            .map(|t_data| (xyz, t_data, None))
                    }
                }
                None => None,
            };
            let (xyz, t_data, slot) = match combined {
                Some(c) => c,
                None => {
                    // A data read that a landing may fall inside would be torn (the part
                    // rewrites its data registers, the bytes already read belong to the sample
                    // before): wait for that landing, then read; the read takes the sample that
                    // landed. Only with a clock that knows its landings to a quarter period
                    // (while it is wider, any read window may hold a landing).
                    let window = SETUP + self.core.timing.duration(clock::read_bits(6));
                    let half = window / 2;
                    // Read again after the landing once a read may have met one: begun later
                    // than the wait placed it (the bus held by another transfer, the CPU by
                    // other work), a landing may have fallen among its bytes.
                    let mut again = false;
                    loop {
                        let now = fine((cx.now)());
                        let clock = &self.core.clock;
                        if self.guards_reads()
                            && (again || clock.newest_at(now + half, half + READ_MARGIN).is_none())
                        {
                            let late = clock.width() / 2 + POLL_MARGIN;
                            let after = clock.instant_after(now, late.raw() as i64);
                            delay_until(cx.delay, cx.now, after).await;
                        }
                        let xyz = match cx.dev.read_data().await {
                            Ok(xyz) => xyz,
                            Err(e) => {
                                self.failed(&e, (cx.now)(), cx.out);
                                return;
                            }
                        };
                        let end = (cx.now)();
                        let start = cx.dev.bus().last_start();
                        if self.core.held(start, clock::read_bits(6), end) {
                            let t_data =
                                self.held_read(cx, start, end, clock::READ_FIRST_BIT).await;
                            break (xyz, t_data, None);
                        }
                        let t_data = self.core.timing.latch(start, clock::READ_FIRST_BIT);
                        if !self.may_be_torn(start) {
                            break (xyz, t_data, None);
                        }
                        if again {
                            // Held up twice: not delivered (its slot is counted lost with the
                            // next reading's).
                            self.last_xyz = Some(xyz);
                            return;
                        }
                        again = true;
                    }
                }
            };
            let k = match slot {
                Some(k) => k,
                None => self.slot_of(cx, t_data, status.skipped).await,
            };
            let stamps = self.core.clock.stamps(k, 1);
            let _ = cx.out.push(SensorMsg::Mag {
                stamps,
                xyz,
                after: self.core.after.take(),
            });
            self.last_xyz = Some(xyz);
            self.core.next_k = k.wrapping_add(1);
            self.core.fresh = false;
            // A stall is timed from when the part last produced, not from this read.
            self.core.last_growth_us = stamps.us(0).min(t);
            if self.core.phase == Phase::Stalled {
                self.core.phase = Phase::Running;
            }
            if let Some(e) = self.core.health.delivering(t) {
                self.core.report(Some(e), cx.out);
            }
            return;
        }
    }

    /// The slot of data latched at `t_data` (`skipped`: the status showed DOR). DOR clear: one
    /// sample landed since the last read, the next one due, unless the clock says the grid has
    /// moved on past it (a part that produced nothing for a while). DOR set (samples
    /// overwritten unread): the newest landed before the data read, by the clock.
    async fn slot_of<I: I2c + TransferTime, D: DelayNs>(
        &mut self,
        cx: &mut Tick<'_, Qmc5883<I>, D>,
        t_data: Fine,
        skipped: bool,
    ) -> u32 {
        let by_clock = self.core.clock.newest_at(t_data, READ_MARGIN);
        let later = |k: u32| k.wrapping_sub(self.core.next_k).wrapping_sub(1) < 1 << 31;
        if !skipped {
            match by_clock {
                Some(k) if later(k) => k,
                Some(_) => self.core.next_k,
                // Too close to an instant `j` to tell `j − 1` from `j`: it matters if both are
                // past the one due, and also if `j − 1` is the one due: DOR clear does not
                // settle that, the status may have been read before `j` landed and the data
                // after (a clock just restarted has no guard against it), and then `j − 1` was
                // overwritten unseen. Polled after `j`'s interval, which must be narrow enough
                // to say where `j` is.
                None if later(self.core.clock.nearest(t_data).wrapping_sub(1))
                    || (later(self.core.clock.nearest(t_data))
                        && self.core.clock.width() <= self.core.clock.period() / 4) =>
                {
                    self.resolve(cx, t_data).await
                }
                None => self.core.next_k,
            }
        } else {
            let k = match by_clock {
                Some(k) => k,
                None => self.resolve(cx, t_data).await,
            };
            // Never an older slot than the next one due (the sample just read is new).
            if self.core.fresh || k.wrapping_sub(self.core.next_k) < 1 << 31 {
                k
            } else {
                self.core.next_k
            }
        }
    }

    /// Whether the clock knows the landings well enough (to a quarter period) to keep data
    /// reads clear of them. (Only while it was located, ≤ 64 µs: after a restart, at 70 µs, a
    /// read held up met a landing among its bytes, and the poll that was to tell which sample
    /// it took found DRDY cleared by its last bytes and took it for the new one.)
    fn guards_reads(&self) -> bool {
        let clock = &self.core.clock;
        clock.known() && clock.width() <= clock.period() / 4
    }

    /// Whether a data read (six bytes) started at `start` may have met a landing among its
    /// bytes, by a clock that [guards reads](Self::guards_reads) (the part rewrites its data
    /// registers at a landing: the bytes before it are the old sample's, the ones after the new
    /// one's). With a wider clock, any read may: not asked.
    fn may_be_torn(&self, start: Fine) -> bool {
        if !self.guards_reads() {
            return false;
        }
        let clock = &self.core.clock;
        let timing = &self.core.timing;
        let first = clock.newest_at(timing.latch(start, clock::READ_FIRST_BIT), READ_MARGIN);
        let last = clock.newest_at(timing.latch(start, clock::read_bits(5)), READ_MARGIN);
        first.is_none() || first != last
    }

    /// Whether a look planned to start at `planned` (after the late end of the next sample's
    /// interval) that starts at `start` is still where the plan put it: no earlier than
    /// [`LOOK_EARLY`] before, no later than a quarter period (at most [`LOOK_SLACK`]) after, so
    /// the sample has landed and the next is still most of a period away (no need to ask the
    /// clock again).
    fn on_plan(&self, planned: Fine, start: Fine) -> bool {
        let d = start.since(planned);
        let slack = (self.core.clock.period() / 4).min(LOOK_SLACK);
        d >= -(LOOK_EARLY.raw() as i64) && d <= slack.raw() as i64
    }

    /// Whether a look started at `start` (status and data in one transfer) is clear of
    /// landings: by the clock, the next sample due landed before its status byte's latch and
    /// the one after lands after its last data byte's. Only while the part's data registers
    /// hold the last reading.
    fn look_clear(&self, start: Fine) -> bool {
        let timing = &self.core.timing;
        !self.core.fresh
            && self.last_xyz.is_some()
            && self.core.clock.alone(
                self.core.next_k,
                timing.latch(start, LOOK_STATUS_BIT),
                timing.latch(start, LOOK_LAST_BIT),
                READ_MARGIN,
            )
    }

    /// A look (started at `start`) that showed a sample may have met the next landing among
    /// or near its data bytes. By the clock, no landing among them: the data are whole, the
    /// newest sample at their latch (returned). Otherwise a status poll after the late end of
    /// that landing's interval tells: DRDY set, the landing came after the last data byte
    /// (reading one clears DRDY), so the data are the sample the status showed (the status
    /// byte's latch returned); DRDY clear, it came before or among them, and the data are the
    /// new sample, whole or torn: `None`, to read them again (the next landing is a period
    /// away).
    async fn among_bytes<I: I2c + TransferTime, D: DelayNs>(
        &mut self,
        cx: &mut Tick<'_, Qmc5883<I>, D>,
        start: Fine,
    ) -> Option<Fine> {
        let timing = self.core.timing;
        let t_data = timing.latch(start, LOOK_DATA_BIT);
        let t_last = timing.latch(start, LOOK_LAST_BIT);
        let clock = &self.core.clock;
        let at_data = clock.newest_at(t_data, READ_MARGIN);
        if at_data.is_some() && clock.newest_at(t_last, READ_MARGIN) == at_data {
            return Some(t_data);
        }
        let landing = clock.time(clock.nearest(t_last));
        let after = landing + clock.width() / 2 + POLL_MARGIN;
        let latch = timing.latch(Fine::ZERO, clock::READ_FIRST_BIT);
        delay_until(cx.delay, cx.now, after - latch).await;
        match cx.dev.status().await {
            Ok(s) if s.ready => Some(timing.latch(start, LOOK_STATUS_BIT)),
            _ => None,
        }
    }

    /// When a data read that took too long (started at `start`, seen done at `end_us`, its
    /// first data byte `first_bit` in) moved its bytes. Either the bus held it (a START that
    /// could not be sent, a slave stretching SCL): its bytes moved at its end. Or the task was
    /// held after it (a CPU stall): they moved at its start. A status poll tells the two apart:
    /// DRDY set again, with no landing between the end and the poll, means a sample landed
    /// after the bytes moved, before the end: they moved at the start.
    async fn held_read<I: I2c + TransferTime, D: DelayNs>(
        &mut self,
        cx: &mut Tick<'_, Qmc5883<I>, D>,
        start: Fine,
        end_us: u64,
        first_bit: u64,
    ) -> Fine {
        // The data bytes end the transfer either way (alone, or after the status).
        let after = clock::read_bits(6) - clock::READ_FIRST_BIT;
        let at_end = fine(end_us) - self.core.timing.duration(after);
        let at_start = self.core.timing.latch(start, first_bit);
        let Ok(status) = cx.dev.status().await else {
            return at_end;
        };
        let poll = self
            .core
            .timing
            .latch(cx.dev.bus().last_start(), clock::READ_FIRST_BIT);
        // No landing between where the bytes moved if the bus held them (their latch at the
        // end, not the transfer's end: a sample landing in between, a few µs after the data
        // bytes, set DRDY and passed for one landed before the end, and a read the bus had held
        // for 20 ms was taken as read at its start, three slots early) and the poll.
        let clock = &self.core.clock;
        let none_since_end = match (
            clock.newest_at(at_end, READ_MARGIN),
            clock.newest_at(poll, READ_MARGIN),
        ) {
            (Some(a), Some(b)) => a == b,
            _ => false,
        };
        if status.ready && none_since_end {
            at_start
        } else {
            at_end
        }
    }

    /// A data read latched too close to a sample instant `j` to tell whether it read `j − 1`
    /// or `j`: poll once more after the instant. DRDY set again means `j` landed after the
    /// read (the read was `j − 1`); clear means the read took `j`.
    async fn resolve<I: I2c + TransferTime, D: DelayNs>(
        &mut self,
        cx: &mut Tick<'_, Qmc5883<I>, D>,
        t_data: Fine,
    ) -> u32 {
        let j = self.core.clock.nearest(t_data);
        let latch = self.core.timing.latch(Fine::ZERO, clock::READ_FIRST_BIT);
        let after = self.core.clock.time(j) + self.core.clock.width() / 2 + POLL_MARGIN;
        delay_until(cx.delay, cx.now, after - latch).await;
        match cx.dev.status().await {
            Ok(s) if s.ready => j.wrapping_sub(1),
            _ => j,
        }
    }

    /// A transfer failed at `t`.
    fn failed<E: embedded_hal::i2c::Error>(&mut self, e: &qmc::Error<E>, t: u64, out: &mut Out) {
        self.last_xyz = None;
        self.core.failed(failure(e), t, out);
    }
}

/// What a driver error says of the bus.
fn failure<E: embedded_hal::i2c::Error>(e: &qmc::Error<E>) -> Failure {
    match e {
        qmc::Error::Bus(b) => Failure::of(b),
        _ => Failure::Other,
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
