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
    if x.len() < ACF_MIN_AVERAGES {
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

/// Averages generated per chunk (stack buffers, so the identification allocates nothing
/// however long the record).
const CHUNK: usize = 256;

/// Fewest averages for the lag-1 ACF method; below it [`b1_mu`] is used.
pub const ACF_MIN_AVERAGES: usize = 30;

/// Number of rate averages over `m` samples in a phase record of `np` points.
pub fn averages(np: usize, m: usize) -> usize {
    np.saturating_sub(1) / m
}

/// `out[k] = (x[(j0+k+1)m] − x[(j0+k)m])/m`, the averages of the rate over `m` samples.
fn fill_means(x: &[f64], m: usize, inv: f64, j0: usize, out: &mut [f64]) {
    if m == 1 {
        let (lo, hi) = (&x[j0..j0 + out.len()], &x[j0 + 1..=j0 + out.len()]);
        for ((o, a), b) in out.iter_mut().zip(lo).zip(hi) {
            *o = (b - a) * inv;
        }
    } else {
        let mut prev = x[j0 * m];
        for (k, o) in out.iter_mut().enumerate() {
            let next = x[(j0 + k + 1) * m];
            *o = (next - prev) * inv;
            prev = next;
        }
    }
}

/// Σ v and Σ v² over `v[..own]`, and Σ v_k·v_{k+1} over the first `pairs` k (in lanes, so the
/// loops vectorise).
fn moments(v: &[f64], own: usize, pairs: usize) -> (f64, f64, f64) {
    let (mut s, mut q, mut p) = ([0.0f64; 4], [0.0f64; 4], [0.0f64; 4]);
    let mut c = v[..own].chunks_exact(4);
    for w in &mut c {
        for l in 0..4 {
            s[l] += w[l];
            q[l] += w[l] * w[l];
        }
    }
    for w in c.remainder() {
        s[0] += w;
        q[0] += w * w;
    }
    // (An empty chunk, the last one of a high difference order, has no pairs and no v[1].)
    let (lo, hi) = (&v[..pairs], v.get(1..pairs + 1).unwrap_or(&[]));
    let mut c = lo.chunks_exact(4).zip(hi.chunks_exact(4));
    for (a, b) in &mut c {
        for l in 0..4 {
            p[l] += a[l] * b[l];
        }
    }
    let done = pairs / 4 * 4;
    for (a, b) in lo[done..].iter().zip(&hi[done..]) {
        p[0] += a * b;
    }
    let sum = |a: [f64; 4]| (a[0] + a[1]) + (a[2] + a[3]);
    (sum(s), sum(q), sum(p))
}

/// `[Σ v, Σ v², Σ v_k·v_{k+1}, Σ t_k·v_k]` over `k < own` (the lag products over `k < pairs`)
/// of `v_k = b_k − (a0 + s0·t_k)`, `t_k = t0 + k`: the [`AvgSums`] of one chunk of averages.
fn chunk_sums(b: &[f64], own: usize, pairs: usize, t0: f64, a0: f64, s0: f64) -> [f64; 4] {
    #[cfg(target_arch = "x86_64")]
    if std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("fma") {
        // SAFETY: the CPU has the features the copy was compiled for.
        return unsafe { chunk_sums_avx2_fma(b, own, pairs, t0, a0, s0) };
    }
    chunk_sums_portable(b, own, pairs, t0, a0, s0)
}

fn chunk_sums_portable(b: &[f64], own: usize, pairs: usize, t0: f64, a0: f64, s0: f64) -> [f64; 4] {
    let mut out = [0.0f64; 4];
    for k in 0..own {
        let t = t0 + k as f64;
        let v = b[k] - (a0 + s0 * t);
        out[0] += v;
        out[1] += v * v;
        if k < pairs {
            out[2] += v * (b[k + 1] - (a0 + s0 * (t + 1.0)));
        }
        out[3] += t * v;
    }
    out
}

/// [`chunk_sums`] in AVX2 registers with fused multiply-adds (intrinsics, so it vectorises at
/// any optimisation level).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn chunk_sums_avx2_fma(b: &[f64], own: usize, pairs: usize, t0: f64, a0: f64, s0: f64) -> [f64; 4] {
    use std::arch::x86_64::*;
    assert!(pairs <= own && own <= b.len() && (pairs == 0 || pairs < b.len()));
    // Vectors of four k, each needing b[k + 1]: whole groups below `pairs`.
    let full = pairs / 4 * 4;
    let p = b.as_ptr();
    let mut out = [0.0f64; 4];
    // SAFETY: loads read b[k .. k + 5] with k + 4 ≤ full ≤ pairs < b.len().
    unsafe {
        let zero = _mm256_setzero_pd();
        let (mut s, mut q, mut pr, mut st) = (zero, zero, zero, zero);
        let (va0, vs0) = (_mm256_set1_pd(a0), _mm256_set1_pd(s0));
        let mut t = _mm256_add_pd(_mm256_set1_pd(t0), _mm256_setr_pd(0.0, 1.0, 2.0, 3.0));
        let mut k = 0;
        while k < full {
            let line = _mm256_fmadd_pd(vs0, t, va0);
            let v = _mm256_sub_pd(_mm256_loadu_pd(p.add(k)), line);
            let next = _mm256_sub_pd(_mm256_loadu_pd(p.add(k + 1)), _mm256_add_pd(line, vs0));
            s = _mm256_add_pd(s, v);
            q = _mm256_fmadd_pd(v, v, q);
            pr = _mm256_fmadd_pd(v, next, pr);
            st = _mm256_fmadd_pd(t, v, st);
            t = _mm256_add_pd(t, _mm256_set1_pd(4.0));
            k += 4;
        }
        for (o, r) in out.iter_mut().zip([s, q, pr, st]) {
            let mut lanes = [0.0f64; 4];
            _mm256_storeu_pd(lanes.as_mut_ptr(), r);
            *o = (lanes[0] + lanes[1]) + (lanes[2] + lanes[3]);
        }
    }
    let rest = chunk_sums_portable(
        &b[full..],
        own - full,
        pairs - full,
        t0 + full as f64,
        a0,
        s0,
    );
    for (o, r) in out.iter_mut().zip(rest) {
        *o += r;
    }
    out
}

