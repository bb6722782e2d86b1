//! Welch power spectral density, spectral-line detection (evidence for the sinusoid effect) and
//! band detection (evidence for the resonance effect, [`find_band`]).
//!
//! Welch (1967): Hann-windowed segments with 50 % overlap, mean removed per segment, averaged
//! periodograms, one-sided density P(f) = 2|X(f)|² / (f_s Σw²) in u²/Hz. Each averaged bin of a
//! smooth spectrum is distributed approximately as P·χ²_ν/ν with ν ≈ 1.9·K for K Hann segments at
//! 50 % overlap (Percival & Walden, *Spectral Analysis for Physical Applications*, §6.17). A line
//! is declared where the bin exceeds the local running-median background by more than the
//! χ²_ν/ν quantile at a family-wise false-alarm probability of 1e-3 over all bins.
use allan::confidence::chi2_ppf as chi2_quantile;

/// A one-sided PSD estimate.
#[derive(Debug, Clone, PartialEq)]
pub struct Psd {
    /// Bin spacing [Hz].
    pub df: f64,
    /// Density per bin k at f = k·df [u²/Hz], k = 0..=L/2.
    pub density: Vec<f64>,
    /// Approximate EDF of each bin.
    pub edf: f64,
    pub segments: usize,
}

/// A detected spectral line.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Line {
    pub freq_hz: f64,
    /// Peak amplitude estimated from the line's excess power, √(2·Σ(P − background)·df) [u].
    pub amplitude: f64,
    /// Peak bin over background.
    pub ratio: f64,
    /// The ratio needed for significance.
    pub threshold: f64,
}

/// In-place iterative radix-2 complex FFT (Cooley–Tukey, decimation in time), e^{−2πi·jk/n}.
/// `re.len()` must be a power of two. The twiddle factors come from one table of n/2 values
/// (each computed directly, not by recurrence, so they keep full precision).
pub fn fft(re: &mut [f64], im: &mut [f64]) {
    let n = re.len();
    assert!(n.is_power_of_two() && im.len() == n);
    if n < 2 {
        return;
    }
    let (cos, sin): (Vec<f64>, Vec<f64>) = (0..n / 2)
        .map(|k| {
            let (s, c) = (-2.0 * std::f64::consts::PI * k as f64 / n as f64).sin_cos();
            (c, s)
        })
        .unzip();
    let mut j = 0usize;
    for i in 1..n {
        let mut bit = n >> 1;
        while j & bit != 0 {
            j ^= bit;
            bit >>= 1;
        }
        j |= bit;
        if i < j {
            re.swap(i, j);
            im.swap(i, j);
        }
    }
    let mut len = 2;
    while len <= n {
        let step = n / len;
        let half = len / 2;
        for start in (0..n).step_by(len) {
            for k in 0..half {
                let (c, s) = (cos[k * step], sin[k * step]);
                let (a, b) = (start + k, start + k + half);
                let tr = re[b] * c - im[b] * s;
                let ti = re[b] * s + im[b] * c;
                re[b] = re[a] - tr;
                im[b] = im[a] - ti;
                re[a] += tr;
                im[a] += ti;
            }
        }
        len <<= 1;
    }
}

