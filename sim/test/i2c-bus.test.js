import { test } from 'node:test';
import assert from 'node:assert/strict';
import { RP2040 } from 'rp2040js';
import { I2cBus } from '../src/devices/i2c-bus.js';
import { Mpu6050, REG } from '../src/devices/mpu6050.js';
import { parseFault, parseClock } from '../src/session.js';
import { patchSevLogger, patchI2cInterruptMask } from '../src/patches.js';
import { constantStream } from './helpers.js';

const I2C0 = 0x40044000;
const IC_DATA_CMD = 0x10, IC_ENABLE = 0x6c, IC_TAR = 0x04, IC_RAW_INTR_STAT = 0x34, IC_TX_ABRT_SOURCE = 0x80, IC_RXFLR = 0x78;
const IC_INTR_MASK = 0x30, IC_INTR_STAT = 0x2c;

function board() {
  const mcu = new RP2040();
  patchSevLogger(mcu, () => {});
  patchI2cInterruptMask(mcu);
  const bus = new I2cBus(mcu);
  const mpu = bus.attach(0x68, new Mpu6050(constantStream({})));
  mcu.writeUint32(I2C0 + IC_ENABLE, 1);
  mcu.writeUint32(I2C0 + IC_TAR, 0x68);
  return { mcu, bus, mpu };
}

/** write [0x75] then repeated-start read 1 byte with STOP, then let bus time pass. */
function readWhoAmI(mcu) {
  mcu.writeUint32(I2C0 + IC_DATA_CMD, 0x75);
  mcu.writeUint32(I2C0 + IC_DATA_CMD, 0x100 | 0x200 | 0x400);
  mcu.clock.tick(1e6);
}

test('a read transaction takes bus time and returns WHO_AM_I', () => {
  const { mcu, bus } = board();
  readWhoAmI(mcu);
  assert.equal(mcu.readUint32(I2C0 + IC_RXFLR), 1);
  assert.equal(mcu.readUint32(I2C0 + IC_DATA_CMD) & 0xff, 0x68);
  // START + address + reg byte + RESTART + address + data byte + STOP = 1+9+9+1+9+9+1 = 39 SCL periods
  assert.equal(bus.stats.busyNanos, 39 * bus.bitNanos);
});

test('injected NACKs abort with ABRT_7B_ADDR_NOACK, then the device answers again', () => {
  const { mcu, bus } = board();
  bus.injectNacks(0x68, 1);
  readWhoAmI(mcu);
  assert.ok(mcu.readUint32(I2C0 + IC_RAW_INTR_STAT) & (1 << 6), 'TX_ABRT raised');
  assert.equal(mcu.readUint32(I2C0 + IC_TX_ABRT_SOURCE) & 1, 1);
  assert.equal(bus.stats.nacks, 1);
  readWhoAmI(mcu);
  assert.equal(mcu.readUint32(I2C0 + IC_DATA_CMD) & 0xff, 0x68);
});

test('the IC_INTR_MASK patch makes a masked-in interrupt visible in IC_INTR_STAT', () => {
  const { mcu } = board();
  mcu.writeUint32(I2C0 + IC_INTR_MASK, 1 << 9); // STOP_DET
  readWhoAmI(mcu);
  assert.equal(mcu.readUint32(I2C0 + IC_INTR_STAT), 1 << 9);
});

test('a vanished sensor NACKs for its window and comes back reset (asleep)', () => {
  const { mcu, bus, mpu } = board();
  mpu.vanish(0, 2e9);
  readWhoAmI(mcu);
  assert.equal(bus.stats.nacks, 1);
  mcu.clock.tick(2e9);
  readWhoAmI(mcu);
  assert.equal(mcu.readUint32(I2C0 + IC_DATA_CMD) & 0xff, 0x68);
  assert.equal(mpu.stats.resets, 2);
});

