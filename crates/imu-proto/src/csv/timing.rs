//! What the time column of a recording says: the sample clock, gaps, duplicated, jittered and
//! bursty stamps, and the segments between gaps.
use std::fmt;
use std::ops::Range;

/// A spacing longer than this many nominal periods may be a gap ([`is_gap`]).
pub const GAP_FACTOR: f64 = 1.5;
/// A spacing between [`GAP_FACTOR`] and 2.5 periods is a one-sample gap only within this
/// fraction of a period of two periods; otherwise it is a late stamp (a device that stamps
/// bursts shows spacings of 1.6 periods with no sample lost).
pub const ONE_SAMPLE_GAP_TOLERANCE: f64 = 0.25;

/// Whether a spacing of `k` periods (no gap reported) is a gap: at least 2.5 periods, or
/// between [`GAP_FACTOR`] and 2.5 periods within [`ONE_SAMPLE_GAP_TOLERANCE`] of 2 (one lost
/// sample).
pub fn is_gap(k: f64) -> bool {
    k >= 2.5 || (k > GAP_FACTOR && (k - 2.0).abs() <= ONE_SAMPLE_GAP_TOLERANCE)
}
/// A spacing that differs from the nominal period by more than this fraction (and is not a gap)
/// is a jittered stamp.
pub const JITTER_TOLERANCE: f64 = 0.01;
/// The stamps are jittered when more than this fraction of the spacings are jittered, or when
/// the RMS deviation of the spacings from the period exceeds [`JITTER_TOLERANCE`] of it. Rarer,
/// smaller deviations (a device correcting its estimate of the sensor's clock by a few µs, a
/// stamp rounded) are counted and described but leave the clock regular: they move no sample,
/// and even at the Nyquist frequency an RMS timing error of 1 % of the period is a phase error
/// of 0.03 rad.
pub const JITTERED_FRACTION: f64 = 0.01;
/// When more than this fraction of the spacings are off the sample clock (shorter than half a
/// period, or long but not a whole number of periods) the stamps are bursty.
pub const BURSTY_FRACTION: f64 = 0.01;

/// How regular a time column is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Regularity {
    /// The spacings are the nominal period (within [`JITTER_TOLERANCE`]) or gaps, but for a
    /// few ([`JITTERED_FRACTION`]).
    Regular,
    /// A sample clock, but many spacings are off the period ([`JITTERED_FRACTION`]).
    Jittered,
    /// Not a sample clock: many spacings far shorter than the period and long ones that are no
    /// whole number of periods (host read times of buffered data). The samples are then taken
    /// as uniformly spaced at the mean spacing, and only device-reported gaps split the record.
    Bursty,
}

impl Regularity {
    /// Lower-case name (`regular`, `jittered`, `bursty`).
    pub fn name(self) -> &'static str {
        match self {
            Regularity::Regular => "regular",
            Regularity::Jittered => "jittered",
            Regularity::Bursty => "bursty",
        }
    }
}

/// One gap: samples missing before row `row`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Gap {
    /// Index (0-based, among the data rows) of the first row after the gap.
    pub row: usize,
    /// Samples missing.
    pub missing_samples: u64,
    /// Time missing, s.
    pub missing_s: f64,
    /// Reported by the device in `gap_before` (else found from `t`).
    pub reported: bool,
}

/// What the time column says about a recording (plain data: the noise lab reads it to name
/// irregular timing before any spectral effect).
#[derive(Debug, Clone, PartialEq)]
pub struct Timing {
    /// Data rows.
    pub rows: usize,
    /// Last stamp minus the first, s.
    pub span_s: f64,
    /// Median spacing of consecutive stamps, s.
    pub median_dt_s: f64,
    /// 95th percentile of the spacings, s.
    pub p95_dt_s: f64,
    /// Mean spacing, span/(rows − 1), s.
    pub mean_dt_s: f64,
    /// Nominal sample period, s: the median spacing, or for bursty stamps the mean spacing
    /// over the record without device-reported gaps.
    pub period_s: f64,
    /// Regular, jittered or bursty.
    pub regularity: Regularity,
    /// Rows whose stamp equals the previous row's.
    pub duplicates: usize,
    /// Spacings (neither duplicates nor gaps) off the period by more than [`JITTER_TOLERANCE`].
    pub jittered: usize,
    /// RMS of (spacing − period) over the spacings that are neither duplicates nor gaps, s.
    pub jitter_rms_s: f64,
    /// Spacings off the sample clock (see [`Clock::off_clock`]).
    pub off_clock: usize,
    /// The gaps, in order.
    pub gaps: Vec<Gap>,
    /// Total time missing in the gaps, s.
    pub missing_s: f64,
    /// Longest gap, s (0 without gaps).
    pub largest_gap_s: f64,
}

