//! The control and status registers the driver writes and reads, each a type with its fields
//! ([`Register`]: address and byte), and the bit shared by GYRO_CONFIG and ACCEL_CONFIG.
use super::reg;
use crate::register::{flag, flags_register, Register};

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

flags_register! {
    /// USER_CTRL (RM 4.27), the FIFO bits.
    UserCtrl at reg::USER_CTRL => {
        /// FIFO_EN: the FIFO fills.
        fifo_en: 1 << 6,
        /// FIFO_RESET: empties the FIFO; acts only while FIFO_EN = 0, self-clearing.
        fifo_reset: 1 << 2,
    }
}

impl UserCtrl {
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

flags_register! {
    /// FIFO_EN (RM 4.6): which outputs go into the FIFO, in frame order accel, temperature,
    /// gyro.
    FifoEn at reg::FIFO_EN => {
        /// TEMP_FIFO_EN.
        temp: 1 << 7,
        /// XG_FIFO_EN, YG_FIFO_EN and ZG_FIFO_EN together.
        gyro: (1 << 6) | (1 << 5) | (1 << 4),
        /// ACCEL_FIFO_EN.
        accel: 1 << 3,
    }
}

flags_register! {
    /// INT_PIN_CFG (RM 4.14).
    IntPinCfg at reg::INT_PIN_CFG => {
        /// INT_LEVEL: active low.
        active_low: 1 << 7,
        /// INT_OPEN: open drain.
        open_drain: 1 << 6,
        /// LATCH_INT_EN: held until cleared instead of a 50 µs pulse.
        latch: 1 << 5,
        /// INT_RD_CLEAR: any read clears the status.
        clear_on_any_read: 1 << 4,
    }
}

flags_register! {
    /// INT_ENABLE (RM 4.15).
    IntEnable at reg::INT_ENABLE => {
        /// FIFO_OFLOW_EN.
        fifo_overflow: 1 << 4,
        /// DATA_RDY_EN.
        data_ready: 1 << 0,
    }
}

flags_register! {
    /// INT_STATUS (RM 4.16, the bits of INT_ENABLE), cleared by reading it.
    IntStatus at reg::INT_STATUS => {
        /// FIFO_OFLOW_INT.
        fifo_overflow: 1 << 4,
        /// DATA_RDY_INT.
        data_ready: 1 << 0,
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
