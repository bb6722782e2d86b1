//! Integer arithmetic for the device's attitude filter, shaped for the Cortex-M0+: it multiplies
//! 32 × 32 → 32 bits in one cycle, has no 64-bit product, no divide, no count-leading-zeros and
//! no FPU. Everything here is exact integer code (bit-identical on the host and the device);
//! the errors against the exact functions are held by the tests below and by
//! `tests/ahrs.rs`.
//!
//! * [`rsqrt`]: `1/√x` by a 96-entry table and one Newton step, relative error ≤ 2·10⁻⁴;
//! * [`atan2`]: the octant by compares, then a polynomial in the ratio of the smaller to the
//!   larger component, that ratio by a table-and-Newton reciprocal; degrees in Q20, error
//!   ≤ 0.004° (on the M0+ a third of a 16-step CORDIC's cycles: docs/benchmarks.md);
//! * [`mul_shr`]: a signed 32 × 32-bit product shifted right, by 16-bit halves (no library
//!   call);
//! * [`to_f32`]: a fixed-point value to `f32` for the wire (one conversion, the scale put into
//!   the exponent).

/// `1/√(X)` for `X = (i + ½)/128`, `i = 32..128`, in Q15: the first guess of [`rsqrt`] for a
/// value normalised into [¼, 1) (its top seven bits pick the entry). Checked against `libm` by a
/// test.
const RSQRT: [u16; 96] = [
    65030, 64052, 63117, 62222, 61363, 60540, 59748, 58987, 58254, 57548, 56867, 56210, 55574,
    54960, 54366, 53791, 53233, 52693, 52169, 51660, 51165, 50685, 50218, 49763, 49321, 48890,
    48470, 48061, 47663, 47273, 46894, 46523, 46161, 45807, 45462, 45124, 44793, 44470, 44153,
    43843, 43540, 43243, 42951, 42666, 42386, 42112, 41843, 41579, 41320, 41065, 40816, 40571,
    40330, 40093, 39861, 39632, 39408, 39187, 38970, 38756, 38546, 38340, 38136, 37936, 37739,
    37545, 37354, 37166, 36980, 36798, 36618, 36441, 36266, 36093, 35924, 35756, 35591, 35428,
    35267, 35109, 34953, 34798, 34646, 34496, 34347, 34201, 34056, 33913, 33772, 33633, 33496,
    33360, 33225, 33093, 32962, 32832,
];

/// `1/√x` for `x > 0` as `(m, s)`: `1/√x ≈ m·2^-s`, `m` in [2^15, 2^16), `s` in [16, 31].
/// Relative error ≤ 2·10⁻⁴ (the table's ≤ 0.8 % squared by the Newton step, and the step's
/// rounding; tested over the whole range). `x = 0` gives the value for `x = 1`: callers test
/// for zero first.
#[inline]
pub fn rsqrt(x: u32) -> (u32, u32) {
    if x == 0 {
        return (1 << 15, 15);
    }
    // x·4^z in [2^30, 2^32): X = that/2^32 in [¼, 1), 1/√X in (1, 2].
    let z = leading_zeros(x) & !1;
    let xn = x << z;
    let y = u32::from(RSQRT[(xn >> 25) as usize - 32]);
    // One Newton step y·(3 − X·y²)/2: X in Q16 times y² in Q14 is X·y² in Q30 (≈ 2^30; y² < 2^32
    // since y ≤ 65030).
    let t = (xn >> 16) * ((y * y) >> 16);
    let y = (y * ((3u32 << 30).wrapping_sub(t) >> 16)) >> 15;
    // 1/√x = 2^(z/2) · 2^-16 / √X = y · 2^-(31 − z/2).
    (y, 31 - z / 2)
}

/// Degrees in Q20: 1° = 2^20.
pub const DEG_Q20: i32 = 1 << 20;

/// `2^15 / X` for `X = (i + ½)/256`, `i = 128..256` (X in [½, 1)), rounded: the first guess
/// of [`ratio_q16`]'s reciprocal, by the divisor's top eight bits.
const RECIP: [u16; 128] = {
    let mut t = [0u16; 128];
    let mut i = 0;
    while i < 128 {
        // 2^15 · 256/(i + 128 + ½) = 2^24/(2i + 257), rounded.
        t[i] = ((2u32 << 24) / (2 * i as u32 + 257)).div_ceil(2) as u16;
        i += 1;
    }
    t
};

