//! Exact batch estimators over a recording, with 68.3 % confidence bounds.
//!
//! Input is rate samples `y_i` (deg/s, m/s², …) taken every `τ0`. Following AllanTools
//! (`frequency2phase`), the mean rate is removed and the phase is the cumulative sum with a
//! leading zero, `x[0] = 0, x[k] = Σ_{i<k} (y_i − ȳ)` (seed eq. 8). Working in units of
//! "rate × samples" makes `τ0` cancel from every deviation except TDEV, which is a time.
//! Removing the mean changes none of the difference-based estimators (a constant rate is a
//! linear phase, annihilated by second and third differences); it only keeps `x` small.
use crate::ci::{self, Variance};
use crate::noise_id;
use crate::stream::LevelSums;
use crate::AllanError;

/// The statistic to compute.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Stat {
    /// Allan deviation, non-overlapping (SP 1065 eq. 7–8).
    Adev,
    /// Overlapping Allan deviation (SP 1065 eq. 11; seed eq. 7).
    Oadev,
    /// Modified Allan deviation (SP 1065 eq. 14).
    Mdev,
    /// Hadamard deviation, non-overlapping (SP 1065 eq. 17).
    Hdev,
    /// Overlapping Hadamard deviation (SP 1065 eq. 18).
    Ohdev,
    /// Time deviation, `τ·MDEV/√3` (SP 1065 eq. 15); unit: rate unit × s.
    Tdev,
    /// Total deviation (SP 1065 eq. 25, reflection at both ends).
    Totdev,
}

impl Stat {
    /// Every statistic, in display order.
    pub const ALL: [Stat; 7] = [
        Stat::Adev,
        Stat::Oadev,
        Stat::Mdev,
        Stat::Hdev,
        Stat::Ohdev,
        Stat::Tdev,
        Stat::Totdev,
    ];

    /// The short lower-case name used on the command line and in JSON.
    pub fn name(self) -> &'static str {
        match self {
            Stat::Adev => "adev",
            Stat::Oadev => "oadev",
            Stat::Mdev => "mdev",
            Stat::Hdev => "hdev",
            Stat::Ohdev => "ohdev",
            Stat::Tdev => "tdev",
            Stat::Totdev => "totdev",
        }
    }

    /// Parse a short name (`adev`, `oadev`, …).
    pub fn parse(s: &str) -> Option<Stat> {
        Stat::ALL.into_iter().find(|st| st.name() == s)
    }

    /// Whether the deviation has the unit of time × rate (TDEV) rather than of the rate.
    pub fn is_time(self) -> bool {
        self == Stat::Tdev
    }

    fn difference_order(self) -> u32 {
        match self {
            Stat::Hdev | Stat::Ohdev => 3,
            _ => 2,
        }
    }
}

/// The averaging factors `m` (τ = m·τ0) to evaluate.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum TauSet {
    /// m = 1, 2, 4, 8, … (AllanTools `taus='octave'`).
    Octave,
    /// m = 1, 2, 4, 10, 20, 40, 100, … (Stable32 / AllanTools `decade`).
    Decade,
    /// Every m = 1, 2, 3, …
    All,
    /// k log-spaced points per octave, m = round(2^(i/k)), duplicates removed.
    PerOctave(u32),
    /// An explicit list of m.
    List(Vec<u64>),
}

impl TauSet {
    /// Parse `octave`, `decade`, `all`, `N/octave` or a comma list of m.
    pub fn parse(s: &str) -> Result<TauSet, AllanError> {
        Ok(match s {
            "octave" => TauSet::Octave,
            "decade" => TauSet::Decade,
            "all" => TauSet::All,
            _ => {
                if let Some(k) = s.strip_suffix("/octave") {
                    let k: u32 = k.parse().map_err(|_| {
                        AllanError::BadTauSet("N in N/octave must be a positive integer")
                    })?;
                    if k == 0 {
                        return Err(AllanError::BadTauSet("N in N/octave must be at least 1"));
                    }
                    TauSet::PerOctave(k)
                } else {
                    let ms: Result<Vec<u64>, _> =
                        s.split(',').map(|v| v.trim().parse::<u64>()).collect();
                    let ms = ms.map_err(|_| {
                        AllanError::BadTauSet(
                            "expected octave, decade, all, N/octave or a list of m",
                        )
                    })?;
                    if ms.contains(&0) {
                        return Err(AllanError::BadTauSet("m = 0 in the list"));
                    }
                    TauSet::List(ms)
                }
            }
        })
    }

