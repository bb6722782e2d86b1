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
use imu_proto::{GapCause, Sensor, SensorState, IMU_PERIOD_US};

use crate::bus::{Failure, TransferTime, TRANSFER_TIMEOUT_US};
use crate::clock::{self, fine, whole_us, BusTiming, Fine, Fit, SampleClock, Seen};
use crate::config::imu_config;
use crate::cycle_marker::{self, Stage};
use crate::msg::{Out, SensorMsg, BURST_MAX};
use crate::sensor::{delay_until, Core, Lead, Phase, Tick, SETUP, WRITE_MARGIN};

/// Bytes of one FIFO frame (accel, temperature, gyro).
const FRAME: u16 = 14;
/// How far ahead a burst may wait for a probe instant (the burst must be done before the next
/// magnetometer read, 5 ms after the one that started it).
const PROBE_WAIT: Fine = fine(1200);
/// Messages kept free in a tick's output for reports.
const REPORT_ROOM: usize = 3;
/// Count reads of one tick that may be repeated because the bus held them.
const HELD_REREADS: u32 = 3;
/// How long before a burst's start a frame must have landed, by the clock, to be read in the
/// same transfer as the count: the clock's phase may be this far wrong without a frame being
/// read that the count does not cover.
const COUNTED_MARGIN: Fine = fine(250);
/// Most frames read with the count: (14 + 1) × 14 bytes stay under 256, so the count's two
/// bytes cannot tear between its high and low byte.
const COUNTED_MAX: u32 = 14;

/// The IMU side.
pub struct ImuService {
    core: Core,
    /// The frames in the FIFO are not aligned (a read abandoned part-way: `BusFault`; frames
    /// read with the count that it did not cover: `Stalled`): restart it, for this cause.
    misaligned: Option<GapCause>,
    /// The last count read, with frames, found a sample later than the clock allowed.
    late_before: bool,
    /// The last count read found no frame where the clock had one landed (a stall going on).
    waited: bool,
    /// The last count read found frames behind the clock's slots whose slots the clock could
    /// not tell there: they stay in the FIFO, and the count is read again between two instants.
    hold: bool,
    /// The count was so read again (it is not read a third time).
    held_back: bool,
    capacity: u16,
    /// How much earlier than its target a probe's count read is begun.
    lead: Lead,
}

impl ImuService {
    /// A service for transfers timed as `timing` (the latch instants of the clock's
    /// observations).
    pub const fn new(timing: BusTiming) -> Self {
        Self {
            core: Core::new(Sensor::Imu, IMU_PERIOD_US as u32, timing),
            misaligned: None,
            late_before: false,
            waited: false,
            hold: false,
            held_back: false,
            capacity: 1024,
            lead: Lead::new(),
        }
    }

    pub fn state(&self) -> SensorState {
        self.core.health.state()
    }

    /// The last burst's transfer failed and the part is not lost: the next burst is a retry,
    /// best soon (the FIFO keeps filling; [`crate::schedule::IMU_RETRY_US`]).
    pub fn retrying(&self) -> bool {
        self.core.phase == Phase::Running && self.core.health.failing()
    }

    /// The IMU's sample clock.
    pub fn clock(&self) -> &SampleClock {
        &self.core.clock
    }

    /// The bus needs recovering before the next tick (a bus fault, or a retry of a lost sensor).
    pub fn wants_recovery(&self, t_us: u64) -> bool {
        self.core.wants_recovery(t_us)
    }

    /// The caller recovered the bus.
    pub fn recovered(&mut self) {
        self.core.recovered();
    }

    /// After a pause (flash write): the FIFO's contents are not delivered; restart it.
    pub async fn resume<I: I2c + TransferTime, D: DelayNs>(
        &mut self,
        cx: &mut Tick<'_, Mpu6050<I>, D>,
    ) {
        if self.core.phase == Phase::Running {
            self.restart_fifo(cx, GapCause::Paused).await;
        }
    }

