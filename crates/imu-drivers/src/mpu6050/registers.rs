//! Every configuration register of the MPU-6050 (and the status register the driver reads),
//! each a type with its named fields on the bit layout of the Register Map (RM, the section
//! of each register cited): the one table of the part's typed registers. Addresses are those of
//! [`super::reg`].
use super::{reg, AccelRange, GyroRange};
use crate::register::{field_enum, register, Register};

field_enum!(GyroRange, 2, [Dps250, Dps500, Dps1000; Dps2000]);
field_enum!(AccelRange, 2, [G2, G4, G8; G16]);

register! {
    /// SMPLRT_DIV (RM 4.2): Sample Rate = Gyroscope Output Rate / (1 + SMPLRT_DIV).
    #[derive(Default)]
    SmplrtDiv at reg::SMPLRT_DIV => {
        /// `SMPLRT_DIV[7:0]`.
        divider: u8 [0, 8],
    }
}

register! {
    /// CONFIG (RM 4.3): frame synchronisation and the digital low-pass filter.
    #[derive(Default)]
    ConfigReg at reg::CONFIG => {
        /// `EXT_SYNC_SET[5:3]`: which sensor's LSB the FSYNC pin latches (0: input disabled).
        ext_sync_set: u8 [3, 3],
        /// `DLPF_CFG[2:0]`: the filter ([`super::Dlpf`] as its code; 7 is reserved).
        dlpf_cfg: u8 [0, 3],
    }
}

register! {
    /// GYRO_CONFIG (RM 4.4): self-test per axis and the full-scale range.
    #[derive(Default)]
    GyroConfig at reg::GYRO_CONFIG => {
        /// XG_ST (bit 7).
        xg_st: bool [7, 1],
        /// YG_ST (bit 6).
        yg_st: bool [6, 1],
        /// ZG_ST (bit 5).
        zg_st: bool [5, 1],
        /// `FS_SEL[4:3]`.
        fs_sel: GyroRange [3, 2],
    }
}

impl GyroConfig {
    /// `range`, self-test off.
    pub const fn range(range: GyroRange) -> Self {
        GyroConfig {
            xg_st: false,
            yg_st: false,
            zg_st: false,
            fs_sel: range,
        }
    }
    /// `range`, self-test on for all three axes (RM 4.1).
    pub const fn self_test(range: GyroRange) -> Self {
        GyroConfig {
            xg_st: true,
            yg_st: true,
            zg_st: true,
            fs_sel: range,
        }
    }
}

register! {
    /// ACCEL_CONFIG (RM 4.5): self-test per axis and the full-scale range (bits 2:0 unused).
    AccelConfig at reg::ACCEL_CONFIG => {
        /// XA_ST (bit 7).
        xa_st: bool [7, 1],
        /// YA_ST (bit 6).
        ya_st: bool [6, 1],
        /// ZA_ST (bit 5).
        za_st: bool [5, 1],
        /// `AFS_SEL[4:3]`.
        afs_sel: AccelRange [3, 2],
    }
}

impl AccelConfig {
    /// `range`, self-test off.
    pub const fn range(range: AccelRange) -> Self {
        AccelConfig {
            xa_st: false,
            ya_st: false,
            za_st: false,
            afs_sel: range,
        }
    }
    /// `range`, self-test on for all three axes (RM 4.1).
    pub const fn self_test(range: AccelRange) -> Self {
        AccelConfig {
            xa_st: true,
            ya_st: true,
            za_st: true,
            afs_sel: range,
        }
    }
}

register! {
    /// ACCEL_CONFIG 2 of the MPU-6500 family (RM-6500 register 29; reserved on the MPU-6050):
    /// the accelerometer's own low-pass filter.
    #[derive(Default)]
    AccelConfig2 at reg::ACCEL_CONFIG2 => {
        /// ACCEL_FCHOICE_B (bit 3): 1 bypasses the filter.
        accel_fchoice_b: bool [3, 1],
        /// `A_DLPF_CFG[2:0]`.
        a_dlpf_cfg: u8 [0, 3],
    }
}

