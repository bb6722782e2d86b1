//! Placeholder until the firmware lands.
#![no_std]
#![no_main]
