//! The stamps of a run of consecutive samples, as a sample clock issues them.
use super::arithmetic::mul;
use super::fine::{whole_us, Fine, FINE_BITS, US};

/// The stamps of a run of consecutive samples: sample `k0 + i` at `t0 + i·period`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Stamps {
    /// Index of the first sample on the sensor's grid.
    pub k0: u32,
    /// Its time.
    pub t0: Fine,
    /// Period.
    pub period: Fine,
}

impl Stamps {
    /// Time of sample `k0 + i`, whole µs.
    #[inline]
    pub fn us(&self, i: u32) -> u64 {
        whole_us(self.t0 + Fine::from_raw(mul(u64::from(i), self.period.raw())))
    }

    /// The stamps of samples `k0 + i`, `k0 + i + 1`, … in whole µs, one addition each.
    pub fn iter_us(&self) -> impl Iterator<Item = u64> {
        let (mut t, p) = (self.t0.raw() + (US.raw() >> 1), self.period.raw());
        core::iter::from_fn(move || {
            let us = t >> FINE_BITS;
            t += p;
            Some(us)
        })
    }
}
