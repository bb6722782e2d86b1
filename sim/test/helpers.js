import { Stream, COLUMNS } from '../src/stream.js';

/** A constant stream (every row the same physical values), `seconds` long at `rate`. */
export function constantStream(values, { seconds = 2, rate = 1000 } = {}) {
  const n = seconds * rate;
  const cols = {};
  for (const c of COLUMNS) cols[c] = new Float64Array(n).fill(c === 't' ? 0 : values[c] ?? 0);
  for (let i = 0; i < n; i++) cols.t[i] = i / rate;
  return new Stream(cols, rate, 0);
}

/** Drives a RegisterDevice like a bus master: write [reg, ...data] at time ns. */
export function writeRegs(dev, nanos, reg, ...data) {
  dev.start('write', nanos);
  dev.write(reg, nanos);
  for (const d of data) dev.write(d, nanos);
  dev.stop(false, nanos);
}

/** write [reg] then repeated-start read of n bytes at time ns. */
export function readRegs(dev, nanos, reg, n) {
  dev.start('write', nanos);
  dev.write(reg, nanos);
  dev.start('read', nanos);
  const out = [];
  for (let i = 0; i < n; i++) out.push(dev.read(nanos));
  dev.stop(false, nanos);
  return out;
}

export const ms = (x) => x * 1e6;
