//! CPU load: the executor's busy time (from each `poll_start` to the following
//! `executor_idle`, via embassy-executor's `trace` hooks) over wall time.
//!
//! Interrupt handlers that run while the executor sleeps are not counted (they are short: I2C
//! FIFO refills, USB endpoint events), so this slightly under-reads; the emulator benchmark
//! counts every executed cycle and is the reference figure (docs/firmware.md).
//!
//! This accumulator is the firmware's only static beyond embassy's own: the hooks are free
//! functions called by the executor, so the state cannot be passed to them.
use core::cell::Cell;

use critical_section::Mutex;
use embassy_time::Instant;

struct Busy {
    since: Cell<u64>,
    total: Cell<u64>,
}

static BUSY: Mutex<Busy> = Mutex::new(Busy {
    since: Cell::new(0),
    total: Cell::new(0),
});

fn now() -> u64 {
    Instant::now().as_ticks()
}

#[unsafe(no_mangle)]
fn _embassy_trace_poll_start(_executor_id: u32) {
    critical_section::with(|cs| BUSY.borrow(cs).since.set(now()));
}

#[unsafe(no_mangle)]
fn _embassy_trace_executor_idle(_executor_id: u32) {
    critical_section::with(|cs| {
        let b = BUSY.borrow(cs);
        b.total.set(
            b.total
                .get()
                .wrapping_add(now().wrapping_sub(b.since.get())),
        );
    });
}

#[unsafe(no_mangle)]
fn _embassy_trace_task_new(_executor_id: u32, _task_id: u32) {}
#[unsafe(no_mangle)]
fn _embassy_trace_task_end(_executor_id: u32, _task_id: u32) {}
#[unsafe(no_mangle)]
fn _embassy_trace_task_exec_begin(_executor_id: u32, _task_id: u32) {}
#[unsafe(no_mangle)]
fn _embassy_trace_task_exec_end(_executor_id: u32, _task_id: u32) {}
#[unsafe(no_mangle)]
fn _embassy_trace_task_ready_begin(_executor_id: u32, _task_id: u32) {}

/// Busy fraction between successive [`Meter::sample`] calls.
pub struct Meter {
    last_busy: u64,
    last_at: u64,
    last_permille: u16,
}

impl Meter {
    pub fn new() -> Self {
        Self {
            last_busy: busy_ticks(),
            last_at: now(),
            last_permille: 0,
        }
    }

    /// Load since the previous sample, ‰ of wall time.
    pub fn sample(&mut self) -> u16 {
        let (busy, at) = (busy_ticks(), now());
        let dt = at.wrapping_sub(self.last_at);
        let db = busy.wrapping_sub(self.last_busy);
        self.last_permille = db
            .saturating_mul(1000)
            .checked_div(dt)
            .unwrap_or(0)
            .min(1000) as u16;
        self.last_busy = busy;
        self.last_at = at;
        self.last_permille
    }

    /// The figure of the last sample.
    pub fn last_permille(&self) -> u16 {
        self.last_permille
    }
}

fn busy_ticks() -> u64 {
    critical_section::with(|cs| BUSY.borrow(cs).total.get())
}
