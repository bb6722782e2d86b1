//! Exact batch estimators over a recording, with 68.3 % confidence bounds.
//!
//! Input is rate samples `y_i` (deg/s, m/s², …) taken every `τ0`. Following AllanTools
//! (`frequency2phase`), the mean rate is removed and the phase is the cumulative sum with a
//! leading zero, `x[0] = 0, x[k] = Σ_{i<k} (y_i − ȳ)` (Jaime et al., eq. 8). Working in units of
//! "rate × samples" makes `τ0` cancel from every deviation except TDEV, which is a time.
//! Removing the mean changes none of the difference-based estimators (a constant rate is a
//! linear phase, annihilated by second and third differences); it only keeps `x` small.
use crate::confidence::{self, Variance};
use crate::noise_id;
use crate::AllanError;

mod kernels;
mod phase;
mod pool;
mod stream_ref;

use kernels::{
    diff_sum, mod_sum, overlapping_partial, split_work, tot_sum, ACF_FUSED_MAX, FUSED_MAX,
};
use phase::phase_from_rate_checked;
use pool::{cores, par_map};
pub use stream_ref::{stream_rows, stride_sums};

/// The statistic to compute.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Stat {
    /// Allan deviation, non-overlapping (SP 1065 eq. 7–8).
    Adev,
    /// Overlapping Allan deviation (SP 1065 eq. 11; Jaime et al., eq. 7).
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
                // From each m straight to the first i whose m is larger (2^(i/k) ≥ m + ½): at
                // most one step per distinct m, however many points per octave (stepping every
                // i, 10⁹/octave never ended and held every duplicate in memory first).
                let k = f64::from(*k);
                let mut i = 0f64;
                loop {
                    let m = 2f64.powf(i / k).round() as u64;
                    if m > max_m {
                        break;
                    }
                    if out.last() != Some(&m) {
                        out.push(m);
                    }
                    i = (k * (m as f64 + 0.5).log2()).ceil().max(i + 1.0);
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

fn check(y: &[f64], tau0: f64) -> Result<(), AllanError> {
    if !(tau0 > 0.0 && tau0.is_finite()) {
        return Err(AllanError::BadTau0(tau0));
    }
    all_finite(y)?;
    long_enough(y)
}

/// `NotFinite` at the first sample that is NaN or infinite.
fn all_finite(y: &[f64]) -> Result<(), AllanError> {
    match y.iter().position(|v| !v.is_finite()) {
        Some(index) => Err(AllanError::NotFinite { index }),
        None => Ok(()),
    }
}

/// `TooShort` below three samples (no second difference).
fn long_enough(y: &[f64]) -> Result<(), AllanError> {
    if y.len() < 3 {
        return Err(AllanError::TooShort {
            samples: y.len(),
            needed: 3,
        });
    }
    Ok(())
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

/// The deviation `stat` of a record cut by gaps into `segments` of rate samples (every `tau0`
/// s), as the device's engine computes it: no difference spans a gap. For every m the squared
/// differences inside each segment are summed and divided by the total number of terms; the
/// noise exponent is identified on the longest segment; the EDF of a row is the sum of the
/// segments' Greenhall EDFs (the segments are independent records). A single segment gives
/// exactly [`deviation`]. Segments shorter than 3 samples contribute nothing. TOTDEV, whose
/// reflected extension is defined for one record, is refused for more than one segment.
pub fn deviation_segments(
    segments: &[&[f64]],
    tau0: f64,
    stat: Stat,
    taus: &TauSet,
) -> Result<Vec<Row>, AllanError> {
    if !(tau0 > 0.0 && tau0.is_finite()) {
        return Err(AllanError::BadTau0(tau0));
    }
    if let [one] = segments {
        return deviation(one, tau0, stat, taus);
    }
    let mut offset = 0;
    for s in segments {
        if let Some(i) = s.iter().position(|v| !v.is_finite()) {
            return Err(AllanError::NotFinite { index: offset + i });
        }
        offset += s.len();
    }
    let used: Vec<&[f64]> = segments.iter().copied().filter(|s| s.len() >= 3).collect();
    if used.is_empty() {
        return Err(AllanError::TooShort {
            samples: segments.iter().map(|s| s.len()).max().unwrap_or(0),
            needed: 3,
        });
    }
    if stat == Stat::Totdev && used.len() > 1 {
        return Err(AllanError::Unsupported(
            "totdev reflects one uninterrupted record; the data have gaps",
        ));
    }
    let phases = used
        .iter()
        .map(|s| phase_from_rate_checked(s))
        .collect::<Result<Vec<_>, _>>()?;
    let refs: Vec<&[f64]> = phases.iter().map(Vec::as_slice).collect();
    deviation_of_phases(&refs, tau0, stat, taus)
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
    deviation_of_phases(&[x], tau0, stat, taus)
}

/// The sums of one phase record at the averaging factors `ms` (each with at least one term in
/// it), with the per-τ noise identification on the record.
struct PhaseSums {
    /// Σ of the statistic's squared differences, per m.
    sums: Vec<f64>,
    /// What identification found, per m.
    idents: Vec<Ident>,
}

/// [`PhaseSums`] of the phase `x`: overlapping sums in fused passes over groups of m, each
/// split by start index over the cores, carrying the identification sums of the short τ; the
/// other statistics one m at a time. Identification of the rest is O(N/m) per m. Without
/// `with_ident` only the sums are taken (the idents are left empty).
fn phase_sums(x: &[f64], ms: &[u64], stat: Stat, with_ident: bool) -> PhaseSums {
    let d = stat.difference_order();
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
        with_ident
            && m as usize <= ACF_FUSED_MAX
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
            .filter(|&row| with_ident && idents[row] != Ident::Fused)
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
    PhaseSums { sums, idents }
}

/// The rows of `stat` over phase records separated by gaps (`phases`, in rate × samples): the
/// sums of every record added, the terms counted per record, the noise identified on the
/// longest record and the EDF summed over the records (module docs of [`deviation_segments`]).
fn deviation_of_phases(
    phases: &[&[f64]],
    tau0: f64,
    stat: Stat,
    taus: &TauSet,
) -> Result<Vec<Row>, AllanError> {
    let longest = phases
        .iter()
        .enumerate()
        .max_by_key(|(i, x)| (x.len(), usize::MAX - i))
        .map_or(0, |(i, _)| i);
    let np_max = phases.get(longest).map_or(0, |x| x.len()) as u64;
    let terms = |m: u64| -> u64 {
        phases
            .iter()
            .map(|x| stat_norm(x.len(), m as usize, stat).0)
            .sum()
    };
    let ms: Vec<u64> = taus
        .ms(largest_m(stat, np_max))?
        .into_iter()
        .filter(|&m| terms(m) >= 2)
        .collect();
    let mut sums = vec![0.0f64; ms.len()];
    let mut long: Option<PhaseSums> = None;
    for (k, x) in phases.iter().enumerate() {
        // The m with a term in this record: a prefix of the ascending ms.
        let own = ms
            .iter()
            .take_while(|&&m| stat_norm(x.len(), m as usize, stat).0 >= 1)
            .count();
        if own == 0 {
            continue;
        }
        let ps = phase_sums(x, &ms[..own], stat, true);
        for (t, v) in sums.iter_mut().zip(&ps.sums) {
            *t += v;
        }
        if k == longest {
            long = Some(ps);
        }
    }
    let Some(long) = long.filter(|_| !ms.is_empty()) else {
        return Ok(Vec::new());
    };
    let x = phases[longest];
    let d = stat.difference_order();
    let mut rows = Vec::with_capacity(ms.len());
    let mut ceiling = None;
    for (row, &m) in ms.iter().enumerate() {
        let denom = stat_norm(x.len(), m as usize, stat).1;
        let n = terms(m);
        let sum = sums[row];
        let mf = m as f64;
        let mut dev = (sum / (denom * n as f64)).sqrt();
        let tau = mf * tau0;
        if stat == Stat::Tdev {
            dev *= tau / 3f64.sqrt();
        }
        let identified = match long.idents[row] {
            Ident::Alpha(a) => a,
            Ident::Fused => unreachable!("resolved in phase_sums"),
            // Either answer is capped by a ceiling of 1 or less: R(n) would change nothing.
            Ident::Pm if m == 1 || ceiling.is_some_and(|c| c <= 1) => Some(2),
            Ident::Pm => {
                let m = m as usize;
                let (sa, na) = if stat == Stat::Oadev {
                    (long.sums[row], stat_norm(x.len(), m, stat).0)
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
        // Records are independent: their degrees of freedom add.
        let edf: f64 = phases
            .iter()
            .filter(|p| stat_norm(p.len(), m as usize, stat).0 >= 1)
            .map(|p| edf_for(stat, alpha, mf, p.len() as f64))
            .filter(|e| e.is_finite())
            .sum();
        let edf = if edf > 0.0 { edf } else { f64::NAN };
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

/// The plain estimate of `stat` at each averaging factor in `ms`: (deviation, number of terms),
/// without noise identification or bounds — what AllanTools returns. `data` is rate samples, or
/// phase in s when `is_phase`, every `tau0` s. Every m with at least one term is computed, TOTDEV
/// at any m below the number of phase points N as AllanTools does (the tables stop at
/// (N − 1)/2, [`deviation`]); an m with no term gives (NaN, 0). The m are shared among the cores.
pub fn plain_deviations(
    data: &[f64],
    tau0: f64,
    stat: Stat,
    ms: &[u64],
    is_phase: bool,
) -> Result<Vec<(f64, u64)>, AllanError> {
    check(data, tau0)?;
    if ms.contains(&0) {
        return Err(AllanError::BadTauSet("m = 0 in the list"));
    }
    let x = if is_phase {
        data.iter().map(|v| v / tau0).collect()
    } else {
        phase_from_rate_checked(data)?
    };
    let np = x.len();
    if matches!(stat, Stat::Oadev | Stat::Ohdev) {
        // One cache-blocked pass for all m (ascending, each with a term), no identification.
        let mut own: Vec<u64> = ms
            .iter()
            .copied()
            .filter(|&m| stat_norm(np, m as usize, stat).0 >= 1)
            .collect();
        own.sort_unstable();
        own.dedup();
        let sums = phase_sums(&x, &own, stat, false).sums;
        return Ok(ms
            .iter()
            .map(|&m| match own.binary_search(&m) {
                Ok(k) => {
                    let (n, denom) = stat_norm(np, m as usize, stat);
                    ((sums[k] / (denom * n as f64)).sqrt(), n)
                }
                Err(_) => (f64::NAN, 0),
            })
            .collect());
    }
    Ok(par_map(ms, |&m| {
        let m = m as usize;
        let (n, denom) = stat_norm(np, m, stat);
        if n == 0 || m >= np {
            return (f64::NAN, 0);
        }
        let mut dev = (stat_sum(&x, m, stat) / (denom * n as f64)).sqrt();
        if stat == Stat::Tdev {
            dev *= m as f64 * tau0 / 3f64.sqrt();
        }
        (dev, n)
    }))
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

pub(super) fn bounds(dev: f64, edf: f64) -> (f64, f64) {
    if edf.is_finite() && edf > 0.0 {
        confidence::chi2_bounds(dev, edf, confidence::ONE_SIGMA)
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
pub(super) fn redder(identified: Option<i32>, ceiling: &mut Option<i32>) -> i32 {
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
        Stat::Totdev => return confidence::edf_totdev(alpha, m, np),
    };
    confidence::edf_greenhall(alpha, m, np, var).unwrap_or(f64::NAN)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `N/octave` is every distinct round(2^(i/N)) up to the largest m, as stepping i one by
    /// one gives (drawn N and largest m), and a huge N is every m, at once.
    #[test]
    fn per_octave_points_are_the_distinct_rounded_powers() {
        let key = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(1, |d| d.subsec_nanos());
        for j in 0..40u32 {
            let k = 1 + (key.wrapping_mul(j + 1) >> 3) % 200;
            let max_m = 1 + u64::from(key.wrapping_add(j * 7919) % 100_000);
            let mut want = Vec::new();
            let mut i = 0u32;
            loop {
                let m = 2f64.powf(f64::from(i) / f64::from(k)).round() as u64;
                if m > max_m {
                    break;
                }
                want.push(m);
                i += 1;
            }
            want.dedup();
            assert_eq!(
                TauSet::PerOctave(k).ms(max_m).unwrap(),
                want,
                "key {key}: {k}/octave to {max_m}"
            );
        }
        let all: Vec<u64> = (1..=5000).collect();
        assert_eq!(TauSet::PerOctave(u32::MAX).ms(5000).unwrap(), all);
    }

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

    #[test]
    fn plain_deviations_are_the_table_without_bounds_and_totdev_reaches_n_minus_1() {
        let key = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(7, |d| d.subsec_nanos() | 1);
        let mut r = crate::test_rng::rng(key);
        let np = 300 + (key % 200) as usize;
        let y: Vec<f64> = (0..np).map(|_| r() + 3.0).collect();
        let tau0 = 0.01;
        let ms: Vec<u64> = (1..np as u64 + 2).collect();
        for stat in [
            Stat::Adev,
            Stat::Oadev,
            Stat::Mdev,
            Stat::Tdev,
            Stat::Hdev,
            Stat::Ohdev,
            Stat::Totdev,
        ] {
            let rows = deviation(&y, tau0, stat, &TauSet::All).unwrap();
            let plain = plain_deviations(&y, tau0, stat, &ms, false).unwrap();
            for row in &rows {
                let (dev, n) = plain[row.m as usize - 1];
                assert_eq!(n, row.n, "key {key} {stat:?} m {}", row.m);
                assert!(
                    (dev / row.dev - 1.0).abs() < 1e-12,
                    "key {key} {stat:?} m {}",
                    row.m
                );
            }
        }
        // Any order, repeats allowed: each m answered where it stands.
        let shuffled: Vec<u64> = ms.iter().rev().chain(&ms[..5]).copied().collect();
        for stat in [Stat::Oadev, Stat::Ohdev, Stat::Mdev] {
            let sorted = plain_deviations(&y, tau0, stat, &ms, false).unwrap();
            let any = plain_deviations(&y, tau0, stat, &shuffled, false).unwrap();
            for (m, got) in shuffled.iter().zip(&any) {
                let want = sorted[*m as usize - 1];
                assert_eq!(got.1, want.1, "{stat:?} m {m}");
                assert!(
                    got.0 == want.0 || (got.0.is_nan() && want.0.is_nan()),
                    "{stat:?} m {m}"
                );
            }
        }
        // TOTDEV past the table's (N−1)/2, against SP 1065 eq. 25 written out: the phase
        // reflected at both ends, N − 2 terms.
        let x: Vec<f64> = std::iter::once(0.0)
            .chain(y.iter().scan(0.0, |s, v| {
                *s += v - y.iter().sum::<f64>() / y.len() as f64;
                Some(*s)
            }))
            .collect();
        let n = x.len() as isize;
        let at = |i: isize| {
            if i < 0 {
                2.0 * x[0] - x[(-i) as usize]
            } else if i >= n {
                2.0 * x[n as usize - 1] - x[(2 * (n - 1) - i) as usize]
            } else {
                x[i as usize]
            }
        };
        let plain = plain_deviations(&y, tau0, Stat::Totdev, &ms, false).unwrap();
        for m in [n / 2 + 1, n - 2, n - 1] {
            let s: f64 = (1..n - 1)
                .map(|i| (at(i - m) - 2.0 * at(i) + at(i + m)).powi(2))
                .sum();
            let want = (s / (2.0 * (m * m) as f64 * (n - 2) as f64)).sqrt();
            let (dev, terms) = plain[m as usize - 1];
            assert_eq!(terms, (n - 2) as u64);
            assert!(
                (dev / want - 1.0).abs() < 1e-9,
                "key {key} m {m}: {dev} vs {want}"
            );
        }
        // No term: NaN and 0; bad input named.
        assert_eq!(plain[np].1, 0);
        assert!(plain[np].0.is_nan());
        let mut bad = y.clone();
        bad[17] = f64::NAN;
        assert_eq!(
            plain_deviations(&bad, tau0, Stat::Oadev, &[1], false),
            Err(AllanError::NotFinite { index: 17 })
        );
    }
}
