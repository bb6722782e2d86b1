#!/usr/bin/env node
// pico-imu-sim: run the firmware ELF on an emulated RP2040 with simulated sensors.
//
//   node src/cli.js run   --elf FW.elf [--seconds 10] [--stream S.csv | --seed N] [--port P]
//                         [--fault SPEC]... [--served DIR] [--summary FILE] [--log FILE]
//   node src/cli.js gen-stream --out S.csv [--seconds 60] [--seed 1] [--sine AMP,FREQ]
//   node src/cli.js bench --elf FW.elf [--seconds 2] --report FILE.md
//
// Exit status: 0 = ran to the end; 1 = the firmware stopped (panic/UDF), deadlocked or a
// model/harness error (the decoded defmt log is printed); 2 = bad arguments.

import { parseArgs } from 'node:util';
import { writeFileSync, openSync, writeSync, closeSync } from 'node:fs';
import { Session, parseFault, parseDuration, parseClock } from './session.js';
import { loadStreamCsv, generateStream, streamToCsv } from './stream.js';
import { benchReport } from './bench.js';
import { profile } from './profile.js';

const usage = `usage:
  pico-imu-sim run --elf FW.elf [--seconds S] [--stream S.csv | --seed N] [--port P | --port-file F]
                   [--warmup S] [--exit-on-disconnect] [--fault SPEC]... [--clock mpu:-1.3%,qmc:-1.3%]
                   [--instant-i2c] [--served DIR] [--summary F.json]
                   [--log F.txt] [--quiet] [--mem-log S]
  pico-imu-sim gen-stream --out S.csv [--seconds S] [--seed N] [--sine AMP_DPS,FREQ_HZ]
  pico-imu-sim bench --elf FW.elf [--seconds S] [--warmup S] [--seed N] [--clock mpu:+1.3%,qmc:+1.3%]
                   [--draw N [--draw-seed S] [--span 1.3]] [--report F.md] [--json F.json]
                   (--draw: the bench at N pairs of part clocks drawn within ±span %, a row each
                   and their sum: windows over budget, runs within the goal in every window)
  pico-imu-sim profile --elf FW.elf [--seconds S] [--top N] [--callers RE] [--copies] [--exact [--from S] [--pcs RE] [--tasks] [--polls F.tsv] [--clock mpu:+1.3%,qmc:+1.3%]]
                   (PC samples by function; callers of leaf functions matching RE; memcpy/memset
                   calls by caller; --exact: every instruction's cycles by function per sample set;
                   --pcs: the cycles of each instruction address in the functions matching RE;
                   --tasks: the cycles of each task's polls, of the interrupts and of the run loop,
                   with each task's costliest functions; --polls: every task poll, its start
                   and cycles, into F.tsv; --clock: the parts' oscillator errors, as for run)
fault SPEC: nack:mpu@5s:3 | nack:mpu@5s:30ms | vanish:qmc@10s:2s | stall:qmc@3s:1s | stall:qmc@0s
            | stuck@20s | stuck@20s:50ms | hang@20s:50ms | overflow@30s:120ms
--clock: each part's oscillator error (a clock 1.3 % slow: mpu:-1.3%)
--seed: without --stream, a generated stream of at most 600 s, wrapped by longer runs
--mem-log: print the process's memory (heap, rss; MiB) to stderr every S emulated seconds`;

function fail(msg, code = 2) {
  process.stderr.write(`pico-imu-sim: ${msg}\n`);
  process.exit(code);
}

/** What the run says when the optional defmt-print decoder is not installed. */
function rawLogNote(log) {
  const where = log ? ` (${log}.rtt)` : '';
  return `defmt-print not installed (optional): the firmware log stays raw${where}; \`cargo install defmt-print\` to decode it`;
}

/**
 * The longest stream `run` generates, s: a longer run wraps it (counted in the summary's
 * `stream_wraps`) rather than hold 80 kB of columns per second of emulated time (2.9 GB for ten
 * hours).
 */
const RUN_STREAM_MAX_S = 600;

