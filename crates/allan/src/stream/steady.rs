//! The per-sample entry points and the steady-state path: once the base ring is full and the
//! unit-stride levels are narrow, every sample with |z| below the gate takes `push_steady`
//! (or, for a [`DeviceEngine`](super::DeviceEngine) with the `thumb-asm` feature on ARM, the
//! hand-scheduled Thumb routines of `thumb.rs`; a [`MagEngine`](super::MagEngine), its own).

#[cfg(all(target_arch = "arm", feature = "thumb-asm"))]
use super::{thumb, DeviceEngine, MagEngine, DEVICE_PARAMS, MAG_PARAMS};
use super::{Engine, Sum128};

/// Which Thumb routines took the samples of an [`Engine::push_pair_traced`] call (`false` and 0
/// off ARM, without `thumb-asm`, and for engines other than
/// [`DeviceEngine`](super::DeviceEngine) and [`MagEngine`](super::MagEngine); a `MagEngine`'s
/// samples are counted in `singles`).
#[doc(hidden)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ThumbTaken {
    /// `pico_imu_allan_push_pair_small` took both samples.
    pub pair: bool,
    /// Samples `pico_imu_allan_push_small` (`pico_imu_allan_mag_push` for a `MagEngine`) took
    /// one at a time (0, 1 or 2), when the pair routine declined them.
    pub singles: u8,
}

impl<const P: usize, const L: usize, const R: usize, const S: usize> Engine<P, L, R, S> {
    /// Feed one rate sample (already corrected, fixed point).
    #[inline]
    pub fn push(&mut self, y: i32) {
        self.push_with::<true>(y);
    }

    /// [`Engine::push`] on the pure-Rust path, never entering the Thumb routines (the same
    /// state changes on every target): the reference the Thumb differential test
    /// (crates/allan/thumb-check) compares the firmware's path with.
    #[doc(hidden)]
    #[inline]
    pub fn push_portable(&mut self, y: i32) {
        self.push_with::<false>(y);
    }

    /// [`Engine::push`], also saying whether a Thumb routine (`pico_imu_allan_push_small`, or
    /// `pico_imu_allan_mag_push` for a [`MagEngine`](super::MagEngine)) took the sample (never
    /// off ARM or without `thumb-asm`), so a test can tell that the code it checks actually ran.
    #[doc(hidden)]
    #[inline]
    pub fn push_traced(&mut self, y: i32) -> bool {
        self.push_with::<true>(y)
    }

    /// `push` (`THUMB`: a [`DeviceEngine`](super::DeviceEngine) may take the Thumb routine) or
    /// `push_portable`; returns whether the Thumb routine took the sample.
    #[inline(always)]
    fn push_with<const THUMB: bool>(&mut self, y: i32) -> bool {
        let gate = self.gate;
        // z = y − c in 32 bits. When the true z does not fit i32, the wrapped one has
        // |z| ≥ 2^31 − 2^30, above any nonzero gate (≤ 2^(30−K0) + 1, the base ring being
        // narrow), so only exact values pass; the general path recomputes z in i64.
        let z = y.wrapping_sub(self.offset);
        if z.unsigned_abs() < gate || self.raise_gate(y) {
            #[cfg(all(target_arch = "arm", feature = "thumb-asm"))]
            if THUMB {
                if let Some(e) = self.as_mag_engine() {
                    // SAFETY: the steady conditions were just checked (any gate).
                    unsafe { thumb::push_mag(e, z) };
                    return true;
                }
            }
            let gate = self.gate;
            // gate = max |y| + 1 here: one `LSRS` tests gate < 2^SMALL_GATE_BITS (2^11 for P = 8).
            if gate >> Self::SMALL_GATE_BITS == 0 {
                #[cfg(all(target_arch = "arm", feature = "thumb-asm"))]
                if THUMB {
                    if let Some(e) = self.as_device_engine() {
                        // SAFETY: the steady, small conditions were just checked.
                        unsafe { thumb::push_small(e, z) };
                        return true;
                    }
                }
                self.push_steady::<true>(z);
            } else {
                self.push_steady::<false>(z);
            }
        } else {
            self.push_general(y);
        }
        false
    }

    /// Feed two consecutive rate samples: exactly `push(y0)` then `push(y1)`.
    ///
    /// On ARM with the `thumb-asm` feature (the firmware's build), a
    /// [`DeviceEngine`](super::DeviceEngine) takes both in one hand-scheduled Thumb routine
    /// (`stream/thumb.rs`) when they are steady-state samples and the segment's count is even
    /// (feed a segment in pairs from its start to keep it so); everything else, and every other
    /// build, goes through [`Engine::push`]. Single samples of a `DeviceEngine` in the steady
    /// state take the same Thumb code, one at a time; a [`MagEngine`](super::MagEngine)'s steady
    /// samples, of any size, take their own routine (range-tested squares) one at a time.
    #[inline]
    pub fn push_pair(&mut self, y0: i32, y1: i32) {
        self.push_pair_with(y0, y1);
    }

    /// [`Engine::push_pair`] on the pure-Rust path: `push_portable(y0)` then
    /// `push_portable(y1)` (see [`Engine::push_portable`]).
    #[doc(hidden)]
    #[inline]
    pub fn push_pair_portable(&mut self, y0: i32, y1: i32) {
        self.push_portable(y0);
        self.push_portable(y1);
    }

    /// [`Engine::push_pair`], also saying which Thumb routines took the samples.
    #[doc(hidden)]
    #[inline]
    pub fn push_pair_traced(&mut self, y0: i32, y1: i32) -> ThumbTaken {
        self.push_pair_with(y0, y1)
    }

    #[inline(always)]
    fn push_pair_with(&mut self, y0: i32, y1: i32) -> ThumbTaken {
        #[cfg(all(target_arch = "arm", feature = "thumb-asm"))]
        if let Some(e) = self.as_device_engine() {
            if thumb::push_pair_small(e, y0, y1) {
                return ThumbTaken {
                    pair: true,
                    singles: 0,
                };
            }
        }
        let first = self.push_traced(y0);
        let second = self.push_traced(y1);
        ThumbTaken {
            pair: false,
            singles: first as u8 + second as u8,
        }
    }

    /// `self` as the firmware's [`DeviceEngine`](super::DeviceEngine), whose layout the Thumb
    /// routines are written for, if that is what it is.
    #[cfg(all(target_arch = "arm", feature = "thumb-asm"))]
    #[inline(always)]
    fn as_device_engine(&mut self) -> Option<&mut DeviceEngine> {
        ([P, L, R, S] == DEVICE_PARAMS)
            // SAFETY: with these parameters `Self` is `DeviceEngine`.
            .then(|| unsafe { &mut *(self as *mut Self).cast::<DeviceEngine>() })
    }

    /// `self` as the firmware's [`MagEngine`](super::MagEngine), which has a Thumb routine for
    /// single samples of any size, if that is what it is.
    #[cfg(all(target_arch = "arm", feature = "thumb-asm"))]
    #[inline(always)]
    fn as_mag_engine(&mut self) -> Option<&mut MagEngine> {
        ([P, L, R, S] == MAG_PARAMS)
            // SAFETY: with these parameters `Self` is `MagEngine`.
            .then(|| unsafe { &mut *(self as *mut Self).cast::<MagEngine>() })
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
}
