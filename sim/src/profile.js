// Statistical profile of the firmware: after each executed instruction batch the PC is sampled
// every `periodCycles` executed cycles and attributed to the function symbol containing it.

import { writeFileSync } from 'node:fs';
import { Session, parseClock } from './session.js';
import { generateStream } from './stream.js';

/** Strips a Rust legacy-mangled name to its path (`_ZN3foo3bar17h…E` → `foo::bar`). */
export function demangle(name) {
  const m = /^_ZN(.*)E$/.exec(name);
  if (!m) return name;
  const parts = [];
  let s = m[1];
  while (s.length) {
    const d = /^(\d+)/.exec(s);
    if (!d) break;
    const n = Number(d[1]);
    const part = s.slice(d[1].length, d[1].length + n);
    s = s.slice(d[1].length + n);
    if (/^h[0-9a-f]{16}$/.test(part)) continue;
    parts.push(part.replace(/\$LT\$/g, '<').replace(/\$GT\$/g, '>').replace(/\$u20\$/g, ' ').replace(/\$C\$/g, ',').replace(/\.\./g, '::').replace(/\$RF\$/g, '&').replace(/\$BP\$/g, '*').replace(/\$u7b\$/g, '{').replace(/\$u7d\$/g, '}'));
  }
  return parts.join('::');
}

export async function profile(v) {
  if (v.exact) return exactProfile(v);
  const seconds = Number(v.seconds ?? 2);
  const s = new Session({ elf: v.elf, stream: generateStream({ seed: 1, seconds: seconds + 3 }), echoLog: false });
  await s.run(1e9);
  const find = symbolFinder(s.emu.elf);
  const hist = new Map();
  const callers = new Map();
  const callersRe = v.callers ? new RegExp(v.callers) : null;
  const core = s.emu.core;
  // --copies: every call of the memcpy/memmove/memset entry points, by caller (LR) and bytes (r2).
  const copies = new Map();
  if (v.copies) {
    const entries = new Map();
    for (const [n, x] of s.emu.elf.symbols.entries()) {
      if (/^__aeabi_mem(cpy|move|set|clr)[48]?$/.test(n)) entries.set(x.value & ~1, n);
    }
    const exec = core.executeInstruction.bind(core);
    core.executeInstruction = () => {
      const name = entries.get(core.PC >>> 0);
      if (name) {
        const key = `${name} ← ${demangle(find((core.LR >>> 0) & ~1))}`;
        const c = copies.get(key) ?? { calls: 0, bytes: 0 };
        c.calls++;
        c.bytes += core.registers[name.includes('clr') ? 1 : 2] >>> 0;
        copies.set(key, c);
      }
      return exec();
    };
  }
  let next = core.cycles;
  let samples = 0;
  const end = s.emu.clock.nanos + seconds * 1e9;
  s.emu.pollHooks.push(() => {});
  // Sample inside the run by stepping in small slices.
  while (s.emu.clock.nanos < end && !s.emu.stopReason) {
    s.emu.runUntil(s.emu.clock.nanos + 2000);
    if (core.cycles >= next && !core.waiting) {
      const f = find(core.PC >>> 0);
      hist.set(f, (hist.get(f) ?? 0) + 1);
      // --callers RE: for samples in a function whose name matches RE (a leaf such as memcpy),
      // also count the function holding the return address (LR).
      if (callersRe && callersRe.test(f)) {
        const c = `${demangle(f)} ← ${demangle(find((core.LR >>> 0) & ~1))}`;
        callers.set(c, (callers.get(c) ?? 0) + 1);
      }
      samples++;
      next = core.cycles + 97;
    }
  }
  await s.close();
  const rows = [...hist.entries()].sort((a, b) => b[1] - a[1]).slice(0, Number(v.top ?? 25));
  process.stdout.write(`# PC samples while executing: ${samples} over ${seconds} s emulated\n`);
  for (const [n, c] of rows) process.stdout.write(`${((100 * c) / samples).toFixed(1).padStart(5)} %  ${demangle(n)}\n`);
  if (v.copies) {
    process.stdout.write(`# memory copies by caller over ${seconds} s: calls, bytes per ms\n`);
    const cs = [...copies.entries()].sort((a, b) => b[1].bytes - a[1].bytes).slice(0, Number(v.top ?? 25));
    for (const [n, c] of cs) process.stdout.write(`${String(c.calls).padStart(8)} calls ${(c.bytes / (seconds * 1000)).toFixed(0).padStart(7)} B/ms  ${n}\n`);
  }
  if (callersRe) {
    process.stdout.write(`# callers (by LR) of functions matching /${v.callers}/\n`);
    const cs = [...callers.entries()].sort((a, b) => b[1] - a[1]).slice(0, Number(v.top ?? 25));
    for (const [n, c] of cs) process.stdout.write(`${((100 * c) / samples).toFixed(1).padStart(5)} %  ${n}\n`);
  }
}

