import { test } from 'node:test';
import assert from 'node:assert/strict';
import { Qmc5883l } from '../src/devices/qmc5883l.js';
import { constantStream, writeRegs, readRegs, ms } from './helpers.js';

const s16 = (l, h) => ((h << 8) | l) << 16 >> 16;

function continuous(stream, ctrl = 0x0d) {
  const q = new Qmc5883l(stream);
  writeRegs(q, 0, 0x0b, 0x01);
  writeRegs(q, 0, 0x09, ctrl); // continuous, 200 Hz, ±2 G, OSR 512
  return q;
}

test('chip id 0xFF at 0x0D; standby produces nothing', () => {
  const q = new Qmc5883l(constantStream({}));
  assert.deepEqual(readRegs(q, 0, 0x0d, 1), [0xff]);
  readRegs(q, ms(100), 0x06, 1);
  assert.equal(q.stats.produced, 0);
});

test('200 Hz ODR: 10 samples in 50 ms; DRDY set, cleared by a data read', () => {
  const q = continuous(constantStream({ mx: 20, my: -5, mz: 40 }));
  const st = readRegs(q, ms(50) + 1, 0x06, 1)[0];
  assert.equal(q.stats.produced, 10);
  assert.equal(st & 1, 1);
  const d = readRegs(q, ms(50) + 1, 0x00, 6);
  assert.equal(s16(d[0], d[1]), 20 * 120); // ±2 G: 12000 LSB/G = 120 LSB/µT
  assert.equal(s16(d[4], d[5]), 40 * 120);
  assert.equal(readRegs(q, ms(50) + 1, 0x06, 1)[0] & 1, 0);
  assert.equal(q.stats.served, 1);
});

test('DOR when a sample is skipped; OVL when a channel saturates; ±8 G range', () => {
  const q = continuous(constantStream({ mx: 300 })); // 300 µT * 120 = 36000 > 32767
  const st = readRegs(q, ms(11), 0x06, 1)[0]; // two samples, first never read
  assert.equal(st & 0x07, 0x07);
  const w = continuous(constantStream({ mx: 300 }), 0x1d); // ±8 G: 30 LSB/µT
  const d = readRegs(w, ms(6), 0x00, 2);
  assert.equal(s16(d[0], d[1]), 9000);
  assert.equal(readRegs(w, ms(6), 0x06, 1)[0] & 2, 0);
});

test('ROL_PNT rolls the pointer from 06H back to 00H', () => {
  const q = continuous(constantStream({ mx: 1 }));
  writeRegs(q, 0, 0x0a, 0x40);
  const d = readRegs(q, ms(6), 0x05, 3); // 05, 06, 00
  assert.equal(s16(d[2], 0), 120);
});

test('a sample is served only if its data follows a status read that showed DRDY', () => {
  const q = continuous(constantStream({ mx: 1 }));
  writeRegs(q, 0, 0x0a, 0x40); // ROL_PNT
  // The first sample lands at 5 ms. A roll-over read whose status byte (at 4.99 ms) is clear
  // and whose data bytes come after 5 ms reads the sample, but the reader discards it.
  assert.equal(readRegs(q, ms(5) - 10000, 0x06, 1)[0] & 1, 0);
  readRegs(q, ms(5) + 1, 0x00, 6);
  assert.equal(q.stats.produced, 1);
  assert.equal(q.stats.served, 0, 'read without seeing DRDY: not served');
  assert.equal(readRegs(q, ms(5) + 2, 0x06, 1)[0] & 1, 0, 'DRDY cleared by that read');
  // The next one is read the normal way: status (DRDY) then data.
  const d = readRegs(q, ms(10) + 1, 0x06, 7);
  assert.equal(d[0] & 1, 1);
  assert.equal(s16(d[1], d[2]), 120);
  assert.equal(q.stats.served, 1);
});
