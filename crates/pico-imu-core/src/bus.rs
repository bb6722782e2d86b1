//! What the sensor services need from the bus besides `embedded_hal_async::i2c::I2c`: when its
//! last transfer started (the reference of every sample-clock observation), and what kind of
//! failure an error was.
use embedded_hal::i2c::{Error, ErrorKind};

use crate::clock::Fine;

/// Longest a transfer may take before the bus abandons it (reported as [`Failure::Timeout`]):
/// the longest one, a FIFO chunk of 16 × 14 bytes, needs ≈ 5.7 ms at 400 kHz, and a slave
/// holding SDA low could otherwise stall a transfer for ever. A transfer that completed took
/// at most this long on the bus, however late its task saw it end.
pub const TRANSFER_TIMEOUT_US: u32 = 25_000;

/// A bus that records when each transfer starts: the instant the first command of the transfer
/// went to the controller, on the µs timer in [`Fine`] units, taken with interrupts off so that
/// nothing comes between it and the start.
pub trait TransferTime {
    /// Start of the most recent transfer made through this handle.
    fn last_start(&self) -> Fine;
}

/// What a failed transfer means for the sensor and the bus.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Failure {
    /// The target did not acknowledge: nothing was transferred; retry.
    Nack,
    /// The START lost arbitration (a slave holds SDA): nothing was transferred; recover the
    /// bus, then retry.
    ArbitrationLost,
    /// The transfer was abandoned at its deadline (a hung START or a stretched clock): an
    /// unknown part of it happened; recover the bus, then retry.
    Timeout,
    /// Anything else the bus reports: treated like a timeout.
    Other,
}

impl Failure {
    /// Classify a bus error. [`ErrorKind::Bus`] is the deadline (the firmware's bus reports a
    /// transfer abandoned at its deadline as a bus error).
    pub fn of<E: Error>(e: &E) -> Self {
        match e.kind() {
            ErrorKind::NoAcknowledge(_) => Failure::Nack,
            ErrorKind::ArbitrationLoss => Failure::ArbitrationLost,
            ErrorKind::Bus => Failure::Timeout,
            _ => Failure::Other,
        }
    }

    /// Whether the bus should be recovered (SCL clocked, STOP) before the next transfer.
    pub fn needs_recovery(self) -> bool {
        !matches!(self, Failure::Nack)
    }

    /// Whether some bytes of the transfer may have moved (a FIFO read then lost its alignment).
    pub fn partial(self) -> bool {
        matches!(self, Failure::Timeout | Failure::Other)
    }

    /// The event's kind, for a fault that is the bus's rather than the sensor's.
    pub fn bus_fault(self) -> Option<imu_proto::BusFault> {
        match self {
            Failure::ArbitrationLost => Some(imu_proto::BusFault::ArbitrationLost),
            Failure::Timeout | Failure::Other => Some(imu_proto::BusFault::Timeout),
            Failure::Nack => None,
        }
    }
}
