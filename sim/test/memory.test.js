// Memory over a run: what the harness retains must not grow with emulated time (a device serving
// its stream for hours must not run the emulator out of heap), and a host slower than the stream
// must not make the bytes waiting for it pile up.
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { spawn } from 'node:child_process';
import { connect } from 'node:net';
import { existsSync, mkdtempSync, readFileSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join, resolve } from 'node:path';
import { fileURLToPath } from 'node:url';
import { Session, HOST_BACKLOG_BYTES, LOG_TAIL_LINES } from '../src/session.js';
import { generateStream } from '../src/stream.js';
import { spinElf, until } from './helpers.js';

const repo = fileURLToPath(new URL('../..', import.meta.url));
const elf = process.env.PICO_IMU_ELF ?? resolve(repo, process.env.CARGO_TARGET_DIR ?? 'target', 'thumbv6m-none-eabi/release/pico-imu');
const cli = fileURLToPath(new URL('../src/cli.js', import.meta.url));

test('the run retains no more heap after 8 s of emulated time than after 2 s', { skip: existsSync(elf) ? false : `no firmware at ${elf}`, timeout: 60000 }, async () => {
  const dir = mkdtempSync(join(tmpdir(), 'sim-memory-'));
  const log = join(dir, 'fw.log');
  const seed = 1 + Math.floor(Math.random() * 1e6);
  // The run as the xtask commands start it (--log, --quiet), with its memory lines after a
  // collection (--expose-gc) every 2 s.
  const p = spawn(process.execPath, ['--expose-gc', cli, 'run', '--elf', elf, '--seconds', '9', '--seed', String(seed), '--log', log, '--quiet', '--mem-log', '2'], { stdio: ['ignore', 'ignore', 'pipe'] });
  let err = '';
  p.stderr.setEncoding('utf8').on('data', (d) => (err += d));
  const code = await new Promise((r) => p.on('exit', r));
  assert.equal(code, 0, err);
  const heap = new Map();
  for (const m of err.matchAll(/memory at ([0-9.]+) s emulated: heap retained \(after GC\) ([0-9.]+) MiB/g)) heap.set(Number(m[1]), Number(m[2]));
  assert.ok(heap.has(2) && heap.has(8), `memory lines at 2 s and 8 s (seed ${seed}):\n${err}`);
  // Keeping every sample (1.2 k a second) cost 0.38 MiB a second, 2.3 MiB over these 6 s; what
  // is bounded (the log's tail, the models' FIFOs) is there by 2 s. 0.5 MiB: the collector's
  // own variation between two collections is under 0.1 MiB here.
  const grew = heap.get(8) - heap.get(2);
  assert.ok(grew < 0.5, `heap retained grew ${grew.toFixed(2)} MiB from 2 s to 8 s of emulated time (seed ${seed}):\n${err}`);
  // The log went to its file as it came.
  assert.match(readFileSync(log, 'utf8'), /booting/);
});

test('a host that stops reading holds emulated time at a bounded backlog; nothing is dropped', { timeout: 20000 }, async () => {
  const s = new Session({ elf: spinElf(mkdtempSync(join(tmpdir(), 'sim-memory-'))), stream: generateStream({ seed: 1, seconds: 1 }), defmtPrint: null });
  const port = await s.listen(0);
  const host = connect({ port, host: '127.0.0.1' });
  host.on('error', () => {});
  await new Promise((r) => host.on('connect', r));
  await until('the host to be served', () => s.client);
  // Whatever fails, the host and the port are closed so the test process can end.
  try {
    host.pause(); // a host busy elsewhere
    let got = 0;
    host.on('data', (d) => (got += d.length));
    // The device sends a chunk (random size, 16–32 KiB) every emulated 50 µs, a stream faster than
    // the host ever reads (and more than the kernel's socket buffers take).
    const chunk = 1024 * (16 + Math.floor(Math.random() * 17));
    let sent = 0;
    let next = 0;
    s.emu.pollHooks.push((nanos) => {
      if (nanos < next) return;
      next = nanos + 50e3;
      s.usb.onData(new Uint8Array(chunk).fill(sent & 0xff));
      sent += chunk;
    });
    s.emu.rttPollNanos = 50e3;
    let maxBacklog = 0;
    const shouldPause = () => {
      maxBacklog = Math.max(maxBacklog, s.client?.writableLength ?? 0);
      return s.hostBacklogged();
    };
    const end = 0.2e9; // 4 k chunks, 64–128 MiB if nothing waited
    const done = s.run(end, { shouldPause, sliceNanos: 1e6 });
    await new Promise((r) => setTimeout(r, 500));
    // Held: emulated time stopped short of the end while the host does not read.
    assert.ok(s.emu.clock.nanos < end, `emulated time ran to ${s.emu.clock.nanos / 1e9} s with the host not reading`);
    assert.ok(s.usbStats.backlogPauses >= 1, JSON.stringify(s.usbStats));
    // The backlog stays within the bound and what one slice sends past it (20 chunks).
    const bound = HOST_BACKLOG_BYTES + 21 * chunk;
    assert.ok(maxBacklog <= bound, `backlog ${maxBacklog} B over ${bound} B`);
    host.resume();
    assert.equal(await done, null);
    assert.equal(s.emu.clock.nanos >= end, true);
    await until('every byte to reach the host', () => got === sent, 10000);
    assert.equal(s.usbStats.droppedToHost, 0);
    assert.equal(s.usbStats.toHost, sent);
  } finally {
    host.destroy();
    s.emu.stop({ kind: 'test', message: 'test over' });
    await s.close();
  }
});

test('the firmware log goes to its sinks as it comes; the session keeps only its tail', async () => {
  const sunk = [];
  let rawSunk = 0;
  const s = new Session({
    elf: spinElf(mkdtempSync(join(tmpdir(), 'sim-memory-'))),
    stream: generateStream({ seed: 1, seconds: 1 }),
    defmtPrint: null,
    onLogLine: (l) => sunk.push(l),
    onRawLog: (b) => (rawSunk += b.length),
  });
  const n = 5 * LOG_TAIL_LINES + Math.floor(Math.random() * 1000);
  for (let i = 0; i < n; i++) s.decoder.onLine(`line ${i}`);
  assert.equal(sunk.length, n);
  assert.equal(s.logLineCount, n);
  assert.ok(s.logLines.length >= LOG_TAIL_LINES && s.logLines.length <= 2 * LOG_TAIL_LINES, `${s.logLines.length} lines kept`);
  assert.equal(s.logLines.at(-1), `line ${n - 1}`);
  assert.equal(s.logLines.at(-LOG_TAIL_LINES), `line ${n - LOG_TAIL_LINES}`);
  // Without the decoder the raw bytes go to their sink, counted, not kept.
  const m = 1 + Math.floor(Math.random() * 4096);
  for (let i = 0; i < 10; i++) s.decoder.push(new Uint8Array(m));
  assert.equal(rawSunk, 10 * m);
  assert.equal(s.decoder.rawByteCount, 10 * m);
  await s.close();
});
