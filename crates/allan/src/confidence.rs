//! Confidence intervals: equivalent degrees of freedom and chi-squared bounds.
//!
//! * EDF of the Allan, Hadamard and modified variances by Greenhall's general algorithm:
//!   C. A. Greenhall and W. J. Riley, "Uncertainty of stability variances based on finite
//!   differences", Proc. 35th PTTI (2003), eqs. 7–13 and Tables 1–3 (the algorithm Stable32
//!   uses).
//! * EDF of the total variance: NIST SP 1065 (Riley 2008), Table 7; the simple formulas of
//!   SP 1065 Table 5 elsewhere.
//! * Bounds: `σ_lo² = edf·σ²/χ²(1−p, edf)`, `σ_hi² = edf·σ²/χ²(p, edf)` (SP 1065 eq. 45),
//!   with `p = (1 − cl)/2`.
//! * The tails the labs test with: χ² through the regularised incomplete gamma function
//!   (`gamma_pq`, `chi2_sf`), F through the regularised incomplete beta function (`beta_reg`,
//!   `f_sf`; Numerical Recipes §6.4, A&S 26.6.2).
//!
//! Everything here is `no_std` (libm), so the device can compute bounds too.

/// The 1-σ confidence level, erf(1/√2).
pub const ONE_SIGMA: f64 = 0.682_689_492_137_085_9;

/// Which family of variance an EDF is for.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Variance {
    /// Allan (d = 2) or Hadamard (d = 3) variance, unmodified, with estimator stride factor
    /// `s_factor` = m/stride (1 = non-overlapping, m = fully overlapping).
    Unmodified {
        /// Difference order: 2 for Allan, 3 for Hadamard.
        d: u32,
        /// m / stride.
        s_factor: f64,
    },
    /// Modified Allan variance (also TDEV), fully overlapping.
    Modified,
}

fn sw(t: f64, alpha: i32) -> f64 {
    // Greenhall eq. 7
    let at = libm::fabs(t);
    match alpha {
        2 => -at,
        1 => {
            if t == 0.0 {
                0.0
            } else {
                t * t * libm::log(at)
            }
        }
        0 => at * at * at,
        -1 => {
            if t == 0.0 {
                0.0
            } else {
                t * t * t * t * libm::log(at)
            }
        }
        -2 => at * at * at * at * at,
        -3 => {
            if t == 0.0 {
                0.0
            } else {
                libm::pow(t, 6.0) * libm::log(at)
            }
        }
        _ => libm::pow(at, 7.0),
    }
}

/// `F = None` stands for F = ∞.
fn sx(t: f64, f: Option<f64>, alpha: i32) -> f64 {
    // Greenhall eq. 8
    match f {
        None => sw(t, alpha + 2),
        Some(f) => f * f * (2.0 * sw(t, alpha) - sw(t - 1.0 / f, alpha) - sw(t + 1.0 / f, alpha)),
    }
}

fn sz(t: f64, f: Option<f64>, alpha: i32, d: u32) -> f64 {
    // Greenhall eq. 9: binomial-weighted sum of sx over t ± k.
    let x = |k: f64| sx(t + k, f, alpha);
    match d {
        1 => 2.0 * x(0.0) - x(-1.0) - x(1.0),
        2 => 6.0 * x(0.0) - 4.0 * (x(-1.0) + x(1.0)) + x(-2.0) + x(2.0),
        _ => {
            20.0 * x(0.0) - 15.0 * (x(-1.0) + x(1.0)) + 6.0 * (x(-2.0) + x(2.0))
                - (x(-3.0) + x(3.0))
        }
    }
}

fn basic_sum(j: f64, m_big: f64, s: f64, f: Option<f64>, alpha: i32, d: u32) -> f64 {
    // Greenhall eq. 10
    let z0 = sz(0.0, f, alpha, d);
    let mut sum = z0 * z0;
    let zj = sz(j / s, f, alpha, d);
    sum += (1.0 - j / m_big) * zj * zj;
    let mut i = 1.0;
    while i < j {
        let z = sz(i / s, f, alpha, d);
        sum += 2.0 * (1.0 - i / m_big) * z * z;
        i += 1.0;
    }
    sum
}

