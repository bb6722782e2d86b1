//! Non-stationarity in the time domain: bias steps, a bias that follows the temperature, a
//! warm-up transient, a smooth drift, a ramp — estimated and tested on the record itself, where the Allan curve
//! alone cannot tell them from noise (a step of Δ in a record of length T has the Allan curve of
//! a rate random walk with K² ≈ Δ²/T).
//!
//! The record is reduced to block means of L samples; within each segment the differences of
//! neighbouring block means, z_b = ȳ_{b+1} − ȳ_b (non-overlapping Haar coefficients at scale L),
//! are stationary for every noise of the vocabulary (rate random walk included), with the
//! autocovariance γ(h) = c(hL)/L² that the noise model's structure function gives
//! ([`crate::cov::second_diff_cov`]). A deterministic signal maps linearly into z (a ramp R into
//! the constant R·L·τ0, a step into one or two block differences, the temperature column into the
//! differences of its block means), so its amplitudes are estimated by generalised least squares
//! on z with that covariance (whitened by the Durbin–Levinson recursion, per segment), with
//! standard errors and likelihood-ratio statistics that already account for the correlated noise.
//!
//! A step at an unknown instant is found by scanning: the likelihood ratio of an impulse at every
//! block difference, LR_i = (rᵀ w_i)²/‖w_i‖² with r and w_i whitened and projected off the other
//! regressors, at several scales L; the maximum is tested against χ²₁ with a Bonferroni factor for
//! the positions and scales searched, after calibrating the LRs by their median (0.455 for χ²₁),
//! so that a noise model that is off by a factor cannot manufacture a step. The instant is then
//! refined on finer blocks and, with the samples at hand, to the sample.
use crate::cov::{second_diff_cov, Component};
use allan::confidence::chi2_sf;
use nalgebra::{DMatrix, DVector};

/// Most blocks per scale in a GLS (the whitening is O(B²) in time and memory).
pub const MAX_BLOCKS: usize = 1024;
/// Family-wise false-alarm probability of the step scan.
pub const P_STEP: f64 = 1e-3;
/// Most steps found in one record.
pub const MAX_STEPS: usize = 4;

/// Block means of a record, per segment.
#[derive(Debug, Clone)]
pub struct Blocks {
    /// Samples per block.
    pub size: u64,
    pub tau0: f64,
    pub segments: Vec<SegBlocks>,
}

/// The blocks of one segment.
#[derive(Debug, Clone)]
pub struct SegBlocks {
    /// Index (as in [`crate::effect::Context::segments`]) of the first sample of the first block.
    pub start: u64,
    pub means: Vec<f64>,
    /// Block means of the temperature column.
    pub temp: Option<Vec<f64>>,
}

impl Blocks {
    /// Blocks of `size` samples of `y` (the segments' samples concatenated) and of `temp`.
    pub fn new(
        y: &[f64],
        temp: Option<&[f64]>,
        segments: &[(u64, u64)],
        size: u64,
        tau0: f64,
    ) -> Blocks {
        let size = size.max(1);
        let mut out = Vec::new();
        let mut off = 0usize;
        for &(start, len) in segments {
            let nb = (len / size) as usize;
            let mean = |x: &[f64], b: usize| {
                let a = off + b * size as usize;
                x[a..a + size as usize].iter().sum::<f64>() / size as f64
            };
            out.push(SegBlocks {
                start,
                means: (0..nb).map(|b| mean(y, b)).collect(),
                temp: temp.map(|t| (0..nb).map(|b| mean(t, b)).collect()),
            });
            off += len as usize;
        }
        Blocks {
            size,
            tau0,
            segments: out,
        }
    }

    /// The blocks aggregated by `factor` (partial groups at segment ends dropped).
    pub fn coarser(&self, factor: usize) -> Blocks {
        let agg = |v: &[f64]| -> Vec<f64> {
            v.chunks_exact(factor)
                .map(|c| c.iter().sum::<f64>() / factor as f64)
                .collect()
        };
        Blocks {
            size: self.size * factor as u64,
            tau0: self.tau0,
            segments: self
                .segments
                .iter()
                .map(|s| SegBlocks {
                    start: s.start,
                    means: agg(&s.means),
                    temp: s.temp.as_ref().map(|t| agg(t)),
                })
                .collect(),
        }
    }

