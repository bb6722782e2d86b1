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
//! copy without range tests on the unit-stride squares while that largest |y| is small), and
//! for a new largest |y| that keeps them narrow, after raising that bound; the rest goes
//! through a general path. docs/allan.md ("Cost on the Cortex-M0+") explains the
//! choices and gives the measured cycles.

mod general;
mod levels;
mod steady;
mod strided;
mod sum;
#[cfg(all(target_arch = "arm", feature = "thumb-asm"))]
mod thumb;

pub use levels::{Frozen, LevelSums};
#[doc(hidden)]
pub use steady::ThumbTaken;
use sum::Sum128;

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

    /// Levels k whose D2 and D3 fit in i32 for inputs up to `amax`: |D3| ≤ 4·2^k·amax < 2^31
    /// ⟺ amax < 2^(29−k). Off the hot path (the M0+ has no count-leading-zeros).
    const fn narrow_levels(amax: u32) -> u8 {
        let bits = 32 - amax.leading_zeros() as usize;
        let n = if bits > 29 { 0 } else { 30 - bits };
        (if n < L { n } else { L }) as u8
    }

    /// The name of the first field in which `self` and `other` differ, `None` when their
    /// states are the same word for word. For the Thumb differential test
    /// (crates/allan/thumb-check), which compares two engines after every call: the arrays are
    /// compared in word loops, so one comparison costs a few thousand Cortex-M0+ cycles.
    #[doc(hidden)]
    pub fn first_difference(&self, other: &Self) -> Option<&'static str> {
        let checks: [(&'static str, bool); 15] = [
            ("theta", self.theta != other.theta),
            ("t", self.t != other.t),
            ("gate", self.gate != other.gate),
            ("amax", self.amax != other.amax),
            ("base_head", self.base_head != other.base_head),
            ("full", self.full != other.full),
            ("narrow", self.narrow != other.narrow),
            ("heads", self.heads != other.heads),
            ("gaps", self.gaps != other.gaps),
            ("offset", self.offset != other.offset),
            ("closed", self.closed != other.closed),
            (
                "sums",
                differ(
                    words(self.sums.as_flattened()),
                    words(other.sums.as_flattened()),
                ),
            ),
            (
                "base",
                differ(self.base.as_flattened(), other.base.as_flattened()),
            ),
            (
                "rings",
                differ(
                    words(self.rings.as_flattened()),
                    words(other.rings.as_flattened()),
                ),
            ),
            (
                "counts",
                differ(
                    words(self.counts.as_flattened()),
                    words(other.counts.as_flattened()),
                ),
            ),
        ];
        checks.iter().find(|c| c.1).map(|c| c.0)
    }

    /// Samples pushed since the last reset.
    pub fn samples(&self) -> u64 {
        self.closed + self.t
    }

    /// Gaps marked since the last reset.
    pub fn gaps(&self) -> u32 {
        self.gaps
    }
}

/// Whether two equally long word arrays differ: one pass, eight words a step, no early exit
/// and no `memcmp` (a byte loop on the Cortex-M0+): about 8 cycles a word there.
#[inline(never)]
fn differ(a: &[u32], b: &[u32]) -> bool {
    let (a8, a1) = a.as_chunks::<8>();
    let (b8, b1) = b.as_chunks::<8>();
    let mut acc = 0;
    for (x, y) in a8.iter().zip(b8) {
        acc |= (x[0] ^ y[0]) | (x[1] ^ y[1]) | (x[2] ^ y[2]) | (x[3] ^ y[3]);
        acc |= (x[4] ^ y[4]) | (x[5] ^ y[5]) | (x[6] ^ y[6]) | (x[7] ^ y[7]);
    }
    for (x, y) in a1.iter().zip(b1) {
        acc |= x ^ y;
    }
    acc != 0 || a.len() != b.len()
}

/// Types made of whole u32 words: the arrays [`Engine::first_difference`] compares word by
/// word.
///
/// # Safety
/// Only for types at least 4-aligned whose size is a multiple of 4 and which have no padding
/// (plain integers, and `repr(C)` arrays of u32).
unsafe trait Words: Sized {}
// SAFETY: integers of 4 and 8 bytes (aligned to their size on every target this builds for, and
// at least to 4), no padding.
unsafe impl Words for u32 {}
// SAFETY: as above.
unsafe impl Words for u64 {}
// SAFETY: as above.
unsafe impl Words for i64 {}
// SAFETY: `repr(C)` with one `[u32; 4]` field.
unsafe impl Words for Sum128 {}

