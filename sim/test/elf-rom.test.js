import { test } from 'node:test';
import assert from 'node:assert/strict';
import { parseElf, ElfError } from '../src/elf.js';
import { buildRom, romCode, ROM_FUNCTIONS, HC_LOOKUP } from '../src/rom.js';
import { buildElf } from './helpers.js';

/**
 * A minimal ELF32 ARM image: one PT_LOAD at paddr 0x10000100 whose vaddr is in RAM (as .data's),
 * a symtab with one symbol.
 */
function tinyElf() {
  const data = new Uint8Array([1, 2, 3, 4, 5, 6, 7, 8]);
  return buildElf(
    [{ paddr: 0x10000100, vaddr: 0x20000000, data }],
    { _SEGGER_RTT: { value: 0x20000400, size: 48 } },
    { entry: 0x10000101 },
  );
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
