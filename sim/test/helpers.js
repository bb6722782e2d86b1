import { existsSync, writeFileSync } from 'node:fs';
import { join } from 'node:path';
import { spawnSync } from 'node:child_process';
import { fileURLToPath } from 'node:url';
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

/**
 * Builds a minimal ELF32 ARM image: PT_LOAD segments and a symbol table.
 * @param segments [{ paddr, vaddr (default paddr), data: Uint8Array }]
 * @param symbols { name: address } or { name: { value, size } } (size 4 by default)
 * @param entry e_entry (default: the first segment's paddr)
 */
export function buildElf(segments, symbols = {}, { entry = segments[0]?.paddr ?? 0 } = {}) {
  const names = Object.keys(symbols);
  const enc = new TextEncoder();
  const strParts = [new Uint8Array([0])];
  const nameOff = [];
  let strLen = 1;
  for (const n of names) {
    nameOff.push(strLen);
    const b = enc.encode(n + '\0');
    strParts.push(b);
    strLen += b.length;
  }
  const strtab = new Uint8Array(strLen);
  let o = 0;
  for (const p of strParts) {
    strtab.set(p, o);
    o += p.length;
  }
  const symtab = new Uint8Array(16 * (names.length + 1));
  const sdv = new DataView(symtab.buffer);
  names.forEach((n, i) => {
    sdv.setUint32(16 * (i + 1), nameOff[i], true);
    const { value, size = 4 } = typeof symbols[n] === 'number' ? { value: symbols[n] } : symbols[n];
    sdv.setUint32(16 * (i + 1) + 4, value, true);
    sdv.setUint32(16 * (i + 1) + 8, size, true);
  });
  const ehsize = 52, phsize = 32, shsize = 40;
  let off = ehsize + phsize * segments.length;
  const segOff = segments.map((s) => {
    const at = off;
    off += s.data.length;
    return at;
  });
  const symOff = off;
  off += symtab.length;
  const strOff = off;
  off += strtab.length;
  const shOff = off;
  const total = shOff + 3 * shsize;
  const b = new Uint8Array(total);
  const dv = new DataView(b.buffer);
  b.set([0x7f, 0x45, 0x4c, 0x46, 1, 1, 1], 0);
  dv.setUint16(18, 40, true);
  dv.setUint32(24, entry, true);
  dv.setUint32(28, ehsize, true);
  dv.setUint32(32, shOff, true);
  dv.setUint16(42, phsize, true);
  dv.setUint16(44, segments.length, true);
  dv.setUint16(46, shsize, true);
  dv.setUint16(48, 3, true);
  segments.forEach((s, i) => {
    const p = ehsize + i * phsize;
    dv.setUint32(p, 1, true);
    dv.setUint32(p + 4, segOff[i], true);
    dv.setUint32(p + 8, s.vaddr ?? s.paddr, true);
    dv.setUint32(p + 12, s.paddr, true);
    dv.setUint32(p + 16, s.data.length, true);
    dv.setUint32(p + 20, s.data.length, true);
    b.set(s.data, segOff[i]);
  });
  b.set(symtab, symOff);
  b.set(strtab, strOff);
  const s1 = shOff + shsize;
  dv.setUint32(s1 + 4, 2, true);
  dv.setUint32(s1 + 16, symOff, true);
  dv.setUint32(s1 + 20, symtab.length, true);
  dv.setUint32(s1 + 24, 2, true);
  dv.setUint32(s1 + 36, 16, true);
  const s2 = shOff + 2 * shsize;
  dv.setUint32(s2 + 4, 3, true);
  dv.setUint32(s2 + 16, strOff, true);
  dv.setUint32(s2 + 20, strtab.length, true);
  return b;
}

/**
 * A flash image: 256 bytes of (fake) boot2, the vector table at 0x10000100 (SP, reset → 0x141)
 * and Thumb halfwords `code` from 0x10000140.
 */
export function flashImage(code) {
  const img = new Uint8Array(0x140 + 2 * code.length);
  const dv = new DataView(img.buffer);
  dv.setUint32(0x100, 0x20040000, true);
  dv.setUint32(0x104, 0x10000141, true);
  code.forEach((h, i) => dv.setUint16(0x140 + 2 * i, h, true));
  return { paddr: 0x10000000, data: img };
}

/** Writes, in `dir`, a firmware that spins for ever (`b .`), never sleeping; returns its path. */
export function spinElf(dir) {
  const path = join(dir, 'spin.elf');
  writeFileSync(path, buildElf([flashImage([0xe7fe])]));
  return path;
}

/** Polls `cond` every 5 ms until it holds; throws after `ms`, naming `what` it waited for. */
export async function until(what, cond, ms = 3000) {
  const t0 = Date.now();
  while (!cond()) {
    if (Date.now() - t0 > ms) throw new Error(`timed out waiting for ${what}`);
    await new Promise((r) => setTimeout(r, 5));
  }
}

/**
 * A bare-metal test program's ELF: the path in `envVar` (`cargo xtask test` builds it and sets
 * it), else built now with cargo for the device (a no-op when it is up to date). `{ elf }`, or
 * `{ why }` when neither works (the test is then skipped, saying why).
 */
export function locateCheckElf(pkg, envVar) {
  const given = process.env[envVar];
  if (given) return existsSync(given) ? { elf: given } : { why: `${envVar}=${given} does not exist` };
  const repo = fileURLToPath(new URL('../..', import.meta.url));
  const r = spawnSync('cargo', ['build', '--release', '--package', pkg, '--target', 'thumbv6m-none-eabi', '--message-format', 'json-render-diagnostics'], {
    cwd: repo,
    encoding: 'utf8',
    stdio: ['ignore', 'pipe', 'inherit'],
    maxBuffer: 64 << 20,
  });
  if (r.error || r.status !== 0) return { why: `cargo build of ${pkg} failed (${r.error?.message ?? `exit ${r.status}`})` };
  for (const line of r.stdout.split('\n')) {
    if (!line.startsWith('{')) continue;
    const m = JSON.parse(line);
    if (m.reason === 'compiler-artifact' && m.target?.name === pkg && m.executable) return { elf: m.executable };
  }
  return { why: `cargo built ${pkg} but named no executable` };
}
