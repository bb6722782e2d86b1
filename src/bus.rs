//! The I2C0 bus shared by the IMU and magnetometer tasks (an embassy-sync mutex around the
//! async HAL driver), with bus recovery: while the mutex is held, the I2C block is released,
//! nine SCL pulses and a STOP are clocked on GP5/GP4 through SIO
//! (`imu_drivers::recovery::recover_bus`, UM10204 §3.1.16), and the block is re-created.
//!
//! Each sensor's handle ([`BusDevice`]) records when its last transfer started
//! (`pico_imu_core::bus::TransferTime`), the reference of the sample clocks' observations, and
//! reports a transfer abandoned at its deadline as [`BusError::Timeout`] (a bus error), apart
//! from what the controller reports.
use core::future::Future;
use core::pin::Pin;
use core::task::{Context, Poll};
use embassy_rp::gpio::{Level, OutputOpenDrain};
use embassy_rp::i2c::{self, AbortReason, I2c};
use embassy_rp::peripherals::{I2C0, PIN_4, PIN_5};
use embassy_sync::blocking_mutex::raw::NoopRawMutex;
use embassy_sync::mutex::Mutex;
use embassy_time::{Duration, Instant};
use embedded_hal_async::i2c::{ErrorType, I2c as AsyncI2c, Operation};

use crate::alarm;
use crate::i2c_dma::I2cDma;
use pico_imu_core::bus::TransferTime;
use pico_imu_core::clock::{fine, Fine};

/// Half an SCL period of the recovery clock, µs (≈ 100 kHz, slow enough for any slave).
const RECOVERY_HALF_PERIOD_US: u32 = 5;
/// Longest a transaction may take before it is abandoned (`pico_imu_core::bus`).
const TRANSACTION_TIMEOUT_US: u32 = pico_imu_core::bus::TRANSFER_TIMEOUT_US;

pub type SharedBus = Mutex<NoopRawMutex, Bus>;

/// Makes a new I2C0 controller on GP5/GP4 (main.rs owns the interrupt bindings it needs).
///
/// # Safety
///
/// Steals I2C0, GP4 and GP5: call only while no other driver of them exists.
pub type MakeI2c = unsafe fn(i2c::Config) -> I2c<'static, I2C0, i2c::Async>;

/// The I2C0 controller, absent only during a recovery.
pub struct Bus {
    i2c: Option<I2c<'static, I2C0, i2c::Async>>,
    make: MakeI2c,
    /// DMA-driven register reads (`crate::i2c_dma`), on the same controller.
    dma: I2cDma,
    config: i2c::Config,
}

impl Bus {
    pub fn new(make: MakeI2c, dma: I2cDma, config: i2c::Config) -> Self {
        // SAFETY: the bus is made once, at boot, before anything else drives I2C0 or its pins.
        let i2c = unsafe { make(config) };
        Self {
            i2c: Some(i2c),
            make,
            dma,
            config,
        }
    }

    /// Re-create the controller (after an abandoned transaction, or after a recovery).
    fn reset_controller(&mut self) {
        self.i2c = None;
        // SAFETY: the only owner of these peripherals was the I2c just dropped (or the GPIO
        // drivers of a recovery, dropped too); the bus mutex, held by our caller, keeps every
        // other user out until the new controller is stored.
        self.i2c = Some(unsafe { (self.make)(self.config) });
        self.dma.forget();
    }

    /// Clock a stuck slave free and re-create the controller; returns the SCL pulses clocked
    /// and whether SDA was free at the end.
    pub fn recover(&mut self) -> (u8, bool) {
        // Drop the driver first: from here on nothing else uses I2C0, GP4 or GP5.
        self.i2c = None;
        // SAFETY: the only owner of these peripherals was the I2c just dropped, and the bus
        // mutex (held by our caller) keeps every other user out until a new I2c is stored.
        let (scl, sda) = unsafe { (PIN_5::steal(), PIN_4::steal()) };
        let mut scl = OutputOpenDrain::new(scl, Level::High);
        let mut sda = OutputOpenDrain::new(sda, Level::High);
        scl.set_pullup(true);
        sda.set_pullup(true);
        let result = match imu_drivers::recovery::recover_bus(
            &mut scl,
            &mut sda,
            &mut embassy_time::Delay,
            RECOVERY_HALF_PERIOD_US,
        ) {
            Ok(r) => {
                defmt::info!(
                    "i2c: bus recovery, {} pulses, SDA released: {}",
                    r.pulses,
                    r.sda_released
                );
                (r.pulses, r.sda_released)
            }
            Err(_) => {
                defmt::warn!("i2c: bus recovery pin error");
                (0, false)
            }
        };
        drop((scl, sda));
        self.reset_controller();
        result
    }
}

