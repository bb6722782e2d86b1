//! `cargo xtask firmware`: release build of the firmware, a flash/RAM size report read from the
//! ELF (no llvm-tools needed), and the UF2 file for users without a debug probe.
//!
//! UF2 format: Microsoft's "USB Flashing Format" specification (github.com/microsoft/uf2,
//! README "File format"): 512-byte blocks, each with six little-endian header words (two magics,
//! flags, target address, payload size, block number), the total block count, a family id
//! (flag 0x2000), 476 data bytes of which the RP2040 bootrom uses 256, and an end magic.
use std::fmt::Write as _;
use std::fs;
use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use object::{Object, ObjectSection, ObjectSymbol};

use crate::{cargo, root, run, target_dir};

/// RP2040 family id (UF2 spec, utils/uf2families.json: "RP2040").
pub const RP2040_FAMILY_ID: u32 = 0xe48b_ff56;
const UF2_MAGIC_START0: u32 = 0x0A32_4655; // "UF2\n"
const UF2_MAGIC_START1: u32 = 0x9E5D_5157;
const UF2_MAGIC_END: u32 = 0x0AB1_6F30;
const UF2_FLAG_FAMILY_ID: u32 = 0x0000_2000;
/// Payload bytes per block the RP2040 bootrom accepts.
const UF2_PAYLOAD: usize = 256;

/// XIP flash window of the Pico W (2 MiB).
const FLASH: std::ops::Range<u64> = 0x1000_0000..0x1020_0000;
/// Flash the firmware may occupy: memory.x keeps the last 64 KiB for calibration.
const FLASH_FOR_CODE: u64 = 2 * 1024 * 1024 - 64 * 1024;
/// SRAM (striped banks 0–3, then the two 4 KiB banks).
const RAM: std::ops::Range<u64> = 0x2000_0000..0x2004_2000;
/// RAM given to the linker in memory.x.
const RAM_LINKED: u64 = 256 * 1024;

/// `cargo xtask firmware [--no-build]`.
#[derive(Debug, Clone, clap::Args)]
pub struct FirmwareArgs {
    /// Report on the ELF already built instead of building it first.
    #[arg(long)]
    pub no_build: bool,
}

/// Builds the firmware (unless `--no-build`), prints and writes its size report, writes the UF2.
pub fn main(args: &FirmwareArgs) -> Result<()> {
    let elf = if args.no_build { elf_path()? } else { build()? };
    let data = fs::read(&elf).with_context(|| format!("reading {}", elf.display()))?;
    let report = size_report(&data)?;
    print!("{}", report.text);
    if report.ram >= RAM_LINKED {
        bail!(
            "static RAM {} B leaves no stack (RAM is {RAM_LINKED} B)",
            report.ram
        );
    }
    println!(
        "firmware: flash {} B, static RAM {} B",
        report.flash, report.ram
    );
    let out = root().join("out");
    fs::create_dir_all(&out).with_context(|| format!("creating {}", out.display()))?;
    fs::write(out.join("firmware-size.md"), &report.text)?;
    let uf2 = elf_to_uf2(&data)?;
    check_uf2(&uf2, &flash_image(&data)?).context("self-check of the UF2 just written")?;
    let uf2_path = out.join("pico-imu.uf2");
    fs::write(&uf2_path, &uf2).with_context(|| format!("writing {}", uf2_path.display()))?;
    println!(
        "UF2: {} ({} blocks, {} bytes; family 0x{RP2040_FAMILY_ID:08x}) — hold BOOTSEL, plug in, copy to RPI-RP2",
        uf2_path.display(),
        uf2.len() / 512,
        uf2.len()
    );
    Ok(())
}

/// The ELF `cargo build --release -p pico-imu` writes, in cargo's target directory (which
/// honours `CARGO_TARGET_DIR` and `build.target-dir`).
pub fn elf_path() -> Result<PathBuf> {
    Ok(elf_in(&target_dir()?))
}

/// The firmware ELF under the target directory `target`.
pub fn elf_in(target: &Path) -> PathBuf {
    target.join("thumbv6m-none-eabi/release/pico-imu")
}

/// Release build of the firmware; returns the ELF path.
pub fn build() -> Result<PathBuf> {
    ensure_target();
    run(cargo().args(["build", "--release", "-p", "pico-imu"]))?;
    let elf = elf_path()?;
    if !elf.is_file() {
        bail!("the firmware build did not produce {}", elf.display());
    }
    Ok(elf)
}

