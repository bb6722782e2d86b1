// A complete emulated board: firmware + I2C0 with an MPU-6050 at 0x68 and a QMC5883L at 0x0D
// (GP4 SDA / GP5 SCL), defmt log decoding, the USB CDC port, fault injection and reports.

import { createServer } from 'node:net';
import { writeFileSync, mkdirSync } from 'node:fs';
import { join } from 'node:path';
import { Emulator, CdcHost } from './emulator.js';
import { I2cBus } from './devices/i2c-bus.js';
import { Mpu6050 } from './devices/mpu6050.js';
import { Qmc5883l } from './devices/qmc5883l.js';
import { DefmtDecoder } from './defmt.js';

export const MPU_ADDR = 0x68;
export const QMC_ADDR = 0x0d;

/** Parses a duration like "2s", "150ms", "20us", "5" (seconds) into ns. */
export function parseDuration(s) {
  const m = /^([0-9]*\.?[0-9]+)\s*(s|ms|us|µs|ns)?$/.exec(String(s).trim());
  if (!m) throw new Error(`bad duration '${s}' (expected e.g. 2s, 150ms, 20us)`);
  const v = Number(m[1]);
  const unit = { s: 1e9, ms: 1e6, us: 1e3, µs: 1e3, ns: 1 }[m[2] ?? 's'];
  return v * unit;
}

/**
 * Fault spec grammar (one per --fault); <time> and <dur> like 3s, 150ms:
 *   nack:<mpu|qmc>@<time>[:<count>]   NACK the next <count> (default 1) address phases
 *   nack:<mpu|qmc>@<time>:<dur>       NACK every address phase for <dur>
 *   vanish:<mpu|qmc>@<time>[:<dur>]   the sensor is unpowered for <dur> (default 2s)
 *   stall:<mpu|qmc>@<time>[:<dur>]    the sensor answers but produces no data for <dur>
 *                                     (DATA_RDY / DRDY never set, FIFO not growing); no <dur>:
 *                                     for ever
 *   stuck@<time>[:<dur>]              a slave holds SDA low: every START loses arbitration;
 *                                     released by 9 SCL pulses, or (with <dur>) after <dur>
 *   hang@<time>:<dur>                 SDA held low for <dur> and a START waits for the bus
 *                                     (the transfer hangs) instead of losing arbitration
 *   overflow@<time>[:<dur>]           the CPU stalls <dur> (default 120ms) so the FIFO overflows
 */
export function parseFault(spec) {
  const m = /^(nack|vanish|stall|stuck|hang|overflow)(?::(mpu|qmc))?@([^:]+)(?::(.+))?$/.exec(spec.trim());
  if (!m) throw new Error(`bad fault '${spec}' (expected e.g. nack:mpu@5s:3, nack:mpu@5s:30ms, vanish:qmc@10s:2s, stall:qmc@3s:1s, stuck@20s, hang@20s:50ms, overflow@30s)`);
  const [, kind, target, at, arg] = m;
  const perSensor = ['nack', 'vanish', 'stall'].includes(kind);
  if (perSensor && !target) throw new Error(`fault '${spec}': say which sensor (mpu or qmc)`);
  if (!perSensor && target) throw new Error(`fault '${spec}': ${kind} is a bus or CPU fault, not a sensor's`);
  if (kind === 'hang' && arg === undefined) throw new Error(`fault '${spec}': say how long SDA is held (e.g. hang@3s:50ms)`);
  const f = { kind, target: target ?? null, at: parseDuration(at), count: undefined, duration: undefined, spec };
  if (kind === 'nack') {
    if (arg !== undefined && /[a-zµ]/.test(arg)) f.duration = parseDuration(arg);
    else f.count = Number(arg ?? 1);
    if (f.count !== undefined && !(Number.isInteger(f.count) && f.count > 0)) throw new Error(`fault '${spec}': NACK count must be a positive integer`);
  } else if (kind === 'vanish') f.duration = parseDuration(arg ?? '2s');
  else if (kind === 'overflow') f.duration = parseDuration(arg ?? '120ms');
  else if (arg !== undefined) f.duration = parseDuration(arg);
  return f;
}