/// Why a time column cannot be read as one.
#[derive(Debug, Clone, PartialEq)]
pub enum TimingError {
    /// Fewer than two rows: no spacing.
    TooFew {
        /// Rows given.
        rows: usize,
    },
    /// A stamp is not a finite number.
    NotFinite {
        /// Its row (0-based).
        row: usize,
    },
    /// Time goes backwards between `row − 1` and `row`.
    Backwards {
        /// The later row (0-based).
        row: usize,
        /// Its predecessor's stamp, s.
        from: f64,
        /// Its stamp, s.
        to: f64,
    },
    /// Every stamp is equal.
    NoSpan,
    /// `gap_before` has another length than `t`.
    Length,
}

impl fmt::Display for TimingError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            TimingError::TooFew { rows } => {
                write!(f, "{rows} row(s): at least two stamps are needed")
            }
            TimingError::NotFinite { row } => write!(f, "data row {} is not finite", row + 1),
            TimingError::Backwards { row, from, to } => write!(
                f,
                "time goes backwards between data rows {} and {} ({from} s → {to} s)",
                row,
                row + 1
            ),
            TimingError::NoSpan => write!(f, "every stamp is the same: the record spans no time"),
            TimingError::Length => write!(f, "gap_before and t differ in length"),
        }
    }
}

impl std::error::Error for TimingError {}

/// Value at `q` (0…1) of the sorted order of `v` (nearest rank); `v` is reordered.
fn quantile(v: &mut [f64], q: f64) -> f64 {
    let k = ((q * (v.len() - 1) as f64).round() as usize).min(v.len() - 1);
    *v.select_nth_unstable_by(k, f64::total_cmp).1
}

/// The sample clock read from stamps (all of them, or a long enough prefix of a file too big to
/// hold): what [`TimingScan`] needs before it can classify each spacing.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Clock {
    /// Median spacing, s.
    pub median_dt_s: f64,
    /// 95th percentile of the spacings, s.
    pub p95_dt_s: f64,
    /// The period a spacing is compared with: the median spacing (the mean if more than half
    /// the stamps are duplicated).
    pub period_s: f64,
    /// The stamps are bursty (see [`Regularity::Bursty`]).
    pub bursty: bool,
    /// Spacings off the clock: shorter than half a period (duplicates excluded), or over
    /// [`GAP_FACTOR`] periods without being a whole number of periods nor a reported gap.
    pub off_clock: usize,
}

/// Read the sample clock from stamps `t` and, when the file has one, its `gap_before` column:
/// the median spacing is the period; the stamps are bursty when more than [`BURSTY_FRACTION`]
/// of the spacings are shorter than half a period or over [`GAP_FACTOR`] periods without being
/// within 10 % of a whole number of periods (and not explained by `gap_before`).
pub fn read_clock(t: &[f64], gap_before: Option<&[f64]>) -> Result<Clock, TimingError> {
    let n = t.len();
    if n < 2 {
        return Err(TimingError::TooFew { rows: n });
    }
    if gap_before.is_some_and(|g| g.len() != n) {
        return Err(TimingError::Length);
    }
    if let Some(row) = t.iter().position(|v| !v.is_finite()) {
        return Err(TimingError::NotFinite { row });
    }
    if let Some(i) = t.windows(2).position(|w| w[1] < w[0]) {
        return Err(TimingError::Backwards {
            row: i + 1,
            from: t[i],
            to: t[i + 1],
        });
    }
    let span = t[n - 1] - t[0];
    if span <= 0.0 {
        return Err(TimingError::NoSpan);
    }
    // The quantiles from at most 2^22 spacings spread over the record (every one below that):
    // a day at 1 kHz would otherwise hold two more copies of the time column.
    let stride = (n / (1 << 22)).max(1);
    let mut sorted: Vec<f64> = t.windows(2).step_by(stride).map(|w| w[1] - w[0]).collect();
    let median = quantile(&mut sorted, 0.5);
    let p95 = quantile(&mut sorted, 0.95);
    drop(sorted);
    let dts = t.windows(2).map(|w| w[1] - w[0]);
    let period = if median > 0.0 {
        median
    } else {
        span / (n - 1) as f64
    };
    let short = dts.clone().filter(|&d| d > 0.0 && d < 0.5 * period).count();
    let off_grid = dts
        .clone()
        .enumerate()
        .filter(|&(i, d)| {
            let k = d / period;
            k > GAP_FACTOR
                && gap_before.is_none_or(|g| g[i + 1] == 0.0)
                && (k - k.round()).abs() > 0.1
        })
        .count();
    Ok(Clock {
        median_dt_s: median,
        p95_dt_s: p95,
        period_s: period,
        bursty: (short + off_grid) as f64 > BURSTY_FRACTION * (n - 1) as f64,
        off_clock: short + off_grid,
    })
}

