//! cargo-fuzz target: the blob decoder (crates/imu-lab/tests/fuzz/targets.rs).
#![no_main]
#![allow(dead_code)]

include!("../../crates/imu-lab/tests/fuzz/targets.rs");

libfuzzer_sys::fuzz_target!(|data: &[u8]| blob_target(data));
