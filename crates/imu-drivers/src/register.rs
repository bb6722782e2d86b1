//! A register and its bit fields as one type: its address and its value to and from the byte
//! on the bus. The drivers write and read control and status registers only through these
//! types (`write_register`, `read_register`), so a field cannot land in the wrong register or
//! the wrong bit.

/// A one-byte register of a chip.
pub trait Register: Copy + Sized {
    /// Register address.
    const ADDR: u8;
    /// The byte this value writes.
    fn bits(self) -> u8;
    /// The value a read byte holds (bits this type does not name are ignored).
    fn from_bits(bits: u8) -> Self;
}

/// `mask` if `on`, else 0.
pub(crate) const fn flag(on: bool, mask: u8) -> u8 {
    if on {
        mask
    } else {
        0
    }
}

/// A register made only of flags: the struct (one `bool` per field, each with its mask; a
/// multi-bit mask reads as set only when all its bits are) and its [`Register`] impl.
macro_rules! flags_register {
    (
        $(#[$doc:meta])*
        $name:ident at $addr:expr => {
            $( $(#[$fdoc:meta])* $field:ident: $mask:expr ),+ $(,)?
        }
    ) => {
        $(#[$doc])*
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
        #[cfg_attr(feature = "defmt", derive(defmt::Format))]
        pub struct $name {
            $( $(#[$fdoc])* pub $field: bool, )+
        }

        impl $crate::register::Register for $name {
            const ADDR: u8 = $addr;
            fn bits(self) -> u8 {
                0 $( | $crate::register::flag(self.$field, $mask) )+
            }
            fn from_bits(b: u8) -> Self {
                $name {
                    $( $field: b & $mask == $mask, )+
                }
            }
        }
    };
}
pub(crate) use flags_register;