/// `num/den` in Q16 for `num ≤ den`, `den > 0`: the reciprocal of `den` by [`RECIP`] and one
/// Newton step, then one product (no division: the M0+ has none, and a library division is
/// ≈ 100 cycles). Relative error ≤ 5·10⁻⁵, absolute ≤ 2^-15 (tested through [`atan2`]).
#[inline(always)]
fn ratio_q16(num: u32, den: u32) -> u32 {
    let s = leading_zeros(den);
    // D = d/2^32 in [½, 1); n ≤ d.
    let (d, n) = (den << s, num << s);
    let r = u32::from(RECIP[(d >> 24) as usize - 128]);
    // r ← r·(2 − D·r) in Q15: D·r in Q31 is (d >> 16)·r (≈ 2^31), 2 − that is 2^32 − e.
    let e = (d >> 16) * r;
    let r = (r * (0u32.wrapping_sub(e) >> 16)) >> 15;
    // n/d · 2^16 = (n/2^32) · (1/D) · 2^16 = (n >> 16) · r >> 15 (≤ 2^31: n ≤ d).
    ((n >> 16) * r) >> 15
}

/// `atan(t)/t` as a polynomial in `t²` for `t` in [0, 1]: coefficients in Q16, a least-squares
/// fit reweighted towards the smallest largest error (0.0007° before rounding; 0.002° in this
/// arithmetic, tested through [`atan2`]).
const ATAN_POLY_Q16: [i32; 5] = [65527, -21646, 11806, -5580, 1366];

/// Radians in Q31 to degrees in Q20: `· 180/π · 2^-11`, as a Q32 factor for [`mul_shr`].
const RAD_Q31_TO_DEG_Q20: i32 = 120_157_959;

/// `atan(t)`, `t` in [0, 1] in Q16, in degrees Q20 (≤ 45°).
#[inline(always)]
fn atan01(t: u32) -> i32 {
    // u = t² in Q16 (≤ 2^16); Horner in Q16 with rounding, every product below 2^31 (|p| stays
    // under 2^15 until the last coefficient).
    let u = ((t * t + (1 << 15)) >> 16) as i32;
    let mut p = ATAN_POLY_Q16[4];
    p = ((p * u + (1 << 15)) >> 16) + ATAN_POLY_Q16[3];
    p = ((p * u + (1 << 15)) >> 16) + ATAN_POLY_Q16[2];
    p = ((p * u + (1 << 15)) >> 16) + ATAN_POLY_Q16[1];
    p = ((p * u + (1 << 15)) >> 16) + ATAN_POLY_Q16[0];
    // p > 0 here: p·t < 2^32 unsigned is atan(t) in Q32 rad; halved, Q31.
    let a = ((p as u32 * t) >> 1) as i32;
    mul_shr(a, RAD_Q31_TO_DEG_Q20, 32)
}

/// `atan2(y, x)` in degrees, Q20, in (−180°, 180°]: the octant by compares, the ratio of the
/// smaller to the larger magnitude by [`ratio_q16`], [`atan01`] of it. Error ≤ 0.004° for any
/// inputs of length ≥ 2^16 (tested); `atan2(0, 0)` is 0.
#[inline]
pub fn atan2(y: i32, x: i32) -> i32 {
    let (ax, ay) = (x.unsigned_abs(), y.unsigned_abs());
    let a = if ay <= ax {
        if ax == 0 {
            return 0;
        }
        atan01(ratio_q16(ay, ax))
    } else {
        90 * DEG_Q20 - atan01(ratio_q16(ax, ay))
    };
    let a = if x < 0 { 180 * DEG_Q20 - a } else { a };
    if y < 0 {
        -a
    } else {
        a
    }
}

/// Leading zero bits of a byte (8 for 0).
const CLZ8: [u8; 256] = {
    let mut t = [8u8; 256];
    let mut b = 1;
    while b < 256 {
        let mut n = 0;
        while b << n < 0x80 {
            n += 1;
        }
        t[b] = n as u8;
        b += 1;
    }
    t
};

/// The number of leading zero bits of `x` (32 for 0), by two compares and a byte table: the
/// Cortex-M0+ has no count-leading-zeros instruction, and `u32::leading_zeros` is a library
/// call of ≈ 75 cycles in the emulator.
#[inline(always)]
pub fn leading_zeros(x: u32) -> u32 {
    let n = if x >= 1 << 16 {
        if x >= 1 << 24 {
            CLZ8[(x >> 24) as usize]
        } else {
            8 + CLZ8[(x >> 16) as usize]
        }
    } else if x >= 1 << 8 {
        16 + CLZ8[(x >> 8) as usize]
    } else {
        24 + CLZ8[x as usize]
    };
    u32::from(n)
}