register! {
    /// FIFO_EN (RM 4.6): which outputs go into the FIFO, in frame order accel, temperature,
    /// gyro (then the external sensors).
    #[derive(Default)]
    FifoEn at reg::FIFO_EN => {
        /// TEMP_FIFO_EN (bit 7).
        temp: bool [7, 1],
        /// XG_FIFO_EN (bit 6).
        xg: bool [6, 1],
        /// YG_FIFO_EN (bit 5).
        yg: bool [5, 1],
        /// ZG_FIFO_EN (bit 4).
        zg: bool [4, 1],
        /// ACCEL_FIFO_EN (bit 3): all three axes.
        accel: bool [3, 1],
        /// SLV2_FIFO_EN (bit 2).
        slv2: bool [2, 1],
        /// SLV1_FIFO_EN (bit 1).
        slv1: bool [1, 1],
        /// SLV0_FIFO_EN (bit 0).
        slv0: bool [0, 1],
    }
}

register! {
    /// INT_PIN_CFG (RM 4.14).
    #[derive(Default)]
    IntPinCfg at reg::INT_PIN_CFG => {
        /// INT_LEVEL (bit 7): active low.
        active_low: bool [7, 1],
        /// INT_OPEN (bit 6): open drain.
        open_drain: bool [6, 1],
        /// LATCH_INT_EN (bit 5): held until cleared instead of a 50 µs pulse.
        latch: bool [5, 1],
        /// INT_RD_CLEAR (bit 4): any read clears the status.
        clear_on_any_read: bool [4, 1],
        /// FSYNC_INT_LEVEL (bit 3): FSYNC active low.
        fsync_active_low: bool [3, 1],
        /// FSYNC_INT_EN (bit 2): FSYNC raises an interrupt.
        fsync_int: bool [2, 1],
        /// I2C_BYPASS_EN (bit 1): the auxiliary bus joined to the host bus.
        i2c_bypass: bool [1, 1],
    }
}

register! {
    /// INT_ENABLE (RM 4.15).
    #[derive(Default)]
    IntEnable at reg::INT_ENABLE => {
        /// FIFO_OFLOW_EN (bit 4).
        fifo_overflow: bool [4, 1],
        /// I2C_MST_INT_EN (bit 3).
        i2c_master: bool [3, 1],
        /// DATA_RDY_EN (bit 0).
        data_ready: bool [0, 1],
    }
}

register! {
    /// INT_STATUS (RM 4.16, the bits of INT_ENABLE), cleared by reading it.
    #[derive(Default)]
    IntStatus at reg::INT_STATUS => {
        /// FIFO_OFLOW_INT (bit 4).
        fifo_overflow: bool [4, 1],
        /// I2C_MST_INT (bit 3).
        i2c_master: bool [3, 1],
        /// DATA_RDY_INT (bit 0).
        data_ready: bool [0, 1],
    }
}

register! {
    /// SIGNAL_PATH_RESET (RM 4.26): resets the analog and digital signal paths (not the
    /// registers).
    #[derive(Default)]
    SignalPathReset at reg::SIGNAL_PATH_RESET => {
        /// GYRO_RESET (bit 2).
        gyro: bool [2, 1],
        /// ACCEL_RESET (bit 1).
        accel: bool [1, 1],
        /// TEMP_RESET (bit 0).
        temp: bool [0, 1],
    }
}

register! {
    /// USER_CTRL (RM 4.27).
    #[derive(Default)]
    UserCtrl at reg::USER_CTRL => {
        /// FIFO_EN (bit 6): the FIFO fills.
        fifo_en: bool [6, 1],
        /// I2C_MST_EN (bit 5): the auxiliary bus master.
        i2c_master: bool [5, 1],
        /// I2C_IF_DIS (bit 4): always 0 on the MPU-6050.
        i2c_if_dis: bool [4, 1],
        /// FIFO_RESET (bit 2): empties the FIFO; acts only while FIFO_EN = 0, self-clearing.
        fifo_reset: bool [2, 1],
        /// I2C_MST_RESET (bit 1).
        i2c_master_reset: bool [1, 1],
        /// SIG_COND_RESET (bit 0): resets the signal paths and clears the sensor registers.
        sig_cond_reset: bool [0, 1],
    }
}

impl UserCtrl {
    /// FIFO filling.
    pub const FIFO_ON: Self = UserCtrl {
        fifo_en: true,
        i2c_master: false,
        i2c_if_dis: false,
        fifo_reset: false,
        i2c_master_reset: false,
        sig_cond_reset: false,
    };
    /// FIFO stopped and emptied.
    pub const FIFO_EMPTIED: Self = UserCtrl {
        fifo_en: false,
        i2c_master: false,
        i2c_if_dis: false,
        fifo_reset: true,
        i2c_master_reset: false,
        sig_cond_reset: false,
    };
}

