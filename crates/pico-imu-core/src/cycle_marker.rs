//! Cycle markers for the emulator's budget (docs/emulator.md, "Cycle markers"): the firmware
//! stores the stage it enters in `PICO_IMU_STAGE` and `0` when it leaves; the harness charges
//! the executed cycles between stores to the current stage. One word store per transition.
use core::sync::atomic::{AtomicU32, Ordering};

/// The marker word the harness watches (symbol name is the contract).
#[unsafe(no_mangle)]
pub static PICO_IMU_STAGE: AtomicU32 = AtomicU32::new(0);

/// Pipeline stages, numbered as the harness expects.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum Stage {
    I2c = 1,
    Corrections = 2,
    Allan = 3,
    Usb = 4,
    /// The attitude filter's update (200 Hz).
    Ahrs = 5,
}

#[inline(always)]
pub fn enter(s: Stage) {
    PICO_IMU_STAGE.store(s as u32, Ordering::Relaxed);
}

#[inline(always)]
pub fn leave() {
    PICO_IMU_STAGE.store(0, Ordering::Relaxed);
}
