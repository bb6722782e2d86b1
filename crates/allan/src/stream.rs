//! The streaming octave engine: bounded memory, integer-exact, no allocation and no floating
//! point on the per-sample path.
//!
//! # What it computes
//! For every octave level `m = 2^k` (`k = 0..L`) it accumulates, exactly in `u128`, the sums of
//! squared second differences of the phase `θ` (seed eq. 8–9, `θ[t] = Σ_{i<t} y_i`):
//!
//! ```text
//! D2(t) = θ[t] − 2θ[t−m] + θ[t−2m]            (Allan, seed eq. 7 through eq. 9)
//! D3(t) = θ[t] − 3θ[t−m] + 3θ[t−2m] − θ[t−3m] (Hadamard, third differences)
//! ```
//!
//! for every `t` that is a multiple of the level's stride `s = max(1, m/P)`. Levels with
//! `m ≤ P` therefore are the fully overlapping estimators exactly; higher levels are the
//! stride-`s` overlapping estimators, which keep `P` differences per cluster length (the
//! scatter of the estimate is within ≈2 % of full overlap for `P = 8`, see docs/allan.md).
//!
//! # Memory: a cascade of rings
//! The naive design keeps, for each level, the last `3P` phase values at its stride. Here the
//! levels share storage: a base ring holds the last `3P` raw phase values (enough for every
//! level with `m ≤ P`), and level `k` (with `m > P`) keeps only the `R = 3P/2` values it needs
//! *older* than what level `k−1` already holds (ages `1.5m < a ≤ 3m` at stride `s`). Values leave
//! the base ring and trickle up the cascade; each level reads `θ[t−m]` from the level below and
//! `θ[t−2m]`, `θ[t−3m]` from its own ring, at fixed offsets from the ring's head, so there is no
//! search and no division on the hot path.
//!
//! # Exactness
//! `θ` is kept in wrapping `i64`: every difference above is exact as long as its true value fits
//! in `i64` (it is below `4·m·max|y| ≤ 2^56` for `m ≤ 2^23` and any `i32` input), even after `θ`
//! itself wraps. Squares are formed in `u64` with three 16×16 multiplies when `|D| < 2^32` (the
//! Cortex-M0+ has only a 32×32→32 multiplier) and in `u128` otherwise, and summed in `u128`.
//! docs/allan.md gives the overflow argument for 30 days at 1 kHz.

/// Sums of one octave level: everything a deviation, its EDF and its bounds derive from.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct LevelSums {
    /// Cluster size in samples (`τ = m·τ0`).
    pub m: u32,
    /// Stride between successive differences, in samples.
    pub stride: u32,
    /// Number of second differences summed.
    pub n2: u64,
    /// Σ D2², in (input LSB · samples)².
    pub sum2: u128,
    /// Number of third differences summed.
    pub n3: u64,
    /// Σ D3², in (input LSB · samples)².
    pub sum3: u128,
}

impl LevelSums {
    /// Overlapping Allan deviation in input units × `scale` (e.g. LSB → deg/s):
    /// `σ² = Σ D2² / (2 n m²)` (seed eq. 7 with eq. 9; NIST SP 1065 eq. 11).
    /// `None` when the level has no terms yet.
    pub fn oadev(&self, scale: f64) -> Option<f64> {
        if self.n2 == 0 {
            return None;
        }
        let m = self.m as f64;
        Some(libm::sqrt(self.sum2 as f64 / (2.0 * self.n2 as f64 * m * m)) * scale)
    }

    /// Overlapping Hadamard deviation: `σ² = Σ D3² / (6 n m²)` (NIST SP 1065 eq. 18).
    pub fn ohdev(&self, scale: f64) -> Option<f64> {
        if self.n3 == 0 {
            return None;
        }
        let m = self.m as f64;
        Some(libm::sqrt(self.sum3 as f64 / (6.0 * self.n3 as f64 * m * m)) * scale)
    }

    /// The number of phase points a single uninterrupted record would need to give `n2`
    /// terms at this stride; used as `N` in Greenhall's EDF.
    pub fn phase_points(&self) -> f64 {
        if self.n2 == 0 {
            return 0.0;
        }
        ((self.n2 - 1) as f64) * self.stride as f64 + 2.0 * self.m as f64 + 1.0
    }
}