/// A rough line `(a0, s0)` through the `n` averages over `m` samples, `a0 + s0·(j − tm)`:
/// their exact mean and the slope between the means of the two halves, each a difference of
/// two phase values.
fn rough_line(x: &[f64], m: usize, n: usize) -> (f64, f64) {
    if n < 2 {
        return (0.0, 0.0);
    }
    let h = n / 2;
    let (x0, xh, xn) = (x[0], x[h * m], x[n * m]);
    let a0 = (xn - x0) / (n * m) as f64;
    let s0 = ((xn - xh) / ((n - h) * m) as f64 - (xh - x0) / (h * m) as f64) / (n as f64 / 2.0);
    (a0, s0)
}

/// Raw sums over the averages `b_j` of the rate over `m` samples, from which the lag-1
/// autocorrelation of the linearly detrended averages follows ([`AvgSums::lag1_detrended`]).
/// The sums are of `b_j` less a rough line through them (a line changes no residual of the
/// least-squares line, and taking it out first keeps the raw sums near the residuals'
/// magnitude, so little cancels). Additive: any split of the averages into ranges, summed in
/// any order, gives the same up to rounding, so one pass over the phase can serve several m
/// and several cores.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct AvgSums {
    /// Σ b′ with b′ = b less the rough line.
    pub sb: f64,
    /// Σ (j − tm)·b′ with tm = (n − 1)/2 the centre of the n averages.
    pub stb: f64,
    /// Σ b′².
    pub sbb: f64,
    /// Σ b′_j·b′_{j+1}.
    pub sbb1: f64,
}

impl AvgSums {
    /// Add the averages `j0..j1` (clipped to the record) of phase `x` over `m` samples; the
    /// lag product of each `j` with `j + 1` counts with `j`.
    pub fn add(&mut self, x: &[f64], m: usize, j0: usize, j1: usize) {
        let n = averages(x.len(), m);
        let j1 = j1.min(n);
        let inv = 1.0 / m as f64;
        let tm = (n as f64 - 1.0) / 2.0;
        let (a0, s0) = rough_line(x, m, n);
        let mut b = [0.0f64; CHUNK + 1];
        let mut j = j0;
        while j < j1 {
            let own = CHUNK.min(j1 - j);
            let len = (own + 1).min(n - j);
            let b = &mut b[..len];
            fill_means(x, m, inv, j, b);
            let [sb, sbb, sbb1, stb] = chunk_sums(b, own, own.min(len - 1), j as f64 - tm, a0, s0);
            self.sb += sb;
            self.sbb += sbb;
            self.sbb1 += sbb1;
            self.stb += stb;
            j += own;
        }
    }

