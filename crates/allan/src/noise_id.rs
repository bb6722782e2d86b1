//! Power-law noise identification per averaging factor, as Stable32 does it
//! (NIST SP 1065 §5.6):
//!
//! * the lag-1 autocorrelation method (W. J. Riley and C. A. Greenhall, "Power law noise
//!   identification using the lag 1 autocorrelation", 18th EFTF, 2004) when at least 30
//!   averaged points exist;
//! * otherwise the B1 bias ratio (Barnes), with the R(n) ratio MVAR/AVAR to tell white from
//!   flicker PM (SP 1065 §5.6.2–5.6.3).
//!
//! `alpha` is the exponent of the rate (fractional frequency) PSD, `S_y(f) ∝ f^alpha`:
//! +2 white PM, +1 flicker PM, 0 white FM, −1 flicker FM, −2 random-walk FM.

/// Block averages of the rate over `m` samples, from the phase `x` (x[k] = Σ_{i<k} y_i):
/// `(x[(i+1)m] − x[im])/m`, O(N/m) work (the incomplete tail is dropped).
fn block_means(x: &[f64], m: usize) -> Vec<f64> {
    let count = x.len().saturating_sub(1) / m;
    (0..count)
        .map(|i| (x[(i + 1) * m] - x[i * m]) / m as f64)
        .collect()
}

fn detrend_linear(x: &mut [f64]) {
    let n = x.len() as f64;
    if x.len() < 2 {
        return;
    }
    let tm = (n - 1.0) / 2.0;
    let xm = x.iter().sum::<f64>() / n;
    let (mut sxy, mut sxx) = (0.0, 0.0);
    for (i, v) in x.iter().enumerate() {
        let dt = i as f64 - tm;
        sxy += dt * (v - xm);
        sxx += dt * dt;
    }
    let b = sxy / sxx;
    for (i, v) in x.iter_mut().enumerate() {
        *v -= xm + b * (i as f64 - tm);
    }
}

/// Lag-1 autocorrelation (Riley & Greenhall 2004, eq. 2).
pub fn lag1_acf(x: &[f64]) -> f64 {
    let n = x.len() as f64;
    let mu = x.iter().sum::<f64>() / n;
    let num: f64 = x.windows(2).map(|w| (w[0] - mu) * (w[1] - mu)).sum();
    let den: f64 = x.iter().map(|v| (v - mu) * (v - mu)).sum();
    if den == 0.0 {
        0.0
    } else {
        num / den
    }
}

/// Lag-1 ACF identification on the rate averaged by `m` (given its phase `x`); `None` with
/// fewer than 30 averages.
pub fn acf_alpha(x: &[f64], m: usize, d_max: u32) -> Option<i32> {
    let mut x = block_means(x, m);
    if x.len() < 30 {
        return None;
    }
    detrend_linear(&mut x);
    let mut d = 0u32;
    loop {
        let r1 = lag1_acf(&x);
        let rho = r1 / (1.0 + r1);
        if rho < 0.25 || d >= d_max {
            return Some(-((2.0 * rho).round_ties_even() as i32) - 2 * d as i32);
        }
        x = x.windows(2).map(|w| w[1] - w[0]).collect();
        d += 1;
    }
}

/// Expected B1 ratio (standard variance / Allan variance) for `n` averages and `σ² ∝ τ^μ`
/// (Barnes; SP 1065 §5.6.2).
pub fn b1_theory(n: f64, mu: i32) -> f64 {
    match mu {
        2 => n * (n + 1.0) / 6.0,
        1 => n / 2.0,
        0 => n * n.ln() / (2.0 * (n - 1.0) * std::f64::consts::LN_2),
        -1 => 1.0,
        -2 => (n * n - 1.0) / (1.5 * n * (n - 1.0)),
        _ => n * (1.0 - n.powi(mu)) / (2.0 * (n - 1.0) * (1.0 - 2f64.powi(mu))),
    }
}

/// Expected R(n) = MVAR/AVAR for white PM (`1/m`) and flicker PM (SP 1065 §5.6.3, with the
/// measurement bandwidth f_h = 1/(2τ0)).
fn rn_theory(m: f64, alpha: i32) -> f64 {
    use std::f64::consts::PI;
    match alpha {
        2 => 1.0 / m,
        1 => {
            let avar = (1.038 + 3.0 * (2.0 * PI * 0.5 * m).ln()) / (4.0 * PI * PI);
            let mvar = 3.0 * (256.0f64 / 27.0).ln() / (8.0 * PI * PI);
            mvar / avar
        }
        _ => 1.0,
    }
}

/// Fewest averages for which the B1 ratio is used; below it B1's scatter exceeds the spacing
/// of its theoretical values and the caller keeps the exponent found at the shorter τ.
pub const B1_MIN_AVERAGES: usize = 10;

/// B1 / R(n) identification for short series, given the phase `x` (Barnes' B1: the standard
/// variance of the `m` averages over their non-overlapping Allan variance); `rn` computes the
/// measured MVAR/AVAR at `m`, needed only to split white from flicker PM.
/// `None` with fewer than [`B1_MIN_AVERAGES`] averages.
pub fn b1_alpha(x: &[f64], m: usize, rn: impl FnOnce() -> Option<f64>) -> Option<i32> {
    let x = block_means(x, m);
    if x.len() < B1_MIN_AVERAGES {
        return None;
    }
    let n = x.len() as f64;
    let mean = x.iter().sum::<f64>() / n;
    let var = x.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0);
    let avar = x.windows(2).map(|w| (w[1] - w[0]).powi(2)).sum::<f64>() / (2.0 * (n - 1.0));
    if avar <= 0.0 {
        return None;
    }
    let b1 = var / avar;
    // Candidate mu from low to high; pick by the geometric-mean boundary between neighbours.
    let mus = [-2, -1, 0, 1, 2];
    let mut mu = 2;
    for w in mus.windows(2) {
        let bound = (b1_theory(n, w[0]) * b1_theory(n, w[1])).sqrt();
        if b1 < bound {
            mu = w[0];
            break;
        }
    }
    Some(match mu {
        -2 => match rn() {
            Some(r) if m > 1 => {
                let bound = (rn_theory(m as f64, 2) * rn_theory(m as f64, 1)).sqrt();
                if r < bound {
                    2
                } else {
                    1
                }
            }
            _ => 2,
        },
        mu => -mu - 1,
    })
}
