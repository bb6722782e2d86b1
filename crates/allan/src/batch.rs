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
#[cfg(test)]
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

/// Σ (v − shift) in eight independent lanes (vectorisable; the order differs from a
/// sequential sum only in rounding).
fn lane_sum(y: &[f64], shift: f64) -> f64 {
    let mut acc = [0.0f64; LANES];
    let mut c = y.chunks_exact(LANES);
    for v in &mut c {
        for l in 0..LANES {
            acc[l] += v[l] - shift;
        }
    }
    acc.iter().sum::<f64>() + c.remainder().iter().map(|v| v - shift).sum::<f64>()
}

/// The same phase as [`phase_from_rate`] (equal up to rounding), built on all cores: each
/// core sums its share of the samples, then writes its share of the cumulative sum starting
/// from the sum of the shares before it. The sums are taken about the first sample, so a
/// large mean rate (gravity on an accelerometer) does not cost the shares' starting values
/// their low bits. The zeroed buffer is fresh from the allocator, so its pages are first
/// touched (and faulted in) by the cores that write them. Checks the input on the way: a
/// non-finite sample makes the total non-finite, and only then is it looked for.
fn phase_from_rate_checked(y: &[f64]) -> Result<Vec<f64>, AllanError> {
    // Several shares a core, so a core that is held up (shared machine) delays little.
    let threads = (4 * cores()).min(y.len() / (1 << 16)).max(1);
    let chunk = y.len().div_ceil(threads).max(1);
    let shift = y.first().copied().unwrap_or(0.0);
    let sums: Vec<f64> = if threads == 1 {
        vec![lane_sum(y, shift)]
    } else {
        std::thread::scope(|s| {
            let hs: Vec<_> = y
                .chunks(chunk)
                .map(|c| s.spawn(move || lane_sum(c, shift)))
                .collect();
            hs.into_iter()
                .map(|h| h.join().expect("worker panicked"))
                .collect()
        })
    };
    let total: f64 = sums.iter().sum();
    if !(total.is_finite() && shift.is_finite()) {
        if let Some(index) = y.iter().position(|v| !v.is_finite()) {
            return Err(AllanError::NotFinite { index });
        }
    }
    if y.len() < 3 {
        return Err(AllanError::TooShort {
            samples: y.len(),
            needed: 3,
        });
    }
    let mean = shift + total / y.len() as f64;
    let mut x = vec![0.0f64; y.len() + 1];
    advise_huge_pages(&mut x);
    let fill = |out: &mut [f64], ys: &[f64], mut acc: f64| {
        for (o, v) in out.iter_mut().zip(ys) {
            acc += v - mean;
            *o = acc;
        }
    };
    if threads == 1 {
        fill(&mut x[1..], y, 0.0);
    } else {
        std::thread::scope(|s| {
            let mut start = 0.0;
            for ((out, ys), sum) in x[1..].chunks_mut(chunk).zip(y.chunks(chunk)).zip(&sums) {
                let acc = start;
                s.spawn(move || fill(out, ys, acc));
                start += sum - ys.len() as f64 * (mean - shift);
            }
        });
    }
    Ok(x)
}

/// Ask Linux to back the 2 MiB-aligned interior of a fresh, not yet touched buffer with
/// transparent huge pages (`madvise(MADV_HUGEPAGE)`; this machine class runs THP in `madvise`
/// mode). Filling a 43 MB phase otherwise takes ~10,000 page faults, about a quarter of the
/// whole computation; with huge pages it takes ~20. Advice only: contents are unchanged, and a
/// refusal (or another OS) just leaves small pages.
#[cfg(target_os = "linux")]
fn advise_huge_pages(buf: &mut [f64]) {
    const HUGE: usize = 2 << 20;
    let start = buf.as_mut_ptr() as usize;
    let end = start + std::mem::size_of_val(buf);
    let (lo, hi) = (start.next_multiple_of(HUGE), end / HUGE * HUGE);
    if hi > lo {
        // SAFETY: madvise(2) on whole pages inside memory this buffer owns; MADV_HUGEPAGE does
        // not change contents, and the result is deliberately ignored (advice only).
        unsafe {
            libc::madvise(lo as *mut libc::c_void, hi - lo, libc::MADV_HUGEPAGE);
        }
    }
}