/// An exact 128-bit sum kept as two u64 words, so that adding a 64-bit square costs one 64-bit
/// add and a rarely taken carry (a `u128 +=` touches four words on the M0+).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
struct Sum128 {
    lo: u64,
    hi: u64,
}

impl Sum128 {
    const ZERO: Sum128 = Sum128 { lo: 0, hi: 0 };

    #[inline(always)]
    fn add64(&mut self, x: u64) {
        let (lo, carry) = self.lo.overflowing_add(x);
        self.lo = lo;
        if carry {
            self.hi += 1;
        }
    }

    #[inline(always)]
    fn add128(&mut self, x: u128) {
        self.add64(x as u64);
        self.hi += (x >> 64) as u64;
    }

    fn get(&self) -> u128 {
        (self.hi as u128) << 64 | self.lo as u128
    }
}

/// The exact accumulators of one level (what the engine stores; `m` and the stride are implied
/// by the level's index). The counts of the current segment follow from its length, so only
/// the counts of closed segments are stored and nothing is counted on the per-sample path.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
struct Acc {
    sum2: Sum128,
    sum3: Sum128,
    closed_n2: u64,
    closed_n3: u64,
}

/// Multiples of `stride` (a power of two) in `[span, t]`: the differences a segment of `t`
/// samples contributes when each needs `span` samples of history.
fn terms(t: u64, span: u64, stride: u64) -> u64 {
    if t < span {
        0
    } else {
        t / stride - span.div_ceil(stride) + 1
    }
}

