//! Passes cortex-m-rt's linker script to the binary when it is built for a Cortex-M target (host
//! builds link nothing special); the memory map comes from `thumb-check-rt`'s build script.
use std::env;

fn main() {
    println!("cargo:rerun-if-changed=build.rs");
    if env::var("TARGET").unwrap_or_default().starts_with("thumbv") {
        for arg in ["--nmagic", "-Tlink.x"] {
            println!("cargo:rustc-link-arg-bins={arg}");
        }
    }
}
