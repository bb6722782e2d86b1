//! Exact sampled-data Allan variances: the basis of a term with its non-linear parameters fixed,
//! and the closed forms of the deterministic and Markov effects.
use super::Context;
use crate::structure::Structure;
pub use crate::structure::{
    resonance_psd_unit, resonance_structure, RESONANCE_ZETA_MAX, RESONANCE_ZETA_START,
};

/// The basis of one term with its non-linear parameters fixed: σ²(m) = c · basis(m).
#[derive(Debug, Clone)]
pub enum Basis {
    /// V(k) = factor · structure.v(k) per unit coefficient.
    Stochastic { structure: Structure, factor: f64 },
    /// σ² = (mτ0)²/2 per unit R².
    Ramp,
    /// Random-phase sinusoid at θ = 2πfτ0.
    Sine { theta: f64 },
    /// Values at the integer averaging factors (ascending m, exact for this record), interpolated
    /// log-log elsewhere.
    Table(Vec<(u64, f64)>),
    /// Contributes nothing (an absent non-linear parameter).
    Zero,
}

impl Basis {
    /// The unit-coefficient Allan variance at m samples (τ = m·τ0).
    pub fn avar(&self, m: f64, tau0: f64) -> f64 {
        match self {
            Basis::Stochastic { structure, factor } => factor * structure.avar(m),
            Basis::Ramp => (m * tau0).powi(2) / 2.0,
            Basis::Sine { theta } => sine_avar(m, *theta),
            Basis::Table(t) => interp_loglog(t, m),
            Basis::Zero => 0.0,
        }
    }
}

fn sine_avar(m: f64, theta: f64) -> f64 {
    let h = (theta / 2.0).sin();
    if h.abs() < 1e-300 {
        return 0.0;
    }
    (m * theta / 2.0).sin().powi(4) / (m * m * h * h)
}

fn interp_loglog(t: &[(u64, f64)], m: f64) -> f64 {
    if t.is_empty() {
        return 0.0;
    }
    if let Some(&(_, v)) = t.iter().find(|p| p.0 as f64 == m) {
        return v;
    }
    let i = t.partition_point(|p| (p.0 as f64) < m);
    if i == 0 {
        return t[0].1;
    }
    if i == t.len() {
        return t[t.len() - 1].1;
    }
    let (m0, v0) = (t[i - 1].0 as f64, t[i - 1].1);
    let (m1, v1) = (t[i].0 as f64, t[i].1);
    if v0 <= 0.0 || v1 <= 0.0 {
        return v0 + (v1 - v0) * (m - m0) / (m1 - m0);
    }
    let f = (m / m0).ln() / (m1 / m0).ln();
    (v0.ln() + f * (v1 / v0).ln()).exp()
}

/// The octave averaging factors 1, 2, 4, … up to the longest segment's quarter.
pub(super) fn octaves(ctx: &Context) -> impl Iterator<Item = u64> {
    let longest = ctx.segments.iter().map(|s| s.1).max().unwrap_or(0);
    (0..63)
        .map(|k| 1u64 << k)
        .take_while(move |&m| 2 * m < longest.max(2))
}

/// Σ_{u=1}^{U} d(u)² for the triangular response of an m-sample Allan difference to a unit step,
/// d(u) = u/m for 0 < u ≤ m, (2m − u)/m for m < u < 2m, U clamped to [0, 2m].
fn tri_sq_sum(u: i128, m: i128) -> f64 {
    let s = |n: i128| -> f64 {
        if n <= 0 {
            0.0
        } else {
            (n * (n + 1) * (2 * n + 1)) as f64 / 6.0
        }
    };
    let u = u.clamp(0, 2 * m);
    let mm = (m * m) as f64;
    if u <= m {
        s(u) / mm
    } else {
        (s(m) + s(m - 1) - s(2 * m - u - 1)) / mm
    }
}

/// Expected overlapping Allan variance at m of a unit bias step at sample `s` (0-based, counted as
/// in [`Context::segments`]): Σ_i d(s − i)² / (2M) over the differences of every segment.
pub fn step_avar(s: u64, m: u64, ctx: &Context) -> f64 {
    let total = ctx.terms(m);
    if total == 0 {
        return 0.0;
    }
    let mut acc = 0.0;
    for &(a, l) in &ctx.segments {
        if s <= a || s >= a + l || l + 1 < 2 * m {
            continue;
        }
        let mi = m as i128;
        let (lo_i, hi_i) = (a as i128, (a + l) as i128 - 2 * mi);
        // u = s − i runs over [s − hi_i, s − lo_i]
        let (u_lo, u_hi) = (s as i128 - hi_i, s as i128 - lo_i);
        acc += tri_sq_sum(u_hi, mi) - tri_sq_sum(u_lo - 1, mi);
    }
    acc / (2.0 * total as f64)
}

