// Runs the real firmware for 1.5 s of emulated time when it has been built
// (`cargo build --release` in the repository root); skipped otherwise. The ELF: PICO_IMU_ELF
// (`cargo xtask test` sets it), else under CARGO_TARGET_DIR, else under the repository's target/.
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { existsSync } from 'node:fs';
import { fileURLToPath } from 'node:url';
import { resolve } from 'node:path';
import { Session } from '../src/session.js';
import { generateStream } from '../src/stream.js';

const repo = fileURLToPath(new URL('../..', import.meta.url));
const elf = process.env.PICO_IMU_ELF ?? resolve(repo, process.env.CARGO_TARGET_DIR ?? 'target', 'thumbv6m-none-eabi/release/pico-imu');

test('the firmware boots, enumerates USB and reads both sensors at their rates', { skip: existsSync(elf) ? false : `no firmware at ${elf}` }, async () => {
  const s = new Session({ elf, stream: generateStream({ seed: 2, seconds: 3 }) });
  const stop = await s.run(1.5e9);
  await s.close();
  assert.equal(stop, null, stop?.message + '\n' + s.logLines.slice(-30).join('\n'));
  assert.ok(s.usb.connected, 'USB CDC enumerated');
  assert.ok(s.emu.rtt?.bytes > 0, 'defmt-RTT output seen');
  // After set-up (≤ 0.5 s) the 1 kHz MPU and the 200 Hz QMC are read continuously:
  // at least 900 and 180 samples served in 1.5 s.
  assert.ok(s.mpu.stats.servedFifo + s.mpu.stats.servedRegs >= 900, `MPU served ${s.mpu.stats.servedFifo}`);
  assert.ok(s.qmc.stats.served >= 180, `QMC served ${s.qmc.stats.served}`);
});

test('profile --exact --clock runs the parts at their oscillator errors', { skip: existsSync(elf) ? false : `no firmware at ${elf}` }, async () => {
  const { exactCycles } = await import('../src/profile.js');
  // 0.5 s after the 1 s warm-up, the MPU-6050 3 % fast or 3 % slow: 515 or 485 sample sets
  // (± one burst), where nominal parts give 500.
  for (const [clock, want] of [['mpu:+3%', 515], ['mpu:-3%,qmc:+1%', 485]]) {
    const r = await exactCycles({ elf, seconds: 0.5, clock });
    assert.ok(Math.abs(r.sets - want) <= 11, `${clock}: sets ${r.sets}, want ${want}`);
  }
});

test('bench --draw runs the drawn clocks and sums their windows', { skip: existsSync(elf) ? false : `no firmware at ${elf}` }, async () => {
  const { benchReport, drawClocks } = await import('../src/bench.js');
  const { mkdtempSync, readFileSync } = await import('node:fs');
  const { tmpdir } = await import('node:os');
  const json = resolve(mkdtempSync(resolve(tmpdir(), 'draw-')), 'draw.json');
  const seed = 1 + Math.floor(Math.random() * 1e6);
  await benchReport({ elf, draw: '2', 'draw-seed': String(seed), span: '2', seconds: '0.5', warmup: '0.4', json, quiet: true });
  const { summary, rows } = JSON.parse(readFileSync(json, 'utf8'));
  assert.deepEqual(rows.map((r) => r.clock), drawClocks(2, seed, 2), `seed ${seed}`);
  for (const r of rows) {
    assert.equal(r.aligned_windows, 5, `${r.clock}: 0.5 s, five aligned windows`);
    assert.ok(r.cycles_per_ms > 4000 && r.cycles_per_ms < 9000, `${r.clock}: ${r.cycles_per_ms} cycles per ms`);
    assert.ok(r.worst_sliding_cycles_per_ms >= r.worst_aligned_cycles_per_ms, `${r.clock}: the sliding windows include the aligned ones`);
  }
  assert.equal(summary.aligned_windows_over, rows.reduce((a, r) => a + r.aligned_windows_over, 0));
  assert.equal(summary.runs_none_over, rows.filter((r) => r.aligned_windows_over === 0).length);
  assert.ok(summary.runs_within_goal <= summary.runs_none_over);
  assert.equal(summary.worst_sliding_max, Math.max(...rows.map((r) => r.worst_sliding_cycles_per_ms)));
  await assert.rejects(benchReport({ elf, draw: '2', clock: 'mpu:+1%' }), /exclude each other/);
  await assert.rejects(benchReport({ elf, draw: '0' }), /--draw 0/);
  await assert.rejects(benchReport({ elf, draw: '2', span: '40' }), /--span 40/);
  // Shorter than a window, a run has no window to be over budget in: refused, not passed.
  await assert.rejects(benchReport({ elf, draw: '2', seconds: '0.05' }), /--seconds 0.05: from 0.1/);
  await assert.rejects(benchReport({ elf, seconds: 'NaN' }), /--seconds NaN/);
});

