//! The streaming octave engine: bounded memory, integer-exact, no allocation and no floating
//! point on the per-sample path.
//!
//! # What it computes
//! For every octave level `m = 2^k` (`k = 0..L`) it accumulates, exactly in `u128`, the sums of
//! squared second differences of the phase `θ` (Jaime et al., "Caracterización y calibración de
//! unidades de medición inercial de bajo costo", eqs. 8–9; `θ[t] = Σ_{i<t} y_i`):
//!
//! ```text
//! D2(t) = θ[t] − 2θ[t−m] + θ[t−2m]            (Allan; Jaime et al. eqs. 7–9)
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
//! itself wraps. While `4·m·max|y| < 2^31` a level's differences are computed from the low 32-bit
//! words of `θ` (exact: they are known to fit in `i32`) and squared with one 32-bit multiply when
//! `|D| < 2^16`, three 16×16 ones otherwise (the Cortex-M0+ has only a 32×32→32 multiplier);
//! wider differences are squared in `u128`. Sums are exact `u128`s kept as four u32 words.
//! docs/allan.md gives the overflow argument for 30 days at 1 kHz.
//!
//! # The hot path
//! `push` takes a straight steady-state path (no per-level checks) once the base ring is full and
//! the unit-stride levels are narrow, for every |y| not above the segment's largest so far (in a
//! copy without range tests on the unit-stride squares while that largest |y| is small); the
//! rest goes through a general path. docs/allan.md ("Cost on the Cortex-M0+") explains the
//! choices and gives the measured cycles.

#[cfg(all(target_arch = "arm", feature = "thumb-asm"))]
mod thumb;

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
    /// `σ² = Σ D2² / (2 n m²)` (Jaime et al. eq. 7 with eq. 9; NIST SP 1065 eq. 11).
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

/// An exact 128-bit sum kept as four u32 words (least significant first). Adding a square
/// below 2^32 — every |D| < 2^16, the common case — is one 32-bit add and a rarely taken carry;
/// a 64-bit square is a 64-bit add and a rarely taken carry. The M0+ has no 64-bit registers, so
/// a `u128 +=` would touch all four words every time.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[repr(C)]
struct Sum128 {
    w: [u32; 4],
}

impl Sum128 {
    const ZERO: Sum128 = Sum128 { w: [0; 4] };

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

    fn get(&self) -> u128 {
        self.w
            .iter()
            .rev()
            .fold(0u128, |acc, &w| acc << 32 | w as u128)
    }
}

