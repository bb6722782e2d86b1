//! The covariance matrix of overlapping Allan variance estimates at several τ, for a given noise
//! model.
//!
//! The estimate at m samples is σ̂²(m) = Σ_i Δ_i² / (2 m² M), Δ_i = P(i+2m) − 2P(i+m) + P(i) over
//! the partial sums P of the rate, M = L − 2m + 1 differences in a segment of L samples (summed
//! over segments). For a Gaussian process Cov(Δ_i², Δ'_j²) = 2 c(j − i)², with
//! c(d) = Cov(Δ_i, Δ'_{i+d}) = −½ Σ_a Σ_b w_a w_b V(|d + b − a|), w = (1, −2, 1) at offsets
//! (0, m, 2m) and (0, m', 2m') (see [`crate::structure`]); so
//!
//! Cov(σ̂²(m), σ̂²(m')) = Σ_d n(d) [2 c(d)² + 4 c(d) g(d)] / (4 m² m'² M M'),
//!
//! n(d) the number of index pairs at lag d. g(d) is the product of the deterministic parts of the
//! two differences (a ramp makes every Δ the same, so g = μ μ'; a random-phase sinusoid has its
//! own structure function): deterministic signals add no variance of their own, only the cross
//! term with the noise. Deterministic effects other than the ramp and the sinusoid (a bias step,
//! a temperature-driven bias) are represented by a coherent mean of the same mean square, an
//! approximation that is conservative where they dominate. This is the sampled-data, finite-record
//! form of the asymptotic Haar wavelet-variance covariance used by GMWM (Guerrier et al., JASA
//! 2013; Percival & Walden, *Wavelet Methods*, §8.3), exact for Gaussian noise; segments separated
//! by gaps are treated as independent.
//!
//! The lag sum runs over up to ~10⁸ lags at the longest τ of a day-long 1 kHz record. Near the
//! points where c(d) is not smooth (d = b − a, the ends of n(d)) it is summed term by term; in
//! between, where c is a smooth function of d (a polynomial for the power-law terms), it is
//! integrated by Gauss–Legendre quadrature on geometrically growing panels, the sum over integers
//! being the integral over half-integer-extended intervals (midpoint rule, error O(f'') per lag).
use crate::diff_profile::DiffProfile;
use crate::structure::Structure;
use nalgebra::DMatrix;

/// One stochastic component: c · V(k).
#[derive(Debug, Clone)]
pub struct Component {
    pub coef: f64,
    pub structure: Structure,
}

/// The deterministic part of a model, per τ point: `mean_diff[j]` is the coherent mean of Δ at
/// point j (in partial-sum units) and `sines` the sinusoids (amplitude² [u²], θ = 2πf·τ0).
#[derive(Debug, Clone, Default)]
pub struct Deterministic {
    pub mean_diff: Vec<f64>,
    pub sines: Vec<(f64, f64)>,
}

/// The sampling design: averaging factors of the points and segment lengths (samples).
#[derive(Debug, Clone)]
pub struct Design {
    pub ms: Vec<u64>,
    pub segments: Vec<u64>,
}

impl Design {
    /// Number of differences M at averaging factor m, over all segments.
    pub fn terms(&self, m: u64) -> u64 {
        self.segments
            .iter()
            .map(|&l| (l + 1).saturating_sub(2 * m))
            .sum()
    }
}

const GL8: [(f64, f64); 8] = [
    (-0.960_289_856_497_536_3, 0.101_228_536_290_376_26),
    (-0.796_666_477_413_626_7, 0.222_381_034_453_374_47),
    (-0.525_532_409_916_329, 0.313_706_645_877_887_3),
    (-0.183_434_642_495_649_8, 0.362_683_783_378_362),
    (0.183_434_642_495_649_8, 0.362_683_783_378_362),
    (0.525_532_409_916_329, 0.313_706_645_877_887_3),
    (0.796_666_477_413_626_7, 0.222_381_034_453_374_47),
    (0.960_289_856_497_536_3, 0.101_228_536_290_376_26),
];

/// Adds w·f(x) (a vector) into `acc`.
fn add_scaled(acc: &mut [f64], w: f64, v: &[f64]) {
    for (a, b) in acc.iter_mut().zip(v) {
        *a += w * b;
    }
}

/// Growth factor of the quadrature panels away from a kink. Between kinks the power-law terms
/// make n(d)·c(d)² a polynomial of degree ≤ 7, which 8-point Gauss–Legendre integrates exactly on
/// any panel; the panels only need to resolve the exponential and logarithmic terms (Markov,
/// flicker) near the kinks. Checked against a 1.5× growth in the tests.
const GROWTH: f64 = 4.0;

