//! Each chip's register table is stated once, in the driver (`imu_drivers::*::reg*::TABLE`);
//! the emulator's JavaScript models (sim/src/devices) name the same registers at the same
//! addresses. The Rust chip models take their addresses from the driver directly.
use std::collections::BTreeMap;
use std::path::Path;

/// The `export const REG = { NAME: 0x.., … };` object of a JavaScript model.
fn js_registers(file: &str) -> BTreeMap<String, u8> {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../sim/src/devices")
        .join(file);
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let start = text
        .find("export const REG = {")
        .unwrap_or_else(|| panic!("{file}: no `export const REG = {{` table"));
    let body = &text[start + "export const REG = {".len()..];
    let body = &body[..body.find("};").expect("the table's end")];
    let mut out = BTreeMap::new();
    for entry in body.split(',').map(str::trim).filter(|e| !e.is_empty()) {
        let (name, value) = entry
            .split_once(':')
            .unwrap_or_else(|| panic!("{file}: entry {entry:?}"));
        let value = value.trim();
        let v = u8::from_str_radix(value.trim_start_matches("0x"), 16)
            .unwrap_or_else(|_| panic!("{file}: {name} = {value:?} is not a hex byte"));
        assert!(
            out.insert(name.trim().to_string(), v).is_none(),
            "{file}: {name} twice"
        );
    }
    out
}

/// Every register of the JavaScript model is in the driver's table at the same address.
fn check(file: &str, table: &[(&str, u8)]) {
    let js = js_registers(file);
    assert!(js.len() >= 5, "{file}: {} registers", js.len());
    let driver: BTreeMap<&str, u8> = table.iter().copied().collect();
    for (name, addr) in &js {
        match driver.get(name.as_str()) {
            Some(&a) => assert_eq!(
                a, *addr,
                "{file}: {name} at {addr:#04x}, the driver's table says {a:#04x}"
            ),
            None => panic!("{file}: {name} ({addr:#04x}) is not in the driver's table"),
        }
    }
}

#[test]
fn the_emulator_models_use_the_drivers_register_tables() {
    check("mpu6050.js", imu_drivers::mpu6050::reg::TABLE);
    check("qmc5883l.js", imu_drivers::qmc5883::reg_l::TABLE);
}

#[test]
fn a_drifted_address_is_caught() {
    let mut table = imu_drivers::qmc5883::reg_l::TABLE.to_vec();
    let status = table.iter_mut().find(|(n, _)| *n == "STATUS").unwrap();
    status.1 = 0x07;
    let r = std::panic::catch_unwind(|| check("qmc5883l.js", &table));
    assert!(r.is_err());
}
