import { test } from 'node:test';
import assert from 'node:assert/strict';
import { parseStreamCsv, generateStream, streamToCsv, StreamError } from '../src/stream.js';
import { parseFault, parseDuration } from '../src/session.js';

test('CSV round trip keeps values to 9 significant digits', () => {
  const s = generateStream({ seed: 7, seconds: 1, rate: 100 });
  const back = parseStreamCsv(streamToCsv(s));
  assert.equal(back.length, 100);
  assert.ok(Math.abs(back.rate - 100) < 1e-6);
  assert.ok(Math.abs(back.cols.gx[17] - s.cols.gx[17]) <= 1e-8 * Math.abs(s.cols.gx[17]) + 1e-12);
});

test('bad CSV: missing column, non-number, uneven time each name the problem', () => {
  assert.throws(() => parseStreamCsv('x,ax\n0,1\n0.1,1\n'), /lacks the time column 't'/);
  assert.throws(() => parseStreamCsv('t,foo\n0,1\n0.1,1\n'), /no data column of the contract/);
  const h = 't,ax,ay,az,gx,gy,gz,mx,my,mz,temp\n';
  assert.throws(() => parseStreamCsv(h + '0,1,1,1,1,1,1,1,1,1,1\n0.001,x,1,1,1,1,1,1,1,1,1\n', 'f.csv'), /f\.csv:3: column 'ax' is not a finite number/);
  assert.throws(() => parseStreamCsv(h + '0,1,1,1,1,1,1,1,1,1,1\n0.001,1,1,1,1,1,1,1,1,1,1\n0.003,1,1,1,1,1,1,1,1,1,1\n'), StreamError);
});

test('seeded generator is deterministic and its white noise has the stated density', () => {
  const a = generateStream({ seed: 3, seconds: 20, rate: 1000, gyroRrw: 0 });
  const b = generateStream({ seed: 3, seconds: 20, rate: 1000, gyroRrw: 0 });
  assert.deepEqual(a.cols.gy.slice(0, 50), b.cols.gy.slice(0, 50));
  // σ = 0.005 deg/s/√Hz · √1000 Hz = 0.158 deg/s; 20000 samples: relative SE of σ ≈ 0.5 %, allow 3 %.
  const x = a.cols.gy;
  const mean = x.reduce((p, v) => p + v, 0) / x.length;
  const sd = Math.sqrt(x.reduce((p, v) => p + (v - mean) ** 2, 0) / (x.length - 1));
  assert.ok(Math.abs(sd / (0.005 * Math.sqrt(1000)) - 1) < 0.03, `sd ${sd}`);
});

test('fault specs and durations parse; bad ones are rejected with the expected form', () => {
  assert.equal(parseDuration('150ms'), 150e6);
  assert.deepEqual(parseFault('vanish:mpu@10s:2s'), { kind: 'vanish', target: 'mpu', at: 10e9, count: undefined, duration: 2e9, spec: 'vanish:mpu@10s:2s' });
  assert.equal(parseFault('nack:qmc@5s:3').count, 3);
  assert.equal(parseFault('overflow@30s').duration, 120e6);
  assert.throws(() => parseFault('nack@5s'), /which sensor/);
  assert.throws(() => parseFault('melt@5s'), /expected e\.g\./);
});

test('columns a file leaves out take the level-and-still defaults', () => {
  const s = parseStreamCsv('t,gx\n0,1.5\n0.001,2.5\n');
  assert.equal(s.cols.gx[1], 2.5);
  assert.equal(s.cols.az[0], 9.80665);
  assert.equal(s.cols.temp[1], 25);
  assert.ok(Math.abs(s.rate - 1000) < 1e-6);
});