/// `(a · b) >> s` for `s` in [16, 47], rounded down, in 32-bit arithmetic by 16-bit halves:
/// the Cortex-M0+ has no 32 × 32 → 64-bit product, and a 64-bit multiply is a library call (a
/// 64-bit sum of these halves, the compiler turns back into one). The caller keeps the result
/// within `i32`.
#[inline(always)]
pub fn mul_shr(a: i32, b: i32, s: u32) -> i32 {
    // a·b = ah·bh·2^32 + (ah·bl + al·bh)·2^16 + al·bl, al and bl the unsigned low halves; each
    // middle product m is (m >> 16)·2^32 plus its low half shifted up by 16.
    let (ah, al) = (a >> 16, (a & 0xffff) as u32);
    let (bh, bl) = (b >> 16, (b & 0xffff) as u32);
    let m1 = ah * bl as i32;
    let m2 = bh * al as i32;
    let (lo, c1) = (al * bl).overflowing_add((m1 as u32) << 16);
    let (lo, c2) = lo.overflowing_add((m2 as u32) << 16);
    let hi = ah * bh + (m1 >> 16) + (m2 >> 16) + c1 as i32 + c2 as i32;
    if s >= 32 {
        hi >> (s - 32)
    } else {
        (hi << (32 - s)) | (lo >> s) as i32
    }
}

/// `v · 2^-frac` as `f32` (the wire's type), truncated toward zero: at most one unit in the
/// last place below `v as f32` scaled (6·10⁻⁸ relative, far under what an estimate carries),
/// without the library's conversion (≈ 80 cycles on the M0+ with its count-leading-zeros
/// call). `frac` ≤ 100.
#[inline(always)]
pub fn to_f32(v: i32, frac: u32) -> f32 {
    if v == 0 {
        return 0.0;
    }
    let sign = (v as u32) & 0x8000_0000;
    let lz = leading_zeros(v.unsigned_abs());
    // The leading one at bit 31, then 24 bits kept; |v| = 1.f·2^(31 − lz − frac). The leading
    // one (bit 23 of the kept bits) adds one to the exponent field, hence the − 1.
    let r = (v.unsigned_abs() << lz) >> 8;
    let exp = (127 + 31 - 1) - lz - frac;
    f32::from_bits(sign | ((exp << 23) + r))
}

