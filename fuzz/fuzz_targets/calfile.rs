//! cargo-fuzz target: the calfile decoder (crates/imu-lab/tests/fuzz/targets.rs).
#![no_main]
#![allow(dead_code)]

include!("../../crates/imu-lab/tests/fuzz/targets.rs");

libfuzzer_sys::fuzz_target!(|data: &[u8]| calfile_target(data));
