import { test } from 'node:test';
import assert from 'node:assert/strict';
import { RP2040 } from 'rp2040js';
import { I2cBus } from '../src/devices/i2c-bus.js';
import { Mpu6050 } from '../src/devices/mpu6050.js';
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

test('a power cycle leaves a hole in the sample index (the host replay sees a gap)', () => {
  const { mcu, mpu } = board();
  const wake = () => {
    mcu.writeUint32(I2C0 + IC_DATA_CMD, 0x6b);
    mcu.writeUint32(I2C0 + IC_DATA_CMD, 0x01 | 0x200);
    mcu.clock.tick(1e6);
  };
  wake();
  mcu.clock.tick(10e6);
  readWhoAmI(mcu); // advances the model: samples k = 0.. produced
  const before = mpu.stats.produced;
  assert.ok(before >= 10);
  mpu.vanish(mcu.clock.nanos, mcu.clock.nanos + 1e6);
  mcu.clock.tick(2e6);
  readWhoAmI(mcu); // back from reset, asleep
  wake();
  mcu.clock.tick(3e6);
  readWhoAmI(mcu);
  const first = mpu.samples.find((s) => s.t > mcu.clock.nanos - 5e6 && s.k >= before);
  assert.equal(first.k, before + 1);
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
