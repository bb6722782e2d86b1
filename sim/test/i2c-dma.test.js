import { test } from 'node:test';
import assert from 'node:assert/strict';
import { RP2040 } from 'rp2040js';
import { I2cBus } from '../src/devices/i2c-bus.js';
import { Mpu6050 } from '../src/devices/mpu6050.js';
import { patchSevLogger, patchI2cInterruptMask, patchI2cDreq } from '../src/patches.js';
import { constantStream } from './helpers.js';

const I2C0 = 0x40044000;
const IC_DATA_CMD = 0x10, IC_ENABLE = 0x6c, IC_TAR = 0x04, IC_RAW_INTR_STAT = 0x34, IC_TXFLR = 0x74;
const IC_CLR_TX_ABRT = 0x54, IC_DMA_CR = 0x88, IC_DMA_TDLR = 0x8c, IC_DMA_RDLR = 0x90;
const DMA = 0x50000000;
const CH = (n) => DMA + n * 0x40; // READ_ADDR +0, WRITE_ADDR +4, TRANS_COUNT +8, CTRL_TRIG +0xc
const RAM = 0x20000000;
const CMDS = RAM + 0x1000;
const BUF = RAM + 0x2000;

function board({ patched = true } = {}) {
  const mcu = new RP2040();
  patchSevLogger(mcu, () => {});
  patchI2cInterruptMask(mcu);
  if (patched) patchI2cDreq(mcu);
  const bus = new I2cBus(mcu);
  bus.attach(0x68, new Mpu6050(constantStream({})));
  mcu.writeUint32(I2C0 + IC_TAR, 0x68);
  mcu.writeUint32(I2C0 + IC_ENABLE, 1);
  return { mcu, bus };
}

/** CTRL: EN, data size (0 byte, 2 word), INCR_READ/INCR_WRITE, CHAIN_TO itself, TREQ_SEL. */
function ctrl(ch, size, incrRead, incrWrite, treq) {
  return 1 | (size << 2) | (incrRead ? 1 << 4 : 0) | (incrWrite ? 1 << 5 : 0) | (ch << 11) | (treq << 15);
}

/**
 * A register read done by two DMA channels: channel 0 feeds the command words (register address
 * as a write, n reads: RESTART on the first, STOP on the last) to IC_DATA_CMD paced by
 * DREQ_I2C0_TX; channel 1 drains IC_DATA_CMD into BUF paced by DREQ_I2C0_RX.
 */
function dmaRead(mcu, reg, n) {
  const words = [reg];
  for (let i = 0; i < n; i++) words.push(0x100 | (i === 0 ? 0x400 : 0) | (i === n - 1 ? 0x200 : 0));
  words.forEach((w, i) => mcu.writeUint32(CMDS + 4 * i, w));
  for (let i = 0; i < n; i++) mcu.writeUint8(BUF + i, 0xee);
  mcu.writeUint32(I2C0 + IC_DMA_TDLR, 4);
  mcu.writeUint32(I2C0 + IC_DMA_RDLR, 0);
  mcu.writeUint32(I2C0 + IC_DMA_CR, 3);
  mcu.writeUint32(CH(1) + 0, I2C0 + IC_DATA_CMD);
  mcu.writeUint32(CH(1) + 4, BUF);
  mcu.writeUint32(CH(1) + 8, n);
  mcu.writeUint32(CH(1) + 0xc, ctrl(1, 0, false, true, 33));
  mcu.writeUint32(CH(0) + 0, CMDS);
  mcu.writeUint32(CH(0) + 4, I2C0 + IC_DATA_CMD);
  mcu.writeUint32(CH(0) + 8, words.length);
  mcu.writeUint32(CH(0) + 0xc, ctrl(0, 2, true, false, 32));
  mcu.clock.tick(5e6);
  return Array.from({ length: n }, (_, i) => mcu.readUint8(BUF + i));
}

const busy = (mcu, ch) => !!(mcu.readUint32(CH(ch) + 0xc) & (1 << 24));

test('I2C DMA: a 20-byte register read (more than a FIFO) runs with DREQ_I2C0_TX/RX, at bus speed', () => {
  const { mcu, bus } = board();
  assert.equal(mcu.readUint32(I2C0 + IC_DMA_CR), 0, 'IC_DMA_CR reads 0 before use');
  const got = dmaRead(mcu, 0x5f, 20); // 0x5f..0x72: stops before FIFO_R_W (0x74), which does not advance
  assert.equal(busy(mcu, 0), false, 'TX channel done');
  assert.equal(busy(mcu, 1), false, 'RX channel done');
  assert.equal(got[0x6b - 0x5f], 0x40, 'PWR_MGMT_1 reset value');
  assert.equal(got[19], 0, 'FIFO_COUNTH');
  assert.ok(got.every((b) => b !== 0xee), 'every byte written by the RX channel');
  assert.ok(mcu.readUint32(I2C0 + IC_RAW_INTR_STAT) & (1 << 9), 'STOP_DET');
  // START + addr + reg + RESTART + addr + 20 data bytes + STOP
  assert.equal(bus.stats.busyNanos, (1 + 9 + 9 + 1 + 9 + 20 * 9 + 1) * bus.bitNanos);
  assert.equal(mcu.readUint32(I2C0 + IC_DMA_CR), 3);
  assert.equal(mcu.readUint32(I2C0 + IC_DMA_TDLR), 4);
});

test('I2C DMA: without the patch no DREQ is raised and the channels never move', () => {
  const { mcu } = board({ patched: false });
  const got = dmaRead(mcu, 0x75, 1);
  assert.equal(got[0], 0xee);
  assert.equal(busy(mcu, 0), true);
  assert.equal(busy(mcu, 1), true);
});

test('I2C DMA: a NACK aborts; the TX FIFO stays flushed until TX_ABRT is cleared (no second transfer)', () => {
  const { mcu, bus } = board();
  bus.injectNacks(0x68, 1);
  const got = dmaRead(mcu, 0x75, 3);
  assert.ok(mcu.readUint32(I2C0 + IC_RAW_INTR_STAT) & (1 << 6), 'TX_ABRT');
  assert.equal(bus.stats.transactions, 1, 'the commands the DMA wrote after the abort were dropped');
  assert.equal(mcu.readUint32(I2C0 + IC_TXFLR), 0);
  assert.equal(busy(mcu, 0), false, 'TX channel ran out (its writes were dropped)');
  assert.equal(busy(mcu, 1), true, 'RX channel still waiting: the firmware must abort it');
  assert.deepEqual(got, [0xee, 0xee, 0xee]);
  mcu.writeUint32(DMA + 0x444, 2); // CHAN_ABORT channel 1
  mcu.readUint32(I2C0 + IC_CLR_TX_ABRT);
  assert.equal(mcu.readUint32(I2C0 + IC_RAW_INTR_STAT) & (1 << 6), 0);
  assert.deepEqual(dmaRead(mcu, 0x75, 1), [0x68], 'the next transfer works');
});
