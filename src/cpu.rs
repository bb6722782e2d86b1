//! CPU load, and the executor's run loop that measures it: the thread-mode executor polls its
//! tasks, then sleeps in `WFE` until an interrupt or a task's wake-up (`SEV`) ends the sleep; the
//! time asleep is idle, everything else busy (over wall time).
//!
//! Interrupt handlers that run while the executor sleeps are counted as idle (they are short:
//! I2C and DMA completions, USB endpoint events), so this slightly under-reads; the emulator
//! benchmark counts every executed cycle and is the reference figure (docs/firmware.md).
//! (embassy's `trace` hooks would measure the same per poll, at a call per task wake-up and
//! poll; two timer reads per sleep are cheaper.)
use core::sync::atomic::Ordering;

use embassy_executor::raw;
use embassy_rp::pac;

use crate::statics::CPU_IDLE;

/// The timer's low word (1 MHz ticks, embassy's time base), read raw: one register read
/// instead of embassy's 64-bit `Instant::now()` (three reads, a retry loop and a call through
/// the time driver), twice per sleep; differences of up to 71 minutes are exact in 32 bits.
fn now() -> u32 {
    pac::TIMER.timerawl().read()
}

/// Run `executor` for ever in thread mode: poll, then sleep until there is work again, adding
/// the time asleep to the idle count. (embassy's thread executor without the count: its pender
/// for thread mode, `SEV`, ends the `WFE`.)
pub fn run(executor: &'static raw::Executor) -> ! {
    loop {
        // SAFETY: the executor is polled from this one thread-mode loop only.
        unsafe { executor.poll() };
        let t0 = now();
        cortex_m::asm::wfe();
        // A single writer (this loop): a plain load and store (the M0+ has no atomic add).
        let idle = CPU_IDLE.load(Ordering::Relaxed);
        CPU_IDLE.store(idle.wrapping_add(now().wrapping_sub(t0)), Ordering::Relaxed);
    }
}

/// Busy fraction between successive [`Meter::sample`] calls.
pub struct Meter {
    last_idle: u32,
    last_at: u32,
    last_permille: u16,
}

impl Meter {
    pub fn new() -> Self {
        Self {
            last_idle: idle_ticks(),
            last_at: now(),
            last_permille: 0,
        }
    }

    /// Load since the previous sample, ‰ of wall time.
    pub fn sample(&mut self) -> u16 {
        let (idle, at) = (idle_ticks(), now());
        let dt = at.wrapping_sub(self.last_at);
        let db = dt.saturating_sub(idle.wrapping_sub(self.last_idle));
        self.last_permille = (u64::from(db) * 1000)
            .checked_div(u64::from(dt))
            .unwrap_or(0)
            .min(1000) as u16;
        self.last_idle = idle;
        self.last_at = at;
        self.last_permille
    }

    /// The figure of the last sample.
    pub fn last_permille(&self) -> u16 {
        self.last_permille
    }
}

fn idle_ticks() -> u32 {
    CPU_IDLE.load(Ordering::Relaxed)
}
