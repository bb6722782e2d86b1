//! Every configuration register of the QMC5883L and of the QMC5883P, each a type with its named
//! fields on the datasheet's bit layout (QMC-L 9.2, the QMC-P register map): the one table of
//! each part's typed registers. Addresses are those of [`super::reg_l`] and [`super::reg_p`].
use super::{reg_l, reg_p, Odr, Osr};
use crate::register::{field_enum, register, Register};

field_enum!(Osr, 2, [Max, High, Low; Min]);
field_enum!(Odr, 2, [Hz10, Hz50, Hz100; Hz200]);

/// QMC5883P CONTROL1 `MODE[1:0]` (QMC-P register map).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ModeP {
    /// 00: suspend.
    #[default]
    Suspend = 0,
    /// 01: normal.
    Normal = 1,
    /// 10: single measurement.
    Single = 2,
    /// 11: continuous.
    Continuous = 3,
}
field_enum!(ModeP, 2, [Suspend, Normal, Single; Continuous]);

/// QMC5883P CONTROL2 `RNG[3:2]` (QMC-P register map): the full-scale range.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum RangeP {
    /// 00: ±30 G (the reset value).
    #[default]
    G30 = 0,
    /// 01: ±12 G.
    G12 = 1,
    /// 10: ±8 G.
    G8 = 2,
    /// 11: ±2 G.
    G2 = 3,
}
field_enum!(RangeP, 2, [G30, G12, G8; G2]);

register! {
    /// QMC5883L CONTROL1 (QMC-L 9.2, control register 1).
    Control1L at reg_l::CONTROL1 => {
        /// `OSR[7:6]`: over-sampling 512, 256, 128, 64.
        osr: Osr [6, 2],
        /// `RNG[5:4]`: [`Control1L::RNG_2G`] or [`Control1L::RNG_8G`] (10 and 11 reserved).
        rng: u8 [4, 2],
        /// `ODR[3:2]`: 10, 50, 100, 200 Hz.
        odr: Odr [2, 2],
        /// `MODE[1:0]`: [`Control1L::MODE_STANDBY`] or [`Control1L::MODE_CONTINUOUS`] (10 and 11
        /// reserved).
        mode: u8 [0, 2],
    }
}

impl Control1L {
    /// RNG 00: ±2 G.
    pub const RNG_2G: u8 = 0;
    /// RNG 01: ±8 G.
    pub const RNG_8G: u8 = 1;
    /// MODE 00: standby.
    pub const MODE_STANDBY: u8 = 0;
    /// MODE 01: continuous.
    pub const MODE_CONTINUOUS: u8 = 1;
}

register! {
    /// QMC5883L CONTROL2 (QMC-L 9.2.3).
    #[derive(Default)]
    Control2L at reg_l::CONTROL2 => {
        /// SOFT_RST (bit 7): restores every register's default; self-clearing.
        soft_reset: bool [7, 1],
        /// ROL_PNT (bit 6): a read that starts in 00H–06H rolls over from 06H to 00H.
        roll_over: bool [6, 1],
        /// INT_ENB (bit 0): 1 disables the DRDY pin.
        drdy_pin_off: bool [0, 1],
    }
}

impl Control2L {
    /// A soft reset.
    pub const RESET: Self = Control2L {
        soft_reset: true,
        roll_over: false,
        drdy_pin_off: false,
    };
}

register! {
    /// QMC5883L SET/RESET period (QMC-L 9.2, register 0BH: "recommended ... 0x01").
    #[derive(Default)]
    SetResetPeriod at reg_l::SET_RESET_PERIOD => {
        /// `FBR[7:0]`.
        fbr: u8 [0, 8],
    }
}