    /// One service tick at `now()` µs.
    pub async fn tick<I: I2c + TransferTime, D: DelayNs>(
        &mut self,
        cx: &mut Tick<'_, Mpu6050<I>, D>,
    ) {
        let t = (cx.now)();
        match self.core.phase {
            Phase::Init => self.init(cx, GapCause::SensorFault).await,
            Phase::Lost => self.retry_lost(cx).await,
            Phase::Stalled if self.core.health.retry_due(t) => {
                // A look at the FIFO first: a part that came back since the last tick has its
                // first samples there, which a re-initialisation would empty (and the grid
                // started on what remained, a slot or more off).
                self.drain(cx).await;
                if self.core.phase != Phase::Stalled {
                    self.core.flush_report(cx.out);
                    return;
                }
                self.init(cx, GapCause::Stalled).await;
                // The back-off counts from the end of the re-initialisation (its reset alone
                // takes 100 ms): the next tick drains what the restarted part produced.
                self.core.health.retried((cx.now)());
                // Still stalled until data comes.
                self.core.phase = Phase::Stalled;
            }
            Phase::Running | Phase::Stalled => {
                if let Some(cause) = self.misaligned {
                    // A stall is still timed from the part's last sample, not the restart.
                    let growth = self.core.last_growth_us;
                    self.restart_fifo(cx, cause).await;
                    if cause == GapCause::Stalled {
                        self.core.last_growth_us = growth;
                    }
                } else {
                    self.drain(cx).await;
                }
            }
        }
        self.core.flush_report(cx.out);
    }

    /// Identify, configure and start the part. A part that had a grid is started in step with
    /// it; its first sample is then the slot it lands on, and the slots since the last frame
    /// delivered are lost (`cause`).
    async fn init<I: I2c + TransferTime, D: DelayNs>(
        &mut self,
        cx: &mut Tick<'_, Mpu6050<I>, D>,
        cause: GapCause,
    ) {
        if let Err(e) = cx.dev.prepare(cx.delay, &imu_config()).await {
            self.failed(&e, (cx.now)(), cx.out);
            return;
        }
        self.core.health.answered();
        self.capacity = cx.dev.fifo_capacity().unwrap_or(1024);
        self.core.wait_to_start(cx.delay, cx.now).await;
        if let Err(e) = cx.dev.start().await {
            self.failed(&e, (cx.now)(), cx.out);
            return;
        }
        self.core
            .started(cx.dev.bus().last_start(), cause, (cx.now)());
        self.misaligned = None;
        self.late_before = false;
        self.waited = false;
    }

    /// A lost sensor is looked for on every tick: identity, then the configuration read back;
    /// re-initialise only if that is gone. The retries the back-off times (the caller recovered
    /// the bus first) count their failures, the looks in between a bus fault only (see
    /// `MagService::tick`).
    async fn retry_lost<I: I2c + TransferTime, D: DelayNs>(
        &mut self,
        cx: &mut Tick<'_, Mpu6050<I>, D>,
    ) {
        let t = (cx.now)();
        let due = self.core.look_due(t);
        let intact = match cx.dev.probe().await {
            Ok(_) => cx.dev.config_intact().await,
            Err(e) => Err(e),
        };
        match intact {
            Ok(true) => {
                // It kept sampling: what the FIFO holds now is judged by its count (an overflow
                // restarts it, counting the slots exactly).
                self.core.found_intact(t);
                self.drain(cx).await;
            }
            Ok(false) => {
                self.core.health.answered();
                self.init(cx, GapCause::SensorFault).await;
            }
            Err(e) => self.core.look_failed(failure(&e), due, t, cx.out),
        }
    }