/// Install the device target when rustup is there and lacks it (a no-op when it is installed;
/// rust-toolchain.toml alone does not install targets everywhere).
fn ensure_target() {
    let listed = std::process::Command::new("rustup")
        .args(["target", "list", "--installed"])
        .current_dir(root())
        .output();
    match listed {
        Ok(out)
            if String::from_utf8_lossy(&out.stdout)
                .lines()
                .any(|l| l.trim() == "thumbv6m-none-eabi") => {}
        Ok(_) => {
            let _ = run(std::process::Command::new("rustup").args([
                "target",
                "add",
                "thumbv6m-none-eabi",
            ]));
        }
        Err(_) => eprintln!(
            "xtask: rustup not found; the thumbv6m-none-eabi target must be installed by hand"
        ),
    }
}

/// Flash and RAM use.
pub struct SizeReport {
    /// Bytes stored in flash (every PT_LOAD segment's file bytes: boot2, vectors, code, rodata,
    /// the initial values of .data).
    pub flash: u64,
    /// Bytes of RAM taken by static data (.data, .bss, .uninit and the like).
    pub ram: u64,
    /// Markdown table by section.
    pub text: String,
}

/// Size report from the ELF's section and segment headers.
pub fn size_report(elf: &[u8]) -> Result<SizeReport> {
    let file = object::File::parse(elf).context("parsing the firmware ELF")?;
    let flash: u64 = load_segments(elf)?
        .iter()
        .map(|(_, d)| d.len() as u64)
        .sum();
    let mut rows = Vec::new();
    let mut ram = 0;
    for s in file.sections() {
        let (addr, size) = (s.address(), s.size());
        if size == 0 || addr == 0 {
            continue; // debug info and other non-allocated sections
        }
        let name = s.name().unwrap_or("?").to_string();
        let region = if FLASH.contains(&addr) {
            "flash"
        } else if RAM.contains(&addr) {
            ram += size;
            if name == ".data" {
                "RAM (initial values in flash)"
            } else {
                "RAM"
            }
        } else {
            continue;
        };
        rows.push((name, addr, size, region));
    }
    rows.sort_by_key(|r| r.1);
    let mut text = String::new();
    writeln!(text, "# Firmware size\n")?;
    writeln!(
        text,
        "| section | address | size [B] | region |\n|---|---|---:|---|"
    )?;
    for (name, addr, size, region) in &rows {
        writeln!(text, "| `{name}` | 0x{addr:08x} | {size} | {region} |")?;
    }
    writeln!(
        text,
        "\nflash: {flash} B of {FLASH_FOR_CODE} B ({:.1} %); static RAM: {ram} B of {RAM_LINKED} B ({:.1} %), the rest is stack\n",
        100.0 * flash as f64 / FLASH_FOR_CODE as f64,
        100.0 * ram as f64 / RAM_LINKED as f64
    )?;
    // The largest statics in RAM (task futures, queues, the device state with its Allan engines).
    let mut statics: Vec<(u64, String)> = file
        .symbols()
        .filter(|s| RAM.contains(&s.address()) && s.size() >= 1024)
        .map(|s| (s.size(), demangle(s.name().unwrap_or("?"))))
        .collect();
    statics.sort_by(|a, b| b.cmp(a));
    writeln!(text, "| largest statics in RAM | size [B] |\n|---|---:|")?;
    for (size, name) in statics.iter().take(8) {
        writeln!(text, "| `{name}` | {size} |")?;
    }
    writeln!(text)?;
    if flash > FLASH_FOR_CODE {
        bail!("the firmware ({flash} B) overlaps the calibration area (limit {FLASH_FOR_CODE} B)");
    }
    Ok(SizeReport { flash, ram, text })
}

/// Readable name of a legacy-mangled Rust symbol (`_ZN8pico_imu6DEVICE17h…E` →
/// `pico_imu::DEVICE`): the length-prefixed path segments, without the trailing hash.
fn demangle(sym: &str) -> String {
    let Some(mut rest) = sym.strip_prefix("_ZN") else {
        return sym.to_string();
    };
    let mut parts = Vec::new();
    while let Some(d) = rest.find(|c: char| !c.is_ascii_digit()).filter(|&d| d > 0) {
        let Ok(n) = rest[..d].parse::<usize>() else {
            break;
        };
        let Some(seg) = rest.get(d..d + n) else { break };
        parts.push(seg);
        rest = &rest[d + n..];
    }
    if parts
        .last()
        .is_some_and(|p| p.len() == 17 && p.starts_with('h'))
    {
        parts.pop();
    }
    if parts.is_empty() {
        sym.to_string()
    } else {
        parts.join("::").replace("$LT$", "<").replace("$GT$", ">")
    }
}