/// Integral of f over [a, b] on panels of width h, h·g, h·g², … (at most `max_width`) growing
/// from both ends, added into `acc`; `buf` is scratch of the same length.
#[allow(clippy::too_many_arguments)]
fn panels_with(
    a: f64,
    b: f64,
    h: f64,
    growth: f64,
    max_width: f64,
    f: &mut dyn FnMut(f64, &mut [f64]),
    acc: &mut [f64],
    buf: &mut [f64],
) {
    let mut gl = |x0: f64, x1: f64, acc: &mut [f64], buf: &mut [f64]| {
        let (c, r) = ((x0 + x1) / 2.0, (x1 - x0) / 2.0);
        for &(x, w) in GL8.iter() {
            f(c + r * x, buf);
            add_scaled(acc, w * r, buf);
        }
    };
    let (mut lo, mut hi, mut w) = (a, b, h);
    while hi - lo > 2.0 * w {
        gl(lo, lo + w, acc, buf);
        gl(hi - w, hi, acc, buf);
        lo += w;
        hi -= w;
        w = (w * growth).min(max_width);
    }
    if hi > lo {
        gl(lo, hi, acc, buf);
    }
}

/// Σ_{d=lo}^{hi} f(d) (vector-valued, added into `acc`) with f smooth except near the `kinks`:
/// term by term within `width` of a kink and of the ends, by quadrature elsewhere, on panels no
/// wider than `max_panel` (an f that oscillates needs a few nodes per period).
fn lag_sum(
    lo: i64,
    hi: i64,
    kinks: &mut Vec<i64>,
    width: i64,
    max_panel: f64,
    f: &mut dyn FnMut(f64, &mut [f64]),
    acc: &mut [f64],
) {
    if hi < lo {
        return;
    }
    let mut buf = vec![0.0; acc.len()];
    let direct =
        |a: i64, b: i64, acc: &mut [f64], buf: &mut [f64], f: &mut dyn FnMut(f64, &mut [f64])| {
            for d in a..=b {
                f(d as f64, buf);
                add_scaled(acc, 1.0, buf);
            }
        };
    if hi - lo <= 4 * width + 64 {
        direct(lo, hi, acc, &mut buf, f);
        return;
    }
    kinks.push(lo);
    kinks.push(hi);
    kinks.retain(|&k| k >= lo && k <= hi);
    kinks.sort_unstable();
    kinks.dedup();
    // merged windows [k − width, k + width] around every kink
    let mut windows: Vec<(i64, i64)> = Vec::new();
    for &k in kinks.iter() {
        let (a, b) = ((k - width).max(lo), (k + width).min(hi));
        match windows.last_mut() {
            Some(last) if a <= last.1 + 1 => last.1 = last.1.max(b),
            _ => windows.push((a, b)),
        }
    }
    let mut prev_end: Option<i64> = None;
    for &(a, b) in &windows {
        direct(a, b, acc, &mut buf, f);
        if let Some(e) = prev_end {
            if a > e + 1 {
                panels_with(
                    e as f64 + 0.5,
                    a as f64 - 0.5,
                    width.max(8) as f64,
                    GROWTH,
                    max_panel,
                    f,
                    acc,
                    &mut buf,
                );
            }
        }
        prev_end = Some(b);
    }
}

const W: [f64; 3] = [1.0, -2.0, 1.0];

/// c(d) = −½ Σ_a Σ_b w_a w_b V(|d + b − a|) for one structure.
pub fn second_diff_cov(s: &Structure, m1: f64, m2: f64, d: f64) -> f64 {
    let mut acc = 0.0;
    for (ia, wa) in W.iter().enumerate() {
        let a = ia as f64 * m1;
        for (ib, wb) in W.iter().enumerate() {
            let b = ib as f64 * m2;
            acc += wa * wb * s.v(d + b - a);
        }
    }
    -0.5 * acc
}

/// V(k) of a unit-amplitude random-phase sinusoid, θ = 2πfτ0: ½·sin²(kθ/2)/sin²(θ/2).
fn sine_v(theta: f64, k: f64) -> f64 {
    let s = (theta / 2.0).sin();
    if s.abs() < 1e-300 {
        return 0.5 * k * k;
    }
    0.5 * (k * theta / 2.0).sin().powi(2) / (s * s)
}

fn sine_cov(theta: f64, m1: f64, m2: f64, d: f64) -> f64 {
    let mut acc = 0.0;
    for (ia, wa) in W.iter().enumerate() {
        for (ib, wb) in W.iter().enumerate() {
            acc += wa * wb * sine_v(theta, d + ib as f64 * m2 - ia as f64 * m1);
        }
    }
    -0.5 * acc
}

