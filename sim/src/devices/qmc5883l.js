// Register-level model of the QST QMC5883L magnetometer (I2C address 0x0D).
// Reference: QST QMC5883L datasheet rev C (2016): registers 00H–05H X/Y/Z LSB/MSB, 06H status
// (DRDY bit 0, OVL bit 1, DOR bit 2), 07H–08H temperature (100 LSB/°C, offset uncalibrated),
// 09H control 1 (MODE 1:0, ODR 3:2 = 10/50/100/200 Hz, RNG 5:4 = ±2 G / ±8 G, OSR 7:6),
// 0AH control 2 (INT_ENB 0, ROL_PNT 6, SOFT_RST 7), 0BH SET/RESET period, 0DH chip id 0xFF.
// Sensitivity 12000 LSB/G at ±2 G and 3000 LSB/G at ±8 G; 1 G = 100 µT.

import { RegisterDevice } from './i2c-bus.js';
import { SlotGrid } from './mpu6050.js';

/** Register addresses (the driver's `imu_drivers::qmc5883::reg_l::TABLE`, checked by a test). */
export const REG = {
  DATA_X_LSB: 0x00, STATUS: 0x06, TEMP_LSB: 0x07, CONTROL1: 0x09, CONTROL2: 0x0a,
  SET_RESET_PERIOD: 0x0b, CHIP_ID: 0x0d,
};

export const ODR_HZ = [10, 50, 100, 200];
export const LSB_PER_UT = [120, 30]; // RNG 0 (±2 G), RNG 1 (±8 G)

export class Qmc5883l extends RegisterDevice {
  constructor(stream, { record = true, clockError = 0 } = {}) {
    super();
    this.stream = stream;
    this.record = record;
    this.clockError = clockError;
    this.samples = [];
    // statusNotReady: status reads that found DRDY clear (a reader polled before the sample).
    this.stats = { produced: 0, overflows: 0, dataOverruns: 0, served: 0, resets: 0, stalledSlots: 0, statusNotReady: 0 };
    this.slots = new SlotGrid();
    this.stalls = [];
    this.powerOnReset(0);
  }

  powerOnReset() {
    this.regs = new Uint8Array(16);
    this.regs[REG.CHIP_ID] = 0xff;
    this.nextSample = null;
    this.latest = null;
    this.dataRead = 0;
    this.readySeen = false;
    this.stats.resets++;
  }

  get continuous() {
    return (this.regs[REG.CONTROL1] & 3) === 1;
  }

  /** Output period on the part's own oscillator (`clockError`: relative rate error). */
  get periodNanos() {
    return 1e9 / (ODR_HZ[(this.regs[REG.CONTROL1] >> 2) & 3] * (1 + this.clockError));
  }

  /** No measurement completes (DRDY never set) in [from, until) ns; the clock runs on. */
  stall(fromNanos, untilNanos = Infinity) {
    this.stalls.push([fromNanos, untilNanos]);
  }

  advance(nanos) {
    if (this.nextSample === null) return;
    while (this.nextSample <= nanos) {
      const t = this.nextSample;
      if (this.stalls.some(([a, b]) => t >= a && t < b)) this.stats.stalledSlots++;
      else this.produce(t);
      this.nextSample += this.periodNanos;
    }
  }

  produce(t) {
    const p = this.stream.magAt(t);
    const rng = (this.regs[REG.CONTROL1] >> 4) & 1;
    const lsb = LSB_PER_UT[rng];
    const raw = new Int16Array(4);
    let ovl = false;
    [p.mx, p.my, p.mz].forEach((v, i) => {
      const c = Math.round(v * lsb);
      if (c > 32767 || c < -32768) ovl = true;
      raw[i] = Math.max(-32768, Math.min(32767, c));
    });
    raw[3] = Math.max(-32768, Math.min(32767, Math.round(p.temp * 100)));
    const status = this.regs[REG.STATUS];
    let s = 0x01 | (ovl ? 0x02 : 0);
    if (status & 0x01) {
      // The previous sample was never read: data skipped.
      s |= 0x04;
      this.stats.dataOverruns++;
    }
    if (ovl) this.stats.overflows++;
    this.regs[REG.STATUS] = s;
    for (let i = 0; i < 3; i++) {
      this.regs[REG.DATA_X_LSB + 2 * i] = raw[i] & 0xff;
      this.regs[REG.DATA_X_LSB + 2 * i + 1] = (raw[i] >> 8) & 0xff;
    }
    this.regs[REG.TEMP_LSB] = raw[3] & 0xff;
    this.regs[REG.TEMP_LSB + 1] = (raw[3] >> 8) & 0xff;
    const sample = { k: this.stats.produced++, slot: this.slots.of(t, this.periodNanos), t, raw, served: 0 };
    if (this.record) this.samples.push(sample);
    this.latest = sample;
    this.dataRead = 0;
  }

  start(mode, nanos) {
    super.start(mode);
    this.advance(nanos);
  }

  nextPointer(p) {
    if (this.regs[REG.CONTROL2] & 0x40 && p === REG.STATUS) return REG.DATA_X_LSB; // ROL_PNT
    return (p + 1) & 0x0f;
  }

  readRegister(r, nanos) {
    this.advance(nanos);
    r &= 0x0f;
    const v = this.regs[r];
    // A reader uses the data only after it has seen DRDY set (a roll-over read from 06H reads
    // the data bytes even when the status it got first was clear, and discards them).
    if (r === REG.STATUS) {
      if (v & 0x01) this.readySeen = true;
      else this.stats.statusNotReady++;
    }
    if (r <= REG.DATA_X_LSB + 5) {
      // Reading any data register clears DRDY and DOR.
      this.regs[REG.STATUS] &= ~0x05;
      this.dataRead |= 1 << r;
      if (this.dataRead === 0x3f && this.latest && !this.latest.served) {
        // Served: all six bytes read after a status read that showed DRDY. A sample that
        // landed during a read whose status byte was clear is lost to the reader (and its
        // DRDY cleared by that read): not served, so the host sees the index jump.
        if (this.readySeen) {
          this.latest.served = nanos;
          this.stats.served++;
        }
        this.readySeen = false;
      }
    }
    return v;
  }

  writeRegister(r, v, nanos) {
    this.advance(nanos);
    r &= 0x0f;
    if (r === REG.CONTROL2 && v & 0x80) {
      this.powerOnReset();
      return;
    }
    if (r <= REG.TEMP_LSB + 1 || r === REG.CHIP_ID) return; // read-only
    this.regs[r] = v;
    if (r === REG.CONTROL1) this.nextSample = this.continuous ? nanos + this.periodNanos : null;
  }

  /** Served samples: k, slot (see SlotGrid), t_ns, mx my mz temp [counts], served_ns. */
  servedCsv() {
    const out = ['k,slot,t_ns,mx,my,mz,temp,served_ns'];
    for (const s of this.samples) if (s.served) out.push([s.k, s.slot, s.t, ...s.raw, s.served].join(','));
    return out.join('\n') + '\n';
  }
}