    /// Number of block differences over all segments.
    pub fn diffs(&self) -> usize {
        self.segments
            .iter()
            .map(|s| s.means.len().saturating_sub(1))
            .sum()
    }

    /// Number of blocks in the longest segment.
    pub fn longest(&self) -> usize {
        self.segments
            .iter()
            .map(|s| s.means.len())
            .max()
            .unwrap_or(0)
    }
}

/// A deterministic signal whose amplitude is estimated.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Signal {
    /// y = R·t (per unit R [u/s]).
    Ramp,
    /// A unit step at sample index s (as counted in the context's segments).
    Step { at: f64 },
    /// The temperature column (per unit coefficient [u/°C]).
    Temperature,
    /// e^{−k/κ}, k the sample index from the record's start (per unit amplitude [u]).
    WarmUp { kappa: f64 },
    /// cos(πjk/T), k the sample index from the record's start and T the record's span in
    /// samples (per unit amplitude [u]): a component of a smooth drift.
    Cosine { j: u8, span: f64 },
}

impl Signal {
    /// Mean of the unit signal over samples [p, p + l).
    fn block_mean(&self, p: f64, l: f64, tau0: f64) -> f64 {
        match *self {
            Signal::Ramp => (p + (l - 1.0) / 2.0) * tau0,
            Signal::Step { at } => ((p + l - at) / l).clamp(0.0, 1.0),
            Signal::WarmUp { kappa } => {
                let e1 = -(-1.0 / kappa).exp_m1();
                let el = -(-l / kappa).exp_m1();
                (-p / kappa).exp() * el / (l * e1)
            }
            Signal::Cosine { j, span } => {
                // mean of cos(ωk) over k = p … p + l − 1
                let w = std::f64::consts::PI * j as f64 / span;
                let h = (w / 2.0).sin();
                let g = if h.abs() < 1e-300 {
                    1.0
                } else {
                    (l * w / 2.0).sin() / (l * h)
                };
                g * (w * (p + (l - 1.0) / 2.0)).cos()
            }
            Signal::Temperature => f64::NAN,
        }
    }

    /// The signal's differences z at the blocks' scale, concatenated over segments.
    pub fn column(&self, blocks: &Blocks) -> Vec<f64> {
        let l = blocks.size as f64;
        let mut out = Vec::with_capacity(blocks.diffs());
        for s in &blocks.segments {
            let means: Vec<f64> = match self {
                Signal::Temperature => match &s.temp {
                    Some(t) => t.clone(),
                    None => vec![0.0; s.means.len()],
                },
                _ => (0..s.means.len())
                    .map(|b| self.block_mean(s.start as f64 + b as f64 * l, l, blocks.tau0))
                    .collect(),
            };
            out.extend(means.windows(2).map(|w| w[1] - w[0]));
        }
        out
    }
}

/// The data's differences z at the blocks' scale, concatenated over segments.
pub fn data_column(blocks: &Blocks) -> Vec<f64> {
    blocks
        .segments
        .iter()
        .flat_map(|s| s.means.windows(2).map(|w| w[1] - w[0]).collect::<Vec<_>>())
        .collect()
}

/// γ(h) = Cov(z_b, z_{b+h}), h = 0..n, of the noise model at block length l.
pub fn noise_acov(comps: &[Component], l: f64, n: usize) -> Vec<f64> {
    (0..n)
        .map(|h| {
            comps
                .iter()
                .filter(|c| c.coef > 0.0)
                .map(|c| c.coef * second_diff_cov(&c.structure, l, l, h as f64 * l))
                .sum::<f64>()
                / (l * l)
        })
        .collect()
}

