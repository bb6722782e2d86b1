// Register-level model of the InvenSense MPU-6050 (I2C address 0x68).
// References: MPU-6000/MPU-6050 Register Map and Descriptions, RM-MPU-6000A-00 rev 4.2
// (register numbers, reset values, FS_SEL/AFS_SEL sensitivities, DLPF table of §4.3, sample
// rate = gyroscope output rate / (1 + SMPLRT_DIV) §4.2, temperature in °C = TEMP_OUT/340 + 36.53
// §4.18, FIFO order by register number §4.7, 1024-byte FIFO, FIFO_OFLOW_INT §4.16) and the
// MPU-6000/MPU-6050 Product Specification PS-MPU-6000A-00 rev 3.4.

import { RegisterDevice } from './i2c-bus.js';

export const REG = {
  SMPLRT_DIV: 0x19, CONFIG: 0x1a, GYRO_CONFIG: 0x1b, ACCEL_CONFIG: 0x1c, FIFO_EN: 0x23,
  INT_PIN_CFG: 0x37, INT_ENABLE: 0x38, INT_STATUS: 0x3a, ACCEL_XOUT_H: 0x3b, TEMP_OUT_H: 0x41,
  GYRO_XOUT_H: 0x43, USER_CTRL: 0x6a, PWR_MGMT_1: 0x6b, PWR_MGMT_2: 0x6c, FIFO_COUNT_H: 0x72,
  FIFO_COUNT_L: 0x73, FIFO_R_W: 0x74, WHO_AM_I: 0x75,
};

const FIFO_SIZE = 1024;
const G = 9.80665; // m/s² per g (standard gravity)
/** LSB per g for AFS_SEL 0..3 (register map §4.17). */
export const ACCEL_LSB_PER_G = [16384, 8192, 4096, 2048];
/** LSB per deg/s for FS_SEL 0..3 (register map §4.19). */
export const GYRO_LSB_PER_DPS = [131, 65.5, 32.8, 16.4];
/** DLPF_CFG 0..7 → [accel bandwidth Hz, gyro bandwidth Hz, gyro output rate Hz] (§4.3). */
export const DLPF = [
  [260, 256, 8000], [184, 188, 1000], [94, 98, 1000], [44, 42, 1000],
  [21, 20, 1000], [10, 10, 1000], [5, 5, 1000], [260, 256, 8000],
];

const clamp16 = (v) => Math.max(-32768, Math.min(32767, Math.round(v)));

export class Mpu6050 extends RegisterDevice {
  /**
   * @param stream source of physical values (Stream.imuAt)
   * @param opts.record keep every sample produced and whether it was served (for bit-exact checks)
   */
  constructor(stream, { record = true, clockError = 0 } = {}) {
    super();
    this.stream = stream;
    this.record = record;
    this.clockError = clockError;
    this.samples = []; // { k, slot, t, raw: Int16Array(7) [ax ay az temp gx gy gz], served: 0 | ns }
    this.stats = { produced: 0, overflows: 0, fifoResets: 0, servedFifo: 0, servedRegs: 0, overwrittenBytes: 0, resets: 0, stalledSlots: 0 };
    this.slots = new SlotGrid();
    this.stalls = [];
    this.powerOnReset(0);
  }

  powerOnReset(nanos = 0) {
    this.regs = new Uint8Array(128);
    this.regs[REG.PWR_MGMT_1] = 0x40; // SLEEP
    this.regs[REG.WHO_AM_I] = 0x68;
    this.fifo = new Uint8Array(FIFO_SIZE);
    this.fifoOwner = new Array(FIFO_SIZE); // the sample each byte belongs to
    this.fifoHead = 0; // read index
    this.fifoCount = 0;
    this.filter = null;
    this.nextSample = null; // ns of the next internal sample; null while asleep
    this.latest = null;
    this.readBurst = null;
    this.stats.resets++;
    this.lastNanos = nanos;
  }

  get sleeping() {
    return (this.regs[REG.PWR_MGMT_1] & 0x40) !== 0;
  }

  get dlpf() {
    return DLPF[this.regs[REG.CONFIG] & 7];
  }

  /**
   * Sample period in ns: gyro output rate / (1 + SMPLRT_DIV), on the part's own oscillator
   * (`clockError`: its relative rate error, −0.013 for a clock 1.3 % slow).
   */
  get samplePeriodNanos() {
    return (1e9 * (1 + this.regs[REG.SMPLRT_DIV])) / (this.dlpf[2] * (1 + this.clockError));
  }

