//! The emulator harness (sim/, Node) reads the contract facts (CSV columns, units, sensor rates)
//! from `sim/src/contract.json`; this test keeps that file equal to what this crate says.
//! `PICO_IMU_WRITE_CONTRACT=1 cargo test -p imu-proto --test contract` rewrites it.
use std::path::PathBuf;

#[test]
fn the_harness_reads_the_same_contract_as_the_crate() {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../sim/src/contract.json");
    let want = imu_proto::contract_json();
    if std::env::var_os("PICO_IMU_WRITE_CONTRACT").is_some() {
        std::fs::write(&path, want.as_str()).expect("writing sim/src/contract.json");
    }
    let have = std::fs::read_to_string(&path).expect("reading sim/src/contract.json");
    assert_eq!(
        have,
        want.as_str(),
        "sim/src/contract.json differs from imu_proto::contract_json(): rerun with \
         PICO_IMU_WRITE_CONTRACT=1 and check the harness still reads it"
    );
    // And it is JSON the harness can parse, with the facts in it.
    let v: serde_json::Value = serde_json::from_str(&have).expect("valid JSON");
    assert_eq!(v["columns"][0]["name"], "t");
    assert_eq!(v["columns"][4]["name"], "gx");
    assert_eq!(v["columns"][4]["unit"], "deg/s");
    assert_eq!(v["sensors"]["imu"]["rate_hz"], imu_proto::IMU_RATE_HZ);
    assert_eq!(v["sensors"]["mag"]["period_us"], imu_proto::MAG_PERIOD_US);
}