/// Expected overlapping Allan variance at m of a unit exponential e^{−k/κ} (k the sample index
/// from the record's start): the window means of an exponential are exponentials, so the sum over
/// differences is geometric.
pub fn warmup_avar(kappa: f64, m: u64, ctx: &Context) -> f64 {
    let total = ctx.terms(m);
    if total == 0 || !(kappa > 0.0) {
        return 0.0;
    }
    let mf = m as f64;
    let e1 = -(-1.0 / kappa).exp_m1(); // 1 − e^{−1/κ}
    let em = -(-mf / kappa).exp_m1(); // 1 − e^{−m/κ}
    let g = em / (mf * e1);
    let d2 = (g * em).powi(2);
    let mut acc = 0.0;
    for &(a, l) in &ctx.segments {
        let mm = (l + 1).saturating_sub(2 * m) as f64;
        if mm == 0.0 {
            continue;
        }
        let geo = -(-2.0 * mm / kappa).exp_m1() / -(-2.0 / kappa).exp_m1();
        acc += (-2.0 * a as f64 / kappa).exp() * geo;
    }
    d2 * acc / (2.0 * total as f64)
}

/// Most cosine components of a smooth drift: its shortest period is 2T/16 of a record of length T
/// (a slower change is a drift of the record; a faster one is noise or a step).
pub const DRIFT_MAX_COMPONENTS: u8 = 16;

/// The record's span in samples (the nominal index one past its last sample): the length T of the
/// drift's cosines cos(πjk/T).
pub fn drift_span(ctx: &Context) -> f64 {
    ctx.segments
        .iter()
        .map(|&(a, l)| (a + l) as f64)
        .fold(0.0, f64::max)
}

/// The drift of shape `c` at sample index k of a record spanning `span` samples:
/// c₀·k + Σ_{j≥1} c_j·cos(πjk/T) — a ramp (per sample) and the cosines of the record's length.
pub fn drift_at(c: &[f64], k: f64, span: f64) -> f64 {
    c.iter().enumerate().fold(0.0, |acc, (j, cj)| {
        acc + cj
            * if j == 0 {
                k
            } else {
                (std::f64::consts::PI * j as f64 * k / span).cos()
            }
    })
}

/// Points of the midpoint rule for the drift's mean square over the record: the components are
/// smooth on the scale span/32, so the rule is exact to ~1e-7 relative.
const DRIFT_RMS_POINTS: usize = 4096;

/// The Gram matrix of the drift's components about their means over the record:
/// G_jk = mean((φ_j − φ̄_j)(φ_k − φ̄_k)), φ₀ = k, φ_j = cos(πjk/T); the drift of shape c has the
/// mean square cᵀGc about its mean.
pub fn drift_gram(components: usize, span: f64) -> Vec<Vec<f64>> {
    let n = DRIFT_RMS_POINTS;
    let cols: Vec<Vec<f64>> = (0..components)
        .map(|j| {
            let mut unit = vec![0.0; components];
            unit[j] = 1.0;
            let v: Vec<f64> = (0..n)
                .map(|i| drift_at(&unit, (i as f64 + 0.5) * span / n as f64, span))
                .collect();
            let mean = v.iter().sum::<f64>() / n as f64;
            v.into_iter().map(|x| x - mean).collect()
        })
        .collect();
    (0..components)
        .map(|j| {
            (0..components)
                .map(|k| {
                    cols[j]
                        .iter()
                        .zip(&cols[k])
                        .map(|(a, b)| a * b)
                        .sum::<f64>()
                        / n as f64
                })
                .collect()
        })
        .collect()
}

/// The size of a drift of shape `c` over a record spanning `span` samples: its root mean square
/// about its mean, √(cᵀGc) ([`drift_gram`]).
pub fn drift_norm(c: &[f64], span: f64) -> f64 {
    let g = drift_gram(c.len(), span);
    let mut q = 0.0;
    for (j, gj) in g.iter().enumerate() {
        for (k, gjk) in gj.iter().enumerate() {
            q += c[j] * gjk * c[k];
        }
    }
    q.max(0.0).sqrt()
}

/// Σ_{i=0}^{n−1} cos(θ·i + φ), in closed form.
fn cos_sum(theta: f64, phi: f64, n: f64) -> f64 {
    let h = (theta / 2.0).sin();
    if h.abs() < 1e-300 {
        return n * phi.cos();
    }
    (n * theta / 2.0).sin() / h * (phi + (n - 1.0) * theta / 2.0).cos()
}

