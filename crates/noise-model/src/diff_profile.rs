//! The autocorrelation of a recorded signal's Allan differences, per averaging factor.
//!
//! The model noise projected on a deterministic signal moves each Allan estimate by
//! Var(Σ D_i N_i) = Σ_d c(d)·R_D(d), D_i the signal's Allan differences, N_i the noise's and c
//! their covariance (docs/noise-model.md §2, [`crate::cov::profile_noise_sum`]). A step or a
//! warm-up has R_D in closed form; a signal known only as a column of the record (the bias
//! following the temperature) has it measured here: D_i at averaging factor m is computed at
//! every position (a running second difference of partial sums), its Allan variance summed
//! exactly, and its normalised autocorrelation ρ(d) = R_D(d)/R_D(0) kept at lags that are
//! multiples of m/8, up to [`LAGS_PER_M`]·m, where the model noise's covariance of the
//! differences has gone to zero (white, random walk) or into its tail (flicker, Markov). A
//! long record's lags come from windows spread over it, so the cost stays one pass per factor.
use crate::psd::fft;

/// ρ(d) = R_D(d)/R_D(0) of a signal's Allan differences at one averaging factor, at the lags
/// d = k·stride (k = 0…rho.len()−1), linear in between and zero beyond.
#[derive(Debug, Clone, PartialEq)]
pub struct DiffProfile {
    /// Lag between the kept values [samples].
    pub stride: f64,
    /// ρ at k·stride; ρ[0] = 1.
    pub rho: Vec<f64>,
}

impl DiffProfile {
    /// ρ at lag d [samples], interpolated.
    pub fn at(&self, d: f64) -> f64 {
        let x = d.abs() / self.stride;
        let k = x.floor();
        if !(k.is_finite() && k >= 0.0) {
            return 0.0;
        }
        let k = k as usize;
        match (self.rho.get(k), self.rho.get(k + 1)) {
            (Some(a), Some(b)) => {
                let f = x - k as f64;
                a * (1.0 - f) + b * f
            }
            (Some(a), None) if x == k as f64 => *a,
            _ => 0.0,
        }
    }

    /// The longest lag with a value [samples].
    pub fn span(&self) -> f64 {
        self.stride * self.rho.len().saturating_sub(1) as f64
    }

    /// The same profile seen at averaging factor `m` from the factor `from` it was measured at:
    /// lags scale with the factor (between octaves, the nearest one's shape).
    pub fn rescaled(&self, from: f64, m: f64) -> DiffProfile {
        DiffProfile {
            stride: self.stride * m / from,
            rho: self.rho.clone(),
        }
    }
}

/// Lags kept, in units of the averaging factor.
pub const LAGS_PER_M: u64 = 32;
/// Positions whose products are summed exactly; beyond, windows of [`WINDOW`] positions.
const POSITIONS: usize = 1 << 17;
const WINDOW: usize = 1 << 13;