register! {
    /// PWR_MGMT_1 (RM 4.28).
    #[derive(Default)]
    PwrMgmt1 at reg::PWR_MGMT_1 => {
        /// DEVICE_RESET (bit 7): resets every register; self-clearing.
        device_reset: bool [7, 1],
        /// SLEEP (bit 6).
        sleep: bool [6, 1],
        /// CYCLE (bit 5): wake for one sample at LP_WAKE_CTRL's rate, sleep between.
        cycle: bool [5, 1],
        /// TEMP_DIS (bit 3): temperature sensor off.
        temp_dis: bool [3, 1],
        /// `CLKSEL[2:0]` (0 internal 8 MHz oscillator, 1 PLL with the X gyro as reference, …).
        clksel: u8 [0, 3],
    }
}

impl PwrMgmt1 {
    /// CLKSEL = 1: PLL with X-axis gyroscope reference (RM 4.28, table).
    pub const CLKSEL_PLL_GYRO_X: u8 = 1;
    /// Awake, clocked from the X gyro's PLL: what `start` writes.
    pub const RUNNING: Self = PwrMgmt1 {
        device_reset: false,
        sleep: false,
        cycle: false,
        temp_dis: false,
        clksel: Self::CLKSEL_PLL_GYRO_X,
    };
    /// Reset every register.
    pub const RESET: Self = PwrMgmt1 {
        device_reset: true,
        sleep: false,
        cycle: false,
        temp_dis: false,
        clksel: 0,
    };
}

register! {
    /// PWR_MGMT_2 (RM 4.29): low-power wake rate and single axes in standby (the driver
    /// leaves every axis on).
    #[derive(Default)]
    PwrMgmt2 at reg::PWR_MGMT_2 => {
        /// `LP_WAKE_CTRL[7:6]`: 1.25, 5, 20 or 40 Hz in cycle mode.
        lp_wake_ctrl: u8 [6, 2],
        /// STBY_XA (bit 5).
        stby_xa: bool [5, 1],
        /// STBY_YA (bit 4).
        stby_ya: bool [4, 1],
        /// STBY_ZA (bit 3).
        stby_za: bool [3, 1],
        /// STBY_XG (bit 2).
        stby_xg: bool [2, 1],
        /// STBY_YG (bit 1).
        stby_yg: bool [1, 1],
        /// STBY_ZG (bit 0).
        stby_zg: bool [0, 1],
    }
}

/// The typed registers' addresses, by name, as the register map lists them: every one is a
/// register of [`reg::TABLE`].
pub const TYPED: &[(&str, u8)] = &[
    ("SMPLRT_DIV", SmplrtDiv::ADDR),
    ("CONFIG", ConfigReg::ADDR),
    ("GYRO_CONFIG", GyroConfig::ADDR),
    ("ACCEL_CONFIG", AccelConfig::ADDR),
    ("ACCEL_CONFIG2", AccelConfig2::ADDR),
    ("FIFO_EN", FifoEn::ADDR),
    ("INT_PIN_CFG", IntPinCfg::ADDR),
    ("INT_ENABLE", IntEnable::ADDR),
    ("INT_STATUS", IntStatus::ADDR),
    ("SIGNAL_PATH_RESET", SignalPathReset::ADDR),
    ("USER_CTRL", UserCtrl::ADDR),
    ("PWR_MGMT_1", PwrMgmt1::ADDR),
    ("PWR_MGMT_2", PwrMgmt2::ADDR),
];

#[cfg(test)]
mod tests {
    use super::*;
    use crate::register::check::layout;

