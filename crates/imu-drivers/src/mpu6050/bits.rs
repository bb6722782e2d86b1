//! The control and status registers the driver writes and reads, each a type with its fields
//! ([`Register`]: address and byte), and the bit shared by GYRO_CONFIG and ACCEL_CONFIG.
use super::reg;
use crate::register::{flag, Register};

/// GYRO_CONFIG XG_ST|YG_ST|ZG_ST and ACCEL_CONFIG XA_ST|YA_ST|ZA_ST (RM 4.4, 4.5).
pub const SELF_TEST_XYZ: u8 = 0xE0;

/// PWR_MGMT_1 (RM 4.28).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PwrMgmt1 {
    /// DEVICE_RESET: resets every register; self-clearing.
    pub device_reset: bool,
    /// SLEEP.
    pub sleep: bool,
    /// CLKSEL (0 internal 8 MHz oscillator, 1 PLL with the X gyro as reference, …).
    pub clksel: u8,
}

impl PwrMgmt1 {
    const DEVICE_RESET: u8 = 1 << 7;
    const SLEEP: u8 = 1 << 6;
    const CLKSEL: u8 = 0x07;
    /// CLKSEL = 1: PLL with X-axis gyroscope reference (RM 4.28, table).
    pub const CLKSEL_PLL_GYRO_X: u8 = 1;
    /// Awake, clocked from the X gyro's PLL: what `start` writes.
    pub const RUNNING: Self = PwrMgmt1 {
        device_reset: false,
        sleep: false,
        clksel: Self::CLKSEL_PLL_GYRO_X,
    };
    /// Reset every register.
    pub const RESET: Self = PwrMgmt1 {
        device_reset: true,
        sleep: false,
        clksel: 0,
    };
}

impl Register for PwrMgmt1 {
    const ADDR: u8 = reg::PWR_MGMT_1;
    fn bits(self) -> u8 {
        flag(self.device_reset, Self::DEVICE_RESET)
            | flag(self.sleep, Self::SLEEP)
            | (self.clksel & Self::CLKSEL)
    }
    fn from_bits(b: u8) -> Self {
        PwrMgmt1 {
            device_reset: b & Self::DEVICE_RESET != 0,
            sleep: b & Self::SLEEP != 0,
            clksel: b & Self::CLKSEL,
        }
    }
}

/// USER_CTRL (RM 4.27), the FIFO bits.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct UserCtrl {
    /// FIFO_EN: the FIFO fills.
    pub fifo_en: bool,
    /// FIFO_RESET: empties the FIFO; acts only while FIFO_EN = 0, self-clearing.
    pub fifo_reset: bool,
}

impl UserCtrl {
    const FIFO_EN: u8 = 1 << 6;
    const FIFO_RESET: u8 = 1 << 2;
    /// FIFO filling.
    pub const FIFO_ON: Self = UserCtrl {
        fifo_en: true,
        fifo_reset: false,
    };
    /// FIFO stopped and emptied.
    pub const FIFO_EMPTIED: Self = UserCtrl {
        fifo_en: false,
        fifo_reset: true,
    };
}

impl Register for UserCtrl {
    const ADDR: u8 = reg::USER_CTRL;
    fn bits(self) -> u8 {
        flag(self.fifo_en, Self::FIFO_EN) | flag(self.fifo_reset, Self::FIFO_RESET)
    }
    fn from_bits(b: u8) -> Self {
        UserCtrl {
            fifo_en: b & Self::FIFO_EN != 0,
            fifo_reset: b & Self::FIFO_RESET != 0,
        }
    }
}

/// FIFO_EN (RM 4.6): which outputs go into the FIFO, in frame order accel, temperature, gyro.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FifoEn {
    /// TEMP_FIFO_EN.
    pub temp: bool,
    /// XG_FIFO_EN, YG_FIFO_EN and ZG_FIFO_EN together.
    pub gyro: bool,
    /// ACCEL_FIFO_EN.
    pub accel: bool,
}

impl FifoEn {
    const TEMP: u8 = 1 << 7;
    const GYRO_XYZ: u8 = (1 << 6) | (1 << 5) | (1 << 4);
    const ACCEL: u8 = 1 << 3;
}

impl Register for FifoEn {
    const ADDR: u8 = reg::FIFO_EN;
    fn bits(self) -> u8 {
        flag(self.temp, Self::TEMP)
            | flag(self.gyro, Self::GYRO_XYZ)
            | flag(self.accel, Self::ACCEL)
    }
    fn from_bits(b: u8) -> Self {
        FifoEn {
            temp: b & Self::TEMP != 0,
            gyro: b & Self::GYRO_XYZ == Self::GYRO_XYZ,
            accel: b & Self::ACCEL != 0,
        }
    }
}

/// INT_PIN_CFG (RM 4.14).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct IntPinCfg {
    /// INT_LEVEL: active low.
    pub active_low: bool,
    /// INT_OPEN: open drain.
    pub open_drain: bool,
    /// LATCH_INT_EN: held until cleared instead of a 50 µs pulse.
    pub latch: bool,
    /// INT_RD_CLEAR: any read clears the status.
    pub clear_on_any_read: bool,
}

