// Sensor streams that feed the device models. A stream is a table in the project's CSV contract
// (docs: imu-lab input contract): columns t [s], ax ay az [m/s²], gx gy gz [deg/s],
// mx my mz [µT], temp [°C]. The models sample it with a zero-order hold at their own rate.

import { readFileSync } from 'node:fs';

/**
 * The contract facts (CSV columns and units, sensor rates), written by the imu-proto crate
 * (`imu_proto::contract_json`) and kept equal to it by that crate's test `contract.rs`.
 */
export const CONTRACT = JSON.parse(readFileSync(new URL('./contract.json', import.meta.url), 'utf8'));
export const COLUMNS = CONTRACT.columns.map((c) => c.name);
/**
 * Values of columns a stream file leaves out (e.g. `imu-lab simulate --columns gx,gy,gz`):
 * the board lying still and level — gravity on +z (9.80665 m/s²), no rotation, a mid-latitude
 * geomagnetic field of 20/−5/40 µT — at 25 °C.
 */
export const DEFAULTS = { ax: 0, ay: 0, az: 9.80665, gx: 0, gy: 0, gz: 0, mx: 20, my: -5, mz: 40, temp: 25 };

export class StreamError extends Error {}

/** A stream of rows at a constant rate, stored column-major in Float64Arrays. */
export class Stream {
  constructor(columns, rate, t0 = 0) {
    this.cols = columns; // { t, ax, ... } each Float64Array
    this.rate = rate; // rows per second
    this.t0 = t0;
    this.length = columns.t.length;
    this.wraps = 0;
  }

  /** Row index for emulated time `nanos` (zero-order hold), wrapping at the end (counted). */
  rowAt(nanos) {
    let i = Math.floor((nanos * 1e-9) * this.rate + 1e-9);
    if (i >= this.length) {
      this.wraps = Math.max(this.wraps, Math.floor(i / this.length));
      i %= this.length;
    }
    return i;
  }

  imuAt(nanos) {
    const i = this.rowAt(nanos);
    const c = this.cols;
    return { ax: c.ax[i], ay: c.ay[i], az: c.az[i], gx: c.gx[i], gy: c.gy[i], gz: c.gz[i], temp: c.temp[i] };
  }

  magAt(nanos) {
    const i = this.rowAt(nanos);
    const c = this.cols;
    return { mx: c.mx[i], my: c.my[i], mz: c.mz[i], temp: c.temp[i] };
  }
}

/**
 * Parses the CSV contract. The header names the columns (any order, `#` comment lines and blank
 * lines skipped); the rate is taken from the time column, which must be uniformly spaced
 * (relative tolerance 1e-3 of the mean step).
 */
export function parseStreamCsv(text, origin = 'stream') {
  const lines = text.split(/\r?\n/);
  let header = null;
  let lineNo = 0;
  const data = [];
  for (const raw of lines) {
    lineNo++;
    const line = raw.trim();
    if (!line || line.startsWith('#')) continue;
    const fields = line.split(',').map((f) => f.trim());
    if (!header) {
      header = fields.map((f) => f.replace(/\s*\[.*\]$/, '').replace(/_.*$/, '').toLowerCase());
      if (!header.includes('t')) throw new StreamError(`${origin}:${lineNo}: header lacks the time column 't' (has: ${fields.join(', ')})`);
      if (!COLUMNS.some((c) => c !== 't' && header.includes(c))) {
        throw new StreamError(`${origin}:${lineNo}: header has no data column of the contract (${COLUMNS.slice(1).join(' ')}); has: ${fields.join(', ')}`);
      }
      continue;
    }
    if (fields.length !== header.length) {
      throw new StreamError(`${origin}:${lineNo}: ${fields.length} fields, header has ${header.length}`);
    }
    const row = {};
    header.forEach((h, k) => {
      const v = Number(fields[k]);
      if (COLUMNS.includes(h) && !Number.isFinite(v)) {
        throw new StreamError(`${origin}:${lineNo}: column '${h}' is not a finite number: '${fields[k]}'`);
      }
      row[h] = v;
    });
    data.push(row);
  }
  if (!header) throw new StreamError(`${origin}: empty (no header)`);
  if (data.length < 2) throw new StreamError(`${origin}: needs at least 2 rows, has ${data.length}`);
  const n = data.length;
  const cols = {};
  for (const c of COLUMNS) cols[c] = header.includes(c) ? Float64Array.from(data, (r) => r[c]) : new Float64Array(n).fill(DEFAULTS[c]);
  const dt = (cols.t[n - 1] - cols.t[0]) / (n - 1);
  if (!(dt > 0)) throw new StreamError(`${origin}: time column does not increase (t[0]=${cols.t[0]} s, t[end]=${cols.t[n - 1]} s)`);
  for (let i = 1; i < n; i++) {
    const step = cols.t[i] - cols.t[i - 1];
    if (Math.abs(step - dt) > 1e-3 * dt) {
      throw new StreamError(`${origin}: row ${i + 1}: time step ${step} s differs from the mean step ${dt} s (stream must be uniformly sampled)`);
    }
  }
  return new Stream(cols, 1 / dt, cols.t[0]);
}

