// The emulated Pico: rp2040js with the run-time patches, the ROM stub, the firmware ELF, a run
// loop that skips idle time and detects deadlocks, RTT capture and cycle markers.

import { readFileSync } from 'node:fs';
import { RP2040, USBCDC } from 'rp2040js';
import { parseElf } from './elf.js';
import { buildRom, HC_LOOKUP, ROM_FUNCTIONS } from './rom.js';
import { patchDmaAbort, patchI2cDreq, patchI2cInterruptMask, patchSevLogger, patchXipCtrl, UsbOutQueue } from './patches.js';
import { RttReader } from './rtt.js';

const FLASH_BASE = 0x10000000;
/**
 * Cycles of an exception's entry and return that rp2040js 1.4.1 does not charge (it stacks and
 * unstacks the eight-word frame at no cost). Entry: the Cortex-M0+'s interrupt latency with
 * zero-wait-state memory, 15 cycles (Cortex-M0+ TRM, ARM DDI 0484C, 3.6.1), stacking included.
 * Return: the instruction that loads EXC_RETURN is charged as executed; on top of it the eight
 * words are unstacked (8 cycles) and the pipeline refilled (2), a model good to ± 3 cycles
 * (the TRM gives no figure). Tail-chaining, which skips an unstack and stack on silicon, is
 * charged as a full return and entry: the count is an upper bound there.
 */
export const EXC_ENTRY_CYCLES = 15;
export const EXC_RETURN_CYCLES = 10;
const ROM_LIMIT = 0x4000;
/** Typical W25Q16JV timings (Winbond datasheet rev H, §9.6): sector erase 45 ms, page program 0.4 ms. */
const SECTOR_ERASE_NS = 45e6;
const PAGE_PROGRAM_NS = 0.4e6;

/** Marker stage id under which interrupt handlers are counted. */
export const IRQ_STAGE = 9;

export class EmulatorStop extends Error {}

export class Emulator {
  /**
   * @param opts.elf path to the firmware ELF (or opts.elfBytes)
   * @param opts.rttPollNanos how often RTT is drained (emulated ns), default 200 µs
   * @param opts.markerSymbol `#[no_mangle]` u32 static the firmware stores stage ids to
   * @param opts.onRtt callback(bytes)
   * @param opts.onLog callback(level, component, message) for emulator diagnostics
   */
  constructor(opts = {}) {
    const bytes = opts.elfBytes ?? readFileSync(opts.elf);
    this.elfPath = opts.elf;
    this.elf = parseElf(bytes);
    this.mcu = new RP2040();
    this.clock = this.mcu.clock;
    this.core = this.mcu.core;
    this.diagnostics = [];
    const onLog = opts.onLog ?? (() => {});
    patchSevLogger(this.mcu, (level, component, message) => {
      if (this.diagnostics.length < 200) this.diagnostics.push(`${level} ${component}: ${message}`);
      onLog(level, component, message);
    });
    patchI2cInterruptMask(this.mcu);
    patchI2cDreq(this.mcu);
    this.xip = patchXipCtrl(this.mcu);
    patchDmaAbort(this.mcu);
    this.usbOut = new UsbOutQueue(this.mcu);
    this.rom = buildRom();
    this.mcu.loadBootrom(this.rom.image); // resets the chip and erases flash: do it before loading
    this.loadSegments();
    this.mcu.onBreak = (code) => this.onBreak(code);
    this.stopReason = null;
    this.stallNanos = 0;
    this.stats = { hypercalls: 0, flashErases: 0, flashPrograms: 0 };
    // RTT
    const rtt = this.elf.symbols.get('_SEGGER_RTT');
    this.rtt = rtt ? new RttReader(this.mcu, rtt.value) : null;
    this.onRtt = opts.onRtt ?? (() => {});
    this.rttPollNanos = opts.rttPollNanos ?? 200_000;
    this.nextPoll = 0;
    this.pollHooks = [];
    this.chargeExceptions();
    // Cycle markers
    this.marks = null;
    const markerSymbol = opts.markerSymbol ?? 'PICO_IMU_STAGE';
    const marker = this.elf.symbols.get(markerSymbol);
    if (marker) this.installMarker(marker.value);
    this.boot();
  }

