//! Second-order structure of a rate process: V(k), the variance of the sum of k consecutive
//! samples.
//!
//! Every Allan-type statistic of a rate record is a sum of squared second differences of the
//! partial sums P(n) = Σ_{i<n} y_i, and for a process with stationary increments
//! Cov(Σ_a w_a P(i + a), Σ_b w_b P(j + b)) = −½ Σ_a Σ_b w_a w_b V(|j + b − i − a|) whenever Σ w = 0
//! (the structure-function identity; e.g. Percival & Walden, *Wavelet Methods for Time Series
//! Analysis*, §7.6, for the Haar wavelet variance, which is half the Allan variance). So V(k)
//! gives both the expected overlapping Allan variance,
//! σ²(m) = (4V(m) − V(2m)) / (2m²),
//! and the covariance of any two Allan estimates ([`crate::cov`]). V may be a *generalised*
//! structure function: adding a + b·k² changes no second difference, which is what lets
//! flicker (V ∝ −k² ln k) and rate random walk (V ∝ k − k³) be written in closed form.
//!
//! For a stationary process with autocovariance R(k), V(k) = Σ_{|j|<k} (k − |j|) R(j)
//! ([`RTable`] computes it for any decaying R).
use std::sync::Arc;

/// V(k) of one unit-coefficient stochastic component (the model multiplies it by c ≥ 0).
#[derive(Debug, Clone)]
pub enum Structure {
    /// White rate samples of unit variance per sample: V(k) = k.
    Linear,
    /// Differences of white phase of unit variance, y_i = e_{i+1} − e_i: V(k) = 2 for k ≥ 1.
    PhaseWhite,
    /// Flicker rate noise: V(k) = −k² ln k / π, which makes σ²(m) = (2 ln 2/π) for every m.
    Flicker,
    /// Rate random walk with unit increment variance per sample: V(k) = (k − k³)/6,
    /// σ²(m) = m/3 + 1/(6m) (the exact sampled form).
    Cubic,
    /// First-order Gauss–Markov (AR(1)) of unit variance and lag-one correlation φ:
    /// V(k) = k(1+φ)/(1−φ) − 2φ(1 − φ^k)/(1−φ)².
    Ar1 { phi: f64 },
    /// Second-order Gauss–Markov (a damped oscillator driven by white noise, damping ratio ζ < 1)
    /// of unit variance, point-sampled: R(k) = e^{−αk}[cos βk + (α/β) sin βk] with α = ζω0τ0,
    /// β = ω0τ0√(1 − ζ²). V(k) in closed form ([`oscillator_v`]).
    Oscillator { alpha: f64, beta: f64 },
    /// Any stationary process with a decaying autocovariance, tabulated.
    Table(Arc<RTable>),
}

impl Structure {
    /// V(k) for real k ≥ 0 (the closed forms are smooth in k; tables interpolate linearly).
    pub fn v(&self, k: f64) -> f64 {
        let k = k.abs();
        if k == 0.0 {
            return 0.0;
        }
        match self {
            Structure::Linear => k,
            Structure::PhaseWhite => {
                if k >= 1.0 {
                    2.0
                } else {
                    2.0 * k
                }
            }
            Structure::Flicker => -k * k * k.ln() / std::f64::consts::PI,
            Structure::Cubic => (k - k * k * k) / 6.0,
            Structure::Ar1 { phi } => ar1_v(*phi, k),
            Structure::Oscillator { alpha, beta } => oscillator_v(*alpha, *beta, k),
            Structure::Table(t) => t.v(k),
        }
    }

    /// Expected overlapping Allan variance at m samples for a unit coefficient.
    pub fn avar(&self, m: f64) -> f64 {
        (4.0 * self.v(m) - self.v(2.0 * m)) / (2.0 * m * m)
    }

    /// An identity for caching: equal keys mean equal structure functions.
    pub fn key(&self) -> (u8, u64) {
        match self {
            Structure::Linear => (0, 0),
            Structure::PhaseWhite => (1, 0),
            Structure::Flicker => (2, 0),
            Structure::Cubic => (3, 0),
            Structure::Ar1 { phi } => (4, phi.to_bits()),
            Structure::Table(t) => (5, t.id),
            Structure::Oscillator { alpha, beta } => (
                6,
                alpha.to_bits() ^ beta.to_bits().rotate_left(32) ^ 0x9E37_79B9_7F4A_7C15,
            ),
        }
    }