    /// Add another partial sum.
    pub fn merge(&mut self, o: &AvgSums) {
        self.sb += o.sb;
        self.stb += o.stb;
        self.sbb += o.sbb;
        self.sbb1 += o.sbb1;
    }

    /// Lag-1 autocorrelation (Riley & Greenhall eq. 2, as [`lag1_acf`] after
    /// `detrend_linear`) of the linearly detrended averages, from the sums over all of them.
    ///
    /// Writing b for b′: with g = b − mean and z = g − slope·t (t = j − tm, Σ t = 0, Σ t² = n(n²−1)/12) the
    /// residual and lag sums are Σ z² = Σ b² − mean·Σ b − slope·Σ t·b and
    /// Σ z_j z_{j+1} = Σ g_j g_{j+1} − slope·Σ (t_{j+1} g_j + t_j g_{j+1}) + slope²·Σ t_j t_{j+1},
    /// every term a raw sum or an end value. The raw sums lose accuracy relative to the direct
    /// two-pass computation by the ratio of the mean square of b′ to the residual variance,
    /// which the rough line keeps near 1.
    pub fn lag1_detrended(&self, x: &[f64], m: usize) -> f64 {
        let n = averages(x.len(), m);
        let nf = n as f64;
        let tm = (nf - 1.0) / 2.0;
        let (a0, s0) = rough_line(x, m, n);
        let b =
            |j: usize| (x[(j + 1) * m] - x[j * m]) * (1.0 / m as f64) - (a0 + s0 * (j as f64 - tm));
        let a = self.sb / nf;
        let stt = nf * (nf * nf - 1.0) / 12.0;
        let slope = self.stb / stt;
        let (g0, gl) = (b(0) - a, b(n - 1) - a);
        let sg = self.sb - nf * a;
        let sgg1 = self.sbb1 - a * (2.0 * self.sb - b(0) - b(n - 1)) + (nf - 1.0) * a * a;
        // t_{j+1} = t_j + 1; t_0 = −tl, t_{n−1} = tl.
        let tl = (nf - 1.0) / 2.0;
        let cross = (self.stb - tl * gl + sg - gl) + (self.stb + tl * g0 - sg + g0);
        let num = sgg1 - slope * cross + slope * slope * (stt - tl * (tl + 1.0));
        let den = self.sbb - self.sb * a - self.stb * slope;
        if den > 0.0 {
            num / den
        } else {
            0.0
        }
    }
}

/// Lag-1 autocorrelations of the 1st … `d_max`-th differences (`d_max` ≤ 3) of the
/// detrended averages over `m` samples, in one pass over the phase (the slope drops out of
/// every difference once it is centred). Entry k is for the (k+1)-th difference.
pub fn lag1_differences(x: &[f64], m: usize, d_max: u32) -> [f64; 3] {
    let n = averages(x.len(), m);
    let d_max = (d_max as usize).min(3);
    let inv = 1.0 / m as f64;
    let (mut sd, mut sdd, mut sdd1) = ([0.0f64; 3], [0.0f64; 3], [0.0f64; 3]);
    let mut b = [0.0f64; CHUNK + 4];
    let mut dk = [[0.0f64; CHUNK + 3]; 3];
    let mut j = 0;
    while j < n {
        let own = CHUNK.min(n - j);
        let len = (own + 4).min(n - j);
        fill_means(x, m, inv, j, &mut b[..len]);
        for k in 0..d_max {
            // Δ^{k+1} at j .. j + l, from Δ^k (b itself for k = 0).
            let l = len.saturating_sub(k + 1);
            let (done, rest) = dk.split_at_mut(k);
            let prev: &[f64] = if k == 0 {
                &b[..len]
            } else {
                &done[k - 1][..l + 1]
            };
            let out = &mut rest[0][..l];
            for (o, w) in out.iter_mut().zip(prev.windows(2)) {
                *o = w[1] - w[0];
            }
            let (s, q, p) = moments(out, own.min(l), own.min(l.saturating_sub(1)));
            sd[k] += s;
            sdd[k] += q;
            sdd1[k] += p;
        }
        j += own;
    }
    let b = |j: usize| (x[(j + 1) * m] - x[j * m]) * inv;
    // The k-th difference of the averages at j.
    let diff = |k: usize, j: usize| -> f64 {
        let c: &[f64] = [&[-1.0, 1.0][..], &[1.0, -2.0, 1.0], &[-1.0, 3.0, -3.0, 1.0]][k - 1];
        c.iter().enumerate().map(|(i, c)| c * b(j + i)).sum()
    };
    let mut r = [0.0f64; 3];
    for k in 0..d_max {
        // Δ^{k+1} b has n − k − 1 terms; centred about its mean.
        let len = (n - k - 1) as f64;
        let mean = sd[k] / len;
        let (first, last) = (diff(k + 1, 0), diff(k + 1, n - k - 2));
        let den = sdd[k] - sd[k] * mean;
        let num = sdd1[k] - mean * (2.0 * sd[k] - first - last) + (len - 1.0) * mean * mean;
        r[k] = if den > 0.0 { num / den } else { 0.0 };
    }
    r
}

