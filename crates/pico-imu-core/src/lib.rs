//! The device-independent part of the pico-imu firmware: everything the tasks decide, kept free
//! of embassy and of the HAL so it is host-tested (tests/tests/firmware_*.rs) against the
//! register-level chip models. The firmware's tasks (`src/main.rs`) only move bytes between the
//! hardware and these types.
//!
//! By job:
//! * sensors: [`imu`] and [`mag`], the sensor tasks' ticks (initialisation, draining, faults,
//!   losses), over what they share in [`service`], with [`health`] (the fault state machine), [`clock`] (the sample clocks: the one
//!   owner of timestamps) and [`bus`] (what a bus must tell them);
//! * samples: [`pipeline`] (corrections → Allan engines → batches, losses and splits) over
//!   [`engines`];
//! * orientation: [`ahrs`] (attitude and heading from the calibrated samples);
//! * host requests: [`requests`];
//! * tables: [`tables`] (rounds of snapshots, spaced out);
//! * [`device`] ties them together for the processing task; [`outbox`] queues frames whole or
//!   drops and counts them; [`stage`] marks the budget stages for the emulator; [`config`]
//!   holds the sensors' configuration; [`msg`] the messages between the tasks.
//!
//! `replay` (feature `std`) replays served samples through the same corrections and engines,
//! for the host tests and the emulator's end-to-end check.
#![cfg_attr(not(any(test, feature = "std")), no_std)]
#[cfg(feature = "std")]
extern crate std;

pub mod ahrs;
pub mod bus;
pub mod clock;
pub mod config;
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
pub mod service;
pub mod stage;
pub mod tables;
