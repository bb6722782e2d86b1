//! The per-sample path the firmware runs: a calibration's coefficients split once for the
//! Q24 multiply, diagonal matrices skipping their zero products.
use super::{round_q12, Affine, Calibration};

/// One [`Affine`] laid out for the per-sample path: each Q24 coefficient already split into
/// the two halves [`mul_q24`](super::mul_q24) multiplies by, and whether the matrix is diagonal (Jaime et al.'s
/// accelerometer model, offset and scale per axis, and a bias-only gyro are), in which case
/// the six zero products are skipped. The results are bit for bit those of
/// [`Affine::apply`]: a zero coefficient contributes exactly 0 to both partial sums.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct FastAffine {
    /// `m >> 12` (Q12) and `m & 0xfff`, row-major.
    hi: [[i32; 3]; 3],
    lo: [[i32; 3]; 3],
    c: [i32; 3],
    diagonal: bool,
}

impl FastAffine {
    fn new(a: &Affine) -> Self {
        let mut hi = [[0; 3]; 3];
        let mut lo = [[0; 3]; 3];
        let mut diagonal = true;
        for i in 0..3 {
            for j in 0..3 {
                hi[i][j] = a.m[i][j] >> 12;
                lo[i][j] = a.m[i][j] & 0xfff;
                diagonal &= i == j || a.m[i][j] == 0;
            }
        }
        FastAffine {
            hi,
            lo,
            c: a.c,
            diagonal,
        }
    }

    /// `M·raw` in Q12, as [`Affine::mat_q12`].
    #[inline(always)]
    fn mat_q12(&self, raw: [i16; 3]) -> [i32; 3] {
        let x = [raw[0] as i32, raw[1] as i32, raw[2] as i32];
        if self.diagonal {
            let d = |i: usize| x[i] * self.hi[i][i] + ((x[i] * self.lo[i][i]) >> 12);
            // Written out: `array::map` is not inlined at opt-level "s".
            return [d(0), d(1), d(2)];
        }
        let mut out = [0i32; 3];
        for i in 0..3 {
            let (h, l) = (&self.hi[i], &self.lo[i]);
            out[i] = x[0] * h[0]
                + x[1] * h[1]
                + x[2] * h[2]
                + ((x[0] * l[0] + x[1] * l[1] + x[2] * l[2]) >> 12);
        }
        out
    }

    #[inline(always)]
    fn apply(&self, raw: [i16; 3]) -> [i32; 3] {
        let q = self.mat_q12(raw);
        [
            round_q12(q[0] - self.c[0]),
            round_q12(q[1] - self.c[1]),
            round_q12(q[2] - self.c[2]),
        ]
    }
}

/// A [`Calibration`] prepared for the per-sample path ([`FastAffine`]): what the firmware
/// applies to every sample, rebuilt whenever the calibration changes. Same results as the
/// [`Calibration`]'s own `apply_*`, bit for bit (`tests/fixed_point.rs`), for ≈ 200 cycles
/// less per 1 kHz sample on the Cortex-M0+ with diagonal matrices.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Prepared {
    accel: FastAffine,
    gyro: FastAffine,
    /// κ split like the matrices.
    kappa_hi: [i32; 3],
    kappa_lo: [i32; 3],
    t_ref: i16,
    mag: FastAffine,
}

impl Prepared {
    pub fn new(cal: &Calibration) -> Self {
        Prepared {
            accel: FastAffine::new(&cal.accel),
            gyro: FastAffine::new(&cal.gyro.affine),
            kappa_hi: cal.gyro.kappa.map(|k| k >> 12),
            kappa_lo: cal.gyro.kappa.map(|k| k & 0xfff),
            t_ref: cal.gyro.t_ref,
            mag: FastAffine::new(&cal.mag),
        }
    }

    /// [`Calibration::apply_accel`].
    #[inline]
    pub fn apply_accel(&self, raw: [i16; 3]) -> [i32; 3] {
        self.accel.apply(raw)
    }

    /// [`Calibration::apply_gyro`] ([`GyroCorrection::apply`]).
    #[inline]
    pub fn apply_gyro(&self, raw: [i16; 3], temp_raw: i16) -> [i32; 3] {
        let q = self.gyro.mat_q12(raw);
        let dt = (temp_raw as i32 - self.t_ref as i32).clamp(i16::MIN as i32, i16::MAX as i32);
        let axis = |i: usize| {
            let t = dt * self.kappa_hi[i] + ((dt * self.kappa_lo[i]) >> 12);
            round_q12(q[i] - self.gyro.c[i] - t)
        };
        [axis(0), axis(1), axis(2)]
    }

    /// [`Self::apply_gyro`] with the temperature if known; without one, the reference
    /// temperature (no temperature term).
    #[inline]
    pub fn apply_gyro_opt(&self, raw: [i16; 3], temp_raw: Option<i16>) -> [i32; 3] {
        self.apply_gyro(raw, temp_raw.unwrap_or(self.t_ref))
    }

    /// [`Calibration::apply_mag`].
    #[inline]
    pub fn apply_mag(&self, raw: [i16; 3]) -> [i32; 3] {
        self.mag.apply(raw)
    }
}