  /** No sample is produced (no DATA_RDY, no FIFO write) in [from, until) ns; the clock runs on. */
  stall(fromNanos, untilNanos = Infinity) {
    this.stalls.push([fromNanos, untilNanos]);
  }

  restartSampling(nanos) {
    this.nextSample = this.sleeping ? null : nanos + this.samplePeriodNanos;
  }

  /** Produces every internal sample due up to `nanos`. */
  advance(nanos) {
    if (this.nextSample === null) return;
    while (this.nextSample <= nanos) {
      const t = this.nextSample;
      if (this.stalls.some(([a, b]) => t >= a && t < b)) this.stats.stalledSlots++;
      else this.produce(t);
      this.nextSample += this.samplePeriodNanos;
    }
  }

  /**
   * One sample: physical values → DLPF (one-pole IIR with the configured bandwidth,
   * α = 1 − exp(−2π·f_c·T_s)) → counts at the configured full-scale range.
   */
  produce(t) {
    const p = this.stream.imuAt(t);
    const [bwA, bwG] = this.dlpf;
    const ts = this.samplePeriodNanos * 1e-9;
    const aA = 1 - Math.exp(-2 * Math.PI * bwA * ts);
    const aG = 1 - Math.exp(-2 * Math.PI * bwG * ts);
    const x = [p.ax, p.ay, p.az, p.gx, p.gy, p.gz];
    if (!this.filter) this.filter = x.slice();
    else for (let i = 0; i < 6; i++) this.filter[i] += (i < 3 ? aA : aG) * (x[i] - this.filter[i]);
    const f = this.filter;
    const la = ACCEL_LSB_PER_G[(this.regs[REG.ACCEL_CONFIG] >> 3) & 3] / G;
    const lg = GYRO_LSB_PER_DPS[(this.regs[REG.GYRO_CONFIG] >> 3) & 3];
    const raw = new Int16Array(7);
    raw[0] = clamp16(f[0] * la);
    raw[1] = clamp16(f[1] * la);
    raw[2] = clamp16(f[2] * la);
    raw[3] = clamp16((p.temp - 36.53) * 340);
    raw[4] = clamp16(f[3] * lg);
    raw[5] = clamp16(f[4] * lg);
    raw[6] = clamp16(f[5] * lg);
    const k = this.stats.produced++;
    const slot = this.slots.of(t, this.samplePeriodNanos);
    const sample = { k, slot, t, raw, served: 0, bytesRead: 0, fifoBytes: 0 };
    if (this.record) this.samples.push(sample);
    this.latest = sample;
    // Data registers 0x3B..0x48 (big-endian words).
    for (let i = 0; i < 7; i++) {
      this.regs[REG.ACCEL_XOUT_H + 2 * i] = (raw[i] >> 8) & 0xff;
      this.regs[REG.ACCEL_XOUT_H + 2 * i + 1] = raw[i] & 0xff;
    }
    this.regs[REG.INT_STATUS] |= 0x01; // DATA_RDY_INT
    if (this.regs[REG.USER_CTRL] & 0x40) this.pushFifo(sample);
  }

  /** FIFO_EN selects accel (bit 3), temp (7), gyro x/y/z (6/5/4); written in register order. */
  pushFifo(sample) {
    const en = this.regs[REG.FIFO_EN];
    const words = [];
    if (en & 0x08) words.push(0, 1, 2);
    if (en & 0x80) words.push(3);
    if (en & 0x40) words.push(4);
    if (en & 0x20) words.push(5);
    if (en & 0x10) words.push(6);
    sample.fifoBytes = words.length * 2;
    for (const w of words) {
      this.fifoPush((sample.raw[w] >> 8) & 0xff, sample);
      this.fifoPush(sample.raw[w] & 0xff, sample);
    }
  }

  fifoPush(byte, owner) {
    if (this.fifoCount === FIFO_SIZE) {
      // Full: the oldest byte is overwritten (register map §4.16, FIFO_OFLOW_INT).
      this.fifoHead = (this.fifoHead + 1) % FIFO_SIZE;
      this.fifoCount--;
      this.stats.overwrittenBytes++;
      if (!(this.regs[REG.INT_STATUS] & 0x10)) this.stats.overflows++;
      this.regs[REG.INT_STATUS] |= 0x10;
    }
    const i = (this.fifoHead + this.fifoCount) % FIFO_SIZE;
    this.fifo[i] = byte;
    this.fifoOwner[i] = owner;
    this.fifoCount++;
  }