/// Greenhall & Riley Table 1 (modified variances): (a0, a1) for alpha = 2..-4, d = 1..3.
fn table1(alpha: i32, d: u32) -> Option<(f64, f64)> {
    const T: [[(f64, f64); 3]; 7] = [
        [
            (2.0 / 3.0, 1.0 / 3.0),
            (7.0 / 9.0, 1.0 / 2.0),
            (22.0 / 25.0, 2.0 / 3.0),
        ],
        [(0.840, 0.345), (0.997, 0.616), (1.141, 0.843)],
        [(1.079, 0.368), (1.033, 0.607), (1.184, 0.848)],
        [(f64::NAN, f64::NAN), (1.048, 0.534), (1.180, 0.816)],
        [(f64::NAN, f64::NAN), (1.302, 0.535), (1.175, 0.777)],
        [(f64::NAN, f64::NAN), (f64::NAN, f64::NAN), (1.194, 0.703)],
        [(f64::NAN, f64::NAN), (f64::NAN, f64::NAN), (1.489, 0.702)],
    ];
    lookup(&T, alpha, d)
}

/// Greenhall & Riley Table 2 (unmodified variances, alpha ≤ 1).
fn table2(alpha: i32, d: u32) -> Option<(f64, f64)> {
    const T: [[(f64, f64); 3]; 7] = [
        [
            (3.0 / 2.0, 1.0 / 2.0),
            (35.0 / 18.0, 1.0),
            (231.0 / 100.0, 3.0 / 2.0),
        ],
        [(78.6, 25.2), (790.0, 410.0), (9950.0, 6520.0)],
        [
            (2.0 / 3.0, 1.0 / 6.0),
            (2.0 / 3.0, 1.0 / 3.0),
            (7.0 / 9.0, 1.0 / 2.0),
        ],
        [(f64::NAN, f64::NAN), (0.852, 0.375), (0.997, 0.617)],
        [(f64::NAN, f64::NAN), (1.079, 0.368), (1.033, 0.607)],
        [(f64::NAN, f64::NAN), (f64::NAN, f64::NAN), (1.053, 0.553)],
        [(f64::NAN, f64::NAN), (f64::NAN, f64::NAN), (1.302, 0.535)],
    ];
    lookup(&T, alpha, d)
}

/// Greenhall & Riley Table 3 (alpha = 1, unmodified): (b0, b1) for d = 1..3.
fn table3(d: u32) -> (f64, f64) {
    [(6.0, 4.0), (15.23, 12.0), (47.8, 40.0)][(d.clamp(1, 3) - 1) as usize]
}

fn lookup(t: &[[(f64, f64); 3]; 7], alpha: i32, d: u32) -> Option<(f64, f64)> {
    let row = usize::try_from(2 - alpha).ok()?;
    let col = usize::try_from(d.checked_sub(1)?).ok()?;
    let v = *t.get(row)?.get(col)?;
    (!v.0.is_nan()).then_some(v)
}

const J_MAX: f64 = 100.0;