export function loadStreamCsv(path) {
  return parseStreamCsv(readFileSync(path, 'utf8'), path);
}

/** mulberry32: a small seeded 32-bit PRNG (Tommy Ettinger's public-domain generator). */
export function mulberry32(seed) {
  let a = seed >>> 0;
  return () => {
    a = (a + 0x6d2b79f5) >>> 0;
    let t = a;
    t = Math.imul(t ^ (t >>> 15), t | 1);
    t ^= t + Math.imul(t ^ (t >>> 7), t | 61);
    return ((t ^ (t >>> 14)) >>> 0) / 4294967296;
  };
}

/** Standard normal deviates by the Box–Muller transform (Box & Muller 1958). */
export function gaussian(rand) {
  let spare = null;
  return () => {
    if (spare !== null) {
      const s = spare;
      spare = null;
      return s;
    }
    let u = 0;
    while (u === 0) u = rand();
    const v = rand();
    const r = Math.sqrt(-2 * Math.log(u));
    spare = r * Math.sin(2 * Math.PI * v);
    return r * Math.cos(2 * Math.PI * v);
  };
}

/**
 * A test stream from a seeded PRNG, used until `imu-lab simulate` provides one. Per axis:
 * white noise of density `arw` (deg/s/√Hz for gyro, m/s²/√Hz for accel: σ = density·√rate,
 * IEEE Std 952-1997 Annex C), a rate random walk of density `rrw` (σ_step = rrw/√rate), plus an
 * optional hidden sinusoid (amplitude, frequency) on gx — an effect outside the five-term model.
 */
export function generateStream({
  seed = 1,
  seconds = 10,
  rate = CONTRACT.sensors.imu.rate_hz,
  gyroWhite = 0.005, // deg/s/√Hz
  gyroRrw = 0.0005, // deg/s/√s
  accelWhite = 0.002, // m/s²/√Hz
  magWhite = 0.2, // µT/√Hz
  sine = null, // { amplitude: deg/s, frequency: Hz }
  tempStart = 25,
  tempSlope = 0.01, // °C/s
} = {}) {
  const n = Math.round(seconds * rate);
  const g = gaussian(mulberry32(seed));
  const cols = {};
  for (const c of COLUMNS) cols[c] = new Float64Array(n);
  const sw = gyroWhite * Math.sqrt(rate);
  const sa = accelWhite * Math.sqrt(rate);
  const sm = magWhite * Math.sqrt(rate);
  const srw = gyroRrw / Math.sqrt(rate);
  const bias = [0.3, -0.2, 0.1];
  const gravity = [0.05, -0.1, 9.80665];
  const field = [20, -5, 40];
  for (let i = 0; i < n; i++) {
    const t = i / rate;
    cols.t[i] = t;
    for (let a = 0; a < 3; a++) bias[a] += srw * g();
    const s = sine ? sine.amplitude * Math.sin(2 * Math.PI * sine.frequency * t) : 0;
    cols.gx[i] = bias[0] + sw * g() + s;
    cols.gy[i] = bias[1] + sw * g();
    cols.gz[i] = bias[2] + sw * g();
    cols.ax[i] = gravity[0] + sa * g();
    cols.ay[i] = gravity[1] + sa * g();
    cols.az[i] = gravity[2] + sa * g();
    cols.mx[i] = field[0] + sm * g();
    cols.my[i] = field[1] + sm * g();
    cols.mz[i] = field[2] + sm * g();
    cols.temp[i] = tempStart + tempSlope * t;
  }
  return new Stream(cols, rate, 0);
}

/** Writes a stream in the CSV contract. */
export function streamToCsv(stream) {
  const out = [COLUMNS.join(',')];
  const c = stream.cols;
  for (let i = 0; i < stream.length; i++) {
    out.push(COLUMNS.map((k) => (k === 't' ? c.t[i].toFixed(6) : c[k][i].toPrecision(9))).join(','));
  }
  return out.join('\n') + '\n';
}
