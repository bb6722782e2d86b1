import { test } from 'node:test';
import assert from 'node:assert/strict';
import { parseElf, ElfError } from '../src/elf.js';
import { buildRom, romCode, ROM_FUNCTIONS, HC_LOOKUP } from '../src/rom.js';

/** A minimal ELF32 ARM image: one PT_LOAD at paddr 0x10000100, a symtab with one symbol. */
function tinyElf() {
  const data = new Uint8Array([1, 2, 3, 4, 5, 6, 7, 8]);
  const strtab = new TextEncoder().encode('\0_SEGGER_RTT\0');
  const symtab = new Uint8Array(32); // null symbol + one
  const sdv = new DataView(symtab.buffer);
  sdv.setUint32(16, 1, true); // name offset
  sdv.setUint32(20, 0x20000400, true); // value
  sdv.setUint32(24, 48, true); // size
  const ehsize = 52, phsize = 32, shsize = 40;
  const dataOff = ehsize + phsize;
  const symOff = dataOff + data.length;
  const strOff = symOff + symtab.length;
  const shOff = strOff + strtab.length;
  const total = shOff + 3 * shsize;
  const b = new Uint8Array(total);
  const dv = new DataView(b.buffer);
  b.set([0x7f, 0x45, 0x4c, 0x46, 1, 1, 1], 0);
  dv.setUint16(18, 40, true);
  dv.setUint32(24, 0x10000101, true);
  dv.setUint32(28, ehsize, true);
  dv.setUint32(32, shOff, true);
  dv.setUint16(42, phsize, true);
  dv.setUint16(44, 1, true);
  dv.setUint16(46, shsize, true);
  dv.setUint16(48, 3, true);
  dv.setUint32(ehsize, 1, true); // PT_LOAD
  dv.setUint32(ehsize + 4, dataOff, true);
  dv.setUint32(ehsize + 8, 0x20000000, true); // vaddr (e.g. .data in RAM)
  dv.setUint32(ehsize + 12, 0x10000100, true); // paddr (load address in flash)
  dv.setUint32(ehsize + 16, data.length, true);
  dv.setUint32(ehsize + 20, data.length, true);
  b.set(data, dataOff);
  b.set(symtab, symOff);
  b.set(strtab, strOff);
  // section 1 = symtab (link 2), section 2 = strtab
  const s1 = shOff + shsize;
  dv.setUint32(s1 + 4, 2, true);
  dv.setUint32(s1 + 16, symOff, true);
  dv.setUint32(s1 + 20, symtab.length, true);
  dv.setUint32(s1 + 24, 2, true);
  dv.setUint32(s1 + 36, 16, true);
  const s2 = shOff + 2 * shsize;
  dv.setUint32(s2 + 4, 3, true);
  dv.setUint32(s2 + 16, strOff, true);
  dv.setUint32(s2 + 20, strtab.length, true);
  return b;
}

test('ELF: PT_LOAD segments by physical address, symbols by name', () => {
  const e = parseElf(tinyElf());
  assert.equal(e.entry, 0x10000101);
  assert.equal(e.segments.length, 1);
  assert.equal(e.segments[0].paddr, 0x10000100);
  assert.deepEqual([...e.segments[0].data], [1, 2, 3, 4, 5, 6, 7, 8]);
  assert.deepEqual(e.symbols.get('_SEGGER_RTT'), { value: 0x20000400, size: 48 });
});

test('ELF: corrupt input is rejected with the field and offset named', () => {
  assert.throws(() => parseElf(new Uint8Array(10)), /too short/);
  const bad = tinyElf();
  bad[0] = 0;
  assert.throws(() => parseElf(bad), /bad magic at offset 0/);
  const cut = tinyElf().subarray(0, 90);
  assert.throws(() => parseElf(cut), ElfError);
  const wrongArch = tinyElf();
  wrongArch[18] = 62;
  assert.throws(() => parseElf(wrongArch), /e_machine=62/);
});

test('ROM stub: lookup ABI header and bkpt/bx lr routines', () => {
  const { image, functions } = buildRom();
  const b = new Uint8Array(image.buffer);
  const dv = new DataView(image.buffer);
  assert.deepEqual([...b.subarray(0x10, 0x13)], [0x4d, 0x75, 0x01]);
  const lookup = dv.getUint16(0x18, true);
  assert.equal(lookup & 1, 1, 'Thumb bit set');
  assert.equal(dv.getUint16(lookup & ~1, true), 0xbe00 | HC_LOOKUP);
  assert.equal(dv.getUint16((lookup & ~1) + 2, true), 0x4770);
  // The function table found through 0x14 lists 'RE' at the routine that traps with its index.
  const table = dv.getUint16(0x14, true);
  let found = null;
  for (let o = table; dv.getUint16(o, true); o += 4) if (dv.getUint16(o, true) === romCode('RE')) found = dv.getUint16(o + 2, true);
  assert.equal(found, functions.get(romCode('RE')));
  assert.equal(dv.getUint16(found & ~1, true), 0xbe00 | ROM_FUNCTIONS.indexOf('RE'));
});