/// Equivalent degrees of freedom by Greenhall's general algorithm.
///
/// * `alpha` — noise exponent of the rate PSD, `S_y(f) ∝ f^alpha`, from +2 to −4;
///   `alpha + 2d > 1` is required.
/// * `m` — averaging factor, `n_phase` — number of phase points `N`.
///
/// Returns `None` when the combination is outside the algorithm's domain.
pub fn edf_greenhall(alpha: i32, m: f64, n_phase: f64, var: Variance) -> Option<f64> {
    let (d, s, f_mod) = match var {
        Variance::Unmodified { d, s_factor } => (d, s_factor, false),
        Variance::Modified => (2, m, true),
    };
    if !(1..=3).contains(&d) || alpha + 2 * d as i32 <= 1 || !(-4..=2).contains(&alpha) {
        return None;
    }
    let f = if f_mod { 1.0 } else { m };
    let l = m / f + m * d as f64;
    let m_big = 1.0 + libm::floor(s * (n_phase - l) / m);
    if m_big < 1.0 {
        return None;
    }
    let j = libm::fmin(m_big, (d as f64 + 1.0) * s);
    let r = m_big / s;
    let inv = if f_mod {
        // Case 1: modified variances, all alpha.
        if j <= J_MAX {
            let z0 = sz(0.0, Some(1.0), alpha, d);
            basic_sum(j, m_big, s, Some(1.0), alpha, d) / (z0 * z0 * m_big)
        } else if r > d as f64 + 1.0 {
            let (a0, a1) = table1(alpha, d)?;
            (a0 - a1 / r) / r
        } else {
            let mp = J_MAX / r;
            let z0 = sz(0.0, Some(1.0), alpha, d);
            basic_sum(J_MAX, J_MAX, mp, Some(1.0), alpha, d) / (z0 * z0 * J_MAX)
        }
    } else if alpha <= 0 {
        // Case 2: unmodified, alpha ≤ 0.
        if j <= J_MAX {
            let fp = if m * (d as f64 + 1.0) <= J_MAX {
                Some(m)
            } else {
                None
            };
            let z0 = sz(0.0, fp, alpha, d);
            basic_sum(j, m_big, s, fp, alpha, d) / (z0 * z0 * m_big)
        } else if r > d as f64 + 1.0 {
            let (a0, a1) = table2(alpha, d)?;
            (a0 - a1 / r) / r
        } else {
            let mp = J_MAX / r;
            let z0 = sz(0.0, None, alpha, d);
            basic_sum(J_MAX, J_MAX, mp, None, alpha, d) / (z0 * z0 * J_MAX)
        }
    } else if alpha == 1 {
        // Case 3: unmodified, flicker PM.
        if j <= J_MAX {
            let z0 = sz(0.0, Some(m), 1, d);
            basic_sum(j, m_big, s, Some(m), 1, d) / (z0 * z0 * m_big)
        } else {
            let (b0, b1) = table3(d);
            let c = b0 + b1 * libm::log(m);
            if r > d as f64 + 1.0 {
                let (a0, a1) = table2(1, d)?;
                (a0 - a1 / r) / (c * c * r)
            } else {
                let mp = J_MAX / r;
                basic_sum(J_MAX, J_MAX, mp, Some(mp), 1, d) / (c * c * J_MAX)
            }
        }
    } else {
        // Case 4: unmodified, white PM (alpha = 2).
        let k = libm::ceil(r);
        if k <= d as f64 {
            return None;
        }
        let a0 = binom(4 * d, 2 * d) / (binom(2 * d, d) * binom(2 * d, d));
        let a1 = d as f64 / 2.0;
        (a0 - a1 / r) / m_big
    };
    (inv > 0.0 && inv.is_finite()).then(|| 1.0 / inv)
}

fn binom(n: u32, k: u32) -> f64 {
    let mut c = 1.0;
    for i in 0..k {
        c = c * (n - i) as f64 / (i + 1) as f64;
    }
    c
}

/// EDF of the total deviation: `b·(N/m) − c` (NIST SP 1065 Table 7) for white, flicker and
/// random-walk FM (N = number of phase points); other noises use [`edf_simple`].
pub fn edf_totdev(alpha: i32, m: f64, n_phase: f64) -> f64 {
    match alpha {
        0 => 1.50 * n_phase / m,
        -1 => 1.17 * n_phase / m - 0.22,
        -2 => 0.93 * n_phase / m - 0.36,
        _ => edf_simple(alpha, m, n_phase),
    }
}

/// The simple EDF approximations of NIST SP 1065 Table 5 (overlapping ADEV).
pub fn edf_simple(alpha: i32, m: f64, n: f64) -> f64 {
    match alpha {
        2 => (n + 1.0) * (n - 2.0 * m) / (2.0 * (n - m)),
        1 => {
            let a = (n - 1.0) / (2.0 * m);
            let b = (2.0 * m + 1.0) * (n - 1.0) / 4.0;
            libm::exp(libm::sqrt(libm::log(a) * libm::log(b)))
        }
        0 => {
            (3.0 * (n - 1.0) / (2.0 * m) - 2.0 * (n - 2.0) / n)
                * (4.0 * m * m / (4.0 * m * m + 5.0))
        }
        -1 => {
            if m <= 1.0 {
                2.0 * (n - 2.0) / (2.3 * n - 4.9)
            } else {
                5.0 * n * n / (4.0 * m * (n + 3.0 * m))
            }
        }
        _ => {
            (n - 2.0) / (m * (n - 3.0) * (n - 3.0))
                * ((n - 1.0) * (n - 1.0) - 3.0 * m * (n - 1.0) + 4.0 * m * m)
        }
    }
}