/// The shift `s` that brings the largest `|v_i|` into [2^14, 2^15) (`v_i · 2^s`, `s` may be
/// negative), and the shifted vector; `None` for a zero vector.
#[inline]
pub fn norm15(v: [i32; 3]) -> Option<([i32; 3], i32)> {
    let m = v[0].unsigned_abs() | v[1].unsigned_abs() | v[2].unsigned_abs();
    if m == 0 {
        return None;
    }
    // The highest bit set of the OR is the largest magnitude's.
    let s = leading_zeros(m) as i32 - 17;
    Some((
        if s >= 0 {
            v.map(|x| x << s)
        } else {
            v.map(|x| x >> -s)
        },
        s,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_tables_are_the_functions_they_claim() {
        for (k, &t) in RSQRT.iter().enumerate() {
            let x = (k as f64 + 32.5) / 128.0;
            assert_eq!(
                t,
                libm::round(32768.0 / libm::sqrt(x)) as u16,
                "rsqrt entry {k}"
            );
        }
        for (k, &r) in RECIP.iter().enumerate() {
            let x = (k as f64 + 128.5) / 256.0;
            assert_eq!(r, libm::round(32768.0 / x) as u16, "recip entry {k}");
        }
        let k = 180.0 / core::f64::consts::PI * libm::ldexp(1.0, 20 - 31 + 32);
        assert_eq!(RAD_Q31_TO_DEG_Q20, libm::round(k) as i32);
    }

    #[test]
    fn rsqrt_within_two_parts_in_ten_thousand() {
        let mut worst = 0f64;
        let mut x = 1u32;
        // Every small value, then a geometric sweep with an odd step (all table entries, both
        // parities of the shift).
        while x < u32::MAX - (x >> 7) {
            let (m, s) = rsqrt(x);
            assert!((1 << 15..1 << 16).contains(&m), "{x}: {m}");
            let got = m as f64 * libm::ldexp(1.0, -(s as i32));
            let rel = (got * libm::sqrt(x as f64) - 1.0).abs();
            worst = worst.max(rel);
            x = if x < 5000 { x + 1 } else { x + (x >> 9) + 7 };
        }
        println!("rsqrt: largest relative error {worst:.2e}");
        assert!(worst < 2e-4, "worst relative error {worst}");
    }

    #[test]
    fn atan2_within_four_thousandths_of_a_degree() {
        let mut worst = 0f64;
        for k in 0..40_000 {
            let a = -180.0 + 360.0 * (k as f64 + 0.37) / 40_000.0;
            for r in [1 << 16, 1 << 20, 1 << 25, 1 << 29, i32::MAX] {
                let (x, y) = (
                    libm::round(r as f64 * libm::cos(a.to_radians())) as i32,
                    libm::round(r as f64 * libm::sin(a.to_radians())) as i32,
                );
                let z = atan2(y, x);
                assert!(z > -180 * DEG_Q20 && z <= 180 * DEG_Q20, "{x} {y}: {z}");
                let want = libm::atan2(y as f64, x as f64).to_degrees();
                let mut d = z as f64 / DEG_Q20 as f64 - want;
                if d > 180.0 {
                    d -= 360.0;
                } else if d < -180.0 {
                    d += 360.0;
                }
                worst = worst.max(d.abs());
            }
        }
        // The axes and the diagonals exactly where they are.
        for (y, x, want) in [
            (0, 5, 0),
            (5, 0, 90),
            (0, -5, 180),
            (-5, 0, -90),
            (7, 7, 45),
        ] {
            let z = atan2(y, x) as f64 / DEG_Q20 as f64;
            assert!((z - want as f64).abs() < 0.003, "atan2({y}, {x}) = {z}");
        }
        println!("atan2: largest error {worst:.5}°");
        assert!(worst < 0.004, "worst {worst}°");
        assert_eq!(atan2(0, 0), 0);
    }

    #[test]
    fn mul_shr_is_the_wide_product() {
        let mut s = 0x1234_5678_9abc_def1u64;
        let mut next = || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            s
        };
        for _ in 0..100_000 {
            let (a, b) = (next() as i32, next() as i32 >> (next() % 16));
            let sh = 16 + (next() % 32) as u32;
            let want = (a as i64 * b as i64) >> sh;
            if want as i32 as i64 == want {
                assert_eq!(mul_shr(a, b, sh), want as i32, "{a} {b} {sh}");
            }
        }
    }

    #[test]
    fn leading_zeros_is_the_instruction() {
        for k in 0..32 {
            for x in [
                1u32 << k,
                (1u32 << k) | 1,
                (2u32 << k).wrapping_sub(1),
                0x9e37_79b9 >> k,
            ] {
                assert_eq!(leading_zeros(x), x.leading_zeros(), "{x:#x}");
            }
        }
        assert_eq!(leading_zeros(0), 32);
    }

    #[test]
    fn to_f32_is_the_scaled_value() {
        let mut s = 0x9e37_79b9_7f4a_7c15u64;
        let mut values = vec![
            0,
            1,
            -1,
            i32::MAX,
            i32::MIN,
            1 << 30,
            -(1 << 30),
            0x0100_0001,
        ];
        for _ in 0..200_000 {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            values.push((s as i32) >> (s >> 59));
        }
        // 25 significant bits and more: truncated.
        values.extend([0x0100_0001, 0x0100_0003, -0x0100_0003, 0x7fff_ffc0]);
        for v in values {
            for f in [0, 20, 30] {
                // Truncated: the exact value's f32 neighbour toward zero.
                let exact = v as f64 / (1u64 << f) as f64;
                let got = to_f32(v, f) as f64;
                let ulp = if v == 0 {
                    1.0
                } else {
                    libm::ldexp(1.0, libm::ilogb(exact) - 23)
                };
                assert!(
                    got.abs() <= exact.abs() && exact.abs() - got.abs() < ulp,
                    "{v} >> {f}: {got} for {exact}"
                );
                assert!(v == 0 || got.signum() == exact.signum(), "{v}: {got}");
            }
        }
    }

    #[test]
    fn norm15_brings_the_largest_into_range() {
        for v in [
            [1, 0, 0],
            [-3, 70_000, 5],
            [i32::MAX / 8, -1, 2],
            [0, 0, -16384],
        ] {
            let (n, s) = norm15(v).unwrap();
            let m = n.iter().map(|x| x.unsigned_abs()).max().unwrap();
            assert!((1 << 14..1 << 15).contains(&m), "{v:?}: {n:?}");
            let back = if s >= 0 { v[1] << s } else { v[1] >> -s };
            assert_eq!(back, n[1]);
        }
        assert!(norm15([0; 3]).is_none());
    }
}