/// Classifies stamps one at a time against a [`Clock`] (bounded memory apart from the list of
/// gaps): gaps, duplicates, jitter. [`timing`] is this over a whole column.
#[derive(Debug, Clone)]
pub struct TimingScan {
    clock: Clock,
    rows: usize,
    first: f64,
    prev: f64,
    duplicates: usize,
    jittered: usize,
    ss: f64,
    cnt: usize,
    reported: u64,
    gaps: Vec<Gap>,
}

impl TimingScan {
    /// Start a scan against `clock`.
    pub fn new(clock: Clock) -> Self {
        TimingScan {
            clock,
            rows: 0,
            first: f64::NAN,
            prev: f64::NAN,
            duplicates: 0,
            jittered: 0,
            ss: 0.0,
            cnt: 0,
            reported: 0,
            gaps: Vec::new(),
        }
    }

    /// The next row's stamp `t` (s) and its `gap_before` (0 when the file has none). Returns the
    /// gap that precedes the row, if any: the record's next segment starts with this row.
    pub fn push(&mut self, t: f64, gap_before: f64) -> Result<Option<Gap>, TimingError> {
        let row = self.rows;
        if !t.is_finite() {
            return Err(TimingError::NotFinite { row });
        }
        self.rows += 1;
        if row == 0 {
            self.first = t;
            self.prev = t;
            return Ok(None);
        }
        let d = t - self.prev;
        if d < 0.0 {
            return Err(TimingError::Backwards {
                row,
                from: self.prev,
                to: t,
            });
        }
        self.prev = t;
        let p = self.clock.period_s;
        let gap = if gap_before > 0.0 {
            self.reported = self.reported.saturating_add(gap_before as u64);
            Some(Gap {
                row,
                missing_samples: gap_before as u64,
                missing_s: gap_before * p,
                reported: true,
            })
        } else if !self.clock.bursty && is_gap(d / p) {
            Some(Gap {
                row,
                missing_samples: ((d / p).round() as u64).saturating_sub(1).max(1),
                missing_s: d - p,
                reported: false,
            })
        } else {
            if d == 0.0 {
                self.duplicates += 1;
            } else if !self.clock.bursty {
                let e = d - p;
                self.ss += e * e;
                self.cnt += 1;
                if e.abs() > JITTER_TOLERANCE * p {
                    self.jittered += 1;
                }
            }
            None
        };
        if let Some(g) = gap {
            self.gaps.push(g);
        }
        Ok(gap)
    }