/// Multiples of `stride` (a power of two) in `[span, t]`: the differences a segment of `t`
/// samples contributes when each needs `span` samples of history.
fn terms(t: u64, span: u64, stride: u64) -> u64 {
    if t < span {
        return 0;
    }
    // Strides are powers of two and every span a multiple of its stride: shifts, not the
    // 64-bit divisions the Cortex-M0+ does in software (a table snapshot asks for 480 of these).
    debug_assert!(stride.is_power_of_two() && span.is_multiple_of(stride));
    let shift = stride.trailing_zeros();
    if t >> 32 == 0 {
        // A variable 64-bit shift is a library call on the Cortex-M0+; a 32-bit one is one
        // instruction (and span ≤ t fits too).
        return u64::from(((t as u32) >> shift) - ((span as u32) >> shift) + 1);
    }
    (t >> shift) - (span >> shift) + 1
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

/// Streaming overlapping Allan and Hadamard engine for one channel.
///
/// * `P` — overlap factor: differences per cluster length at the high levels (power of two ≥ 2).
/// * `L` — number of octave levels (`m = 1, 2, …, 2^(L−1)`).
/// * `R` — own-ring length per strided level, must equal `3P/2`.
/// * `S` — number of strided levels (`m > P`), must equal `L − log2(P) − 1`.
///
/// `R` and `S` are separate parameters only because stable Rust cannot size an array by
/// `3 * P / 2` or `L − log2(P) − 1`; both are checked at compile time. Use [`DeviceEngine`] and
/// [`MagEngine`] for the firmware's configurations.
///
/// The layout is `repr(C)` and ordered for the Cortex-M0+, whose loads and stores reach only
/// 124 bytes past a base register: the sums come first (the unit-stride levels' are then
/// addressed straight from `self`), then the base ring, the per-sample scalars, the own rings
/// and the closed counts.
#[derive(Clone, Debug)]
#[repr(C)]
pub struct Engine<const P: usize, const L: usize, const R: usize, const S: usize> {
    /// Σ D2² and Σ D3² of each level.
    sums: [[Sum128; 2]; L],
    /// The base ring: the last 3P phase values, in one of two forms.
    ///
    /// * Narrow (`narrow ≥ K0`, i.e. max |y| < 2^(30−K0)): low words only, mirrored —
    ///   lo θ[t − a] (1 ≤ a ≤ 3P) in word (t − a) mod 3P and again 3P words later. Any 3P
    ///   consecutive words starting at t mod 3P are then the last 3P values in order, so the
    ///   unit-stride levels read them at constant offsets with no wrap. A full value is
    ///   θ[t − a] = θ[t] − (lo θ[t] − lo θ[t − a]) as i32, exact because |θ[t] − θ[t − a]| ≤
    ///   3P·max|y| < 2^31.
    /// * Wide (larger inputs, until the next gap): θ[t − a] as an i64 in words
    ///   2s, 2s + 1 (low first) of slot s = (t − a) mod 3P.
    base: [[u32; R]; 4],
    /// θ[t], wrapping.
    theta: i64,
    /// Samples pushed since the start of the current segment (θ's index).
    t: u64,
    /// `push` takes the steady-state path for `|y| < gate`: `amax + 1` once the base ring is
    /// full (t ≥ 3P) and every unit-stride level is narrow, else 0 (never).
    gate: u32,
    /// Largest |z| = |y − c| of this segment (see `offset`).
    amax: u32,
    /// Base ring: slot of the next write (= t mod 3P).
    base_head: u8,
    /// The first strided level without third differences yet in this segment (levels below it
    /// have both; it is advanced when that level next works, so the hot path never checks t).
    full: u8,
    /// Levels whose differences provably fit in i32 given `amax` (computed in 32-bit words).
    narrow: u8,
    /// Own rings: slot of the newest entry.
    heads: [u8; S],
    /// Number of gaps marked since the last reset.
    gaps: u32,
    /// c, subtracted from every input of the segment: its first sample, clamped to ±2^30.
    /// D2 and D3 of y − c equal those of y exactly (c·t is linear in t, which second and third
    /// differences cancel), and for a sensor at rest |y − c| is the noise and the drift only,
    /// so more channels stay on the small path. Everything below (θ, max |y|, the gate)
    /// refers to z = y − c, |z| < 2^31 + 2^30. (Fills what was padding before `closed`.)
    offset: i32,
    /// Samples of the closed segments since the last reset (`samples() = closed + t`).
    closed: u64,
    /// Own rings of the strided levels (row `k − K0` for level `k`).
    rings: [[i64; R]; S],
    /// Numbers of second and third differences of the closed segments of each level (the
    /// current segment's follow from its length, so nothing is counted per sample).
    counts: [[u64; 2]; L],
}

/// The firmware's configuration: overlap factor 8, 24 octave levels (τ up to 2^23 samples,
/// 2.3 h at 1 kHz).
pub type DeviceEngine =
    Engine<{ DEVICE_PARAMS[0] }, { DEVICE_PARAMS[1] }, { DEVICE_PARAMS[2] }, { DEVICE_PARAMS[3] }>;

/// [`DeviceEngine`]'s parameters `[P, L, R, S]`, stated once: the type is built from them, the
/// firmware reports them, and the Thumb routines (written for this layout) run exactly when an
/// engine's parameters are these.
pub const DEVICE_PARAMS: [usize; 4] = [8, 24, 12, 20];

/// The firmware's magnetometer configuration: the same overlap, 22 levels (τ up to 2^21 samples,
/// 2.9 h at 200 Hz, the same reach in seconds as [`DeviceEngine`] at 1 kHz).
pub type MagEngine =
    Engine<{ MAG_PARAMS[0] }, { MAG_PARAMS[1] }, { MAG_PARAMS[2] }, { MAG_PARAMS[3] }>;

/// [`MagEngine`]'s parameters `[P, L, R, S]`, stated once.
pub const MAG_PARAMS: [usize; 4] = [8, 22, 12, 18];

// The firmware's per-channel memory (docs/allan.md), checked on every target including
// thumbv6m: the layout is repr(C) and u64/i64 align to 8 there as on the host.
const _: () = assert!(core::mem::size_of::<DeviceEngine>() == 3328);
const _: () = assert!(core::mem::size_of::<MagEngine>() == 3040);

impl<const P: usize, const L: usize, const R: usize, const S: usize> Default
    for Engine<P, L, R, S>
{
    fn default() -> Self {
        Self::new()
    }
}

impl<const P: usize, const L: usize, const R: usize, const S: usize> Engine<P, L, R, S> {
    /// log2(P) + 1: the number of unit-stride levels, and the first level with stride 2
    /// (m = 2P).
    const K0: usize = P.trailing_zeros() as usize + 1;
    const BASE: usize = 3 * P;
    /// Entries between the newest one of a ring and the value 2P strides older.
    const BACK: usize = 2 * P - R - 1;
    /// `push` takes the small steady path while gate = max |y| + 1 < 2^SMALL_GATE_BITS: then
    /// |D3| ≤ 4·m·max|y| < 4·P·2^SMALL_GATE_BITS ≤ 2^16 for every unit-stride level (m ≤ P).
    const SMALL_GATE_BITS: u32 = 14 - P.trailing_zeros();
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
        assert!(S + Self::K0 == L, "S must equal L − log2(P) − 1");
        assert!(3 * P <= 255, "ring slots are u8");
    };

    /// A fresh engine with no samples.
    pub const fn new() -> Self {
        #[allow(clippy::let_unit_value)]
        let _ = Self::VALID;
        Self {
            sums: [[Sum128::ZERO; 2]; L],
            base: [[0; R]; 4],
            theta: 0,
            t: 0,
            gate: 0,
            amax: 0,
            base_head: 0,
            full: Self::K0 as u8,
            narrow: Self::narrow_levels(0),
            heads: [R as u8 - 1; S],
            gaps: 0,
            offset: 0,
            closed: 0,
            rings: [[0; R]; S],
            counts: [[0; 2]; L],
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
            self.counts[k][0] += n2;
            self.counts[k][1] += n3;
        }
        self.closed += self.t;
        self.theta = 0;
        self.t = 0;
        self.gate = 0;
        self.amax = 0;
        self.base_head = 0;
        self.full = Self::K0 as u8;
        self.narrow = Self::narrow_levels(0);
        self.heads = [R as u8 - 1; S];
    }

    /// (second, third) differences level `k` has taken in the current segment.
    fn segment_terms(&self, k: usize) -> (u64, u64) {
        let m = if k < 32 {
            u64::from(1u32 << k)
        } else {
            1u64 << k
        };
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

    /// Samples pushed since the last reset.
    pub fn samples(&self) -> u64 {
        self.closed + self.t
    }

    /// Gaps marked since the last reset.
    pub fn gaps(&self) -> u32 {
        self.gaps
    }

    /// The sums of level `k` (m = 2^k), or `None` past the last level.
    pub fn level(&self, k: usize) -> Option<LevelSums> {
        let [s2, s3] = self.sums.get(k)?;
        let [c2, c3] = self.counts[k];
        let (n2, n3) = self.segment_terms(k);
        Some(LevelSums {
            m: 1u32 << k,
            stride: Self::stride(k),
            n2: c2 + n2,
            sum2: s2.get(),
            n3: c3 + n3,
            sum3: s3.get(),
        })
    }

    /// The per-level sums, level 0 (m = 1) first.
    pub fn levels(&self) -> impl Iterator<Item = LevelSums> + '_ {
        (0..L).filter_map(|k| self.level(k))
    }

    /// Whether the base ring holds mirrored low words (see [`Engine::base`]): exactly when
    /// every unit-stride level is narrow, max |y| < 2^(30−K0).
    #[inline(always)]
    fn base_is_narrow(&self) -> bool {
        self.narrow as usize >= Self::K0
    }

    /// θ[t] − (lo θ[t] − lo): the full value of a phase whose distance from θ[t] fits in i32.
    #[inline(always)]
    fn from_low(theta: i64, lo: u32) -> i64 {
        theta.wrapping_sub((theta as u32).wrapping_sub(lo) as i32 as i64)
    }

    /// θ[t − age] from the base ring, 1 ≤ age ≤ 3P.
    #[inline(always)]
    fn base_at_age(&self, age: usize) -> i64 {
        let h = self.base_head as usize;
        let slot = if h >= age {
            h - age
        } else {
            h + Self::BASE - age
        };
        let words = self.base.as_flattened();
        if self.base_is_narrow() {
            Self::from_low(self.theta, words[slot])
        } else {
            (words[2 * slot + 1] as i64) << 32 | words[2 * slot] as i64
        }
    }

    /// θ[t] enters the base ring; returns θ[t − 3P], which leaves it.
    #[inline(always)]
    fn base_push(&mut self) -> i64 {
        let h = (self.base_head as usize).min(Self::BASE - 1);
        let theta = self.theta;
        let narrow = self.base_is_narrow();
        let words = self.base.as_flattened_mut();
        let leaving = if narrow {
            let lo = core::mem::replace(&mut words[h], theta as u32);
            words[h + Self::BASE] = theta as u32;
            Self::from_low(theta, lo)
        } else {
            let lo = core::mem::replace(&mut words[2 * h], theta as u32);
            let hi = core::mem::replace(&mut words[2 * h + 1], (theta >> 32) as u32);
            (hi as i64) << 32 | lo as i64
        };
        self.base_head = if h + 1 == Self::BASE { 0 } else { h as u8 + 1 };
        leaving
    }

    /// Rewrite the base ring from the narrow to the wide form (once per segment at most, when
    /// max |y| first reaches 2^(30−K0)). Runs before θ[t] enters the ring, so every value held
    /// is within (3P − 1)·(the old max |y|) < 2^31 of θ[t] and is recovered exactly.
    #[cold]
    #[inline(never)]
    fn widen_base(&mut self) {
        let theta = self.theta;
        let words = self.base.as_flattened_mut();
        for s in 0..Self::BASE {
            // Slot s's low word is read from its mirror, 3P words on: the wide slots written so
            // far cover words 0 … 2s − 1 < s + 3P.
            let v = Self::from_low(theta, words[s + Self::BASE]);
            words[2 * s] = v as u32;
            words[2 * s + 1] = (v >> 32) as u32;
        }
    }

    /// Entry `back` places older than the newest of strided level `k`'s own ring.
    #[inline(always)]
    fn ring_back(&self, k: usize, back: usize) -> i64 {
        let j = k - Self::K0;
        let h = self.heads[j] as usize;
        let slot = if h >= back { h - back } else { h + R - back };
        self.rings[j][slot]
    }

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
    fn accumulate_narrow(sums: &mut [Sum128; 2], t0: u32, tm: u32, t2m: u32, t3m: Option<u32>) {
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
    fn accumulate_small(sums: &mut [Sum128; 2], t0: u32, tm: u32, t2m: u32, t3m: u32) {
        let d2 = t0.wrapping_sub(tm.wrapping_mul(2)).wrapping_add(t2m);
        let d3 = d2.wrapping_sub(tm.wrapping_sub(t2m.wrapping_mul(2)).wrapping_add(t3m));
        let [s2, s3] = sums;
        s2.add32(d2.wrapping_mul(d2));
        s3.add32(d3.wrapping_mul(d3));
    }

    #[inline(always)]
    fn accumulate(&mut self, k: usize, tm: i64, t2m: i64, t3m: Option<i64>) {
        if k < self.narrow as usize {
            let t0 = self.theta as u32;
            let t3m = t3m.map(|v| v as u32);
            Self::accumulate_narrow(&mut self.sums[k], t0, tm as u32, t2m as u32, t3m);
        } else {
            self.accumulate_wide(k, tm, t2m, t3m);
        }
    }

    /// Feed one rate sample (already corrected, fixed point).
    #[inline]
    pub fn push(&mut self, y: i32) {
        let gate = self.gate;
        // z = y − c in 32 bits. When the true z does not fit i32, the wrapped one has
        // |z| ≥ 2^31 − 2^30, above any nonzero gate (≤ 2^(30−K0) + 1, the base ring being
        // narrow), so only exact values pass; the general path recomputes z in i64.
        let z = y.wrapping_sub(self.offset);
        if z.unsigned_abs() < gate {
            // gate = max |y| + 1 here: one `LSRS` tests gate < 2^SMALL_GATE_BITS (2^11 for P = 8).
            if gate >> Self::SMALL_GATE_BITS == 0 {
                #[cfg(all(target_arch = "arm", feature = "thumb-asm"))]
                if let Some(e) = self.as_device_engine() {
                    // SAFETY: the steady, small conditions were just checked.
                    unsafe { thumb::push_small(e, z) };
                    return;
                }
                self.push_steady::<true>(z);
            } else {
                self.push_steady::<false>(z);
            }
        } else {
            self.push_general(y);
        }
    }

    /// Feed two consecutive rate samples: exactly `push(y0)` then `push(y1)`.
    ///
    /// On ARM with the `thumb-asm` feature (the firmware's build), a [`DeviceEngine`] takes both
    /// in one hand-scheduled Thumb routine (`stream/thumb.rs`) when they are steady-state samples
    /// and the segment's count is even (feed a segment in pairs from its start to keep it so);
    /// everything else, and every other build, goes through [`Engine::push`]. Single samples of
    /// a `DeviceEngine` in the steady state take the same Thumb code, one at a time.
    #[inline]
    pub fn push_pair(&mut self, y0: i32, y1: i32) {
        #[cfg(all(target_arch = "arm", feature = "thumb-asm"))]
        if let Some(e) = self.as_device_engine() {
            if thumb::push_pair_small(e, y0, y1) {
                return;
            }
        }
        self.push(y0);
        self.push(y1);
    }

    /// `self` as the firmware's [`DeviceEngine`], whose layout the Thumb routines are written
    /// for, if that is what it is.
    #[cfg(all(target_arch = "arm", feature = "thumb-asm"))]
    #[inline(always)]
    fn as_device_engine(&mut self) -> Option<&mut DeviceEngine> {
        ([P, L, R, S] == DEVICE_PARAMS)
            // SAFETY: with these parameters `Self` is `DeviceEngine`.
            .then(|| unsafe { &mut *(self as *mut Self).cast::<DeviceEngine>() })
    }

    /// The steady state: the base ring is full (t ≥ 3P, so every unit-stride level has D2 and
    /// D3 and the cascade runs), every unit-stride level is narrow and |y| ≤ amax (nothing to
    /// re-derive). No per-level validity checks, no 64-bit multiplies, no variable 64-bit shifts.
    ///
    /// `SMALL`: max |y| < 2^11, so every unit-stride difference is below 2^16 (|D3| ≤ 4·m·max|y|
    /// ≤ 32·(2^11 − 1) < 2^16 for m ≤ 8) and is squared with one multiply and no range test.
    #[inline(always)]
    fn push_steady<const SMALL: bool>(&mut self, z: i32) {
        // 1. θ[t] enters the (narrow) base ring; θ[t − 3P] leaves it.
        let t = self.t;
        let theta = self.theta;
        let h = (self.base_head as usize).min(Self::BASE - 1);
        let words = self.base.as_flattened_mut();
        let lo = core::mem::replace(&mut words[h], theta as u32);
        words[h + Self::BASE] = theta as u32;
        let h = if h + 1 == Self::BASE { 0 } else { h + 1 };
        self.base_head = h as u8;
        let theta = theta.wrapping_add(z as i64);
        self.theta = theta;
        self.t = t + 1;

        // 2. Unit-stride levels (m ≤ P).
        let t2p = self.unit_levels::<SMALL>(h, theta as u32);

        // 3. θ[t − 3P] trickles up the cascade (even t), or the strided levels work (odd t:
        //    t + 1 is a multiple of their strides); 3P is even, so θ[t − 3P] enters level K0
        //    exactly when t is even.
        if t as u32 & 1 == 0 {
            // θ[t − 3P] from θ[t + 1]: 3P + 1 samples apart, each below 2^(30−K0), so within
            //    (3P + 1)·2^(30−K0) < 2^31.
            let index = (t as u32).wrapping_sub(Self::BASE as u32);
            self.cascade(index, Self::from_low(theta, lo));
        } else {
            self.strided(t2p);
        }
    }

    /// D2 and D3 of every unit-stride level, in 32-bit words, with no validity checks; unrolled
    /// by hand (`opt-level = "s"` keeps the loop), so every read is at a constant offset.
    /// `h` = t mod 3P. Returns lo θ[t − 2P].
    #[inline(always)]
    fn unit_levels<const SMALL: bool>(&mut self, h: usize, t0: u32) -> u32 {
        // The last 3P low words of θ, oldest first: w[3P − a] = lo θ[t − a], 1 ≤ a ≤ 3P.
        let w = &self.base.as_flattened()[h..h + Self::BASE];
        let sums = &mut self.sums;
        let tm = w[Self::BASE - 1];
        let tm = Self::unit_level::<0, SMALL>(sums, w, t0, tm);
        let tm = Self::unit_level::<1, SMALL>(sums, w, t0, tm);
        let tm = Self::unit_level::<2, SMALL>(sums, w, t0, tm);
        let tm = Self::unit_level::<3, SMALL>(sums, w, t0, tm);
        let tm = Self::unit_level::<4, SMALL>(sums, w, t0, tm);
        let tm = Self::unit_level::<5, SMALL>(sums, w, t0, tm);
        Self::unit_level::<6, SMALL>(sums, w, t0, tm)
    }

    /// Unit-stride level `K` (m = 2^K ≤ P; nothing for K ≥ K0) given lo θ[t] and lo θ[t − m];
    /// returns lo θ[t − 2m], the next level's θ[t − m].
    #[inline(always)]
    fn unit_level<const K: usize, const SMALL: bool>(
        sums: &mut [[Sum128; 2]; L],
        w: &[u32],
        t0: u32,
        tm: u32,
    ) -> u32 {
        if K >= Self::K0 {
            return tm;
        }
        let m = 1 << K;
        let t2m = w[Self::BASE - 2 * m];
        let t3m = w[Self::BASE - 3 * m];
        if SMALL {
            Self::accumulate_small(&mut sums[K], t0, tm, t2m, t3m);
        } else {
            Self::accumulate_narrow(&mut sums[K], t0, tm, t2m, Some(t3m));
        }
        t2m
    }

    /// Everything else: the start of a segment (t < 3P), a new largest |y|, or inputs so large
    /// that the unit-stride levels need 64-bit differences.
    #[inline(never)]
    fn push_general(&mut self, y: i32) {
        if self.t == 0 {
            self.offset = y.clamp(-(1 << 30), 1 << 30);
        }
        let z = y as i64 - self.offset as i64;
        // |z| ≤ 2^31 + 2^30 < 2^32.
        let a = z.unsigned_abs() as u32;
        if a > self.amax {
            let was_narrow = self.base_is_narrow();
            self.amax = a;
            self.narrow = Self::narrow_levels(a);
            if was_narrow && !self.base_is_narrow() {
                self.widen_base();
            }
        }
        let leaving = self.base_push();
        self.cascade((self.t as u32).wrapping_sub(Self::BASE as u32), leaving);
        self.theta = self.theta.wrapping_add(z);
        self.t += 1;
        let t = self.t;
        for k in 0..Self::K0 {
            let m = 1usize << k;
            if t < 2 * m as u64 {
                break;
            }
            let tm = self.base_at_age(m);
            let t2m = self.base_at_age(2 * m);
            let t3m = (t >= 3 * m as u64).then(|| self.base_at_age(3 * m));
            self.accumulate(k, tm, t2m, t3m);
        }
        self.strided_general(t, Self::K0);
        self.gate = if t >= Self::BASE as u64 && self.base_is_narrow() {
            self.amax + 1
        } else {
            0
        };
    }

    /// Strided levels at the current sample count t (even), steady state: level `K0 + j` works when t is
    /// a multiple of its stride 2^(j+1), i.e. for the levels below the lowest set bit of t
    /// (tested on the low word: strides are below 2^32). `tm` = lo θ[t − 2P]. Levels that are
    /// full and narrow chain like the unit-stride ones; the rest go to [`Self::strided_general`].
    ///
    /// Level K0 works on every call and is peeled: its ring and sums are at constant offsets
    /// from `self`. The higher levels (every other call and rarer) loop in [`Self::strided_up`].
    #[inline(never)]
    extern "C" fn strided(&mut self, tm: u32) {
        if S == 0 {
            return;
        }
        let t = self.t as u32;
        let fast = self.full.min(self.narrow) as usize;
        if Self::K0 >= fast {
            self.strided_general(self.t, Self::K0);
            return;
        }
        // Level K0 (m = 2P) has |D3| ≤ 8·P·max|z| < 2^16 when gate < 2^(SMALL_GATE_BITS − 1).
        let t0 = self.theta as u32;
        let tm = if self.gate >> (Self::SMALL_GATE_BITS - 1) == 0 {
            self.strided_level::<true>(0, t0, tm)
        } else {
            self.strided_level::<false>(0, t0, tm)
        };
        if t & 2 == 0 {
            self.strided_up(tm, fast);
        }
    }

    /// One full, narrow strided level `K0 + j` given lo θ[t] and lo θ[t − m]; returns
    /// lo θ[t − 2m], the next level's θ[t − m].
    #[inline(always)]
    fn strided_level<const SMALL: bool>(&mut self, j: usize, t0: u32, tm: u32) -> u32 {
        // θ[t − 2m] is BACK entries behind the newest of this level's ring, θ[t − 3m] is the
        // oldest (the one after the newest).
        let h = (self.heads[j] as usize).min(R - 1);
        let back = if h >= Self::BACK {
            h - Self::BACK
        } else {
            h + R - Self::BACK
        };
        let oldest = if h + 1 == R { 0 } else { h + 1 };
        let ring = &self.rings[j];
        let (t2m, t3m) = (ring[back] as u32, ring[oldest] as u32);
        let sums = &mut self.sums[Self::K0 + j];
        if SMALL {
            Self::accumulate_small(sums, t0, tm, t2m, t3m);
        } else {
            Self::accumulate_narrow(sums, t0, tm, t2m, Some(t3m));
        }
        t2m
    }

    /// Strided levels from K0 + 1 on (t a multiple of 4), `tm` = lo θ[t − 2^(K0+1)];
    /// `fast` = min(full, narrow). Level K0 + 1 is peeled like level K0; the loop over the
    /// higher ones runs when t is a multiple of 8.
    #[inline(never)]
    fn strided_up(&mut self, tm: u32, fast: usize) {
        if S < 2 {
            return;
        }
        let t = self.t;
        if Self::K0 + 1 >= fast {
            self.strided_general(t, Self::K0 + 1);
            return;
        }
        let tm = self.strided_level::<false>(1, self.theta as u32, tm);
        if t as u32 & 4 == 0 {
            self.strided_rest(tm, fast);
        }
    }

    /// Strided levels from K0 + 2 on (t a multiple of 8), `tm` = lo θ[t − 2^(K0+2)].
    #[inline(never)]
    fn strided_rest(&mut self, mut tm: u32, fast: usize) {
        let t = self.t;
        let t0 = self.theta as u32;
        let mut bits = (t as u32) >> 2;
        let mut j = 2;
        while j < S {
            if bits & 1 != 0 {
                return;
            }
            bits >>= 1;
            let k = Self::K0 + j;
            if k >= fast {
                self.strided_general(t, k);
                return;
            }
            tm = self.strided_level::<false>(j, t0, tm);
            j += 1;
        }
    }

    /// [`Self::strided_general`] from level `from` at the current count (for the Thumb code).
    #[cfg(all(target_arch = "arm", feature = "thumb-asm"))]
    #[inline(never)]
    extern "C" fn strided_tail(&mut self, from: u32) {
        self.strided_general(self.t, from as usize);
    }

    /// Strided levels from level `from` on at sample count `t`, any state (start of a segment,
    /// wide levels).
    #[cold]
    #[inline(never)]
    fn strided_general(&mut self, t: u64, from: usize) {
        let mut k = from;
        while k < L {
            let stride_mask = (1u32 << (k + 1 - Self::K0)) - 1;
            if t as u32 & stride_mask != 0 {
                return;
            }
            let tm = if k == Self::K0 {
                self.base_at_age(2 * P)
            } else {
                self.ring_back(k - 1, Self::BACK)
            };
            let t2m = self.ring_back(k, Self::BACK);
            let t3m = self.ring_back(k, R - 1);
            let m = 1u64 << k;
            if t < 2 * m {
                // No higher level has a difference yet either.
                return;
            }
            let has3 = t >= 3 * m;
            if has3 && k >= self.full as usize {
                // The levels below worked at this t too and became full first.
                self.full = (k + 1) as u8;
            }
            self.accumulate(k, tm, t2m, has3.then_some(t3m));
            k += 1;
        }
    }

    /// Move θ[index] (which just left the base ring) into the strided levels' rings: it enters
    /// level K0 if index is a multiple of 2, and the value it displaces, θ[index − 2R],
    /// moves on to level K0 + 1 if that index is a multiple of 4, and so on. Only the low word
    /// of the index is needed (the strides are below 2^32).
    ///
    /// The cascade also runs at the start of a segment, from t = 0 on (index negative): the
    /// rings then hold values of an imagined history before the segment, in the positions the
    /// real values will take. Differences are only ever formed from indices ≥ 0, so nothing
    /// needs to know when a ring has filled.
    #[inline(never)]
    fn cascade(&mut self, index: u32, value: i64) {
        // Level K0 (index is always even in the steady state, but the general path calls this
        // for every index).
        if S == 0 || index & 1 != 0 {
            return;
        }
        let value = self.ring_enter(0, value);
        // The value displaced, θ[index − 2R], moves on if that index is a multiple of 4.
        let index = index.wrapping_sub(2 * R as u32);
        if index & 3 == 0 {
            self.cascade_up(index, value);
        }
    }

    /// Put `value` into level `K0 + j`'s ring as its newest entry; returns the oldest, which
    /// it displaces.
    #[inline(always)]
    fn ring_enter(&mut self, j: usize, value: i64) -> i64 {
        let h = (self.heads[j] as usize).min(R - 1);
        let next = if h + 1 == R { 0 } else { h + 1 };
        self.heads[j] = next as u8;
        core::mem::replace(&mut self.rings[j][next], value)
    }

    /// The cascade from level K0 + 1 on: θ[index] (index a multiple of 4) enters it. Level
    /// K0 + 1 is peeled; the loop over the higher ones runs when the value displaced goes on.
    #[inline(never)]
    fn cascade_up(&mut self, index: u32, value: i64) {
        if S < 2 {
            return;
        }
        let value = self.ring_enter(1, value);
        let index = index.wrapping_sub(4 * R as u32);
        if index & 7 == 0 {
            self.cascade_rest(index, value);
        }
    }

    /// The cascade from level K0 + 2 on: θ[index] (index a multiple of 8) enters it.
    #[inline(never)]
    fn cascade_rest(&mut self, mut index: u32, mut value: i64) {
        let mut mask = 7u32;
        let mut span = 8 * R as u32;
        let mut j = 2;
        while j < S {
            if index & mask != 0 {
                return;
            }
            value = self.ring_enter(j, value);
            index = index.wrapping_sub(span);
            mask = mask << 1 | 1;
            span <<= 1;
            j += 1;
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
        let mut e = Engine::<4, 8, 6, 5>::new();
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
