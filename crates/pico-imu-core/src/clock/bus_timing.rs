//! Where in an I²C transfer a register is latched: the instants every observation of a sample
//! clock is taken at.
use super::arithmetic::mul;
use super::fine::{Fine, US};

/// Where in a transfer a register is latched: the bus's bit period and the start of the
/// transfer, from which a sensor service derives the latch instant of the byte it reads.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BusTiming {
    /// One SCL period (2.5 µs at 400 kHz; 0 for an instantaneous test bus).
    pub bit: Fine,
}

impl BusTiming {
    /// An SCL clock of `hz` (0 Hz: instantaneous transfers, as the host tests' simulated bus).
    pub const fn from_hz(hz: u32) -> Self {
        BusTiming {
            bit: Fine::from_raw(if hz == 0 {
                0
            } else {
                (1_000_000 * US.raw()) / hz as u64
            }),
        }
    }

    /// The instant, `bits` SCL periods after the transfer started at `start`, at which the
    /// target latches a byte: START (1) + address (9) + register (9) put a written data byte at
    /// 19; a repeated START (1) and the address again (9) put the first byte read at 29, the
    /// second at 38.
    pub const fn latch(&self, start: Fine, bits: u64) -> Fine {
        Fine::from_raw(start.raw() + self.duration(bits).raw())
    }

    /// `bits` SCL periods: one 32-bit multiply whenever the product fits (any bus of 62.5 kHz
    /// or more and a transfer under 2,048 bits).
    pub const fn duration(&self, bits: u64) -> Fine {
        let bit = self.bit.raw();
        Fine::from_raw(if bit >> 20 == 0 && bits >> 11 == 0 {
            ((bits as u32) * (bit as u32)) as u64
        } else {
            mul(bits, bit)
        })
    }
}

/// Bit of a written data byte (one-register write).
pub const WRITE_DATA_BIT: u64 = 19;
/// Bit of the first byte of a register read.
pub const READ_FIRST_BIT: u64 = 29;
/// Bit of the second byte of a register read.
pub const READ_SECOND_BIT: u64 = 38;

/// SCL periods of a whole register read of `n` bytes, to its STOP.
pub const fn read_bits(n: u64) -> u64 {
    READ_FIRST_BIT + 9 * n
}
