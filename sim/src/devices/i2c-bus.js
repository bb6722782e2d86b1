// An I2C bus attached to one rp2040js I2C controller: routes the controller's callbacks to
// register-level device models, takes real bus time per byte, and injects faults.
//
// Timing: a byte plus its ACK is 9 SCL periods; START and STOP are one period each. The SCL
// period comes from the controller's IC_FS_SCL_HCNT + IC_FS_SCL_LCNT in clk_sys cycles
// (RP2040 datasheet §4.3.14.2), 2.5 µs (400 kHz) if those are not programmed.

export class I2cBus {
  /**
   * @param mcu rp2040js RP2040
   * @param opts.index controller (0 = I2C0)
   * @param opts.sda, opts.scl GPIO numbers (for bus-stuck modelling), default 4 and 5
   * @param opts.instant complete every bus phase at once (no bus time; fast path only)
   */
  constructor(mcu, { index = 0, sda = 4, scl = 5, instant = false } = {}) {
    this.mcu = mcu;
    this.i2c = mcu.i2c[index];
    this.devices = new Map();
    this.instant = instant;
    this.sdaPin = mcu.gpio[sda];
    this.sclPin = mcu.gpio[scl];
    this.current = null;
    this.pending = null;
    this.alarm = mcu.clock.createAlarm(() => {
      const f = this.pending;
      this.pending = null;
      if (f) f();
    });
    // Faults
    this.nackBudget = new Map(); // address -> number of address phases still to NACK
    this.stuck = false;
    this.sclPulsesWhileStuck = 0;
    this.stats = { transactions: 0, nacks: 0, arbitrationLost: 0, bytes: 0, busyNanos: 0, stuckEvents: 0, stuckReleases: 0 };
    // Pull-ups: both lines idle high.
    this.sdaPin.setInputValue(true);
    this.sclPin.setInputValue(true);
    let lastScl = this.sclPin.value;
    this.sclPin.addListener((value) => {
      const low = value === 0; // GPIOPinState.Low
      const wasLow = lastScl === 0;
      lastScl = value;
      if (this.stuck && wasLow && !low) {
        this.sclPulsesWhileStuck++;
        if (this.sclPulsesWhileStuck >= 9) this.releaseStuck();
      }
    });
    const c = this.i2c;
    c.onStart = (repeated) => this.onStart(repeated);
    c.onConnect = (addr, mode) => this.onConnect(addr, mode);
    c.onWriteByte = (v) => this.onWriteByte(v);
    c.onReadByte = (ack) => this.onReadByte(ack);
    c.onStop = () => this.onStop();
  }

  attach(address, device) {
    this.devices.set(address, device);
    return device;
  }

  /** SCL period in ns from the controller's fast-mode counts. */
  get bitNanos() {
    const h = this.i2c.fsClockHighPeriod;
    const l = this.i2c.fsClockLowPeriod;
    const clk = this.mcu.clkSys || 125e6;
    const ns = ((h + l) * 1e9) / clk;
    return ns > 100 ? ns : 2500;
  }

  after(bits, f) {
    const ns = bits * this.bitNanos;
    this.stats.busyNanos += ns;
    if (this.instant) {
      f();
      return;
    }
    this.pending = f;
    this.alarm.schedule(ns);
  }

  /** NACK the next `count` address phases to `address`. */
  injectNacks(address, count) {
    this.nackBudget.set(address, (this.nackBudget.get(address) ?? 0) + count);
  }

  /** SDA held low by a slave until 9 SCL pulses are clocked through GPIO (bus recovery). */
  injectStuckBus() {
    this.stuck = true;
    this.sclPulsesWhileStuck = 0;
    this.stats.stuckEvents++;
    this.sdaPin.setInputValue(false);
  }

  releaseStuck() {
    this.stuck = false;
    this.stats.stuckReleases++;
    this.sdaPin.setInputValue(true);
  }

  onStart(repeated) {
    if (this.stuck) {
      // A master cannot drive START on a bus whose SDA is held low: the DW_apb_i2c reports it
      // as arbitration lost (ABRT_ARB_LOST).
      this.stats.arbitrationLost++;
      this.after(1, () => this.i2c.arbitrationLost());
      return;
    }
    if (repeated && this.current) this.current.device?.stop?.(true);
    this.after(1, () => this.i2c.completeStart());
  }

  onConnect(addr, mode) {
    this.stats.transactions++;
    const device = this.devices.get(addr);
    let ack = !!device && device.present(this.mcu.clock.nanos);
    const budget = this.nackBudget.get(addr) ?? 0;
    if (ack && budget > 0) {
      this.nackBudget.set(addr, budget - 1);
      ack = false;
    }
    if (!ack) this.stats.nacks++;
    this.current = ack ? { device, mode } : null;
    if (ack) device.start(mode === 1 ? 'read' : 'write', this.mcu.clock.nanos);
    this.after(9, () => this.i2c.completeConnect(ack));
  }

  onWriteByte(v) {
    this.stats.bytes++;
    const ack = this.current ? this.current.device.write(v, this.mcu.clock.nanos) !== false : false;
    this.after(9, () => this.i2c.completeWrite(ack));
  }

  onReadByte() {
    this.stats.bytes++;
    const v = this.current ? this.current.device.read(this.mcu.clock.nanos) & 0xff : 0xff;
    this.after(9, () => this.i2c.completeRead(v));
  }

  onStop() {
    if (this.current) this.current.device.stop(false, this.mcu.clock.nanos);
    this.current = null;
    this.after(1, () => this.i2c.completeStop());
  }
}

/** Base for register-file devices: first written byte sets the register pointer. */
export class RegisterDevice {
  constructor() {
    this.pointer = 0;
    this.firstWrite = false;
    this.absentFrom = null;
    this.absentUntil = null;
  }

  /** The device does not answer (NACKs its address) between `from` and `until` ns. */
  vanish(fromNanos, untilNanos) {
    this.absentFrom = fromNanos;
    this.absentUntil = untilNanos;
  }

  present(nanos) {
    if (this.absentFrom === null || nanos < this.absentFrom) return true;
    if (nanos < this.absentUntil) return false;
    // Back: it was unpowered, so it comes back from power-on reset.
    this.absentFrom = this.absentUntil = null;
    this.powerOnReset(nanos);
    return true;
  }

  powerOnReset() {}

  start(mode) {
    if (mode === 'write') this.firstWrite = true;
  }

  write(v, nanos) {
    if (this.firstWrite) {
      this.firstWrite = false;
      this.pointer = v;
      return true;
    }
    this.writeRegister(this.pointer, v, nanos);
    this.pointer = this.nextPointer(this.pointer);
    return true;
  }

  read(nanos) {
    const v = this.readRegister(this.pointer, nanos);
    this.pointer = this.nextPointer(this.pointer);
    return v;
  }

  nextPointer(p) {
    return (p + 1) & 0xff;
  }

  stop() {}
}