test('a power cycle: nothing is produced while unpowered; a restart in step with the old grid keeps its slots', () => {
  const { mcu, mpu } = board();
  // CONFIG = 1 (1 kHz) while asleep, then wake: the sample clock starts one period later.
  const wake = () => {
    mcu.writeUint32(I2C0 + IC_DATA_CMD, 0x1a);
    mcu.writeUint32(I2C0 + IC_DATA_CMD, 0x01 | 0x200);
    mcu.clock.tick(0.2e6);
    mcu.writeUint32(I2C0 + IC_DATA_CMD, 0x6b);
    mcu.writeUint32(I2C0 + IC_DATA_CMD, 0x01 | 0x200);
  };
  wake();
  mcu.clock.tick(10e6);
  readWhoAmI(mcu); // advances the model
  const before = mpu.stats.produced;
  assert.ok(before >= 10);
  const last = mpu.samples[mpu.samples.length - 1];
  assert.equal(last.slot, last.k, 'an uninterrupted run: one slot a sample');
  mpu.vanish(mcu.clock.nanos, mcu.clock.nanos + 5e6);
  mcu.clock.tick(20e6);
  readWhoAmI(mcu); // back from reset, asleep: nothing produced while away
  assert.equal(mpu.stats.produced, before);
  // Wake so that the first new sample lands on the old grid, 30 periods after the last one.
  const target = last.t + 30e6 - 1e6;
  mcu.clock.tick(target - mcu.clock.nanos - 0.2e6 - 19 * bus_bit(mcu));
  wake();
  mcu.clock.tick(3e6);
  readWhoAmI(mcu);
  const first = mpu.samples.find((s) => s.k === before);
  assert.ok(Math.abs(first.t - (last.t + 30e6)) < 0.1e6, `first new sample at ${first.t} ns`);
  assert.equal(first.slot, last.slot + 30);
});

function bus_bit(mcu) {
  const c = mcu.i2c[0];
  const ns = ((c.fsClockHighPeriod + c.fsClockLowPeriod) * 1e9) / (mcu.clkSys || 125e6);
  return ns > 100 ? ns : 2500;
}

test('a NACK window NACKs every address phase for its duration, then the device answers', () => {
  const { mcu, bus } = board();
  bus.injectNackWindow(0x68, 3e6);
  readWhoAmI(mcu);
  readWhoAmI(mcu);
  assert.equal(bus.stats.nacks, 2);
  mcu.clock.tick(2e6);
  readWhoAmI(mcu);
  assert.equal(bus.stats.nacks, 2);
  assert.equal(mcu.readUint32(I2C0 + IC_DATA_CMD) & 0xff, 0x68);
});

test('a stall: the clock runs on but no sample is produced in the window', () => {
  const { mcu, mpu } = board();
  mcu.writeUint32(I2C0 + IC_DATA_CMD, 0x1a);
  mcu.writeUint32(I2C0 + IC_DATA_CMD, 0x01 | 0x200);
  mcu.clock.tick(0.2e6);
  mcu.writeUint32(I2C0 + IC_DATA_CMD, 0x6b);
  mcu.writeUint32(I2C0 + IC_DATA_CMD, 0x01 | 0x200);
  mcu.clock.tick(10.5e6);
  mpu.stall(mcu.clock.nanos, mcu.clock.nanos + 5e6);
  mcu.clock.tick(10e6);
  readWhoAmI(mcu);
  const slots = mpu.samples.map((s) => s.slot);
  assert.equal(mpu.stats.stalledSlots, 5);
  assert.equal(slots.length, slots[slots.length - 1] + 1 - 5);
  const jump = slots.findIndex((v, i) => i > 0 && v !== slots[i - 1] + 1);
  assert.equal(slots[jump] - slots[jump - 1], 6);
});

test('a slow clock stretches the sample period', () => {
  const m = new Mpu6050(constantStream({}), { clockError: -0.013 });
  m.regs[REG.CONFIG] = 1;
  assert.ok(Math.abs(m.samplePeriodNanos - 1e6 / 0.987) < 1e-6);
});