    /// The candidate m values up to `max_m`, sorted, without duplicates.
    pub fn ms(&self, max_m: u64) -> Result<Vec<u64>, AllanError> {
        let mut out = Vec::new();
        match self {
            TauSet::Octave => {
                let mut m = 1u64;
                while m <= max_m {
                    out.push(m);
                    m *= 2;
                }
            }
            TauSet::Decade => {
                let mut dec = 1u64;
                'outer: loop {
                    for k in [1, 2, 4] {
                        let m = k * dec;
                        if m > max_m {
                            break 'outer;
                        }
                        out.push(m);
                    }
                    dec *= 10;
                }
            }
            TauSet::All => out.extend(1..=max_m),
            TauSet::PerOctave(k) => {
                if *k == 0 {
                    return Err(AllanError::BadTauSet("0 points per octave"));
                }
                let mut i = 0u32;
                loop {
                    let m = 2f64.powf(i as f64 / *k as f64).round() as u64;
                    if m > max_m {
                        break;
                    }
                    out.push(m);
                    i += 1;
                }
            }
            TauSet::List(ms) => {
                if ms.contains(&0) {
                    return Err(AllanError::BadTauSet("m = 0 in the list"));
                }
                out.extend(ms.iter().copied().filter(|&m| m <= max_m));
            }
        }
        out.sort_unstable();
        out.dedup();
        Ok(out)
    }
}

/// Which estimator produced a row.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Estimator {
    /// The exact estimator over the whole phase record.
    Exact,
    /// The stride-`stride` overlapping estimator of the streaming engine (bounded memory).
    Stride {
        /// Samples between successive differences.
        stride: u64,
    },
}

impl Estimator {
    /// `exact` or `stride-N`.
    pub fn label(&self) -> String {
        match self {
            Estimator::Exact => "exact".into(),
            Estimator::Stride { stride } => format!("stride-{stride}"),
        }
    }
}

/// One row of a deviation table.
#[derive(Clone, Debug, PartialEq)]
pub struct Row {
    /// Cluster time τ = m·τ0, in s.
    pub tau: f64,
    /// Averaging factor.
    pub m: u64,
    /// The deviation, in the rate unit (TDEV: rate unit × s).
    pub dev: f64,
    /// Number of terms in the sum.
    pub n: u64,
    /// Noise exponent used for the EDF (`S_y ∝ f^alpha`).
    pub alpha: i32,
    /// Equivalent degrees of freedom.
    pub edf: f64,
    /// Lower 68.3 % bound.
    pub lo: f64,
    /// Upper 68.3 % bound.
    pub hi: f64,
    /// Which estimator produced the row.
    pub estimator: Estimator,
}

/// Phase in "rate × samples" units with the mean rate removed and a leading 0.
fn phase_from_rate(y: &[f64]) -> Vec<f64> {
    let mean = y.iter().sum::<f64>() / y.len() as f64;
    let mut x = Vec::with_capacity(y.len() + 1);
    let mut acc = 0.0;
    x.push(0.0);
    for v in y {
        acc += v - mean;
        x.push(acc);
    }
    x
}

fn check(y: &[f64], tau0: f64) -> Result<(), AllanError> {
    if !(tau0 > 0.0 && tau0.is_finite()) {
        return Err(AllanError::BadTau0(tau0));
    }
    if let Some(index) = y.iter().position(|v| !v.is_finite()) {
        return Err(AllanError::NotFinite { index });
    }
    if y.len() < 3 {
        return Err(AllanError::TooShort {
            samples: y.len(),
            needed: 3,
        });
    }
    Ok(())
}

/// Sum of squared d-th differences at lag m over start indices 0, stride, 2·stride, …
fn diff_sum(x: &[f64], m: usize, d: u32, stride: usize) -> (f64, u64) {
    let span = d as usize * m;
    if x.len() <= span {
        return (0.0, 0);
    }
    if stride == 1 {
        return (overlapping_sum(x, m, d), (x.len() - span) as u64);
    }
    let (mut s, mut n) = (0.0, 0u64);
    let mut i = 0;
    while i + span < x.len() {
        let v = if d == 2 {
            x[i + 2 * m] - 2.0 * x[i + m] + x[i]
        } else {
            x[i + 3 * m] - 3.0 * x[i + 2 * m] + 3.0 * x[i + m] - x[i]
        };
        s += v * v;
        n += 1;
        i += stride;
    }
    (s, n)
}