/// Regularised incomplete gamma functions `(P(a, x), Q(a, x) = 1 − P)`, each computed directly
/// where it is small so both tails keep full relative accuracy (series below a+1, Lentz's
/// continued fraction above; Numerical Recipes §6.2, A&S 6.5.29/6.5.31). A NaN argument or a
/// shape that is not a positive finite number gives NaN for both (never a probability of 0 or 1
/// that a comparison would take for a verdict); x = +∞ gives (1, 0).
pub fn gamma_pq(a: f64, x: f64) -> (f64, f64) {
    if x.is_nan() || !(a > 0.0 && a.is_finite()) {
        return (f64::NAN, f64::NAN);
    }
    if x <= 0.0 {
        return (0.0, 1.0);
    }
    if x == f64::INFINITY {
        return (1.0, 0.0);
    }
    let ln_pre = a * libm::log(x) - x - libm::lgamma(a);
    if x < a + 1.0 {
        let (mut ap, mut del) = (a, 1.0 / a);
        let mut sum = del;
        for _ in 0..10_000 {
            ap += 1.0;
            del *= x / ap;
            sum += del;
            if libm::fabs(del) < libm::fabs(sum) * 1e-16 {
                break;
            }
        }
        let p = libm::fmin(sum * libm::exp(ln_pre), 1.0);
        (p, 1.0 - p)
    } else {
        let tiny = 1e-300;
        let mut b = x + 1.0 - a;
        let mut c = 1.0 / tiny;
        let mut d = 1.0 / b;
        let mut h = d;
        for i in 1..10_000 {
            let an = -(i as f64) * (i as f64 - a);
            b += 2.0;
            d = an * d + b;
            if libm::fabs(d) < tiny {
                d = tiny;
            }
            c = b + an / c;
            if libm::fabs(c) < tiny {
                c = tiny;
            }
            d = 1.0 / d;
            let del = d * c;
            h *= del;
            if libm::fabs(del - 1.0) < 1e-16 {
                break;
            }
        }
        let q = libm::fmin(libm::exp(ln_pre) * h, 1.0);
        (1.0 - q, q)
    }
}

/// Regularised lower incomplete gamma function P(a, x).
pub fn gamma_p(a: f64, x: f64) -> f64 {
    gamma_pq(a, x).0
}

/// Chi-squared CDF with `nu` (possibly fractional) degrees of freedom.
pub fn chi2_cdf(x: f64, nu: f64) -> f64 {
    gamma_pq(nu / 2.0, x / 2.0).0
}

/// Chi-squared survival function P(X > x), accurate in the far upper tail.
pub fn chi2_sf(x: f64, nu: f64) -> f64 {
    gamma_pq(nu / 2.0, x / 2.0).1
}

/// Regularised incomplete beta function `I_x(a, b)`, by its continued fraction (modified Lentz)
/// on the side where it converges fast: directly below x = (a+1)/(a+b+2), else as
/// `1 − I_{1−x}(b, a)` (Numerical Recipes §6.4; A&S 26.5.8). NaN unless a > 0, b > 0 and
/// 0 ≤ x ≤ 1.
pub fn beta_reg(a: f64, b: f64, x: f64) -> f64 {
    if !(a > 0.0 && b > 0.0 && (0.0..=1.0).contains(&x)) {
        return f64::NAN;
    }
    if x == 0.0 || x == 1.0 {
        return x;
    }
    let ln_front = libm::lgamma(a + b) - libm::lgamma(a) - libm::lgamma(b)
        + a * libm::log(x)
        + b * libm::log1p(-x);
    if x < (a + 1.0) / (a + b + 2.0) {
        libm::exp(ln_front) * beta_cf(a, b, x) / a
    } else {
        1.0 - libm::exp(ln_front) * beta_cf(b, a, 1.0 - x) / b
    }
}

