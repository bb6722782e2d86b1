// A tiny hand-written boot ROM image for the emulated RP2040. It is NOT the official bootrom:
// it only implements the ROM lookup ABI of RP2040 datasheet §2.8.3 ("Bootrom Contents": the
// 'M','u' magic at 0x10, version at 0x13, 16-bit pointers to the function table at 0x14, the data
// table at 0x16 and the lookup function at 0x18) so that embassy-rp's flash driver and
// `rom_data::*` calls find their functions. Every routine is two Thumb instructions,
// `bkpt #N; bx lr`: the breakpoint is a hypercall serviced in JavaScript (see hypercalls.js).

export const ROM_SIZE = 16 * 1024;
/** Hypercall number of the table lookup function (rom_table_lookup(table, code)). */
export const HC_LOOKUP = 0xf0;
const FUNC_TABLE = 0x100;
const DATA_TABLE = 0x180;
const LOOKUP_FN = 0x200;
const FUNCS_BASE = 0x210;
const DATA_BASE = 0x300;

/** ROM functions the stub implements, in hypercall-number order (hypercall N = index N). */
export const ROM_FUNCTIONS = ['IF', 'EX', 'RE', 'RP', 'FC', 'CX', 'C4', 'MC', 'MS', 'S4', 'P3', 'R3', 'L3', 'T3'];

const code = (s) => s.charCodeAt(0) | (s.charCodeAt(1) << 8);

/** Builds the ROM image. Returns { image: Uint32Array, functions: Map(code -> address|1), data }. */
export function buildRom() {
  const bytes = new Uint8Array(ROM_SIZE);
  const dv = new DataView(bytes.buffer);
  // Vector table: SP and reset are unused (the harness sets them), keep them recognisable.
  dv.setUint32(0x00, 0x20042000, true);
  dv.setUint32(0x04, LOOKUP_FN | 1, true);
  bytes.set([0x4d, 0x75, 0x01, 0x03], 0x10); // 'M' 'u' 0x01, version 3 (B2 silicon)
  dv.setUint16(0x14, FUNC_TABLE, true);
  dv.setUint16(0x16, DATA_TABLE, true);
  dv.setUint16(0x18, LOOKUP_FN | 1, true);
  const thumbBkpt = (n) => 0xbe00 | n;
  const BX_LR = 0x4770;
  dv.setUint16(LOOKUP_FN, thumbBkpt(HC_LOOKUP), true);
  dv.setUint16(LOOKUP_FN + 2, BX_LR, true);
  const functions = new Map();
  ROM_FUNCTIONS.forEach((name, i) => {
    const addr = FUNCS_BASE + 4 * i;
    dv.setUint16(addr, thumbBkpt(i), true);
    dv.setUint16(addr + 2, BX_LR, true);
    dv.setUint16(FUNC_TABLE + 4 * i, code(name), true);
    dv.setUint16(FUNC_TABLE + 4 * i + 2, addr | 1, true);
    functions.set(code(name), addr | 1);
  });
  dv.setUint16(FUNC_TABLE + 4 * ROM_FUNCTIONS.length, 0, true);
  // Data table: 'GR' git revision word, 'CR' copyright string.
  const data = new Map();
  dv.setUint32(DATA_BASE, 0x5eed0001, true);
  data.set(code('GR'), DATA_BASE);
  const cr = new TextEncoder().encode('pico-imu emulator ROM stub\0');
  bytes.set(cr, DATA_BASE + 4);
  data.set(code('CR'), DATA_BASE + 4);
  let i = 0;
  for (const [c, a] of data) {
    dv.setUint16(DATA_TABLE + 4 * i, c, true);
    dv.setUint16(DATA_TABLE + 4 * i + 2, a, true);
    i++;
  }
  dv.setUint16(DATA_TABLE + 4 * i, 0, true);
  return { image: new Uint32Array(bytes.buffer), functions, data, funcTable: FUNC_TABLE, dataTable: DATA_TABLE };
}

/** The two-character code of a ROM table tag (as `rom_table_lookup` receives it). */
export function romCode(s) {
  return code(s);
}
