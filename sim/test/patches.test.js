import { test } from 'node:test';
import assert from 'node:assert/strict';
import { RP2040 } from 'rp2040js';
import { patchXipCtrl, patchDmaAbort, patchSevLogger } from '../src/patches.js';

test('XIP streaming: STREAM_ADDR/CTR stream flash words through STREAM_FIFO and XIP_AUX', () => {
  const mcu = new RP2040();
  patchSevLogger(mcu, () => {});
  patchXipCtrl(mcu);
  mcu.flashView.setUint32(0x1000, 0x11223344, true);
  mcu.flashView.setUint32(0x1004, 0x55667788, true);
  mcu.flashView.setUint32(0x1008, 0x99aabbcc, true);
  const XIP = 0x14000000;
  assert.equal(mcu.readUint32(XIP + 0x08) & 2, 2, 'FIFO_EMPTY while idle');
  mcu.writeUint32(XIP + 0x14, 0x10001000);
  mcu.writeUint32(XIP + 0x18, 3);
  assert.equal(mcu.readUint32(XIP + 0x08) & 2, 0);
  assert.equal(mcu.dma.dreq[37], true, 'DREQ_XIP_STREAM asserted');
  assert.equal(mcu.readUint32(XIP + 0x1c), 0x11223344);
  assert.equal(mcu.readUint32(0x50400000), 0x55667788);
  assert.equal(mcu.readUint32(XIP + 0x18), 1);
  assert.equal(mcu.readUint32(0x50400000) >>> 0, 0x99aabbcc);
  assert.equal(mcu.dma.dreq[37], false, 'DREQ dropped when the stream is done');
  assert.equal(mcu.readUint32(XIP + 0x08) & 2, 2);
});

test('DMA CHAN_ABORT reads 0 after an abort (rp2040js aborts synchronously)', () => {
  const mcu = new RP2040();
  patchSevLogger(mcu, () => {});
  const before = mcu.readUint32(0x50000444) >>> 0;
  assert.equal(before, 0xffffffff, 'unpatched: unimplemented read');
  patchDmaAbort(mcu);
  mcu.writeUint32(0x50000444, 1);
  assert.equal(mcu.readUint32(0x50000444), 0);
});