    /// The lag (in samples) beyond which this structure adds nothing to a second-difference
    /// covariance other than what a power law gives: the decay length of a Markov or tabulated
    /// autocovariance, 0 otherwise.
    pub fn memory(&self) -> f64 {
        match self {
            Structure::Ar1 { phi } if *phi > 0.0 && *phi < 1.0 => 20.0 / -phi.ln(),
            Structure::Table(t) => t.len() as f64,
            Structure::Oscillator { alpha, .. } if *alpha > 0.0 => 20.0 / alpha,
            _ => 0.0,
        }
    }
}

/// The cubic B-spline on [−2, 2] (unit area): the autocorrelation of a unit-area triangle of
/// half-width 1, i.e. of two boxcars in cascade.
pub fn bspline3(x: f64) -> f64 {
    let x = x.abs();
    if x <= 1.0 {
        2.0 / 3.0 - x * x + x * x * x / 2.0
    } else if x < 2.0 {
        (2.0 - x).powi(3) / 6.0
    } else {
        0.0
    }
}

/// V(k) of a unit-variance AR(1), written with `expm1` so that φ near 1 keeps its digits.
fn ar1_v(phi: f64, k: f64) -> f64 {
    if !(phi > 0.0) {
        return k;
    }
    if phi >= 1.0 {
        return k * k;
    }
    let beta = -phi.ln(); // τ0/τ_c
    let a = -(-beta).exp_m1(); // 1 − φ
    let x = beta * k;
    if x < 1e-4 {
        // nearly fully correlated over k samples: the series in β to second order,
        // V = k² − β(k³ − k)/3 + β²k²(k² − 1)/12 (relative error O(x²) in the Allan variance)
        return k * k - beta * (k * k * k - k) / 3.0 + beta * beta * k * k * (k * k - 1.0) / 12.0;
    }
    let b = -(-x).exp_m1(); // 1 − φ^k
    (k * (2.0 - a) * a - 2.0 * (1.0 - a) * b) / (a * a)
}

/// e^{x+iy} − 1 without cancellation for small |x + iy|: (expm1(x)·cos y − 2 sin²(y/2),
/// e^x·sin y).
fn cexpm1(x: f64, y: f64) -> (f64, f64) {
    let h = (y / 2.0).sin();
    (x.exp_m1() * y.cos() - 2.0 * h * h, x.exp() * y.sin())
}

fn cmul(a: (f64, f64), b: (f64, f64)) -> (f64, f64) {
    (a.0 * b.0 - a.1 * b.1, a.0 * b.1 + a.1 * b.0)
}

fn cdiv(a: (f64, f64), b: (f64, f64)) -> (f64, f64) {
    let d = b.0 * b.0 + b.1 * b.1;
    ((a.0 * b.0 + a.1 * b.1) / d, (a.1 * b.0 - a.0 * b.1) / d)
}

/// V(k) of the unit-variance sampled damped oscillator (see [`Structure::Oscillator`]).
///
/// R(j) = Re(a·zʲ) with z = e^λ, λ = −α + iβ, a = 1 − i·α/β (Re a = R(0) = 1). The weighted
/// geometric sum Σ_{j=1}^{k−1} (k − j) zʲ = z[k(1 − z) − (1 − zᵏ)]/(1 − z)², so
/// V(k) = k + 2·Re(a·(1 + E₁)(E_k − k·E₁)/E₁²) with E₁ = e^λ − 1 and E_k = e^{kλ} − 1, both taken
/// from `expm1` so that a slow oscillator (|λ| ≪ 1) keeps its digits. Smooth in real k.
pub fn oscillator_v(alpha: f64, beta: f64, k: f64) -> f64 {
    if !(beta > 0.0) || !(alpha >= 0.0) {
        return f64::NAN;
    }
    let e1 = cexpm1(-alpha, beta);
    let ek = cexpm1(-alpha * k, beta * k);
    let num = cmul((1.0 + e1.0, e1.1), (ek.0 - k * e1.0, ek.1 - k * e1.1));
    let s = cdiv(num, cmul(e1, e1));
    // Re((1 − ic)(s.0 + i s.1)) = s.0 + c·s.1
    k + 2.0 * (s.0 + alpha / beta * s.1)
}

