//! The device-independent part of the pico-imu firmware: everything the tasks decide, kept free
//! of embassy and of the HAL so it is host-tested (tests/tests/firmware_*.rs) against the
//! register-level chip models. The firmware's tasks (`src/main.rs`) only move bytes between the
//! hardware and these types.
//!
//! * [`outbox`]: frames queued whole or dropped and counted, never blocking the sampler;
//! * [`health`]: the sensor fault state machine (lost, retry with bus recovery, back);
//! * [`device`]: per-sample pipeline (corrections → Allan → batch) and host request handling;
//! * [`sensors`]: the sensor tasks' tick (init, FIFO drain, overflow, loss and retry);
//! * [`stage`]: cycle markers for the emulator's budget.
#![no_std]

pub mod device;
pub mod health;
pub mod outbox;
pub mod sensors;
pub mod stage;
