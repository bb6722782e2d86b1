// The `run` command as a process: what it says without the optional log decoder, and how it
// stops on SIGINT/SIGTERM, with and without a host on its USB port.
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { spawn } from 'node:child_process';
import { connect } from 'node:net';
import { mkdtempSync, readFileSync, existsSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { dirname, join } from 'node:path';
import { fileURLToPath } from 'node:url';
import { spinElf, until } from './helpers.js';

const cli = fileURLToPath(new URL('../src/cli.js', import.meta.url));

/** Runs cli.js with no defmt-print reachable (PATH has node only, HOME is empty). */
function runCli(args, dir) {
  const p = spawn(process.execPath, [cli, ...args], {
    env: { PATH: dirname(process.execPath), HOME: dir },
    stdio: ['ignore', 'pipe', 'pipe'],
  });
  p.stderrText = '';
  p.stderr.setEncoding('utf8').on('data', (d) => (p.stderrText += d));
  p.exited = new Promise((resolve) => p.on('exit', (code, signal) => resolve({ code, signal })));
  return p;
}

/** Waits for the exit, failing after `ms`; kills the process then so the test run ends. */
async function exitWithin(p, ms) {
  let timer;
  const late = new Promise((resolve) => (timer = setTimeout(() => resolve('late'), ms)));
  const r = await Promise.race([p.exited, late]);
  clearTimeout(timer);
  if (r === 'late') {
    p.kill('SIGKILL');
    await p.exited;
  }
  return r;
}

test('without defmt-print the run says the decoder is optional and where the raw log is', { timeout: 30000 }, async () => {
  const dir = mkdtempSync(join(tmpdir(), 'sim-cli-'));
  const log = join(dir, 'fw.log');
  const p = runCli(['run', '--elf', spinElf(dir), '--seconds', '0.01', '--log', log], dir);
  const r = await exitWithin(p, 20000);
  assert.deepEqual(r, { code: 0, signal: null }, p.stderrText);
  assert.match(p.stderrText, /defmt-print not installed \(optional\): the firmware log stays raw/);
  assert.match(p.stderrText, /`cargo install defmt-print` to decode it/);
  assert.ok(p.stderrText.includes(`${log}.rtt`), p.stderrText);
  assert.doesNotMatch(p.stderrText, /not found|FAILED/);
  assert.ok(existsSync(`${log}.rtt`));
});

for (const [signal, host] of [['SIGTERM', false], ['SIGINT', true]]) {
  test(`${signal} stops a run with its USB port open ${host ? 'and a host connected' : 'and no host'} within 2 s`, { timeout: 30000 }, async () => {
    const dir = mkdtempSync(join(tmpdir(), 'sim-cli-'));
    const portFile = join(dir, 'port');
    const summary = join(dir, 'summary.json');
    const p = runCli(['run', '--elf', spinElf(dir), '--seconds', '30', '--port-file', portFile, '--summary', summary, '--quiet'], dir);
    await until('the port file', () => existsSync(portFile) && readFileSync(portFile, 'utf8').endsWith('\n'), 10000);
    let sock = null;
    if (host) {
      // A host busy elsewhere: it does not close its end when the emulator closes the port.
      sock = connect({ port: Number(readFileSync(portFile, 'utf8')), host: '127.0.0.1', allowHalfOpen: true });
      sock.on('error', () => {});
      await new Promise((r) => sock.on('connect', r));
      await new Promise((r) => setTimeout(r, 300)); // emulated time runs while a host is there
    }
    const t0 = Date.now();
    p.kill(signal);
    const r = await exitWithin(p, 2000);
    sock?.destroy();
    assert.notEqual(r, 'late', `still running 2 s after ${signal}:\n${p.stderrText}`);
    assert.deepEqual(r, { code: 0, signal: null }, p.stderrText);
    assert.ok(Date.now() - t0 < 2000);
    // It ended like a finished run: the summary is written.
    assert.ok(JSON.parse(readFileSync(summary, 'utf8')).emulated_s >= 0);
  });
}
