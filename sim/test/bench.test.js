import { test } from 'node:test';
import assert from 'node:assert/strict';
import { worstSliding, BUCKET_NS, WINDOW_NS } from '../src/bench.js';

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