/** Sorted function symbols of the firmware and a finder from an address to its name. */
function symbolFinder(elf) {
  const syms = [...elf.symbols.entries()]
    .filter(([, x]) => x.size > 0 && x.value >= 0x10000000 && x.value < 0x20042000)
    .map(([n, x]) => ({ n, a: x.value & ~1, e: (x.value & ~1) + x.size }))
    .sort((a, b) => a.a - b.a);
  return (pc) => {
    let lo = 0;
    let hi = syms.length - 1;
    while (lo <= hi) {
      const mid = (lo + hi) >> 1;
      if (pc < syms[mid].a) hi = mid - 1;
      else if (pc >= syms[mid].e) lo = mid + 1;
      else return syms[mid].n;
    }
    return `0x${pc.toString(16)}`;
  };
}

/**
 * `profile --exact`: every executed instruction counted after a warm-up (`--from S`, 1 s), its cycles charged
 * to the function holding it (exclusive), per 1 kHz sample set served by the MPU-6050 model:
 * the same unit as the bench. With `--callers RE`, calls of library leaf functions matching RE
 * (memcpy, division, 64-bit multiply, …) are also charged inclusively to their call sites.
 * Deterministic: the same ELF gives the same table.
 */
export async function exactCycles({ elf, seconds = 1, callers = null, from = 1, tasks = false, polls = false, clock = null }) {
  const s = new Session({ elf, stream: generateStream({ seed: 1, seconds: from + seconds + 2 }), echoLog: false, clock: parseClock(clock) });
  await s.run(from * 1e9);
  const core = s.emu.core;
  const find = symbolFinder(s.emu.elf);
  const perPc = new Map();
  const leafRe = callers ? new RegExp(callers) : null;
  const leaves = new Map();
  if (leafRe) {
    for (const [n, x] of s.emu.elf.symbols.entries()) {
      if (x.size > 0 && leafRe.test(demangle(n))) leaves.set(x.value & ~1, n);
    }
  }
  const calls = new Map();
  let open = null;
  // --tasks: an embassy task's poll (`TaskStorage<F>::poll`, one per task, told apart by
  // address) is charged every cycle until it returns to the executor; handlers by exception
  // number; the rest is the run loop and the executor.
  const taskEntries = new Map();
  if (tasks) {
    for (const [n, x] of s.emu.elf.symbols.entries()) {
      if (x.size > 0 && /TaskStorage.*poll/.test(n)) taskEntries.set(x.value & ~1, `task ${(x.value & ~1).toString(16)}`);
    }
  }
  const byTask = new Map();
  const pollsByTask = new Map();
  // --polls: every task poll, when it began (emulated ns) and its own cycles, in order.
  const pollLog = [];
  let task = null;
  const exec = core.executeInstruction.bind(core);
  core.executeInstruction = () => {
    const pc = core.PC >>> 0;
    let taskKey = null;
    if (tasks) {
      if (core.IPSR === 0) {
        if (task && pc === task.ret) {
          if (polls) pollLog.push({ task: task.name, nanos: task.nanos, cycles: task.own });
          task = null;
        }
        if (!task && taskEntries.has(pc)) {
          task = { name: taskEntries.get(pc), ret: (core.LR >>> 0) & ~1, nanos: s.emu.clock.nanos, own: 0 };
          pollsByTask.set(task.name, (pollsByTask.get(task.name) ?? 0) + 1);
        }
      }
      taskKey = core.IPSR !== 0 ? `exception ${core.IPSR}` : task ? task.name : 'run loop and executor';
    }
    if (open && pc === open.ret) {
      const c = calls.get(open.key) ?? { calls: 0, cycles: 0 };
      c.calls++;
      c.cycles += core.cycles - open.c0;
      calls.set(open.key, c);
      open = null;
    }
    if (!open && leaves.has(pc)) {
      const ret = (core.LR >>> 0) & ~1;
      open = { ret, c0: core.cycles, key: `${demangle(leaves.get(pc))} ← ${demangle(find(ret))}` };
    }
    const c0 = core.cycles;
    const r = exec();
    perPc.set(pc, (perPc.get(pc) ?? 0) + (core.cycles - c0));
    if (taskKey) {
      const t = byTask.get(taskKey) ?? { cycles: 0, pcs: new Map() };
      t.cycles += core.cycles - c0;
      t.pcs.set(pc, (t.pcs.get(pc) ?? 0) + (core.cycles - c0));
      byTask.set(taskKey, t);
      // A poll's own cycles: interrupts taken during it are charged to their exception.
      if (task && taskKey === task.name) task.own += core.cycles - c0;
    }
    return r;
  };
  const served0 = s.mpu.stats.servedFifo + s.mpu.stats.servedRegs;
  await s.run((from + seconds) * 1e9);
  const sets = s.mpu.stats.servedFifo + s.mpu.stats.servedRegs - served0;
  await s.close();
  const byFn = new Map();
  let total = 0;
  for (const [pc, c] of perPc) {
    const f = find(pc & ~1);
    byFn.set(f, (byFn.get(f) ?? 0) + c);
    total += c;
  }
  return { seconds, sets, total, byFn, calls, perPc, find, byTask, pollsByTask, pollLog };
}