/// The memory of `s` as u32 words.
fn words<T: Words>(s: &[T]) -> &[u32] {
    // SAFETY: `T: Words` is a run of initialised u32 words with no padding, aligned to 4.
    unsafe { core::slice::from_raw_parts(s.as_ptr().cast::<u32>(), core::mem::size_of_val(s) / 4) }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_frozen_engine_keeps_its_levels_samples_and_gaps() {
        let mut e = MagEngine::new();
        let mut x = 0x1234_5678u32;
        let mut next = || {
            x ^= x << 13;
            x ^= x >> 17;
            x ^= x << 5;
            (x % 4001) as i32 - 2000
        };
        for i in 0..5000 {
            if i == 1700 {
                e.gap();
            }
            e.push(next());
        }
        let mut wide = Frozen::<8, 24>::EMPTY;
        let mut narrow = Frozen::<8, 4>::EMPTY;
        e.freeze(&mut wide);
        e.freeze(&mut narrow);
        let levels: std::vec::Vec<_> = e.levels().collect();
        let (samples, gaps) = (e.samples(), e.gaps());
        // The engine goes on; the frozen copies do not.
        for _ in 0..3000 {
            e.push(next());
        }
        assert_eq!((wide.samples(), wide.gaps()), (samples, gaps));
        assert_eq!((samples, gaps), (5000, 1));
        for (k, l) in levels.iter().enumerate() {
            assert_eq!(wide.level(k).as_ref(), Some(l), "level {k}");
            assert_eq!(narrow.level(k).as_ref(), (k < 4).then_some(l), "level {k}");
        }
        assert!(levels.iter().any(|l| l.sum3 > 0 && l.n3 > 0));
        // The levels with terms: those up to m = 1024 (a segment of 3300 samples since the gap,
        // 1700 before it: levels up to m = 1024 have second differences, m = 2048 needs 4096).
        let with_terms = levels.iter().take_while(|l| l.n2 > 0).count();
        assert_eq!(with_terms, 11);
        assert_eq!(wide.levels_with_terms(), with_terms);
        assert_eq!(narrow.levels_with_terms(), 4);
        assert_eq!(Frozen::<8, 24>::EMPTY.levels_with_terms(), 0);
        assert_eq!(levels.len(), MAG_PARAMS[1]);
        assert_eq!(wide.level(MAG_PARAMS[1]), None);
        assert_ne!(e.level(3), wide.level(3));
        // Frozen again after a reset: nothing of the deeper levels frozen before is left.
        e.reset();
        for _ in 0..100 {
            e.push(next());
        }
        e.freeze(&mut wide);
        assert_eq!(wide.levels_with_terms(), 6);
        for (k, l) in e.levels().enumerate() {
            assert_eq!(wide.level(k), Some(l), "level {k} after the reset");
        }
    }

    /// A frozen engine's levels with terms are the engine's, whatever the segments: random
    /// lengths and gaps (so that closed segments reach deeper or shallower than the current
    /// one), frozen at random moments, for both of the firmware's engines.
    #[test]
    fn frozen_levels_with_terms_are_the_engines_over_random_segments() {
        let key = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(7, |d| d.subsec_nanos() | 1);
        std::println!("generator key {key:#x}");
        let mut r = crate::test_rng::rng(key);
        // Uniform in 0..n.
        let mut next = move |n: u64| ((r() + 0.5) * n as f64) as u64;
        for _ in 0..20 {
            frozen_levels_match(&mut MagEngine::new(), &mut next);
            frozen_levels_match(&mut DeviceEngine::new(), &mut next);
        }
    }

    fn frozen_levels_match<const L: usize, const R: usize, const S: usize>(
        e: &mut Engine<8, L, R, S>,
        next: &mut impl FnMut(u64) -> u64,
    ) {
        let mut wide = Frozen::<8, 24>::EMPTY;
        let mut narrow = Frozen::<8, 5>::EMPTY;
        for _ in 0..1 + next(4) {
            // Segment lengths spread over the octaves: 0 to 32k samples.
            let octave = next(16);
            let n = next(1 << octave);
            for _ in 0..n {
                e.push(next(2001) as i32 - 1000);
            }
            let with_terms = e.levels().take_while(|l| l.n2 > 0).count();
            e.freeze(&mut wide);
            e.freeze(&mut narrow);
            assert_eq!(wide.levels_with_terms(), with_terms, "{n} samples");
            assert_eq!(narrow.levels_with_terms(), with_terms.min(5), "{n} samples");
            for (k, l) in e.levels().enumerate() {
                assert_eq!(wide.level(k), Some(l), "level {k}");
            }
            if next(2) == 0 {
                e.gap();
            }
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

    #[test]
    fn first_difference_names_the_field_that_differs() {
        let mut a = DeviceEngine::new();
        for i in 0..200 {
            a.push(i * 7 % 13 - 6);
        }
        let mut b = a.clone();
        assert_eq!(a.first_difference(&b), None);
        b.rings[3][5] ^= 1 << 40;
        assert_eq!(a.first_difference(&b), Some("rings"));
        b = a.clone();
        b.sums[20][1].w[3] ^= 1;
        assert_eq!(a.first_difference(&b), Some("sums"));
        b = a.clone();
        b.heads[19] ^= 1;
        assert_eq!(a.first_difference(&b), Some("heads"));
        b = a.clone();
        b.counts[23][1] += 1;
        assert_eq!(a.first_difference(&b), Some("counts"));
    }

    #[test]
    fn portable_pushes_are_the_pushes() {
        let (mut a, mut b) = (DeviceEngine::new(), DeviceEngine::new());
        for i in 0..3000 {
            let y = (i * 7919 % 4001) - 2000;
            if i % 3 == 0 {
                a.push(y);
                b.push_portable(y);
            } else {
                a.push_pair(y, -y / 2);
                b.push_pair_portable(y, -y / 2);
            }
            assert_eq!(a.first_difference(&b), None, "after call {i}");
        }
    }
}