/**
 * `--clock mpu:-1.3%,qmc:+0.5%`: each part's oscillator error (its rate relative to nominal;
 * −1.3 % = a clock 1.3 % slow). Returns { mpu, qmc } as fractions.
 */
export function parseClock(spec) {
  const out = { mpu: 0, qmc: 0 };
  if (!spec) return out;
  for (const part of spec.split(',')) {
    const m = /^(mpu|qmc):([+-]?[0-9]*\.?[0-9]+)%$/.exec(part.trim());
    if (!m) throw new Error(`bad clock '${part}' (expected e.g. mpu:-1.3%)`);
    const v = Number(m[2]) / 100;
    if (!(Math.abs(v) < 0.2)) throw new Error(`clock '${part}': an error of ${m[2]} % is not a crystal or RC oscillator's`);
    out[m[1]] = v;
  }
  return out;
}

/** How many of the firmware's last log lines a session keeps (for a failure's report). */
export const LOG_TAIL_LINES = 200;

/**
 * Bytes the host may leave unread on its TCP socket before emulated time waits for it (see
 * `Session.hostBacklogged`): 256 KiB, about 4 s of the firmware's stream.
 */
export const HOST_BACKLOG_BYTES = 256 * 1024;

/**
 * Bytes from the host the emulator holds before the device takes them (before enumeration, and
 * queued for the OUT endpoint): 64 KiB. Past it the host's socket is paused, and TCP's flow
 * control holds the host back, so a host that sends faster than the firmware reads (or before
 * it can) neither grows the emulator's memory without bound nor loses a byte; reading resumes
 * once half of it is taken (`Session.hostInBytes`).
 */
export const HOST_IN_BYTES = 64 * 1024;

export class Session {
  /**
   * `defmtPrint`: the decoder's binary (default: found on PATH; null: keep the log raw).
   * `record`: keep every sample the sensor models produce, for `writeServed` (grows by about
   * 330 bytes of heap per sample: for bounded runs only). `onLogLine(line)`: where every decoded
   * log line goes as it comes (the session itself keeps the last `LOG_TAIL_LINES`);
   * `onRawLog(bytes)`: where the raw RTT bytes go when there is no decoder.
   */
  constructor({ elf, stream, instantI2c = false, faults = [], clock = { mpu: 0, qmc: 0 }, echoLog = false, markerSymbol, defmtPrint, record = false, onLogLine = () => {}, onRawLog = () => {} } = {}) {
    this.logLines = []; // the last LOG_TAIL_LINES lines
    this.logLineCount = 0;
    this.decoder = new DefmtDecoder(elf, {
      onLine: (l) => {
        this.logLineCount++;
        this.logLines.push(l);
        if (this.logLines.length > 2 * LOG_TAIL_LINES) this.logLines.splice(0, this.logLines.length - LOG_TAIL_LINES);
        onLogLine(l);
        if (echoLog) process.stderr.write(`[fw] ${l}\n`);
      },
      onRaw: onRawLog,
      binary: defmtPrint,
    });
    this.emu = new Emulator({ elf, markerSymbol, onRtt: (b) => this.decoder.push(b) });
    this.bus = new I2cBus(this.emu.mcu, { index: 0, sda: 4, scl: 5, instant: instantI2c });
    this.mpu = this.bus.attach(MPU_ADDR, new Mpu6050(stream, { clockError: clock.mpu, record }));
    this.qmc = this.bus.attach(QMC_ADDR, new Qmc5883l(stream, { clockError: clock.qmc, record }));
    this.usb = new CdcHost(this.emu);
    // backlogPauses: the times emulated time waited for the host to read its backlog.
    // hostInPauses: the times the host's socket was paused, its bytes not yet taken by the device.
    this.usbStats = { toHost: 0, fromHost: 0, droppedToHost: 0, backlogPauses: 0, maxHostBacklog: 0, hostInPauses: 0 };
    this.client = null;
    this.usb.onData = (buf) => {
      if (this.client) {
        this.usbStats.toHost += buf.length;
        this.client.write(Buffer.from(buf));
        this.usbStats.maxHostBacklog = Math.max(this.usbStats.maxHostBacklog, this.client.writableLength);
      } else {
        this.usbStats.droppedToHost += buf.length;
      }
    };
    this.clock = clock;
    this.faults = faults.map((f) => ({ ...f, fired: null }));
    for (const f of this.faults) this.scheduleFault(f);
  }