/// Welch PSD of `y` sampled at `fs` Hz with segments of `seg` samples (power of two ≥ 16).
/// Returns None when the record is shorter than one segment.
pub fn welch(y: &[f64], fs: f64, seg: usize) -> Option<Psd> {
    if !seg.is_power_of_two() || seg < 16 || y.len() < seg {
        return None;
    }
    let w: Vec<f64> = (0..seg)
        .map(|i| 0.5 - 0.5 * (2.0 * std::f64::consts::PI * i as f64 / seg as f64).cos())
        .collect();
    let sw2: f64 = w.iter().map(|v| v * v).sum();
    let mut acc = vec![0.0; seg / 2 + 1];
    let step = seg / 2;
    let starts: Vec<usize> = (0..)
        .map(|k| k * step)
        .take_while(|s| s + seg <= y.len())
        .collect();
    let count = starts.len();
    let mut re = vec![0.0; seg];
    let mut im = vec![0.0; seg];
    let fill = |buf: &mut [f64], start: usize| {
        let s = &y[start..start + seg];
        let mean = s.iter().sum::<f64>() / seg as f64;
        for ((b, v), wi) in buf.iter_mut().zip(s).zip(&w) {
            *b = (v - mean) * wi;
        }
    };
    let norm = fs * sw2;
    // two real segments per complex FFT: x = a + i·b gives A_k = (X_k + X*_{n−k})/2 and
    // B_k = (X_k − X*_{n−k})/(2i), so |A_k|² + |B_k|² = (|X_k|² + |X_{n−k}|²)/2
    for pair in starts.chunks(2) {
        fill(&mut re, pair[0]);
        match pair.get(1) {
            Some(&b) => fill(&mut im, b),
            None => im.iter_mut().for_each(|v| *v = 0.0),
        }
        fft(&mut re, &mut im);
        for (k, a) in acc.iter_mut().enumerate() {
            let nk = (seg - k) % seg;
            let p = if pair.len() == 2 {
                (re[k] * re[k] + im[k] * im[k] + re[nk] * re[nk] + im[nk] * im[nk]) / 2.0
            } else {
                // A_k = (X_k + X*_{n−k})/2 alone
                let (ar, ai) = ((re[k] + re[nk]) / 2.0, (im[k] - im[nk]) / 2.0);
                ar * ar + ai * ai
            };
            let one_sided = if k == 0 || k == seg / 2 { 1.0 } else { 2.0 };
            *a += one_sided * p / norm;
        }
    }
    for a in &mut acc {
        *a /= count as f64;
    }
    Some(Psd {
        df: fs / seg as f64,
        density: acc,
        edf: (1.9 * count as f64).max(2.0),
        segments: count,
    })
}

/// A default segment length: the largest power of two ≤ N/16, clamped to [256, 65536].
pub fn default_segment(n: usize) -> usize {
    let mut s = 256usize;
    while s * 2 <= n / 16 && s < 65_536 {
        s *= 2;
    }
    s
}

/// Log-log slope of a periodogram between two groups of bins, from the medians of ln P and ln f
/// on each side (robust against a line between them and against the steep rise near DC).
fn side_slope(p: &[f64], left: &[usize], right: &[usize]) -> f64 {
    let med = |mut v: Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let lnp = |s: &[usize]| med(s.iter().map(|&i| p[i].max(1e-300).ln()).collect());
    let lnf = |s: &[usize]| med(s.iter().map(|&i| (i as f64).ln()).collect());
    let (fl, fr) = (lnf(left), lnf(right));
    if fr > fl {
        (lnp(right) - lnp(left)) / (fr - fl)
    } else {
        0.0
    }
}

/// The strongest significant line of the PSD, if any (see [`find_lines`]).
pub fn find_line(psd: &Psd) -> Option<Line> {
    find_lines(psd).into_iter().next()
}