    /// Drain the FIFO: count, then the frames, in bursts of up to [`BURST_MAX`].
    async fn drain<I: I2c + TransferTime, D: DelayNs>(&mut self, cx: &mut Tick<'_, Mpu6050<I>, D>) {
        // A probe instant shortly ahead: wait for it, so the count read halves the clock's
        // uncertainty about where the samples fall.
        let count_latch = self.core.timing.latch(Fine::ZERO, clock::READ_SECOND_BIT);
        self.held_back = false;
        let t0 = fine((cx.now)());
        // The count read's start if it is placed (begun early by the learnt lead).
        let mut aimed = None;
        if let Some(p) = self.core.clock.probe_after(t0 + SETUP + count_latch) {
            if p - t0 < PROBE_WAIT + SETUP + count_latch {
                let start = p - count_latch;
                delay_until(cx.delay, cx.now, self.lead.begin(start)).await;
                aimed = Some(start);
            }
        }
        let counted = self.counted_frames(fine((cx.now)()));
        if counted > 0 && cx.out.len() + REPORT_ROOM <= cx.out.capacity() {
            self.drain_counted(cx, counted, aimed).await;
            return;
        }
        let mut held = 0;
        while cx.out.len() + REPORT_ROOM <= cx.out.capacity() {
            cycle_marker::enter(Stage::I2c);
            let count = cx.dev.fifo_count().await;
            let read_at = (cx.now)();
            cycle_marker::leave();
            let count = match count {
                Ok(c) => c,
                Err(e) => {
                    self.failed(&e, read_at, cx.out);
                    return;
                }
            };
            let start = cx.dev.bus().last_start();
            if let Some(a) = aimed.take() {
                self.lead.learn(a, start);
            }
            let tau = self.core.answered(start, clock::READ_SECOND_BIT);
            let held_read = self.core.held(start, clock::read_bits(2), read_at);
            if held_read && held < HELD_REREADS {
                // When this count was latched is not known (the bus was held): it says nothing
                // about the clock, and would pass for stale. Read it again.
                held += 1;
                continue;
            }
            if count >= self.capacity
                || count_may_be_stale(count, read_at.saturating_sub(whole_us(tau)), self.capacity)
            {
                self.core.overflows += 1;
                self.restart_fifo(cx, GapCause::FifoOverflow).await;
                return;
            }
            let frames = frames_in(count);
            let newest = self.observe_count(tau, count, held_read);
            if core::mem::take(&mut self.hold) {
                // Read again between two instants, where the clock tells its newest slot (once:
                // a count there is never ambiguous unless the clock is a period wide).
                let t = fine((cx.now)()) + SETUP + count_latch;
                let mid = self.core.clock.mid_slot_after(t);
                delay_until(cx.delay, cx.now, mid - count_latch).await;
                self.held_back = true;
                continue;
            }
            if frames == 0 {
                self.core.no_data(read_at, cx.out);
                return;
            }
            // The part last produced when its newest frame was sampled (a stall is timed from
            // there, not from this read, which may come up to a burst later).
            self.core.last_growth_us = whole_us(self.core.clock.time(newest)).min(read_at);
            if self.core.phase == Phase::Stalled {
                if self.core.clock.confirmed() || held_read {
                    // Data again after a stall: the frames' slots are not known by counting
                    // (the part produced nothing for a while); restart the FIFO to know them.
                    self.restart_fifo(cx, GapCause::Stalled).await;
                    return;
                }
                // The part's first samples ever (it stalled before its first): the FIFO,
                // emptied when the part was started, holds them from its first, slot
                // `next_k`, and the clock's grid starts there.
                self.anchor(tau, frames);
            }
            let slot = cx.out.len();
            let layout = cx.dev.fifo_frame().unwrap_or(mpu::FifoFrame::AccelTempGyro);
            let Some(frames) = cx.out.open_burst(layout, self.core.after) else {
                return;
            };
            cycle_marker::enter(Stage::I2c);
            // The frames read straight into the message, undecoded (at most BURST_MAX).
            let r = cx
                .dev
                .read_fifo_counted_raw(count, &mut frames.bytes[..BURST_MAX * layout.bytes()])
                .await;
            if let Ok(n) = r {
                frames.n = n;
            }
            cycle_marker::leave();
            let n = match r {
                Ok(n) => n,
                Err(e) => {
                    self.read_failed(cx.out, slot, &e, (cx.now)());
                    return;
                }
            };
            self.delivered(cx.out, slot, n, read_at);
            if n < BURST_MAX {
                return;
            }
        }
    }

