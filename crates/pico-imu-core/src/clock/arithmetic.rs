//! The clock's integer arithmetic, shaped for the Cortex-M0+ (no 32 × 32 → 64-bit multiply,
//! no divide instruction): products by 16-bit halves, small quotients by subtraction.

/// `a · b` (wrapping). Operands below 2^32 — the clock's periods, indices and spans — take
/// four 16 × 16-bit products: the Cortex-M0+ has no 32 × 32 → 64-bit multiply, and a 64-bit
/// product is a library call.
#[inline]
pub(crate) const fn mul(a: u64, b: u64) -> u64 {
    if (a | b) >> 32 != 0 {
        return mul_full(a, b);
    }
    let (a, b) = (a as u32, b as u32);
    let (al, ah) = (a & 0xffff, a >> 16);
    let (bl, bh) = (b & 0xffff, b >> 16);
    let mid = (al * bh) as u64 + (ah * bl) as u64;
    ((al * bl) as u64)
        .wrapping_add(mid << 16)
        .wrapping_add(((ah * bh) as u64) << 32)
}

/// [`mul`]'s rare path, out of line: inline, the compiler computes the library call's product
/// on every path and then picks one.
#[cold]
#[inline(never)]
const fn mul_full(a: u64, b: u64) -> u64 {
    a.wrapping_mul(b)
}

/// `d · p` for a signed `d` (wrapping), by [`mul`].
#[inline]
pub(super) const fn mul_signed(d: i64, p: u64) -> u64 {
    let m = mul(d.unsigned_abs(), p);
    if d < 0 {
        m.wrapping_neg()
    } else {
        m
    }
}

/// `n / p` (`p > 0`). The clock divides times up to a few dozen periods apart by a period, so
/// the quotient is nearly always below 256: then eight shift-and-subtract steps give it, where
/// a 64-bit division is a library call of about 450 cycles on the Cortex-M0+.
#[inline]
pub(super) fn quot(n: u64, p: u64) -> u64 {
    if n < p {
        return 0;
    }
    if p == 0 || p > u64::MAX >> 8 || n >= p << 8 {
        return n.checked_div(p).unwrap_or(0);
    }
    let (mut r, mut q) = (n, 0);
    for b in (0..8).rev() {
        if r >= p << b {
            r -= p << b;
            q |= 1 << b;
        }
    }
    q
}

/// `ceil(n / p)` (`p > 0`).
pub(super) fn quot_ceil(n: u64, p: u64) -> u64 {
    let q = quot(n, p);
    if mul(q, p) == n {
        q
    } else {
        q + 1
    }
}

/// `floor(a / p)` for a signed `a`.
pub(super) fn floor_div(a: i64, p: u64) -> i64 {
    if a >= 0 {
        quot(a as u64, p) as i64
    } else {
        -(quot_ceil(a.unsigned_abs(), p) as i64)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::clock::{fine, US};
    use crate::test_util::xorshift;

    #[test]
    fn products_by_halves_equal_multiplication() {
        let mut next = xorshift(0x2545_F491_4F6C_DD1D);
        let edges = [0, 1, 0xffff, 0x1_0000, 0xffff_ffff, 0x1_0000_0000, u64::MAX];
        for &a in &edges {
            for &b in &edges {
                assert_eq!(mul(a, b), a.wrapping_mul(b), "{a} · {b}");
            }
        }
        for i in 0..100_000 {
            let (a, b) = match i % 3 {
                0 => (next() >> 32, next() >> 32),
                1 => (next() >> 48, next() >> 33),
                _ => (next(), next() >> 40),
            };
            assert_eq!(mul(a, b), a.wrapping_mul(b), "{a} · {b}");
            let d = (next() >> 33) as i64 - (1 << 30);
            assert_eq!(
                mul_signed(d, b),
                (d.wrapping_mul(b as i64)) as u64,
                "{d} · {b}"
            );
        }
    }

    #[test]
    fn quotients_by_subtraction_equal_division() {
        let mut next = xorshift(0x9E37_79B9_7F4A_7C15);
        let us = US.raw();
        for i in 0..200_000u64 {
            let p = match i % 4 {
                0 => next() % (1 << 28) + 1,
                1 => fine(1000).raw() + next() % 1000,
                2 => next() >> (next() % 64),
                _ => u64::MAX - next() % 3,
            }
            .max(1);
            let n = match i % 3 {
                0 => next() % (p.saturating_mul(20).max(1)),
                1 => p.saturating_mul(next() % 300).saturating_add(next() % 2),
                _ => next(),
            };
            assert_eq!(quot(n, p), n / p, "{n} / {p}");
            assert_eq!(quot_ceil(n, p), n.div_ceil(p), "ceil {n} / {p}");
        }
        for a in [-3 * us as i64 - 1, -(us as i64), -1, 0, 1, us as i64 * 17] {
            assert_eq!(floor_div(a, us), a.div_euclid(us as i64), "{a}");
        }
    }
}