/// A tabulated autocovariance R(0..=K) of a stationary process, with the prefix sums that give
/// V(k) exactly for every k: V(k) = k·R(0) + 2 Σ_{j=1}^{k−1} (k − j) R(j). R(j) is taken as 0 for
/// j > K, so the table must extend until R has decayed (callers cut it below 1e-12 of R(0)).
#[derive(Debug, Clone)]
pub struct RTable {
    /// A hash of the values (FNV-1a), the table's identity for caching.
    pub id: u64,
    r0: f64,
    /// C0[k] = Σ_{j=1}^{k} R(j), C1[k] = Σ_{j=1}^{k} j·R(j), for k = 0..=K.
    c0: Vec<f64>,
    c1: Vec<f64>,
}

impl RTable {
    /// Build from R(0), R(1), … (at least one value).
    pub fn new(r: &[f64]) -> RTable {
        let mut c0 = Vec::with_capacity(r.len());
        let mut c1 = Vec::with_capacity(r.len());
        let (mut s0, mut s1) = (0.0, 0.0);
        c0.push(0.0);
        c1.push(0.0);
        for (j, &v) in r.iter().enumerate().skip(1) {
            s0 += v;
            s1 += j as f64 * v;
            c0.push(s0);
            c1.push(s1);
        }
        let mut id: u64 = 0xcbf2_9ce4_8422_2325;
        for v in r {
            for b in v.to_bits().to_le_bytes() {
                id = (id ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3);
            }
        }
        RTable {
            id,
            r0: r.first().copied().unwrap_or(0.0),
            c0,
            c1,
        }
    }

    /// Build by evaluating `r` at k = 0, 1, … until |R| stays below `rel`·|R(0)| for 16
    /// consecutive lags, or `max_len` lags (an error when R has not decayed by then).
    pub fn from_fn(
        mut r: impl FnMut(usize) -> f64,
        rel: f64,
        max_len: usize,
    ) -> Result<RTable, String> {
        let r0 = r(0);
        if !r0.is_finite() {
            return Err(format!("R(0) = {r0} is not finite"));
        }
        let mut vals = vec![r0];
        let mut quiet = 0;
        let mut k = 1;
        while quiet < 16 {
            if k > max_len {
                return Err(format!(
                    "the autocovariance has not decayed below {rel:e}·R(0) after {max_len} lags \
                     (R({max_len}) = {:e}, R(0) = {r0:e}); give a decaying R(k)",
                    vals[max_len]
                ));
            }
            let v = r(k);
            if !v.is_finite() {
                return Err(format!("R({k}) = {v} is not finite"));
            }
            quiet = if v.abs() <= rel * r0.abs() {
                quiet + 1
            } else {
                0
            };
            vals.push(v);
            k += 1;
        }
        vals.truncate(vals.len() - 16);
        Ok(RTable::new(&vals))
    }

    /// Number of tabulated lags beyond 0.
    pub fn len(&self) -> usize {
        self.c0.len() - 1
    }

    /// Whether only R(0) is tabulated (white).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    fn v_int(&self, k: usize) -> f64 {
        if k == 0 {
            return 0.0;
        }
        let i = (k - 1).min(self.len());
        k as f64 * self.r0 + 2.0 * (k as f64 * self.c0[i] - self.c1[i])
    }

    /// V(k), linearly interpolated between integers.
    pub fn v(&self, k: f64) -> f64 {
        let lo = k.floor();
        let f = k - lo;
        let a = self.v_int(lo as usize);
        if f == 0.0 {
            a
        } else {
            a + f * (self.v_int(lo as usize + 1) - a)
        }
    }
}

/// Largest damping ratio of the resonance effect: ζ ≥ 1 has no resonant peak (a critically damped
/// or overdamped second-order process is a two-pole low-pass shape, the lowpass2 or two Markov
/// terms), and the oscillator form R = e^{−αk}[cos βk + (α/β) sin βk] needs β > 0.
pub const RESONANCE_ZETA_MAX: f64 = 0.99;

/// The damping ratio the resonance's frequency is searched with before ζ itself is.
pub const RESONANCE_ZETA_START: f64 = 0.2;

/// The unit-variance structure of a resonance at `f0` [Hz], damping ratio `zeta`, point-sampled
/// every `tau0`: α = ζω0τ0, β = ω0τ0√(1 − ζ²) (an error outside 0 < ζ ≤ [`RESONANCE_ZETA_MAX`]
/// or 0 < f0 < 1/(2τ0)).
pub fn resonance_structure(f0: f64, zeta: f64, tau0: f64) -> Result<Structure, String> {
    if !(zeta > 0.0 && zeta <= RESONANCE_ZETA_MAX) {
        return Err(format!(
            "damping ratio ζ = {zeta} outside (0, {RESONANCE_ZETA_MAX}]: ζ ≥ 1 has no resonant \
             peak (use lowpass2 or Markov terms)"
        ));
    }
    if !(f0 > 0.0 && f0 * tau0 < 0.5) {
        return Err(format!(
            "natural frequency f0 = {f0} Hz outside (0, {}) Hz (Nyquist)",
            0.5 / tau0
        ));
    }
    let w = 2.0 * std::f64::consts::PI * f0 * tau0;
    Ok(Structure::Oscillator {
        alpha: zeta * w,
        beta: w * ((1.0 - zeta) * (1.0 + zeta)).sqrt(),
    })
}

