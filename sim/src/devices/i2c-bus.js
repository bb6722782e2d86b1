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
    this.nackUntil = new Map(); // address -> ns until which every address phase is NACKed
    this.stuck = false;
    this.stuckUntil = null; // ns: SDA held regardless of clocking until then (null: until 9 pulses)
    this.hang = false; // a START waits (does not lose arbitration) while SDA is held
    this.hangPending = false; // a START is waiting for the bus
    this.sclPulsesWhileStuck = 0;
    this.stats = { transactions: 0, nacks: 0, arbitrationLost: 0, hungStarts: 0, bytes: 0, busyNanos: 0, stuckEvents: 0, stuckReleases: 0 };
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
        if (this.sclPulsesWhileStuck >= 9 && this.stuckUntil === null) this.releaseStuck();
      }
    });
    this.patchControllerReset();
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

  /** NACK every address phase to `address` for the next `nanos` ns. */
  injectNackWindow(address, nanos) {
    this.nackUntil.set(address, this.mcu.clock.nanos + nanos);
  }

  /**
   * A slave holds SDA low. Without `nanos`, until 9 SCL pulses are clocked through GPIO (bus
   * recovery, UM10204 §3.1.16); with `nanos`, for that long whatever is clocked. `hang`: a
   * START waits for the bus to be free (silicon's behaviour on a busy bus) instead of losing
   * arbitration at once, so the transfer hangs until the firmware gives up on it.
   */
  injectStuckBus({ nanos = null, hang = false } = {}) {
    this.stuck = true;
    this.hang = hang;
    this.sclPulsesWhileStuck = 0;
    this.stats.stuckEvents++;
    this.sdaPin.setInputValue(false);
    this.stuckUntil = null;
    if (nanos !== null) {
      this.stuckUntil = this.mcu.clock.nanos + nanos;
      const alarm = this.mcu.clock.createAlarm(() => this.releaseStuck());
      alarm.schedule(nanos);
    }
  }

  releaseStuck() {
    if (!this.stuck) return;
    this.stuck = false;
    this.hang = false;
    this.stuckUntil = null;
    this.stats.stuckReleases++;
    this.sdaPin.setInputValue(true);
    if (this.hangPending) {
      // The waiting START goes ahead now that the bus is free.
      this.hangPending = false;
      this.after(1, () => this.i2c.completeStart());
    }
  }

  /**
   * rp2040js does not reset a peripheral through RESETS (RP2040 datasheet §2.14): a controller
   * left waiting on a START would stay busy for ever after the firmware re-creates it. Setting
   * the I2C0/I2C1 reset bit puts the controller back in its idle state and drops its FIFOs.
   */
  patchControllerReset() {
    const resets = this.mcu.findPeripheral(0x4000c000); // RESETS
    if (!resets || resets.__i2cResetPatched) return;
    resets.__i2cResetPatched = true;
    const bit = 1 << (3 + (this.i2c === this.mcu.i2c[1] ? 1 : 0));
    const write = resets.writeUint32.bind(resets);
    resets.writeUint32 = (offset, value) => {
      if (offset === 0 && value & bit && !(resets.reset & bit)) {
        const c = this.i2c;
        c.state = 0; // I2CState.Idle
        c.busy = false;
        c.stop = false;
        c.pendingRestart = false;
        c.txFIFO.reset();
        c.rxFIFO.reset();
        c.abortSource = 0;
        c.intRaw = 0;
        c.checkInterrupts();
        this.hangPending = false;
        this.pending = null;
      }
      write(offset, value);
    };
  }

  onStart(repeated) {
    if (this.stuck && this.hang) {
      // The START waits for a free bus: nothing completes until the slave lets go.
      this.stats.hungStarts++;
      this.hangPending = true;
      return;
    }
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
    const now = this.mcu.clock.nanos;
    let ack = !!device && device.present(now);
    const budget = this.nackBudget.get(addr) ?? 0;
    if (ack && budget > 0) {
      this.nackBudget.set(addr, budget - 1);
      ack = false;
    }
    if (ack && now < (this.nackUntil.get(addr) ?? 0)) ack = false;
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

  /**
   * The device loses power between `from` and `until` ns: it NACKs its address, produces
   * nothing, and comes back from power-on reset. Call at `from` (it produces what was due up to
   * then first).
   */
  vanish(fromNanos, untilNanos) {
    this.advance?.(fromNanos);
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