test('stuck bus: START loses arbitration until 9 SCL pulses are clocked on GP5 by SIO', () => {
  const { mcu, bus } = board();
  bus.injectStuckBus();
  readWhoAmI(mcu);
  assert.ok(mcu.readUint32(I2C0 + IC_TX_ABRT_SOURCE) & (1 << 12), 'ARB_LOST');
  assert.equal(mcu.gpio[4].rawInputValue, false, 'SDA reads low');
  // GP5 to SIO (FUNCSEL 5), output enabled, toggled 8 times: still stuck.
  mcu.writeUint32(0x40014000 + 8 * 5 + 4, 5);
  mcu.writeUint32(0xd0000024, 1 << 5); // GPIO_OE_SET
  const pulse = () => {
    mcu.writeUint32(0xd0000018, 1 << 5); // OUT_CLR
    mcu.writeUint32(0xd0000014, 1 << 5); // OUT_SET
  };
  for (let i = 0; i < 8; i++) pulse();
  assert.equal(bus.stuck, true);
  pulse();
  assert.equal(bus.stuck, false);
  assert.equal(mcu.gpio[4].rawInputValue, true);
  assert.equal(bus.stats.stuckReleases, 1);
});

test('stuck for a duration: clocking does not free SDA before the time is up', () => {
  const { mcu, bus } = board();
  bus.injectStuckBus({ nanos: 50e6 });
  mcu.writeUint32(0x40014000 + 8 * 5 + 4, 5);
  mcu.writeUint32(0xd0000024, 1 << 5);
  for (let i = 0; i < 9; i++) {
    mcu.writeUint32(0xd0000018, 1 << 5);
    mcu.writeUint32(0xd0000014, 1 << 5);
  }
  assert.equal(bus.stuck, true);
  mcu.clock.tick(50e6);
  assert.equal(bus.stuck, false);
  assert.equal(mcu.gpio[4].rawInputValue, true);
});

test('a hung START waits for the bus and goes ahead when SDA is let go; a controller reset drops it', () => {
  const { mcu, bus } = board();
  bus.injectStuckBus({ nanos: 10e6, hang: true });
  mcu.writeUint32(I2C0 + IC_DATA_CMD, 0x75);
  mcu.writeUint32(I2C0 + IC_DATA_CMD, 0x100 | 0x200 | 0x400);
  mcu.clock.tick(5e6);
  assert.equal(mcu.readUint32(I2C0 + IC_RXFLR), 0, 'nothing yet');
  assert.equal(mcu.readUint32(I2C0 + IC_TX_ABRT_SOURCE), 0, 'no abort either');
  mcu.clock.tick(6e6);
  assert.equal(mcu.readUint32(I2C0 + IC_DATA_CMD) & 0xff, 0x68);
  // Again, but the firmware gives up and resets the block through RESETS (I2C0 = bit 3).
  bus.injectStuckBus({ nanos: 10e6, hang: true });
  readWhoAmI(mcu);
  assert.equal(bus.hangPending, true);
  mcu.writeUint32(0x4000c000 + 0x2000, 1 << 3); // RESETS set alias
  assert.equal(bus.hangPending, false);
  assert.equal(mcu.i2c[0].busy, false);
});

test('fault and clock specs parse, and bad ones are refused with the reason', () => {
  assert.equal(parseFault('nack:mpu@3s:30ms').duration, 30e6);
  assert.equal(parseFault('nack:mpu@3s:4').count, 4);
  assert.equal(parseFault('stall:qmc@0s').duration, undefined);
  assert.equal(parseFault('hang@3s:50ms').kind, 'hang');
  assert.throws(() => parseFault('hang@3s'), /how long/);
  assert.throws(() => parseFault('stuck:mpu@3s'), /bus or CPU fault/);
  assert.throws(() => parseFault('nack:mpu@3s:0'), /positive/);
  const c = parseClock('mpu:-1.3%,qmc:+0.5%');
  assert.ok(Math.abs(c.mpu + 0.013) < 1e-15 && Math.abs(c.qmc - 0.005) < 1e-15, JSON.stringify(c));
  assert.throws(() => parseClock('mpu:-30%'), /not a crystal/);
});