/// The continued fraction of `I_x(a, b)` (Numerical Recipes §6.4 `betacf`), modified Lentz.
fn beta_cf(a: f64, b: f64, x: f64) -> f64 {
    let tiny = 1e-300;
    let (qab, qap, qam) = (a + b, a + 1.0, a - 1.0);
    let mut c = 1.0;
    let mut d = 1.0 - qab * x / qap;
    if libm::fabs(d) < tiny {
        d = tiny;
    }
    d = 1.0 / d;
    let mut h = d;
    // one modified-Lentz step with coefficient aa: updates c and d, returns the factor of h
    let step = |aa: f64, c: &mut f64, d: &mut f64| {
        *d = 1.0 + aa * *d;
        if libm::fabs(*d) < tiny {
            *d = tiny;
        }
        *c = 1.0 + aa / *c;
        if libm::fabs(*c) < tiny {
            *c = tiny;
        }
        *d = 1.0 / *d;
        *d * *c
    };
    for m in 1..10_000 {
        let m = m as f64;
        let m2 = 2.0 * m;
        // even step, then odd step
        h *= step(m * (b - m) * x / ((qam + m2) * (a + m2)), &mut c, &mut d);
        let del = step(
            -(a + m) * (qab + m) * x / ((a + m2) * (qap + m2)),
            &mut c,
            &mut d,
        );
        h *= del;
        if libm::fabs(del - 1.0) < 1e-16 {
            break;
        }
    }
    h
}

/// Upper tail P(F > f) of the Fisher–Snedecor distribution with (d1, d2) degrees of freedom,
/// `I_{d2/(d2 + d1·f)}(d2/2, d1/2)` (A&S 26.6.2), the argument taken in the form that keeps the
/// far tail's relative accuracy. f = +∞ gives 0; f ≤ 0, a NaN f and degrees of freedom that are
/// not positive give 1 (no evidence against the null).
pub fn f_sf(f: f64, d1: f64, d2: f64) -> f64 {
    if !(d1 > 0.0 && d2 > 0.0 && d1.is_finite() && d2.is_finite()) {
        return if f == f64::INFINITY { 0.0 } else { 1.0 };
    }
    if f == f64::INFINITY {
        return 0.0;
    }
    if f.is_nan() || f <= 0.0 {
        return 1.0;
    }
    beta_reg(d2 / 2.0, d1 / 2.0, d2 / (d2 + d1 * f))
}

/// Standard normal CDF, Φ(z) = ½[1 ± P(½, z²/2)].
pub fn norm_cdf(z: f64) -> f64 {
    let (p, q) = gamma_pq(0.5, 0.5 * z * z);
    if z >= 0.0 {
        0.5 + 0.5 * p
    } else {
        0.5 * q
    }
}

/// Standard normal quantile Φ⁻¹(p): Acklam's rational approximation refined by one Halley step
/// on [`norm_cdf`] (full double precision); ±∞ at p = 0, 1 and NaN outside [0, 1].
pub fn norm_ppf(p: f64) -> f64 {
    if p.is_nan() || !(0.0..=1.0).contains(&p) {
        return f64::NAN;
    }
    if p == 0.0 {
        return f64::NEG_INFINITY;
    }
    if p == 1.0 {
        return f64::INFINITY;
    }
    let x = norm_ppf_approx(p);
    let e = norm_cdf(x) - p;
    let u = e * libm::sqrt(2.0 * core::f64::consts::PI) * libm::exp(x * x / 2.0);
    let refined = x - u / (1.0 + x * u / 2.0);
    // In the far tails (p below ~1e-290) e^{x²/2} overflows and the Halley step is 0·∞: the
    // rational approximation is then the answer (its relative error stays below 1.2e-9).
    if refined.is_finite() {
        refined
    } else {
        x
    }
}

/// Acklam's rational approximation of the standard normal quantile (|error| < 1.2e-9).
fn norm_ppf_approx(p: f64) -> f64 {
    const A: [f64; 6] = [
        -3.969683028665376e1,
        2.209460984245205e2,
        -2.759285104469687e2,
        1.383_577_518_672_69e2,
        -3.066479806614716e1,
        2.506628277459239,
    ];
    const B: [f64; 5] = [
        -5.447609879822406e1,
        1.615858368580409e2,
        -1.556989798598866e2,
        6.680131188771972e1,
        -1.328068155288572e1,
    ];
    const C: [f64; 6] = [
        -7.784894002430293e-3,
        -3.223964580411365e-1,
        -2.400758277161838,
        -2.549732539343734,
        4.374664141464968,
        2.938163982698783,
    ];
    const D: [f64; 4] = [
        7.784695709041462e-3,
        3.224671290700398e-1,
        2.445134137142996,
        3.754408661907416,
    ];
    let tail = |q: f64| {
        (((((C[0] * q + C[1]) * q + C[2]) * q + C[3]) * q + C[4]) * q + C[5])
            / ((((D[0] * q + D[1]) * q + D[2]) * q + D[3]) * q + 1.0)
    };
    if p < 0.02425 {
        tail(libm::sqrt(-2.0 * libm::log(p)))
    } else if p > 1.0 - 0.02425 {
        -tail(libm::sqrt(-2.0 * libm::log(1.0 - p)))
    } else {
        let q = p - 0.5;
        let r = q * q;
        (((((A[0] * r + A[1]) * r + A[2]) * r + A[3]) * r + A[4]) * r + A[5]) * q
            / (((((B[0] * r + B[1]) * r + B[2]) * r + B[3]) * r + B[4]) * r + 1.0)
    }
}