/// Σ over segments and lags of n(d)·f(d) for the pair of points (j, k) (vector-valued, into
/// `acc`), divided by the normalisation 4m²m'²MM'. `reach` bounds |d| where f may be non-zero;
/// `width` is the window summed term by term around each kink.
fn pair_sum(
    design: &Design,
    j: usize,
    k: usize,
    reach: f64,
    width: i64,
    f: &mut dyn FnMut(f64, &mut [f64]),
    acc: &mut [f64],
) {
    let (mj, mk) = (design.ms[j], design.ms[k]);
    let (tj, tk) = (design.terms(mj), design.terms(mk));
    if tj == 0 || tk == 0 {
        return;
    }
    let (m1, m2) = (mj as f64, mk as f64);
    let reach = reach.min(1e15) as i64 + 1;
    let (i1, i2) = (mj as i64, mk as i64);
    let mut sum = vec![0.0; acc.len()];
    for &len in &design.segments {
        let mm1 = (len + 1).saturating_sub(2 * mj) as i64;
        let mm2 = (len + 1).saturating_sub(2 * mk) as i64;
        if mm1 == 0 || mm2 == 0 {
            continue;
        }
        // n(d) = #{i ∈ [0, M1), i + d ∈ [0, M2)}
        let count = |d: f64| -> f64 { ((mm1 as f64).min(mm2 as f64 - d) - (-d).max(0.0)).max(0.0) };
        let mut kinks: Vec<i64> = Vec::with_capacity(12);
        for a in [0, i1, 2 * i1] {
            for b in [0, i2, 2 * i2] {
                kinks.push(a - b);
            }
        }
        kinks.push(0);
        kinks.push(mm2 - mm1);
        let lo = (-(mm1 - 1)).max(-reach);
        let hi = (mm2 - 1).min(reach);
        lag_sum(
            lo,
            hi,
            &mut kinks,
            width,
            f64::INFINITY,
            &mut |d, out: &mut [f64]| {
                f(d, out);
                let c = count(d);
                for v in out.iter_mut() {
                    *v *= c;
                }
            },
            &mut sum,
        );
    }
    add_scaled(
        acc,
        1.0 / (4.0 * m1 * m1 * m2 * m2 * tj as f64 * tk as f64),
        &sum,
    );
}

type Key = (u8, u64);

/// The covariance of the Allan estimates is quadratic in the stochastic coefficients and linear
/// in the deterministic parts: Cov = Σ_a Σ_b c_a c_b G^{ab} + Σ_a c_a (μμᵀ ∘ H^a + Σ_s A_s² S^{a,s}),
/// with G^{ab} = Σ_d n(d)·2c_a(d)c_b(d)/norm for unit structures a, b. The cache keeps G, H and S
/// per structure pair of one design, so refits with new coefficients (the fit's outer
/// iterations, the lab's candidates) cost a quadratic form, not a lag sum.
pub struct CovCache {
    design: Design,
    g: std::sync::Mutex<std::collections::HashMap<(Key, Key), DMatrix<f64>>>,
    h: std::sync::Mutex<std::collections::HashMap<Key, DMatrix<f64>>>,
    s: std::sync::Mutex<std::collections::HashMap<(Key, u64), DMatrix<f64>>>,
}

impl std::fmt::Debug for CovCache {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "CovCache({:?})", self.design)
    }
}

impl CovCache {
    pub fn new(design: Design) -> CovCache {
        CovCache {
            design,
            g: Default::default(),
            h: Default::default(),
            s: Default::default(),
        }
    }

    pub fn design(&self) -> &Design {
        &self.design
    }

