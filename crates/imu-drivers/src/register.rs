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