const LANES: usize = 8;

/// The fully overlapping sum over equal-length shifted slices, in eight independent lanes so
/// the compiler can keep the loop in vector registers (the hot loop of every octave table).
fn overlapping_sum(x: &[f64], m: usize, d: u32) -> f64 {
    let mut acc = [0.0f64; LANES];
    let tail = accumulate(x, m, d, 0, x.len() - d as usize * m, &mut acc);
    acc.iter().sum::<f64>() + tail
}

/// Add the squared d-th differences at lag m for start indices `i0..i1` into `acc`; returns
/// the sum of the part that does not fill a whole lane group.
fn accumulate(x: &[f64], m: usize, d: u32, i0: usize, i1: usize, acc: &mut [f64; LANES]) -> f64 {
    let n = i1 - i0;
    let mut tail = 0.0;
    if d == 2 {
        let (a, b, c) = (
            &x[i0..i1],
            &x[i0 + m..i0 + m + n],
            &x[i0 + 2 * m..i0 + 2 * m + n],
        );
        let mut ca = a.chunks_exact(LANES);
        let mut cb = b.chunks_exact(LANES);
        let mut cc = c.chunks_exact(LANES);
        for ((a, b), c) in (&mut ca).zip(&mut cb).zip(&mut cc) {
            for l in 0..LANES {
                let v = c[l] - 2.0 * b[l] + a[l];
                acc[l] += v * v;
            }
        }
        for ((a, b), c) in ca
            .remainder()
            .iter()
            .zip(cb.remainder())
            .zip(cc.remainder())
        {
            let v = c - 2.0 * b + a;
            tail += v * v;
        }
    } else {
        let (a, b, c, e) = (
            &x[i0..i1],
            &x[i0 + m..i0 + m + n],
            &x[i0 + 2 * m..i0 + 2 * m + n],
            &x[i0 + 3 * m..i0 + 3 * m + n],
        );
        let mut ca = a.chunks_exact(LANES);
        let mut cb = b.chunks_exact(LANES);
        let mut cc = c.chunks_exact(LANES);
        let mut ce = e.chunks_exact(LANES);
        for (((a, b), c), e) in (&mut ca).zip(&mut cb).zip(&mut cc).zip(&mut ce) {
            for l in 0..LANES {
                let v = e[l] - 3.0 * c[l] + 3.0 * b[l] - a[l];
                acc[l] += v * v;
            }
        }
        for (((a, b), c), e) in ca
            .remainder()
            .iter()
            .zip(cb.remainder())
            .zip(cc.remainder())
            .zip(ce.remainder())
        {
            let v = e - 3.0 * c + 3.0 * b - a;
            tail += v * v;
        }
    }
    tail
}

/// Start indices per block of the cache-blocked pass, and the largest lag span it takes:
/// a block reads `BLOCK + d·m` phase values, ≤ 160 KiB, which stay in L2 while every small m
/// is summed over them, so the phase streams from memory once for all the small levels.
const BLOCK: usize = 4096;
const BLOCKED_SPAN: usize = 16384;

/// Fully overlapping sums for several small m in one cache-blocked pass over the phase.
fn overlapping_sums_blocked(x: &[f64], ms: &[usize], d: u32) -> Vec<f64> {
    let mut acc = vec![[0.0f64; LANES]; ms.len()];
    let mut tails = vec![0.0f64; ms.len()];
    let ends: Vec<usize> = ms
        .iter()
        .map(|&m| x.len().saturating_sub(d as usize * m))
        .collect();
    let last = ends.iter().copied().max().unwrap_or(0);
    let mut i0 = 0;
    while i0 < last {
        for (k, &m) in ms.iter().enumerate() {
            let i1 = (i0 + BLOCK).min(ends[k]);
            if i1 > i0 {
                tails[k] += accumulate(x, m, d, i0, i1, &mut acc[k]);
            }
        }
        i0 += BLOCK;
    }
    acc.iter()
        .zip(tails)
        .map(|(a, t)| a.iter().sum::<f64>() + t)
        .collect()
}