/// The flash image of the ELF as UF2 blocks of 256 bytes, every 256-byte page the image
/// touches, padded with 0xFF, in address order.
pub fn elf_to_uf2(elf: &[u8]) -> Result<Vec<u8>> {
    let image = flash_image(elf)?;
    let pages: Vec<(u32, &[u8])> = image
        .chunks(UF2_PAYLOAD)
        .enumerate()
        .filter(|(_, c)| c.iter().any(|&b| b != 0xFF))
        .map(|(i, c)| ((FLASH.start as usize + i * UF2_PAYLOAD) as u32, c))
        .collect();
    if pages.is_empty() {
        bail!("the ELF has nothing to place in flash");
    }
    let total = pages.len() as u32;
    let mut out = Vec::with_capacity(pages.len() * 512);
    for (n, (addr, data)) in pages.iter().enumerate() {
        let mut block = [0u8; 512];
        let words = [
            UF2_MAGIC_START0,
            UF2_MAGIC_START1,
            UF2_FLAG_FAMILY_ID,
            *addr,
            UF2_PAYLOAD as u32,
            n as u32,
            total,
            RP2040_FAMILY_ID,
        ];
        for (i, w) in words.iter().enumerate() {
            block[i * 4..i * 4 + 4].copy_from_slice(&w.to_le_bytes());
        }
        block[32..32 + data.len()].copy_from_slice(data);
        block[32 + data.len()..32 + UF2_PAYLOAD].fill(0xFF);
        block[508..512].copy_from_slice(&UF2_MAGIC_END.to_le_bytes());
        out.extend_from_slice(&block);
    }
    Ok(out)
}

/// Flash contents from the PT_LOAD segments, by physical address (so .data's initial values
/// land at their load address in flash, not at their RAM address). 0xFF where nothing is loaded.
pub fn flash_image(elf: &[u8]) -> Result<Vec<u8>> {
    let segs = load_segments(elf)?;
    let end = segs
        .iter()
        .map(|(p, d)| *p + d.len() as u64)
        .max()
        .unwrap_or(FLASH.start);
    let mut image = vec![0xFFu8; (end - FLASH.start) as usize];
    for (paddr, data) in segs {
        let off = (paddr - FLASH.start) as usize;
        image[off..off + data.len()].copy_from_slice(data);
    }
    Ok(image)
}

/// (physical address, file bytes) of every PT_LOAD segment that lands in flash, read from the
/// ELF32 program headers (the `object` crate's segment API gives only virtual addresses).
fn load_segments(elf: &[u8]) -> Result<Vec<(u64, &[u8])>> {
    use object::elf::{FileHeader32, PT_LOAD};
    use object::read::elf::{FileHeader, ProgramHeader};
    use object::LittleEndian;
    let hdr =
        FileHeader32::<LittleEndian>::parse(elf).context("the firmware is not an ELF32 file")?;
    let e = hdr.endian().context("ELF endianness")?;
    let mut out = Vec::new();
    for ph in hdr
        .program_headers(e, elf)
        .context("reading program headers")?
    {
        if ph.p_type(e) != PT_LOAD || ph.p_filesz(e) == 0 {
            continue;
        }
        let paddr = u64::from(ph.p_paddr(e));
        let data = ph
            .data(e, elf)
            .map_err(|()| anyhow::anyhow!("segment at 0x{paddr:08x} lies outside the file"))?;
        if !FLASH.contains(&paddr) {
            continue;
        }
        if paddr + data.len() as u64 > FLASH.end {
            bail!(
                "segment at 0x{paddr:08x} ({} B) runs past the end of flash",
                data.len()
            );
        }
        out.push((paddr, data));
    }
    Ok(out)
}

