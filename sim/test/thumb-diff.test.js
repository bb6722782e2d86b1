// Per-call differential test of allan's hand-written Thumb routines on the emulated RP2040.
// crates/allan/thumb-check is a bare-metal program that drives two DeviceEngines in lock step,
// one through the firmware's path (the Thumb routines when the samples are steady and small),
// one through the pure-Rust path, and compares their whole states after every call; it leaves
// its counts in the `THUMB_CHECK` static and stops at `bkpt #1`. This test runs it and reads them.
//
// The ELF: PICO_IMU_THUMB_CHECK_ELF (`cargo xtask test` builds it and sets it), else built here
// with cargo (a no-op when it is up to date); skipped when neither is possible.
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { Emulator } from '../src/emulator.js';
import { locateCheckElf } from './helpers.js';

/** The layout of `allan_thumb_check::Report` (repr(C), u32 words; crates/allan/thumb-check). */
const REPORT = {
  size: 124,
  words: ['state', 'cases', 'pairCalls', 'singleCalls', 'pairTaken', 'singleTaken', 'pairPredicted', 'singlePredicted', 'mismatches', 'firstCase', 'firstRoutine', 'firstY0', 'firstY1', 'firstTaken', 'firstT'],
  firstField: 60,
  after: ['segments', 'maxT'],
  edges: 84,
  edgeNames: ['|z| = gate - 1', '|z| = gate', 'gate = 2^11 - 1', 'gate = 2^11', 'gate around 2^10', 'i32 extremes', 'square waves near 2^16', 'pairs at odd counts', 'counts >= 4096'],
  panicLine: 120,
};
const DONE = 0x444f4e45;
const RUNNING = 0x52554e21;
/** Emulated cycles the run may take (it needs about a quarter of this); a hang ends here. */
const CYCLE_CAP = 1.2e9;

function readReport(emu, address) {
  const mcu = emu.mcu;
  const r = {};
  REPORT.words.forEach((name, i) => (r[name] = mcu.readUint32(address + 4 * i) >>> 0));
  r.firstY0 |= 0;
  r.firstY1 |= 0;
  const bytes = [];
  for (let i = 0; i < 16; i++) bytes.push(mcu.readUint8(address + REPORT.firstField + i));
  r.firstField = String.fromCharCode(...bytes.filter((b) => b));
  REPORT.after.forEach((name, i) => (r[name] = mcu.readUint32(address + REPORT.firstField + 16 + 4 * i) >>> 0));
  r.edges = REPORT.edgeNames.map((_, i) => mcu.readUint32(address + REPORT.edges + 4 * i) >>> 0);
  r.panicLine = mcu.readUint32(address + REPORT.panicLine) >>> 0;
  return r;
}

/** The first mismatch in words: the call, which Thumb routine ran, which field differed. */
function describeMismatch(r) {
  const call = r.firstRoutine === 1 ? `push_pair(${r.firstY0}, ${r.firstY1})` : r.firstRoutine === 2 ? `push(${r.firstY0})` : 'reset/gap';
  const thumb = r.firstTaken === 1 ? 'pico_imu_allan_push_pair_small took the pair' : r.firstTaken ? `pico_imu_allan_push_small took ${r.firstTaken / 2} sample(s)` : 'no Thumb routine ran';
  return `${r.mismatches} call(s) left the Thumb path's engine differing from the Rust path's; the first: case ${r.firstCase}, ${call} at segment count ${r.firstT} (${thumb}), field \`${r.firstField}\` differs`;
}

const found = locateCheckElf('allan-thumb-check', 'PICO_IMU_THUMB_CHECK_ELF');

/** The program run once (it runs both checks); the emulator, the stop and the wall time. */
let ran = null;
function runOnce() {
  if (ran) return ran;
  const emu = new Emulator({ elf: found.elf });
  const wall0 = performance.now();
  const stop = emu.runUntil((CYCLE_CAP * 1e9) / (emu.mcu.clkSys || 125e6));
  ran = { emu, stop, wall: (performance.now() - wall0) / 1000 };
  return ran;
}