  /** Writes each PT_LOAD segment that lies in flash at its physical (load) address. */
  loadSegments() {
    let loaded = 0;
    for (const s of this.elf.segments) {
      if (s.paddr >= FLASH_BASE && s.paddr + s.data.length <= FLASH_BASE + this.mcu.flash.length) {
        this.mcu.flash.set(s.data, s.paddr - FLASH_BASE);
        loaded += s.data.length;
      }
    }
    if (!loaded) throw new EmulatorStop(`${this.elfPath}: no PT_LOAD segment lies in flash (0x10000000..): not an RP2040 firmware image`);
    this.flashBytes = loaded;
  }

  /**
   * Boots without running boot2: VTOR = 0x10000100 (the vector table right after the 256-byte
   * boot2), SP and PC from its first two words (ARMv6-M ARM B1.5.5, reset behaviour).
   */
  boot() {
    const vt = FLASH_BASE + 0x100;
    const sp = this.mcu.readUint32(vt);
    const pc = this.mcu.readUint32(vt + 4);
    if (sp < 0x20000000 || sp > 0x20042000 || (pc & 1) === 0 || pc < FLASH_BASE) {
      throw new EmulatorStop(`no vector table at 0x10000100 (SP=0x${sp.toString(16)}, reset=0x${pc.toString(16)}): is boot2 linked in (link-rp.x)?`);
    }
    this.core.VTOR = vt;
    this.core.SP = sp;
    this.core.PC = pc & ~1;
  }

  /**
   * Charges exception entry and return (`EXC_ENTRY_CYCLES`, `EXC_RETURN_CYCLES`) to
   * `core.cycles`, and to the clock through `pendingCycles` (taken by `runUntil` with the next
   * instruction: an entry that ends a WFE sleep happens outside any instruction).
   */
  chargeExceptions() {
    const core = this.core;
    this.pendingCycles = 0;
    this.exceptions = { entries: 0, returns: 0 };
    const entry = core.exceptionEntry.bind(core);
    core.exceptionEntry = (n) => {
      entry(n);
      core.cycles += EXC_ENTRY_CYCLES;
      this.pendingCycles += EXC_ENTRY_CYCLES;
      this.exceptions.entries++;
    };
    const ret = core.exceptionReturn.bind(core);
    core.exceptionReturn = (r) => {
      ret(r);
      core.cycles += EXC_RETURN_CYCLES;
      this.pendingCycles += EXC_RETURN_CYCLES;
      this.exceptions.returns++;
    };
  }

  installMarker(address) {
    const mcu = this.mcu;
    const core = this.core;
    this.marks = { address, stage: 0, since: 0, cycles: new Map(), entries: new Map(), log: null };
    const m = this.marks;
    const charge = () => {
      const now = core.cycles;
      m.cycles.set(m.stage, (m.cycles.get(m.stage) ?? 0) + (now - m.since));
      m.since = now;
    };
    // Thread-mode stage to resume after the interrupt handlers (null: in thread mode).
    let interrupted = null;
    const enter = (v) => {
      if (interrupted !== null) {
        interrupted = v; // a marker store inside a handler names the stage to resume
        return;
      }
      charge();
      m.stage = v;
      m.entries.set(v, (m.entries.get(v) ?? 0) + 1);
    };
    // Interrupt handlers are charged to their own stage, not to the stage they interrupted, so
    // a stage's cycles are its own code (and whatever other tasks it awaits).
    const exEntry = core.exceptionEntry.bind(core);
    core.exceptionEntry = (n) => {
      if (interrupted === null) {
        charge();
        interrupted = m.stage;
        m.stage = IRQ_STAGE;
        m.entries.set(IRQ_STAGE, (m.entries.get(IRQ_STAGE) ?? 0) + 1);
      }
      exEntry(n);
    };
    const exReturn = core.exceptionReturn.bind(core);
    core.exceptionReturn = (r) => {
      exReturn(r);
      if (interrupted !== null && core.IPSR === 0) {
        charge();
        m.stage = interrupted;
        interrupted = null;
      }
    };
    const w32 = mcu.writeUint32.bind(mcu);
    mcu.writeUint32 = (a, v) => {
      w32(a, v);
      if (a === address) enter(v >>> 0);
    };
    const w16 = mcu.writeUint16.bind(mcu);
    mcu.writeUint16 = (a, v) => {
      w16(a, v);
      if (a === address) enter(v & 0xffff);
    };
    const w8 = mcu.writeUint8.bind(mcu);
    mcu.writeUint8 = (a, v) => {
      w8(a, v);
      if (a === address) enter(v & 0xff);
    };
  }