    /// How many frames to read together with the count at `now` (0: count first, then read
    /// what it says): in the steady state (a located clock, frames flowing), those the clock
    /// says landed [`COUNTED_MARGIN`] before `now` and so before the count is latched, up to
    /// [`COUNTED_MAX`].
    fn counted_frames(&self, now: Fine) -> u32 {
        let clock = &self.core.clock;
        if self.core.fresh
            || self.core.phase != Phase::Running
            || !clock.known()
            || clock.width() > clock::LOCKED_WIDTH
        {
            return 0;
        }
        // Stepped along the clock's line from the next frame due (a few additions; the
        // divisions of `newest_at` cost ≈ 470 cycles a burst on the M0+).
        let by = now - COUNTED_MARGIN;
        let period = clock.period();
        let mut t = clock.time(self.core.next_k);
        let mut n = 0;
        while t <= by {
            if n == COUNTED_MAX {
                return 0;
            }
            n += 1;
            t += period;
        }
        n
    }

    /// One transfer: the FIFO count, then the `n` frames the clock says it holds (one transfer,
    /// one wake-up and one message fewer per burst than the count and then the frames). The
    /// count feeds the clock as in [`Self::drain`]; frames it does not cover (the part produced
    /// fewer than its clock says: a stall beginning, a reset) were read from an empty FIFO or
    /// in part from a sample landing meanwhile, so the FIFO is restarted on the next tick.
    async fn drain_counted<I: I2c + TransferTime, D: DelayNs>(
        &mut self,
        cx: &mut Tick<'_, Mpu6050<I>, D>,
        n: u32,
        aimed: Option<Fine>,
    ) {
        let slot = cx.out.len();
        let layout = cx.dev.fifo_frame().unwrap_or(mpu::FifoFrame::AccelTempGyro);
        let Some(frames) = cx.out.open_burst(layout, self.core.after) else {
            return;
        };
        cycle_marker::enter(Stage::I2c);
        let r = cx
            .dev
            .read_counted_fifo_raw(
                n as usize,
                &mut frames.count,
                &mut frames.bytes[..BURST_MAX * layout.bytes()],
            )
            .await;
        if let Ok(c) = r {
            frames.n = c.covered;
        }
        let read_at = (cx.now)();
        cycle_marker::leave();
        let c = match r {
            Ok(c) => c,
            Err(mpu::Error::FifoOverflow) => {
                cx.out.truncate(slot);
                self.core.overflows += 1;
                self.restart_fifo(cx, GapCause::FifoOverflow).await;
                return;
            }
            Err(e) => {
                self.read_failed(cx.out, slot, &e, read_at);
                return;
            }
        };
        let start = cx.dev.bus().last_start();
        if let Some(a) = aimed {
            self.lead.learn(a, start);
        }
        let tau = self.core.answered(start, clock::READ_SECOND_BIT);
        let bits = clock::read_bits(2) + clock::read_bits(u64::from(FRAME) * c.read as u64);
        let held_read = self.core.held(start, bits, read_at);
        // The frames followed the count on the bus, within the transfer's deadline however
        // late the task saw its end: only that long can the FIFO have filled in between. But a
        // transfer the bus held before its START (busy, a slave holding SDA) latched its count
        // at its end and read the frames right after it: that count holds every sample up to
        // the end by the clock, not only those up to the start. (Taken for stale, a START held
        // for 21 ms cost a FIFO's frames that had been read whole.)
        let on_bus = if held_read && self.latched_at_end(c.count, read_at, bits) {
            whole_us(self.core.timing.duration(bits))
        } else {
            read_at.saturating_sub(whole_us(tau))
        }
        .min(u64::from(TRANSFER_TIMEOUT_US));
        if count_may_be_stale(c.count, on_bus, self.capacity) {
            cx.out.truncate(slot);
            self.core.overflows += 1;
            self.restart_fifo(cx, GapCause::FifoOverflow).await;
            return;
        }
        let newest = self.observe_count(tau, c.count, held_read);
        // Read already: delivered as counted.
        self.hold = false;
        if !c.whole() {
            self.misaligned = Some(GapCause::Stalled);
        }
        if c.covered == 0 {
            cx.out.truncate(slot);
            self.core.no_data(read_at, cx.out);
            return;
        }
        self.core.last_growth_us = whole_us(self.core.clock.time(newest)).min(read_at);
        self.delivered(cx.out, slot, c.covered, read_at);
    }