function streamFrom(v, seconds, maxSeconds = Infinity) {
  if (v.stream) return loadStreamCsv(v.stream);
  const sine = v.sine ? v.sine.split(',').map(Number) : null;
  return generateStream({
    seed: Number(v.seed ?? 1),
    seconds: Math.max(1, Math.ceil(Math.min(seconds, maxSeconds))),
    sine: sine ? { amplitude: sine[0], frequency: sine[1] } : null,
  });
}

/** `--mem-log S`: the interval of the memory lines, emulated seconds (> 0). */
function parseMemLog(text) {
  const n = Number(text);
  if (!(Number.isFinite(n) && n > 0)) fail(`--mem-log '${text}': an interval in emulated seconds, e.g. 60`);
  return n;
}

/**
 * Prints the process's memory to stderr every `every` emulated seconds: the JS heap in use
 * (live objects and garbage not yet collected), the heap's size, the resident set and the
 * memory outside the heap held by buffers (ArrayBuffers, Buffers), all in MiB.
 */
function logMemory(s, every) {
  let next = 0;
  const mib = (b) => (b / 2 ** 20).toFixed(1);
  s.emu.pollHooks.push((nanos) => {
    if (nanos < next) return;
    next = nanos + every * 1e9;
    // With `node --expose-gc` the heap is collected first: what is used is what is retained.
    if (typeof globalThis.gc === 'function') globalThis.gc();
    const m = process.memoryUsage();
    const what = typeof globalThis.gc === 'function' ? 'heap retained (after GC)' : 'heap used';
    process.stderr.write(`pico-imu-sim: memory at ${(nanos / 1e9).toFixed(1)} s emulated: ${what} ${mib(m.heapUsed)} MiB of ${mib(m.heapTotal)} MiB, rss ${mib(m.rss)} MiB, array buffers ${mib(m.arrayBuffers)} MiB\n`);
  });
}