register! {
    /// QMC5883P CONTROL1 (QMC-P register map).
    Control1P at reg_p::CONTROL1 => {
        /// `OSR2[7:6]`: down-sampling 1, 2, 4, 8 (as its code).
        osr2: u8 [6, 2],
        /// `OSR1[5:4]`: over-sampling 8, 4, 2, 1.
        osr1: Osr [4, 2],
        /// `ODR[3:2]`: 10, 50, 100, 200 Hz.
        odr: Odr [2, 2],
        /// `MODE[1:0]`.
        mode: ModeP [0, 2],
    }
}

register! {
    /// QMC5883P CONTROL2 (QMC-P register map).
    #[derive(Default)]
    Control2P at reg_p::CONTROL2 => {
        /// SOFT_RST (bit 7).
        soft_reset: bool [7, 1],
        /// SELF_TEST (bit 6).
        self_test: bool [6, 1],
        /// `RNG[3:2]`.
        range: RangeP [2, 2],
        /// SET/RESET `mode[1:0]`: 00 set and reset on, 01 set only, 1x set and reset off.
        set_reset: u8 [0, 2],
    }
}

impl Control2P {
    /// A soft reset (the range field then reads ±30 G, its reset value).
    pub const RESET: Self = Control2P {
        soft_reset: true,
        self_test: false,
        range: RangeP::G30,
        set_reset: 0,
    };
}

register! {
    /// QMC5883P axis sign definition (0x29). The datasheet names it "define the sign for X, Y
    /// and Z axis" without a bit layout, and its continuous-mode example (QMC-P 7.2) writes
    /// [`AxisSign::DATASHEET`]: one field, the whole byte.
    #[derive(Default)]
    AxisSign at reg_p::AXIS_SIGN => {
        /// The byte.
        signs: u8 [0, 8],
    }
}

impl AxisSign {
    /// The value of the datasheet's set-up example, 0x06.
    pub const DATASHEET: Self = AxisSign {
        signs: reg_p::AXIS_SIGN_VALUE,
    };
}

/// The QMC5883L's typed registers' addresses, by name: every one is in [`reg_l::TABLE`].
pub const TYPED_L: &[(&str, u8)] = &[
    ("CONTROL1", Control1L::ADDR),
    ("CONTROL2", Control2L::ADDR),
    ("SET_RESET_PERIOD", SetResetPeriod::ADDR),
];

/// The QMC5883P's typed registers' addresses, by name: every one is in [`reg_p::TABLE`].
pub const TYPED_P: &[(&str, u8)] = &[
    ("CONTROL1", Control1P::ADDR),
    ("CONTROL2", Control2P::ADDR),
    ("AXIS_SIGN", AxisSign::ADDR),
];

#[cfg(test)]
mod tests {
    use super::*;
    use crate::register::check::layout;