test('the Thumb routines change the engine exactly as the Rust path does, call by call', { skip: found.elf ? false : found.why }, () => {
  const { emu, stop, wall } = runOnce();
  const sym = emu.elf.symbols.get('THUMB_CHECK');
  assert.ok(sym, `${found.elf} has no THUMB_CHECK symbol`);
  assert.equal(sym.size, REPORT.size, 'THUMB_CHECK size: the Report layout changed; update REPORT here');
  const r = readReport(emu, sym.value);
  const cycles = emu.core.cycles;
  const thumbSamples = 2 * r.pairTaken + r.singleTaken;
  const samples = 2 * r.pairCalls + r.singleCalls;
  console.log(
    `thumb-diff: ${r.cases} calls (${r.pairCalls} pairs, ${r.singleCalls} single), Thumb routines took ${r.pairTaken} pairs and ${r.singleTaken} single samples ` +
      `(${((100 * thumbSamples) / samples).toFixed(1)} % of ${samples} samples), ${r.segments} segments, longest ${r.maxT} samples; ` +
      `${(cycles / 1e6).toFixed(0)} M emulated cycles in ${wall.toFixed(1)} s`,
  );
  console.log(`thumb-diff edges: ${REPORT.edgeNames.map((n, i) => `${n}: ${r.edges[i]}`).join(', ')}`);

  if (r.panicLine) assert.fail(`the test program panicked at line ${r.panicLine} of crates/allan/thumb-check (after ${r.cases} calls)`);
  if (r.state === RUNNING) assert.fail(`the test program did not finish within ${CYCLE_CAP / 1e6} M cycles (${r.cases} calls done; stop: ${stop?.message ?? 'cycle cap'})`);
  assert.equal(r.state, DONE, `THUMB_CHECK.state = 0x${r.state.toString(16)}: the program did not run (stop: ${stop?.message})`);
  assert.equal(stop?.kind, 'break', `expected the program to end at its breakpoint: ${stop?.message}`);
  assert.equal(stop.code, 1, stop.message);

  assert.equal(r.mismatches, 0, describeMismatch(r));
  assert.ok(r.cases >= 20000, `only ${r.cases} calls compared`);
  // The routines took exactly the calls the inputs say they must (a routine that declines a
  // steady pair, or takes a sample it must not, is a bug even when the result agrees).
  assert.equal(r.pairTaken, r.pairPredicted, 'pairs taken by pico_imu_allan_push_pair_small vs pairs with steady, small samples at an even count');
  assert.equal(r.singleTaken, r.singlePredicted, 'samples taken by pico_imu_allan_push_small vs steady, small samples outside such pairs');
  // Not vacuous: both routines ran, on a large share of the samples.
  assert.ok(r.pairTaken >= 5000, `the pair routine took only ${r.pairTaken} pairs`);
  assert.ok(r.singleTaken >= 5000, `the single routine took only ${r.singleTaken} samples`);
  assert.ok(thumbSamples >= 0.5 * samples, `the Thumb routines took only ${thumbSamples} of ${samples} samples`);
  REPORT.edgeNames.forEach((n, i) => assert.ok(r.edges[i] > 0, `no call hit the edge \`${n}\``));
});

/** The magnetometer run's edges (crates/allan/thumb-check, `mag_edge`). */
const MAG_EDGE_NAMES = ['|z| = gate - 1', 'gate raised', 'gate < 2^11', '|z| >= 2^15', '|z| = 2^16 - 1', 'i16 extremes', 'square waves at |z| >= 2^14', 'counts >= 4096', '|z| >= 2^26'];

test("the magnetometer engines' Thumb routine changes the engine exactly as the Rust path does, over the whole i16 range", { skip: found.elf ? false : found.why }, () => {
  const { emu, stop } = runOnce();
  const sym = emu.elf.symbols.get('THUMB_CHECK_MAG');
  assert.ok(sym, `${found.elf} has no THUMB_CHECK_MAG symbol`);
  assert.equal(sym.size, REPORT.size, 'THUMB_CHECK_MAG size: the Report layout changed; update REPORT here');
  const r = readReport(emu, sym.value);
  console.log(
    `thumb-diff (magnetometer): ${r.singleCalls} single calls, pico_imu_allan_mag_push took ${r.singleTaken} (${((100 * r.singleTaken) / r.singleCalls).toFixed(1)} %), ${r.segments} segments, longest ${r.maxT} samples`,
  );
  console.log(`thumb-diff (magnetometer) edges: ${MAG_EDGE_NAMES.map((n, i) => `${n}: ${r.edges[i]}`).join(', ')}`);
  if (r.panicLine) assert.fail(`the test program panicked at line ${r.panicLine} of crates/allan/thumb-check (magnetometer run, after ${r.cases} calls)`);
  assert.equal(r.state, DONE, `THUMB_CHECK_MAG.state = 0x${r.state.toString(16)}: the magnetometer run did not finish (stop: ${stop?.message ?? 'cycle cap'})`);
  assert.equal(r.mismatches, 0, describeMismatch(r).replace('pico_imu_allan_push_small', 'pico_imu_allan_mag_push'));
  assert.ok(r.cases >= 10000, `only ${r.cases} calls compared`);
  assert.equal(r.singleTaken, r.singlePredicted, 'samples taken by pico_imu_allan_mag_push vs steady samples');
  assert.ok(r.singleTaken >= 0.8 * r.singleCalls, `the routine took only ${r.singleTaken} of ${r.singleCalls} samples`);
  MAG_EDGE_NAMES.forEach((n, i) => assert.ok(r.edges[i] > 0, `no call hit the magnetometer edge \`${n}\``));
});