#[cfg(not(target_os = "linux"))]
fn advise_huge_pages(_: &mut [f64]) {}

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
///
/// On x86-64 CPUs with AVX2 and FMA (checked at run time, cached by std) a copy compiled for
/// them runs: four lanes a register and fused multiply-adds, which round once where the
/// portable code rounds twice (a difference in the last bit of a term).
fn accumulate(x: &[f64], m: usize, d: u32, i0: usize, i1: usize, acc: &mut [f64; LANES]) -> f64 {
    #[cfg(target_arch = "x86_64")]
    if std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("fma") {
        // SAFETY: the CPU has the features the copy was compiled for.
        return unsafe { accumulate_avx2_fma(x, m, d, i0, i1, acc) };
    }
    accumulate_lanes::<false>(x, m, d, i0, i1, acc)
}

/// [`accumulate`] in AVX2 registers: the eight lanes are two 4-wide vectors, each term
/// `v = (c − 2b) + a` (or `(e − a) + 3(b − c)`) and `acc += v²` by fused multiply-adds. Written
/// with intrinsics so that it vectorises whatever the optimisation level (the workspace's
/// release profile optimises for size, which turns the auto-vectoriser off).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn accumulate_avx2_fma(
    x: &[f64],
    m: usize,
    d: u32,
    i0: usize,
    i1: usize,
    acc: &mut [f64; LANES],
) -> f64 {
    use std::arch::x86_64::*;
    let n = i1 - i0;
    let full = n / LANES * LANES;
    // Every load below is inside x: the last one starts at i1 − 4 + d·m.
    assert!(i1 + d as usize * m <= x.len());
    let p = x.as_ptr();
    // SAFETY: `acc` holds 8 f64, and every x index is in bounds by the assertion above.
    unsafe {
        let mut lo = _mm256_loadu_pd(acc.as_ptr());
        let mut hi = _mm256_loadu_pd(acc.as_ptr().add(4));
        // A macro, not closures or an inner loop: the body must inherit this function's
        // features and keep both accumulators in registers at any optimisation level.
        macro_rules! second {
            ($j:expr) => {{
                let j = $j;
                let c = _mm256_loadu_pd(p.add(j + 2 * m));
                let v = _mm256_fmadd_pd(_mm256_set1_pd(-2.0), _mm256_loadu_pd(p.add(j + m)), c);
                _mm256_add_pd(v, _mm256_loadu_pd(p.add(j)))
            }};
        }
        macro_rules! third {
            ($j:expr) => {{
                let j = $j;
                let (a, b) = (_mm256_loadu_pd(p.add(j)), _mm256_loadu_pd(p.add(j + m)));
                let c = _mm256_loadu_pd(p.add(j + 2 * m));
                let e = _mm256_loadu_pd(p.add(j + 3 * m));
                _mm256_fmadd_pd(
                    _mm256_set1_pd(3.0),
                    _mm256_sub_pd(b, c),
                    _mm256_sub_pd(e, a),
                )
            }};
        }
        let mut i = i0;
        if d == 2 {
            while i < i0 + full {
                let (v, w) = (second!(i), second!(i + 4));
                lo = _mm256_fmadd_pd(v, v, lo);
                hi = _mm256_fmadd_pd(w, w, hi);
                i += LANES;
            }
        } else {
            while i < i0 + full {
                let (v, w) = (third!(i), third!(i + 4));
                lo = _mm256_fmadd_pd(v, v, lo);
                hi = _mm256_fmadd_pd(w, w, hi);
                i += LANES;
            }
        }
        _mm256_storeu_pd(acc.as_mut_ptr(), lo);
        _mm256_storeu_pd(acc.as_mut_ptr().add(4), hi);
    }
    let mut rest = [0.0f64; LANES];
    accumulate_lanes::<true>(x, m, d, i0 + full, i1, &mut rest) + rest.iter().sum::<f64>()
}