/// Every significant line of the PSD (local maxima), strongest first. The background at each bin
/// is a local power law fitted robustly to ±16 neighbours (the line's own ±2 bins excluded); bins
/// below 6·df are not searched.
pub fn find_lines(psd: &Psd) -> Vec<Line> {
    let p = &psd.density;
    let nb = p.len();
    if nb < 16 {
        return Vec::new();
    }
    let half = 16usize;
    let nu = psd.edf;
    // median of χ²_ν/ν relative to its mean, Wilson–Hilferty: (1 − 2/(9ν))³
    let med_corr = (1.0 - 2.0 / (9.0 * nu)).powi(3);
    let threshold = chi2_quantile(1.0 - 1e-3 / nb as f64, nu) / nu;
    let mut peaks: Vec<(usize, f64, f64)> = Vec::new();
    let med = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    for k in 6..nb - 1 {
        let lo = k.saturating_sub(half).max(1);
        let hi = (k + half).min(nb - 1);
        let left: Vec<usize> = (lo..k.saturating_sub(2)).collect();
        let right: Vec<usize> = (k + 3..=hi).collect();
        if left.len() < 3 || right.len() < 3 || p[k] <= 0.0 {
            continue;
        }
        // Local power-law background: slope of ln P on ln f from the medians of the two sides,
        // then the median of the de-trended neighbours (robust against the line itself and
        // against the steep flicker/random-walk rise near DC).
        let lnf = |i: usize| (i as f64).ln();
        let lnp = |i: usize| p[i].max(1e-300).ln();
        let slope = side_slope(p, &left, &right);
        let mut detr: Vec<f64> = left
            .iter()
            .chain(&right)
            .map(|&i| lnp(i) - slope * (lnf(i) - lnf(k)))
            .collect();
        let bg = med(&mut detr).exp() / med_corr;
        if !(bg > 0.0) {
            continue;
        }
        let r = p[k] / bg;
        if r > threshold && p[k] >= p[k - 1] && p[k] >= p[k + 1] {
            peaks.push((k, r, bg));
        }
    }
    peaks.sort_by(|a, b| b.1.total_cmp(&a.1));
    let mut lines: Vec<Line> = Vec::new();
    let mut taken: Vec<usize> = Vec::new();
    for (k, ratio, bg) in peaks {
        if taken.iter().any(|&t| t.abs_diff(k) <= 3) {
            continue;
        }
        taken.push(k);
        lines.push(line_at(p, psd.df, k, ratio, bg, threshold));
    }
    lines
}

fn line_at(p: &[f64], df: f64, k: usize, ratio: f64, bg: f64, threshold: f64) -> Line {
    let nb = p.len();
    // parabolic interpolation of the peak on ln P
    let (a, b, c) = (p[k - 1].ln(), p[k].ln(), p[k + 1].ln());
    let den = a - 2.0 * b + c;
    let delta = if den.abs() > 0.0 {
        (0.5 * (a - c) / den).clamp(-0.5, 0.5)
    } else {
        0.0
    };
    let excess: f64 = (k.saturating_sub(2)..=(k + 2).min(nb - 1))
        .map(|i| (p[i] - bg).max(0.0))
        .sum::<f64>()
        * df;
    Line {
        freq_hz: (k as f64 + delta) * df,
        amplitude: (2.0 * excess).sqrt(),
        ratio,
        threshold,
    }
}

/// A band of excess power in the PSD: a resonance's peak of finite width (evidence for the
/// resonance effect, as a line is for the sinusoid).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Band {
    /// Natural frequency [Hz] and damping ratio of the best resonance shape, with their
    /// standard errors from the curvature of the spectrum's χ² (each with the other fixed).
    pub f0_hz: f64,
    pub zeta: f64,
    pub f0_sigma: f64,
    pub zeta_sigma: f64,
    /// The fall of the spectrum's χ² (each Welch bin's relative variance 2/ν) when the resonance
    /// joins the smooth background, scaled by the fit's χ²/dof when that exceeds 1.
    pub delta_chi2: f64,
    /// The resonance's density at f0 over the background's there.
    pub peak_ratio: f64,
}

/// Smallest Δχ² for a band (a 3-parameter shape searched over a grid; far beyond any
/// look-elsewhere correction, because the smooth background is only approximately right).
pub const BAND_MIN_DELTA_CHI2: f64 = 100.0;
/// The spectrum is averaged in log-spaced groups of bins, this many per decade (a group of c bins
/// has relative variance 2/(νc)).
pub const BAND_GROUPS_PER_DECADE: f64 = 400.0;
/// Largest damping ratio searched for a band: beyond it the peak is hardly one (|H|² has no maximum
/// above ζ = 1/√2) and the shape is a low-pass one.
pub const BAND_MAX_ZETA: f64 = 0.5;
/// Smallest peak-to-background ratio for a band: the peak adds at least a quarter to the density
/// there (a resonance of ζ = 0.2 and σ = 0.02 °/s on 5e-3 °/s·√s white noise reaches 0.9; the
/// quiet records of the tests up to 0.38, but with Δχ² ≤ 14: the Δχ² gate separates them).
pub const BAND_MIN_PEAK_RATIO: f64 = 0.25;