/// Modified Allan variance sum: Σ_j [Σ_{i=j}^{j+m−1} (x[i+2m] − 2x[i+m] + x[i])]² (SP 1065 eq. 14).
fn mod_sum(x: &[f64], m: usize) -> (f64, u64) {
    let np = x.len();
    if np < 3 * m + 1 {
        return (0.0, 0);
    }
    let d2 = |i: usize| x[i + 2 * m] - 2.0 * x[i + m] + x[i];
    let mut inner: f64 = (0..m).map(d2).sum();
    let mut s = inner * inner;
    let n = (np - 3 * m + 1) as u64;
    for j in 1..n as usize {
        inner += d2(j + m - 1) - d2(j - 1);
        s += inner * inner;
    }
    (s, n)
}

/// Total variance sum with reflection at both ends (SP 1065 eq. 25; AllanTools `totdev`).
fn tot_sum(x: &[f64], m: usize) -> (f64, u64) {
    let np = x.len();
    // x*[1−j] = 2x[0] − x[j], x*[np−2+j] = 2x[np−1] − x[np−1−j], j = 1..np−2
    let at = |i: isize| -> f64 {
        let last = np as isize - 1;
        if i < 0 {
            2.0 * x[0] - x[(-i) as usize]
        } else if i > last {
            2.0 * x[last as usize] - x[(2 * last - i) as usize]
        } else {
            x[i as usize]
        }
    };
    let mut s = 0.0;
    for i in 1..np - 1 {
        let i = i as isize;
        let v = at(i - m as isize) - 2.0 * at(i) + at(i + m as isize);
        s += v * v;
    }
    (s, (np - 2) as u64)
}

fn largest_m(stat: Stat, np: u64) -> u64 {
    match stat {
        Stat::Totdev => (np - 1) / 2,
        Stat::Hdev | Stat::Ohdev | Stat::Mdev | Stat::Tdev => np / 3,
        _ => np / 2,
    }
}

/// The deviation `stat` of rate samples `y` (every `tau0` s) at the averaging factors in
/// `taus`, each row with its EDF and 68.3 % bounds. Rows with fewer than 2 terms are dropped
/// (as AllanTools does).
pub fn deviation(y: &[f64], tau0: f64, stat: Stat, taus: &TauSet) -> Result<Vec<Row>, AllanError> {
    check(y, tau0)?;
    let x = phase_from_rate(y);
    deviation_of_phase(&x, tau0, stat, taus)
}

/// The same from phase data `x` in seconds (e.g. Stable32's PHASE.DAT), every `tau0` s.
pub fn deviation_from_phase(
    x: &[f64],
    tau0: f64,
    stat: Stat,
    taus: &TauSet,
) -> Result<Vec<Row>, AllanError> {
    check(x, tau0)?;
    let xs: Vec<f64> = x.iter().map(|v| v / tau0).collect();
    deviation_of_phase(&xs, tau0, stat, taus)
}

fn deviation_of_phase(
    x: &[f64],
    tau0: f64,
    stat: Stat,
    taus: &TauSet,
) -> Result<Vec<Row>, AllanError> {
    let np = x.len() as u64;
    let ms = taus.ms(largest_m(stat, np))?;
    // The sums dominate the cost. Small-lag overlapping sums share one cache-blocked pass;
    // the rest are independent per m; the work items are spread over the cores.
    let d = stat.difference_order();
    let blocked: Vec<usize> = match stat {
        Stat::Oadev | Stat::Ohdev => ms
            .iter()
            .map(|&m| m as usize)
            .filter(|&m| d as usize * m <= BLOCKED_SPAN && x.len() > d as usize * m)
            .collect(),
        _ => Vec::new(),
    };
    let mut items: Vec<Option<u64>> = vec![None];
    items.extend(
        ms.iter()
            .filter(|&&m| !blocked.contains(&(m as usize)))
            .map(|&m| Some(m)),
    );
    let parts = par_map(&items, |item| match item {
        None => overlapping_sums_blocked(x, &blocked, d),
        Some(m) => vec![stat_sum(x, *m as usize, stat)],
    });
    let mut by_m = std::collections::HashMap::new();
    for (item, part) in items.iter().zip(parts) {
        match item {
            None => by_m.extend(blocked.iter().map(|&m| m as u64).zip(part)),
            Some(m) => {
                by_m.insert(*m, part[0]);
            }
        }
    }
    let sums: Vec<(f64, u64, f64)> = ms
        .iter()
        .map(|&m| {
            let (n, denom) = stat_norm(x.len(), m as usize, stat);
            (by_m[&m], n, denom)
        })
        .collect();
    let mut rows = Vec::with_capacity(ms.len());
    let mut ceiling = None;
    for (m, (sum, n, denom)) in ms.into_iter().zip(sums) {
        if n < 2 {
            continue;
        }
        let mf = m as f64;
        let mut dev = (sum / (denom * n as f64)).sqrt();
        let tau = mf * tau0;
        if stat == Stat::Tdev {
            dev *= tau / 3f64.sqrt();
        }
        let alpha = redder(identify(x, m as usize, stat), &mut ceiling);
        let edf = edf_for(stat, alpha, mf, np as f64);
        let (lo, hi) = bounds(dev, edf);
        rows.push(Row {
            tau,
            m,
            dev,
            n,
            alpha,
            edf,
            lo,
            hi,
            estimator: Estimator::Exact,
        });
    }
    Ok(rows)
}

