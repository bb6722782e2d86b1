//! DMA-driven I2C0 register reads: `[Write(register address), Read(n)]` (or a plain `Read(n)`)
//! run by two DMA channels, so the task wakes once per transaction instead of once per 16 bytes
//! (embassy-rp's async I2C refills the 16-entry FIFOs from the interrupt's wake-up).
//!
//! RP2040 datasheet §4.3.9 ("Using DMA"), §2.5.3.1 (DREQ 32/33): a TX channel paced by
//! DREQ_I2C0_TX copies a prepared list of IC_DATA_CMD words (the address bytes as writes, then
//! `n` read commands, RESTART on the first read after a write, STOP on the last) into
//! IC_DATA_CMD; an RX channel paced by DREQ_I2C0_RX copies the received bytes from IC_DATA_CMD
//! into the caller's buffer. The task sleeps until the RX channel's completion interrupt
//! (`DmaDoneHandler` on DMA_IRQ_0), an I2C TX_ABRT (a NACK, lost arbitration; `I2cAbortHandler`,
//! bound next to embassy's I2C handler), or the transfer's deadline (`alarm::DEADLINE`, armed
//! with two stores: its interrupt wakes the same waker). The controller's STOP after the last
//! byte (one SCL period) is not waited for: `settle` checks for its STOP_DET before the next
//! transaction of either path. Both channels are aborted whenever a transfer ends early,
//! including at its deadline and when its future is dropped, so the RX channel never writes
//! into a buffer that is gone — provided the future is dropped or completed, never leaked:
//! hence [`I2cDma::write_read`] is `unsafe`, with that as its contract.
use core::future::poll_fn;
use core::sync::atomic::{compiler_fence, Ordering};
use core::task::Poll;

use embassy_rp::i2c::{AbortReason, Error};
use embassy_rp::interrupt::typelevel::{Handler, DMA_IRQ_0, I2C0_IRQ};
use embassy_rp::interrupt::InterruptExt;
use embassy_rp::pac;
use embassy_rp::pac::dma::vals::{DataSize, TreqSel};
use embassy_rp::peripherals::{DMA_CH0, DMA_CH1};
use embassy_rp::Peri;
use embassy_time::{Duration, Instant};

use crate::alarm;
use crate::statics::{DMA_WAITING, DMA_WAKER};

/// Longest read done by DMA; longer ones go through embassy's path. The MPU-6050 driver reads
/// the FIFO in chunks of at most 16 frames × 14 bytes.
pub const MAX_READ: usize = 256;
/// Most address bytes written before a DMA read (one register address in practice).
pub const MAX_WRITE: usize = 4;

/// IC_DATA_CMD command bits (datasheet §4.3.17, IC_DATA_CMD).
const CMD_READ: u32 = 1 << 8;
const CMD_STOP: u32 = 1 << 9;
const CMD_RESTART: u32 = 1 << 10;
/// TX DREQ while the TX FIFO holds ≤ this many commands: keeps it half full, far ahead of the bus.
const TX_DMA_LEVEL: u8 = 8;
/// Longest wait for the STOP of the previous DMA transfer (one SCL period, 2.5 µs at 400 kHz,
/// unless a slave stretches SCL).
const STOP_WAIT_US: u64 = 200;
/// More time for a transfer whose bytes were arriving when its deadline passed ([`wait_end`]),
/// µs: the longest read, 256 bytes of 9 SCL periods at 400 kHz (5.8 ms), with a margin.
const LATE_BYTES_US: u32 = 7_000;

const TX_CH: usize = 0;
const RX_CH: usize = 1;

/// I2C0 interrupt, next to embassy's `i2c::InterruptHandler` (which masks every source and wakes
/// its own transfer): wakes a DMA transfer, if one is waiting (for TX_ABRT).
pub struct I2cAbortHandler;

impl Handler<I2C0_IRQ> for I2cAbortHandler {
    unsafe fn on_interrupt() {
        pac::I2C0
            .ic_intr_mask()
            .write_value(pac::i2c::regs::IcIntrMask(0));
        if DMA_WAITING.load(Ordering::Relaxed) {
            DMA_WAKER.wake();
        }
    }
}

/// DMA_IRQ_0: the RX channel has copied its last byte.
pub struct DmaDoneHandler;

