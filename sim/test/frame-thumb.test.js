// Differential test of imu-proto's frame scan in Thumb code (`pico_imu_crc_cobs`: CRC-32 four
// bytes at a time, COBS as the bytes come) on the emulated RP2040. crates/imu-proto/thumb-check
// is a bare-metal program that frames drawn contents (lengths, zeros, the bytes at the edges of
// the zero-byte test, alignments, pieces) with the firmware's encoder and compares each frame
// with the `crc` crate's CRC-32 and a plain COBS; it leaves its counts in the `FRAME_CHECK`
// static and stops at `bkpt #1`. This test runs it and reads them.
//
// The ELF: PICO_IMU_FRAME_CHECK_ELF (`cargo xtask test` builds it and sets it), else built here
// with cargo; skipped when neither is possible.
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { Emulator } from '../src/emulator.js';
import { locateCheckElf } from './helpers.js';

/** `imu_proto_thumb_check::Report` (repr(C), u32 words). */
const WORDS = ['state', 'cases', 'bytes', 'mismatches', 'firstCase', 'firstLen', 'firstAt'];
const EDGE_NAMES = ['a piece starting at a word', 'at a word + 1', 'at a word + 2', 'at a word + 3', 'a zero in byte 0 of a word', 'in byte 1', 'in byte 2', 'in byte 3', 'a full COBS block', 'a word of 0x01/0x80 bytes without a zero'];
const SIZE = 4 * (WORDS.length + EDGE_NAMES.length + 1);
const DONE = 0x444f4e45;
/** Emulated cycles the run may take (it needs well under a tenth of this); a hang ends here. */
const CYCLE_CAP = 1.5e9;

const found = locateCheckElf('imu-proto-thumb-check', 'PICO_IMU_FRAME_CHECK_ELF');

test("the frame encoder's Thumb scan writes the crc crate's CRC-32 and a plain COBS, frame by frame", { skip: found.elf ? false : found.why }, () => {
  const emu = new Emulator({ elf: found.elf });
  const wall0 = performance.now();
  const stop = emu.runUntil((CYCLE_CAP * 1e9) / (emu.mcu.clkSys || 125e6));
  const wall = (performance.now() - wall0) / 1000;
  const sym = emu.elf.symbols.get('FRAME_CHECK');
  assert.ok(sym, `${found.elf} has no FRAME_CHECK symbol`);
  assert.equal(sym.size, SIZE, 'FRAME_CHECK size: the Report layout changed; update it here');
  const word = (i) => emu.mcu.readUint32(sym.value + 4 * i) >>> 0;
  const r = Object.fromEntries(WORDS.map((n, i) => [n, word(i)]));
  const edges = EDGE_NAMES.map((_, i) => word(WORDS.length + i));
  const panicLine = word(WORDS.length + EDGE_NAMES.length);
  console.log(`frame-thumb: ${r.cases} frames, ${r.bytes} content bytes; ${(emu.core.cycles / 1e6).toFixed(0)} M emulated cycles in ${wall.toFixed(1)} s`);
  console.log(`frame-thumb edges: ${EDGE_NAMES.map((n, i) => `${n}: ${edges[i]}`).join(', ')}`);
  if (panicLine) assert.fail(`the test program panicked at line ${panicLine} of crates/imu-proto/thumb-check (after ${r.cases} frames)`);
  assert.equal(r.state, DONE, `FRAME_CHECK.state = 0x${r.state.toString(16)}: the run did not finish (stop: ${stop?.message ?? 'cycle cap'})`);
  assert.equal(stop?.kind, 'break', `expected the program to end at its breakpoint: ${stop?.message}`);
  assert.equal(r.mismatches, 0, `${r.mismatches} frames differ from the reference; the first: case ${r.firstCase}, ${r.firstLen} content bytes, first differing frame byte ${r.firstAt}`);
  assert.ok(r.cases >= 4000, `only ${r.cases} frames compared`);
  EDGE_NAMES.forEach((n, i) => assert.ok(edges[i] > 0, `no frame reached the edge \`${n}\``));
});
