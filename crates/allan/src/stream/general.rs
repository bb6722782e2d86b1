//! The general path and the base ring: the start of a segment, a new largest |y| (raising the
//! gate), wide inputs, and the base ring's two forms (mirrored low words while narrow, full i64
//! values when wide).

use super::Engine;

impl<const P: usize, const L: usize, const R: usize, const S: usize> Engine<P, L, R, S> {
    /// Everything else: the start of a segment (t < 3P), or inputs so large that the
    /// unit-stride levels need 64-bit differences.
    #[inline(never)]
    pub(super) fn push_general(&mut self, y: i32) {
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

    /// A sample at or above the gate in the steady state: when it is a new largest |y| that
    /// keeps the base ring narrow, nothing but `amax`, `narrow` and the gate depends on the
    /// largest |y| (the sums' form does not, and the steady path reads `narrow` for the strided
    /// levels), so they are raised here and the sample takes the steady path; `true` then.
    /// Otherwise (before the steady state, or an input that widens the base ring) nothing
    /// changes and the general path takes the sample. Without this a signal that drifts, or
    /// the noise's first seconds, would send every new extreme through the general path.
    #[cold]
    #[inline(never)]
    pub(super) fn raise_gate(&mut self, y: i32) -> bool {
        if self.gate == 0 {
            return false;
        }
        let z = y as i64 - self.offset as i64;
        // |z| ≤ 2^31 + 2^30 < 2^32, and above amax (|z| ≥ gate = amax + 1).
        let a = z.unsigned_abs() as u32;
        let narrow = Self::narrow_levels(a);
        if (narrow as usize) < Self::K0 {
            return false;
        }
        self.amax = a;
        self.narrow = narrow;
        self.gate = a + 1;
        true
    }

    /// Whether the base ring holds mirrored low words (see [`Engine::base`]): exactly when
    /// every unit-stride level is narrow, max |y| < 2^(30−K0).
    #[inline(always)]
    pub(super) fn base_is_narrow(&self) -> bool {
        self.narrow as usize >= Self::K0
    }

    /// θ[t] − (lo θ[t] − lo): the full value of a phase whose distance from θ[t] fits in i32.
    #[inline(always)]
    pub(super) fn from_low(theta: i64, lo: u32) -> i64 {
        theta.wrapping_sub((theta as u32).wrapping_sub(lo) as i32 as i64)
    }

    /// θ[t − age] from the base ring, 1 ≤ age ≤ 3P.
    #[inline(always)]
    pub(super) fn base_at_age(&self, age: usize) -> i64 {
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
    pub(super) fn base_push(&mut self) -> i64 {
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
    pub(super) fn widen_base(&mut self) {
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
}