/// Chi-squared quantile: the x with `chi2_cdf(x, nu) = p`, to ~1e-12 relative.
/// Wilson–Hilferty start, then safeguarded Newton/bisection.
pub fn chi2_ppf(p: f64, nu: f64) -> f64 {
    if !(p > 0.0 && p < 1.0 && nu > 0.0) {
        return f64::NAN;
    }
    let z = norm_ppf_approx(p);
    let h = 2.0 / (9.0 * nu);
    let mut x = nu * libm::pow(libm::fmax(1.0 - h + z * libm::sqrt(h), 0.01), 3.0);
    let (mut lo, mut hi) = (0.0, f64::INFINITY);
    let k = nu / 2.0;
    let ln_norm = libm::lgamma(k) + k * libm::log(2.0);
    for _ in 0..200 {
        let f = chi2_cdf(x, nu) - p;
        if f > 0.0 {
            hi = x;
        } else {
            lo = x;
        }
        let pdf = libm::exp((k - 1.0) * libm::log(x) - x / 2.0 - ln_norm);
        let mut next = x - f / pdf;
        if !(next > lo && next < hi && next.is_finite()) {
            next = if hi.is_finite() {
                0.5 * (lo + hi)
            } else {
                2.0 * x + 1.0
            };
        }
        if libm::fabs(next - x) <= 1e-14 * x {
            return next;
        }
        x = next;
    }
    x
}

/// Confidence bounds `(lo, hi)` of a deviation with `edf` degrees of freedom at confidence
/// level `cl` (e.g. [`ONE_SIGMA`]); SP 1065 eq. 45.
pub fn chi2_bounds(dev: f64, edf: f64, cl: f64) -> (f64, f64) {
    let p = (1.0 - cl) / 2.0;
    let lo = dev * libm::sqrt(edf / chi2_ppf(1.0 - p, edf));
    let hi = dev * libm::sqrt(edf / chi2_ppf(p, edf));
    (lo, hi)
}