  fifoPop(nanos) {
    if (this.fifoCount === 0) return 0xff; // reading an empty FIFO returns garbage; 0xFF here
    const b = this.fifo[this.fifoHead];
    const owner = this.fifoOwner[this.fifoHead];
    this.fifoHead = (this.fifoHead + 1) % FIFO_SIZE;
    this.fifoCount--;
    this.fifoOwner[this.fifoHead === 0 ? FIFO_SIZE - 1 : this.fifoHead - 1] = undefined;
    owner.bytesRead++;
    if (owner.bytesRead === owner.fifoBytes && !owner.served) {
      owner.served = nanos;
      this.stats.servedFifo++;
    }
    return b;
  }

  start(mode, nanos) {
    super.start(mode);
    this.advance(nanos);
    this.readBurst = mode === 'read' && this.pointer === REG.ACCEL_XOUT_H ? { sample: this.latest, n: 0 } : null;
  }

  nextPointer(p) {
    return p === REG.FIFO_R_W ? p : (p + 1) & 0x7f;
  }

  readRegister(r, nanos) {
    this.advance(nanos);
    if (this.readBurst) this.readBurst.n++;
    if (r === REG.FIFO_R_W) return this.fifoPop(nanos);
    if (r === REG.FIFO_COUNT_H) return (this.fifoCount >> 8) & 0xff;
    if (r === REG.FIFO_COUNT_L) return this.fifoCount & 0xff;
    const v = this.regs[r & 0x7f];
    if (r === REG.INT_STATUS || this.regs[REG.INT_PIN_CFG] & 0x10) this.regs[REG.INT_STATUS] = 0;
    return v;
  }

  writeRegister(r, v, nanos) {
    this.advance(nanos);
    r &= 0x7f;
    switch (r) {
      case REG.WHO_AM_I:
      case REG.INT_STATUS:
        return; // read-only
      case REG.PWR_MGMT_1:
        if (v & 0x80) {
          // DEVICE_RESET: every register to its reset value.
          this.powerOnReset(nanos);
          return;
        }
        this.regs[r] = v;
        this.restartSampling(nanos);
        return;
      case REG.USER_CTRL:
        if (v & 0x04) {
          // FIFO_RESET (self-clearing).
          this.fifoHead = 0;
          this.fifoCount = 0;
          this.stats.fifoResets++;
        }
        this.regs[r] = v & ~0x07;
        return;
      case REG.SMPLRT_DIV:
      case REG.CONFIG:
        this.regs[r] = v;
        this.restartSampling(nanos);
        return;
      default:
        this.regs[r] = v;
    }
  }

  stop(repeated, nanos) {
    if (this.readBurst && this.readBurst.n >= 14 && this.readBurst.sample && !this.readBurst.sample.served) {
      this.readBurst.sample.served = nanos ?? 1;
      this.stats.servedRegs++;
    }
    this.readBurst = null;
  }

  /**
   * Served samples as CSV rows: k (produced index), slot (position on the sample grid),
   * t_ns (when the part sampled it), ax ay az temp gx gy gz [counts], served_ns.
   */
  servedCsv() {
    const out = ['k,slot,t_ns,ax,ay,az,temp,gx,gy,gz,served_ns'];
    for (const s of this.samples) if (s.served) out.push([s.k, s.slot, s.t, ...s.raw, s.served].join(','));
    return out.join('\n') + '\n';
  }
}

/**
 * A sensor's sample grid, the ground truth of what was lost: slot = round((t − t₀) / T), t₀ the
 * first sample the part ever produced and T its period at the time. Within an uninterrupted run
 * consecutive samples are one slot apart; a stall, an unread FIFO or an outage leaves the slots
 * of the samples that never reached the reader, and a part restarted in step with its old grid
 * (the firmware times its re-initialisation for that) continues on the same slots.
 */
export class SlotGrid {
  constructor() {
    this.origin = null;
  }

  of(t, period) {
    if (this.origin === null) this.origin = t;
    return Math.round((t - this.origin) / period);
  }
}
