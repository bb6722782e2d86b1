//! The TIMER alarms the firmware drives itself: embassy-rp's time driver owns alarm 0; alarms
//! 1–3 each serve one waiting future at a time, without embassy's timer queue.
//!
//! A wait on embassy's queue (`Timer::at`) registers the task in the queue, whose every change
//! walks all its timers and re-arms alarm 0, and each expiry walks it again from the interrupt
//! (the cost is in docs/benchmarks.md). The sensor tasks wait hundreds of times a second (the
//! magnetometer's ticks, the IMU's burst fallback, every transfer's deadline), so each has an
//! alarm of its own: arming is one register write, the interrupt sets a flag and wakes the task.
//!
//! RP2040 datasheet §4.6 (Timer): an armed alarm fires when the low 32 bits of the µs counter
//! equal its value, so an instant that passes before it is armed would fire only after the
//! counter wraps (71 minutes): [`Wait`] checks the time again after arming.
use core::future::Future;
use core::pin::Pin;
use core::sync::atomic::Ordering;
use core::task::{Context, Poll, Waker};

use embassy_rp::interrupt::typelevel::{Binding, Handler, TIMER_IRQ_1, TIMER_IRQ_2, TIMER_IRQ_3};
use embassy_rp::interrupt::InterruptExt;
use embassy_rp::pac;
use embassy_time::{Duration, Instant};
use embedded_hal_async::delay::DelayNs;

use crate::statics::{ALARM_FIRED, ALARM_WAKERS, DMA_WAITING, DMA_WAKER};

// Alarms are programmed in embassy-time ticks: they must be the TIMER's µs.
const _: () = assert!(embassy_time::TICK_HZ == 1_000_000);

/// One of the TIMER alarms 1–3.
#[derive(Clone, Copy)]
pub struct Alarm(usize);

/// The I2C transaction deadline (`crate::bus`, `crate::i2c_dma`): transactions hold the bus
/// mutex, so one runs at a time.
pub const DEADLINE: Alarm = Alarm(1);
/// The magnetometer task's ticks.
pub const MAG_TICK: Alarm = Alarm(2);
/// The IMU task's burst fallback.
pub const IMU_FALLBACK: Alarm = Alarm(3);

impl Alarm {
    /// Arm for `at` and have `waker` woken when it passes. `false`: `at` has already passed
    /// (the alarm is left disarmed).
    pub fn arm(self, at: Instant, waker: &Waker) -> bool {
        ALARM_WAKERS[self.0].register(waker);
        ALARM_FIRED[self.0].store(false, Ordering::Relaxed);
        pac::TIMER.alarm(self.0).write_value(at.as_ticks() as u32);
        if Instant::now() >= at {
            self.disarm();
            return false;
        }
        true
    }

    /// Arm for the low 32 bits `at_us` of a µs instant well ahead, without a waker: a DMA
    /// transfer's deadline ([`DEADLINE`]), whose interrupt wakes that transfer's waker. Two
    /// stores, where [`Self::arm`] registers a waker (a critical section on the M0+) and reads
    /// the 64-bit time again.
    pub fn arm_deadline(self, at_us: u32) {
        ALARM_FIRED[self.0].store(false, Ordering::Relaxed);
        pac::TIMER.alarm(self.0).write_value(at_us);
    }

    /// Whether the alarm has fired since it was last armed.
    pub fn fired(self) -> bool {
        ALARM_FIRED[self.0].load(Ordering::Relaxed)
    }

    /// Disarm (harmless when not armed, or already fired).
    pub fn disarm(self) {
        pac::TIMER.armed().write(|w| w.set_armed(1 << self.0));
    }

    /// A future that completes at `at` (at once if it has passed). One wait per alarm at a time.
    pub fn wait_until(self, at: Instant) -> Wait {
        Wait {
            alarm: self,
            at,
            armed: false,
        }
    }
}

/// [`Alarm::wait_until`]. Disarms its alarm when dropped early.
pub struct Wait {
    alarm: Alarm,
    at: Instant,
    armed: bool,
}

impl Future for Wait {
    type Output = ();

    fn poll(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<()> {
        let this = self.get_mut();
        if this.armed {
            // Woken by something else (a `select`'s other branch): still waiting. The task's
            // waker, registered when armed, stays the same (an embassy task's).
            if !this.alarm.fired() {
                return Poll::Pending;
            }
            // A fired alarm disarms itself.
            this.armed = false;
            if Instant::now() >= this.at {
                return Poll::Ready(());
            }
            // Fired before `at`: the 32-bit compare matched a wrap of the counter (a wait over
            // 71 minutes). Armed again below.
        }
        // `arm` finds an instant already passed (and leaves the alarm disarmed).
        this.armed = this.alarm.arm(this.at, cx.waker());
        if this.armed {
            Poll::Pending
        } else {
            Poll::Ready(())
        }
    }
}

impl Drop for Wait {
    fn drop(&mut self) {
        if self.armed {
            self.alarm.disarm();
        }
    }
}

/// `DelayNs` on one of these alarms: the sensor tasks' waits within a tick (a probe instant, a
/// status re-poll, a part's start-up) stay off embassy's timer queue too. Its alarm must not be
/// waited on otherwise meanwhile (each task lends its own tick alarm, idle during a tick).
pub struct Delay(pub Alarm);

impl DelayNs for Delay {
    async fn delay_ns(&mut self, ns: u32) {
        self.delay_us(ns.div_ceil(1000)).await;
    }

    async fn delay_us(&mut self, us: u32) {
        let at = Instant::now() + Duration::from_micros(u64::from(us));
        self.0.wait_until(at).await;
    }

    async fn delay_ms(&mut self, ms: u32) {
        let at = Instant::now() + Duration::from_millis(u64::from(ms));
        self.0.wait_until(at).await;
    }
}

/// TIMER_IRQ_1..3: an alarm fired; flag it and wake its task.
pub struct AlarmHandler;

fn fire(n: usize) {
    pac::TIMER.intr().write(|w| w.set_alarm(n, true));
    ALARM_FIRED[n].store(true, Ordering::Relaxed);
    ALARM_WAKERS[n].wake();
}

impl Handler<TIMER_IRQ_1> for AlarmHandler {
    unsafe fn on_interrupt() {
        fire(1);
        // The deadline of a DMA transfer (`crate::i2c_dma`), armed without a waker of its own.
        if DMA_WAITING.load(Ordering::Relaxed) {
            DMA_WAKER.wake();
        }
    }
}

impl Handler<TIMER_IRQ_2> for AlarmHandler {
    unsafe fn on_interrupt() {
        fire(2);
    }
}

impl Handler<TIMER_IRQ_3> for AlarmHandler {
    unsafe fn on_interrupt() {
        fire(3);
    }
}

/// Enable the interrupts of alarms 1–3 (once, at boot; [`AlarmHandler`] must be bound to all
/// three).
pub fn init<B>(_irqs: B)
where
    B: Binding<TIMER_IRQ_1, AlarmHandler>
        + Binding<TIMER_IRQ_2, AlarmHandler>
        + Binding<TIMER_IRQ_3, AlarmHandler>,
{
    pac::TIMER.inte().modify(|w| {
        for n in 1..4 {
            w.set_alarm(n, true);
        }
    });
    for irq in [
        embassy_rp::interrupt::TIMER_IRQ_1,
        embassy_rp::interrupt::TIMER_IRQ_2,
        embassy_rp::interrupt::TIMER_IRQ_3,
    ] {
        irq.unpend();
        // SAFETY: its handler (`AlarmHandler`) only clears its alarm's flag and wakes a waker.
        unsafe { irq.enable() };
    }
}
