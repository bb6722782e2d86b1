//! The differential test as a bare-metal RP2040 program for the emulator
//! (sim/test/thumb-diff.test.js): runs [`allan_thumb_check::run`] and stops at a breakpoint;
//! then [`allan_thumb_check::run_mag`], and stops at a breakpoint; the results are in the
//! `#[no_mangle]` statics `THUMB_CHECK` and `THUMB_CHECK_MAG` (each an [`allan_thumb_check::Report`]),
//! which the test reads from RAM by its symbol. No boot2, no clocks set up (the emulator needs
//! neither), no semihosting. On other targets this binary does nothing.
#![cfg_attr(all(target_arch = "arm", target_os = "none"), no_std, no_main)]

#[cfg(all(target_arch = "arm", target_os = "none"))]
mod device {
    use allan::{DeviceEngine, MagEngine};
    use allan_thumb_check::{run, run_mag, Report, CASES, MAG_CASES, MAG_SEED, SEED};
    use core::ptr::addr_of_mut;

    /// The results, read by the emulator test at this symbol's address.
    #[no_mangle]
    static mut THUMB_CHECK: Report = Report::new();

    /// The magnetometer run's results ([`run_mag`]), read the same way.
    #[no_mangle]
    static mut THUMB_CHECK_MAG: Report = Report::new();

    #[cortex_m_rt::entry]
    fn main() -> ! {
        // The two engines live on the stack (2 × 3328 bytes).
        let mut a = DeviceEngine::new();
        let mut b = DeviceEngine::new();
        // SAFETY: the only reference to the report while the program runs (the panic handler
        // writes through a raw pointer, after this one's last use).
        let report = unsafe { &mut *addr_of_mut!(THUMB_CHECK) };
        run(report, &mut a, &mut b, CASES, SEED);
        // Then the magnetometer's engines (2 × 3040 bytes on the stack).
        let mut a = MagEngine::new();
        let mut b = MagEngine::new();
        // SAFETY: as above; `report` is not used from here on.
        let report = unsafe { &mut *addr_of_mut!(THUMB_CHECK_MAG) };
        run_mag(report, &mut a, &mut b, MAG_CASES, MAG_SEED);
        thumb_check_rt::done()
    }

    #[panic_handler]
    fn panic(info: &core::panic::PanicInfo) -> ! {
        let line = info.location().map_or(u32::MAX, |l| l.line());
        // SAFETY: the run is over; a plain store through the static's address.
        unsafe { (*addr_of_mut!(THUMB_CHECK)).panic_line = line };
        // SAFETY: as above (either run may be the one that panicked).
        unsafe { (*addr_of_mut!(THUMB_CHECK_MAG)).panic_line = line };
        thumb_check_rt::panicked()
    }
}

#[cfg(not(all(target_arch = "arm", target_os = "none")))]
fn main() {
    eprintln!("allan-thumb-check runs on the emulated RP2040: build it for thumbv6m-none-eabi");
}
