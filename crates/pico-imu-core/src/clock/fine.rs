//! The clock's unit of time: [`Fine`], the RP2040's µs timer in 1/65536 µs.
use core::ops::{Add, AddAssign, Div, Mul, Sub, SubAssign};

/// A time on the RP2040's µs timer in 1/65536 µs, or a duration in those units. Arithmetic is
/// that of the `u64` it holds (overflow checked in debug builds, as for a bare `u64`); the
/// wrapping and signed forms the clock needs are named methods.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(transparent)]
pub struct Fine(u64);

/// Fractional bits of [`Fine`].
pub const FINE_BITS: u32 = 16;

/// One µs.
pub const US: Fine = Fine(1 << FINE_BITS);

/// `us` µs as [`Fine`].
pub const fn fine(us: u64) -> Fine {
    Fine(us << FINE_BITS)
}

/// A [`Fine`] time rounded to whole µs.
pub const fn whole_us(t: Fine) -> u64 {
    (t.0 + (US.0 >> 1)) >> FINE_BITS
}

impl Fine {
    /// Zero: the timer's origin, or no time.
    pub const ZERO: Fine = Fine(0);

    /// A time or duration of `raw` units of 1/65536 µs.
    #[inline]
    pub const fn from_raw(raw: u64) -> Self {
        Fine(raw)
    }

    /// The number of 1/65536 µs units.
    #[inline]
    pub const fn raw(self) -> u64 {
        self.0
    }

    /// Rounded to whole ns.
    #[inline]
    pub const fn ns(self) -> u64 {
        (self.0 * 1000 + (US.0 >> 1)) >> FINE_BITS
    }

    /// `self + d` modulo 2^64 units.
    #[inline]
    pub const fn wrapping_add(self, d: Fine) -> Fine {
        Fine(self.0.wrapping_add(d.0))
    }

    /// `self − d` modulo 2^64 units.
    #[inline]
    pub const fn wrapping_sub(self, d: Fine) -> Fine {
        Fine(self.0.wrapping_sub(d.0))
    }

    /// `self + d` for a signed offset `d` (units), modulo 2^64 units.
    #[inline]
    pub const fn wrapping_add_signed(self, d: i64) -> Fine {
        Fine(self.0.wrapping_add(d as u64))
    }

    /// `self − d`, or zero if `d` is later.
    #[inline]
    pub const fn saturating_sub(self, d: Fine) -> Fine {
        Fine(self.0.saturating_sub(d.0))
    }

    /// `|self − other|`.
    #[inline]
    pub const fn abs_diff(self, other: Fine) -> Fine {
        Fine(self.0.abs_diff(other.0))
    }

    /// `self − origin` as signed units (both times below 2^63 units, 4.4 years of uptime).
    #[inline]
    pub const fn since(self, origin: Fine) -> i64 {
        self.0 as i64 - origin.0 as i64
    }
}

impl Add for Fine {
    type Output = Fine;
    #[inline]
    fn add(self, d: Fine) -> Fine {
        Fine(self.0 + d.0)
    }
}

impl AddAssign for Fine {
    #[inline]
    fn add_assign(&mut self, d: Fine) {
        self.0 += d.0;
    }
}

impl Sub for Fine {
    type Output = Fine;
    #[inline]
    fn sub(self, d: Fine) -> Fine {
        Fine(self.0 - d.0)
    }
}

impl SubAssign for Fine {
    #[inline]
    fn sub_assign(&mut self, d: Fine) {
        self.0 -= d.0;
    }
}

/// `n` times a duration.
impl Mul<u64> for Fine {
    type Output = Fine;
    #[inline]
    fn mul(self, n: u64) -> Fine {
        Fine(self.0 * n)
    }
}

/// `n` times a duration.
impl Mul<Fine> for u64 {
    type Output = Fine;
    #[inline]
    fn mul(self, d: Fine) -> Fine {
        Fine(self * d.0)
    }
}

/// A duration in `n` equal parts (rounded down).
impl Div<u64> for Fine {
    type Output = Fine;
    #[inline]
    fn div(self, n: u64) -> Fine {
        Fine(self.0 / n)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The unit and its roundings: µs to and from Fine, ns rounded half up.
    #[test]
    fn microseconds_and_nanoseconds_round_half_up() {
        assert_eq!(fine(3).raw(), 3 << 16);
        assert_eq!(whole_us(fine(7)), 7);
        assert_eq!(whole_us(fine(7) + US / 2), 8);
        assert_eq!(whole_us(fine(7) + US / 2 - Fine::from_raw(1)), 7);
        assert_eq!(fine(1).ns(), 1000);
        // 1/65536 µs = 0.0153 ns: 33 units are 0.504 ns, 32 are 0.488 ns.
        assert_eq!(Fine::from_raw(33).ns(), 1);
        assert_eq!(Fine::from_raw(32).ns(), 0);
        assert_eq!(fine(5_000_000).ns(), 5_000_000_000);
        assert_eq!(fine(10).since(fine(12)), -2 * US.raw() as i64);
        assert_eq!(Fine::ZERO.wrapping_sub(US).wrapping_add(US), Fine::ZERO);
        assert_eq!(fine(5).wrapping_add_signed(-(US.raw() as i64)), fine(4));
    }
}