/// The same identification as [`acf_alpha`] (equal up to rounding) given the sums over all
/// the averages ([`AvgSums`]): the difference pass runs only if the detrended averages are
/// too correlated to decide. `None` with fewer than [`ACF_MIN_AVERAGES`] averages.
pub fn acf_alpha_from_sums(x: &[f64], m: usize, d_max: u32, sums: &AvgSums) -> Option<i32> {
    if averages(x.len(), m) < ACF_MIN_AVERAGES {
        return None;
    }
    let mut r1 = sums.lag1_detrended(x, m);
    let mut diffs = None;
    let mut d = 0u32;
    loop {
        let rho = r1 / (1.0 + r1);
        if rho < 0.25 || d >= d_max {
            return Some(-((2.0 * rho).round_ties_even() as i32) - 2 * d as i32);
        }
        let r = *diffs.get_or_insert_with(|| lag1_differences(x, m, d_max));
        r1 = r[d as usize];
        d += 1;
    }
}

/// [`acf_alpha`] computed in passes over the phase without materialising the averages.
pub fn acf_alpha_from_phase(x: &[f64], m: usize, d_max: u32) -> Option<i32> {
    let mut sums = AvgSums::default();
    sums.add(x, m, 0, usize::MAX);
    acf_alpha_from_sums(x, m, d_max, &sums)
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
    Some(match b1_mu(x, m)? {
        -2 => pm_alpha(m, rn()),
        mu => -mu - 1,
    })
}

/// The exponent μ of `σ² ∝ τ^μ` that Barnes' B1 ratio of the `m` averages points to
/// (−2 … 2; −2 means phase modulation, white or flicker, see [`pm_alpha`]).
/// `None` with fewer than [`B1_MIN_AVERAGES`] averages or a zero Allan variance.
pub fn b1_mu(x: &[f64], m: usize) -> Option<i32> {
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
    for w in mus.windows(2) {
        let bound = (b1_theory(n, w[0]) * b1_theory(n, w[1])).sqrt();
        if b1 < bound {
            return Some(w[0]);
        }
    }
    Some(2)
}