    /// The report over the rows pushed.
    pub fn finish(self) -> Result<Timing, TimingError> {
        if self.rows < 2 {
            return Err(TimingError::TooFew { rows: self.rows });
        }
        let span = self.prev - self.first;
        if span <= 0.0 {
            return Err(TimingError::NoSpan);
        }
        let mut gaps = self.gaps;
        let period = if self.clock.bursty {
            // The record's own mean spacing, counting the samples the device says it lost.
            let p = span / ((self.rows - 1) as f64 + self.reported as f64);
            for g in &mut gaps {
                g.missing_s = g.missing_samples as f64 * p;
            }
            p
        } else {
            self.clock.period_s
        };
        let regularity = if self.clock.bursty {
            Regularity::Bursty
        } else if self.jittered as f64 > JITTERED_FRACTION * self.cnt.max(1) as f64
            || self.ss > (JITTER_TOLERANCE * period).powi(2) * self.cnt as f64
        {
            Regularity::Jittered
        } else {
            Regularity::Regular
        };
        Ok(Timing {
            rows: self.rows,
            span_s: span,
            median_dt_s: self.clock.median_dt_s,
            p95_dt_s: self.clock.p95_dt_s,
            mean_dt_s: span / (self.rows - 1) as f64,
            period_s: period,
            regularity,
            duplicates: self.duplicates,
            jittered: self.jittered,
            jitter_rms_s: if self.cnt > 0 {
                (self.ss / self.cnt as f64).sqrt()
            } else {
                0.0
            },
            off_clock: self.clock.off_clock,
            missing_s: gaps.iter().map(|g| g.missing_s).sum(),
            largest_gap_s: gaps.iter().map(|g| g.missing_s).fold(0.0, f64::max),
            gaps,
        })
    }
}

/// Read a time column (s) and, when the file has one, its `gap_before` column (module docs):
/// [`read_clock`] over all the stamps, then a [`TimingScan`] of each.
///
/// A spacing that [`is_gap`] is a gap of `round(spacing/period) − 1` samples; a
/// positive `gap_before` is a gap the device reported (its count is used as is). Bursty stamps
/// find no gaps: their period is the record's mean spacing.
pub fn timing(t: &[f64], gap_before: Option<&[f64]>) -> Result<Timing, TimingError> {
    let clock = read_clock(t, gap_before)?;
    let mut scan = TimingScan::new(clock);
    for (i, &v) in t.iter().enumerate() {
        scan.push(v, gap_before.map_or(0.0, |g| g[i]))?;
    }
    scan.finish()
}

impl Timing {
    /// The nominal sample rate, Hz.
    pub fn rate_hz(&self) -> f64 {
        1.0 / self.period_s
    }

    /// Whether the stamps are anything but a clean sample clock (jittered, bursty, or with
    /// duplicated stamps).
    pub fn irregular(&self) -> bool {
        self.regularity != Regularity::Regular || self.duplicates > 0
    }

    /// The row ranges between gaps (at least one; no Allan difference may span two).
    pub fn segments(&self) -> Vec<Range<usize>> {
        segments_between(self.rows, self.gaps.iter().map(|g| g.row))
    }

    /// Samples missing in all gaps.
    pub fn missing_samples(&self) -> u64 {
        self.gaps
            .iter()
            .fold(0u64, |a, g| a.saturating_add(g.missing_samples))
    }

    /// One paragraph for people: the period, the spacings, the gaps, duplicates and jitter,
    /// each with its count and unit.
    pub fn describe(&self) -> String {
        let ms = |s: f64| format!("{} ms", sig3(s * 1e3));
        let mut s = format!(
            "time column: {} rows over {} s; spacing median {}, 95th percentile {}, mean {}; ",
            self.rows,
            sig3(self.span_s),
            ms(self.median_dt_s),
            ms(self.p95_dt_s),
            ms(self.mean_dt_s)
        );
        match self.regularity {
            Regularity::Bursty => {
                s += &format!(
                    "BURSTY stamps ({} of {} spacings fit no sample clock: shorter than half the \
                     median spacing, or long without being a whole number of them): they are \
                     read times of buffered data, not a sample clock, so the samples are taken as \
                     uniformly spaced at the mean period {} ({} Hz) and any effect at the burst \
                     rates may be the timing's",
                    self.off_clock,
                    self.rows - 1,
                    ms(self.period_s),
                    sig3(self.rate_hz())
                );
            }
            _ => {
                s += &format!(
                    "nominal period {} ({} Hz)",
                    ms(self.period_s),
                    sig3(self.rate_hz())
                );
                if self.jittered > 0 {
                    s += &format!(
                        "; {} jittered stamps (more than {} % off the period; RMS jitter {})",
                        self.jittered,
                        JITTER_TOLERANCE * 100.0,
                        ms(self.jitter_rms_s)
                    );
                }
            }
        }
        if self.duplicates > 0 {
            s += &format!("; {} duplicated stamps", self.duplicates);
        }
        if self.gaps.is_empty() {
            s += "; no gaps";
        } else {
            let rep = self.gaps.iter().filter(|g| g.reported).count();
            s += &format!(
                "; {} gap(s) ({} reported by the device), {} samples ({} s) missing in all, the \
                 largest {} s: the record is {} segments and no Allan difference spans a gap",
                self.gaps.len(),
                rep,
                self.missing_samples(),
                sig3(self.missing_s),
                sig3(self.largest_gap_s),
                self.gaps.len() + 1
            );
        }
        s
    }
}