/// The lower-triangular whitening W (W Σ Wᵀ = I) of a stationary sequence of length n with
/// autocovariance γ, by the Durbin–Levinson recursion (Brockwell & Davis, *Time Series: Theory
/// and Methods*, §5.2). A non-positive prediction variance (a model that is not positive
/// definite at this scale) is floored at 1e-9·γ(0).
pub fn whitening(gamma: &[f64], n: usize) -> DMatrix<f64> {
    let mut w = DMatrix::<f64>::zeros(n, n);
    if n == 0 {
        return w;
    }
    let g0 = gamma[0].max(1e-300);
    let mut phi: Vec<f64> = Vec::with_capacity(n);
    let mut v = g0;
    w[(0, 0)] = 1.0 / v.sqrt();
    for t in 1..n {
        // order-t coefficients from order t−1
        let mut acc = gamma.get(t).copied().unwrap_or(0.0);
        for (k, p) in phi.iter().enumerate() {
            acc -= p * gamma.get(t - 1 - k).copied().unwrap_or(0.0);
        }
        let kappa = acc / v;
        let prev = phi.clone();
        for k in 0..prev.len() {
            phi[k] = prev[k] - kappa * prev[prev.len() - 1 - k];
        }
        phi.push(kappa);
        v = (v * (1.0 - kappa * kappa)).max(1e-9 * g0);
        // e_t = (x_t − Σ_k φ_k x_{t−1−k}) / √v
        let s = 1.0 / v.sqrt();
        w[(t, t)] = s;
        for (k, p) in phi.iter().enumerate() {
            w[(t, t - 1 - k)] = -p * s;
        }
    }
    w
}

/// A GLS problem at one scale: whitened data and the whitening per segment.
pub struct Gls {
    pub blocks: Blocks,
    /// Whitening matrices, one per segment (block-diagonal overall).
    pub w: Vec<DMatrix<f64>>,
    /// Whitened data.
    pub zw: DVector<f64>,
}

impl Gls {
    /// Set up at the scale of `blocks` with the noise components `comps`.
    pub fn new(blocks: Blocks, comps: &[Component]) -> Gls {
        let l = blocks.size as f64;
        let longest = blocks
            .segments
            .iter()
            .map(|s| s.means.len().saturating_sub(1))
            .max()
            .unwrap_or(0);
        let gamma = noise_acov(comps, l, longest);
        let w: Vec<DMatrix<f64>> = blocks
            .segments
            .iter()
            .map(|s| whitening(&gamma, s.means.len().saturating_sub(1)))
            .collect();
        let z = data_column(&blocks);
        let mut g = Gls {
            blocks,
            w,
            zw: DVector::zeros(0),
        };
        g.zw = g.apply(&z);
        g
    }

    /// Whiten a column (concatenated over segments).
    pub fn apply(&self, x: &[f64]) -> DVector<f64> {
        let mut out = Vec::with_capacity(x.len());
        let mut off = 0;
        for w in &self.w {
            let n = w.nrows();
            let v = DVector::from_column_slice(&x[off..off + n]);
            out.extend((w * v).iter());
            off += n;
        }
        DVector::from_vec(out)
    }

    /// Least squares of the whitened data on whitened `cols`: estimates, their covariance, and
    /// the residual sum of squares (χ² of the whitened residual).
    pub fn solve(&self, cols: &[DVector<f64>]) -> (Vec<f64>, DMatrix<f64>, f64) {
        let n = self.zw.len();
        if cols.is_empty() || n == 0 {
            return (Vec::new(), DMatrix::zeros(0, 0), self.zw.norm_squared());
        }
        let x = DMatrix::from_columns(cols);
        let xtx = x.transpose() * &x;
        let inv = xtx
            .clone()
            .try_inverse()
            .or_else(|| crate::nnls::pinv(&xtx))
            .unwrap_or_else(|| DMatrix::from_element(cols.len(), cols.len(), f64::NAN));
        let beta = &inv * (x.transpose() * &self.zw);
        let rss = (&self.zw - &x * &beta).norm_squared();
        (beta.iter().copied().collect(), inv, rss)
    }