/// Check a UF2 file (used by the tests and by `main` as a self-check).
pub fn check_uf2(uf2: &[u8], image: &[u8]) -> Result<()> {
    if !uf2.len().is_multiple_of(512) {
        bail!("UF2 length {} is not a multiple of 512", uf2.len());
    }
    let word = |b: &[u8], i: usize| {
        u32::from_le_bytes([b[i * 4], b[i * 4 + 1], b[i * 4 + 2], b[i * 4 + 3]])
    };
    let total = uf2.len() / 512;
    for (n, b) in uf2.chunks(512).enumerate() {
        if word(b, 0) != UF2_MAGIC_START0
            || word(b, 1) != UF2_MAGIC_START1
            || word(b, 127) != UF2_MAGIC_END
        {
            bail!("block {n}: bad magic");
        }
        if word(b, 5) as usize != n
            || word(b, 6) as usize != total
            || word(b, 7) != RP2040_FAMILY_ID
        {
            bail!("block {n}: bad number/total/family");
        }
        let addr = word(b, 3) as u64;
        let off = (addr - FLASH.start) as usize;
        let want = &image[off..(off + UF2_PAYLOAD).min(image.len())];
        if &b[32..32 + want.len()] != want {
            bail!("block {n} at 0x{addr:08x}: payload differs from the ELF image");
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A minimal ELF32 little-endian ARM image with two PT_LOAD segments: 300 bytes at
    /// 0x10000000 and 8 bytes whose VMA is in RAM but whose LMA is 0x10000400 (like .data).
    fn tiny_elf() -> Vec<u8> {
        let mut f = vec![0u8; 52 + 2 * 32];
        let seg_a: Vec<u8> = (0..300u32).map(|i| (i % 251) as u8).collect();
        let seg_b = [1u8, 2, 3, 4, 5, 6, 7, 8];
        let off_a = f.len();
        f.extend_from_slice(&seg_a);
        let off_b = f.len();
        f.extend_from_slice(&seg_b);
        f[0..4].copy_from_slice(b"\x7fELF");
        f[4] = 1; // ELFCLASS32
        f[5] = 1; // little endian
        f[6] = 1; // version
        f[16..18].copy_from_slice(&2u16.to_le_bytes()); // ET_EXEC
        f[18..20].copy_from_slice(&40u16.to_le_bytes()); // EM_ARM
        f[20..24].copy_from_slice(&1u32.to_le_bytes());
        f[28..32].copy_from_slice(&52u32.to_le_bytes()); // e_phoff
        f[40..42].copy_from_slice(&52u16.to_le_bytes()); // e_ehsize
        f[42..44].copy_from_slice(&32u16.to_le_bytes()); // e_phentsize
        f[44..46].copy_from_slice(&2u16.to_le_bytes()); // e_phnum
        f[46..48].copy_from_slice(&40u16.to_le_bytes()); // e_shentsize
        let ph = |f: &mut Vec<u8>, i: usize, off: usize, vaddr: u32, paddr: u32, len: usize| {
            let b = 52 + i * 32;
            let w = [1u32, off as u32, vaddr, paddr, len as u32, len as u32, 5, 4];
            for (k, x) in w.iter().enumerate() {
                f[b + 4 * k..b + 4 * k + 4].copy_from_slice(&x.to_le_bytes());
            }
        };
        ph(&mut f, 0, off_a, 0x1000_0000, 0x1000_0000, seg_a.len());
        ph(&mut f, 1, off_b, 0x2000_0000, 0x1000_0400, seg_b.len());
        f
    }

    #[test]
    fn uf2_places_every_segment_at_its_load_address() {
        let elf = tiny_elf();
        let image = flash_image(&elf).unwrap();
        // 0x400 + 8 bytes: the .data-like segment lands at its LMA, not its RAM address.
        assert_eq!(image.len(), 0x408);
        assert_eq!(&image[0x400..0x408], &[1, 2, 3, 4, 5, 6, 7, 8]);
        assert_eq!(image[300], 0xFF);
        let uf2 = elf_to_uf2(&elf).unwrap();
        // Pages 0x000, 0x100 (bytes 256..300) and 0x400; 0x200 and 0x300 are empty and skipped.
        assert_eq!(uf2.len(), 3 * 512);
        check_uf2(&uf2, &image).unwrap();
        let addr =
            |n: usize| u32::from_le_bytes(uf2[n * 512 + 12..n * 512 + 16].try_into().unwrap());
        assert_eq!(
            [addr(0), addr(1), addr(2)],
            [0x1000_0000, 0x1000_0100, 0x1000_0400]
        );
    }

    /// The ELF is looked for where cargo builds it: under `CARGO_TARGET_DIR` when that is set,
    /// absolute or relative to the workspace root, not in the workspace's own `target/`.
    #[test]
    fn the_firmware_elf_is_found_under_cargo_target_dir() {
        let dir = std::env::temp_dir().join(format!("xtask-target-{}", std::process::id()));
        let mut c = cargo();
        c.current_dir(root()).env("CARGO_TARGET_DIR", &dir);
        let target = crate::target_dir_from(&mut c).unwrap();
        assert_eq!(
            elf_in(&target),
            dir.join("thumbv6m-none-eabi/release/pico-imu")
        );
        let mut c = cargo();
        c.current_dir(root()).env("CARGO_TARGET_DIR", "elsewhere/t");
        let target = crate::target_dir_from(&mut c).unwrap();
        assert_eq!(
            elf_in(&target),
            root().join("elsewhere/t/thumbv6m-none-eabi/release/pico-imu")
        );
    }

    #[test]
    fn legacy_symbols_are_demangled() {
        assert_eq!(
            demangle("_ZN8pico_imu6DEVICE17hadb0efd42087a55dE"),
            "pico_imu::DEVICE"
        );
        assert_eq!(demangle("_SEGGER_RTT"), "_SEGGER_RTT");
    }

    #[test]
    fn a_corrupted_block_is_detected() {
        let elf = tiny_elf();
        let image = flash_image(&elf).unwrap();
        let mut uf2 = elf_to_uf2(&elf).unwrap();
        uf2[512 + 40] ^= 0xFF;
        assert!(check_uf2(&uf2, &image).is_err());
    }
}
