//! The device-independent part of the pico-imu firmware: everything the tasks decide, kept free
//! of embassy and of the HAL so it is host-tested (tests/tests/firmware_*.rs) against the
//! register-level chip models. The firmware's tasks (`src/main.rs`) only move bytes between the
//! hardware and these types.
//!
//! By job:
//! * sensors: [`imu`] and [`mag`], the sensor tasks' ticks (initialisation, draining, faults,
//!   losses), over what they share in [`sensor`], with [`health`] (the fault state machine), [`clock`] (the sample clocks: the one
//!   owner of timestamps) and [`bus`] (what a bus must tell them);
//! * samples: [`pipeline`] (corrections → Allan engines → batches, losses and splits) over
//!   [`engines`];
//! * orientation: [`ahrs`] (attitude and heading from the calibrated samples);
//! * host requests: [`requests`];
//! * tables: [`tables`] (rounds of snapshots, spaced out);
//! * when each task's burst runs: [`schedule`] (the instants and turns the tasks wait for);
//! * [`device`] ties them together for the processing task; [`outbox`] queues frames whole or
//!   drops and counts them; [`cycle_marker`] marks the budget stages for the emulator; [`config`]
//!   holds the sensors' configuration; [`msg`] the messages between the tasks.
//!
//! `replay` (feature `std`) replays served samples through the same corrections and engines,
//! for the host tests and the emulator's end-to-end check.
//!
//! ```
//! use pico_imu_core::clock::{fine, Fine, SampleClock, Seen, US};
//!
//! // A 1 kHz part woken so that its first sample lands near 2 ms: its phase is known to half
//! // a period until observations bracket a sample instant.
//! let mut c = SampleClock::new(1000);
//! c.start(0, fine(2000), false, Fine::ZERO);
//! assert_eq!(c.width(), fine(1000));
//! // Sample 5 had been produced by a read latched at 7002 µs; at 6998 µs sample 4 had, 5 not.
//! c.observe(fine(7002), 5, Seen::Produced);
//! c.observe(fine(6998), 4, Seen::NextNotYet);
//! // Sample 5 is now located to within the latches' 4 µs plus their jitter and drift allowance.
//! assert!(c.width() <= 42 * US);
//! assert_eq!(c.newest_at(fine(7500), 10 * US), Some(5));
//! assert_eq!(c.newest_at(fine(7005), 10 * US), None, "too near sample 5 to tell");
//! // The stamps of samples 5, 6, 7, in whole µs: one period apart, on the located instant.
//! let s: Vec<u64> = c.stamps(5, 3).iter_us().take(3).collect();
//! assert!(s[0].abs_diff(7000) <= 21, "{s:?}");
//! assert_eq!([s[1] - s[0], s[2] - s[1]], [1000, 1000]);
//! ```
#![cfg_attr(not(any(test, feature = "std")), no_std)]
#[cfg(feature = "std")]
extern crate std;

pub mod ahrs;
pub mod bus;
pub mod clock;
pub mod config;
pub mod cycle_marker;
pub mod device;
pub mod engines;
pub mod health;
pub mod imu;
pub mod mag;
pub mod msg;
pub mod outbox;
pub mod pipeline;
#[cfg(feature = "std")]
pub mod replay;
pub mod requests;
pub mod schedule;
pub mod sensor;
pub mod settings;
pub mod tables;

/// What the unit tests share: the generator, a clock-keyed one, and a sink that keeps every
/// frame's bytes.
#[cfg(test)]
pub(crate) mod test_util {
    /// A xorshift64 stream from `seed` (not 0).
    pub fn xorshift(mut x: u64) -> impl FnMut() -> u64 {
        move || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            x
        }
    }

    /// A xorshift64 stream keyed by the clock (a fresh realisation every run); the key is
    /// printed, so that a failure can be replayed with [`xorshift`].
    pub fn clock_keyed() -> impl FnMut() -> u64 {
        let key = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(1, |d| d.as_nanos() as u64)
            | 1;
        std::println!("generator key {key:#x}");
        xorshift(key)
    }

    /// A [`crate::outbox::FrameSink`] with unlimited room that keeps every frame's bytes.
    pub struct Sink(pub std::vec::Vec<u8>);

    impl crate::outbox::FrameSink for Sink {
        fn room(&self) -> usize {
            usize::MAX
        }
        fn put(&mut self, frame: &[u8]) {
            self.0.extend_from_slice(frame);
        }
    }
}
