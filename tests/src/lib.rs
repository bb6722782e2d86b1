//! Shared helpers for the host tests: register-level chip models and a simulated I²C bus.
//!
//! [`SimBus`] is an embedded-hal 1.0 `I2c` (blocking and async) that routes each transaction
//! to the model at the addressed slave, NACKs empty addresses, and owns a simulated clock.
//! [`SimDelay`] advances that clock, so FIFOs fill while a driver waits, exactly as on the
//! chip. The models are written from the data sheets independently of `imu-drivers` (they
//! repeat the constants on purpose, so a wrong driver constant fails a test).

pub mod mpu6050_model;
pub mod qmc5883_model;

use std::cell::RefCell;
use std::rc::Rc;

use embedded_hal::i2c::{ErrorKind, ErrorType, NoAcknowledgeSource, Operation};

pub use mpu6050_model::Mpu6050Model;
pub use qmc5883_model::{QmcModel, QmcVariant};

/// A xorshift generator keyed by the clock, so that every run of a randomized test draws a
/// different realisation; the key is printed, so a failing run can be replayed with
/// [`Keyed::new`], or without editing the test by `PICO_IMU_TEST_KEY=<key> cargo test <name>`.
pub struct Keyed(u64);

impl Keyed {
    /// Keyed by the system clock (the key printed), or by `PICO_IMU_TEST_KEY` when it is set
    /// (a printed key, to replay a run).
    pub fn from_clock() -> Self {
        if let Some(key) = std::env::var("PICO_IMU_TEST_KEY")
            .ok()
            .and_then(|k| k.trim().parse().ok())
        {
            return Self::new(key);
        }
        let key = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(1, |d| d.as_nanos() as u64);
        Self::new(key)
    }

    /// Keyed by `key` (printed).
    pub fn new(key: u64) -> Self {
        println!("key {}", key | 1);
        Keyed(key | 1)
    }

    /// The next 64 random bits.
    pub fn bits(&mut self) -> u64 {
        let x = &mut self.0;
        *x ^= *x << 13;
        *x ^= *x >> 7;
        *x ^= *x << 17;
        *x
    }
}

/// Bus error of the simulated bus.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SimError {
    /// No device acknowledged the address, or the device NACKed a data byte.
    Nack(NoAcknowledgeSource),
}

impl embedded_hal::i2c::Error for SimError {
    fn kind(&self) -> ErrorKind {
        match self {
            SimError::Nack(s) => ErrorKind::NoAcknowledge(*s),
        }
    }
}

/// Everything on the simulated bus.
#[derive(Default)]
pub struct World {
    /// Simulated time, ns.
    pub now_ns: u64,
    /// MPU-6050 model, if fitted.
    pub mpu: Option<Mpu6050Model>,
    /// QMC5883L/P model, if fitted.
    pub mag: Option<QmcModel>,
    /// An HMC5883L at 0x1E answering its identification registers.
    pub hmc5883l: bool,
    /// Transactions seen (each `transaction` call counts once).
    pub transactions: u64,
    /// Bytes moved over the bus (address bytes excluded).
    pub bytes: u64,
    /// Start of the last transaction, ns.
    pub last_start_ns: u64,
    /// Every address phase to this address is NACKed until this time, ns.
    pub nack_until: Option<(u8, u64)>,
    /// The next transaction starts this long after it is asked for, ns (the bus held by
    /// another task's transfer meanwhile).
    pub hold_next_ns: u64,
    /// The next transaction's START is held this long (a slave holding SDA, the bus busy):
    /// it starts where it is asked for, as the firmware's bus reports it, and its bytes move
    /// after the hold, ns.
    pub hang_next_ns: u64,
    /// After this many more transactions, one starts this long after it is asked for, ns (as
    /// [`World::hold_next_ns`], for a later transfer of a task's turn).
    pub hold_later: Option<(u32, u64)>,
}

impl World {
    fn advance_to(&mut self, t_ns: u64) {
        self.now_ns = t_ns.max(self.now_ns);
        let now = self.now_ns;
        if let Some(m) = self.mpu.as_mut() {
            m.advance_to(now);
        }
        if let Some(m) = self.mag.as_mut() {
            m.advance_to(now);
        }
    }
}

/// Simulated I²C bus; clones share the same world.
#[derive(Clone, Default)]
pub struct SimBus {
    world: Rc<RefCell<World>>,
}

