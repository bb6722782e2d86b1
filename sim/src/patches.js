// Run-time patches for rp2040js 1.4.1 (see docs/emulator.md, "Emulator bugs patched at run time").
// Each patch is applied to one RP2040 instance; nothing in node_modules is modified.

import { BasePeripheral } from 'rp2040js';

const IC_INTR_MASK = 0x30;
const USB_BUF_CTRL_AVAILABLE = 1 << 10;
const USB_BUF_CTRL_FULL = 1 << 15;
const USB_BUF_CTRL_LEN_MASK = 0x3ff;
const EP0_IN_BUFFER_CONTROL = 0x80;
const EP15_OUT_BUFFER_CONTROL = 0xfc;

/** Bug 1: I2C ignores writes to IC_INTR_MASK, so the I2C IRQ never fires and async I2C deadlocks. */
export function patchI2cInterruptMask(mcu) {
  for (const i2c of mcu.i2c) {
    const write = i2c.writeUint32.bind(i2c);
    i2c.writeUint32 = (offset, value) => {
      if (offset === IC_INTR_MASK) {
        i2c.intEnable = value & 0x1fff;
        i2c.checkInterrupts();
        return;
      }
      write(offset, value);
    };
  }
}

/**
 * Bug 2: SEV only logs "SEV". The logger installed here turns that message into the event
 * register being set (ARMv6-M ARM B1.5.18: SEV sets the event register of the executing core).
 * Other messages go to `sink(level, component, message)`.
 */
export function patchSevLogger(mcu, sink) {
  const core = mcu.core;
  mcu.logger = {
    debug() {},
    info(component, message) {
      if (message === 'SEV') {
        core.eventRegistered = true;
        return;
      }
      if (message === 'Yield') return;
      sink('info', component, message);
    },
    warn(component, message) {
      sink('warn', component, message);
    },
    error(component, message) {
      sink('error', component, message);
    },
  };
}

/**
 * Bug 3: rp2040js clears AVAILABLE as soon as firmware arms an OUT buffer and its host helper
 * answers every arm with a zero-length packet. With this patch an armed OUT endpoint (>= 1) stays
 * AVAILABLE (the host NAKs) until `UsbOutQueue.push` has data for it.
 */
export class UsbOutQueue {
  constructor(mcu, delayNanos = 10_000) {
    this.mcu = mcu;
    this.usb = mcu.usbCtrl;
    this.armed = new Map(); // endpoint -> requested length
    this.pending = new Map(); // endpoint -> array of byte arrays
    this.delayNanos = delayNanos;
    this.deliveries = 0;
    const original = this.usb.DPRAMUpdated.bind(this.usb);
    this.usb.DPRAMUpdated = (offset, value) => {
      if (
        !this.usb.hostMode &&
        value & USB_BUF_CTRL_AVAILABLE &&
        offset >= EP0_IN_BUFFER_CONTROL + 8 &&
        offset <= EP15_OUT_BUFFER_CONTROL &&
        offset & 4
      ) {
        const endpoint = (offset - EP0_IN_BUFFER_CONTROL) >> 3;
        this.armed.set(endpoint, value & USB_BUF_CTRL_LEN_MASK);
        this.tryDeliver(endpoint);
        return;
      }
      original(offset, value);
    };
    this.alarm = mcu.clock.createAlarm(() => this.deliverDue());
    this.due = [];
  }

  /** Bytes the host sends to OUT endpoint `endpoint`. */
  push(endpoint, bytes) {
    if (!bytes.length) return;
    const q = this.pending.get(endpoint) ?? [];
    q.push(Uint8Array.from(bytes));
    this.pending.set(endpoint, q);
    this.tryDeliver(endpoint);
  }

  queuedBytes(endpoint) {
    return (this.pending.get(endpoint) ?? []).reduce((n, b) => n + b.length, 0);
  }

  tryDeliver(endpoint) {
    const q = this.pending.get(endpoint);
    if (!q || !q.length || !this.armed.has(endpoint)) return;
    if (this.due.includes(endpoint)) return;
    this.due.push(endpoint);
    // (rp2040js never clears ClockAlarm.scheduled after firing: track it ourselves.)
    if (this.due.length === 1) this.alarm.schedule(this.delayNanos);
  }