    /// A part that stalled before its first sample (its grid only implied by the waking
    /// write) produced at last: its first `frames` samples, slots `next_k…`, are in the FIFO,
    /// the newest landed before `tau` and the next not yet. The grid starts on them (a phase
    /// known to a period, then narrowed by this count), and the part runs again. (Numbered on
    /// the waking write's grid, the emulator's MPU-6050 stalled from 0.1 s to 0.6 s had every
    /// sample a few hundred slots off; restarting its FIFO instead needs a phase known better
    /// than that, and the part stayed stalled.)
    fn anchor(&mut self, tau: Fine, frames: u16) {
        let period = self.core.clock.period();
        let first = self.core.next_k;
        let newest = first.wrapping_add(u32::from(frames)).wrapping_sub(1);
        let t_first = tau - period * u64::from(frames) + period / 2;
        self.core.clock.start(first, t_first, false, Fine::ZERO);
        self.core.clock.observe(tau, newest, Seen::NextNotYet);
        self.core.phase = Phase::Running;
        self.core.fresh = false;
        self.misaligned = None;
    }

    /// Whether a FIFO count of `count` bytes, read in a transfer of `bits` seen done at
    /// `read_at` µs, holds every frame the clock says the part had produced by the time the
    /// count would have been latched had the transfer begun last (less one: the sample landing
    /// about then): so it was latched there, not at the transfer's start.
    fn latched_at_end(&self, count: u16, read_at: u64, bits: u64) -> bool {
        let timing = &self.core.timing;
        let at = timing.latch(
            fine(read_at) - timing.duration(bits),
            clock::READ_SECOND_BIT,
        );
        let due = self
            .core
            .clock
            .nearest(at)
            .wrapping_sub(self.core.next_k)
            .wrapping_add(1);
        due < 1 << 16 && u32::from(frames_in(count)) + 1 >= due
    }

    /// A count of `count` bytes latched at `tau` (`held`: the bus held its transfer): the
    /// clock's observation, unless the count cannot be trusted for timing (one that crossed 255
    /// between its two bytes, or one the bus held; none while no frames have come since a
    /// restart, and none from a part coming back from a stall, whose frames' slots are not
    /// known by counting: re-initialised while still stalled, it may skip the first samples
    /// after its waking write, and the count, read as frames from that write on, would place
    /// the line up to a period late). Returns the newest sample it shows produced (`next_k +
    /// frames − 1`; `next_k + frames` was not, by the latch).
    fn observe_count(&mut self, tau: Fine, count: u16, held: bool) -> u32 {
        let frames = frames_in(count);
        let newest = self
            .core
            .next_k
            .wrapping_add(u32::from(frames))
            .wrapping_sub(1);
        if (frames > 0 || !self.core.fresh)
            && count < 256
            && !held
            && self.core.phase != Phase::Stalled
        {
            // A sample later than the clock allows, with frames flowing, is a phase to correct
            // only if the read before saw the same: a stall that began right after the frames
            // of this read looks the same once, and then the next read finds none.
            let seen = if frames > 0 && self.late_before {
                Seen::NextNotYetTrusted
            } else {
                Seen::NextNotYet
            };
            let fit = self.core.clock.observe(tau, newest, seen);
            // Frames after a read that found none where the clock had one landed (or after a
            // restart for a stall), or late after a read that was late too, may follow slots
            // the part skipped (a stall too short to name): its later samples sit right behind
            // its earlier ones in the FIFO, where counting frames cannot see the skip. These
            // frames all came after it, so they are the part's newest: when they are a whole
            // slot or more behind the clock's newest, they are numbered back from it, the
            // slots before them lost to the stall. (Counted as contiguous, a 45 ms stall left
            // every later sample 45 slots off and the clock's interval a period wide for the
            // rest of the run: `--fault stall:mpu@0.253s:45ms --clock mpu:+1.71%,qmc:+1.70%`.)
            // Where the clock cannot tell its newest slot at τ (an instant within its
            // uncertainty of τ: count reads are aimed at instants), the frames stay in the FIFO
            // and the count is read again between two instants ([`Self::hold`]). The first late
            // read with frames is not enough: a stall that began right after them looks the
            // same (the next read finds none), and so does a skip among them, which no count
            // can place.
            if frames > 0 && (self.waited || fit == Fit::Late && self.late_before) {
                if let Some(k) = self.after_skip(tau, newest) {
                    return k;
                }
            }
            self.late_before = frames > 0 && fit == Fit::Late;
            self.waited = frames == 0 && fit == Fit::Late;
        }
        newest
    }