/// The body of [`accumulate`]; `FMA` only where the target has fused multiply-add in hardware
/// (elsewhere `mul_add` is a slow library call).
#[inline(always)]
fn accumulate_lanes<const FMA: bool>(
    x: &[f64],
    m: usize,
    d: u32,
    i0: usize,
    i1: usize,
    acc: &mut [f64; LANES],
) -> f64 {
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
                if FMA {
                    let v = (-2.0f64).mul_add(b[l], c[l]) + a[l];
                    acc[l] = v.mul_add(v, acc[l]);
                } else {
                    let v = c[l] - 2.0 * b[l] + a[l];
                    acc[l] += v * v;
                }
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
                if FMA {
                    let v = 3.0f64.mul_add(b[l] - c[l], e[l] - a[l]);
                    acc[l] = v.mul_add(v, acc[l]);
                } else {
                    let v = e[l] - 3.0 * c[l] + 3.0 * b[l] - a[l];
                    acc[l] += v * v;
                }
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

/// Start indices per block of the fused pass. A block reads `BLOCK` phase values at each
/// shift k·m (k = 0 … d) and sums every m of the group over them; for octave m the shift 2m
/// of one m is the shift m of the next (still in L1), so 22 octaves read 23 shifted blocks of
/// 16 KiB, those up to a few MiB ahead already in L2 from earlier blocks, the farthest from
/// L3. One pass serves every m instead of one pass per m.
const BLOCK: usize = 2048;
/// Most m summed in one fused pass (more shifted blocks would fall out of L2).
const FUSED_MAX: usize = 32;

/// Largest m whose noise-identification sums ride along the fused pass; beyond it the
/// averages are few and far apart and a pass of their own costs little.
const ACF_FUSED_MAX: usize = 256;

/// Fully overlapping sums of squared d-th differences for every m in `ms` over the start
/// indices `lo..hi` (each m clipped to its own last start), in one cache-blocked pass, and the
/// noise-identification sums ([`noise_id::AvgSums`]) of the averages over the first `acf` of
/// the `ms` that start in `lo..hi` (to the end of the record when `tail`).
fn overlapping_partial(
    x: &[f64],
    ms: &[usize],
    d: u32,
    (lo, hi): (usize, usize),
    acf: usize,
    tail: bool,
) -> (Vec<f64>, Vec<noise_id::AvgSums>) {
    let mut acc = vec![[0.0f64; LANES]; ms.len()];
    let mut tails = vec![0.0f64; ms.len()];
    let mut avg = vec![noise_id::AvgSums::default(); acf];
    let ends: Vec<usize> = ms
        .iter()
        .map(|&m| x.len().saturating_sub(d as usize * m).min(hi))
        .collect();
    let mut i0 = lo;
    while i0 < hi {
        let i1 = (i0 + BLOCK).min(hi);
        for (k, &m) in ms.iter().enumerate() {
            let e = i1.min(ends[k]);
            if e > i0 {
                tails[k] += accumulate(x, m, d, i0, e, &mut acc[k]);
            }
        }
        for (a, &m) in avg.iter_mut().zip(ms) {
            let j1 = if tail && i1 == hi {
                usize::MAX
            } else {
                i1.div_ceil(m)
            };
            a.add(x, m, i0.div_ceil(m), j1);
        }
        i0 = i1;
    }
    let sums = acc
        .iter()
        .zip(tails)
        .map(|(a, t)| a.iter().sum::<f64>() + t)
        .collect();
    (sums, avg)
}

/// Split the start indices of the fused pass over `ms` into `pieces` ranges of about equal
/// work (m has `len − d·m` starts, so the ranges near the end serve fewer m).
fn split_work(len: usize, ms: &[usize], d: u32, pieces: usize) -> Vec<(usize, usize)> {
    let ends: Vec<usize> = ms
        .iter()
        .map(|&m| len.saturating_sub(d as usize * m))
        .collect();
    let last = ends.iter().copied().max().unwrap_or(0);
    let work = |a: usize| ends.iter().map(|&e| e.min(a) as u128).sum::<u128>();
    let total = work(last);
    let mut cuts = vec![0usize];
    for p in 1..pieces {
        let target = total * p as u128 / pieces as u128;
        let (mut lo, mut hi) = (*cuts.last().unwrap(), last);
        while lo < hi {
            let mid = lo + (hi - lo) / 2;
            if work(mid) < target {
                lo = mid + 1;
            } else {
                hi = mid;
            }
        }
        cuts.push(lo);
    }
    cuts.push(last);
    cuts.windows(2)
        .filter(|w| w[1] > w[0])
        .map(|w| (w[0], w[1]))
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
    if !(tau0 > 0.0 && tau0.is_finite()) {
        return Err(AllanError::BadTau0(tau0));
    }
    let x = phase_from_rate_checked(y)?;
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

/// A unit of work of [`deviation_of_phase`], in the order handed to the cores (costliest first).
enum Job {
    /// Fused overlapping sums (and identification sums) of group `group` over start indices
    /// `range`; `tail` for the last range.
    Fused {
        group: usize,
        range: (usize, usize),
        tail: bool,
    },
    /// The sum of the statistic at row `row` on its own.
    Single { row: usize },
    /// Noise identification at row `row` on its own.
    Identify { row: usize },
}

enum Done {
    Fused(Vec<f64>, Vec<noise_id::AvgSums>),
    Single(f64),
    Identify(Ident),
}

/// What the per-τ noise identification found before the rows are put in order.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Ident {
    /// An exponent (or nothing identifiable).
    Alpha(Option<i32>),
    /// B1 says phase modulation; white (2) or flicker (1) needs the measured R(n), which is
    /// computed only if the exponent ceiling of the shorter τ leaves the choice open.
    Pm,
    /// The lag-1 ACF sums come from the fused pass.
    Fused,
}

fn deviation_of_phase(
    x: &[f64],
    tau0: f64,
    stat: Stat,
    taus: &TauSet,
) -> Result<Vec<Row>, AllanError> {
    let np = x.len() as u64;
    let ms: Vec<u64> = taus
        .ms(largest_m(stat, np))?
        .into_iter()
        .filter(|&m| stat_norm(x.len(), m as usize, stat).0 >= 2)
        .collect();
    let d = stat.difference_order();
    // Overlapping sums: fused passes over groups of m, each split by start index over the
    // cores, carrying the identification sums of the short τ; the other statistics one m at a
    // time. Identification of the rest is O(N/m) per m.
    let fused = matches!(stat, Stat::Oadev | Stat::Ohdev);
    let groups: Vec<&[u64]> = if fused {
        ms.chunks(FUSED_MAX).collect()
    } else {
        Vec::new()
    };
    let group_ms: Vec<Vec<usize>> = groups
        .iter()
        .map(|g| g.iter().map(|&m| m as usize).collect())
        .collect();
    let acf_fused = |m: u64| {
        m as usize <= ACF_FUSED_MAX
            && noise_id::averages(x.len(), m as usize) >= noise_id::ACF_MIN_AVERAGES
    };
    // Fused identification sums are taken for a prefix of each group (ascending m).
    let group_acf: Vec<usize> = groups
        .iter()
        .map(|g| g.iter().take_while(|&&m| acf_fused(m)).count())
        .collect();
    let mut jobs = Vec::new();
    for (g, group) in group_ms.iter().enumerate() {
        // Several pieces a core, taken as they come: a core held up delays little.
        let ranges = split_work(x.len(), group, d, 8 * cores());
        let last = ranges.len().saturating_sub(1);
        for (k, &range) in ranges.iter().enumerate() {
            let tail = k == last;
            jobs.push(Job::Fused {
                group: g,
                range,
                tail,
            });
        }
    }
    if !fused {
        jobs.extend((0..ms.len()).map(|row| Job::Single { row }));
    }
    let mut idents = vec![Ident::Alpha(None); ms.len()];
    for (g, &count) in group_acf.iter().enumerate() {
        let first = g * FUSED_MAX;
        idents[first..first + count].fill(Ident::Fused);
    }
    jobs.extend(
        (0..ms.len())
            .filter(|&row| idents[row] != Ident::Fused)
            .map(|row| Job::Identify { row }),
    );
    let done = par_map(&jobs, |job| match *job {
        Job::Fused { group, range, tail } => {
            let (s, a) = overlapping_partial(x, &group_ms[group], d, range, group_acf[group], tail);
            Done::Fused(s, a)
        }
        Job::Single { row } => Done::Single(stat_sum(x, ms[row] as usize, stat)),
        Job::Identify { row } => Done::Identify(identify(x, ms[row] as usize, d)),
    });
    let mut sums = vec![0.0f64; ms.len()];
    let mut avg = vec![noise_id::AvgSums::default(); ms.len()];
    for (job, out) in jobs.iter().zip(done) {
        match (job, out) {
            (Job::Fused { group, .. }, Done::Fused(part, a)) => {
                let first = group * FUSED_MAX;
                for (k, v) in part.into_iter().enumerate() {
                    sums[first + k] += v;
                }
                for (k, v) in a.iter().enumerate() {
                    avg[first + k].merge(v);
                }
            }
            (Job::Single { row }, Done::Single(v)) => sums[*row] = v,
            (Job::Identify { row }, Done::Identify(id)) => idents[*row] = id,
            _ => unreachable!("job and result kinds match"),
        }
    }
    for (row, id) in idents.iter_mut().enumerate() {
        if *id == Ident::Fused {
            let m = ms[row] as usize;
            *id = Ident::Alpha(noise_id::acf_alpha_from_sums(x, m, d, &avg[row]));
        }
    }
    let mut rows = Vec::with_capacity(ms.len());
    let mut ceiling = None;
    for (row, &m) in ms.iter().enumerate() {
        let (n, denom) = stat_norm(x.len(), m as usize, stat);
        let sum = sums[row];
        let mf = m as f64;
        let mut dev = (sum / (denom * n as f64)).sqrt();
        let tau = mf * tau0;
        if stat == Stat::Tdev {
            dev *= tau / 3f64.sqrt();
        }
        let identified = match idents[row] {
            Ident::Alpha(a) => a,
            Ident::Fused => unreachable!("resolved above"),
            // Either answer is capped by a ceiling of 1 or less: R(n) would change nothing.
            Ident::Pm if m == 1 || ceiling.is_some_and(|c| c <= 1) => Some(2),
            Ident::Pm => {
                let m = m as usize;
                let (sa, na) = if stat == Stat::Oadev {
                    (sum, n)
                } else {
                    diff_sum(x, m, 2, 1)
                };
                let (sm, nm) = mod_sum(x, m);
                let rn = (na > 0 && nm > 0 && sa > 0.0)
                    .then(|| (sm / (m as f64).powi(2) / nm as f64) / (sa / na as f64));
                Some(noise_id::pm_alpha(m, rn))
            }
        };
        let alpha = redder(
            identified.map(|a| a.clamp(2 - 2 * d as i32, 2)),
            &mut ceiling,
        );
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

fn cores() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get())
}

/// `f` over `items` on all available cores (scoped threads, each taking the next untaken item,
/// so with the costliest items first the cores finish together), results in input order.
fn par_map<T: Sync, R: Send>(items: &[T], f: impl Fn(&T) -> R + Sync) -> Vec<R> {
    use std::sync::atomic::{AtomicUsize, Ordering};
    let threads = cores().min(items.len().max(1));
    if threads <= 1 {
        return items.iter().map(&f).collect();
    }
    let (f, next) = (&f, &AtomicUsize::new(0));
    let mut parts: Vec<Vec<(usize, R)>> = std::thread::scope(|s| {
        let handles: Vec<_> = (0..threads)
            .map(|_| {
                s.spawn(move || {
                    let mut out = Vec::new();
                    loop {
                        let i = next.fetch_add(1, Ordering::Relaxed);
                        let Some(it) = items.get(i) else { break };
                        out.push((i, f(it)));
                    }
                    out
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

/// Noise exponent at averaging factor m: lag-1 ACF with ≥ 30 averages, else B1 (R(n) left to
/// the caller, see [`Ident::Pm`]).
///
/// `Alpha(None)` when too few averages remain for either method; the caller then keeps the
/// exponent of the previous (shorter) τ, or white FM (0) if there is none.
fn identify(x: &[f64], m: usize, d: u32) -> Ident {
    if let Some(a) = noise_id::acf_alpha_from_phase(x, m, d) {
        return Ident::Alpha(Some(a));
    }
    match noise_id::b1_mu(x, m) {
        None => Ident::Alpha(None),
        Some(-2) => Ident::Pm,
        Some(mu) => Ident::Alpha(Some(-mu - 1)),
    }
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
/// [`crate::Engine`]`<P, L, _, _>` accumulates over the same samples, computed directly from the
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
    use crate::test_rng::rng;

    #[test]
    fn term_counts_match_the_sums() {
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
    }

    /// Σ over i0..i1 of the squared d-th difference at lag m, term by term.
    fn straightforward(x: &[f64], m: usize, d: u32, i0: usize, i1: usize) -> f64 {
        (i0..i1)
            .map(|i| {
                let v = if d == 2 {
                    x[i + 2 * m] - 2.0 * x[i + m] + x[i]
                } else {
                    x[i + 3 * m] - 3.0 * x[i + 2 * m] + 3.0 * x[i + m] - x[i]
                };
                v * v
            })
            .sum()
    }

    #[test]
    fn difference_kernels_match_the_formula_on_random_data() {
        let mut u = rng(0x1234_5678);
        let mut acc = 0.0;
        let x: Vec<f64> = (0..30_011)
            .map(|_| {
                acc += 9.81 + u();
                acc
            })
            .collect();
        for d in [2u32, 3] {
            for (m, i0, i1) in [
                (1usize, 0usize, 29_000usize),
                (3, 5, 13),
                (64, 101, 20_000),
                (997, 7, 27_000),
            ] {
                let want = straightforward(&x, m, d, i0, i1);
                let mut lanes = [0.0; LANES];
                let tail = accumulate_lanes::<false>(&x, m, d, i0, i1, &mut lanes);
                let portable = lanes.iter().sum::<f64>() + tail;
                let mut lanes = [0.0; LANES];
                let tail = accumulate(&x, m, d, i0, i1, &mut lanes);
                let dispatched = lanes.iter().sum::<f64>() + tail;
                for got in [portable, dispatched] {
                    assert!(
                        (got / want - 1.0).abs() < 1e-11,
                        "d={d} m={m}: {got} vs {want}"
                    );
                }
            }
        }
    }

    #[test]
    fn fused_pass_matches_direct_sums_however_split() {
        let mut u = rng(0x0bad_cafe);
        let mut acc = 0.0;
        let x: Vec<f64> = (0..50_001)
            .map(|i| {
                acc += u() + if i % 7000 < 3500 { 0.1 } else { -0.1 };
                acc
            })
            .collect();
        for d in [2u32, 3] {
            for ms in [
                vec![
                    1usize, 2, 4, 8, 16, 32, 64, 128, 256, 512, 1024, 2048, 4096, 8192,
                ],
                vec![1, 3, 10, 30, 100, 5000, 16_000],
            ] {
                let n_acf = ms
                    .iter()
                    .take_while(|&&m| noise_id::averages(x.len(), m) >= 30)
                    .count();
                for pieces in [1usize, 2, 5] {
                    let ranges = split_work(x.len(), &ms, d, pieces);
                    let mut sums = vec![0.0; ms.len()];
                    let mut avg = vec![noise_id::AvgSums::default(); n_acf];
                    for (k, &r) in ranges.iter().enumerate() {
                        let (s, a) =
                            overlapping_partial(&x, &ms, d, r, n_acf, k + 1 == ranges.len());
                        sums.iter_mut().zip(s).for_each(|(t, v)| *t += v);
                        avg.iter_mut().zip(&a).for_each(|(t, v)| t.merge(v));
                    }
                    for (k, &m) in ms.iter().enumerate() {
                        let want = straightforward(&x, m, d, 0, x.len() - d as usize * m);
                        assert!(
                            (sums[k] / want - 1.0).abs() < 1e-11,
                            "d={d} m={m} pieces={pieces}"
                        );
                        if k < n_acf {
                            let mut whole = noise_id::AvgSums::default();
                            whole.add(&x, m, 0, usize::MAX);
                            let (a, b) = (avg[k], whole);
                            for (p, q) in [
                                (a.sb, b.sb),
                                (a.stb, b.stb),
                                (a.sbb, b.sbb),
                                (a.sbb1, b.sbb1),
                            ] {
                                assert!(
                                    (p - q).abs() <= 1e-9 * q.abs().max(1.0),
                                    "m={m}: {p} vs {q}"
                                );
                            }
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn parallel_phase_matches_the_sequential_one_and_checks_the_input() {
        let mut u = rng(0x5eed);
        let y: Vec<f64> = (0..300_000).map(|_| 9.81 + u()).collect();
        let (a, b) = (phase_from_rate(&y), phase_from_rate_checked(&y).unwrap());
        assert_eq!(a.len(), b.len());
        // Both round: a sequential sum of n samples near ȳ is itself uncertain by ~n·|ȳ|·ε.
        // A different rounding of the mean is a linear phase (no difference sees it), so that
        // is taken out before comparing.
        let tol = 4.0 * y.len() as f64 * 9.81 * f64::EPSILON;
        let n = y.len() as f64;
        let drift = (a[y.len()] - b[y.len()]) / n;
        for (k, (p, q)) in a.iter().zip(&b).enumerate() {
            let e = p - q - drift * k as f64;
            assert!(e.abs() < tol, "k = {k}: {p} vs {q}");
        }
        let mut bad = y.clone();
        bad[200_000] = f64::NAN;
        bad[250_000] = f64::INFINITY;
        assert_eq!(
            phase_from_rate_checked(&bad),
            Err(AllanError::NotFinite { index: 200_000 })
        );
        assert_eq!(
            phase_from_rate_checked(&[1.0, 2.0]),
            Err(AllanError::TooShort {
                samples: 2,
                needed: 3
            })
        );
        assert_eq!(
            phase_from_rate_checked(&[1.0, f64::NAN]),
            Err(AllanError::NotFinite { index: 1 })
        );
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
