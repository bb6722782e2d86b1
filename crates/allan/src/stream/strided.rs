//! The strided levels (m > P): their differences at multiples of their strides, and the
//! cascade that moves each phase value leaving the base ring up through their own rings.

use super::Engine;

impl<const P: usize, const L: usize, const R: usize, const S: usize> Engine<P, L, R, S> {
    /// Strided levels at the current sample count t (even), steady state: level `K0 + j` works when t is
    /// a multiple of its stride 2^(j+1), i.e. for the levels below the lowest set bit of t
    /// (tested on the low word: strides are below 2^32). `tm` = lo θ[t − 2P]. Levels that are
    /// full and narrow chain like the unit-stride ones; the rest go to [`Self::strided_general`].
    ///
    /// Level K0 works on every call and is peeled: its ring and sums are at constant offsets
    /// from `self`. The higher levels (every other call and rarer) loop in [`Self::strided_up`].
    #[inline(never)]
    pub(super) extern "C" fn strided(&mut self, tm: u32) {
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
    pub(super) extern "C" fn strided_tail(&mut self, from: u32) {
        self.strided_general(self.t, from as usize);
    }

    /// Strided levels from level `from` on at sample count `t`, any state (start of a segment,
    /// wide levels). Level `K0 + j` works when t is a multiple of its stride 2^(j+1) (strides
    /// are below 2^32, so the low word decides), i.e. the levels below K0 + tz(t) do.
    #[cold]
    #[inline(never)]
    pub(super) fn strided_general(&mut self, t: u64, from: usize) {
        let working = (Self::K0 + (t as u32).trailing_zeros() as usize).min(L);
        let mut k = from;
        while k < working && self.strided_general_level(t, k) {
            k += 1;
        }
    }

    /// Level `k`'s differences at `t` (a multiple of its stride), any state; `false` when it
    /// has none yet (t < 2m), and then no higher level has either.
    #[inline(always)]
    fn strided_general_level(&mut self, t: u64, k: usize) -> bool {
        // ⌊t / m⌋, saturated, with a 32-bit shift unless t ≥ 2^32 (k < L ≤ 32).
        let whole = if t >> 32 == 0 {
            (t as u32) >> k
        } else {
            (t >> k).min(u32::MAX as u64) as u32
        };
        if whole < 2 {
            return false;
        }
        let tm = if k == Self::K0 {
            self.base_at_age(2 * P)
        } else {
            self.ring_back(k - 1, Self::BACK)
        };
        let t2m = self.ring_back(k, Self::BACK);
        let t3m = if whole >= 3 {
            if k >= self.full as usize {
                // The levels below worked at this t too and became full first.
                self.full = (k + 1) as u8;
            }
            Some(self.ring_back(k, R - 1))
        } else {
            None
        };
        self.accumulate(k, tm, t2m, t3m);
        true
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
    pub(super) fn cascade(&mut self, index: u32, value: i64) {
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

    /// Entry `back` places older than the newest of strided level `k`'s own ring.
    #[inline(always)]
    pub(super) fn ring_back(&self, k: usize, back: usize) -> i64 {
        let j = k - Self::K0;
        let h = self.heads[j] as usize;
        let slot = if h >= back { h - back } else { h + R - back };
        self.rings[j][slot]
    }
}