/// (number of terms, normaliser) of `stat` at `m` for `np` phase points, without touching the
/// data: the variance is `sum / (normaliser · n)`.
fn stat_norm(np: usize, m: usize, stat: Stat) -> (u64, f64) {
    let mf = m as f64;
    let span = stat.difference_order() as usize * m;
    let count = |stride: usize| {
        if np > span {
            ((np - span - 1) / stride + 1) as u64
        } else {
            0
        }
    };
    match stat {
        Stat::Adev => (count(m), 2.0 * mf * mf),
        Stat::Oadev => (count(1), 2.0 * mf * mf),
        Stat::Hdev => (count(m), 6.0 * mf * mf),
        Stat::Ohdev => (count(1), 6.0 * mf * mf),
        Stat::Mdev | Stat::Tdev => (
            if np > 3 * m {
                (np - 3 * m + 1) as u64
            } else {
                0
            },
            2.0 * mf.powi(4),
        ),
        Stat::Totdev => (np.saturating_sub(2) as u64, 2.0 * mf * mf),
    }
}

/// The sum of squared differences of `stat` at `m` (see [`stat_norm`] for n and the normaliser).
fn stat_sum(x: &[f64], m: usize, stat: Stat) -> f64 {
    match stat {
        Stat::Adev => diff_sum(x, m, 2, m).0,
        Stat::Oadev => diff_sum(x, m, 2, 1).0,
        Stat::Hdev => diff_sum(x, m, 3, m).0,
        Stat::Ohdev => diff_sum(x, m, 3, 1).0,
        Stat::Mdev | Stat::Tdev => mod_sum(x, m).0,
        Stat::Totdev => tot_sum(x, m).0,
    }
}

/// `f` over `items` on all available cores (scoped threads, round-robin so that the costly
/// small-m and cheap large-m items mix), results in input order.
fn par_map<T: Sync, R: Send>(items: &[T], f: impl Fn(&T) -> R + Sync) -> Vec<R> {
    let threads = std::thread::available_parallelism()
        .map_or(1, |n| n.get())
        .min(items.len().max(1));
    if threads <= 1 {
        return items.iter().map(&f).collect();
    }
    let f = &f;
    let mut parts: Vec<Vec<(usize, R)>> = std::thread::scope(|s| {
        let handles: Vec<_> = (0..threads)
            .map(|t| {
                s.spawn(move || {
                    items
                        .iter()
                        .enumerate()
                        .skip(t)
                        .step_by(threads)
                        .map(|(i, it)| (i, f(it)))
                        .collect::<Vec<_>>()
                })
            })
            .collect();
        handles
            .into_iter()
            .map(|h| h.join().expect("worker panicked"))
            .collect()
    });
    let mut out: Vec<(usize, R)> = parts.drain(..).flatten().collect();
    out.sort_by_key(|(i, _)| *i);
    out.into_iter().map(|(_, r)| r).collect()
}

fn bounds(dev: f64, edf: f64) -> (f64, f64) {
    if edf.is_finite() && edf > 0.0 {
        ci::chi2_bounds(dev, edf, ci::ONE_SIGMA)
    } else {
        (f64::NAN, f64::NAN)
    }
}