/// One-sided PSD [1/Hz] at `f` (0 ≤ f ≤ 1/(2τ0)) of the *sampled* unit-variance resonance,
/// aliasing included: S(f) = 2τ0[1 + 2 Re Σ_{k≥1} R(k) e^{−iθk}], θ = 2πfτ0, which with
/// R(k) = Re(a·zᵏ) is 2τ0[1 + Re(a·q/(1 − q)) + Re(ā·q′/(1 − q′))], q = z·e^{−iθ},
/// q′ = z̄·e^{−iθ}. For f0 ≪ 1/τ0 it is the continuous oscillator's 2σ²·4ζω0³/|ω0² − ω² + 2iζω0ω|²
/// (the white level times |H|², normalised to unit variance).
pub fn resonance_psd_unit(f: f64, tau0: f64, f0: f64, zeta: f64) -> f64 {
    let Ok(Structure::Oscillator { alpha, beta }) = resonance_structure(f0, zeta, tau0) else {
        return f64::NAN;
    };
    let theta = 2.0 * std::f64::consts::PI * f * tau0;
    let c = alpha / beta;
    // Re(a·q/(1 − q)) with a = 1 − ic, q = e^{−α + iφ}: q/(1 − q) = −(1 + E)/E, E = e^{ln q} − 1
    let term = |phi: f64, c: f64| {
        let h = (phi / 2.0).sin();
        let (er, ei) = (
            (-alpha).exp_m1() * phi.cos() - 2.0 * h * h,
            (-alpha).exp() * phi.sin(),
        );
        let d = er * er + ei * ei;
        // −(1 + E)/E = −(1 + E)·Ē/|E|²
        let (nr, ni) = (1.0 + er, ei);
        let (qr, qi) = (-(nr * er + ni * ei) / d, -(ni * er - nr * ei) / d);
        qr + c * qi
    };
    2.0 * tau0 * (1.0 + term(beta - theta, c) + term(-beta - theta, -c))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn direct_v(r: impl Fn(usize) -> f64, k: usize) -> f64 {
        let mut s = k as f64 * r(0);
        for j in 1..k {
            s += 2.0 * (k - j) as f64 * r(j);
        }
        s
    }

    #[test]
    fn closed_forms_give_the_textbook_allan_variances() {
        for m in [1.0, 2.0, 7.0, 64.0, 1e6] {
            assert!((Structure::Linear.avar(m) - 1.0 / m).abs() < 1e-12 / m);
            assert!((Structure::PhaseWhite.avar(m) - 3.0 / (m * m)).abs() < 1e-12 / (m * m));
            let fl = 2.0 * std::f64::consts::LN_2 / std::f64::consts::PI;
            assert!((Structure::Flicker.avar(m) - fl).abs() < 1e-9 * fl, "m {m}");
            let rrw = m / 3.0 + 1.0 / (6.0 * m);
            assert!((Structure::Cubic.avar(m) - rrw).abs() < 1e-9 * rrw, "m {m}");
        }
    }

    #[test]
    fn ar1_matches_its_autocovariance_sum() {
        for phi in [0.01f64, 0.5, 0.97, 0.999_99] {
            let s = Structure::Ar1 { phi };
            for k in [1usize, 2, 3, 10, 100, 2000] {
                let d = direct_v(|j| phi.powi(j as i32), k);
                let v = s.v(k as f64);
                assert!((v - d).abs() <= 1e-9 * d.abs(), "φ {phi} k {k}: {v} vs {d}");
            }
        }
    }

    /// The sampled oscillator's R(j), straight from its definition.
    fn oscillator_r(alpha: f64, beta: f64, j: usize) -> f64 {
        let j = j as f64;
        (-alpha * j).exp() * ((beta * j).cos() + alpha / beta * (beta * j).sin())
    }

    #[test]
    fn oscillator_matches_its_autocovariance_sum() {
        // f0 from 0.01·fs to 0.45·fs, ζ from 0.02 to 0.99: V(k) and the Allan variance against the
        // direct sums of R(j) (σ² from the direct V, as the lab computes it)
        let mut worst: f64 = 0.0;
        for f0 in [0.01, 0.037, 0.1, 0.25, 0.45] {
            for zeta in [0.02f64, 0.1, 0.3, 0.7, 0.99] {
                let w = 2.0 * std::f64::consts::PI * f0;
                let (alpha, beta) = (zeta * w, w * (1.0 - zeta * zeta).sqrt());
                let s = Structure::Oscillator { alpha, beta };
                let r = |j: usize| oscillator_r(alpha, beta, j);
                for m in [1usize, 2, 3, 5, 10, 33, 100, 1000, 4000] {
                    let (dm, d2m) = (direct_v(r, m), direct_v(r, 2 * m));
                    let want = (4.0 * dm - d2m) / (2.0 * (m * m) as f64);
                    let got = s.avar(m as f64);
                    let e = ((got - want) / want).abs();
                    worst = worst.max(e);
                    assert!(e < 1e-9, "f0 {f0} ζ {zeta} m {m}: {got} vs {want}");
                    let ev = ((s.v(m as f64) - dm) / dm).abs();
                    assert!(
                        ev < 1e-9,
                        "f0 {f0} ζ {zeta} V({m}): {} vs {dm}",
                        s.v(m as f64)
                    );
                }
            }
        }
        eprintln!("oscillator closed form vs direct sums: worst relative error {worst:.1e}");
        assert!(worst < 1e-9, "{worst:e}");
    }

    #[test]
    fn oscillator_limits() {
        let pi = std::f64::consts::PI;
        // m = 1: σ² = R(0) − R(1) exactly
        let (alpha, beta) = (0.05, 0.6);
        let s = Structure::Oscillator { alpha, beta };
        let r1 = oscillator_r(alpha, beta, 1);
        assert!((s.avar(1.0) - (1.0 - r1)).abs() < 1e-14);
        // long τ: white noise of the process's total correlation Σ_j R(j) per sample,
        // which tends to the continuous ∫R dt/τ0 = 4ζ/(ω0τ0) for a slow oscillator
        for (f0, zeta) in [(0.001, 0.05), (0.001, 0.5), (0.2, 0.1)] {
            let w = 2.0 * pi * f0;
            let (alpha, beta) = (zeta * w, w * (1.0 - zeta * zeta).sqrt());
            let s = Structure::Oscillator { alpha, beta };
            let total: f64 = 1.0
                + 2.0
                    * (1..200_000)
                        .map(|j| oscillator_r(alpha, beta, j))
                        .sum::<f64>();
            let m = 1e7;
            assert!(
                (s.avar(m) * m / total - 1.0).abs() < 1e-3,
                "f0 {f0} ζ {zeta}"
            );
            if f0 < 0.01 {
                assert!((total / (4.0 * zeta / w) - 1.0).abs() < 1e-3, "{total}");
            }
        }
        // a slow oscillator point-sampled fast: σ² at m = τ/τ0 tends to the continuous form
        // (1/τ²)∫∫ over two adjacent windows, checked against a fine direct sum in continuous time
        // through R(t) itself: the sampled value moves by O(τ0/τ) only
        let (f0, zeta) = (1e-3, 0.2);
        let w = 2.0 * pi * f0;
        let s = Structure::Oscillator {
            alpha: zeta * w,
            beta: w * (1.0 - zeta * zeta).sqrt(),
        };
        let s2 = Structure::Oscillator {
            alpha: zeta * w / 10.0,
            beta: w / 10.0 * (1.0 - zeta * zeta).sqrt(),
        };
        for m in [50.0, 300.0, 2000.0] {
            let (a, b) = (s.avar(m), s2.avar(10.0 * m));
            assert!((a / b - 1.0).abs() < 0.02, "m {m}: {a} vs {b}");
        }
    }

    #[test]
    fn table_matches_direct_sums_and_continues_linearly() {
        let r = |j: usize| (-(j as f64) / 3.0).exp() * (1.0 + 0.1 * j as f64);
        let t = RTable::from_fn(r, 1e-14, 100_000).unwrap();
        for k in [1usize, 2, 5, 17, 150, 5000] {
            let d = direct_v(r, k);
            assert!((t.v(k as f64) - d).abs() < 1e-9 * d, "k {k}");
        }
        let never = RTable::from_fn(|_| 1.0, 1e-12, 1000);
        assert!(never.unwrap_err().contains("not decayed"));
    }
}