    /// Scan for a step at every block difference given the regressors `cols`: (index of the
    /// difference, calibrated LR, calibration factor).
    pub fn scan(&self, cols: &[DVector<f64>]) -> Option<(usize, f64, f64)> {
        let n = self.zw.len();
        if n < 8 {
            return None;
        }
        // orthonormal basis of the whitened regressors
        let q = if cols.is_empty() {
            None
        } else {
            Some(DMatrix::from_columns(cols).qr().q())
        };
        let proj = |v: DVector<f64>| match &q {
            Some(q) => &v - q * (q.transpose() * &v),
            None => v,
        };
        let r = proj(self.zw.clone());
        let mut lrs = Vec::with_capacity(n);
        let mut off = 0;
        for w in &self.w {
            let ns = w.nrows();
            for i in 0..ns {
                let mut col = DVector::zeros(n);
                for t in i..ns {
                    col[off + t] = w[(t, i)];
                }
                let c = proj(col);
                let d = c.norm_squared();
                lrs.push(if d > 1e-12 {
                    r.dot(&c).powi(2) / d
                } else {
                    0.0
                });
            }
            off += ns;
        }
        let (i, &best) = lrs.iter().enumerate().max_by(|a, b| a.1.total_cmp(b.1))?;
        // Calibration: the whitened residual after the other regressors and the best step should
        // have unit variance when the noise model is right; a larger one (noise the model lacks)
        // scales every LR down, F-test fashion.
        let dof = n.saturating_sub(cols.len() + 1).max(1) as f64;
        let cal = ((r.norm_squared() - best) / dof).max(1.0);
        Some((i, best / cal, cal))
    }

    /// The (segment, block) whose upper boundary the difference `i` straddles: the step lies
    /// between blocks `b` and `b + 1` of segment `s`.
    pub fn locate(&self, i: usize) -> (usize, usize) {
        let mut off = 0;
        for (s, seg) in self.blocks.segments.iter().enumerate() {
            let ns = seg.means.len().saturating_sub(1);
            if i < off + ns {
                return (s, i - off);
            }
            off += ns;
        }
        (self.blocks.segments.len().saturating_sub(1), 0)
    }
}

/// −2 log-likelihood (up to a constant) of the block differences at the scale of `blocks` under
/// the noise components `comps`, the amplitudes of `signals` profiled out by GLS:
/// −2ℓ = r̃ᵀr̃ + ln det Σ, r̃ the whitened residual. Differences between noise models are
/// likelihood-ratio statistics in the time domain, which see the long-τ structure (a bounded,
/// mean-reverting Markov process against an unbounded random walk) far more sharply than the
/// few long-τ Allan points.
pub fn neg2_loglik(blocks: &Blocks, comps: &[Component], signals: &[Signal]) -> f64 {
    let g = Gls::new(blocks.clone(), comps);
    let cols: Vec<DVector<f64>> = signals
        .iter()
        .map(|s| g.apply(&s.column(&g.blocks)))
        .collect();
    let rss = g.solve(&cols).2;
    let ln_det: f64 =
        g.w.iter()
            .flat_map(|w| (0..w.nrows()).map(move |t| -2.0 * w[(t, t)].ln()))
            .sum();
    rss + ln_det
}

/// The likelihood ratios of `base` + the first k signals of `extra` against `base` alone, for
/// k = 1 … extra.len(), under the noise components `comps` (one whitening for all).
pub fn nested_lrs(
    blocks: &Blocks,
    comps: &[Component],
    base: &[Signal],
    extra: &[Signal],
) -> Vec<f64> {
    let g = Gls::new(blocks.clone(), comps);
    let col = |s: &Signal| g.apply(&s.column(&g.blocks));
    let mut cols: Vec<DVector<f64>> = base.iter().map(col).collect();
    let rss0 = g.solve(&cols).2;
    extra
        .iter()
        .map(|s| {
            cols.push(col(s));
            (rss0 - g.solve(&cols).2).max(0.0)
        })
        .collect()
}

/// One estimated deterministic term.
#[derive(Debug, Clone, PartialEq)]
pub struct Estimate {
    pub signal: Signal,
    /// Amplitude [u, u/s, u/°C].
    pub value: f64,
    pub sigma: f64,
    /// Likelihood ratio of the model with this signal against the model without it.
    pub lr: f64,
}

/// The choice of scale for a GLS: the finest block multiple with at most [`MAX_BLOCKS`] blocks
/// in the longest segment.
pub fn gls_scale(base: &Blocks) -> Blocks {
    let longest = base.longest();
    let mut f = 1;
    while longest / f > MAX_BLOCKS {
        f *= 2;
    }
    if f == 1 {
        base.clone()
    } else {
        base.coarser(f)
    }
}

