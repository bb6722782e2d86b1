//! Puts memory.x and boot2.x on the linker search path and passes the cortex-m-rt and defmt
//! linker scripts to this binary (it is built for thumbv6m-none-eabi only).
use std::env;
use std::fs;
use std::path::PathBuf;

fn main() {
    let out = PathBuf::from(env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    fs::write(out.join("memory.x"), include_bytes!("memory.x")).expect("writing memory.x");
    fs::write(
        out.join("rp2040-hal-blocking-boot2.x"),
        include_bytes!("boot2.x"),
    )
    .expect("writing boot2.x");
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rerun-if-changed=memory.x");
    println!("cargo:rerun-if-changed=boot2.x");
    println!("cargo:rerun-if-changed=build.rs");
    if env::var("TARGET").unwrap_or_default().starts_with("thumbv") {
        for arg in [
            "--nmagic",
            "-Tlink.x",
            "-Trp2040-hal-blocking-boot2.x",
            "-Tdefmt.x",
        ] {
            println!("cargo:rustc-link-arg-bins={arg}");
        }
    }
}