/// The overlapping Allan variance of `x` over its `segments` (samples per uninterrupted run, in
/// order) at averaging factor m, with the profile of its differences; `None` when no segment is
/// 2m long or the differences are all zero (a constant column).
pub fn allan_profile(x: &[f64], segments: &[u64], m: u64) -> Option<(f64, DiffProfile)> {
    if m == 0 {
        return None;
    }
    let stride = (m / 8).max(1) as usize;
    let mu = m as usize;
    let lags = (LAGS_PER_M * m) as usize / stride;
    // positions kept per segment at the stride
    let kept: Vec<usize> = segments
        .iter()
        .map(|&l| (l as usize + 1).saturating_sub(2 * mu).div_ceil(stride))
        .collect();
    let total: usize = kept.iter().sum();
    if total == 0 {
        return None;
    }
    let windowed = total > POSITIONS;
    let (mut sum_sq, mut terms) = (0.0f64, 0u64);
    let mut r = vec![0.0f64; lags + 1];
    let mut off = 0usize;
    for (&len, &p) in segments.iter().zip(&kept) {
        let s = &x[off..off + len as usize];
        off += len as usize;
        if p == 0 {
            continue;
        }
        // windows [start, start + WINDOW) of kept positions whose products with the next `lags`
        // positions are summed, each weighted to stand for its share of the segment
        let windows: Vec<(usize, f64)> = if !windowed {
            vec![(0, 1.0)]
        } else if p < WINDOW {
            Vec::new()
        } else {
            let w =
                ((p as f64 * (POSITIONS / WINDOW) as f64 / total as f64).round() as usize).max(1);
            // evenly spread from the segment's start to its end
            let room = p - WINDOW;
            let weight = p as f64 / (w * WINDOW) as f64;
            (0..w)
                .map(|j| (if w > 1 { room * j / (w - 1) } else { room / 2 }, weight))
                .collect()
        };
        let mean = s.iter().sum::<f64>() / s.len() as f64;
        let stored: Vec<(usize, usize)> = windows
            .iter()
            .map(|&(a, _)| {
                let b = if windowed { a + WINDOW + lags } else { p };
                (a, b.min(p))
            })
            .collect();
        let mut bufs: Vec<Vec<f64>> = stored
            .iter()
            .map(|&(a, b)| Vec::with_capacity(b - a))
            .collect();
        // D_0 directly, then D_{i+1} = D_i + x_{i+2m} − 2x_{i+m} + x_i
        let mut d: f64 = (0..mu).map(|j| (s[mu + j] - mean) - (s[j] - mean)).sum();
        let positions = s.len() + 1 - 2 * mu;
        let (mut next_kept, mut q) = (0usize, 0usize);
        for i in 0..positions {
            if i > 0 {
                let k = i - 1;
                // the mean cancels in x_{k+2m} − 2x_{k+m} + x_k
                d += s[k + 2 * mu] - 2.0 * s[k + mu] + s[k];
            }
            sum_sq += d * d;
            if i == next_kept {
                for (buf, &(a, b)) in bufs.iter_mut().zip(&stored) {
                    if q >= a && q < b {
                        buf.push(d);
                    }
                }
                next_kept += stride;
                q += 1;
            }
        }
        terms += positions as u64;
        for ((buf, &(_, weight)), &(a, b)) in bufs.iter().zip(&windows).zip(&stored) {
            let starts = if windowed { WINDOW.min(b - a) } else { b - a };
            correlate(buf, starts, lags, weight, &mut r);
        }
    }
    if !(r[0] > 0.0 && r[0].is_finite() && sum_sq > 0.0) {
        return None;
    }
    let avar = sum_sq / (2.0 * (m * m) as f64 * terms as f64);
    let rho: Vec<f64> = r.iter().map(|v| v / r[0]).collect();
    Some((
        avar,
        DiffProfile {
            stride: stride as f64,
            rho,
        },
    ))
}