impl Handler<DMA_IRQ_0> for DmaDoneHandler {
    unsafe fn on_interrupt() {
        let ints = pac::DMA.ints(0);
        if ints.read() & (1 << RX_CH) != 0 {
            ints.write_value(1 << RX_CH);
            DMA_WAKER.wake();
        }
    }
}

/// The two DMA channels and the command list.
pub struct I2cDma {
    _tx: Peri<'static, DMA_CH0>,
    _rx: Peri<'static, DMA_CH1>,
    /// `[MAX_WRITE slots for the address bytes | MAX_READ read commands]`. The read slots hold
    /// `CMD_READ`; a transfer marks its first (RESTART) and last (STOP) read and the next one
    /// restores them, so setting up a read costs a few stores whatever its length.
    cmds: [u32; MAX_WRITE + MAX_READ],
    /// The read slot whose STOP the last transfer set.
    last_stop: usize,
    /// A transfer ended (or was NACKed) and its STOP may still be on the bus.
    stop_pending: bool,
    /// When the last transfer started: the µs timer read just before the I2C DMA requests were
    /// turned on (the first command reaches the controller at once), with interrupts off.
    last_start_us: u64,
}

/// What ended a transfer.
enum Ending {
    Done,
    Abort(u32),
    /// The transfer's deadline passed first.
    Timeout,
}

impl I2cDma {
    /// Takes the two channels; the `Binding`s show that both handlers are bound.
    pub fn new<B>(tx: Peri<'static, DMA_CH0>, rx: Peri<'static, DMA_CH1>, _irqs: B) -> Self
    where
        B: embassy_rp::interrupt::typelevel::Binding<DMA_IRQ_0, DmaDoneHandler>
            + embassy_rp::interrupt::typelevel::Binding<I2C0_IRQ, I2cAbortHandler>,
    {
        pac::DMA.inte(0).modify(|v| *v |= 1 << RX_CH);
        embassy_rp::interrupt::DMA_IRQ_0.unpend();
        // SAFETY: the handler bound to DMA_IRQ_0 (`DmaDoneHandler`) touches only the RX
        // channel's status bit and `DMA_WAKER`.
        unsafe { embassy_rp::interrupt::DMA_IRQ_0.enable() };
        Self {
            _tx: tx,
            _rx: rx,
            cmds: [CMD_READ; MAX_WRITE + MAX_READ],
            last_stop: MAX_WRITE,
            stop_pending: false,
            last_start_us: 0,
        }
    }

    /// When the last transfer started, µs since boot.
    pub fn last_start_us(&self) -> u64 {
        self.last_start_us
    }

    /// Wait (spinning, at most `STOP_WAIT_US`) for the STOP that ended the last DMA transfer, so
    /// the controller is idle before it is re-programmed. `false`: no STOP came, the controller
    /// must be re-created. Call before every transaction, of either path.
    pub fn settle(&mut self) -> bool {
        if !self.stop_pending {
            return true;
        }
        let i2c = pac::I2C0;
        let mut since: Option<Instant> = None;
        while !i2c.ic_raw_intr_stat().read().stop_det() {
            let now = Instant::now();
            let t0 = *since.get_or_insert(now);
            if now.saturating_duration_since(t0) > Duration::from_micros(STOP_WAIT_US) {
                self.stop_pending = false;
                return false;
            }
        }
        i2c.ic_clr_stop_det().read();
        self.stop_pending = false;
        true
    }

    /// The controller was reset: nothing of a previous transfer is pending.
    pub fn forget(&mut self) {
        self.stop_pending = false;
    }

    /// Whether `write` then `read` fits the DMA path.
    pub fn fits(write: &[u8], read: &[u8]) -> bool {
        write.len() <= MAX_WRITE && !read.is_empty() && read.len() <= MAX_READ
    }