  scheduleFault(f) {
    const emu = this.emu;
    const alarm = emu.clock.createAlarm(() => {
      f.fired = emu.clock.nanos;
      const dev = f.target === 'mpu' ? this.mpu : f.target === 'qmc' ? this.qmc : null;
      const addr = f.target === 'mpu' ? MPU_ADDR : QMC_ADDR;
      switch (f.kind) {
        case 'nack':
          if (f.duration !== undefined) this.bus.injectNackWindow(addr, f.duration);
          else this.bus.injectNacks(addr, f.count);
          break;
        case 'vanish':
          dev.vanish(emu.clock.nanos, emu.clock.nanos + f.duration);
          break;
        case 'stall':
          dev.stall(emu.clock.nanos, f.duration === undefined ? Infinity : emu.clock.nanos + f.duration);
          break;
        case 'stuck':
          this.bus.injectStuckBus({ nanos: f.duration ?? null });
          break;
        case 'hang':
          this.bus.injectStuckBus({ nanos: f.duration, hang: true });
          break;
        case 'overflow':
          emu.stallCpu(f.duration);
          break;
      }
    });
    alarm.schedule(Math.max(0, f.at - emu.clock.nanos));
  }

  /**
   * Opens the CDC port as a TCP server on 127.0.0.1 (port 0 = any free port). One host at a
   * time, like a serial port: a host that connects while another has the port waits, and is
   * served as soon as that one goes (closes or ends its side).
   */
  listen(port = 0) {
    this.waitingHosts = [];
    return new Promise((resolve, reject) => {
      this.server = createServer((sock) => {
        sock.setNoDelay(true);
        sock.on('error', () => {}); // a reset host is dropped by the 'close' that follows
        if (this.client) {
          this.waitingHosts.push(sock);
          sock.on('close', () => {
            this.waitingHosts = this.waitingHosts.filter((w) => w !== sock);
          });
        } else this.serve(sock);
      });
      this.server.on('error', reject);
      this.server.listen(port, '127.0.0.1', () => resolve(this.server.address().port));
    });
  }

  /** Makes `sock` the host of the port. */
  serve(sock) {
    this.client = sock;
    sock.on('data', (d) => {
      if (this.client !== sock) return;
      this.usbStats.fromHost += d.length;
      if (this.usb.connected) this.usb.write(d);
      else this.pendingFromHost = Buffer.concat([this.pendingFromHost ?? Buffer.alloc(0), d]);
      this.paceHostIn();
    });
    const drop = () => {
      if (this.client !== sock) return;
      this.client = null;
      const next = this.waitingHosts.shift();
      if (next) this.serve(next);
    };
    // 'end' (the host closed its side) comes before 'close': the next host is served then,
    // not after the socket has been torn down.
    sock.on('end', drop);
    sock.on('close', drop);
  }

  /**
   * Whether the host has more than `HOST_BACKLOG_BYTES` unread: a host slower than the stream.
   * The bytes wait in the socket's buffer, which would otherwise grow without bound; a run
   * that asks this before each slice (`shouldPause`) lets emulated time wait for the host
   * instead, as it waits while no host is connected, so nothing is dropped.
   */
  hostBacklogged() {
    const waiting = !!this.client && this.client.writableLength > HOST_BACKLOG_BYTES;
    if (waiting && !this.backlogged) this.usbStats.backlogPauses++;
    this.backlogged = waiting;
    return waiting;
  }