/// Expected overlapping Allan variance at m of the drift of shape `c` ([`drift_at`]), exact over
/// the record's segments: the difference of neighbouring m-sample means is the ramp's constant
/// c₀·m plus a sum of cosines, Δ_i = c₀m + Σ_j R_j cos(ω_j i + φ_j) with ω_j = πj/T,
/// R_j = −2c_j·sin(mω_j/2)²/(m·sin(ω_j/2)) and φ_j = ω_j(a + m − ½) − π/2 in a segment starting at
/// a, so Σ_i Δ_i² is a double sum of closed-form cosine sums.
pub fn drift_avar(c: &[f64], m: u64, ctx: &Context) -> f64 {
    let total = ctx.terms(m);
    let span = drift_span(ctx);
    if total == 0 || span <= 0.0 || c.is_empty() {
        return 0.0;
    }
    let mf = m as f64;
    let ramp = c[0] * mf;
    let mut acc = 0.0;
    for &(a, l) in &ctx.segments {
        let terms = (l + 1).saturating_sub(2 * m) as f64;
        if terms == 0.0 {
            continue;
        }
        let comp: Vec<(f64, f64, f64)> = c[1..]
            .iter()
            .enumerate()
            .map(|(j, &cj)| {
                let w = std::f64::consts::PI * (j + 1) as f64 / span;
                let s = (mf * w / 2.0).sin();
                let r = -2.0 * cj * s * s / (mf * (w / 2.0).sin());
                (
                    w,
                    r,
                    w * (a as f64 + mf - 0.5) - std::f64::consts::FRAC_PI_2,
                )
            })
            .collect();
        acc += ramp * ramp * terms;
        for &(wj, rj, pj) in &comp {
            acc += 2.0 * ramp * rj * cos_sum(wj, pj, terms);
            for &(wk, rk, pk) in &comp {
                acc += rj
                    * rk
                    * 0.5
                    * (cos_sum(wj - wk, pj - pk, terms) + cos_sum(wj + wk, pj + pk, terms));
            }
        }
    }
    acc / (2.0 * total as f64)
}

/// Allan variance of unit-variance first-order Gauss–Markov noise with correlation time `tau_c`,
/// point-sampled every `tau0`, at τ = m·τ0 (the sampled AR(1) form of [`Structure::Ar1`]; tends to
/// IEEE 952 eq. C.7 as τ0 → 0, see [`markov_avar_continuous`]).
pub fn markov_avar_unit(tau: f64, tau0: f64, tau_c: f64) -> f64 {
    if !(tau_c > 0.0) || !(tau > 0.0) {
        return 0.0;
    }
    if tau0 <= 0.0 {
        return markov_avar_continuous(tau, tau_c);
    }
    Structure::Ar1 {
        phi: (-tau0 / tau_c).exp(),
    }
    .avar(tau / tau0)
    .max(0.0)
}

/// The continuous-time Gauss–Markov Allan variance (IEEE 952 C.7), unit steady-state variance:
/// σ²(τ) = (2τ_c/τ)[1 − (τ_c/2τ)(3 − 4e^{−τ/τ_c} + e^{−2τ/τ_c})], with a series for τ ≪ τ_c.
pub fn markov_avar_continuous(tau: f64, tau_c: f64) -> f64 {
    let x = tau / tau_c;
    if x < 0.5 {
        // σ² = Σ_{k≥3} (−1)^{k+1} (2^k − 4)/k! · x^{k−2}
        let mut sum = 0.0;
        let mut fact = 2.0; // 2!
        let mut p2 = 4.0; // 2^2
        let mut xp = 1.0; // x^{k−2}, built incrementally from k = 2
        for k in 3..40 {
            fact *= k as f64;
            p2 *= 2.0;
            xp *= x;
            let sign = if k % 2 == 1 { 1.0 } else { -1.0 };
            let t = sign * (p2 - 4.0) / fact * xp;
            sum += t;
            if t.abs() < 1e-18 * sum.abs() {
                break;
            }
        }
        sum
    } else {
        let h = 3.0 - 4.0 * (-x).exp() + (-2.0 * x).exp();
        2.0 / x - h / (x * x)
    }
}

/// Allan variance of a unit-amplitude sinusoid of frequency `f` point-sampled every `tau0`,
/// averaged over phase (the overlapping estimator averages over all starting phases):
/// σ²(m) = sin⁴(mθ/2) / (m² sin²(θ/2)), θ = 2πfτ0, from the Fejér kernel. As τ0 → 0 it is
/// IEEE 952 C.8, σ = A·sin²(πfτ)/(πfτ).
pub fn sinusoid_avar_unit(tau: f64, tau0: f64, f: f64) -> f64 {
    if !(f > 0.0) || !(tau > 0.0) {
        return 0.0;
    }
    if tau0 <= 0.0 {
        let x = std::f64::consts::PI * f * tau;
        return x.sin().powi(4) / (x * x);
    }
    sine_avar(tau / tau0, 2.0 * std::f64::consts::PI * f * tau0)
}

/// Allan variance of a unit-variance resonance (second-order Gauss–Markov, natural frequency
/// `f0`, damping ratio `zeta`) point-sampled every `tau0`, at τ = m·τ0 (NaN for parameters
/// outside [`resonance_structure`]'s range).
pub fn resonance_avar_unit(tau: f64, tau0: f64, f0: f64, zeta: f64) -> f64 {
    match resonance_structure(f0, zeta, tau0) {
        Ok(s) => s.avar(tau / tau0),
        Err(_) => f64::NAN,
    }
}