/// The amplitudes of `signals` estimated jointly by GLS at the scale of `blocks`, with their
/// covariance matrix.
pub fn joint(blocks: &Blocks, comps: &[Component], signals: &[Signal]) -> (Vec<f64>, DMatrix<f64>) {
    let g = Gls::new(blocks.clone(), comps);
    let cols: Vec<DVector<f64>> = signals
        .iter()
        .map(|s| g.apply(&s.column(&g.blocks)))
        .collect();
    let (beta, cov, _) = g.solve(&cols);
    (beta, cov)
}

/// Estimate the amplitudes of `signals` jointly by GLS at the scale of `blocks`.
pub fn estimate(blocks: &Blocks, comps: &[Component], signals: &[Signal]) -> Vec<Estimate> {
    let g = Gls::new(blocks.clone(), comps);
    let cols: Vec<DVector<f64>> = signals
        .iter()
        .map(|s| g.apply(&s.column(&g.blocks)))
        .collect();
    let (beta, cov, rss) = g.solve(&cols);
    (0..signals.len())
        .map(|k| {
            let others: Vec<DVector<f64>> = cols
                .iter()
                .enumerate()
                .filter(|(j, _)| *j != k)
                .map(|(_, c)| c.clone())
                .collect();
            let rss0 = g.solve(&others).2;
            Estimate {
                signal: signals[k],
                value: beta[k],
                sigma: cov[(k, k)].max(0.0).sqrt(),
                lr: (rss0 - rss).max(0.0),
            }
        })
        .collect()
}

/// The samples (segments concatenated) with their segments, for refining instants to the sample.
pub type Samples<'a> = Option<(&'a [f64], &'a [(u64, u64)])>;

/// A step found by the scan.
#[derive(Debug, Clone, PartialEq)]
pub struct StepFound {
    /// Sample index of the first sample after the step (as in the context's segments).
    pub at: u64,
    pub size: f64,
    pub sigma: f64,
    /// Calibrated likelihood ratio and its family-wise p-value.
    pub lr: f64,
    pub p_value: f64,
    /// Block length [samples] of the scale where it was found.
    pub scale: u64,
}

/// Find up to [`MAX_STEPS`] steps given the other signals of the model, scanning the scales from
/// the GLS scale up to 16 blocks per segment. `y` (the samples, concatenated over segments) refines
/// each instant to the sample when given.
pub fn find_steps(
    base: &Blocks,
    comps: &[Component],
    others: &[Signal],
    y: Samples,
) -> Vec<StepFound> {
    let mut found: Vec<StepFound> = Vec::new();
    let start = gls_scale(base);
    let mut scales = vec![start.clone()];
    loop {
        let last = scales.last().expect("one scale");
        let longest = last.longest();
        if longest < 32 {
            break;
        }
        scales.push(last.coarser(2));
    }
    let n_scales = scales.len() as f64;
    let gls: Vec<Gls> = scales.into_iter().map(|b| Gls::new(b, comps)).collect();
    for _ in 0..MAX_STEPS {
        let mut signals: Vec<Signal> = others.to_vec();
        signals.extend(found.iter().map(|s| Signal::Step { at: s.at as f64 }));
        let mut best: Option<(f64, f64, usize, usize)> = None; // (p, lr, scale index, diff index)
        for (si, g) in gls.iter().enumerate() {
            let cols: Vec<DVector<f64>> = signals
                .iter()
                .map(|s| g.apply(&s.column(&g.blocks)))
                .collect();
            if let Some((i, lr, _cal)) = g.scan(&cols) {
                let p = (chi2_sf(lr, 1.0) * g.zw.len() as f64 * n_scales).min(1.0);
                if best.is_none_or(|b| p < b.0) {
                    best = Some((p, lr, si, i));
                }
            }
        }
        let Some((p, lr, si, i)) = best else { break };
        if p >= P_STEP {
            break;
        }
        let g = &gls[si];
        let (s, b) = g.locate(i);
        let seg = &g.blocks.segments[s];
        let l = g.blocks.size;
        let coarse = seg.start + (b as u64 + 1) * l;
        let at = refine_step(base, y, coarse, l);
        // The refinement reads the samples, not the residual: near a step the model has, it
        // can land on that step's instant again, and a second step there is the same column
        // (its size split between them: a staircase at one instant). Nothing new is there.
        if signals
            .iter()
            .any(|s| matches!(s, Signal::Step { at: a } if (a - at as f64).abs() < 1.0))
        {
            break;
        }
        // size and σ at the GLS scale with the others
        let mut sigs = signals.clone();
        sigs.push(Signal::Step { at: at as f64 });
        let est = estimate(&gls[0].blocks, comps, &sigs);
        let e = est.last().expect("the step");
        found.push(StepFound {
            at,
            size: e.value,
            sigma: e.sigma,
            lr,
            p_value: p,
            scale: l,
        });
    }
    found.sort_by_key(|s| s.at);
    found
}