impl IntPinCfg {
    const LEVEL_LOW: u8 = 1 << 7;
    const OPEN_DRAIN: u8 = 1 << 6;
    const LATCH: u8 = 1 << 5;
    const RD_CLEAR: u8 = 1 << 4;
}

impl Register for IntPinCfg {
    const ADDR: u8 = reg::INT_PIN_CFG;
    fn bits(self) -> u8 {
        flag(self.active_low, Self::LEVEL_LOW)
            | flag(self.open_drain, Self::OPEN_DRAIN)
            | flag(self.latch, Self::LATCH)
            | flag(self.clear_on_any_read, Self::RD_CLEAR)
    }
    fn from_bits(b: u8) -> Self {
        IntPinCfg {
            active_low: b & Self::LEVEL_LOW != 0,
            open_drain: b & Self::OPEN_DRAIN != 0,
            latch: b & Self::LATCH != 0,
            clear_on_any_read: b & Self::RD_CLEAR != 0,
        }
    }
}

/// FIFO_OFLOW and DATA_RDY: the same bits in INT_ENABLE (RM 4.15) and INT_STATUS (RM 4.16).
const INT_FIFO_OFLOW: u8 = 1 << 4;
const INT_DATA_RDY: u8 = 1 << 0;

/// INT_ENABLE (RM 4.15).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct IntEnable {
    /// FIFO_OFLOW_EN.
    pub fifo_overflow: bool,
    /// DATA_RDY_EN.
    pub data_ready: bool,
}

impl Register for IntEnable {
    const ADDR: u8 = reg::INT_ENABLE;
    fn bits(self) -> u8 {
        flag(self.fifo_overflow, INT_FIFO_OFLOW) | flag(self.data_ready, INT_DATA_RDY)
    }
    fn from_bits(b: u8) -> Self {
        IntEnable {
            fifo_overflow: b & INT_FIFO_OFLOW != 0,
            data_ready: b & INT_DATA_RDY != 0,
        }
    }
}

/// INT_STATUS (RM 4.16), cleared by reading it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct IntStatus {
    /// FIFO_OFLOW_INT.
    pub fifo_overflow: bool,
    /// DATA_RDY_INT.
    pub data_ready: bool,
}

impl IntStatus {
    /// Decode INT_STATUS.
    pub const fn from_bits(b: u8) -> Self {
        IntStatus {
            fifo_overflow: b & INT_FIFO_OFLOW != 0,
            data_ready: b & INT_DATA_RDY != 0,
        }
    }
}

impl Register for IntStatus {
    const ADDR: u8 = reg::INT_STATUS;
    fn bits(self) -> u8 {
        flag(self.fifo_overflow, INT_FIFO_OFLOW) | flag(self.data_ready, INT_DATA_RDY)
    }
    fn from_bits(b: u8) -> Self {
        IntStatus::from_bits(b)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every byte a register's fields can express reads back as the same fields, and the
    /// documented bit positions hold (RM 4.6, 4.14-4.16, 4.27, 4.28).
    #[test]
    fn fields_sit_on_the_documented_bits_and_round_trip() {
        assert_eq!(PwrMgmt1::RESET.bits(), 0x80);
        assert_eq!(PwrMgmt1::RUNNING.bits(), 0x01);
        assert!(PwrMgmt1::from_bits(0x40).sleep);
        assert_eq!(UserCtrl::FIFO_ON.bits(), 0x40);
        assert_eq!(UserCtrl::FIFO_EMPTIED.bits(), 0x04);
        let all = FifoEn {
            temp: true,
            gyro: true,
            accel: true,
        };
        assert_eq!(all.bits(), 0xF8);
        assert_eq!(
            IntPinCfg {
                active_low: true,
                open_drain: false,
                latch: true,
                clear_on_any_read: false,
            }
            .bits(),
            0xA0
        );
        assert_eq!(
            IntEnable {
                fifo_overflow: true,
                data_ready: true
            }
            .bits(),
            0x11
        );
        for b in 0..=255u8 {
            let p = PwrMgmt1::from_bits(b);
            assert_eq!(PwrMgmt1::from_bits(p.bits()), p);
            assert_eq!(p.bits(), b & 0xC7, "PWR_MGMT_1 {b:#04x}");
            let u = UserCtrl::from_bits(b);
            assert_eq!(u.bits(), b & 0x44, "USER_CTRL {b:#04x}");
            let f = FifoEn::from_bits(b);
            assert_eq!(FifoEn::from_bits(f.bits()), f);
            assert_eq!(
                IntPinCfg::from_bits(b).bits(),
                b & 0xF0,
                "INT_PIN_CFG {b:#04x}"
            );
            assert_eq!(
                IntStatus::from_bits(b).bits(),
                b & 0x11,
                "INT_STATUS {b:#04x}"
            );
            assert_eq!(
                IntEnable::from_bits(b).bits(),
                b & 0x11,
                "INT_ENABLE {b:#04x}"
            );
        }
        assert_eq!(
            [
                PwrMgmt1::ADDR,
                UserCtrl::ADDR,
                FifoEn::ADDR,
                IntPinCfg::ADDR,
                IntEnable::ADDR,
                IntStatus::ADDR
            ],
            [0x6B, 0x6A, 0x23, 0x37, 0x38, 0x3A]
        );
    }
}