    /// Compute every missing piece for the structures `st` (and the sines) in one pass over the
    /// point pairs and lags.
    fn fill(&self, st: &[&Structure], need_h: bool, sines: &[f64]) {
        // missing pieces: G pairs (structure, structure), H (structure), S (structure, sine)
        let mut gm: Vec<(usize, usize)> = Vec::new();
        let mut hm: Vec<usize> = Vec::new();
        let mut sm: Vec<(usize, usize)> = Vec::new();
        {
            let g = self.g.lock().expect("cache");
            let h = self.h.lock().expect("cache");
            let s = self.s.lock().expect("cache");
            for a in 0..st.len() {
                for b in a..st.len() {
                    if !g.contains_key(&pair_key(st[a], st[b]))
                        && !gm
                            .iter()
                            .any(|&(x, y)| pair_key(st[x], st[y]) == pair_key(st[a], st[b]))
                    {
                        gm.push((a, b));
                    }
                }
                if need_h
                    && !h.contains_key(&st[a].key())
                    && !hm.iter().any(|&x| st[x].key() == st[a].key())
                {
                    hm.push(a);
                }
                for (si, th) in sines.iter().enumerate() {
                    if !s.contains_key(&(st[a].key(), th.to_bits())) {
                        sm.push((a, si));
                    }
                }
            }
        }
        if gm.is_empty() && hm.is_empty() && sm.is_empty() {
            return;
        }
        // evaluate only the structures the missing pieces involve
        let mut used = vec![false; st.len()];
        for &(a, b) in &gm {
            used[a] = true;
            used[b] = true;
        }
        for &a in &hm {
            used[a] = true;
        }
        for &(a, _) in &sm {
            used[a] = true;
        }
        let n = self.design.ms.len();
        let q = gm.len() + hm.len() + sm.len();
        let mut out = vec![DMatrix::<f64>::zeros(n, n); q];
        let fl = st
            .iter()
            .zip(&used)
            .any(|(a, &u)| u && matches!(a, Structure::Flicker));
        let mem = st
            .iter()
            .zip(&used)
            .filter(|p| *p.1)
            .map(|(a, _)| a.memory())
            .fold(0.0, f64::max);
        // exponentials and flicker tails are smooth at the panel scale; only the kinks need terms
        let width = 32;
        let mut acc = vec![0.0; q];
        let mut cv = vec![0.0; st.len()];
        let mut sv = vec![0.0; sines.len()];
        for j in 0..n {
            for k in j..n {
                let (m1, m2) = (self.design.ms[j] as f64, self.design.ms[k] as f64);
                let reach = 2.0 * (m1 + m2) + if fl { 16.0 * m1.max(m2) } else { 0.0 } + mem;
                acc.iter_mut().for_each(|v| *v = 0.0);
                pair_sum(
                    &self.design,
                    j,
                    k,
                    reach,
                    width,
                    &mut |d, o: &mut [f64]| {
                        for ((c, a), &u) in cv.iter_mut().zip(st).zip(&used) {
                            if u {
                                *c = second_diff_cov(a, m1, m2, d);
                            }
                        }
                        for (v, th) in sv.iter_mut().zip(sines) {
                            *v = sine_cov(*th, m1, m2, d);
                        }
                        let mut i = 0;
                        for &(a, b) in &gm {
                            o[i] = 2.0 * cv[a] * cv[b];
                            i += 1;
                        }
                        for &a in &hm {
                            o[i] = 4.0 * cv[a];
                            i += 1;
                        }
                        for &(a, si) in &sm {
                            o[i] = 4.0 * cv[a] * sv[si];
                            i += 1;
                        }
                    },
                    &mut acc,
                );
                for (m, v) in out.iter_mut().zip(&acc) {
                    m[(j, k)] = *v;
                    m[(k, j)] = *v;
                }
            }
        }
        let mut it = out.into_iter();
        let mut g = self.g.lock().expect("cache");
        for &(a, b) in &gm {
            g.insert(pair_key(st[a], st[b]), it.next().expect("piece"));
        }
        let mut h = self.h.lock().expect("cache");
        for &a in &hm {
            h.insert(st[a].key(), it.next().expect("piece"));
        }
        let mut s = self.s.lock().expect("cache");
        for &(a, si) in &sm {
            s.insert(
                (st[a].key(), sines[si].to_bits()),
                it.next().expect("piece"),
            );
        }
    }

    /// Covariance of the overlapping Allan variance estimates at the design's points under the
    /// model (`stochastic` + `det`). Entries in u⁴.
    pub fn covariance(&self, stochastic: &[Component], det: &Deterministic) -> DMatrix<f64> {
        let n = self.design.ms.len();
        let comps: Vec<&Component> = stochastic.iter().filter(|c| c.coef > 0.0).collect();
        let st: Vec<&Structure> = comps.iter().map(|c| &c.structure).collect();
        let need_h = det.mean_diff.iter().any(|&m| m != 0.0);
        let thetas: Vec<f64> = det.sines.iter().map(|s| s.1).collect();
        self.fill(&st, need_h, &thetas);
        let g = self.g.lock().expect("cache");
        let h = self.h.lock().expect("cache");
        let s = self.s.lock().expect("cache");
        let mut cov = DMatrix::<f64>::zeros(n, n);
        for (ia, a) in comps.iter().enumerate() {
            for (ib, b) in comps.iter().enumerate().skip(ia) {
                let w = if ia == ib { 1.0 } else { 2.0 };
                cov += &g[&pair_key(&a.structure, &b.structure)] * (w * a.coef * b.coef);
            }
            if need_h {
                let hm = &h[&a.structure.key()];
                for j in 0..n {
                    for k in 0..n {
                        cov[(j, k)] += a.coef * hm[(j, k)] * det.mean_diff[j] * det.mean_diff[k];
                    }
                }
            }
            for &(a2, th) in &det.sines {
                cov += &s[&(a.structure.key(), th.to_bits())] * (a.coef * a2);
            }
        }
        cov
    }
}

