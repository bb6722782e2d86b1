// Minimal ELF32 little-endian reader: program headers (what a flasher writes) and the symbol
// table (to find `_SEGGER_RTT` and marker statics). Reference: System V ABI, "ELF Object File
// Format", Tool Interface Standard ELF specification v1.2, sections 1-2 (header, program header,
// symbol table layouts).

const PT_LOAD = 1;
const SHT_SYMTAB = 2;

export class ElfError extends Error {}

/** Parses an ELF32 LE image for ARM. Throws ElfError naming the field that is wrong. */
export function parseElf(buf) {
  const bytes = buf instanceof Uint8Array ? buf : new Uint8Array(buf);
  if (bytes.length < 52) throw new ElfError(`ELF too short: ${bytes.length} bytes (header needs 52)`);
  const dv = new DataView(bytes.buffer, bytes.byteOffset, bytes.byteLength);
  if (dv.getUint32(0, false) !== 0x7f454c46) throw new ElfError('not an ELF file (bad magic at offset 0)');
  if (bytes[4] !== 1) throw new ElfError(`not ELF32 (EI_CLASS=${bytes[4]} at offset 4)`);
  if (bytes[5] !== 1) throw new ElfError(`not little-endian (EI_DATA=${bytes[5]} at offset 5)`);
  const machine = dv.getUint16(18, true);
  if (machine !== 40) throw new ElfError(`not an ARM ELF (e_machine=${machine} at offset 18, expected 40)`);
  const entry = dv.getUint32(24, true);
  const phoff = dv.getUint32(28, true);
  const shoff = dv.getUint32(32, true);
  const phentsize = dv.getUint16(42, true);
  const phnum = dv.getUint16(44, true);
  const shentsize = dv.getUint16(46, true);
  const shnum = dv.getUint16(48, true);
  const check = (off, len, what) => {
    if (off + len > bytes.length) {
      throw new ElfError(`${what} at offset ${off} (+${len} bytes) runs past the end of the file (${bytes.length} bytes)`);
    }
  };
  const segments = [];
  for (let i = 0; i < phnum; i++) {
    const o = phoff + i * phentsize;
    check(o, 32, `program header ${i}`);
    const type = dv.getUint32(o, true);
    if (type !== PT_LOAD) continue;
    const offset = dv.getUint32(o + 4, true);
    const vaddr = dv.getUint32(o + 8, true);
    const paddr = dv.getUint32(o + 12, true);
    const filesz = dv.getUint32(o + 16, true);
    const memsz = dv.getUint32(o + 20, true);
    if (filesz === 0) continue;
    check(offset, filesz, `PT_LOAD segment ${i} data`);
    segments.push({ vaddr, paddr, memsz, data: bytes.subarray(offset, offset + filesz) });
  }
  const symbols = new Map();
  for (let i = 0; i < shnum; i++) {
    const o = shoff + i * shentsize;
    check(o, 40, `section header ${i}`);
    if (dv.getUint32(o + 4, true) !== SHT_SYMTAB) continue;
    const symoff = dv.getUint32(o + 16, true);
    const symsize = dv.getUint32(o + 20, true);
    const strndx = dv.getUint32(o + 24, true);
    const entsize = dv.getUint32(o + 36, true) || 16;
    const so = shoff + strndx * shentsize;
    check(so, 40, `string table section header ${strndx}`);
    const stroff = dv.getUint32(so + 16, true);
    const strsize = dv.getUint32(so + 20, true);
    check(symoff, symsize, 'symbol table');
    check(stroff, strsize, 'string table');
    for (let s = symoff; s + entsize <= symoff + symsize; s += entsize) {
      const nameOff = dv.getUint32(s, true);
      if (nameOff === 0 || nameOff >= strsize) continue;
      let end = stroff + nameOff;
      while (end < stroff + strsize && bytes[end] !== 0) end++;
      const name = new TextDecoder().decode(bytes.subarray(stroff + nameOff, end));
      const value = dv.getUint32(s + 4, true);
      const size = dv.getUint32(s + 8, true);
      if (!symbols.has(name)) symbols.set(name, { value, size });
    }
  }
  return { entry, segments, symbols };
}