/// White (2) or flicker (1) PM at averaging factor `m` from the measured R(n) = MVAR/AVAR
/// (`None`: not measurable, taken as white PM, as at m = 1).
pub fn pm_alpha(m: usize, rn: Option<f64>) -> i32 {
    match rn {
        Some(r) if m > 1 => {
            let bound = (rn_theory(m as f64, 2) * rn_theory(m as f64, 1)).sqrt();
            if r < bound {
                2
            } else {
                1
            }
        }
        _ => 2,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_rng::rng;

    /// Phase of rate samples: offset + trend + white + random walk (weights vary per case).
    fn phase(n: usize, key: u32, offset: f64, trend: f64, walk: f64) -> Vec<f64> {
        let mut u = rng(key);
        let (mut acc, mut w) = (0.0, 0.0);
        let mut x = vec![0.0];
        for i in 0..n {
            w += walk * u();
            acc += offset + trend * i as f64 / n as f64 + u() + w;
            x.push(acc);
        }
        x
    }

    /// The straightforward way: materialise, detrend, difference, `lag1_acf`.
    fn direct(x: &[f64], m: usize) -> [f64; 4] {
        let mut z = block_means(x, m);
        detrend_linear(&mut z);
        let mut r = [0.0; 4];
        for v in r.iter_mut() {
            *v = lag1_acf(&z);
            z = z.windows(2).map(|w| w[1] - w[0]).collect();
        }
        r
    }

    #[test]
    fn chunk_kernel_matches_the_formula_on_random_data() {
        let mut u = rng(99);
        let b: Vec<f64> = (0..300).map(|_| 5.0 + u()).collect();
        for (own, pairs) in [(299usize, 299usize), (299, 298), (7, 7), (64, 63), (0, 0)] {
            let (t0, a0, s0) = (-120.5, 5.01, 0.003);
            let mut want = [0.0f64; 4];
            for k in 0..own {
                let t = t0 + k as f64;
                let v = b[k] - (a0 + s0 * t);
                want[0] += v;
                want[1] += v * v;
                want[3] += t * v;
                if k < pairs {
                    want[2] += v * (b[k + 1] - (a0 + s0 * (t + 1.0)));
                }
            }
            for got in [
                chunk_sums(&b, own, pairs, t0, a0, s0),
                chunk_sums_portable(&b, own, pairs, t0, a0, s0),
            ] {
                for k in 0..4 {
                    let scale = want[k].abs().max(1.0);
                    assert!(
                        (got[k] - want[k]).abs() < 1e-12 * scale * own.max(1) as f64,
                        "own={own} sum {k}: {} vs {}",
                        got[k],
                        want[k]
                    );
                }
            }
        }
    }

    #[test]
    fn lag1_sums_match_the_direct_detrended_differenced_series() {
        let cases = [
            (0.0, 0.0, 0.0),
            (3.0, 0.0, 0.0),
            (0.5, 40.0, 0.0),
            (0.0, 0.0, 0.05),
            (-2.0, 5.0, 0.3),
        ];
        for (c, &(offset, trend, walk)) in cases.iter().enumerate() {
            let x = phase(20_000 + 37 * c, 7 + c as u32, offset, trend, walk);
            for m in [1usize, 2, 3, 7, 64, 600] {
                let want = direct(&x, m);
                let mut sums = AvgSums::default();
                // Split unevenly: the sums are additive over ranges of averages.
                let n = averages(x.len(), m);
                for (j0, j1) in [(0, n / 3), (n / 3, n / 3 + 1), (n / 3 + 1, usize::MAX)] {
                    sums.add(&x, m, j0, j1);
                }
                let mut got = [0.0; 4];
                got[0] = sums.lag1_detrended(&x, m);
                got[1..].copy_from_slice(&lag1_differences(&x, m, 3));
                for k in 0..4 {
                    assert!(
                        (got[k] - want[k]).abs() < 1e-9,
                        "case {c} m={m} d={k}: {} vs {}",
                        got[k],
                        want[k]
                    );
                }
                for d_max in [2, 3] {
                    assert_eq!(
                        acf_alpha_from_phase(&x, m, d_max),
                        acf_alpha(&x, m, d_max),
                        "case {c} m={m}"
                    );
                }
            }
        }
    }

    #[test]
    fn differences_of_a_last_chunk_shorter_than_their_order_add_nothing() {
        // n averages with n mod CHUNK ≤ 3 leave the third (and second) differences no term in
        // the last chunk; each r must still equal the formula on the whole series.
        let mut r = crate::test_rng::rng(0x5eed_1234);
        for extra in 1..=3usize {
            let m = 2;
            let n = CHUNK + extra;
            let mut x = vec![0.0f64];
            for _ in 0..n * m {
                let last = *x.last().unwrap();
                x.push(last + r());
            }
            let got = lag1_differences(&x, m, 3);
            let b: Vec<f64> = (0..n)
                .map(|j| (x[(j + 1) * m] - x[j * m]) / m as f64)
                .collect();
            let mut d = b.clone();
            for (k, g) in got.iter().enumerate() {
                d = d.windows(2).map(|w| w[1] - w[0]).collect();
                let mean = d.iter().sum::<f64>() / d.len() as f64;
                let c: Vec<f64> = d.iter().map(|v| v - mean).collect();
                let num: f64 = c.windows(2).map(|w| w[0] * w[1]).sum();
                let den: f64 = c.iter().map(|v| v * v).sum();
                assert!(
                    (g - num / den).abs() < 1e-9,
                    "extra {extra} order {}: {g} vs {}",
                    k + 1,
                    num / den
                );
            }
        }
    }
}