    /// Write `write` (may be empty) to `address`, then read `read.len()` bytes (repeated start
    /// after a write), then STOP. `fits(write, read)` must hold (else `Err(InvalidReadBufferLength)`).
    /// `None`: abandoned `timeout_us` after its start (the controller's state is then unknown).
    ///
    /// # Safety
    ///
    /// The RX channel writes into `read` while the transfer runs, beyond the borrow checker's
    /// sight: the returned future must be polled to completion or dropped (dropping it aborts
    /// both channels first), never leaked (`mem::forget`, a leaked `Box`), before `read` is used
    /// or freed.
    pub async unsafe fn write_read(
        &mut self,
        address: u8,
        write: &[u8],
        read: &mut [u8],
        timeout_us: u32,
    ) -> Option<Result<(), Error>> {
        if !Self::fits(write, read) {
            return Some(Err(Error::InvalidReadBufferLength));
        }
        let n = read.len();
        let first = MAX_WRITE - write.len();
        for (slot, b) in self.cmds[first..MAX_WRITE].iter_mut().zip(write) {
            *slot = u32::from(*b);
        }
        let cmds = self.mark_reads(n, !write.is_empty());
        // SAFETY: the command list lives in `self`, borrowed for the whole transfer; `read` is
        // the caller's, under this function's own contract.
        let started = unsafe {
            self.start(
                address,
                cmds.add(first),
                write.len() + n,
                read.as_mut_ptr(),
                n,
                timeout_us,
            )
        };
        let (waiting, running) = match started {
            Ok(guards) => guards,
            Err(e) => return Some(Err(e)),
        };
        let ending = wait_end(pac::DMA.ch(RX_CH), n).await;
        self.finish(ending, waiting, running)
    }

    /// Whether [`Self::read_two`] takes `n_first` bytes of the first register and `n_rx` in all.
    pub fn fits_two(n_first: usize, n_rx: usize) -> bool {
        (1..=MAX_WRITE - 2).contains(&n_first) && n_rx > n_first && n_rx - n_first <= MAX_READ
    }

    /// Two register reads in one transfer: register `regs[0]`'s `n_first` bytes, then (after a
    /// repeated START) register `regs[1]`'s, `n_rx` bytes in all received into one run at `rx`.
    /// `fits_two(n_first, n_rx)` must hold (else `Err(InvalidReadBufferLength)`). `None` as for
    /// [`Self::write_read`].
    ///
    /// # Safety
    ///
    /// `rx` must be valid for `n_rx` bytes of writes until the returned future has completed or
    /// been dropped, and the future must not be leaked (as [`Self::write_read`]).
    pub async unsafe fn read_two(
        &mut self,
        address: u8,
        regs: [u8; 2],
        n_first: usize,
        rx: *mut u8,
        n_rx: usize,
        timeout_us: u32,
    ) -> Option<Result<(), Error>> {
        if !Self::fits_two(n_first, n_rx) {
            return Some(Err(Error::InvalidReadBufferLength));
        }
        // The write slots hold the first read whole: its address, its reads (RESTART on the
        // first), then the second address with a RESTART; the read slots take the second.
        let begin = MAX_WRITE - 2 - n_first;
        self.cmds[begin] = u32::from(regs[0]);
        self.cmds[begin + 1] = CMD_READ | CMD_RESTART;
        for slot in &mut self.cmds[begin + 2..MAX_WRITE - 1] {
            *slot = CMD_READ;
        }
        self.cmds[MAX_WRITE - 1] = u32::from(regs[1]) | CMD_RESTART;
        let n_second = n_rx - n_first;
        let cmds = self.mark_reads(n_second, true);
        // SAFETY: the command list lives in `self`, borrowed for the whole transfer; `rx` is
        // the caller's, under this function's own contract.
        let started = unsafe {
            self.start(
                address,
                cmds.add(begin),
                MAX_WRITE - begin + n_second,
                rx,
                n_rx,
                timeout_us,
            )
        };
        let (waiting, running) = match started {
            Ok(guards) => guards,
            Err(e) => return Some(Err(e)),
        };
        let ending = wait_end(pac::DMA.ch(RX_CH), n_rx).await;
        self.finish(ending, waiting, running)
    }

    /// Mark the first (RESTART after a write) and last (STOP) of `n` read slots, restoring the
    /// ones the previous transfer marked; the command list's start.
    #[inline(always)]
    fn mark_reads(&mut self, n: usize, after_write: bool) -> *const u32 {
        self.cmds[MAX_WRITE] = CMD_READ;
        self.cmds[self.last_stop] = CMD_READ;
        let restart = if after_write { CMD_RESTART } else { 0 };
        self.cmds[MAX_WRITE] |= restart;
        self.last_stop = MAX_WRITE + n - 1;
        self.cmds[self.last_stop] |= CMD_STOP;
        self.cmds.as_ptr()
    }