    /// Each register's fields, one at a time, against the bits the Register Map gives them (RM
    /// 4.2–4.6, 4.14–4.16, 4.26–4.29; ACCEL_CONFIG 2: RM-6500 register 29).
    #[test]
    fn every_register_sits_on_the_register_maps_bits() {
        layout(0x19, 0xFF, &[(SmplrtDiv { divider: 0xA5 }, 0xA5)]);
        let c = ConfigReg::default();
        layout(
            0x1A,
            0b0011_1111,
            &[
                (
                    ConfigReg {
                        ext_sync_set: 7,
                        ..c
                    },
                    0b0011_1000,
                ),
                (
                    ConfigReg {
                        ext_sync_set: 1,
                        ..c
                    },
                    0b0000_1000,
                ),
                (ConfigReg { dlpf_cfg: 6, ..c }, 0b0000_0110),
                (ConfigReg { dlpf_cfg: 1, ..c }, 0b0000_0001),
            ],
        );
        let g = GyroConfig::default();
        layout(
            0x1B,
            0b1111_1000,
            &[
                (GyroConfig { xg_st: true, ..g }, 0b1000_0000),
                (GyroConfig { yg_st: true, ..g }, 0b0100_0000),
                (GyroConfig { zg_st: true, ..g }, 0b0010_0000),
                (GyroConfig::range(GyroRange::Dps500), 0b0000_1000),
                (GyroConfig::range(GyroRange::Dps1000), 0b0001_0000),
                (GyroConfig::range(GyroRange::Dps2000), 0b0001_1000),
                (GyroConfig::self_test(GyroRange::Dps250), 0b1110_0000),
            ],
        );
        let a = AccelConfig::range(AccelRange::G2);
        layout(
            0x1C,
            0b1111_1000,
            &[
                (AccelConfig { xa_st: true, ..a }, 0b1000_0000),
                (AccelConfig { ya_st: true, ..a }, 0b0100_0000),
                (AccelConfig { za_st: true, ..a }, 0b0010_0000),
                (AccelConfig::range(AccelRange::G4), 0b0000_1000),
                (AccelConfig::range(AccelRange::G8), 0b0001_0000),
                (AccelConfig::range(AccelRange::G16), 0b0001_1000),
                (AccelConfig::self_test(AccelRange::G8), 0b1111_0000),
            ],
        );
        let a2 = AccelConfig2::default();
        layout(
            0x1D,
            0b0000_1111,
            &[
                (
                    AccelConfig2 {
                        accel_fchoice_b: true,
                        ..a2
                    },
                    0b0000_1000,
                ),
                (
                    AccelConfig2 {
                        a_dlpf_cfg: 7,
                        ..a2
                    },
                    0b0000_0111,
                ),
            ],
        );
        let f = FifoEn::default();
        layout(
            0x23,
            0xFF,
            &[
                (FifoEn { temp: true, ..f }, 0b1000_0000),
                (FifoEn { xg: true, ..f }, 0b0100_0000),
                (FifoEn { yg: true, ..f }, 0b0010_0000),
                (FifoEn { zg: true, ..f }, 0b0001_0000),
                (FifoEn { accel: true, ..f }, 0b0000_1000),
                (FifoEn { slv2: true, ..f }, 0b0000_0100),
                (FifoEn { slv1: true, ..f }, 0b0000_0010),
                (FifoEn { slv0: true, ..f }, 0b0000_0001),
            ],
        );
        let p = IntPinCfg::default();
        layout(
            0x37,
            0b1111_1110,
            &[
                (
                    IntPinCfg {
                        active_low: true,
                        ..p
                    },
                    0b1000_0000,
                ),
                (
                    IntPinCfg {
                        open_drain: true,
                        ..p
                    },
                    0b0100_0000,
                ),
                (IntPinCfg { latch: true, ..p }, 0b0010_0000),
                (
                    IntPinCfg {
                        clear_on_any_read: true,
                        ..p
                    },
                    0b0001_0000,
                ),
                (
                    IntPinCfg {
                        fsync_active_low: true,
                        ..p
                    },
                    0b0000_1000,
                ),
                (
                    IntPinCfg {
                        fsync_int: true,
                        ..p
                    },
                    0b0000_0100,
                ),
                (
                    IntPinCfg {
                        i2c_bypass: true,
                        ..p
                    },
                    0b0000_0010,
                ),
            ],
        );
        let e = IntEnable::default();
        layout(
            0x38,
            0b0001_1001,
            &[
                (
                    IntEnable {
                        fifo_overflow: true,
                        ..e
                    },
                    0b0001_0000,
                ),
                (
                    IntEnable {
                        i2c_master: true,
                        ..e
                    },
                    0b0000_1000,
                ),
                (
                    IntEnable {
                        data_ready: true,
                        ..e
                    },
                    0b0000_0001,
                ),
            ],
        );
        let s = IntStatus::default();
        layout(
            0x3A,
            0b0001_1001,
            &[
                (
                    IntStatus {
                        fifo_overflow: true,
                        ..s
                    },
                    0b0001_0000,
                ),
                (
                    IntStatus {
                        i2c_master: true,
                        ..s
                    },
                    0b0000_1000,
                ),
                (
                    IntStatus {
                        data_ready: true,
                        ..s
                    },
                    0b0000_0001,
                ),
            ],
        );
        let r = SignalPathReset::default();
        layout(
            0x68,
            0b0000_0111,
            &[
                (SignalPathReset { gyro: true, ..r }, 0b0000_0100),
                (SignalPathReset { accel: true, ..r }, 0b0000_0010),
                (SignalPathReset { temp: true, ..r }, 0b0000_0001),
            ],
        );
        let u = UserCtrl::default();
        layout(
            0x6A,
            0b0111_0111,
            &[
                (UserCtrl::FIFO_ON, 0b0100_0000),
                (
                    UserCtrl {
                        i2c_master: true,
                        ..u
                    },
                    0b0010_0000,
                ),
                (
                    UserCtrl {
                        i2c_if_dis: true,
                        ..u
                    },
                    0b0001_0000,
                ),
                (UserCtrl::FIFO_EMPTIED, 0b0000_0100),
                (
                    UserCtrl {
                        i2c_master_reset: true,
                        ..u
                    },
                    0b0000_0010,
                ),
                (
                    UserCtrl {
                        sig_cond_reset: true,
                        ..u
                    },
                    0b0000_0001,
                ),
            ],
        );
        let m = PwrMgmt1::default();
        layout(
            0x6B,
            0b1110_1111,
            &[
                (PwrMgmt1::RESET, 0b1000_0000),
                (PwrMgmt1 { sleep: true, ..m }, 0b0100_0000),
                (PwrMgmt1 { cycle: true, ..m }, 0b0010_0000),
                (
                    PwrMgmt1 {
                        temp_dis: true,
                        ..m
                    },
                    0b0000_1000,
                ),
                (PwrMgmt1 { clksel: 7, ..m }, 0b0000_0111),
                (PwrMgmt1::RUNNING, 0b0000_0001),
            ],
        );
        let m2 = PwrMgmt2::default();
        layout(
            0x6C,
            0xFF,
            &[
                (
                    PwrMgmt2 {
                        lp_wake_ctrl: 3,
                        ..m2
                    },
                    0b1100_0000,
                ),
                (
                    PwrMgmt2 {
                        lp_wake_ctrl: 1,
                        ..m2
                    },
                    0b0100_0000,
                ),
                (
                    PwrMgmt2 {
                        stby_xa: true,
                        ..m2
                    },
                    0b0010_0000,
                ),
                (
                    PwrMgmt2 {
                        stby_ya: true,
                        ..m2
                    },
                    0b0001_0000,
                ),
                (
                    PwrMgmt2 {
                        stby_za: true,
                        ..m2
                    },
                    0b0000_1000,
                ),
                (
                    PwrMgmt2 {
                        stby_xg: true,
                        ..m2
                    },
                    0b0000_0100,
                ),
                (
                    PwrMgmt2 {
                        stby_yg: true,
                        ..m2
                    },
                    0b0000_0010,
                ),
                (
                    PwrMgmt2 {
                        stby_zg: true,
                        ..m2
                    },
                    0b0000_0001,
                ),
            ],
        );
    }

    /// The typed registers are the configuration registers of the one address table, under
    /// the same names.
    #[test]
    fn every_typed_register_is_in_the_address_table() {
        for entry in TYPED {
            assert!(reg::TABLE.contains(entry), "{entry:?}");
        }
        // Every register of the table that configures the part has a type.
        for name in [
            "SMPLRT_DIV",
            "CONFIG",
            "GYRO_CONFIG",
            "ACCEL_CONFIG",
            "ACCEL_CONFIG2",
            "FIFO_EN",
            "INT_PIN_CFG",
            "INT_ENABLE",
            "SIGNAL_PATH_RESET",
            "USER_CTRL",
            "PWR_MGMT_1",
            "PWR_MGMT_2",
        ] {
            assert!(TYPED.iter().any(|(n, _)| *n == name), "{name} untyped");
        }
    }
}
