// Reads SEGGER RTT up-channel 0 from emulated RAM. Control block layout (SEGGER RTT, as used by
// defmt-rtt): char acID[16]; int MaxNumUpBuffers @16; int MaxNumDownBuffers @20; up buffer 0 @24:
// sName @+0, pBuffer @+4, SizeOfBuffer @+8, WrOff @+12, RdOff @+16, Flags @+20.

export class RttReader {
  constructor(mcu, controlBlock) {
    this.mcu = mcu;
    this.cb = controlBlock;
    this.bytes = 0;
  }

  /** Copies new bytes out of the up buffer and advances RdOff, like a debug probe does. */
  poll() {
    const { mcu, cb } = this;
    const up = cb + 24;
    const buf = mcu.readUint32(up + 4);
    const size = mcu.readUint32(up + 8);
    if (!buf || !size || size > 0x40000) return null; // not initialised yet
    const wr = mcu.readUint32(up + 12);
    let rd = mcu.readUint32(up + 16);
    if (wr === rd || wr >= size || rd >= size) return null;
    const out = [];
    while (rd !== wr) {
      out.push(mcu.readUint8(buf + rd));
      rd = rd + 1 === size ? 0 : rd + 1;
    }
    mcu.writeUint32(up + 16, rd);
    this.bytes += out.length;
    return Uint8Array.from(out);
  }
}