impl SimBus {
    /// An empty bus at t = 0.
    pub fn new() -> Self {
        Self::default()
    }
    /// Fit an MPU-6050 model.
    pub fn with_mpu(self, m: Mpu6050Model) -> Self {
        self.world.borrow_mut().mpu = Some(m);
        self
    }
    /// Fit a QMC5883 model.
    pub fn with_mag(self, m: QmcModel) -> Self {
        self.world.borrow_mut().mag = Some(m);
        self
    }
    /// Fit an HMC5883L (identification registers only).
    pub fn with_hmc5883l(self) -> Self {
        self.world.borrow_mut().hmc5883l = true;
        self
    }
    /// A delay that advances this bus's clock.
    pub fn delay(&self) -> SimDelay {
        SimDelay {
            world: self.world.clone(),
        }
    }
    /// Let simulated time pass.
    pub fn advance_us(&self, us: u64) {
        let mut w = self.world.borrow_mut();
        let t = w.now_ns + us * 1000;
        w.advance_to(t);
    }
    /// Hold the next transaction back by `us` µs, as a transfer of another task holding the
    /// bus would.
    pub fn hold_next_us(&self, us: u64) {
        self.world.borrow_mut().hold_next_ns = us * 1000;
    }
    /// Hold the transaction after the next `skip` ones back by `us` µs ([`World::hold_later`]).
    pub fn hold_later_us(&self, skip: u32, us: u64) {
        self.world.borrow_mut().hold_later = Some((skip, us * 1000));
    }
    /// Hold the next transaction's START for `us` µs after it is asked for ([`World::hang_next_ns`]).
    pub fn hang_next_us(&self, us: u64) {
        self.world.borrow_mut().hang_next_ns = us * 1000;
    }
    /// Current simulated time, ns.
    pub fn now_ns(&self) -> u64 {
        self.world.borrow().now_ns
    }
    /// Inspect or modify the world.
    pub fn with_world<R>(&self, f: impl FnOnce(&mut World) -> R) -> R {
        f(&mut self.world.borrow_mut())
    }
    /// Inspect or modify the MPU model (panics if none is fitted: test set-up error).
    pub fn mpu<R>(&self, f: impl FnOnce(&mut Mpu6050Model) -> R) -> R {
        f(self
            .world
            .borrow_mut()
            .mpu
            .as_mut()
            .expect("no MPU model fitted"))
    }
    /// Inspect or modify the magnetometer model (panics if none is fitted: test set-up error).
    pub fn mag<R>(&self, f: impl FnOnce(&mut QmcModel) -> R) -> R {
        f(self
            .world
            .borrow_mut()
            .mag
            .as_mut()
            .expect("no magnetometer model fitted"))
    }

    fn run(&mut self, address: u8, ops: &mut [Operation<'_>]) -> Result<(), SimError> {
        let mut w = self.world.borrow_mut();
        w.transactions += 1;
        let mut held = std::mem::take(&mut w.hold_next_ns);
        match w.hold_later {
            Some((0, ns)) => {
                held += ns;
                w.hold_later = None;
            }
            Some((n, ns)) => w.hold_later = Some((n - 1, ns)),
            None => {}
        }
        let hung = std::mem::take(&mut w.hang_next_ns);
        w.last_start_ns = w.now_ns + held;
        let now = w.last_start_ns + hung;
        w.advance_to(now);
        let moved: usize = ops
            .iter()
            .map(|o| match o {
                Operation::Read(b) => b.len(),
                Operation::Write(b) => b.len(),
            })
            .sum();
        w.bytes += moved as u64;
        let nack = Err(SimError::Nack(NoAcknowledgeSource::Address));
        if w.nack_until
            .is_some_and(|(a, until)| a == address && now < until)
        {
            return nack;
        }
        if let Some(m) = w.mpu.as_mut().filter(|m| m.address == address) {
            return m.transaction(now, ops);
        }
        if let Some(m) = w.mag.as_mut().filter(|m| m.address() == address) {
            return m.transaction(now, ops);
        }
        if w.hmc5883l && address == 0x1E {
            return hmc_transaction(ops);
        }
        nack
    }
}

/// HMC5883L stand-in: registers 10, 11, 12 hold 'H', '4', '3' (HMC5883L data sheet, table 2).
fn hmc_transaction(ops: &mut [Operation<'_>]) -> Result<(), SimError> {
    let mut regs = [0u8; 13];
    regs[10..13].copy_from_slice(b"H43");
    let mut ptr = 0usize;
    for op in ops {
        match op {
            Operation::Write(b) => {
                if let Some(&p) = b.first() {
                    ptr = p as usize;
                }
            }
            Operation::Read(buf) => {
                for x in buf.iter_mut() {
                    *x = regs.get(ptr).copied().unwrap_or(0);
                    ptr = (ptr + 1) % 13;
                }
            }
        }
    }
    Ok(())
}

/// The start of the last transaction, as the firmware's bus reports it.
impl pico_imu_core::bus::TransferTime for SimBus {
    fn last_start(&self) -> pico_imu_core::clock::Fine {
        let ns = self.world.borrow().last_start_ns;
        let us = u128::from(pico_imu_core::clock::US.raw());
        pico_imu_core::clock::Fine::from_raw((u128::from(ns) * us / 1000) as u64)
    }
}

impl ErrorType for SimBus {
    type Error = SimError;
}

impl embedded_hal::i2c::I2c for SimBus {
    fn transaction(&mut self, address: u8, ops: &mut [Operation<'_>]) -> Result<(), SimError> {
        self.run(address, ops)
    }
}

impl embedded_hal_async::i2c::I2c for SimBus {
    async fn transaction(
        &mut self,
        address: u8,
        ops: &mut [Operation<'_>],
    ) -> Result<(), SimError> {
        self.run(address, ops)
    }
}

/// Delay that advances the simulated clock of its bus (blocking and async).
#[derive(Clone)]
pub struct SimDelay {
    world: Rc<RefCell<World>>,
}

impl SimDelay {
    fn wait(&self, ns: u64) {
        let mut w = self.world.borrow_mut();
        let t = w.now_ns + ns;
        w.advance_to(t);
    }
}

impl embedded_hal::delay::DelayNs for SimDelay {
    fn delay_ns(&mut self, ns: u32) {
        self.wait(ns as u64);
    }
}

impl embedded_hal_async::delay::DelayNs for SimDelay {
    async fn delay_ns(&mut self, ns: u32) {
        self.wait(ns as u64);
    }
}
