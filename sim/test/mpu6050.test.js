import { test } from 'node:test';
import assert from 'node:assert/strict';
import { Mpu6050, REG } from '../src/devices/mpu6050.js';
import { constantStream, writeRegs, readRegs, ms } from './helpers.js';

const s16 = (h, l) => ((h << 8) | l) << 16 >> 16;

function awake(stream, { div = 0, dlpf = 1, fifoEn = 0x78 } = {}) {
  const m = new Mpu6050(stream);
  writeRegs(m, 0, REG.PWR_MGMT_1, 0x01);
  writeRegs(m, 0, REG.SMPLRT_DIV, div);
  writeRegs(m, 0, REG.CONFIG, dlpf);
  writeRegs(m, 0, REG.FIFO_EN, fifoEn);
  writeRegs(m, 0, REG.USER_CTRL, 0x44);
  return m;
}

test('WHO_AM_I reads 0x68 and the device powers up asleep (no samples)', () => {
  const m = new Mpu6050(constantStream({}));
  assert.deepEqual(readRegs(m, 0, REG.WHO_AM_I, 1), [0x68]);
  assert.deepEqual(readRegs(m, ms(50), REG.PWR_MGMT_1, 1), [0x40]);
  assert.equal(m.stats.produced, 0);
});

test('FIFO fills at 1 kHz with DLPF_CFG=1, SMPLRT_DIV=0: 12 bytes per sample set', () => {
  const m = awake(constantStream({}));
  const [h, l] = readRegs(m, ms(10) + 1, REG.FIFO_COUNT_H, 2);
  assert.equal((h << 8) | l, 10 * 12); // samples at 1, 2, ..., 10 ms
});

test('rate honours SMPLRT_DIV and the 8 kHz gyro rate of DLPF_CFG=0', () => {
  const a = awake(constantStream({}), { div: 4, dlpf: 1 }); // 1 kHz / 5 = 200 Hz
  const [h, l] = readRegs(a, ms(100) + 1, REG.FIFO_COUNT_H, 2);
  assert.equal(((h << 8) | l) / 12, 20);
  const b = awake(constantStream({}), { div: 7, dlpf: 0 }); // 8 kHz / 8 = 1 kHz
  const [h2, l2] = readRegs(b, ms(20) + 1, REG.FIFO_COUNT_H, 2);
  assert.equal(((h2 << 8) | l2) / 12, 20);
});

test('counts follow the configured ranges; temperature = raw/340 + 36.53', () => {
  // az = 1 g, gx = 100 deg/s, temp 25 °C
  const m = awake(constantStream({ az: 9.80665, gx: 100, temp: 25 }), { fifoEn: 0xf8 });
  writeRegs(m, 0, REG.ACCEL_CONFIG, 0x08); // ±4 g: 8192 LSB/g
  writeRegs(m, 0, REG.GYRO_CONFIG, 0x18); // ±2000 deg/s: 16.4 LSB/(deg/s)
  const d = readRegs(m, ms(5) + 1, REG.ACCEL_XOUT_H, 14);
  assert.equal(s16(d[4], d[5]), 8192);
  assert.equal(s16(d[8], d[9]), Math.round(100 * 16.4));
  const raw = s16(d[6], d[7]);
  assert.ok(Math.abs(raw / 340 + 36.53 - 25) < 1 / 340, `temp raw ${raw}`);
});

test('FIFO overflows after 1024 bytes: FIFO_OFLOW_INT set, cleared on read, count stays 1024', () => {
  const m = awake(constantStream({}));
  // 1024 / 12 = 85.3 sample sets: at 90 ms the FIFO has overflowed.
  const st = readRegs(m, ms(90) + 1, REG.INT_STATUS, 1)[0];
  assert.equal(st & 0x10, 0x10);
  assert.equal(readRegs(m, ms(90) + 1, REG.INT_STATUS, 1)[0] & 0x10, 0);
  const [h, l] = readRegs(m, ms(90) + 1, REG.FIFO_COUNT_H, 2);
  assert.equal((h << 8) | l, 1024);
  assert.equal(m.stats.overflows, 1);
  // After overflow the oldest bytes were overwritten: 90*12 - 1024 = 56 bytes lost.
  assert.equal(m.stats.overwrittenBytes, 90 * 12 - 1024);
  // FIFO_RESET empties it.
  writeRegs(m, ms(90) + 1, REG.USER_CTRL, 0x44);
  const [h2, l2] = readRegs(m, ms(90) + 1, REG.FIFO_COUNT_H, 2);
  assert.equal((h2 << 8) | l2, 0);
});

test('a sample set read completely from the FIFO is recorded as served, bit for bit', () => {
  const m = awake(constantStream({ ax: 1, gy: -3 }));
  const bytes = readRegs(m, ms(3) + 1, REG.FIFO_R_W, 24); // two sets
  assert.equal(m.stats.servedFifo, 2);
  const s = m.samples[0];
  assert.equal(s16(bytes[0], bytes[1]), s.raw[0]);
  assert.equal(s16(bytes[8], bytes[9]), s.raw[5]);
  assert.equal(m.samples[2].served, 0); // third still in the FIFO
});

test('DATA_RDY_INT is set by each new sample and cleared by reading INT_STATUS', () => {
  const m = awake(constantStream({}));
  assert.equal(readRegs(m, ms(1) + 1, REG.INT_STATUS, 1)[0] & 1, 1);
  assert.equal(readRegs(m, ms(1) + 2, REG.INT_STATUS, 1)[0] & 1, 0);
});

test('DLPF: one sample after a step, the 5 Hz setting passes 1 − exp(−2π·5 Hz·1 ms) of it', () => {
  // One-pole response after one 1 ms sample: 1 - exp(-2π·5·0.001) ≈ 0.031 of the step
  const step = constantStream({ gx: 100 });
  const slow = awake(step, { dlpf: 6 });
  slow.filter = [0, 0, 0, 0, 0, 0];
  const d = readRegs(slow, ms(1) + 1, REG.GYRO_XOUT_H, 2);
  const expected = Math.round(100 * (1 - Math.exp(-2 * Math.PI * 5 * 0.001)) * 131);
  assert.equal(s16(d[0], d[1]), expected);
});