  flushPendingHost() {
    if (this.pendingFromHost && this.usb.connected) {
      this.usb.write(this.pendingFromHost);
      this.pendingFromHost = null;
    }
    this.paceHostIn();
  }

  /** Bytes from the host held by the emulator, not yet taken by the device. */
  hostInBytes() {
    const ep = this.usb.cdc.outEndpoint;
    const queued = ep >= 0 ? this.emu.usbOut.queuedBytes(ep) : 0;
    return (this.pendingFromHost?.length ?? 0) + queued;
  }

  /**
   * Pauses the host's socket while it has more than `HOST_IN_BYTES` waiting, resumes it when
   * half of that is taken (called on every arrival and from the run loop's poll hook).
   */
  paceHostIn() {
    const sock = this.client;
    if (!sock) return;
    const held = this.hostInBytes();
    if (!sock.isPaused() && held > HOST_IN_BYTES) {
      sock.pause();
      this.usbStats.hostInPauses++;
    } else if (sock.isPaused() && held <= HOST_IN_BYTES / 2) {
      sock.resume();
    }
  }

  async run(untilNanos, opts = {}) {
    if (!this.flushHook) {
      this.flushHook = () => this.flushPendingHost();
      this.emu.pollHooks.push(this.flushHook);
    }
    const t0 = process.hrtime.bigint();
    const n0 = this.emu.clock.nanos;
    const paused0 = this.emu.pausedWallSeconds ?? 0;
    const stop = await this.emu.run(untilNanos, opts);
    // Wall time spent running (time paused waiting for a host to connect excluded).
    this.wallSeconds = (this.wallSeconds ?? 0) + Number(process.hrtime.bigint() - t0) / 1e9 - ((this.emu.pausedWallSeconds ?? 0) - paused0);
    this.emulatedSeconds = (this.emulatedSeconds ?? 0) + (this.emu.clock.nanos - n0) / 1e9;
    return stop;
  }

  /**
   * Closes the port and stops decoding. Hosts are asked to close (their pending bytes are
   * flushed) and cut off after 300 ms if they keep their end open.
   */
  async close() {
    const hosts = [this.client, ...(this.waitingHosts ?? [])].filter(Boolean);
    for (const h of hosts) h.end();
    if (this.server) {
      const cut = setTimeout(() => hosts.forEach((h) => h.destroy()), 300);
      await new Promise((r) => this.server.close(r));
      clearTimeout(cut);
    }
    await this.decoder.close();
  }

  summary() {
    const e = this.emu;
    const marks = e.markReport();
    return {
      emulated_s: e.clock.nanos / 1e9,
      wall_s: this.wallSeconds ?? 0,
      emulated_per_wall: this.wallSeconds ? (this.emulatedSeconds ?? 0) / this.wallSeconds : null,
      cpu_load_percent: 100 * e.cpuLoad,
      executed_cycles: e.core.cycles,
      stop: e.stopReason,
      rtt_bytes: e.rtt ? e.rtt.bytes : null,
      i2c: this.bus.stats,
      mpu: this.mpu.stats,
      qmc: this.qmc.stats,
      stream_wraps: this.mpu.stream.wraps,
      usb: { ...this.usbStats, enumerated: this.usb.connected, out_packets: e.usbOut.deliveries },
      flash: e.stats,
      log_lines: this.logLineCount,
      faults: this.faults.map((f) => ({ spec: f.spec, fired_s: f.fired === null ? null : f.fired / 1e9 })),
      clock: this.clock,
      marks: marks ? { cycles: Object.fromEntries(marks.cycles), entries: Object.fromEntries(marks.entries) } : null,
      diagnostics: e.diagnostics.slice(0, 20),
    };
  }

  /** Writes the exact raw samples the models served (mpu_served.csv, qmc_served.csv). */
  writeServed(dir) {
    mkdirSync(dir, { recursive: true });
    writeFileSync(join(dir, 'mpu_served.csv'), this.mpu.servedCsv());
    writeFileSync(join(dir, 'qmc_served.csv'), this.qmc.servedCsv());
  }
}