/// The shape of a deterministic signal localised in time, as its Allan differences see it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SignalShape {
    /// A bias step: at averaging factor m its differences are a triangle 2m samples wide, whose
    /// autocorrelation is the cubic B-spline m³·B₃(d/m).
    Step,
    /// An exponential e^{−k/κ} from the record's start (a warm-up), κ in samples: its
    /// differences at any m are the same exponential, autocorrelation ∝ e^{−|d|/κ}.
    Exponential { kappa: f64 },
}

/// The model noise's covariance of the Allan differences at averaging factor m and lag d
/// (partial-sum units): [`second_diff_cov`] of every component.
fn noise_diff_cov(comps: &[Component], m: f64, d: f64) -> f64 {
    comps
        .iter()
        .map(|k| k.coef * second_diff_cov(&k.structure, m, m, d))
        .sum()
}

/// Σ_{|d| ≤ hi} c_m(d)·w_k(d) for each weight k that `w` writes (w even in d, kinks of c at 0, m
/// and 2m): the lag sums the localised signals' covariance needs.
fn weighted_lag_sums(
    comps: &[Component],
    m: f64,
    hi: f64,
    max_panel: f64,
    n: usize,
    w: &dyn Fn(f64, &mut [f64]),
) -> Vec<f64> {
    let mut at0 = vec![0.0; n];
    w(0.0, &mut at0);
    let c0 = noise_diff_cov(comps, m, 0.0);
    let mut half = vec![0.0; n];
    let mi = m.round() as i64;
    let mut kinks = vec![mi, 2 * mi];
    let mut f = |d: f64, out: &mut [f64]| {
        w(d, out);
        let cd = noise_diff_cov(comps, m, d);
        out.iter_mut().for_each(|o| *o *= cd);
    };
    lag_sum(
        1,
        hi.floor().max(0.0) as i64,
        &mut kinks,
        32,
        max_panel,
        &mut f,
        &mut half,
    );
    at0.iter()
        .zip(&half)
        .map(|(w0, h)| c0 * w0 + 2.0 * h)
        .collect()
}

/// Σ_d c_m(d)·cos(ωd) over every lag up to `span` samples, for each ω of `omegas` [rad/sample]:
/// the noise's covariance of the Allan differences seen by a cosine (the Allan-filtered noise
/// spectrum at ω, over the record). A drift's differences are a constant (its ramp, ω = 0) and
/// cosines of the record's length, orthogonal over the record, so Var(Σ D_i N_i) is the sum of
/// these, each weighted by its share of Σ D_i². The quadrature's panels are at most a quarter
/// of the fastest period.
pub fn cosine_noise_sums(comps: &[Component], m: f64, omegas: &[f64], span: f64) -> Vec<f64> {
    let w = |d: f64, out: &mut [f64]| {
        for (o, om) in out.iter_mut().zip(omegas) {
            *o = (om * d).cos();
        }
    };
    // a quarter of the fastest period per panel (8 nodes)
    let fastest = omegas.iter().fold(0.0f64, |a, w| a.max(w.abs()));
    let max_panel = if fastest > 0.0 {
        (0.5 * std::f64::consts::PI / fastest).max(8.0)
    } else {
        f64::INFINITY
    };
    weighted_lag_sums(comps, m, span, max_panel, omegas.len(), &w)
}

/// Σ_d c_m(d)·ρ(d): the noise's covariance of the Allan differences at averaging factor m
/// (partial-sum units, [`second_diff_cov`] of every component) weighted by the normalised
/// autocorrelation ρ of a localised signal's differences (ρ(0) = 1), summed over every lag up to
/// `span` samples. With D_i the signal's differences and N_i the noise's,
/// Var(Σ D_i N_i) = Σ_d c(d)·R_D(d) = Σ D_i² · (this sum), exact for a step or an exponential in
/// the record's interior; white noise of q per sample gives q·m² for a step (the Allan filter's
/// gain seen by a triangle) and less for a slow exponential, red noise more.
pub fn signal_noise_sum(comps: &[Component], m: f64, shape: SignalShape, span: f64) -> f64 {
    match shape {
        SignalShape::Step if m <= 64.0 => {
            // short triangles exactly: tri(u) = min(u, 2m − u), u = 0…2m
            let mi = m.round().max(1.0) as usize;
            let tri: Vec<f64> = (0..=2 * mi).map(|u| u.min(2 * mi - u) as f64).collect();
            let r = |d: usize| -> f64 { tri.iter().zip(&tri[d..]).map(|(a, b)| a * b).sum() };
            let r0 = r(0);
            noise_diff_cov(comps, m, 0.0)
                + 2.0
                    * (1..=2 * mi)
                        .map(|d| noise_diff_cov(comps, m, d as f64) * r(d) / r0)
                        .sum::<f64>()
        }
        SignalShape::Step => {
            let w = |d: f64, out: &mut [f64]| out[0] = crate::structure::bspline3(d / m) * 1.5;
            weighted_lag_sums(comps, m, 2.0 * m, f64::INFINITY, 1, &w)[0]
        }
        SignalShape::Exponential { kappa } if kappa > 0.0 && kappa.is_finite() => {
            let w = |d: f64, out: &mut [f64]| out[0] = (-d / kappa).exp();
            weighted_lag_sums(comps, m, (50.0 * kappa).min(span), f64::INFINITY, 1, &w)[0]
        }
        SignalShape::Exponential { .. } => f64::NAN,
    }
}

