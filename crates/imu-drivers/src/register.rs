//! A register and its bit fields as one type: its address and its value to and from the byte
//! on the bus. The drivers write and read configuration and status registers only through these
//! types (`write_register`, `read_register`), so a field cannot land in the wrong register or
//! the wrong bit. Each chip's registers are declared in one table, with `register!`:
//! [`crate::mpu6050::registers`], [`crate::qmc5883::registers`].

/// A one-byte register of a chip.
pub trait Register: Copy + Sized {
    /// Register address.
    const ADDR: u8;
    /// The byte this value writes.
    fn bits(self) -> u8;
    /// The value a read byte holds (bits this type does not name are ignored).
    fn from_bits(bits: u8) -> Self;
    /// The bytes of a one-register write of this value: the address, then the byte.
    #[inline]
    fn write_bytes(self) -> [u8; 2] {
        [Self::ADDR, self.bits()]
    }
}

/// What a register field holds, as its code in the field's bits: a flag (`bool`), a number
/// (`u8`, the field's raw code) or an enum with one variant per code.
pub trait Field: Copy {
    /// The field's code (only the field's width of it is written).
    fn code(self) -> u8;
    /// The value of a code (already masked to the field's width).
    fn from_code(code: u8) -> Self;
}

impl Field for bool {
    #[inline]
    fn code(self) -> u8 {
        self as u8
    }
    #[inline]
    fn from_code(code: u8) -> Self {
        code != 0
    }
}

impl Field for u8 {
    #[inline]
    fn code(self) -> u8 {
        self
    }
    #[inline]
    fn from_code(code: u8) -> Self {
        code
    }
}

/// The low `width` bits set.
#[inline]
pub const fn mask(width: u32) -> u8 {
    ((1u16 << width) - 1) as u8
}

/// The [`Field`] impl of a C-like enum whose discriminants are the codes of a field `$width`
/// bits wide, one variant per code: the variants in any order, the last after `;` taking every
/// code the others do not (so decoding is total without a panic path).
macro_rules! field_enum {
    ($ty:ident, $width:expr, [$($variant:ident),+ ; $last:ident]) => {
        impl $crate::register::Field for $ty {
            #[inline]
            fn code(self) -> u8 {
                self as u8
            }
            #[inline]
            fn from_code(code: u8) -> Self {
                let code = code & $crate::register::mask($width);
                $( if code == $ty::$variant as u8 {
                    return $ty::$variant;
                } )+
                $ty::$last
            }
        }
    };
}
pub(crate) use field_enum;

/// A register: the struct (one public field per named bit field, each declared as
/// `name: Type [shift, width]` after the datasheet's bit layout) and its [`Register`] impl.
/// Attributes before the name (docs, `#[derive(Default)]`) go on the struct.
macro_rules! register {
    (
        $(#[$attr:meta])*
        $name:ident at $addr:expr => {
            $( $(#[$fdoc:meta])* $field:ident: $ty:ty [$shift:expr, $width:expr] ),+ $(,)?
        }
    ) => {
        $(#[$attr])*
        #[derive(Debug, Clone, Copy, PartialEq, Eq)]
        #[cfg_attr(feature = "defmt", derive(defmt::Format))]
        pub struct $name {
            $( $(#[$fdoc])* pub $field: $ty, )+
        }

        impl $crate::register::Register for $name {
            const ADDR: u8 = $addr;
            #[inline]
            fn bits(self) -> u8 {
                0 $( | (($crate::register::Field::code(self.$field)
                    & $crate::register::mask($width)) << $shift) )+
            }
            #[inline]
            fn from_bits(b: u8) -> Self {
                $name {
                    $( $field: $crate::register::Field::from_code(
                        (b >> $shift) & $crate::register::mask($width),
                    ), )+
                }
            }
        }
    };
}
pub(crate) use register;

/// Checks of a register type against its datasheet layout, for the chips' register tables.
#[cfg(test)]
pub(crate) mod check {
    use super::Register;
    use core::fmt::Debug;

    /// `R` sits at `addr`; each value of `bytes` writes exactly its byte (each written out from
    /// the datasheet, one field at a time, so a field on a wrong bit fails); and every byte
    /// reads back as the fields that write it again, limited to the `named` bits (so a bit two
    /// fields claim, or one no field covers, fails).
    pub fn layout<R: Register + Debug + PartialEq>(addr: u8, named: u8, bytes: &[(R, u8)]) {
        let name = core::any::type_name::<R>();
        assert_eq!(R::ADDR, addr, "{name}: address");
        for (value, byte) in bytes {
            assert_eq!(value.bits(), *byte, "{name}: {value:?}");
            assert_eq!(R::from_bits(*byte), *value, "{name}: {byte:#010b}");
        }
        for b in 0..=255u8 {
            let r = R::from_bits(b);
            assert_eq!(r.bits(), b & named, "{name}: {b:#010b} reads as {r:?}");
            assert_eq!(R::from_bits(r.bits()), r, "{name}: {b:#010b}");
        }
    }
}