    /// Start a transfer: `n_cmds` IC_DATA_CMD words from `cmds` through the TX channel, the
    /// `n_rx` received bytes into `rx_buf` through the RX channel, its deadline `timeout_us`
    /// after its start (the transfer's own TIMER alarm, whose interrupt wakes this transfer's
    /// waker, `alarm::DEADLINE`: arming it is two stores). The caller then waits for
    /// its end ([`wait_end`]) and hands it to [`Self::finish`], holding the two guards in
    /// between. Set-up and end are functions of their own so that none of their values
    /// (register blocks, pointers, lengths) is kept in the future across the wait: ≈ 20 cycles
    /// per ms less on the M0+ (docs/benchmarks.md).
    ///
    /// # Safety
    ///
    /// `cmds` and `rx_buf` must stay valid until the transfer has ended or `Running` has been
    /// dropped (which aborts both channels first), and `Running` must not be leaked.
    #[inline(always)]
    unsafe fn start(
        &mut self,
        address: u8,
        cmds: *const u32,
        n_cmds: usize,
        rx_buf: *mut u8,
        n_rx: usize,
        timeout_us: u32,
    ) -> Result<(Waiting, Running), Error> {
        if address >= 0x80 {
            return Err(Error::AddressOutOfRange(address.into()));
        }
        let i2c = pac::I2C0;
        i2c.ic_enable().write(|w| w.set_enable(false));
        i2c.ic_tar().write(|w| w.set_ic_tar(address.into()));
        i2c.ic_clr_intr().read(); // STOP_DET, TX_ABRT (and its hold on the TX FIFO) from before
        i2c.ic_dma_tdlr().write(|w| w.set_dmatdl(TX_DMA_LEVEL));
        i2c.ic_dma_rdlr().write(|w| w.set_dmardl(0));
        i2c.ic_enable().write(|w| w.set_enable(true));

        let data_cmd = i2c.ic_data_cmd().as_ptr() as u32;
        // From here on the channels run; `Running` aborts them however this future ends, and
        // `Waiting` routes the I2C interrupt to this transfer until it ends.
        let waiting = Waiting::new();
        let running = Running;
        compiler_fence(Ordering::SeqCst);
        let dma = pac::DMA;
        let rx = dma.ch(RX_CH);
        rx.read_addr().write_value(data_cmd);
        rx.write_addr().write_value(rx_buf as u32);
        rx.trans_count().write_value(n_rx as u32);
        rx.ctrl_trig().write(|w| {
            w.set_treq_sel(TreqSel::I2C0_RX);
            w.set_data_size(DataSize::SIZE_BYTE);
            w.set_incr_read(false);
            w.set_incr_write(true);
            w.set_chain_to(RX_CH as u8);
            w.set_en(true);
        });
        let tx = dma.ch(TX_CH);
        tx.read_addr().write_value(cmds as u32);
        tx.write_addr().write_value(data_cmd);
        tx.trans_count().write_value(n_cmds as u32);
        tx.ctrl_trig().write(|w| {
            w.set_treq_sel(TreqSel::I2C0_TX);
            w.set_data_size(DataSize::SIZE_WORD);
            w.set_incr_read(true);
            w.set_incr_write(false);
            w.set_chain_to(TX_CH as u8);
            w.set_en(true);
        });
        compiler_fence(Ordering::SeqCst);
        // DREQs on: the TX channel starts feeding commands, and the START follows. The time is
        // taken with interrupts off, so that nothing comes between it and the start.
        self.last_start_us = cortex_m::interrupt::free(|_| {
            let t = Instant::now().as_micros();
            i2c.ic_dma_cr().write(|w| {
                w.set_tdmae(true);
                w.set_rdmae(true);
            });
            t
        });
        alarm::DEADLINE.arm_deadline((self.last_start_us as u32).wrapping_add(timeout_us));
        Ok((waiting, running))
    }

    /// The end of a transfer begun by [`Self::start`] (`None`: its deadline passed).
    #[inline(always)]
    fn finish(
        &mut self,
        ending: Ending,
        waiting: Waiting,
        running: Running,
    ) -> Option<Result<(), Error>> {
        let i2c = pac::I2C0;
        alarm::DEADLINE.disarm();
        match ending {
            // Both channels have run their counts out: only the DMA requests to turn off.
            Ending::Done => running.finished(),
            Ending::Abort(_) | Ending::Timeout => drop(running),
        }
        drop(waiting);
        i2c.ic_intr_mask()
            .write_value(pac::i2c::regs::IcIntrMask(0));
        compiler_fence(Ordering::SeqCst);
        match ending {
            Ending::Done => {
                self.stop_pending = true;
                Some(Ok(()))
            }
            Ending::Abort(source) => {
                let reason = abort_reason(source);
                // A NACK ends with a STOP the controller sends itself; after lost arbitration
                // the bus is someone else's and no STOP of ours follows.
                self.stop_pending = !matches!(reason, AbortReason::ArbitrationLoss);
                Some(Err(Error::Abort(reason)))
            }
            // The controller's state is unknown: the caller re-creates it.
            Ending::Timeout => None,
        }
    }
}