/// Refine a step instant known to ±`l` samples: on the base blocks, the boundary with the largest
/// two-sample statistic between the means after and before it over windows of up to 64·`l`
/// samples (the segment's ends permitting); then, with the samples at hand, the same to the
/// sample within ±1 base block.
fn refine_step(base: &Blocks, y: Samples, coarse: u64, l: u64) -> u64 {
    let bsz = base.size;
    let Some(seg) = base
        .segments
        .iter()
        .find(|s| coarse >= s.start && coarse <= s.start + s.means.len() as u64 * bsz)
    else {
        return coarse;
    };
    let nb = seg.means.len();
    let w = ((l / bsz) as usize).max(1);
    let c = ((coarse - seg.start) / bsz) as usize;
    let mut best = (0.0, c);
    for q in c.saturating_sub(w).max(1)..=(c + w).min(nb - 1) {
        let k = (64 * w).min(q).min(nb - q);
        if k == 0 {
            continue;
        }
        let after: f64 = seg.means[q..q + k].iter().sum::<f64>() / k as f64;
        let before: f64 = seg.means[q - k..q].iter().sum::<f64>() / k as f64;
        let d = (after - before).abs() * (k as f64).sqrt();
        if d > best.0 {
            best = (d, q);
        }
    }
    let at = seg.start + best.1 as u64 * bsz;
    let Some((y, segs)) = y else { return at };
    if bsz == 1 {
        return at;
    }
    // sample level: prefix sums over the segment that holds `at`
    let mut off = 0usize;
    for &(st, len) in segs {
        if at >= st && at < st + len {
            let x = &y[off..off + len as usize];
            let mut pre = vec![0.0; x.len() + 1];
            for (i, v) in x.iter().enumerate() {
                pre[i + 1] = pre[i] + v;
            }
            let centre = (at - st) as usize;
            let mut best = (0.0, centre);
            let span = 64 * l as usize;
            for q in centre.saturating_sub(bsz as usize).max(1)
                ..=(centre + bsz as usize).min(x.len() - 1)
            {
                let k = span.min(q).min(x.len() - q);
                let d = ((pre[q + k] - pre[q]) - (pre[q] - pre[q - k])).abs() / (k as f64).sqrt();
                if d > best.0 {
                    best = (d, q);
                }
            }
            return st + best.1 as u64;
        }
        off += len as usize;
    }
    at
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::structure::Structure;

    use crate::test_noise as lcg;

    #[test]
    fn whitening_inverts_the_covariance() {
        let gamma = [2.0, 0.9, 0.3, -0.1, 0.0, 0.0];
        let w = whitening(&gamma, 6);
        let sigma = DMatrix::from_fn(6, 6, |a, b| {
            gamma[(a as i64 - b as i64).unsigned_abs() as usize]
        });
        let i = &w * sigma * w.transpose();
        assert!((i - DMatrix::identity(6, 6)).amax() < 1e-12);
    }

    #[test]
    fn cosine_block_means_are_exact_and_a_drift_is_estimated_with_its_error() {
        let span = 50_000.0;
        let sig = Signal::Cosine { j: 3, span };
        for (p, l) in [(0.0, 1.0), (17.0, 25.0), (49_000.0, 1000.0)] {
            let want = (0..l as usize)
                .map(|i| (std::f64::consts::PI * 3.0 * (p + i as f64) / span).cos())
                .sum::<f64>()
                / l;
            let got = sig.block_mean(p, l, 0.01);
            assert!((got - want).abs() < 1e-12, "p {p} l {l}: {got} vs {want}");
        }
        // white noise of unit σ plus 0.05·cos(πk/T) − 0.03·cos(2πk/T): both amplitudes found
        // within 4σ, and σ as GLS on block means predicts (√(2/n) for a unit cosine)
        for seed in 11..15 {
            let mut rng = lcg(seed);
            let n = 50_000usize;
            let (a1, a2) = (0.05, -0.03);
            let y: Vec<f64> = (0..n)
                .map(|k| {
                    let w = std::f64::consts::PI * k as f64 / n as f64;
                    rng() + a1 * w.cos() + a2 * (2.0 * w).cos()
                })
                .collect();
            let segs = [(0u64, n as u64)];
            let base = Blocks::new(&y, None, &segs, 50, 0.01);
            let comps = [Component {
                coef: 1.0,
                structure: Structure::Linear,
            }];
            let sigs = [
                Signal::Cosine {
                    j: 1,
                    span: n as f64,
                },
                Signal::Cosine {
                    j: 2,
                    span: n as f64,
                },
            ];
            let est = estimate(&base, &comps, &sigs);
            let want_sigma = (2.0 / n as f64).sqrt();
            for (e, a) in est.iter().zip([a1, a2]) {
                assert!((e.value - a).abs() < 4.0 * e.sigma, "seed {seed}: {e:?}");
                assert!(
                    (e.sigma / want_sigma - 1.0).abs() < 0.05,
                    "seed {seed}: {e:?}"
                );
            }
            let lrs = nested_lrs(&base, &comps, &[], &sigs);
            assert!(lrs[0] > 10.0 && lrs[1] > lrs[0], "seed {seed}: {lrs:?}");
        }
    }

    #[test]
    fn a_step_in_white_noise_is_found_to_the_sample_and_sized() {
        let mut rng = lcg(3);
        let n = 100_000usize;
        let at = 61_234u64;
        let y: Vec<f64> = (0..n)
            .map(|k| rng() + if k as u64 >= at { 0.2 } else { 0.0 })
            .collect();
        let segs = [(0u64, n as u64)];
        let base = Blocks::new(&y, None, &segs, 25, 0.01);
        let comps = [Component {
            coef: 1.0,
            structure: Structure::Linear,
        }];
        let f = find_steps(&base, &comps, &[], Some((&y, &segs)));
        assert_eq!(f.len(), 1, "{f:?}");
        // the change-point estimate scatters on the scale σ²/Δ² = 25 samples (Hinkley 1970)
        assert!((f[0].at as i64 - at as i64).abs() <= 250, "{f:?}");
        assert!((f[0].size - 0.2).abs() < 4.0 * f[0].sigma, "{f:?}");
        // no step: nothing found
        let mut rng = lcg(4);
        let y: Vec<f64> = (0..n).map(|_| rng()).collect();
        let base = Blocks::new(&y, None, &segs, 25, 0.01);
        assert!(find_steps(&base, &comps, &[], Some((&y, &segs))).is_empty());
    }

    #[test]
    fn a_temperature_coefficient_is_estimated_with_its_error() {
        let mut rng = lcg(5);
        let n = 200_000usize;
        let temp: Vec<f64> = (0..n)
            .map(|k| 25.0 + 15.0 * (1.0 - (-(k as f64) / 40_000.0).exp()))
            .collect();
        let y: Vec<f64> = (0..n).map(|k| rng() + 0.02 * temp[k]).collect();
        let segs = [(0u64, n as u64)];
        let base = Blocks::new(&y, Some(&temp), &segs, 200, 0.01);
        let comps = [Component {
            coef: 1.0,
            structure: Structure::Linear,
        }];
        let e = estimate(&gls_scale(&base), &comps, &[Signal::Temperature]);
        assert!(
            (e[0].value - 0.02).abs() < 4.0 * e[0].sigma && e[0].sigma < 0.002,
            "{e:?}"
        );
        assert!(e[0].lr > 100.0, "{e:?}");
    }
}
