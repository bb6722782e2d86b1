//! What an engine reports: the per-level sums and the counts of differences they hold.
//!
//! The counts of the current segment are not kept per sample: they follow from its length and
//! each level's stride, and are added to the closed segments' counts here.

use super::sum::Sum128;
use super::Engine;

/// Sums of one octave level: everything a deviation, its EDF and its bounds derive from.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
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

/// Multiples of the stride `2^shift` in `[span, t]`: the differences a segment of `t` samples
/// contributes when each needs `span` samples of history (every span is a multiple of its
/// stride).
fn terms(t: u64, span: u64, shift: u32) -> u64 {
    if t < span {
        return 0;
    }
    (t >> shift) - (span >> shift) + 1
}

/// (second, third) differences level `k` has taken in the current segment.
///
/// A device's table asks this of every level of every engine. The Cortex-M0+ has no
/// divide, no count-trailing-zeros and no 64-bit shift instruction, so the stride is a shift
/// known from `k` (1 up to m = P, then m / P, P a power of two), and a segment shorter than
/// 2^32 samples takes 32-bit shifts.
fn segment_terms<const P: usize>(t: u64, k: usize) -> (u64, u64) {
    let shift = k.saturating_sub(P.trailing_zeros() as usize) as u32;
    if t >> 32 == 0 && k < 30 {
        let (t, m) = (t as u32, 1u32 << k);
        let terms = |span: u32| {
            if t < span {
                0
            } else {
                u64::from((t >> shift) - (span >> shift) + 1)
            }
        };
        return (terms(2 * m), terms(3 * m));
    }
    let m = 1u64 << k;
    (terms(t, 2 * m, shift), terms(t, 3 * m, shift))
}

/// Level `k` from its sums and its closed segments' counts, in a segment of `t` samples.
fn level_of<const P: usize>(k: usize, t: u64, sums: &[Sum128; 2], counts: &[u64; 2]) -> LevelSums {
    let (n2, n3) = segment_terms::<P>(t, k);
    LevelSums {
        m: 1u32 << k,
        stride: stride::<P>(k),
        n2: counts[0] + n2,
        sum2: sums[0].get(),
        n3: counts[1] + n3,
        sum3: sums[1].get(),
    }
}

/// Stride between the differences of level `k`: 1 up to m = P, then m / P.
fn stride<const P: usize>(k: usize) -> u32 {
    let m = 1u32 << k;
    if m as usize <= P {
        1
    } else {
        m / P as u32
    }
}

impl<const P: usize, const L: usize, const R: usize, const S: usize> Engine<P, L, R, S> {
    /// (second, third) differences level `k` has taken in the current segment.
    pub(super) fn segment_terms(&self, k: usize) -> (u64, u64) {
        segment_terms::<P>(self.t, k)
    }

    /// The sums of level `k` (m = 2^k), or `None` past the last level.
    pub fn level(&self, k: usize) -> Option<LevelSums> {
        Some(level_of::<P>(k, self.t, self.sums.get(k)?, &self.counts[k]))
    }

    /// The per-level sums, level 0 (m = 1) first.
    pub fn levels(&self) -> impl Iterator<Item = LevelSums> + '_ {
        (0..L).filter_map(|k| self.level(k))
    }

    /// Copy what the levels derive from into `out` (its first `min(L, N)` levels): a snapshot
    /// of a few words per level with terms (the others are all zeros, and not copied), where
    /// working the [`LevelSums`] out costs 64-bit and 128-bit arithmetic per level (a device
    /// freezes every engine between two samples and derives the levels later,
    /// [`Frozen::level`]).
    pub fn freeze<const N: usize>(&self, out: &mut Frozen<P, N>) {
        let depth = L.min(N);
        // Level k has second differences in the current segment once it spans 2^(k+1)
        // samples: the first ⌊log2 t⌋ levels. Above them, those whose closed segments had
        // some (a prefix too: a segment long enough for a level was long enough for every
        // level below). Without a segment_terms per level: the snapshot runs in one
        // millisecond of the device's budget.
        let by_segment = if self.t >= 2 {
            (63 - self.t.leading_zeros()) as usize
        } else {
            0
        };
        let mut filled = by_segment.min(depth);
        while filled < depth && self.counts[filled][0] > 0 {
            filled += 1;
        }
        out.t = self.t;
        out.closed = self.closed;
        out.gaps = self.gaps;
        out.depth = depth as u8;
        out.filled = filled as u8;
        out.sums[..filled].copy_from_slice(&self.sums[..filled]);
        out.counts[..filled].copy_from_slice(&self.counts[..filled]);
    }
}

/// An engine's level sums frozen at one instant ([`Engine::freeze`]): the same
/// [`Frozen::level`]s, [`Frozen::samples`] and [`Frozen::gaps`] as the engine had then, up to
/// `N` levels.
#[derive(Clone, Debug)]
pub struct Frozen<const P: usize, const N: usize> {
    t: u64,
    closed: u64,
    gaps: u32,
    /// Levels frozen (the engine's, at most `N`).
    depth: u8,
    /// Of these, the levels with terms, the only ones copied: the others have no differences
    /// yet, so their sums and counts are zero (a level has terms only if every level below it
    /// has: each needs more history than the one below).
    filled: u8,
    sums: [[Sum128; 2]; N],
    counts: [[u64; 2]; N],
}

impl<const P: usize, const N: usize> Frozen<P, N> {
    /// Nothing frozen yet: no samples, no levels.
    pub const EMPTY: Self = Frozen {
        t: 0,
        closed: 0,
        gaps: 0,
        depth: 0,
        filled: 0,
        sums: [[Sum128::ZERO; 2]; N],
        counts: [[0; 2]; N],
    };

    /// [`Engine::samples`] when frozen.
    pub fn samples(&self) -> u64 {
        self.closed + self.t
    }

    /// [`Engine::gaps`] when frozen.
    pub fn gaps(&self) -> u32 {
        self.gaps
    }

    /// How many levels, from level 0 up, have second differences (each needs more history
    /// than the one below, so these are the levels with any terms), without working out their
    /// sums.
    pub fn levels_with_terms(&self) -> usize {
        self.filled.into()
    }

    /// [`Engine::level`] when frozen.
    pub fn level(&self, k: usize) -> Option<LevelSums> {
        if k >= usize::from(self.depth) {
            return None;
        }
        if k >= usize::from(self.filled) {
            return Some(level_of::<P>(k, self.t, &[Sum128::ZERO; 2], &[0; 2]));
        }
        Some(level_of::<P>(k, self.t, &self.sums[k], &self.counts[k]))
    }
}
