//! Puts memory.x on the linker search path and passes cortex-m-rt's linker script to the binary
//! when it is built for a Cortex-M target (host builds link nothing special).
use std::env;
use std::fs;
use std::path::PathBuf;

fn main() {
    let out = PathBuf::from(env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    fs::write(out.join("memory.x"), include_bytes!("memory.x")).expect("writing memory.x");
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rerun-if-changed=memory.x");
    println!("cargo:rerun-if-changed=build.rs");
    if env::var("TARGET").unwrap_or_default().starts_with("thumbv") {
        for arg in ["--nmagic", "-Tlink.x"] {
            println!("cargo:rustc-link-arg-bins={arg}");
        }
    }
}
