import { test } from 'node:test';
import assert from 'node:assert/strict';
import { Emulator, EmulatorStop, IRQ_STAGE, EXC_ENTRY_CYCLES, EXC_RETURN_CYCLES } from '../src/emulator.js';
import { buildElf, flashImage } from './helpers.js';

const elf = (code, symbols) => buildElf([flashImage(code)], symbols);

test('a core sleeping with no timer or event pending is reported as a deadlock', () => {
  const emu = new Emulator({ elfBytes: elf([0xbf30, 0xe7fe]) }); // wfi; b .
  const stop = emu.runUntil(1e9);
  assert.equal(stop?.kind, 'deadlock');
  assert.match(stop.message, /PC=0x10000142/);
});

test('UDF (panic-probe\'s end) stops the run with its code and PC', () => {
  const emu = new Emulator({ elfBytes: elf([0x2001, 0xde07]) }); // movs r0,#1; udf #7
  const stop = emu.runUntil(1e9);
  assert.equal(stop?.kind, 'break');
  assert.equal(stop.code, 7);
  assert.equal(stop.pc, 0x10000142);
});

test('an image without a vector table after boot2 is refused with the reason', () => {
  assert.throws(() => new Emulator({ elfBytes: buildElf([{ paddr: 0x10000000, data: new Uint8Array(0x140) }]) }), EmulatorStop);
});

/** ldr r0,=MARK; movs r1,#1; str r1,[r0]; movs r2,#n; 1: subs r2,#1; bne 1b; movs r1,#0; str r1,[r0]; udf #0 */
function markerLoop(n) {
  return elf([0x4804, 0x2101, 0x6001, 0x2200 | n, 0x3a01, 0xd1fd, 0x2100, 0x6001, 0xde00, 0xbf00, 0x0100, 0x2000], { PICO_IMU_STAGE: 0x20000100 });
}

test('stage markers: cycles between stores are attributed to the stage (3 cycles per loop turn)', () => {
  const run = (n) => {
    const emu = new Emulator({ elfBytes: markerLoop(n) });
    emu.runUntil(1e9);
    return emu.markReport();
  };
  const a = run(50);
  const b = run(150);
  assert.equal(a.entries.get(1), 1);
  assert.equal(a.entries.get(0), 1);
  // Cortex-M0+ TRM table 3.1: SUBS 1 cycle, taken B<cond> 2 cycles → 3 per extra iteration.
  assert.equal(b.cycles.get(1) - a.cycles.get(1), 100 * 3);
});

test('time advances by executed cycles at 125 MHz (8 ns per cycle)', () => {
  const emu = new Emulator({ elfBytes: markerLoop(200) });
  emu.runUntil(1e9);
  assert.equal(emu.clock.nanos, emu.core.cycles * 8);
});

/**
 * Stage 1 pends PendSV (ICSR.PENDSVSET) and loops 20 turns; the PendSV handler loops `h` turns.
 * ldr r0,=MARK; movs r1,#1; str r1,[r0]; ldr r3,=ICSR; ldr r4,=PENDSVSET; str r4,[r3];
 * movs r2,#20; 1: subs r2,#1; bne 1b; movs r1,#0; str r1,[r0]; udf #0
 * handler: movs r2,#h; 2: subs r2,#1; bne 2b; bx lr
 */
function interruptedLoop(h) {
  const code = [0x4807, 0x2101, 0x6001, 0x4b07, 0x4c07, 0x601c, 0x2214, 0x3a01, 0xd1fd, 0x2100, 0x6001, 0xde00,
    0x2200 | h, 0x3a01, 0xd1fd, 0x4770, 0x0100, 0x2000, 0xed04, 0xe000, 0x0000, 0x1000];
  const img = flashImage(code);
  new DataView(img.data.buffer).setUint32(0x100 + 14 * 4, 0x10000159, true); // PendSV vector
  return buildElf([img], { PICO_IMU_STAGE: 0x20000100 });
}

test('stage markers: interrupt handlers are charged to their own stage, not to the one they interrupt', () => {
  const run = (h) => {
    const emu = new Emulator({ elfBytes: interruptedLoop(h) });
    const stop = emu.runUntil(1e9);
    assert.equal(stop?.kind, 'break');
    return emu.markReport();
  };
  const a = run(10);
  const b = run(100);
  assert.equal(a.entries.get(IRQ_STAGE), 1);
  assert.equal(b.cycles.get(1), a.cycles.get(1), 'stage 1 does not pay for the handler');
  assert.equal(b.cycles.get(IRQ_STAGE) - a.cycles.get(IRQ_STAGE), 90 * 3);
});

test('exception entry and return are charged (rp2040js charges none), to the handler stage and to the clock', () => {
  const emu = new Emulator({ elfBytes: interruptedLoop(10) });
  const stop = emu.runUntil(1e9);
  assert.equal(stop?.kind, 'break');
  assert.deepEqual(emu.exceptions, { entries: 1, returns: 1 });
  // movs (1) + 10 turns of subs (1) and bne (2 taken, 1 the last), entry and return; the bx lr's
  // own 2 cycles are added when it has returned, to the stage returned to.
  assert.equal(emu.markReport().cycles.get(IRQ_STAGE), 1 + 10 + 19 + EXC_ENTRY_CYCLES + EXC_RETURN_CYCLES);
  assert.equal(emu.clock.nanos, emu.core.cycles * 8, 'the clock advances by the charged cycles too');
});