/// One sensor's handle on the shared bus.
pub struct BusDevice {
    bus: &'static SharedBus,
    /// Start of the last transfer through this handle, µs.
    last_start_us: u64,
}

impl BusDevice {
    pub fn new(bus: &'static SharedBus) -> Self {
        Self {
            bus,
            last_start_us: 0,
        }
    }
}

/// What a transfer on the shared bus can end with.
#[derive(Debug, Clone, Copy, PartialEq, Eq, defmt::Format)]
pub enum BusError {
    /// The controller's report (NACK, lost arbitration, …).
    Hal(i2c::Error),
    /// Abandoned at its deadline ([`TRANSACTION_TIMEOUT_US`]).
    Timeout,
}

impl embedded_hal_async::i2c::Error for BusError {
    fn kind(&self) -> embedded_hal_async::i2c::ErrorKind {
        match self {
            BusError::Hal(e) => e.kind(),
            // A transfer that did not finish: the bus is at fault (pico_imu_core::bus::Failure).
            BusError::Timeout => embedded_hal_async::i2c::ErrorKind::Bus,
        }
    }
}

impl ErrorType for BusDevice {
    type Error = BusError;
}

impl TransferTime for BusDevice {
    fn last_start(&self) -> Fine {
        fine(self.last_start_us)
    }
}

impl Bus {
    /// Ready for a transaction: the previous DMA read's STOP over (or the controller
    /// re-created); the controller, if there is one.
    fn ready(&mut self) -> Result<&mut I2c<'static, I2C0, i2c::Async>, BusError> {
        if self.i2c.is_none() || !self.dma.settle() {
            self.reset_controller();
        }
        self.i2c
            .as_mut()
            .ok_or(BusError::Hal(i2c::Error::Abort(AbortReason::Other(0))))
    }

    /// A transaction's result (`None`: abandoned at its deadline, the controller's state
    /// unknown).
    fn ended(&mut self, result: Option<Result<(), i2c::Error>>) -> Result<(), BusError> {
        match result {
            Some(r) => r.map_err(BusError::Hal),
            None => {
                // Re-created at once, not at the next transaction: the abandoned commands
                // still in its TX FIFO would go out as soon as the bus frees (a START held by
                // a slave's SDA), reading a sample that is then never delivered.
                self.reset_controller();
                Err(BusError::Timeout)
            }
        }
    }
}

/// When a transaction started at `now` must be abandoned.
fn deadline(now: Instant) -> Instant {
    now + Duration::from_micros(u64::from(TRANSACTION_TIMEOUT_US))
}

impl AsyncI2c for BusDevice {
    /// A register read (every read the drivers make, and a plain read: `write` empty) goes
    /// straight to the DMA path: one wake-up per transfer, and none of `transaction`'s matching
    /// of an operation list.
    async fn write_read(
        &mut self,
        address: u8,
        write: &[u8],
        read: &mut [u8],
    ) -> Result<(), Self::Error> {
        if !I2cDma::fits(write, read) {
            let ops = &mut [Operation::Write(write), Operation::Read(read)];
            return self.embassy_path(address, ops).await;
        }
        // Uncontended nearly always (the two tasks take turns): no lock future to poll then.
        let mut guard = match self.bus.try_lock() {
            Ok(g) => g,
            Err(_) => self.bus.lock().await,
        };
        let bus = &mut *guard;
        bus.ready()?;
        // SAFETY: the transfer is driven here to its end (it keeps its own deadline), or dropped
        // with this future (which aborts the channels); the sensor tasks await this future to
        // completion, never leak it.
        let r = unsafe {
            bus.dma
                .write_read(address, write, read, TRANSACTION_TIMEOUT_US)
                .await
        };
        self.last_start_us = bus.dma.last_start_us();
        bus.ended(r)
    }