/// r(k) += weight·Σ_{i < starts} x_i·x_{i+k} for k = 0…lags (products within `x` only), by FFT.
fn correlate(x: &[f64], starts: usize, lags: usize, weight: f64, r: &mut [f64]) {
    let starts = starts.min(x.len());
    if starts == 0 {
        return;
    }
    let n = (starts + x.len()).next_power_of_two();
    let (mut ar, mut ai) = (vec![0.0; n], vec![0.0; n]);
    let (mut br, mut bi) = (vec![0.0; n], vec![0.0; n]);
    ar[..starts].copy_from_slice(&x[..starts]);
    br[..x.len()].copy_from_slice(x);
    fft(&mut ar, &mut ai);
    fft(&mut br, &mut bi);
    // conj(A)·B, then the inverse transform as the conjugate of the forward one
    for k in 0..n {
        let (re, im) = (ar[k] * br[k] + ai[k] * bi[k], ar[k] * bi[k] - ai[k] * br[k]);
        ar[k] = re;
        ai[k] = -im;
    }
    fft(&mut ar, &mut ai);
    for (k, v) in r.iter_mut().enumerate().take(lags.min(x.len() - 1) + 1) {
        *v += weight * ar[k] / n as f64;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    struct Lcg(u64);
    impl Lcg {
        fn uniform(&mut self) -> f64 {
            self.0 = self
                .0
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (self.0 >> 11) as f64 / (1u64 << 53) as f64
        }
    }

    /// The differences and their products, lag by lag, with nothing left out.
    fn direct(x: &[f64], segments: &[u64], m: usize, lags: &[usize]) -> (f64, Vec<f64>) {
        let (mut sq, mut n, mut r) = (0.0, 0usize, vec![0.0; lags.len()]);
        let mut off = 0;
        for &l in segments {
            let s = &x[off..off + l as usize];
            off += l as usize;
            if s.len() < 2 * m {
                continue;
            }
            let d: Vec<f64> = (0..=s.len() - 2 * m)
                .map(|i| s[i + m..i + 2 * m].iter().sum::<f64>() - s[i..i + m].iter().sum::<f64>())
                .collect();
            sq += d.iter().map(|v| v * v).sum::<f64>();
            n += d.len();
            for (rk, &k) in r.iter_mut().zip(lags) {
                *rk += d
                    .iter()
                    .zip(d.iter().skip(k))
                    .map(|(a, b)| a * b)
                    .sum::<f64>();
            }
        }
        let r0 = r[0];
        (
            sq / (2.0 * (m * m) as f64 * n as f64),
            r.iter().map(|v| v / r0).collect(),
        )
    }

    #[test]
    fn the_profile_is_the_lag_by_lag_autocorrelation() {
        let mut g = Lcg(0x5eed_0fd1_ff00);
        for _ in 0..6 {
            // a warm-up curve with noise on it, in one to three segments
            let n = 3000 + (g.uniform() * 4000.0) as usize;
            let tau = 50.0 + 2000.0 * g.uniform();
            let noise = 0.01 * g.uniform();
            let x: Vec<f64> = (0..n)
                .map(|i| {
                    25.0 + 8.0 * (1.0 - (-(i as f64) / tau).exp()) + noise * (g.uniform() - 0.5)
                })
                .collect();
            let cut = n / 3 + (g.uniform() * n as f64 / 3.0) as usize;
            let segments: Vec<u64> = if g.uniform() < 0.5 {
                vec![n as u64]
            } else {
                vec![cut as u64, (n - cut) as u64]
            };
            for m in [1usize, 4, 16, 64] {
                let (avar, p) = allan_profile(&x, &segments, m as u64).expect("profile");
                let lags: Vec<usize> = (0..p.rho.len()).map(|k| k * p.stride as usize).collect();
                let (want_avar, want_rho) = direct(&x, &segments, m, &lags);
                assert!(
                    (avar / want_avar - 1.0).abs() < 1e-9,
                    "m {m}: avar {avar} vs {want_avar}"
                );
                // the kept positions are every stride-th: a Riemann sum of the products
                let tol = if p.stride > 1.0 { 0.02 } else { 1e-9 };
                for (k, (a, b)) in p.rho.iter().zip(&want_rho).enumerate() {
                    assert!((a - b).abs() < tol, "m {m} lag {}: ρ {a} vs {b}", lags[k]);
                }
            }
        }
    }

    #[test]
    fn a_long_record_is_profiled_from_windows_close_to_the_whole() {
        let mut g = Lcg(0x1096_7ec0);
        let n = 3 * POSITIONS;
        let tau = n as f64 * (0.05 + 0.3 * g.uniform());
        let x: Vec<f64> = (0..n)
            .map(|i| (1.0 - (-(i as f64) / tau).exp()) + 1e-4 * (g.uniform() - 0.5))
            .collect();
        let m = 2usize;
        let (_, p) = allan_profile(&x, &[n as u64], m as u64).expect("profile");
        let lags: Vec<usize> = (0..p.rho.len()).collect();
        let (_, want) = direct(&x, &[n as u64], m, &lags);
        for (k, (a, b)) in p.rho.iter().zip(&want).enumerate() {
            assert!((a - b).abs() < 0.05, "lag {k}: ρ {a} vs {b}");
        }
    }

    #[test]
    fn interpolation_and_bounds() {
        let p = DiffProfile {
            stride: 4.0,
            rho: vec![1.0, 0.5, 0.25],
        };
        assert_eq!(p.at(0.0), 1.0);
        assert_eq!(p.at(-2.0), 0.75);
        assert_eq!(p.at(8.0), 0.25);
        assert_eq!(p.at(8.5), 0.0);
        assert_eq!(p.at(f64::NAN), 0.0);
        assert_eq!(p.span(), 8.0);
        assert_eq!(p.rescaled(8.0, 16.0).at(4.0), 0.75);
        assert!(allan_profile(&[3.0; 100], &[100], 4).is_none());
        assert!(allan_profile(&[3.0; 10], &[10], 8).is_none());
    }
}