/// Square of a difference known to fit in i32: three 16×16→32 multiplies.
#[inline(always)]
fn square32(d: i32) -> u64 {
    let a = d.unsigned_abs();
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

/// Streaming overlapping Allan and Hadamard engine for one channel.
///
/// * `P` — overlap factor: differences per cluster length at the high levels (power of two ≥ 2).
/// * `L` — number of octave levels (`m = 1, 2, …, 2^(L−1)`).
/// * `R` — own-ring length per level, must equal `3P/2` (a separate parameter only because
///   stable Rust cannot size an array by `3 * P / 2`). Use [`DeviceEngine`] for the firmware's
///   configuration.
#[derive(Clone, Debug)]
pub struct Engine<const P: usize, const L: usize, const R: usize> {
    /// θ[t], wrapping.
    theta: i64,
    /// Samples pushed since the start of the current segment (θ's index).
    t: u64,
    /// Samples pushed since the last reset, across gaps.
    total: u64,
    /// Number of gaps marked since the last reset.
    gaps: u32,
    /// Rows 0 and 1 form the base ring (3P = 2R raw phase values); rows `K0..L` are the own
    /// rings of the strided levels. Rows `2..K0` are unused (at most `log2 P − 1` rows).
    rings: [[i64; R]; L],
    /// Base ring: slot of the next write (= t mod 3P).
    base_head: u8,
    /// Own rings: slot of the newest entry.
    heads: [u8; L],
    /// Levels with at least one second difference in this segment (t ≥ 2m) …
    half: u8,
    /// … and with third differences too (t ≥ 3m).
    full: u8,
    /// Levels whose differences provably fit in i32 given `amax` (computed in 32-bit words).
    narrow: u8,
    /// The t at which `half` or `full` next grows.
    next_valid: u64,
    /// Largest |y| of this segment.
    amax: u32,
    sums: [Acc; L],
}

/// The firmware's configuration: overlap factor 8, 24 octave levels (τ up to 2^23 samples,
/// 2.3 h at 1 kHz).
pub type DeviceEngine = Engine<8, 24, 12>;

/// The firmware's magnetometer configuration: the same overlap, 22 levels (τ up to 2^21 samples,
/// 2.9 h at 200 Hz, the same reach in seconds as [`DeviceEngine`] at 1 kHz).
pub type MagEngine = Engine<8, 22, 12>;

impl<const P: usize, const L: usize, const R: usize> Default for Engine<P, L, R> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const P: usize, const L: usize, const R: usize> Engine<P, L, R> {
    /// log2(P) + 1: the first level with stride 2 (m = 2P).
    const K0: usize = P.trailing_zeros() as usize + 1;
    const BASE: usize = 3 * P;
    /// Entries between the newest one of a ring and the value 2P strides older.
    const BACK: usize = 2 * P - R - 1;
    const VALID: () = {
        assert!(
            P >= 2 && P.is_power_of_two(),
            "P must be a power of two ≥ 2"
        );
        assert!(2 * R == 3 * P, "R must equal 3P/2");
        assert!(
            L >= Self::K0 && L <= 32,
            "L must cover the unit-stride levels and m < 2^32"
        );
        assert!(3 * P <= 255, "ring slots are u8");
    };

    /// A fresh engine with no samples.
    pub const fn new() -> Self {
        #[allow(clippy::let_unit_value)]
        let _ = Self::VALID;
        Self {
            theta: 0,
            t: 0,
            total: 0,
            gaps: 0,
            rings: [[0; R]; L],
            base_head: 0,
            heads: [R as u8 - 1; L],
            half: 0,
            full: 0,
            narrow: Self::narrow_levels(0),
            next_valid: 2,
            amax: 0,
            sums: [Acc {
                sum2: Sum128::ZERO,
                sum3: Sum128::ZERO,
                closed_n2: 0,
                closed_n3: 0,
            }; L],
        }
    }

    /// Forget everything: sums, counts and the current segment.
    pub fn reset(&mut self) {
        *self = Self::new();
    }

    /// Mark a gap in the data (e.g. a FIFO overflow): no difference will ever straddle it.
    /// The accumulated sums are kept; a new segment starts with the next sample.
    pub fn gap(&mut self) {
        if self.t != 0 {
            self.gaps += 1;
        }
        for k in 0..L {
            let (n2, n3) = self.segment_terms(k);
            self.sums[k].closed_n2 += n2;
            self.sums[k].closed_n3 += n3;
        }
        self.theta = 0;
        self.t = 0;
        self.base_head = 0;
        self.heads = [R as u8 - 1; L];
        self.half = 0;
        self.full = 0;
        self.next_valid = 2;
        self.amax = 0;
        self.narrow = Self::narrow_levels(0);
    }

    /// (second, third) differences level `k` has taken in the current segment.
    fn segment_terms(&self, k: usize) -> (u64, u64) {
        let m = 1u64 << k;
        let s = Self::stride(k) as u64;
        (terms(self.t, 2 * m, s), terms(self.t, 3 * m, s))
    }

    fn stride(k: usize) -> u32 {
        let m = 1u32 << k;
        if m as usize <= P {
            1
        } else {
            m / P as u32
        }
    }

    /// Levels k whose D2 and D3 fit in i32 for inputs up to `amax`: |D3| ≤ 4·2^k·amax < 2^31
    /// ⟺ amax < 2^(29−k). Off the hot path (the M0+ has no count-leading-zeros).
    const fn narrow_levels(amax: u32) -> u8 {
        let bits = 32 - amax.leading_zeros() as usize;
        let n = if bits > 29 { 0 } else { 30 - bits };
        (if n < L { n } else { L }) as u8
    }

    /// Recompute `half`, `full` and `next_valid` for the current t (rarely: ~2 log2 t times).
    #[cold]
    fn advance_valid(&mut self) {
        let t = self.t;
        while (self.half as usize) < L && t >= 2u64 << self.half {
            self.half += 1;
        }
        while (self.full as usize) < L && t >= 3u64 << self.full {
            self.full += 1;
        }
        let h = if (self.half as usize) < L {
            2u64 << self.half
        } else {
            u64::MAX
        };
        let f = if (self.full as usize) < L {
            3u64 << self.full
        } else {
            u64::MAX
        };
        self.next_valid = h.min(f);
    }

    /// Samples pushed since the last reset.
    pub fn samples(&self) -> u64 {
        self.total
    }

    /// Gaps marked since the last reset.
    pub fn gaps(&self) -> u32 {
        self.gaps
    }

    /// The sums of level `k` (m = 2^k), or `None` past the last level.
    pub fn level(&self, k: usize) -> Option<LevelSums> {
        let a = self.sums.get(k)?;
        let (n2, n3) = self.segment_terms(k);
        Some(LevelSums {
            m: 1u32 << k,
            stride: Self::stride(k),
            n2: a.closed_n2 + n2,
            sum2: a.sum2.get(),
            n3: a.closed_n3 + n3,
            sum3: a.sum3.get(),
        })
    }

    /// The per-level sums, level 0 (m = 1) first.
    pub fn levels(&self) -> impl Iterator<Item = LevelSums> + '_ {
        (0..L).filter_map(|k| self.level(k))
    }

    #[inline(always)]
    fn base_at_age(&self, age: usize) -> i64 {
        // θ[t − age] lives in slot (t − age) mod 3P; base_head = t mod 3P, 1 ≤ age ≤ 3P.
        let h = self.base_head as usize;
        let slot = if h >= age {
            h - age
        } else {
            h + Self::BASE - age
        };
        Self::base_slot(&self.rings, slot)
    }

    /// The low 32 bits of θ[t − age] (all a narrow difference needs: one load, not two).
    #[inline(always)]
    fn base_low(&self, age: usize) -> i32 {
        let h = self.base_head as usize;
        let slot = if h >= age {
            h - age
        } else {
            h + Self::BASE - age
        };
        Self::base_slot(&self.rings, slot) as i32
    }

    /// The base ring spans rows 0 and 1 (no division: the M0+ has no divide instruction).
    #[inline(always)]
    fn base_slot(rings: &[[i64; R]; L], slot: usize) -> i64 {
        if slot < R {
            rings[0][slot]
        } else {
            rings[1][slot - R]
        }
    }

    #[inline(always)]
    fn ring_back(&self, level: usize, back: usize) -> i64 {
        let h = self.heads[level] as usize;
        let slot = if h >= back { h - back } else { h + R - back };
        self.rings[level][slot]
    }

    /// Differences from i64 phase values (any level, any input).
    #[inline(always)]
    fn accumulate_wide(&mut self, k: usize, tm: i64, t2m: i64, t3m: Option<i64>) {
        let d2 = self
            .theta
            .wrapping_sub(tm.wrapping_mul(2))
            .wrapping_add(t2m);
        let s = &mut self.sums[k];
        s.sum2.add128(square(d2));
        if let Some(t3m) = t3m {
            // D3(t) = D2(t) − D2(t − m)
            let d2_prev = tm.wrapping_sub(t2m.wrapping_mul(2)).wrapping_add(t3m);
            s.sum3.add128(square(d2.wrapping_sub(d2_prev)));
        }
    }

    /// The same in 32-bit words: exact because the differences are known to fit in i32, so
    /// their value mod 2^32 (computed from the low words of θ) is the value itself.
    #[inline(always)]
    fn accumulate_narrow(&mut self, k: usize, tm: i64, t2m: i64, t3m: Option<i64>) {
        let (t0, tm, t2m) = (self.theta as i32, tm as i32, t2m as i32);
        let d2 = t0.wrapping_sub(tm.wrapping_mul(2)).wrapping_add(t2m);
        let s = &mut self.sums[k];
        s.sum2.add64(square32(d2));
        if let Some(t3m) = t3m {
            let d2_prev = tm
                .wrapping_sub(t2m.wrapping_mul(2))
                .wrapping_add(t3m as i32);
            s.sum3.add64(square32(d2.wrapping_sub(d2_prev)));
        }
    }

    #[inline(always)]
    fn accumulate(&mut self, k: usize, tm: i64, t2m: i64, t3m: Option<i64>) {
        if k < self.narrow as usize {
            self.accumulate_narrow(k, tm, t2m, t3m);
        } else {
            self.accumulate_wide(k, tm, t2m, t3m);
        }
    }

    /// Feed one rate sample (already corrected, fixed point).
    #[inline]
    pub fn push(&mut self, y: i32) {
        // 1. θ[t] enters the base ring; θ[t − 3P] leaves it and trickles up the cascade.
        let slot = self.base_head as usize;
        let (row, col) = if slot < R { (0, slot) } else { (1, slot - R) };
        let leaving = core::mem::replace(&mut self.rings[row][col], self.theta);
        self.base_head = if slot + 1 == Self::BASE {
            0
        } else {
            slot as u8 + 1
        };
        if self.t >= Self::BASE as u64 {
            self.cascade(self.t - Self::BASE as u64, leaving);
        }
        self.theta = self.theta.wrapping_add(y as i64);
        self.t += 1;
        self.total += 1;
        let a = y.unsigned_abs();
        if a > self.amax {
            self.amax = a;
            self.narrow = Self::narrow_levels(a);
        }
        if self.t >= self.next_valid {
            self.advance_valid();
        }
        let (half, full) = (self.half as usize, self.full as usize);

        // 2. Unit-stride levels (m ≤ P): every sample. The steady state (all of them valid, all
        //    narrow) is a fixed-trip, 32-bit loop the compiler unrolls with constant ages.
        let unit = if half < Self::K0 { half } else { Self::K0 };
        if full >= Self::K0 && self.narrow as usize >= Self::K0 {
            let t0 = self.theta as i32;
            for k in 0..Self::K0 {
                let m = 1usize << k;
                let (tm, t2m, t3m) = (self.base_low(m), self.base_low(2 * m), self.base_low(3 * m));
                let d2 = t0.wrapping_sub(tm.wrapping_mul(2)).wrapping_add(t2m);
                let d2_prev = tm.wrapping_sub(t2m.wrapping_mul(2)).wrapping_add(t3m);
                let s = &mut self.sums[k];
                s.sum2.add64(square32(d2));
                s.sum3.add64(square32(d2.wrapping_sub(d2_prev)));
            }
        } else {
            for k in 0..unit {
                let m = 1usize << k;
                let tm = self.base_at_age(m);
                let t2m = self.base_at_age(2 * m);
                let t3m = (k < full).then(|| self.base_at_age(3 * m));
                self.accumulate(k, tm, t2m, t3m);
            }
        }
        // 3. Strided levels: level k works when t is a multiple of its stride 2^(k−K0+1)
        //    (tested on the low word: strides are below 2^32).
        let t32 = self.t as u32;
        let mut k = Self::K0;
        while k < half {
            let stride_mask = (1u32 << (k + 1 - Self::K0)) - 1;
            if t32 & stride_mask != 0 {
                return;
            }
            let tm = if k == Self::K0 {
                self.base_at_age(2 * P)
            } else {
                self.ring_back(k - 1, Self::BACK)
            };
            let t2m = self.ring_back(k, Self::BACK);
            let t3m = (k < full).then(|| self.ring_back(k, R - 1));
            self.accumulate(k, tm, t2m, t3m);
            k += 1;
        }
    }

    /// Move θ[index] (which just left the level below) into the strided levels' rings.
    #[inline]
    fn cascade(&mut self, mut index: u64, mut value: i64) {
        let mut k = Self::K0;
        while k < L {
            let stride_shift = k + 1 - Self::K0;
            if (index as u32) & ((1u32 << stride_shift) - 1) != 0 {
                return;
            }
            let h = self.heads[k] as usize;
            let next = if h + 1 == R { 0 } else { h + 1 };
            self.heads[k] = next as u8;
            let leaving = core::mem::replace(&mut self.rings[k][next], value);
            let span = ((R as u32) << stride_shift) as u64;
            if index < span {
                return;
            }
            index -= span;
            value = leaving;
            k += 1;
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

    #[test]
    fn constant_rate_gives_zero_sums_and_right_counts() {
        let mut e = Engine::<4, 8, 6>::new();
        for _ in 0..1000 {
            e.push(-12345);
        }
        for l in e.levels() {
            let l = &l;
            assert_eq!(l.sum2, 0);
            assert_eq!(l.sum3, 0);
            // n2 = number of t in [2m, 1000] that are multiples of the stride.
            let s = l.stride as u64;
            let m = l.m as u64;
            let expect = if 1000 >= 2 * m {
                1000 / s - (2 * m).div_ceil(s) + 1
            } else {
                0
            };
            assert_eq!(l.n2, expect, "m = {}", l.m);
        }
    }
}