/// The noise exponent of a row, given the exponent identified at it (if any) and the one used
/// at the previous, shorter τ (`ceiling`, updated).
///
/// In a sum of power-law noises the term that dominates the Allan variance at a longer τ is
/// never bluer than the one dominating at a shorter τ, so α never increases with τ. Holding to
/// that keeps a misidentification on a few noisy averages at long τ (B1 reading white PM on
/// Markov or drift data, say) from inflating the EDF tenfold. With nothing identified the
/// previous row's exponent is kept, or white FM (0) for the first row.
fn redder(identified: Option<i32>, ceiling: &mut Option<i32>) -> i32 {
    let alpha = match (identified, *ceiling) {
        (Some(a), Some(c)) => a.min(c),
        (Some(a), None) => a,
        (None, Some(c)) => c,
        (None, None) => 0,
    };
    *ceiling = Some(alpha);
    alpha
}

/// Noise exponent at averaging factor m: lag-1 ACF with ≥ 30 averages, else B1 with R(n).
///
/// `None` when too few averages remain for either method; the caller then keeps the exponent of
/// the previous (shorter) τ, or white FM (0) if there is none.
fn identify(x: &[f64], m: usize, stat: Stat) -> Option<i32> {
    let d = stat.difference_order();
    let alpha = noise_id::acf_alpha(x, m, d).or_else(|| {
        noise_id::b1_alpha(x, m, || {
            let (sa, na) = diff_sum(x, m, 2, 1);
            let (sm, nm) = mod_sum(x, m);
            (na > 0 && nm > 0 && sa > 0.0)
                .then(|| (sm / (m as f64).powi(2) / nm as f64) / (sa / na as f64))
        })
    });
    alpha.map(|a| a.clamp(2 - 2 * d as i32, 2))
}

fn edf_for(stat: Stat, alpha: i32, m: f64, np: f64) -> f64 {
    let var = match stat {
        Stat::Adev => Variance::Unmodified {
            d: 2,
            s_factor: 1.0,
        },
        Stat::Oadev => Variance::Unmodified { d: 2, s_factor: m },
        Stat::Hdev => Variance::Unmodified {
            d: 3,
            s_factor: 1.0,
        },
        Stat::Ohdev => Variance::Unmodified { d: 3, s_factor: m },
        Stat::Mdev | Stat::Tdev => Variance::Modified,
        Stat::Totdev => return ci::edf_totdev(alpha, m, np),
    };
    ci::edf_greenhall(alpha, m, np, var).unwrap_or(f64::NAN)
}

/// The host "stride" estimator: exactly the integer sums the streaming engine
/// [`crate::Engine`]`<P, L, _>` accumulates over the same samples, computed directly from the
/// phase array. `segments` are runs of samples separated by gaps.
pub fn stride_sums(segments: &[&[i32]], p: usize, levels: usize) -> Vec<LevelSums> {
    let mut out: Vec<LevelSums> = (0..levels)
        .map(|k| {
            let m = 1u32 << k;
            LevelSums {
                m,
                stride: if m as usize <= p { 1 } else { m / p as u32 },
                ..Default::default()
            }
        })
        .collect();
    for seg in segments {
        let mut theta = Vec::with_capacity(seg.len() + 1);
        let mut acc = 0i64;
        theta.push(0i64);
        for &y in *seg {
            acc = acc.wrapping_add(y as i64);
            theta.push(acc);
        }
        let n = seg.len() as u64;
        for lv in out.iter_mut() {
            let (m, s) = (lv.m as u64, lv.stride as u64);
            let mut t = (2 * m).div_ceil(s) * s;
            while t <= n {
                let th = |i: u64| theta[i as usize] as i128;
                let d2 = th(t) - 2 * th(t - m) + th(t - 2 * m);
                lv.sum2 += (d2 * d2) as u128;
                lv.n2 += 1;
                if t >= 3 * m {
                    let d3 = th(t) - 3 * th(t - m) + 3 * th(t - 2 * m) - th(t - 3 * m);
                    lv.sum3 += (d3 * d3) as u128;
                    lv.n3 += 1;
                }
                t += s;
            }
        }
    }
    out
}

