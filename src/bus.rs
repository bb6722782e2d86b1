//! The I2C0 bus shared by the IMU and magnetometer tasks (an embassy-sync mutex around the
//! async HAL driver), with bus recovery: while the mutex is held, the I2C block is released,
//! nine SCL pulses and a STOP are clocked on GP5/GP4 through SIO
//! (`imu_drivers::recovery::recover_bus`, UM10204 §3.1.16), and the block is re-created.
use embassy_rp::gpio::{Level, OutputOpenDrain};
use embassy_rp::i2c::{self, AbortReason, I2c};
use embassy_rp::peripherals::{I2C0, PIN_4, PIN_5};
use embassy_sync::blocking_mutex::raw::NoopRawMutex;
use embassy_sync::mutex::Mutex;
use embassy_time::{with_timeout, Duration};
use embedded_hal_async::i2c::{ErrorType, I2c as AsyncI2c, Operation};

use crate::Irqs;

/// Half an SCL period of the recovery clock, µs (≈ 100 kHz, slow enough for any slave).
const RECOVERY_HALF_PERIOD_US: u32 = 5;
/// Longest a transaction may take before it is abandoned: the longest one (a FIFO chunk of
/// 32 × 14 bytes) needs ≈ 11 ms at 400 kHz. A slave holding SDA low can otherwise stall a
/// transfer for ever; after a timeout the controller is re-created before the next use.
const TRANSACTION_TIMEOUT_MS: u64 = 25;

pub type SharedBus = Mutex<NoopRawMutex, Bus>;

/// The I2C0 controller, absent only during a recovery.
pub struct Bus {
    i2c: Option<I2c<'static, I2C0, i2c::Async>>,
    config: i2c::Config,
    /// A transaction was abandoned mid-way: the controller's state is unknown.
    wedged: bool,
}

impl Bus {
    pub fn new(i2c: I2c<'static, I2C0, i2c::Async>, config: i2c::Config) -> Self {
        Self {
            i2c: Some(i2c),
            config,
            wedged: false,
        }
    }

    /// Re-create the controller (after an abandoned transaction, or after a recovery).
    fn reset_controller(&mut self) {
        self.i2c = None;
        // SAFETY: the only owner of these peripherals was the I2c just dropped (or the GPIO
        // drivers of a recovery, dropped too); the bus mutex, held by our caller, keeps every
        // other user out until the new controller is stored.
        let (p, scl, sda) = unsafe { (I2C0::steal(), PIN_5::steal(), PIN_4::steal()) };
        self.i2c = Some(I2c::new_async(p, scl, sda, Irqs, self.config));
        self.wedged = false;
    }

    /// Clock a stuck slave free and re-create the controller; returns the recoveries done (1).
    pub fn recover(&mut self) -> u32 {
        // Drop the driver first: from here on nothing else uses I2C0, GP4 or GP5.
        self.i2c = None;
        // SAFETY: the only owner of these peripherals was the I2c just dropped, and the bus
        // mutex (held by our caller) keeps every other user out until a new I2c is stored.
        let (scl, sda) = unsafe { (PIN_5::steal(), PIN_4::steal()) };
        let mut scl = OutputOpenDrain::new(scl, Level::High);
        let mut sda = OutputOpenDrain::new(sda, Level::High);
        scl.set_pullup(true);
        sda.set_pullup(true);
        match imu_drivers::recovery::recover_bus(
            &mut scl,
            &mut sda,
            &mut embassy_time::Delay,
            RECOVERY_HALF_PERIOD_US,
        ) {
            Ok(r) => defmt::info!(
                "i2c: bus recovery, {} pulses, SDA released: {}",
                r.pulses,
                r.sda_released
            ),
            Err(_) => defmt::warn!("i2c: bus recovery pin error"),
        }
        drop((scl, sda));
        self.reset_controller();
        1
    }
}

/// One sensor's handle on the shared bus.
pub struct BusDevice {
    bus: &'static SharedBus,
}

impl BusDevice {
    pub fn new(bus: &'static SharedBus) -> Self {
        Self { bus }
    }
}

impl ErrorType for BusDevice {
    type Error = i2c::Error;
}

impl AsyncI2c for BusDevice {
    async fn transaction(
        &mut self,
        address: u8,
        operations: &mut [Operation<'_>],
    ) -> Result<(), Self::Error> {
        let mut bus = self.bus.lock().await;
        if bus.wedged || bus.i2c.is_none() {
            bus.reset_controller();
        }
        let Some(i2c) = bus.i2c.as_mut() else {
            return Err(i2c::Error::Abort(AbortReason::Other(0)));
        };
        let t = Duration::from_millis(TRANSACTION_TIMEOUT_MS);
        match with_timeout(t, i2c.transaction(address, operations)).await {
            Ok(r) => r,
            Err(_) => {
                bus.wedged = true;
                Err(i2c::Error::Abort(AbortReason::Other(u32::MAX)))
            }
        }
    }
}