  deliverDue() {
    const due = this.due;
    this.due = [];
    for (const endpoint of due) {
      const q = this.pending.get(endpoint);
      const max = this.armed.get(endpoint);
      if (!q || !q.length || max === undefined) continue;
      // One USB packet: up to `max` bytes gathered from the queue.
      const packet = [];
      while (q.length && packet.length < max) {
        const head = q[0];
        const take = Math.min(head.length, max - packet.length);
        for (let i = 0; i < take; i++) packet.push(head[i]);
        if (take === head.length) q.shift();
        else q[0] = head.subarray(take);
      }
      this.armed.delete(endpoint);
      const dv = this.mcu.usbDPRAMView;
      const ctrlOffset = EP0_IN_BUFFER_CONTROL + endpoint * 8 + 4;
      const bufferOffset = this.usb.getEndpointBufferOffset(endpoint, true);
      this.mcu.usbDPRAM.set(packet, bufferOffset);
      let ctrl = dv.getUint32(ctrlOffset, true);
      ctrl &= ~(USB_BUF_CTRL_AVAILABLE | USB_BUF_CTRL_LEN_MASK);
      ctrl |= USB_BUF_CTRL_FULL | packet.length;
      dv.setUint32(ctrlOffset, ctrl, true);
      this.deliveries++;
      this.usb.indicateBufferReady(endpoint, true);
      if (q.length) this.tryDeliver(endpoint);
    }
  }
}

/**
 * Bug 4: XIP_CTRL (0x14000000) is unmapped, and embassy-rp's in-RAM flash routine and its async
 * `Flash::background_read` use it. This model implements the XIP streaming interface of RP2040
 * datasheet §2.6.3.4: STREAM_ADDR/STREAM_CTR start a stream of words from flash, read through
 * STREAM_FIFO or the XIP_AUX port (0x50400000) with DREQ_XIP_STREAM (37) asserted while words
 * remain. STAT reports FLUSH_READY and FIFO_EMPTY. The stream is instantaneous (no QSPI timing).
 */
export class XipCtrl extends BasePeripheral {
  constructor(mcu) {
    super(mcu, 'XIP_CTRL');
    this.mcu = mcu;
    this.ctrl = 0x3;
    this.streamAddr = 0;
    this.streamCtr = 0;
    this.words = 0;
  }

  pop() {
    if (this.streamCtr === 0) return 0;
    const off = (this.streamAddr - 0x10000000) >>> 0;
    const v = off + 3 < this.mcu.flash.length ? this.mcu.flashView.getUint32(off, true) : 0;
    this.streamAddr = (this.streamAddr + 4) >>> 0;
    this.streamCtr--;
    this.words++;
    if (this.streamCtr === 0) this.mcu.dma.clearDREQ(DREQ_XIP_STREAM);
    return v;
  }

  readUint32(offset) {
    switch (offset) {
      case 0x00:
        return this.ctrl;
      case 0x08:
        return 0x1 | (this.streamCtr === 0 ? 0x2 : 0);
      case 0x0c:
      case 0x10:
        return 0;
      case 0x14:
        return this.streamAddr;
      case 0x18:
        return this.streamCtr;
      case 0x1c:
        return this.pop();
      default:
        return 0;
    }
  }

  writeUint32(offset, value) {
    switch (offset) {
      case 0x00:
        this.ctrl = value;
        return;
      case 0x14:
        this.streamAddr = value & ~3;
        return;
      case 0x18:
        this.streamCtr = value & 0x3fffff;
        if (this.streamCtr) this.mcu.dma.setDREQ(DREQ_XIP_STREAM);
        else this.mcu.dma.clearDREQ(DREQ_XIP_STREAM);
        return;
      default:
    }
  }
}

const DREQ_XIP_STREAM = 37;

export function patchXipCtrl(mcu) {
  const xip = new XipCtrl(mcu);
  mcu.peripherals[(0x14000000 >>> 14) << 2] = xip;
  // XIP_AUX: the streaming FIFO seen from the DMA's bus port.
  mcu.peripherals[(0x50400000 >>> 14) << 2] = {
    readUint32: () => xip.pop(),
    writeUint32: () => {},
    writeUint32Atomic: () => {},
  };
  return xip;
}

/**
 * Bug 7 (found with the pico-imu firmware): DMA CHAN_ABORT (0x444) reads fall through to
 * "unimplemented" (0xFFFFFFFF), so embassy-rp's `Transfer` drop, which waits for the abort bits to
 * clear, spins forever. rp2040js aborts synchronously on the write, so the register reads 0.
 * FIFO_LEVELS (0x440) also reads 0 (the DMA has no FIFOs in the model).
 */
