// Decodes defmt-RTT bytes with the firmware ELF by piping them through `defmt-print -e ELF`
// (crate defmt-print, installed with `cargo install defmt-print`). Without it the raw bytes
// go to the caller, which says how to decode them.

import { spawn, spawnSync } from 'node:child_process';

export function findDefmtPrint() {
  const candidates = [process.env.DEFMT_PRINT, 'defmt-print', `${process.env.HOME}/.cargo/bin/defmt-print`].filter(Boolean);
  for (const c of candidates) {
    const r = spawnSync(c, ['--version'], { encoding: 'utf8' });
    if (r.status === 0) return c;
  }
  return null;
}

/**
 * Nothing is kept: each decoded line goes to `onLine` as it comes and, without the decoder,
 * each chunk of raw bytes to `onRaw`, so a run of any length holds no log in memory.
 */
export class DefmtDecoder {
  constructor(elfPath, { onLine = () => {}, onRaw = () => {}, binary = findDefmtPrint() } = {}) {
    this.onLine = onLine;
    this.onRaw = onRaw;
    this.rawByteCount = 0;
    this.available = !!binary;
    if (!binary) return;
    this.proc = spawn(binary, ['-e', elfPath, '--log-format', '{t} {L} {s}', 'stdin'], { stdio: ['pipe', 'pipe', 'pipe'] });
    let partial = '';
    const take = (chunk) => {
      partial += chunk;
      const parts = partial.split('\n');
      partial = parts.pop();
      for (const l of parts) this.onLine(l);
    };
    this.proc.stdout.setEncoding('utf8').on('data', take);
    this.proc.stderr.setEncoding('utf8').on('data', take);
    this.exited = new Promise((resolve) => this.proc.on('close', () => {
      if (partial) this.onLine(partial);
      resolve();
    }));
    this.proc.stdin.on('error', () => {});
  }

  push(bytes) {
    if (this.proc) this.proc.stdin.write(bytes);
    else {
      this.rawByteCount += bytes.length;
      this.onRaw(bytes);
    }
  }

  /** Flushes and waits for every decoded line. */
  async close() {
    if (!this.proc) return;
    this.proc.stdin.end();
    await this.exited;
  }
}