/// Sets `DMA_WAITING` while it lives.
struct Waiting;

impl Waiting {
    fn new() -> Self {
        DMA_WAITING.store(true, Ordering::Relaxed);
        Self
    }
}

impl Drop for Waiting {
    fn drop(&mut self) {
        DMA_WAITING.store(false, Ordering::Relaxed);
    }
}

/// Aborts both channels and turns the I2C DMA requests off when dropped.
struct Running;

impl Running {
    /// The transfer completed (the RX channel copied its last byte, so the TX channel had
    /// sent every command before): the channels are idle, nothing to abort.
    fn finished(self) {
        pac::I2C0
            .ic_dma_cr()
            .write_value(pac::i2c::regs::IcDmaCr(0));
        core::mem::forget(self);
        compiler_fence(Ordering::SeqCst);
    }
}

impl Drop for Running {
    fn drop(&mut self) {
        alarm::DEADLINE.disarm();
        pac::I2C0
            .ic_dma_cr()
            .write_value(pac::i2c::regs::IcDmaCr(0));
        let dma = pac::DMA;
        dma.chan_abort()
            .write(|w| w.set_chan_abort((1 << TX_CH) | (1 << RX_CH)));
        while dma.ch(TX_CH).ctrl_trig().read().busy() || dma.ch(RX_CH).ctrl_trig().read().busy() {}
        for ch in [TX_CH, RX_CH] {
            dma.ch(ch).ctrl_trig().write(|w| w.set_en(false));
        }
        compiler_fence(Ordering::SeqCst);
    }
}

/// Sleep until the RX channel has copied its last byte, TX_ABRT is raised, or the transfer's
/// deadline passes; an abort is read and cleared (which also ends its hold on the TX FIFO). A
/// transfer whose bytes have begun to arrive (`n_rx` expected) when its deadline passes gets
/// [`LATE_BYTES_US`] more, once: a START held by the bus until just before the deadline
/// otherwise had its read cut off while the part's bytes moved, a sample read and lost.
async fn wait_end(rx: pac::dma::Channel, n_rx: usize) -> Ending {
    let i2c = pac::I2C0;
    let mut extended = false;
    let mut ended = || {
        if i2c.ic_raw_intr_stat().read().tx_abrt() {
            let source = i2c.ic_tx_abrt_source().read().0;
            i2c.ic_clr_tx_abrt().read();
            return Some(Ending::Abort(source));
        }
        if !rx.ctrl_trig().read().busy() {
            return Some(Ending::Done);
        }
        if !alarm::DEADLINE.fired() {
            return None;
        }
        if !extended && (rx.trans_count().read() as usize) < n_rx {
            extended = true;
            let now = Instant::now().as_micros() as u32;
            alarm::DEADLINE.arm_deadline(now.wrapping_add(LATE_BYTES_US));
            return None;
        }
        Some(Ending::Timeout)
    };
    poll_fn(|cx| {
        if let Some(e) = ended() {
            return Poll::Ready(e);
        }
        // Registered only while the transfer runs (the poll that finds it ended does not), and
        // checked again after: an end between the first check and the registration is seen.
        DMA_WAKER.register(cx.waker());
        if let Some(e) = ended() {
            return Poll::Ready(e);
        }
        // Raised after the check: the unmasked source interrupts at once.
        i2c.ic_intr_mask().write(|w| w.set_m_tx_abrt(true));
        Poll::Pending
    })
    .await
}

/// The same classification as embassy-rp's async path.
fn abort_reason(source: u32) -> AbortReason {
    let s = pac::i2c::regs::IcTxAbrtSource(source);
    if s.abrt_7b_addr_noack() || s.abrt_10addr1_noack() || s.abrt_10addr2_noack() {
        AbortReason::NoAcknowledge
    } else if s.arb_lost() {
        AbortReason::ArbitrationLoss
    } else {
        AbortReason::Other(source)
    }
}