async function exactProfile(v) {
  const r = await exactCycles({ elf: v.elf, seconds: Number(v.seconds ?? 1), callers: v.callers, from: Number(v.from ?? 1), tasks: Boolean(v.tasks || v.polls), polls: Boolean(v.polls), clock: v.clock });
  const { sets, total, byFn, calls, seconds } = r;
  if (v.polls) {
    // --polls F: one line per task poll (its start in emulated seconds, the task as in --tasks,
    // its own cycles, without the interrupts taken meanwhile): where in each 10 ms the
    // processing runs, and what moved it.
    const lines = ['start_s\ttask\tcycles', ...r.pollLog.map((p) => `${(p.nanos / 1e9).toFixed(7)}\t${p.task}\t${p.cycles}`)];
    writeFileSync(v.polls, lines.join('\n') + '\n');
  }
  const top = Number(v.top ?? 25);
  const out = [`# executed cycles per sample set, by function (exclusive): ${(total / sets).toFixed(0)} in all, ${sets} sample sets in ${seconds} s`];
  for (const [n, c] of [...byFn.entries()].sort((a, b) => b[1] - a[1]).slice(0, top)) {
    out.push(`${(c / sets).toFixed(1).padStart(8)}  ${demangle(n)}`);
  }
  if (v.pcs) {
    // --pcs RE: the cycles of every instruction address in the functions matching RE, per sample
    // set (to read against a disassembly: which instructions of a hot function cost).
    const re = new RegExp(v.pcs);
    const rows = [...r.perPc.entries()].filter(([pc]) => re.test(demangle(r.find(pc & ~1))));
    out.push(`# cycles per sample set by instruction address in /${v.pcs}/`);
    for (const [pc, c] of rows.sort((a, b) => a[0] - b[0])) {
      out.push(`${(pc >>> 0).toString(16)} ${(c / sets).toFixed(2)}`);
    }
  }
  if (v.tasks) {
    // Interrupts are charged to their exception number (16 + IRQ: 21 USBCTRL, 27 DMA_IRQ_0,
    // 16–19 TIMER_IRQ_0–3, 39 I2C0), not to the task they interrupted.
    out.push(`# cycles per sample set by task poll (with polls per sample set), exception and run loop; each task's costliest functions (exclusive)`);
    for (const [name, t] of [...r.byTask.entries()].sort((a, b) => b[1].cycles - a[1].cycles)) {
      const polls = r.pollsByTask.get(name);
      out.push(`${(t.cycles / sets).toFixed(1).padStart(8)}  ${name}${polls ? ` (${(polls / sets).toFixed(3)} polls)` : ''}`);
      const fns = new Map();
      for (const [pc, c] of t.pcs) {
        const f = demangle(r.find(pc & ~1));
        fns.set(f, (fns.get(f) ?? 0) + c);
      }
      for (const [f, c] of [...fns.entries()].sort((a, b) => b[1] - a[1]).slice(0, 6)) {
        out.push(`${''.padStart(8)}  ${(c / sets).toFixed(1).padStart(8)}  ${f}`);
      }
    }
  }
  if (v.callers) {
    out.push(`# calls of /${v.callers}/ by call site (inclusive): cycles and calls per sample set`);
    for (const [k, c] of [...calls.entries()].sort((a, b) => b[1].cycles - a[1].cycles).slice(0, top)) {
      out.push(`${(c.cycles / sets).toFixed(1).padStart(8)} ${(c.calls / sets).toFixed(2).padStart(6)}  ${k}`);
    }
  }
  process.stdout.write(out.join('\n') + '\n');
}
