//! I²C bus recovery: clock out up to nine SCL pulses until a slave that is holding SDA low
//! (typically after a reset in the middle of a read) lets go, then send a STOP.
//!
//! Reference: NXP UM10204 "I²C-bus specification and user manual" rev 7, section 3.1.16
//! "Bus clear": "If the data line (SDA) is stuck LOW, the controller should send nine clock
//! pulses. The device that held the bus LOW should release it sometime within those nine
//! clocks."
//!
//! The pins must be open-drain (or emulate it: `set_high` releases the line to the pull-up),
//! and the I²C peripheral must not own them while this runs. SDA must also be readable.

use embedded_hal::delay::DelayNs;
use embedded_hal::digital::{InputPin, OutputPin};

/// Pulses clocked out at most (UM10204 3.1.16).
pub const MAX_PULSES: u8 = 9;

/// What the recovery did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Recovery {
    /// SCL pulses sent before SDA read high (0 if it was already free).
    pub pulses: u8,
    /// SDA read high after the STOP: the bus is free.
    pub sda_released: bool,
}

/// A pin failed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum RecoveryError<ESCL, ESDA> {
    /// SCL pin error.
    Scl(ESCL),
    /// SDA pin error.
    Sda(ESDA),
}

/// Clock out up to nine pulses on `scl` until `sda` reads high, then generate a STOP
/// (SDA low → high while SCL is high). `half_period_us` is half an SCL period (5 µs for
/// 100 kHz). Returns whether SDA was released; a slave still holding SDA after nine pulses
/// means a hardware fault (power-cycle the sensor).
pub fn recover_bus<SCL, SDA, D>(
    scl: &mut SCL,
    sda: &mut SDA,
    delay: &mut D,
    half_period_us: u32,
) -> Result<Recovery, RecoveryError<SCL::Error, SDA::Error>>
where
    SCL: OutputPin,
    SDA: OutputPin + InputPin,
    D: DelayNs,
{
    use RecoveryError::{Scl, Sda};
    sda.set_high().map_err(Sda)?;
    scl.set_high().map_err(Scl)?;
    delay.delay_us(half_period_us);
    let mut pulses = 0;
    while pulses < MAX_PULSES && sda.is_low().map_err(Sda)? {
        scl.set_low().map_err(Scl)?;
        delay.delay_us(half_period_us);
        scl.set_high().map_err(Scl)?;
        delay.delay_us(half_period_us);
        pulses += 1;
    }
    // STOP: SDA rises while SCL is high.
    scl.set_low().map_err(Scl)?;
    delay.delay_us(half_period_us);
    sda.set_low().map_err(Sda)?;
    delay.delay_us(half_period_us);
    scl.set_high().map_err(Scl)?;
    delay.delay_us(half_period_us);
    sda.set_high().map_err(Sda)?;
    delay.delay_us(half_period_us);
    let sda_released = sda.is_high().map_err(Sda)?;
    Ok(Recovery {
        pulses,
        sda_released,
    })
}