export function patchDmaAbort(mcu) {
  const dma = mcu.dma;
  const read = dma.readUint32.bind(dma);
  dma.readUint32 = (offset) => (offset === 0x444 || offset === 0x440 ? 0 : read(offset));
}

const IC_DATA_CMD = 0x10;
const IC_DMA_CR = 0x88;
const IC_DMA_TDLR = 0x8c;
const IC_DMA_RDLR = 0x90;
const IC_DMA_CR_RDMAE = 1 << 0;
const IC_DMA_CR_TDMAE = 1 << 1;
const IC_RAW_TX_ABRT = 1 << 6;
/** DREQ numbers of I2C0 TX/RX; I2C1's are the next two (RP2040 datasheet §2.5.3.1). */
const DREQ_I2C0_TX = 32;

/**
 * Bug 8 (found with the pico-imu firmware's DMA I2C path): rp2040js's I2C has no DMA interface.
 * IC_DMA_CR, IC_DMA_TDLR and IC_DMA_RDLR read as "unimplemented" and no DREQ is ever raised, so a
 * DMA channel paced by DREQ_I2Cn_TX/RX never moves. Modelled on RP2040 datasheet §4.3.9 and the
 * register descriptions of §4.3.17:
 * - TX DREQ (32 + 2n) is asserted while IC_DMA_CR.TDMAE is set and the TX FIFO level is
 *   ≤ IC_DMA_TDLR; RX DREQ (33 + 2n) while IC_DMA_CR.RDMAE is set and the RX FIFO level is
 *   > IC_DMA_RDLR. Both are re-evaluated on every FIFO push, pull and flush.
 * - After a transmit abort the TX FIFO "remains in this flushed state until the register
 *   IC_CLR_TX_ABRT is read" (IC_TX_ABRT_SOURCE, §4.3.17): writes to IC_DATA_CMD are dropped while
 *   TX_ABRT is raised, so a DMA channel still feeding commands cannot start a new transfer. The
 *   model would otherwise run them as a fresh transaction after the abort's STOP.
 * The bus timing of every byte is unchanged (the FIFOs drain at the device model's pace).
 */
export function patchI2cDreq(mcu) {
  mcu.i2c.forEach((i2c, index) => {
    const dreqTx = DREQ_I2C0_TX + 2 * index;
    const dreqRx = dreqTx + 1;
    const dma = mcu.dma;
    const state = { cr: 0, tdlr: 0, rdlr: 0 };
    const update = () => {
      const tx = state.cr & IC_DMA_CR_TDMAE && i2c.txFIFO.itemCount <= state.tdlr;
      const rx = state.cr & IC_DMA_CR_RDMAE && i2c.rxFIFO.itemCount > state.rdlr;
      if (tx) dma.setDREQ(dreqTx);
      else dma.clearDREQ(dreqTx);
      if (rx) dma.setDREQ(dreqRx);
      else dma.clearDREQ(dreqRx);
    };
    for (const fifo of [i2c.txFIFO, i2c.rxFIFO]) {
      for (const name of ['push', 'pull', 'reset']) {
        const original = fifo[name].bind(fifo);
        fifo[name] = (value) => {
          const r = original(value);
          update();
          return r;
        };
      }
    }
    const read = i2c.readUint32.bind(i2c);
    i2c.readUint32 = (offset) => {
      switch (offset) {
        case IC_DMA_CR:
          return state.cr;
        case IC_DMA_TDLR:
          return state.tdlr;
        case IC_DMA_RDLR:
          return state.rdlr;
        default:
          return read(offset);
      }
    };
    const write = i2c.writeUint32.bind(i2c);
    i2c.writeUint32 = (offset, value) => {
      switch (offset) {
        case IC_DMA_CR:
          state.cr = value & (IC_DMA_CR_TDMAE | IC_DMA_CR_RDMAE);
          update();
          return;
        case IC_DMA_TDLR:
          state.tdlr = value & 0xf;
          update();
          return;
        case IC_DMA_RDLR:
          state.rdlr = value & 0xf;
          update();
          return;
        case IC_DATA_CMD:
          if (i2c.intRaw & IC_RAW_TX_ABRT) return; // TX FIFO held flushed until TX_ABRT is cleared
          write(offset, value);
          return;
        default:
          write(offset, value);
      }
    };
    // (Reading IC_CLR_TX_ABRT or IC_CLR_INTR clears TX_ABRT in rp2040js itself.)
  });
}