/// Table rows from streaming-engine sums: OADEV (or OHDEV with `hadamard`) in input units ×
/// `scale`, EDF by Greenhall with the estimator's stride factor S = m/stride, and the noise
/// exponent read from the slope to the neighbouring level.
pub fn stream_rows(levels: &[LevelSums], tau0: f64, scale: f64, hadamard: bool) -> Vec<Row> {
    let mut ceiling = None;
    let d = if hadamard { 3 } else { 2 };
    let var = |l: &LevelSums| if hadamard { l.ohdev(1.0) } else { l.oadev(1.0) };
    let mut rows = Vec::new();
    for (k, l) in levels.iter().enumerate() {
        let n = if hadamard { l.n3 } else { l.n2 };
        let Some(dev) = var(l).filter(|_| n >= 2) else {
            continue;
        };
        let neighbour = levels
            .get(k + 1)
            .and_then(|h| var(h).filter(|_| (if hadamard { h.n3 } else { h.n2 }) >= 2))
            .map(|v| (dev, v))
            .or_else(|| {
                k.checked_sub(1)
                    .and_then(|j| var(&levels[j]))
                    .map(|v| (v, dev))
            });
        let alpha = redder(
            neighbour.map(|(a, b)| ci::alpha_from_slope(a * a, b * b, 2.0, d)),
            &mut ceiling,
        );
        let m = l.m as f64;
        let np = (n - 1) as f64 * l.stride as f64 + d as f64 * m + 1.0;
        let edf = ci::edf_greenhall(
            alpha,
            m,
            np,
            Variance::Unmodified {
                d,
                s_factor: m / l.stride as f64,
            },
        )
        .unwrap_or(f64::NAN);
        let dev = dev * scale;
        let (lo, hi) = bounds(dev, edf);
        let estimator = if l.stride == 1 {
            Estimator::Exact
        } else {
            Estimator::Stride {
                stride: l.stride as u64,
            }
        };
        rows.push(Row {
            tau: m * tau0,
            m: l.m as u64,
            dev,
            n,
            alpha,
            edf,
            lo,
            hi,
            estimator,
        });
    }
    rows
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn term_counts_match_the_sums_and_blocking_matches_direct() {
        let x: Vec<f64> = (0..2000)
            .map(|i| ((i * 7919) % 1009) as f64 * 0.01 - (i as f64).sqrt())
            .collect();
        for np in [5usize, 17, 64, 999, 2000] {
            let x = &x[..np];
            for m in [1usize, 2, 3, 5, 16, 100, 333] {
                let counted = [
                    (Stat::Adev, diff_sum(x, m, 2, m).1),
                    (Stat::Oadev, diff_sum(x, m, 2, 1).1),
                    (Stat::Hdev, diff_sum(x, m, 3, m).1),
                    (Stat::Ohdev, diff_sum(x, m, 3, 1).1),
                    (Stat::Mdev, mod_sum(x, m).1),
                ];
                for (stat, n) in counted {
                    assert_eq!(stat_norm(np, m, stat).0, n, "{} np={np} m={m}", stat.name());
                }
            }
        }
        let ms = [1usize, 2, 4, 8, 64, 512];
        for d in [2, 3] {
            let blocked = overlapping_sums_blocked(&x, &ms, d);
            for (k, &m) in ms.iter().enumerate() {
                let direct = diff_sum(&x, m, d, 1).0;
                assert!((blocked[k] / direct - 1.0).abs() < 1e-12, "d={d} m={m}");
            }
        }
    }

    #[test]
    fn noise_exponent_goes_from_white_pm_to_random_walk_and_never_back() {
        // Quantisation-like white PM (differenced white noise) dominates short τ, a rate random
        // walk dominates long τ.
        let mut s = 0x2545_f491u32;
        let mut u = move || {
            s ^= s << 13;
            s ^= s >> 17;
            s ^= s << 5;
            s as f64 / 4_294_967_296.0 - 0.5
        };
        let (mut prev, mut walk) = (0.0, 0.0);
        let y: Vec<f64> = (0..1 << 17)
            .map(|_| {
                let w = u();
                walk += 0.002 * u();
                let v = w - prev + walk;
                prev = w;
                v
            })
            .collect();
        let rows = deviation(&y, 1.0, Stat::Oadev, &TauSet::Octave).unwrap();
        assert_eq!(rows[0].alpha, 2, "white PM at m = 1");
        assert!(
            rows.last().unwrap().alpha <= -1,
            "redder than white FM at the longest τ"
        );
        for w in rows.windows(2) {
            assert!(
                w[1].alpha <= w[0].alpha,
                "alpha rose from {} to {} at m = {}",
                w[0].alpha,
                w[1].alpha,
                w[1].m
            );
        }
    }
}