/// Row ranges of a record of `rows` rows cut before each of `cuts` (ascending; 0 and
/// duplicates ignored).
pub fn segments_between(rows: usize, cuts: impl IntoIterator<Item = usize>) -> Vec<Range<usize>> {
    let mut out = Vec::new();
    let mut start = 0;
    for c in cuts {
        if c > start && c < rows {
            out.push(start..c);
            start = c;
        }
    }
    out.push(start..rows);
    out
}

fn sig3(x: f64) -> String {
    if x == 0.0 || !x.is_finite() {
        return format!("{x}");
    }
    let e = x.abs().log10().floor() as i32;
    if (-3..6).contains(&e) {
        format!("{:.*}", (2 - e).max(0) as usize, x)
    } else {
        format!("{x:.2e}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn clock(n: usize, rate: f64) -> Vec<f64> {
        (0..n).map(|i| i as f64 / rate).collect()
    }

    #[test]
    fn regular_clock() {
        let t = clock(1000, 100.0);
        let tm = timing(&t, None).unwrap();
        assert_eq!(tm.regularity, Regularity::Regular);
        assert!((tm.rate_hz() - 100.0).abs() < 1e-9);
        assert!(tm.gaps.is_empty() && tm.duplicates == 0 && tm.jittered == 0);
        assert_eq!(tm.segments(), vec![0..1000]);
    }

    #[test]
    fn gaps_from_t_split_segments_and_keep_the_rate() {
        // 100 Hz with a 0.5 s gap (49 samples missing) and a 1000 s gap.
        let mut t = clock(300, 100.0);
        for v in &mut t[100..] {
            *v += 0.49;
        }
        for v in &mut t[200..] {
            *v += 1000.0;
        }
        let tm = timing(&t, None).unwrap();
        assert!((tm.rate_hz() - 100.0).abs() < 1e-6, "{}", tm.rate_hz());
        assert_eq!(tm.gaps.len(), 2);
        assert_eq!((tm.gaps[0].row, tm.gaps[0].missing_samples), (100, 49));
        assert_eq!((tm.gaps[1].row, tm.gaps[1].missing_samples), (200, 100_000));
        assert!((tm.largest_gap_s - 1000.0).abs() < 1e-6);
        assert!((tm.missing_s - 1000.49).abs() < 1e-6);
        assert_eq!(tm.segments(), vec![0..100, 100..200, 200..300]);
        assert!(tm.describe().contains("2 gap(s)"), "{}", tm.describe());
    }

    #[test]
    fn reported_gaps_are_taken_as_reported() {
        let mut t = clock(100, 1000.0);
        for v in &mut t[40..] {
            *v += 0.032;
        }
        let mut g = vec![0.0; 100];
        g[40] = 32.0;
        let tm = timing(&t, Some(&g)).unwrap();
        assert_eq!(tm.gaps.len(), 1);
        assert_eq!(
            (
                tm.gaps[0].row,
                tm.gaps[0].missing_samples,
                tm.gaps[0].reported
            ),
            (40, 32, true)
        );
        assert!((tm.rate_hz() - 1000.0).abs() < 1e-6);
    }

    #[test]
    fn duplicates_and_jitter_are_counted() {
        let mut t = clock(1000, 100.0);
        t.insert(500, t[499]); // a row written twice
        t[701] += 0.002; // 20 % late: the spacings before and after it are off
        let tm = timing(&t, None).unwrap();
        assert_eq!(tm.duplicates, 1);
        assert!(tm.gaps.is_empty());
        assert_eq!(tm.jittered, 2, "both sides of the late stamp");
        // Two of 998 spacings, RMS 0.9 % of the period: counted, but the clock is regular;
        // the duplicated row makes the record irregular.
        assert_eq!(tm.regularity, Regularity::Regular);
        assert!(tm.irregular());
        // A stamp jittered every 50 rows (4 % of the spacings): jittered.
        let mut t = clock(1000, 100.0);
        for k in (10..1000).step_by(50) {
            t[k] += 0.0003;
        }
        let tm = timing(&t, None).unwrap();
        assert_eq!((tm.jittered, tm.duplicates), (40, 0));
        assert_eq!(tm.regularity, Regularity::Jittered);
        assert!(tm.irregular());
    }

    #[test]
    fn rare_small_stamp_corrections_leave_the_clock_regular() {
        // A device stamping t0 + k·T̂ that now and then corrects its estimate of the sensor's
        // clock: 0.3 % of the spacings off by 2–6 % of the period.
        let mut t = clock(60_000, 1000.0);
        for (i, k) in (100..60_000).step_by(300).enumerate() {
            let shift = 20e-6 + 40e-6 * (i % 2) as f64;
            for v in &mut t[k..] {
                *v += shift;
            }
        }
        let tm = timing(&t, None).unwrap();
        assert_eq!(tm.jittered, 200);
        assert!(tm.jitter_rms_s < 0.01 * tm.period_s, "{}", tm.jitter_rms_s);
        assert_eq!(tm.regularity, Regularity::Regular);
        assert!(!tm.irregular());
        assert!(tm.describe().contains("200 jittered"), "{}", tm.describe());
    }

    #[test]
    fn bursty_host_stamps() {
        // Buffered reads: bursts of 40 samples 0.9 ms apart every 0.4 s (mean rate 100 Hz).
        let mut t = Vec::new();
        for b in 0..50 {
            for k in 0..40 {
                t.push(b as f64 * 0.4 + 0.0125 * (b % 3) as f64 + k as f64 * 0.0009);
            }
        }
        let tm = timing(&t, None).unwrap();
        assert_eq!(tm.regularity, Regularity::Bursty);
        assert!(tm.gaps.is_empty());
        assert!((tm.median_dt_s - 0.0009).abs() < 1e-9);
        assert!((tm.rate_hz() - (t.len() - 1) as f64 / (t[t.len() - 1] - t[0])).abs() < 1e-9);
        assert!(tm.describe().contains("BURSTY"));
    }

    #[test]
    fn absurd_gaps_saturate_instead_of_overflowing() {
        // Found by fuzzing: a stamp of 3e31 s after 1 ms spacings is a gap of more samples
        // than a u64 holds.
        let tm = timing(&[0.0, 0.001, 0.002, 0.003, 3e31, 6e31], None).unwrap();
        assert_eq!(tm.gaps.len(), 2);
        assert_eq!(tm.missing_samples(), u64::MAX);
    }

    #[test]
    fn a_late_stamp_is_jitter_not_a_gap() {
        // A device that stamps bursts: now and then a spacing of 1.6 periods, no sample lost
        // (the emulated board's recordings). Spacings of 2 ± ¼ periods are one lost sample.
        let mut t = clock(1000, 1000.0);
        for v in &mut t[300..] {
            *v += 0.0006;
        }
        for v in &mut t[600..] {
            *v += 0.0011;
        }
        let tm = timing(&t, None).unwrap();
        assert_eq!(tm.gaps.len(), 1, "{:?}", tm.gaps);
        assert_eq!((tm.gaps[0].row, tm.gaps[0].missing_samples), (600, 1));
        assert_eq!(tm.jittered, 1);
        assert_eq!(tm.regularity, Regularity::Jittered);
        assert!(is_gap(2.6) && is_gap(1e6) && is_gap(1.8) && !is_gap(1.6) && !is_gap(2.3));
    }

    #[test]
    fn bad_time_columns() {
        assert_eq!(timing(&[1.0], None), Err(TimingError::TooFew { rows: 1 }));
        assert!(matches!(
            timing(&[0.0, 0.02, 0.01], None),
            Err(TimingError::Backwards { row: 2, .. })
        ));
        assert_eq!(timing(&[3.0, 3.0], None), Err(TimingError::NoSpan));
    }
}