    /// Frames counted at `tau` whose newest, numbered `newest` by counting, may follow
    /// skipped slots (see [`Self::observe_count`]): `Some` of their newest slot when they were
    /// renumbered back from the clock's newest, or when the clock cannot tell that slot and
    /// they are to stay in the FIFO ([`Self::hold`]); `None` when counting numbered them right.
    /// Out of line: the steady bursts never take it.
    #[cold]
    #[inline(never)]
    fn after_skip(&mut self, tau: Fine, newest: u32) -> Option<u32> {
        match self.core.clock.newest_at(tau, Fine::ZERO) {
            Some(line) if line.wrapping_sub(newest) as i32 > 0 => {
                let behind = line.wrapping_sub(newest);
                self.core.next_k = self.core.next_k.wrapping_add(behind);
                self.core.after.get_or_insert(GapCause::Stalled);
                self.core.clock.observe(tau, line, Seen::NextNotYet);
                self.late_before = false;
                self.waited = false;
                Some(line)
            }
            None if !self.held_back => {
                self.hold = true;
                Some(newest)
            }
            _ => None,
        }
    }

    /// The burst opened in `out[slot]` was not read (`e` at `t`): dropped; a bus fault that
    /// may have moved bytes leaves the FIFO misaligned.
    fn read_failed<E: embedded_hal::i2c::Error>(
        &mut self,
        out: &mut Out,
        slot: usize,
        e: &mpu::Error<E>,
        t: u64,
    ) {
        out.truncate(slot);
        if let mpu::Error::Bus(b) = e {
            if Failure::of(b).partial() {
                self.misaligned = Some(GapCause::BusFault);
            }
        }
        self.failed(e, t, out);
    }

    /// The `n` frames of the burst in `out[slot]` were read at `read_at`: stamped (the clock
    /// issues stamps only for frames delivered: it keeps them from going back behind the last
    /// it issued, so stamps issued for a read that then failed would push every later one
    /// late), and the next slot due moves past them.
    fn delivered(&mut self, out: &mut Out, slot: usize, n: usize, read_at: u64) {
        let stamps = self.core.clock.stamps(self.core.next_k, n as u32);
        if let Some(SensorMsg::Imu { stamps: s, .. }) = out.get_mut(slot) {
            *s = stamps;
        }
        self.core.after = None;
        self.core.next_k = self.core.next_k.wrapping_add(n as u32);
        self.core.fresh = false;
        if let Some(e) = self.core.health.delivering(read_at) {
            self.core.report(Some(e), out);
        }
    }