/// The strongest band of excess power of finite width in a Welch PSD of data sampled every `tau0`,
/// if any. The spectrum from 6·df to 0.49·f_s, averaged in log-spaced groups of bins
/// ([`BAND_GROUPS_PER_DECADE`]; weights relative to the ±4-bin running mean, with the Hann
/// window's correlation of neighbouring bins), is fitted by
/// non-negative least squares with a smooth background — white (flat), quantization (∝ sin²(πfτ0)),
/// flicker (1/f), random walk (1/f²), and one- and two-pole low-pass shapes with corners on octaves
/// from 32·df (Markov noise, the sensor's filters), all monotone or rising, none with a peak — with
/// and without the sampled resonance shape [`crate::structure::resonance_psd_unit`], its f0 on a log
/// grid (40 per decade, from 16·df to 0.45·f_s) and ζ in 0.02–[`BAND_MAX_ZETA`], the best refined
/// by golden sections on ln f0 and ln ζ between the grid's neighbours. Shapes narrower than 6 bins
/// or 3 groups (2ζf0 < 6·df, or ζ < 0.009) are lines, left to [`find_lines`]. A band needs Δχ²
/// ≥ [`BAND_MIN_DELTA_CHI2`] and a peak ratio ≥ [`BAND_MIN_PEAK_RATIO`].
pub fn find_band(psd: &Psd, tau0: f64) -> Option<Band> {
    use nalgebra::{DMatrix, DVector};
    let p = &psd.density;
    let nb = p.len();
    let df = psd.df;
    let fs = 1.0 / tau0;
    let hi = ((0.49 * fs / df) as usize).min(nb.saturating_sub(1));
    let lo = 6usize;
    if hi < lo + 64 {
        return None;
    }
    let f = |k: usize| k as f64 * df;
    // log-spaced groups of bins [a, b]
    let step = 10f64.powf(1.0 / BAND_GROUPS_PER_DECADE);
    let mut groups: Vec<(usize, usize)> = Vec::new();
    let mut k = lo;
    while k <= hi {
        let end = ((k as f64 * step).floor() as usize).clamp(k, hi);
        groups.push((k, end));
        k = end + 1;
    }
    let ng = groups.len();
    let mean_over = |g: (usize, usize), v: &dyn Fn(usize) -> f64| {
        (g.0..=g.1).map(v).sum::<f64>() / (g.1 - g.0 + 1) as f64
    };
    // row weights √(νc/2)/P̂, P̂ the group's mean of the ±4-bin running mean
    let running = |k: usize| {
        let (a, b) = (k.saturating_sub(4).max(1), (k + 4).min(nb - 1));
        p[a..=b].iter().sum::<f64>() / (b - a + 1) as f64
    };
    // Neighbouring Hann-windowed bins are correlated: |ρ| = 2/3 between adjacent coefficients
    // and 1/6 two apart, so ρ = 4/9 and 1/36 between their powers. The mean of c bins then has
    // relative variance (2/ν)·[1 + 2Σ_l (1 − l/c)ρ_l]/c.
    let corr = |c: f64| 1.0 + 2.0 * ((1.0 - 1.0 / c) * 4.0 / 9.0 + (1.0 - 2.0 / c).max(0.0) / 36.0);
    let rw: Vec<f64> = groups
        .iter()
        .map(|&g| {
            let ph = mean_over(g, &running);
            let c = (g.1 - g.0 + 1) as f64;
            if ph > 0.0 {
                (psd.edf * c / (2.0 * corr(c))).sqrt() / ph
            } else {
                0.0
            }
        })
        .collect();
    let mut shapes: Vec<Box<dyn Fn(f64) -> f64>> = vec![
        Box::new(|_| 1.0),
        Box::new(move |f| (std::f64::consts::PI * f * tau0).sin().powi(2)),
        Box::new(|f| 1.0 / f),
        Box::new(|f| 1.0 / (f * f)),
    ];
    let mut fc = 32.0 * df;
    while fc < 0.5 * fs {
        shapes.push(Box::new(move |f| 1.0 / (1.0 + (f / fc).powi(2))));
        shapes.push(Box::new(move |f| 1.0 / (1.0 + (f / fc).powi(2)).powi(2)));
        fc *= 2.0;
    }
    let nbg = shapes.len();
    let mut a = DMatrix::<f64>::zeros(ng, nbg + 1);
    for (j, shape) in shapes.iter().enumerate() {
        for (r, &g) in groups.iter().enumerate() {
            a[(r, j)] = mean_over(g, &|k| shape(f(k))) * rw[r];
        }
        // column scales, so that NNLS sees comparable columns
        let s = a.column(j).norm();
        if s > 0.0 {
            a.column_mut(j).scale_mut(1.0 / s);
        }
    }
    let b = DVector::from_iterator(
        ng,
        groups
            .iter()
            .zip(&rw)
            .map(|(&g, w)| mean_over(g, &|k| p[k]) * w),
    );
    let chi2 = |a: &DMatrix<f64>| {
        let c = crate::nnls::nnls(a, &b);
        let r = &b - a * &c;
        (r.norm_squared(), c)
    };
    let (chi0, _) = chi2(&a.columns(0, nbg).into_owned());
    // χ² and peak ratio of the background with the resonance shape (f0, ζ)
    let mut with = |f0: f64, zeta: f64| -> (f64, f64) {
        for (r, &g) in groups.iter().enumerate() {
            a[(r, nbg)] = mean_over(g, &|k| {
                crate::structure::resonance_psd_unit(f(k), tau0, f0, zeta)
            }) * rw[r];
        }
        let s = a.column(nbg).norm();
        if !(s > 0.0 && s.is_finite()) {
            return (f64::INFINITY, 0.0);
        }
        a.column_mut(nbg).scale_mut(1.0 / s);
        let (c2, c) = chi2(&a);
        // densities in f0's group of the resonance and of the background
        let k0 = (f0 / df).round() as usize;
        let r0 = groups.iter().position(|g| g.1 >= k0).unwrap_or(ng - 1);
        let res = a[(r0, nbg)] * c[nbg];
        let back: f64 = (0..nbg).map(|j| a[(r0, j)] * c[j]).sum();
        (
            c2,
            if back > 0.0 {
                res / back
            } else {
                f64::INFINITY
            },
        )
    };
    // a band at least 6 bins and 3 groups wide: narrower, a line and a band look alike
    let min_zeta = |f0: f64| (3.0 * df / f0).max(1.5 * (step - 1.0));
    let zetas = [
        0.02,
        0.03,
        0.05,
        0.07,
        0.1,
        0.15,
        0.2,
        0.3,
        0.4,
        BAND_MAX_ZETA,
    ];
    let (flo, fhi) = (16.0 * df, 0.45 * fs);
    let nf = ((fhi / flo).log10() * 40.0).ceil().max(1.0) as usize;
    let mut best: Option<(f64, f64, f64)> = None; // (χ², f0, ζ)
    for i in 0..=nf {
        let f0 = flo * (fhi / flo).powf(i as f64 / nf as f64);
        for &zeta in &zetas {
            if zeta < min_zeta(f0) {
                continue;
            }
            let (c2, _) = with(f0, zeta);
            if best.is_none_or(|b| c2 < b.0) {
                best = Some((c2, f0, zeta));
            }
        }
    }
    let (_, mut f0_hz, mut zeta) = best?;
    // refine between the grid's neighbours: golden sections on ln f0 and ln ζ in turn
    for _ in 0..3 {
        let (x, _) = crate::optim::golden_min(
            |x| with(x.exp(), zeta).0,
            (f0_hz / 1.06).ln(),
            (f0_hz * 1.06).min(0.499 * fs).ln(),
            30,
        );
        f0_hz = x.exp();
        let (x, _) = crate::optim::golden_min(
            |x| with(f0_hz, x.exp()).0,
            // no narrower than a line there either
            (zeta / 1.5).max(min_zeta(f0_hz)).min(zeta).ln(),
            (zeta * 1.5).min(BAND_MAX_ZETA).ln(),
            30,
        );
        zeta = x.exp();
    }
    let (c2, peak_ratio) = with(f0_hz, zeta);
    let dof = ng.saturating_sub(nbg + 3).max(1) as f64;
    let s2 = (c2 / dof).max(1.0);
    // σ of a parameter from the χ² curvature: Var = 2·s²/(∂²χ²/∂θ²)
    let curvature_sigma = |v: f64, g: &mut dyn FnMut(f64) -> f64| {
        let h = 1e-3 * v;
        let d2 = (g(v + h) - 2.0 * c2 + g(v - h)) / (h * h);
        if d2 > 0.0 {
            (2.0 * s2 / d2).sqrt()
        } else {
            f64::INFINITY
        }
    };
    let f0_sigma = curvature_sigma(f0_hz, &mut |v| with(v, zeta).0);
    let zeta_sigma = curvature_sigma(zeta, &mut |v| with(f0_hz, v).0);
    let delta_chi2 = (chi0 - c2) / s2;
    (delta_chi2 >= BAND_MIN_DELTA_CHI2 && peak_ratio >= BAND_MIN_PEAK_RATIO).then_some(Band {
        f0_hz,
        zeta,
        f0_sigma,
        zeta_sigma,
        delta_chi2,
        peak_ratio,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fft_of_a_cosine() {
        let n = 64;
        let mut re: Vec<f64> = (0..n)
            .map(|i| (2.0 * std::f64::consts::PI * 5.0 * i as f64 / n as f64).cos())
            .collect();
        let mut im = vec![0.0; n];
        fft(&mut re, &mut im);
        assert!((re[5] - 32.0).abs() < 1e-9 && (re[59] - 32.0).abs() < 1e-9);
        assert!(re[4].abs() < 1e-9 && im[5].abs() < 1e-9);
    }

    #[test]
    fn welch_matches_a_direct_dft_average() {
        // 9 half-overlapping segments of 16 (an odd count: the last FFT holds one segment)
        let y: Vec<f64> = (0..80)
            .map(|i| ((i * 37 % 23) as f64 - 11.0) * 0.1 + (i as f64 * 0.3).sin())
            .collect();
        let (seg, fs) = (16usize, 50.0);
        let p = welch(&y, fs, seg).unwrap();
        assert_eq!(p.segments, 9);
        let w: Vec<f64> = (0..seg)
            .map(|i| 0.5 - 0.5 * (2.0 * std::f64::consts::PI * i as f64 / seg as f64).cos())
            .collect();
        let sw2: f64 = w.iter().map(|v| v * v).sum();
        for k in 0..=seg / 2 {
            let mut acc = 0.0;
            for s in 0..9 {
                let x = &y[s * 8..s * 8 + seg];
                let mean = x.iter().sum::<f64>() / seg as f64;
                let (mut re, mut im) = (0.0, 0.0);
                for (i, v) in x.iter().enumerate() {
                    let ang = -2.0 * std::f64::consts::PI * (i * k) as f64 / seg as f64;
                    re += (v - mean) * w[i] * ang.cos();
                    im += (v - mean) * w[i] * ang.sin();
                }
                let one = if k == 0 || k == seg / 2 { 1.0 } else { 2.0 };
                acc += one * (re * re + im * im) / (fs * sw2);
            }
            let want = acc / 9.0;
            assert!(
                (p.density[k] - want).abs() <= 1e-12 * want.max(1e-12),
                "bin {k}: {} vs {want}",
                p.density[k]
            );
        }
    }

    #[test]
    fn line_found_in_a_noisy_sine() {
        // deterministic pseudo-noise (LCG) plus a sine of amplitude 0.2 at 7.3 Hz, fs = 100 Hz
        let mut noise = crate::test_noise(12345);
        let y: Vec<f64> = (0..65536)
            .map(|i| noise() + 0.2 * (2.0 * std::f64::consts::PI * 7.3 * i as f64 / 100.0).sin())
            .collect();
        let psd = welch(&y, 100.0, default_segment(y.len())).unwrap();
        let line = find_line(&psd).expect("line");
        assert!((line.freq_hz - 7.3).abs() < psd.df, "{line:?}");
        assert!((line.amplitude - 0.2).abs() < 0.05, "{line:?}");
        let t = line_near(&y, 100.0, 7.0, 0.1).unwrap();
        assert!(t.p_value < 1e-6 && (t.freq_hz - 7.3).abs() < 0.01, "{t:?}");
        // no line near 20 Hz: the p-value is not small
        let t = line_near(&y, 100.0, 20.0, 0.1).unwrap();
        assert!(t.p_value > 1e-3, "{t:?}");
    }
}

/// The result of testing the whole record for a line near a given frequency.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LineTest {
    /// Frequency of the strongest bin in the search window [Hz].
    pub freq_hz: f64,
    /// That bin over the local power-law background.
    pub ratio: f64,
    /// Probability of a ratio this large or larger from noise alone, Bonferroni-corrected over
    /// the bins searched (single periodogram bins are χ²₂/2, i.e. exponential).
    pub p_value: f64,
    /// Bins searched.
    pub bins: usize,
}

/// Test the whole record (Hann window, one periodogram, resolution f_s/N) for a line within
/// `f·(1 ± rel)` (at least ±3 bins). The background is a power law fitted robustly (as in
/// [`find_line`]) to 3–48 bins on each side of the window. This resolves far lower frequencies
/// than the Welch average and is the spectral check on a sinusoid found in the Allan fit.
pub fn line_near(y: &[f64], fs: f64, f: f64, rel: f64) -> Option<LineTest> {
    let n = y.len();
    if n < 64 || !(f > 0.0) || !(fs > 0.0) {
        return None;
    }
    let len = n.next_power_of_two();
    let mean = y.iter().sum::<f64>() / n as f64;
    let mut re = vec![0.0; len];
    let mut im = vec![0.0; len];
    for (i, v) in y.iter().enumerate() {
        let w = 0.5 - 0.5 * (2.0 * std::f64::consts::PI * i as f64 / n as f64).cos();
        re[i] = (v - mean) * w;
    }
    fft(&mut re, &mut im);
    let df = fs / len as f64;
    let p: Vec<f64> = (0..=len / 2)
        .map(|k| re[k] * re[k] + im[k] * im[k])
        .collect();
    let kc = f / df;
    let half = (kc * rel).max(3.0);
    let lo = (kc - half).floor().max(1.0) as usize;
    let hi = ((kc + half).ceil() as usize).min(p.len() - 1);
    if lo >= hi {
        return None;
    }
    let left: Vec<usize> = (lo.saturating_sub(48).max(1)..lo.saturating_sub(3)).collect();
    let right: Vec<usize> = (hi + 3..=(hi + 48).min(p.len() - 1)).collect();
    if left.len() + right.len() < 16 {
        return None;
    }
    let med = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let lnf = |i: usize| (i as f64).ln();
    let lnp = |i: usize| p[i].max(1e-300).ln();
    let slope = if left.len() >= 3 && right.len() >= 3 {
        side_slope(&p, &left, &right)
    } else {
        0.0
    };
    let kref = kc.max(1.0).ln();
    let mut detr: Vec<f64> = left
        .iter()
        .chain(&right)
        .map(|&i| lnp(i) - slope * (lnf(i) - kref))
        .collect();
    // median of an exponential variable is ln 2 times its mean
    let bg0 = med(&mut detr).exp() / std::f64::consts::LN_2;
    let (mut best_k, mut best_r) = (lo, 0.0);
    for (k, &pk) in p.iter().enumerate().take(hi + 1).skip(lo) {
        let bg = bg0 * ((lnf(k) - kref) * slope).exp();
        let r = pk / bg;
        if r > best_r {
            best_r = r;
            best_k = k;
        }
    }
    let bins = hi - lo + 1;
    Some(LineTest {
        freq_hz: best_k as f64 * df,
        ratio: best_r,
        p_value: (bins as f64 * (-best_r).exp()).min(1.0),
        bins,
    })
}
