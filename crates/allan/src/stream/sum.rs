//! The exact arithmetic: 128-bit sums kept as four u32 words, squares of exact differences
//! with the Cortex-M0+'s 32×32→32 multiplier only, and the accumulation of one level's D2² and
//! D3² from phase values in 64-bit or 32-bit words.

use super::Engine;

/// An exact 128-bit sum kept as four u32 words (least significant first). Adding a square
/// below 2^32 — every |D| < 2^16, the common case — is one 32-bit add and a rarely taken carry;
/// a 64-bit square is a 64-bit add and a rarely taken carry. The M0+ has no 64-bit registers, so
/// a `u128 +=` would touch all four words every time.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[repr(C)]
pub(super) struct Sum128 {
    pub(super) w: [u32; 4],
}

impl Sum128 {
    pub(super) const ZERO: Sum128 = Sum128 { w: [0; 4] };

    /// Carry into word 1 and up.
    #[inline(always)]
    fn carry1(&mut self) {
        let (w1, c) = self.w[1].overflowing_add(1);
        self.w[1] = w1;
        if c {
            self.carry2(1);
        }
    }

    /// Add `x` into words 2 and 3 (the upper half).
    #[inline(always)]
    fn carry2(&mut self, x: u64) {
        let hi = ((self.w[3] as u64) << 32 | self.w[2] as u64).wrapping_add(x);
        self.w[2] = hi as u32;
        self.w[3] = (hi >> 32) as u32;
    }

    #[inline(always)]
    fn add32(&mut self, x: u32) {
        let (w0, c) = self.w[0].overflowing_add(x);
        self.w[0] = w0;
        if c {
            self.carry1();
        }
    }

    #[inline(always)]
    fn add64(&mut self, x: u64) {
        let lo = (self.w[1] as u64) << 32 | self.w[0] as u64;
        let (lo, c) = lo.overflowing_add(x);
        self.w[0] = lo as u32;
        self.w[1] = (lo >> 32) as u32;
        if c {
            self.carry2(1);
        }
    }

    /// Add d², d known to fit in i32: one multiply when |d| < 2^16, else three 16×16 ones.
    #[inline(always)]
    fn add_square32(&mut self, d: i32) {
        // |d| < 2^16 ⟺ d + (2^16 − 1) ∈ [0, 2^17 − 2]: one add and one compare, no abs.
        if (d as u32).wrapping_add(0xffff) < 0x1ffff {
            self.add32((d as u32).wrapping_mul(d as u32));
        } else {
            self.add64(square32(d.unsigned_abs()));
        }
    }

    #[inline(always)]
    fn add128(&mut self, x: u128) {
        self.add64(x as u64);
        self.carry2((x >> 64) as u64);
    }

    pub(super) fn get(&self) -> u128 {
        self.w
            .iter()
            .rev()
            .fold(0u128, |acc, &w| acc << 32 | w as u128)
    }
}

/// Square of |d| for a difference known to fit in i32: three 16×16→32 multiplies.
#[inline(always)]
fn square32(a: u32) -> u64 {
    let (h, l) = (a >> 16, a & 0xffff);
    // (h·2^16 + l)² = h²·2^32 + 2hl·2^16 + l²
    (((h * h) as u64) << 32 | (l * l) as u64) + (((h * l) as u64) << 17)
}

/// Square of an exact difference, cheap when it fits in 32 bits (the common case).
#[inline(always)]
fn square(d: i64) -> u128 {
    let a = d.unsigned_abs();
    if a >> 32 == 0 {
        let a = a as u32;
        let (h, l) = (a >> 16, a & 0xffff);
        // (h·2^16 + l)² = h²·2^32 + 2hl·2^16 + l², each product a 16×16→32 multiply.
        let sq = ((h * h) as u64) << 32 | (l * l) as u64;
        (sq + (((h * l) as u64) << 17)) as u128
    } else {
        (a as u128) * (a as u128)
    }
}

impl<const P: usize, const L: usize, const R: usize, const S: usize> Engine<P, L, R, S> {
    /// Differences of level `k` from i64 phase values (any level, any input).
    #[inline(always)]
    fn accumulate_wide(&mut self, k: usize, tm: i64, t2m: i64, t3m: Option<i64>) {
        let d2 = self
            .theta
            .wrapping_sub(tm.wrapping_mul(2))
            .wrapping_add(t2m);
        let [s2, s3] = &mut self.sums[k];
        s2.add128(square(d2));
        if let Some(t3m) = t3m {
            // D3(t) = D2(t) − D2(t − m)
            let d2_prev = tm.wrapping_sub(t2m.wrapping_mul(2)).wrapping_add(t3m);
            s3.add128(square(d2.wrapping_sub(d2_prev)));
        }
    }

    /// The same in 32-bit words: exact because the differences are known to fit in i32, so
    /// their value mod 2^32 (computed from the low words of θ) is the value itself.
    #[inline(always)]
    pub(super) fn accumulate_narrow(
        sums: &mut [Sum128; 2],
        t0: u32,
        tm: u32,
        t2m: u32,
        t3m: Option<u32>,
    ) {
        let d2 = t0.wrapping_sub(tm.wrapping_mul(2)).wrapping_add(t2m);
        let [s2, s3] = sums;
        s2.add_square32(d2 as i32);
        if let Some(t3m) = t3m {
            let d2_prev = tm.wrapping_sub(t2m.wrapping_mul(2)).wrapping_add(t3m);
            s3.add_square32(d2.wrapping_sub(d2_prev) as i32);
        }
    }

    /// The same for differences known to be below 2^16 in magnitude: one multiply each, no
    /// range test.
    #[inline(always)]
    pub(super) fn accumulate_small(sums: &mut [Sum128; 2], t0: u32, tm: u32, t2m: u32, t3m: u32) {
        let d2 = t0.wrapping_sub(tm.wrapping_mul(2)).wrapping_add(t2m);
        let d3 = d2.wrapping_sub(tm.wrapping_sub(t2m.wrapping_mul(2)).wrapping_add(t3m));
        let [s2, s3] = sums;
        s2.add32(d2.wrapping_mul(d2));
        s3.add32(d3.wrapping_mul(d3));
    }

    #[inline(always)]
    pub(super) fn accumulate(&mut self, k: usize, tm: i64, t2m: i64, t3m: Option<i64>) {
        if k < self.narrow as usize {
            let t0 = self.theta as u32;
            let t3m = t3m.map(|v| v as u32);
            Self::accumulate_narrow(&mut self.sums[k], t0, tm as u32, t2m as u32, t3m);
        } else {
            self.accumulate_wide(k, tm, t2m, t3m);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn square_matches_wide_multiply() {
        for d in [
            0i64,
            1,
            -1,
            65535,
            65536,
            -65537,
            0xffff_ffff,
            1 << 32,
            -(1 << 40),
            i32::MIN as i64,
        ] {
            assert_eq!(square(d), (d as i128 * d as i128) as u128, "d = {d}");
        }
    }
}
