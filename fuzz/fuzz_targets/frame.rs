//! cargo-fuzz target: the frame decoder (crates/imu-lab/tests/fuzz/targets.rs).
#![no_main]
#![allow(dead_code)]

include!("../../crates/imu-lab/tests/fuzz/targets.rs");

libfuzzer_sys::fuzz_target!(|data: &[u8]| frame_target(data));