/// Σ_d c_m(d)·ρ(d) as [`signal_noise_sum`] does, for a signal whose differences' autocorrelation
/// was measured on the record ([`crate::diff_profile`]): a bias following a column such as the
/// temperature. Lags up to the profile's span; at a stride of one lag the sum is term by term,
/// otherwise by quadrature on panels up to m/2 wide (the differences' autocorrelation is smooth
/// on the scale of m; wider panels miss the test against lag-by-lag sums).
pub fn profile_noise_sum(comps: &[Component], m: f64, profile: &DiffProfile) -> f64 {
    let span = profile.span();
    if !(span.is_finite() && profile.stride > 0.0) {
        return f64::NAN;
    }
    if profile.stride <= 1.0 && span <= 4096.0 {
        let hi = span.floor() as i64;
        return noise_diff_cov(comps, m, 0.0)
            + 2.0
                * (1..=hi)
                    .map(|d| noise_diff_cov(comps, m, d as f64) * profile.at(d as f64))
                    .sum::<f64>();
    }
    let w = |d: f64, out: &mut [f64]| out[0] = profile.at(d);
    weighted_lag_sums(
        comps,
        m,
        span,
        (0.5 * m).max(profile.stride).max(8.0),
        1,
        &w,
    )[0]
}

fn pair_key(a: &Structure, b: &Structure) -> (Key, Key) {
    if a.key() <= b.key() {
        (a.key(), b.key())
    } else {
        (b.key(), a.key())
    }
}

/// Covariance of the overlapping Allan variance estimates at the design's points under the model
/// (`stochastic` + `det`), without a cache. Entries in u⁴.
pub fn allan_covariance(
    design: &Design,
    stochastic: &[Component],
    det: &Deterministic,
) -> DMatrix<f64> {
    CovCache::new(design.clone()).covariance(stochastic, det)
}