    /// Each register's fields, one at a time, against the bits the datasheets give them (QMC-L
    /// 9.2; the QMC-P register map).
    #[test]
    fn every_register_sits_on_the_datasheets_bits() {
        let c1 = Control1L::from_bits(0);
        layout(
            0x09,
            0xFF,
            &[
                (
                    Control1L {
                        osr: Osr::Min,
                        ..c1
                    },
                    0b1100_0000,
                ),
                (
                    Control1L {
                        osr: Osr::High,
                        ..c1
                    },
                    0b0100_0000,
                ),
                (Control1L { rng: 3, ..c1 }, 0b0011_0000),
                (
                    Control1L {
                        rng: Control1L::RNG_8G,
                        ..c1
                    },
                    0b0001_0000,
                ),
                (
                    Control1L {
                        odr: Odr::Hz200,
                        ..c1
                    },
                    0b0000_1100,
                ),
                (
                    Control1L {
                        odr: Odr::Hz50,
                        ..c1
                    },
                    0b0000_0100,
                ),
                (Control1L { mode: 3, ..c1 }, 0b0000_0011),
                (
                    Control1L {
                        mode: Control1L::MODE_CONTINUOUS,
                        ..c1
                    },
                    0b0000_0001,
                ),
            ],
        );
        let c2 = Control2L::default();
        layout(
            0x0A,
            0b1100_0001,
            &[
                (Control2L::RESET, 0b1000_0000),
                (
                    Control2L {
                        roll_over: true,
                        ..c2
                    },
                    0b0100_0000,
                ),
                (
                    Control2L {
                        drdy_pin_off: true,
                        ..c2
                    },
                    0b0000_0001,
                ),
            ],
        );
        layout(0x0B, 0xFF, &[(SetResetPeriod { fbr: 0x01 }, 0x01)]);
        let p1 = Control1P::from_bits(0);
        layout(
            0x0A,
            0xFF,
            &[
                (Control1P { osr2: 3, ..p1 }, 0b1100_0000),
                (Control1P { osr2: 1, ..p1 }, 0b0100_0000),
                (
                    Control1P {
                        osr1: Osr::Min,
                        ..p1
                    },
                    0b0011_0000,
                ),
                (
                    Control1P {
                        osr1: Osr::High,
                        ..p1
                    },
                    0b0001_0000,
                ),
                (
                    Control1P {
                        odr: Odr::Hz200,
                        ..p1
                    },
                    0b0000_1100,
                ),
                (
                    Control1P {
                        odr: Odr::Hz100,
                        ..p1
                    },
                    0b0000_1000,
                ),
                (
                    Control1P {
                        mode: ModeP::Continuous,
                        ..p1
                    },
                    0b0000_0011,
                ),
                (
                    Control1P {
                        mode: ModeP::Normal,
                        ..p1
                    },
                    0b0000_0001,
                ),
                (
                    Control1P {
                        mode: ModeP::Single,
                        ..p1
                    },
                    0b0000_0010,
                ),
            ],
        );
        let p2 = Control2P::default();
        layout(
            0x0B,
            0b1100_1111,
            &[
                (Control2P::RESET, 0b1000_0000),
                (
                    Control2P {
                        self_test: true,
                        ..p2
                    },
                    0b0100_0000,
                ),
                (
                    Control2P {
                        range: RangeP::G2,
                        ..p2
                    },
                    0b0000_1100,
                ),
                (
                    Control2P {
                        range: RangeP::G12,
                        ..p2
                    },
                    0b0000_0100,
                ),
                (
                    Control2P {
                        range: RangeP::G8,
                        ..p2
                    },
                    0b0000_1000,
                ),
                (Control2P { set_reset: 3, ..p2 }, 0b0000_0011),
                (Control2P { set_reset: 1, ..p2 }, 0b0000_0001),
            ],
        );
        layout(0x29, 0xFF, &[(AxisSign::DATASHEET, 0x06)]);
    }

    /// What the default configuration writes (the one of Jaime et al.): L CONTROL1 = OSR 512,
    /// ±2 G, 200 Hz, continuous; P CONTROL1 = OSR1 8, 200 Hz, continuous; P CONTROL2 = ±2 G.
    #[test]
    fn the_default_configuration_writes_the_datasheets_bytes() {
        let c = super::super::Config::default();
        assert_eq!(c.control1_l().map(|r| r.bits()), Some(0b0000_1101));
        assert_eq!(c.control2_l().bits(), 0x00);
        assert_eq!(c.set_reset_period_l().bits(), 0x01);
        assert_eq!(c.control1_p().bits(), 0b0000_1111);
        assert_eq!(c.control2_p().bits(), 0b0000_1100);
        let pinless = super::super::Config {
            drdy_pin: false,
            roll_over: true,
            ..c
        };
        assert_eq!(pinless.control2_l().bits(), 0x41);
    }

    /// The typed registers are registers of their part's one address table, under the same
    /// names.
    #[test]
    fn every_typed_register_is_in_its_address_table() {
        for entry in TYPED_L {
            assert!(reg_l::TABLE.contains(entry), "L {entry:?}");
        }
        for entry in TYPED_P {
            assert!(reg_p::TABLE.contains(entry), "P {entry:?}");
        }
    }
}