/// Noise exponent from the local slope of the variance between two levels:
/// `σ² ∝ τ^μ` ⇒ `alpha = −μ − 1` (μ = −2 is read as white PM, alpha = 2). Used for the
/// streaming tables, where the raw data is no longer available for a lag-1 ACF test.
pub fn alpha_from_slope(var_lo: f64, var_hi: f64, tau_ratio: f64, d: u32) -> i32 {
    if !(var_lo > 0.0 && var_hi > 0.0 && tau_ratio > 1.0) {
        return 0;
    }
    let mu = libm::log(var_hi / var_lo) / libm::log(tau_ratio);
    let alpha = libm::round(-mu - 1.0) as i32;
    // alpha + 2d > 1 is needed by the EDF algorithm; +2 is the largest alpha that exists.
    alpha.clamp(2 - 2 * d as i32, 2)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn f_tail_matches_tables_and_closed_form() {
        // Upper 5 % point of F(3, 20) = 3.098 (NIST/SEMATECH e-Handbook of Statistical Methods,
        // §1.3.6.7.3, table of the F distribution's upper critical values; A&S Table 26.9).
        assert!((f_sf(3.098, 3.0, 20.0) - 0.05).abs() < 1e-4);
        // upper 1 % point of F(5, 10) = 5.636 (same tables)
        assert!((f_sf(5.636, 5.0, 10.0) - 0.01).abs() < 1e-4);
        // d1 = 2 has the closed form P(F > f) = (1 + 2f/d2)^(−d2/2): to the last digits, far
        // tail included
        for &(f, d2) in &[(0.3, 7.0), (2.5, 40.0), (60.0, 12.5), (1e3, 30.0)] {
            let exact = libm::pow(1.0 + 2.0 * f / d2, -d2 / 2.0);
            assert!(
                (f_sf(f, 2.0, d2) / exact - 1.0).abs() < 1e-12,
                "{f} {d2}: {} vs {exact}",
                f_sf(f, 2.0, d2)
            );
        }
        // the edges: no evidence without a positive statistic, none left at +∞
        assert_eq!(f_sf(0.0, 3.0, 20.0), 1.0);
        assert_eq!(f_sf(f64::NAN, 3.0, 20.0), 1.0);
        assert_eq!(f_sf(f64::INFINITY, 3.0, 20.0), 0.0);
        assert_eq!(f_sf(2.0, 0.0, 20.0), 1.0);
        // I_x(a, b) + I_{1−x}(b, a) = 1
        assert!((beta_reg(2.5, 4.0, 0.3) + beta_reg(4.0, 2.5, 0.7) - 1.0).abs() < 1e-14);
    }

    #[test]
    fn chi2_quantiles_match_tables() {
        // Values from standard chi-squared tables (Abramowitz & Stegun Table 26.8).
        assert!((chi2_ppf(0.95, 10.0) - 18.307_038).abs() < 1e-5);
        assert!((chi2_ppf(0.05, 10.0) - 3.940_299).abs() < 1e-5);
        assert!((chi2_ppf(0.5, 1.0) - 0.454_936_4).abs() < 1e-6);
        assert!((chi2_ppf(0.99, 100.0) - 135.806_7).abs() < 1e-3);
    }

    #[test]
    fn normal_and_tails() {
        // A&S Table 26.1: Φ(1) = 0.841344746, Φ⁻¹(0.975) = 1.959963985.
        assert!((norm_cdf(1.0) - 0.841_344_746_068_543).abs() < 1e-14);
        assert!((norm_ppf(0.975) - 1.959_963_984_540_054).abs() < 1e-13);
        assert!((norm_ppf(1e-10) + 6.361_340_902_404_056).abs() < 1e-9);
        // The far tails are finite and ordered down to the smallest subnormal: there the Halley
        // step's e^{x²/2} overflows (it made a z-score NaN, and a whole fit fail).
        let mut last = f64::NEG_INFINITY;
        for p in [5e-324, 1e-320, 1e-310, 1e-300, 1e-290, 1e-200] {
            let z = norm_ppf(p);
            assert!(z.is_finite() && z > last, "Φ⁻¹({p:e}) = {z}");
            // the quantile's density: ln p ≈ −z²/2 − ln(−z√(2π)) within 1e-3 relative
            let lp = -z * z / 2.0 - libm::log(-z * libm::sqrt(2.0 * core::f64::consts::PI));
            assert!(
                libm::fabs(lp / libm::log(p) - 1.0) < 1e-3,
                "Φ⁻¹({p:e}) = {z}"
            );
            let q = libm::fmax(p, 1e-10);
            assert!(libm::fabs(norm_ppf(1.0 - q) + norm_ppf(q)) < 1e-6);
            last = z;
        }
        // Upper tail keeps relative accuracy where 1 − CDF would cancel: Q(χ²=200, ν=10).
        let sf = chi2_sf(200.0, 10.0);
        assert!(sf > 0.0 && sf < 1e-35, "{sf}");
        assert!((chi2_sf(18.307_038, 10.0) - 0.05).abs() < 1e-7);
        // χ²(2) survival is exp(−x/2) exactly; A&S 26.8: χ²(10) 99.9 % point 29.588.
        assert!((chi2_sf(7.0, 2.0) - (-3.5f64).exp()).abs() < 1e-14);
        assert!((chi2_ppf(0.999, 10.0) - 29.588_3).abs() < 1e-3);
    }

    #[test]
    fn a_nan_statistic_is_no_probability() {
        // A NaN statistic or degree of freedom must not read as p = 1 (a model passing) or 0.
        for (x, nu) in [
            (f64::NAN, 10.0),
            (5.0, f64::NAN),
            (5.0, 0.0),
            (5.0, f64::INFINITY),
        ] {
            assert!(chi2_sf(x, nu).is_nan(), "chi2_sf({x}, {nu})");
            assert!(chi2_cdf(x, nu).is_nan(), "chi2_cdf({x}, {nu})");
        }
        assert_eq!(chi2_sf(f64::INFINITY, 3.0), 0.0);
        assert_eq!(chi2_cdf(f64::INFINITY, 3.0), 1.0);
    }
}