    async fn transaction(
        &mut self,
        address: u8,
        operations: &mut [Operation<'_>],
    ) -> Result<(), Self::Error> {
        match operations {
            [Operation::Write(w), Operation::Read(r)] if I2cDma::fits(w, r) => {
                self.write_read(address, w, r).await
            }
            [Operation::Read(r)] if I2cDma::fits(&[], r) => self.write_read(address, &[], r).await,
            // Two register reads whose buffers lie end to end (a FIFO count and the frames
            // after it): one DMA run receives both.
            [Operation::Write(wa), Operation::Read(ra), Operation::Write(wb), Operation::Read(rb)]
                if wa.len() == 1
                    && wb.len() == 1
                    && ra.as_ptr().wrapping_add(ra.len()) == rb.as_ptr()
                    && I2cDma::fits_two(ra.len(), ra.len() + rb.len()) =>
            {
                let (n_first, n_rx) = (ra.len(), ra.len() + rb.len());
                // SAFETY: `ra` and `rb` are one run of `n_rx` bytes, both borrowed until this
                // transaction is over.
                unsafe {
                    self.read_two(address, [wa[0], wb[0]], n_first, ra.as_mut_ptr(), n_rx)
                        .await
                }
            }
            _ => self.embassy_path(address, operations).await,
        }
    }
}

impl BusDevice {
    /// [`I2cDma::read_two`] under the bus lock, as `write_read` does for one register.
    ///
    /// # Safety
    ///
    /// `rx` must be valid for `n_rx` bytes of writes until the returned future has completed or
    /// been dropped; the future must not be leaked.
    async unsafe fn read_two(
        &mut self,
        address: u8,
        regs: [u8; 2],
        n_first: usize,
        rx: *mut u8,
        n_rx: usize,
    ) -> Result<(), BusError> {
        let mut guard = match self.bus.try_lock() {
            Ok(g) => g,
            Err(_) => self.bus.lock().await,
        };
        let bus = &mut *guard;
        bus.ready()?;
        // SAFETY: under this function's contract; the transfer is driven to its end here.
        let r = unsafe {
            bus.dma
                .read_two(address, regs, n_first, rx, n_rx, TRANSACTION_TIMEOUT_US)
                .await
        };
        self.last_start_us = bus.dma.last_start_us();
        bus.ended(r)
    }

    /// Anything but a register read (the configuration's register writes): embassy-rp's
    /// interrupt-driven path, under the same deadline.
    async fn embassy_path(
        &mut self,
        address: u8,
        operations: &mut [Operation<'_>],
    ) -> Result<(), BusError> {
        let mut guard = self.bus.lock().await;
        let bus = &mut *guard;
        let i2c = bus.ready()?;
        let now = Instant::now();
        self.last_start_us = now.as_micros();
        let result = {
            let transfer = core::pin::pin!(i2c.transaction(address, operations));
            Deadline::new(deadline(now), transfer).await
        };
        bus.ended(result)
    }
}

/// `fut`, abandoned (`None`) once `deadline` has passed: a cheap `embassy_time::with_timeout`,
/// for embassy's path (the DMA path keeps its own deadline, cheaper still: `crate::i2c_dma`).
///
/// `with_timeout` polls a `Timer` on every poll, and each poll re-registers the task with
/// embassy's timer queue, which walks the queue and re-arms the time driver's alarm; even one
/// registration per transaction cost ≈ 550 cycles (emulator). Here the deadline goes straight
/// into its own TIMER alarm ([`alarm::DEADLINE`]) on the first poll; its interrupt flags it and
/// wakes the task, and later polls only look at that flag. The alarm is disarmed when the future
/// ends or is dropped (a wake that races with the end is a harmless extra poll of that task; the
/// flag is cleared again when the next transaction arms the alarm).
struct Deadline<'a, F> {
    fut: Pin<&'a mut F>,
    deadline: Instant,
    armed: bool,
}

impl<'a, F> Deadline<'a, F> {
    fn new(deadline: Instant, fut: Pin<&'a mut F>) -> Self {
        Self {
            fut,
            deadline,
            armed: false,
        }
    }

    fn disarm(&mut self) {
        if self.armed {
            alarm::DEADLINE.disarm();
            self.armed = false;
        }
    }
}

impl<F> Drop for Deadline<'_, F> {
    fn drop(&mut self) {
        self.disarm();
    }
}

impl<F: Future> Future for Deadline<'_, F> {
    type Output = Option<F::Output>;

    fn poll(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<Self::Output> {
        let this = self.get_mut();
        if let Poll::Ready(r) = this.fut.as_mut().poll(cx) {
            this.disarm();
            return Poll::Ready(Some(r));
        }
        if this.armed {
            if alarm::DEADLINE.fired() {
                this.disarm();
                return Poll::Ready(None);
            }
        } else if alarm::DEADLINE.arm(this.deadline, cx.waker()) {
            this.armed = true;
        } else {
            return Poll::Ready(None);
        }
        Poll::Pending
    }
}
