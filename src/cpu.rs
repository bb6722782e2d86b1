//! CPU load: the executor's busy time (from each `poll_start` to the following
//! `executor_idle`, via embassy-executor's `trace` hooks) over wall time.
//!
//! Interrupt handlers that run while the executor sleeps are not counted (they are short: I2C
//! FIFO refills, USB endpoint events), so this slightly under-reads; the emulator benchmark
//! counts every executed cycle and is the reference figure (docs/firmware.md).
//!
//! The hooks are free functions called by the executor, so their state is in `crate::shared`.
use core::sync::atomic::Ordering;

use embassy_time::Instant;

use crate::shared::{CPU_BUSY, CPU_SINCE};

fn now() -> u32 {
    Instant::now().as_ticks() as u32
}

// The hooks run only in thread mode, on the one executor, so each word has a single writer:
// plain atomic loads and stores suffice (the M0+ has no atomic read-modify-write, and a
// critical section per poll cost more than the measurement is worth).
#[unsafe(no_mangle)]
fn _embassy_trace_poll_start(_executor_id: u32) {
    CPU_SINCE.store(now(), Ordering::Relaxed);
}

#[unsafe(no_mangle)]
fn _embassy_trace_executor_idle(_executor_id: u32) {
    let busy = now().wrapping_sub(CPU_SINCE.load(Ordering::Relaxed));
    CPU_BUSY.store(
        CPU_BUSY.load(Ordering::Relaxed).wrapping_add(busy),
        Ordering::Relaxed,
    );
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
    last_busy: u32,
    last_at: u32,
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
        self.last_permille = (u64::from(db) * 1000)
            .checked_div(u64::from(dt))
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

fn busy_ticks() -> u32 {
    CPU_BUSY.load(Ordering::Relaxed)
}