/// The correlation factor of a covariance matrix: its standard deviations and the lower Cholesky
/// factor L of its correlation ρ = LLᵀ (a jitter of up to 1e-2 on the diagonal where ρ is not
/// numerically positive definite; None when even that fails, or when an entry of the covariance
/// is not finite: a NaN must never reach a whitened residual, where it would make χ² NaN).
pub fn correlation_factor(cov: &DMatrix<f64>) -> (Vec<f64>, Option<DMatrix<f64>>) {
    let n = cov.nrows();
    let s: Vec<f64> = (0..n).map(|j| cov[(j, j)].max(1e-300).sqrt()).collect();
    if cov.iter().any(|v| !v.is_finite()) {
        return (s, None);
    }
    let rho = DMatrix::from_fn(n, n, |a, b| {
        if a == b {
            1.0
        } else {
            (cov[(a, b)] / (s[a] * s[b])).clamp(-1.0, 1.0)
        }
    });
    let l = [0.0, 1e-10, 1e-8, 1e-6, 1e-4, 1e-2]
        .iter()
        .find_map(|j| (&rho + DMatrix::identity(n, n) * *j).cholesky())
        .map(|c| c.l())
        .filter(|l| l.iter().all(|v| v.is_finite()) && (0..n).all(|j| l[(j, j)] > 0.0));
    (s, l)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Brute force: every pair of differences, same model.
    fn brute(design: &Design, comps: &[Component]) -> DMatrix<f64> {
        let n = design.ms.len();
        let mut out = DMatrix::zeros(n, n);
        for j in 0..n {
            for k in 0..n {
                let (m1, m2) = (design.ms[j], design.ms[k]);
                let mut s = 0.0;
                for &len in &design.segments {
                    let (a, b) = (
                        (len + 1) as i64 - 2 * m1 as i64,
                        (len + 1) as i64 - 2 * m2 as i64,
                    );
                    for i in 0..a.max(0) {
                        for jj in 0..b.max(0) {
                            let c: f64 = comps
                                .iter()
                                .map(|c| {
                                    c.coef
                                        * second_diff_cov(
                                            &c.structure,
                                            m1 as f64,
                                            m2 as f64,
                                            (jj - i) as f64,
                                        )
                                })
                                .sum();
                            s += 2.0 * c * c;
                        }
                    }
                }
                out[(j, k)] = s
                    / (4.0
                        * (m1 * m1 * m2 * m2) as f64
                        * design.terms(m1) as f64
                        * design.terms(m2) as f64);
            }
        }
        out
    }

    #[test]
    fn quadrature_matches_brute_force() {
        let design = Design {
            ms: vec![1, 2, 8, 64, 300],
            segments: vec![1500, 700],
        };
        let comps = vec![
            Component {
                coef: 1.0,
                structure: Structure::Linear,
            },
            Component {
                coef: 0.01,
                structure: Structure::Flicker,
            },
            Component {
                coef: 1e-4,
                structure: Structure::Cubic,
            },
            Component {
                coef: 0.5,
                structure: Structure::Ar1 { phi: 0.9 },
            },
        ];
        let q = allan_covariance(&design, &comps, &Deterministic::default());
        let b = brute(&design, &comps);
        for j in 0..5 {
            for k in 0..5 {
                let rel = (q[(j, k)] - b[(j, k)]).abs() / (b[(j, j)] * b[(k, k)]).sqrt();
                assert!(rel < 2e-3, "({j},{k}): {} vs {}", q[(j, k)], b[(j, k)]);
            }
        }
    }

    #[test]
    fn quadrature_converges_on_long_records() {
        // a day-long design with flicker, a slow and a fast Markov term: the panels' default
        // growth against a much finer one
        let design = Design {
            ms: vec![1, 64, 4096, 1 << 18, 1 << 22],
            segments: vec![1 << 24],
        };
        let comps = [
            Component {
                coef: 1.0,
                structure: Structure::Linear,
            },
            Component {
                coef: 1e-3,
                structure: Structure::Flicker,
            },
            Component {
                coef: 0.1,
                structure: Structure::Ar1 {
                    phi: (-1.0f64 / 3.0).exp(),
                },
            },
            Component {
                coef: 1e-2,
                structure: Structure::Ar1 {
                    phi: (-1.0f64 / 30_000.0).exp(),
                },
            },
        ];
        let n = design.ms.len();
        let fine = |j: usize, k: usize| {
            let (m1, m2) = (design.ms[j] as f64, design.ms[k] as f64);
            let mut out = [0.0];
            let (mj, mk) = (design.ms[j] as i64, design.ms[k] as i64);
            let len = design.segments[0] as i64;
            let (mm1, mm2) = (len + 1 - 2 * mj, len + 1 - 2 * mk);
            let count = |d: f64| ((mm1 as f64).min(mm2 as f64 - d) - (-d).max(0.0)).max(0.0);
            let mut f = |d: f64, o: &mut [f64]| {
                let c: f64 = comps
                    .iter()
                    .map(|c| c.coef * second_diff_cov(&c.structure, m1, m2, d))
                    .sum();
                o[0] = count(d) * 2.0 * c * c;
            };
            let mut buf = [0.0];
            // terms within 64 of 0, panels of growth 1.5 outward, to the reach
            let reach = (2.0 * (m1 + m2) + 16.0 * m1.max(m2) + 600_000.0).min(mm1.min(mm2) as f64);
            for d in -64..=64 {
                f(d as f64, &mut buf);
                out[0] += buf[0];
            }
            panels_with(
                64.5,
                reach,
                4.0,
                1.5,
                f64::INFINITY,
                &mut f,
                &mut out,
                &mut buf,
            );
            panels_with(
                -reach,
                -64.5,
                4.0,
                1.5,
                f64::INFINITY,
                &mut f,
                &mut out,
                &mut buf,
            );
            out[0]
                / (4.0
                    * m1
                    * m1
                    * m2
                    * m2
                    * design.terms(design.ms[j]) as f64
                    * design.terms(design.ms[k]) as f64)
        };
        let c = allan_covariance(&design, &comps, &Deterministic::default());
        for j in 0..n {
            for k in j..n {
                let f = fine(j, k);
                let rel = (c[(j, k)] - f).abs() / (c[(j, j)] * c[(k, k)]).sqrt();
                assert!(rel < 1e-3, "({j},{k}): {} vs fine {f}", c[(j, k)]);
            }
        }
    }

    #[test]
    fn white_noise_edf_matches_the_handbook() {
        // NIST SP 1065 §5.3 (Howe, Allan & Barnes), overlapping ADEV of white FM with N phase
        // points: edf = [3(N−1)/(2m) − 2(N−2)/N] · 4m²/(4m² + 5).
        for (n_samp, m) in [(1u64 << 16, 16u64), (1000, 3), (50_000, 64)] {
            let design = Design {
                ms: vec![m],
                segments: vec![n_samp],
            };
            let comps = vec![Component {
                coef: 1.0,
                structure: Structure::Linear,
            }];
            let c = allan_covariance(&design, &comps, &Deterministic::default());
            let mean = Structure::Linear.avar(m as f64);
            let edf = 2.0 * mean * mean / c[(0, 0)];
            let (nn, mm) = ((n_samp + 1) as f64, m as f64);
            let sp1065 = (3.0 * (nn - 1.0) / (2.0 * mm) - 2.0 * (nn - 2.0) / nn) * 4.0 * mm * mm
                / (4.0 * mm * mm + 5.0);
            assert!(
                (edf / sp1065 - 1.0).abs() < 1e-3,
                "N {n_samp} m {m}: {edf} vs {sp1065}"
            );
        }
    }

    /// The localised signals' lag sums against direct sums over every lag, on white, flicker and
    /// Markov noise at random levels: a step under white noise gives exactly the Allan filter's
    /// gain q·m²; an exponential and the cosines of a drift match Σ_d c(d)·ρ(d) summed lag by lag.
    #[test]
    fn signal_lag_sums_match_direct_sums() {
        let mut x = 0x51a1_5eedu64;
        let mut u = || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x >> 11) as f64 / (1u64 << 53) as f64
        };
        let q = 0.5 + u();
        let white = [Component {
            coef: q,
            structure: Structure::Linear,
        }];
        for m in [4.0, 16.0, 100.0, 1000.0] {
            let g = signal_noise_sum(&white, m, SignalShape::Step, 1e6) / (q * m * m);
            // 1 + O(1/m²) for the discrete triangle (1.034 at m = 4, summed exactly for
            // m ≤ 64); the B-spline's continuum form beyond
            assert!(
                (g - 1.0).abs() < (0.6 / (m * m)).max(1e-3),
                "m = {m}: gain {g}"
            );
        }
        let comps = [
            Component {
                coef: q,
                structure: Structure::Linear,
            },
            Component {
                coef: 0.1 + u(),
                structure: Structure::Flicker,
            },
            Component {
                coef: 0.1 + u(),
                structure: Structure::Ar1 {
                    phi: 0.5 + 0.49 * u(),
                },
            },
        ];
        let direct = |m: f64, hi: usize, rho: &dyn Fn(f64) -> f64| -> f64 {
            noise_diff_cov(&comps, m, 0.0)
                + 2.0
                    * (1..=hi)
                        .map(|d| noise_diff_cov(&comps, m, d as f64) * rho(d as f64))
                        .sum::<f64>()
        };
        for m in [8.0, 50.0, 300.0] {
            let kappa = m * (0.3 + 10.0 * u());
            let span = 20_000.0;
            let fast = signal_noise_sum(&comps, m, SignalShape::Exponential { kappa }, span);
            let hi = (50.0 * kappa).min(span) as usize;
            let slow = direct(m, hi, &|d| (-d / kappa).exp());
            let scale = noise_diff_cov(&comps, m, 0.0);
            assert!(
                (fast - slow).abs() < 1e-3 * scale,
                "m = {m}, κ = {kappa}: {fast} vs {slow}"
            );
            let j = 1.0 + (16.0 * u()).floor();
            let omegas = [
                0.0,
                std::f64::consts::PI * 3.0 / span,
                std::f64::consts::PI * j / span,
            ];
            let fast = cosine_noise_sums(&comps, m, &omegas, span);
            for (w, f) in omegas.iter().zip(&fast) {
                let slow = direct(m, span as usize, &|d| (w * d).cos());
                assert!(
                    (f - slow).abs() < 1e-3 * scale,
                    "m = {m}, ω = {w}: {f} vs {slow}"
                );
            }
        }
        // a profile measured on a column: a warming with reading noise, in two segments
        let n = 60_000usize;
        let tau = 3000.0 + 20_000.0 * u();
        let col: Vec<f64> = (0..n)
            .map(|i| -(-(i as f64) / tau).exp_m1() + 2e-4 * (u() - 0.5))
            .collect();
        let cut = (n as f64 * (0.3 + 0.4 * u())) as u64;
        for m in [2u64, 8, 64, 512, 2048] {
            let (_, p) = crate::diff_profile::allan_profile(&col, &[cut, n as u64 - cut], m)
                .expect("profile");
            let mf = m as f64;
            let fast = profile_noise_sum(&comps, mf, &p);
            let slow = direct(mf, p.span() as usize, &|d| p.at(d));
            let scale = noise_diff_cov(&comps, mf, 0.0);
            assert!(
                (fast - slow).abs() < 1e-3 * scale,
                "profile at m = {m}: {fast} vs {slow} (scale {scale})"
            );
        }
    }
}
