//! The firmware's statics: the only state shared between tasks and the code that cannot be
//! handed a reference (interrupt handlers, and the executor's run loop for the CPU meter). Each
//! is an atomic or a waker with one writer per side, named after its owner; everything else a
//! task needs it is given at spawn (`StaticCell`s in `main.rs`, initialised once).
use core::sync::atomic::{AtomicBool, AtomicU32};

use embassy_sync::waitqueue::AtomicWaker;

/// `crate::cpu`: µs the executor has slept, wrapping (differences are right for intervals under
/// 71 minutes).
pub static CPU_IDLE: AtomicU32 = AtomicU32::new(0);

/// `crate::alarm`: the task waiting on each TIMER alarm (index = alarm; 0 is embassy's).
pub static ALARM_WAKERS: [AtomicWaker; 4] = [const { AtomicWaker::new() }; 4];
/// `crate::alarm`: set by an alarm's interrupt, cleared when the alarm is armed.
pub static ALARM_FIRED: [AtomicBool; 4] = [const { AtomicBool::new(false) }; 4];

/// `crate::i2c_dma`: the task whose DMA transfer is in flight.
pub static DMA_WAKER: AtomicWaker = AtomicWaker::new();
/// `crate::i2c_dma`: a DMA transfer is waiting on [`DMA_WAKER`] (else the I2C interrupt is
/// embassy's path's alone).
pub static DMA_WAITING: AtomicBool = AtomicBool::new(false);
