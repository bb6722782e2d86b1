//! The differential test as a bare-metal RP2040 program for the emulator
//! (sim/test/frame-thumb.test.js): runs [`imu_proto_thumb_check::run`] and stops at a
//! breakpoint; the results are in the `#[no_mangle]` static `FRAME_CHECK` (an
//! [`imu_proto_thumb_check::Report`]), which the test reads from RAM by its symbol. No boot2,
//! no clocks set up (the emulator needs neither), no semihosting. On other targets this binary
//! does nothing.
#![cfg_attr(all(target_arch = "arm", target_os = "none"), no_std, no_main)]

#[cfg(all(target_arch = "arm", target_os = "none"))]
mod device {
    use core::ptr::addr_of_mut;
    use imu_proto_thumb_check::{run, Report, CASES, SEED};

    /// The results, read by the emulator test at this symbol's address.
    #[no_mangle]
    static mut FRAME_CHECK: Report = Report::new();

    #[cortex_m_rt::entry]
    fn main() -> ! {
        // SAFETY: the only reference to the report while the program runs (the panic handler
        // writes through a raw pointer, after this one's last use).
        let report = unsafe { &mut *addr_of_mut!(FRAME_CHECK) };
        run(report, CASES, SEED);
        thumb_check_rt::done()
    }

    #[panic_handler]
    fn panic(info: &core::panic::PanicInfo) -> ! {
        let line = info.location().map_or(u32::MAX, |l| l.line());
        // SAFETY: the run is over; a plain store through the static's address.
        unsafe { (*addr_of_mut!(FRAME_CHECK)).panic_line = line };
        thumb_check_rt::panicked()
    }
}

#[cfg(not(all(target_arch = "arm", target_os = "none")))]
fn main() {
    eprintln!("imu-proto-thumb-check runs on the emulated RP2040: build it for thumbv6m-none-eabi");
}