test('profile --exact charges every executed cycle to a function, per sample set', { skip: existsSync(elf) ? false : `no firmware at ${elf}` }, async () => {
  const { exactCycles } = await import('../src/profile.js');
  const r = await exactCycles({ elf, seconds: 0.2, callers: '^__aeabi_mem', tasks: true, polls: true });
  // 0.2 s after the 1 s warm-up: 200 IMU sample sets (± one burst of slack).
  assert.ok(r.sets >= 180 && r.sets <= 220, `sets ${r.sets}`);
  const sum = [...r.byFn.values()].reduce((a, b) => a + b, 0);
  assert.equal(sum, r.total, 'the per-function charges add up to the executed cycles');
  const perSet = r.total / r.sets;
  assert.ok(perSet > 1000 && perSet < 60000, `cycles per sample set ${perSet}`);
  // The IMU engines' pushes: the hand-scheduled Thumb routine (allan/src/stream/thumb.rs).
  const push = [...r.byFn.entries()].find(([n]) => /^pico_imu_allan_push_pair_small$/.test(n));
  assert.ok(push && push[1] / r.sets > 100, 'the Allan push shows up with its cycles');
  // What `--pcs RE` lists: the charges by instruction address, which add up to the function's.
  const byPc = [...r.perPc.entries()].filter(([pc]) => r.find(pc & ~1) === push[0]);
  assert.ok(byPc.length > 20, `addresses in the push ${byPc.length}`);
  assert.equal(byPc.reduce((a, [, c]) => a + c, 0), push[1], 'per-address cycles add up');
  // What `--tasks` lists: every cycle charged once, to a task's polls, an exception or the run
  // loop; the sensor, processing and USB tasks polled, the USB and DMA interrupts taken.
  const byTask = [...r.byTask.entries()];
  assert.equal(byTask.reduce((a, [, t]) => a + t.cycles, 0), r.total, 'the per-task charges add up');
  const polled = byTask.filter(([n]) => n.startsWith('task ') && r.pollsByTask.get(n) > 0);
  assert.ok(polled.length >= 4, `tasks polled: ${polled.map(([n]) => n)}`);
  for (const irq of ['exception 21', 'exception 27']) assert.ok(r.byTask.get(irq)?.cycles > 0, `${irq} charged`);
  // The processing task holds the Allan push.
  const processing = byTask.find(([, t]) => [...t.pcs.keys()].some((pc) => r.find(pc & ~1) === push[0]));
  assert.ok(processing && processing[1].cycles > push[1], 'the Allan push is inside a task poll');
  // What `--polls` writes: every poll, in time order within the 0.2 s, its cycles adding up to
  // the task's; the processing task polled at least once per 10 ms IMU burst.
  const log = r.pollLog;
  assert.equal(log.length, [...r.pollsByTask.values()].reduce((a, b) => a + b, 0), 'one line per poll');
  for (let i = 1; i < log.length; i++) assert.ok(log[i].nanos >= log[i - 1].nanos, `poll ${i} in time order`);
  assert.ok(log[0].nanos >= 1e9 && log.at(-1).nanos <= 1.2e9, 'within the measured 0.2 s');
  for (const [name, t] of polled) {
    // A poll still running when the measurement ends is charged but not logged.
    const logged = log.filter((p) => p.task === name).reduce((a, p) => a + p.cycles, 0);
    assert.ok(logged <= t.cycles && logged > 0.9 * t.cycles, `${name}: ${logged} logged of ${t.cycles}`);
  }
  const processingPolls = log.filter((p) => p.task === processing[0]).length;
  assert.ok(processingPolls >= 20, `processing task polled ${processingPolls} times in 0.2 s`);
});