    /// Empty the FIFO and start it again with the enabling write halfway between two sample
    /// instants: the first frame after it is the first slot after that write, exactly.
    async fn restart_fifo<I: I2c + TransferTime, D: DelayNs>(
        &mut self,
        cx: &mut Tick<'_, Mpu6050<I>, D>,
        cause: GapCause,
    ) {
        let latch = self.core.timing.latch(Fine::ZERO, clock::WRITE_DATA_BIT);
        let mut known = None;
        for _ in 0..3 {
            if let Err(e) = cx.dev.stop_fifo().await {
                self.failed(&e, (cx.now)(), cx.out);
                return;
            }
            let target = self
                .core
                .clock
                .mid_slot_after(fine((cx.now)()) + SETUP + latch);
            delay_until(cx.delay, cx.now, target - latch).await;
            if let Err(e) = cx.dev.start_fifo().await {
                self.failed(&e, (cx.now)(), cx.out);
                return;
            }
            let tau = self
                .core
                .timing
                .latch(cx.dev.bus().last_start(), clock::WRITE_DATA_BIT);
            let margin = if self.core.timing.bit == Fine::ZERO {
                Fine::ZERO
            } else {
                WRITE_MARGIN
            };
            // The drift the period's error allows since the last observation widens the
            // uncertainty about the slots here (after an outage early on, the period still
            // the nominal's ±3 %, hundreds of µs or more).
            let drift = self.core.clock.drift_at(tau);
            known = self.core.clock.first_after(tau, margin + drift);
            if known.is_some() || drift + drift >= self.core.clock.period() {
                // Told, or not a delayed write: the slot cannot be told anywhere.
                break;
            }
            // Too close to a sample instant to tell its side (a delayed write): again.
        }
        self.core.next_k = match known {
            Some(k) => k,
            None => {
                // The slot after the write unknown (the clock has no phase yet, or its
                // uncertainty has grown past a period since the last observation): the
                // midline's guess, on a grid of its own. (Continued, the instants located
                // before and after a 375 ms outage early on gave a period 1.6 % short with a
                // bound of 0.17 %, the guess 9 slots off spanning them: the line then ran
                // early, and the FIFO was restarted every 0.35 s for seconds, 10 samples lost
                // each time: `--fault nack:mpu@0.1438s:351ms --clock mpu:-1.95%,qmc:-1.37%`.)
                let tau = self
                    .core
                    .timing
                    .latch(cx.dev.bus().last_start(), clock::WRITE_DATA_BIT);
                let k = self.core.clock.nearest(tau + self.core.clock.period() / 2);
                let t = self.core.clock.time(k);
                self.core.clock.start(k, t, false, Fine::ZERO);
                k
            }
        };
        self.core.health.answered();
        self.core.fresh = true;
        self.misaligned = None;
        self.late_before = false;
        // Restarted for a stall (its count short of the clock's): the part may still be
        // stalled, its first frames then later than the first slots after the write.
        self.waited = cause == GapCause::Stalled;
        self.core.after.get_or_insert(cause);
        self.core.last_growth_us = (cx.now)();
        if self.core.phase == Phase::Stalled {
            self.core.phase = Phase::Running;
        }
    }

    /// A transfer failed at `t`.
    fn failed<E: embedded_hal::i2c::Error>(&mut self, e: &mpu::Error<E>, t: u64, out: &mut Out) {
        self.core.failed(failure(e), t, out);
    }
}

/// What a driver error says of the bus.
fn failure<E: embedded_hal::i2c::Error>(e: &mpu::Error<E>) -> Failure {
    match e {
        mpu::Error::Bus(b) => Failure::of(b),
        _ => Failure::Other,
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
    u64::from(count) + clock::mul(u64::from(FRAME), (dt_us >> 9) + 1) >= u64::from(capacity)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A part re-initialised while still stalled may skip its first samples after the waking
    /// write: the FIFO count of a part coming back from a stall is not timing (counted as
    /// frames from that write on, one sample short, it bounds the clock off the truth;
    /// docs/firmware.md has the e2e run that showed it). Random grids, counts and latch
    /// instants: the same count from a running part moves the clock (so the test can tell),
    /// from a stalled one it leaves the clock as it was.
    #[test]
    fn a_stalled_parts_fifo_count_is_not_timing() {
        let mut rnd = crate::test_util::clock_keyed();
        for _ in 0..200 {
            let t_first = fine(1_000_000 + rnd() % 1_000_000);
            let frames = 1 + (rnd() % 12) as u16;
            // Latched after the sample the count says is the newest, before the next, not in
            // the middle (the line just started is a period wide: there, neither end moves).
            let off = 100 + rnd() % 300 + 500 * (rnd() % 2);
            let tau = t_first + fine(1000 * u64::from(frames - 1) + off);
            let moved = |phase: Phase| {
                let mut s = ImuService::new(BusTiming::from_hz(0));
                s.core.clock.start(0, t_first, false, Fine::ZERO);
                s.core.phase = phase;
                s.core.next_k = 0;
                s.core.fresh = true;
                let before = (s.core.clock.time(0), s.core.clock.width());
                s.observe_count(tau, frames * FRAME, false);
                (s.core.clock.time(0), s.core.clock.width()) != before
            };
            assert!(
                moved(Phase::Running),
                "a running part's count is an observation"
            );
            assert!(
                !moved(Phase::Stalled),
                "a stalled part's count moved the clock"
            );
        }
    }

    #[test]
    fn frames_by_multiplication_equal_division() {
        for c in 0..=4096 {
            assert_eq!(frames_in(c), c / FRAME, "{c}");
        }
    }
}