  /** Cycles per stage id since the last `resetMarks()`. */
  markReport() {
    if (!this.marks) return null;
    const m = this.marks;
    const cycles = new Map(m.cycles);
    cycles.set(m.stage, (cycles.get(m.stage) ?? 0) + (this.core.cycles - m.since));
    return { cycles, entries: new Map(m.entries) };
  }

  resetMarks() {
    if (!this.marks) return;
    this.marks.cycles.clear();
    this.marks.entries.clear();
    this.marks.since = this.core.cycles;
  }

  reg(n) {
    return this.core.registers[n] >>> 0;
  }

  setReg(n, v) {
    this.core.registers[n] = v >>> 0;
  }

  onBreak(code) {
    const pc = (this.core.PC - this.core.breakRewind) >>> 0;
    if (pc < ROM_LIMIT) {
      this.hypercall(code);
      return;
    }
    this.stop({ kind: 'break', code, pc, message: `firmware stopped: breakpoint/UDF #${code} at PC=0x${pc.toString(16)} (panic-probe ends in UDF)` });
  }

  /** Services a ROM function (see rom.js) in JavaScript. Arguments in r0..r3 (AAPCS). */
  hypercall(code) {
    this.stats.hypercalls++;
    const mcu = this.mcu;
    const [r0, r1, r2] = [this.reg(0), this.reg(1), this.reg(2)];
    if (code === HC_LOOKUP) {
      const table = r0 === this.rom.funcTable ? this.rom.functions : r0 === this.rom.dataTable ? this.rom.data : null;
      const addr = table?.get(r1 & 0xffff) ?? 0;
      if (!addr) {
        const tag = String.fromCharCode(r1 & 0xff, (r1 >> 8) & 0xff);
        this.stop({ kind: 'rom', message: `firmware asked the ROM for '${tag}', which the ROM stub does not implement` });
      }
      this.setReg(0, addr);
      return;
    }
    const name = ROM_FUNCTIONS[code];
    const flashOffset = (a) => {
      if (a >= mcu.flash.length) throw new EmulatorStop(`flash offset 0x${a.toString(16)} outside the 16 MiB flash`);
      return a;
    };
    switch (name) {
      case 'IF':
      case 'EX':
      case 'FC':
      case 'CX':
        return;
      case 'RE': {
        // flash_range_erase(addr, count, block_size, block_cmd)
        const a = flashOffset(r0);
        if (a % 4096 || r1 % 4096) {
          this.stop({ kind: 'rom', message: `flash_range_erase(0x${a.toString(16)}, ${r1}) not 4096-aligned` });
          return;
        }
        mcu.flash.fill(0xff, a, a + r1);
        this.stats.flashErases++;
        this.stallNanos += (r1 / 4096) * SECTOR_ERASE_NS;
        return;
      }
      case 'RP': {
        // flash_range_program(addr, data, count): NOR programming only clears bits.
        const a = flashOffset(r0);
        for (let i = 0; i < r2; i++) mcu.flash[a + i] &= mcu.readUint8(r1 + i);
        this.stats.flashPrograms++;
        this.stallNanos += Math.ceil(r2 / 256) * PAGE_PROGRAM_NS;
        return;
      }
      case 'C4':
      case 'MC':
        for (let i = 0; i < r2; i++) mcu.writeUint8(r0 + i, mcu.readUint8(r1 + i));
        return; // r0 (dest) is the return value already
      case 'MS':
      case 'S4':
        for (let i = 0; i < r2; i++) mcu.writeUint8(r0 + i, r1 & 0xff);
        return;
      case 'P3': {
        let v = r0;
        let n = 0;
        while (v) {
          n += v & 1;
          v >>>= 1;
        }
        this.setReg(0, n);
        return;
      }
      case 'R3': {
        let v = 0;
        for (let i = 0; i < 32; i++) if (r0 & (1 << i)) v |= 1 << (31 - i);
        this.setReg(0, v);
        return;
      }
      case 'L3':
        this.setReg(0, Math.clz32(r0));
        return;
      case 'T3':
        this.setReg(0, r0 === 0 ? 32 : 31 - Math.clz32(r0 & -r0));
        return;
      default:
        this.stop({ kind: 'rom', message: `unknown hypercall #${code}` });
    }
  }

