//! What an engine reports: the per-level sums and the counts of differences they hold.
//!
//! The counts of the current segment are not kept per sample: they follow from its length and
//! each level's stride, and are added to the closed segments' counts here.

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

impl<const P: usize, const L: usize, const R: usize, const S: usize> Engine<P, L, R, S> {
    /// (second, third) differences level `k` has taken in the current segment.
    ///
    /// A table snapshot asks this of every level of every engine. The Cortex-M0+ has no
    /// divide, no count-trailing-zeros and no 64-bit shift instruction, so the stride is a shift
    /// known from `k` (1 up to m = P, then m / P, P a power of two), and a segment shorter than
    /// 2^32 samples takes 32-bit shifts.
    pub(super) fn segment_terms(&self, k: usize) -> (u64, u64) {
        let shift = k.saturating_sub(P.trailing_zeros() as usize) as u32;
        if self.t >> 32 == 0 && k < 30 {
            let (t, m) = (self.t as u32, 1u32 << k);
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
        (terms(self.t, 2 * m, shift), terms(self.t, 3 * m, shift))
    }

    pub(super) fn stride(k: usize) -> u32 {
        let m = 1u32 << k;
        if m as usize <= P {
            1
        } else {
            m / P as u32
        }
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
}
