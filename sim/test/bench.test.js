import { test } from 'node:test';
import assert from 'node:assert/strict';
import { worstSliding, drawClocks, windowsOver, BUCKET_NS, WINDOW_NS } from '../src/bench.js';
import { parseClock } from '../src/session.js';

test('the worst sliding window sums the heaviest run of whole buckets, wherever it starts', () => {
  const per = WINDOW_NS / BUCKET_NS;
  // Random light buckets with a heavy run placed at a random bucket, straddling aligned edges.
  for (let trial = 0; trial < 20; trial++) {
    const n = 5 * per + Math.floor(Math.random() * per);
    const buckets = Array.from({ length: n }, (_, i) => ({ from_s: (i * BUCKET_NS) / 1e9, cycles: 1000 + Math.floor(Math.random() * 10) }));
    const at = 1 + Math.floor(Math.random() * (n - per - 1));
    for (let i = at; i < at + per; i++) buckets[i].cycles += 100_000;
    const w = worstSliding(buckets);
    const want = buckets.slice(at, at + per).reduce((a, b) => a + b.cycles, 0);
    assert.equal(w.cycles, want, `heavy run at bucket ${at}`);
    assert.equal(w.from_s, buckets[at].from_s);
  }
  assert.deepEqual(worstSliding([]), { from_s: 0, cycles: 0 }, 'fewer buckets than a window: none');
});

test('drawn part clocks are the same for a seed, within the span, and spread over it', () => {
  const seed = 1 + Math.floor(Math.random() * 1e6);
  const span = 0.5 + Math.random() * 2;
  const a = drawClocks(400, seed, span);
  assert.deepEqual(drawClocks(400, seed, span), a, `seed ${seed}: drawn again, the same clocks`);
  assert.notDeepEqual(drawClocks(400, seed + 1, span), a, 'another seed, other clocks');
  const errs = { mpu: [], qmc: [] };
  for (const spec of a) {
    const m = /^mpu:([+-]\d+\.\d\d)%,qmc:([+-]\d+\.\d\d)%$/.exec(spec);
    assert.ok(m, `${spec}: not a --clock spec with two decimals`);
    assert.ok(parseClock(spec), `${spec}: parseClock refused it`);
    errs.mpu.push(Number(m[1]));
    errs.qmc.push(Number(m[2]));
  }
  for (const [part, xs] of Object.entries(errs)) {
    assert.ok(xs.every((x) => Math.abs(x) <= span + 0.005), `${part}: outside ±${span} %`);
    // Uniform: each half of the span and each sign holds a fair share of 400 draws.
    assert.ok(xs.filter((x) => x > 0).length > 150 && xs.filter((x) => x < 0).length > 150, `${part}: signs ${xs.filter((x) => x > 0).length} +`);
    assert.ok(xs.filter((x) => Math.abs(x) > span / 2).length > 150, `${part}: too few beyond half the span`);
  }
  assert.deepEqual(new Set(drawClocks(10, seed, 0)), new Set(['mpu:+0.00%,qmc:+0.00%']), 'span 0: nominal parts');
});

test('a window over budget, or with no number for its cycles, counts as over', () => {
  const budget = 1000 + Math.floor(Math.random() * 1e6);
  assert.equal(windowsOver([budget - 1, budget, budget + 1], budget), 1, `budget ${budget}: only the one above`);
  assert.equal(windowsOver([NaN, undefined, Infinity, 0], budget), 3, 'NaN, undefined and Infinity count as over');
  assert.equal(windowsOver([], budget), 0);
});