  stop(reason) {
    if (!this.stopReason) this.stopReason = { ...reason, nanos: this.clock.nanos, pc: reason.pc ?? this.core.PC >>> 0 };
  }

  /** Stalls the CPU for `nanos` (clock and peripherals run, no instruction executes). */
  stallCpu(nanos) {
    this.stallNanos += nanos;
  }

  pollRtt() {
    if (this.rtt) {
      const b = this.rtt.poll();
      if (b) this.onRtt(b);
    }
    for (const h of this.pollHooks) h(this.clock.nanos);
  }

  /**
   * Runs until emulated time `untilNanos` or a stop. Executes one instruction at a time and
   * advances the clock by its cycles at clk_sys; while the core sleeps (WFI/WFE) the clock jumps
   * to the next alarm. Sleeping with no alarm pending is a deadlock. Returns the stop reason or null.
   */
  runUntil(untilNanos) {
    const { core, clock } = this;
    const cycleNanos = 1e9 / (this.mcu.clkSys || 125e6);
    while (!this.stopReason) {
      const now = clock.nanos;
      if (now >= untilNanos) break;
      if (now >= this.nextPoll) {
        this.pollRtt();
        this.nextPoll = now + this.rttPollNanos;
      }
      if (this.stallNanos > 0) {
        const dt = Math.min(this.stallNanos, untilNanos - now);
        this.stallNanos -= dt;
        clock.tick(dt);
        continue;
      }
      if (core.waiting) {
        const next = clock.nextAlarm;
        if (!next) {
          this.stop({ kind: 'deadlock', message: `deadlock: the core sleeps (WFI/WFE) at PC=0x${(core.PC >>> 0).toString(16)} and no timer or peripheral event is pending` });
          break;
        }
        const dt = Math.max(0, Math.min(next.nanos - now, this.nextPoll - now, untilNanos - now));
        clock.tick(dt);
        continue;
      }
      // Inner burst: execute without re-checking the slow conditions every instruction.
      const limit = Math.min(this.nextPoll, untilNanos);
      let t = now;
      do {
        const c = core.executeInstruction() + this.pendingCycles;
        this.pendingCycles = 0;
        t += c * cycleNanos;
        clock.tick(c * cycleNanos);
      } while (t < limit && !core.waiting && !this.stopReason && this.stallNanos === 0);
    }
    return this.stopReason;
  }

  /** Runs in slices, yielding to the event loop between them (sockets, child processes). */
  async run(untilNanos, { sliceNanos = 2e6, shouldPause = () => false } = {}) {
    while (!this.stopReason && this.clock.nanos < untilNanos) {
      const p0 = performance.now();
      while (shouldPause() && !this.stopReason) await new Promise((r) => setTimeout(r, 5));
      this.pausedWallSeconds = (this.pausedWallSeconds ?? 0) + (performance.now() - p0) / 1000;
      this.runUntil(Math.min(untilNanos, this.clock.nanos + sliceNanos));
      await new Promise((r) => setImmediate(r));
    }
    this.pollRtt();
    return this.stopReason;
  }

  /** Emulated CPU load: executed cycles / elapsed clk_sys cycles. */
  get cpuLoad() {
    const elapsed = (this.clock.nanos * (this.mcu.clkSys || 125e6)) / 1e9;
    return elapsed ? this.core.cycles / elapsed : 0;
  }
}

/** The host end of the emulated USB CDC-ACM port: enumeration by rp2040js's USBCDC helper. */
export class CdcHost {
  constructor(emu) {
    this.emu = emu;
    this.cdc = new USBCDC(emu.mcu.usbCtrl);
    this.connected = false;
    this.onData = () => {};
    this.cdc.onDeviceConnected = () => {
      this.connected = true;
      if (this.waiting) for (const w of this.waiting.splice(0)) w();
    };
    this.cdc.onSerialData = (buf) => this.onData(buf);
    this.waiting = [];
  }

  write(bytes) {
    if (this.cdc.outEndpoint < 0) throw new Error('USB CDC not enumerated yet: no OUT endpoint');
    this.emu.usbOut.push(this.cdc.outEndpoint, bytes);
  }
}
