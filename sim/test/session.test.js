// The TCP bridge of the emulated USB CDC port: one host at a time, the next one served as soon
// as the previous goes, like a serial port opened again.
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { connect } from 'node:net';
import { mkdtempSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join } from 'node:path';
import { Session, HOST_IN_BYTES } from '../src/session.js';
import { generateStream } from '../src/stream.js';
import { spinElf, until } from './helpers.js';

function session() {
  const elf = spinElf(mkdtempSync(join(tmpdir(), 'sim-session-')));
  return new Session({ elf, stream: generateStream({ seed: 1, seconds: 1 }), defmtPrint: null });
}

/**
 * A host: connects and collects what the device sends it. `busy`: a host that does not close
 * its end when the port closes (not reading at the moment).
 */
async function host(port, { busy = false } = {}) {
  const sock = connect({ port, host: '127.0.0.1', allowHalfOpen: busy });
  sock.got = [];
  sock.ended = false;
  sock.on('data', (d) => sock.got.push(...d));
  sock.on('end', () => (sock.ended = true));
  sock.on('error', () => {});
  await new Promise((r) => sock.on('connect', r));
  return sock;
}

/** The device sends `bytes`; returns once someone (or no one) had the chance to get them. */
async function deviceSends(s, bytes) {
  s.usb.onData(new Uint8Array(bytes));
  await new Promise((r) => setTimeout(r, 50));
}

test('a host that connects while another holds the port is served when that one leaves', { timeout: 5000 }, async () => {
  const s = session();
  const port = await s.listen(0);
  const a = await host(port);
  await until('the first host to be served', () => s.client);
  const b = await host(port);
  await new Promise((r) => setTimeout(r, 50));
  assert.equal(b.ended, false, 'the waiting host was turned away');
  await deviceSends(s, [1, 2]);
  assert.deepEqual([a.got, b.got], [[1, 2], []]);
  a.end();
  await until('the second host to be served', () => s.client && s.usbStats.toHost === 2 && a.ended);
  await deviceSends(s, [3]);
  assert.deepEqual(b.got, [3]);
  b.write(Buffer.from([9, 9, 9]));
  await until('the second host\'s bytes to arrive', () => s.usbStats.fromHost === 3);
  b.destroy();
  await s.close();
});

test('a host that connects right after another closed is served', { timeout: 5000 }, async () => {
  const s = session();
  const port = await s.listen(0);
  for (let i = 0; i < 5; i++) {
    const h = await host(port);
    await until(`host ${i} to be served`, () => s.client);
    await deviceSends(s, [i]);
    assert.deepEqual(h.got, [i], `host ${i}`);
    h.end(); // the next connects at once, before the port has seen this one go
  }
  await s.close();
});

test('closing the session does not wait for a host that keeps its end open', { timeout: 5000 }, async () => {
  const s = session();
  const port = await s.listen(0);
  const a = await host(port, { busy: true });
  const b = await host(port, { busy: true });
  await until('the first host to be served', () => s.client);
  const t0 = Date.now();
  await s.close();
  assert.ok(Date.now() - t0 < 1500, `close took ${Date.now() - t0} ms`);
  a.destroy();
  b.destroy();
});

test('a host that sends faster than the device takes is paused, not buffered without bound, and loses nothing', { timeout: 20000 }, async () => {
  const s = session();
  const port = await s.listen(0);
  const h = await host(port);
  await until('the host to be served', () => s.client);
  // Random bytes of a random length, 4 to 8 times the limit (the device is not enumerated:
  // everything waits in the emulator).
  const n = HOST_IN_BYTES * (4 + Math.floor(Math.random() * 5)) + Math.floor(Math.random() * 1000);
  const sent = Buffer.alloc(n);
  for (let i = 0; i < n; i++) sent[i] = Math.floor(Math.random() * 256);
  h.write(sent);
  await until('the host to be paused', () => s.usbStats.hostInPauses > 0);
  await new Promise((r) => setTimeout(r, 100));
  // One socket read (at most 64 KiB) may land after the limit is reached, no more.
  assert.ok(s.hostInBytes() <= 2 * HOST_IN_BYTES, `${s.hostInBytes()} bytes held`);
  assert.ok(s.usbStats.fromHost < n, 'every byte was taken in without waiting');
  // The device takes what is held, a slice at a time: reading resumes, and every byte arrives
  // once, in order.
  const taken = [];
  while (s.usbStats.fromHost < n || s.pendingFromHost?.length) {
    if (s.pendingFromHost?.length) {
      taken.push(Buffer.from(s.pendingFromHost));
      s.pendingFromHost = null;
    }
    s.paceHostIn();
    await new Promise((r) => setTimeout(r, 5));
    assert.ok(s.hostInBytes() <= 2 * HOST_IN_BYTES, `${s.hostInBytes()} bytes held`);
  }
  assert.ok(Buffer.concat(taken).equals(sent), 'the bytes the device got differ from those sent');
  assert.ok(s.usbStats.hostInPauses >= 2, `${s.usbStats.hostInPauses} pauses`);
  h.destroy();
  await s.close();
});