async function cmdRun(v) {
  if (!v.elf) fail('run: --elf is required');
  const seconds = Number(v.seconds ?? 10);
  const warmup = v.warmup ? parseDuration(v.warmup) : 0;
  const faults = (v.fault ?? []).map(parseFault);
  const clock = parseClock(v.clock);
  const stream = streamFrom(v, seconds, RUN_STREAM_MAX_S);
  // The log is written as it comes (a run of hours keeps none of it in memory): decoded lines
  // to --log, or without the decoder the raw RTT bytes to --log's .rtt file.
  const logFd = v.log ? openSync(v.log, 'w') : null;
  let rawFd = null;
  const s = new Session({
    elf: v.elf, stream, faults, clock, instantI2c: !!v['instant-i2c'], echoLog: !v.quiet,
    // Every sample the models produce is kept only when --served asks for them.
    record: !!v.served,
    onLogLine: (l) => logFd !== null && writeSync(logFd, `${l}\n`),
    onRawLog: (b) => rawFd !== null && writeSync(rawFd, b),
  });
  if (!s.decoder.available) {
    process.stderr.write(`pico-imu-sim: ${rawLogNote(v.log)}\n`);
    if (v.log) rawFd = openSync(`${v.log}.rtt`, 'w');
  }
  const stopAt = seconds * 1e9;
  if (v['mem-log'] !== undefined) logMemory(s, parseMemLog(v['mem-log']));
  let stop = null;
  if (v.port !== undefined || v['port-file']) {
    // Boot and run the warm-up before the port opens; afterwards emulated time advances only
    // while a host is connected (a closed port would otherwise race ahead of the host).
    if (warmup) stop = await s.run(warmup);
    const port = await s.listen(Number(v.port ?? 0));
    process.stderr.write(`pico-imu-sim: USB CDC on tcp:127.0.0.1:${port}\n`);
    if (v['port-file']) writeFileSync(v['port-file'], `${port}\n`);
    // A signal ends the run like its end time: the port closes, summary and log are written.
    // A second one exits at once.
    let signalled = false;
    const onSignal = (sig) => {
      if (signalled) process.exit(sig === 'SIGINT' ? 130 : 143);
      signalled = true;
      s.emu.stop({ kind: 'signal', message: 'stopped by signal' });
    };
    process.on('SIGINT', onSignal);
    process.on('SIGTERM', onSignal);
    // --exit-on-disconnect: the run ends (successfully) when the host that connected goes away.
    let seenClient = false;
    // Emulated time also waits while the host has a backlog of unread bytes (a host slower
    // than the stream): the bytes wait in the socket, bounded, and none is dropped.
    const shouldPause = () => {
      if (s.client) seenClient = true;
      else if (seenClient && v['exit-on-disconnect']) s.emu.stop({ kind: 'disconnect', message: 'host disconnected' });
      return !s.client || s.hostBacklogged();
    };
    if (!stop) stop = await s.run(stopAt, { shouldPause });
    if (stop && (stop.kind === 'signal' || stop.kind === 'disconnect')) stop = null;
  } else {
    stop = await s.run(stopAt);
  }
  await s.close();
  const summary = s.summary();
  if (v.served) s.writeServed(v.served);
  if (v.summary) writeFileSync(v.summary, JSON.stringify(summary, null, 2));
  for (const fd of [logFd, rawFd]) if (fd !== null) closeSync(fd);
  const line = `emulated ${summary.emulated_s.toFixed(3)} s in ${summary.wall_s.toFixed(2)} s wall (${(summary.emulated_per_wall ?? 0).toFixed(3)} emulated s per wall s), CPU load ${summary.cpu_load_percent.toFixed(2)} %, I2C ${summary.i2c.transactions} transactions / ${summary.i2c.nacks} NACKs, MPU samples produced ${summary.mpu.produced} served ${summary.mpu.servedFifo + summary.mpu.servedRegs}, QMC produced ${summary.qmc.produced} served ${summary.qmc.served}`;
  process.stderr.write(`pico-imu-sim: ${line}\n`);
  if (stop) {
    process.stderr.write(`pico-imu-sim: FAILED at ${(stop.nanos / 1e9).toFixed(6)} s emulated: ${stop.message}\n`);
    process.stderr.write('--- decoded defmt log (last 60 lines) ---\n');
    process.stderr.write(s.logLines.slice(-60).join('\n') + '\n');
    process.exit(1);
  }
}

async function cmdGen(v) {
  if (!v.out) fail('gen-stream: --out is required');
  const st = streamFrom(v, Number(v.seconds ?? 60));
  writeFileSync(v.out, streamToCsv(st));
}

// The options of every subcommand: values given once, flags, and --fault (repeatable).
const STRING_OPTIONS = [
  'elf', 'seconds', 'stream', 'seed', 'sine', 'port', 'port-file', 'warmup', 'clock',
  'served', 'summary', 'log', 'mem-log', 'out', 'report', 'json', 'top', 'callers', 'pcs', 'polls', 'from',
  'draw', 'draw-seed', 'span',
];
const BOOLEAN_OPTIONS = ['instant-i2c', 'exit-on-disconnect', 'quiet', 'copies', 'exact', 'tasks'];

async function main() {
  const [cmd, ...rest] = process.argv.slice(2);
  let parsed;
  try {
    parsed = parseArgs({
      args: rest,
      options: {
        ...Object.fromEntries(STRING_OPTIONS.map((o) => [o, { type: 'string' }])),
        ...Object.fromEntries(BOOLEAN_OPTIONS.map((o) => [o, { type: 'boolean' }])),
        fault: { type: 'string', multiple: true },
      },
    });
  } catch (e) {
    fail(`${e.message}\n${usage}`);
  }
  const v = parsed.values;
  try {
    if (cmd === 'run') await cmdRun(v);
    else if (cmd === 'gen-stream') await cmdGen(v);
    else if (cmd === 'bench') await benchReport(v);
    else if (cmd === 'profile') await profile(v);
    else fail(usage);
  } catch (e) {
    fail(e.stack ?? String(e), 1);
  }
}

main();
