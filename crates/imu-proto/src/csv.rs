//! The CSV recording contract (host side, feature `std`): the one place that says which columns a
//! recording has, their units, how a file is read and written, and what its time column says.
//!
//! # Layout
//! * A header row, then one sample per row, comma-separated. Leading and trailing blanks of a
//!   field are ignored; a UTF-8 byte-order mark and CRLF line ends are accepted.
//! * `t` (s): the device's sample-clock stamp of the row.
//! * `gap_before` (samples, integer ≥ 0): samples the device lost immediately before this row
//!   (FIFO overflow, a dropped batch). Optional; absent means "none reported".
//! * `ax ay az` (m/s²), `gx gy gz` (deg/s), `mx my mz` (µT), `temp` (°C): the channels of
//!   [`Channel`], in that order. Any subset may be present; other columns are ignored.
//! * A missing value is an empty field. Only [`may_be_empty`] columns (`temp`) may have one: a
//!   sensor that reports no temperature leaves the field empty. Anywhere else an empty field is
//!   an error naming the line and the column.
//! * A header naming a column twice is refused (which of the two would be meant?).
//!
//! Files in other layouts (metadata lines above the header, other column names) are read with
//! [`ReadOptions`]: `skip_lines` and `renames`. The units of such files are the caller's business
//! (a renamed or metadata-preceded column is not known to hold contract units).
//!
//! # Time
//! [`timing`] reads the `t` column as what it is, a list of stamps, and reports how regular it
//! is ([`Timing`]): the nominal period (median spacing), gaps (spacings over
//! [`GAP_FACTOR`] periods, or reported by `gap_before`) which split the record into segments no
//! Allan difference may span, duplicated and jittered stamps, and bursty stamps (host read times
//! of buffered data, not a sample clock).
use std::fmt;
use std::io::{BufRead, BufReader, Read, Write};
use std::ops::Range;

use crate::Channel;

/// Name of the time column (s).
pub const TIME: &str = "t";
/// Name of the column of samples lost before a row.
pub const GAP_BEFORE: &str = "gap_before";
/// The full header a recorder writes: `t`, `gap_before`, then every channel in [`Channel::ALL`]
/// order.
pub const HEADER: [&str; 12] = [
    "t",
    "gap_before",
    "ax",
    "ay",
    "az",
    "gx",
    "gy",
    "gz",
    "mx",
    "my",
    "mz",
    "temp",
];

/// A spacing longer than this many nominal periods is a gap.
pub const GAP_FACTOR: f64 = 1.5;
/// A spacing that differs from the nominal period by more than this fraction (and is not a gap)
/// is a jittered stamp.
pub const JITTER_TOLERANCE: f64 = 0.01;
/// When more than this fraction of the spacings are off the sample clock (shorter than half a
/// period, or long but not a whole number of periods) the stamps are bursty.
pub const BURSTY_FRACTION: f64 = 0.01;

/// The channel a contract column name stands for.
pub fn channel(name: &str) -> Option<Channel> {
    Channel::ALL.into_iter().find(|c| c.name() == name)
}

/// The contract unit of a column name: `s` for `t`, `samples` for `gap_before`, the channel's
/// unit otherwise; `None` for names outside the contract.
pub fn unit(name: &str) -> Option<&'static str> {
    match name {
        TIME => Some("s"),
        GAP_BEFORE => Some("samples"),
        _ => channel(name).map(Channel::unit),
    }
}

/// Whether a column may hold empty (missing) fields.
pub fn may_be_empty(name: &str) -> bool {
    name == Channel::Temp.name()
}

/// A reading or writing error: what, where (file and line, when known).
#[derive(Debug, Clone, PartialEq)]
pub struct CsvError {
    /// The file (or stream) as shown to the user.
    pub source: String,
    /// 1-based line of the file, when the error is about one.
    pub line: Option<usize>,
    /// What is wrong, naming the field where there is one.
    pub message: String,
}

impl fmt::Display for CsvError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.line {
            Some(l) => write!(f, "{}: line {l}: {}", self.source, self.message),
            None => write!(f, "{}: {}", self.source, self.message),
        }
    }
}

impl std::error::Error for CsvError {}

/// How to reach the header of a file that does not follow the contract exactly.
#[derive(Debug, Clone, Default)]
pub struct ReadOptions {
    /// Lines to skip before the header row (metadata).
    pub skip_lines: usize,
    /// Column renames applied to the header, `(name in the file, contract name)`.
    pub renames: Vec<(String, String)>,
}

/// Parse `OLD=NEW` rename specifications.
pub fn parse_renames(specs: &[String]) -> Result<Vec<(String, String)>, String> {
    specs
        .iter()
        .filter(|s| !s.trim().is_empty())
        .map(|r| {
            r.split_once('=')
                .map(|(o, n)| (o.trim().to_string(), n.trim().to_string()))
                .filter(|(o, n)| !o.is_empty() && !n.is_empty())
                .ok_or_else(|| format!("rename {r:?}: expected OLD=NEW"))
        })
        .collect()
}

/// One column of the header.
#[derive(Debug, Clone, PartialEq)]
pub struct HeaderColumn {
    /// Name after renaming (the contract name, for contract columns).
    pub name: String,
    /// Name as written in the file.
    pub original: String,
}

impl HeaderColumn {
    /// Whether the name was changed by a rename.
    pub fn renamed(&self) -> bool {
        self.name != self.original
    }
}

/// A recording opened for row-by-row reading (constant memory whatever the file's length).
pub struct Reader<R: Read> {
    source: String,
    skip_lines: usize,
    csv: ::csv::Reader<BufReader<R>>,
    record: ::csv::StringRecord,
    header: Vec<HeaderColumn>,
    /// Selected columns: (name, index in the row).
    selected: Vec<(String, usize)>,
    line: usize,
}

impl<R: Read> Reader<R> {
    /// Read the metadata lines and the header of `input`, shown in errors as `source`.
    /// Refuses a header that names a column twice (before or after renaming).
    pub fn new(input: R, source: &str, opts: &ReadOptions) -> Result<Self, CsvError> {
        let err = |line: Option<usize>, message: String| CsvError {
            source: source.to_string(),
            line,
            message,
        };
        let mut buf = BufReader::with_capacity(1 << 16, input);
        let mut skipped = String::new();
        for i in 0..opts.skip_lines {
            skipped.clear();
            let n = buf
                .read_line(&mut skipped)
                .map_err(|e| err(Some(i + 1), format!("cannot read: {e}")))?;
            if n == 0 {
                return Err(err(
                    None,
                    format!(
                        "the file has only {i} lines, but {} metadata lines were to be skipped",
                        opts.skip_lines
                    ),
                ));
            }
        }
        let header_line = opts.skip_lines + 1;
        let mut csv = ::csv::ReaderBuilder::new()
            .has_headers(true)
            .trim(::csv::Trim::All)
            .from_reader(buf);
        let raw: Vec<String> = csv
            .headers()
            .map_err(|e| {
                err(
                    Some(header_line),
                    format!("cannot read the header row: {e}"),
                )
            })?
            .iter()
            .map(str::to_string)
            .collect();
        if raw.iter().all(|h| h.is_empty()) {
            return Err(err(
                Some(header_line),
                "no header row (the file is empty here)".into(),
            ));
        }
        let header: Vec<HeaderColumn> = raw
            .iter()
            .map(|h| HeaderColumn {
                name: opts
                    .renames
                    .iter()
                    .find(|(old, _)| old == h)
                    .map_or_else(|| h.clone(), |(_, new)| new.clone()),
                original: h.clone(),
            })
            .collect();
        for (i, c) in header.iter().enumerate() {
            if c.name.is_empty() {
                continue;
            }
            if let Some(j) = header[..i].iter().position(|d| d.name == c.name) {
                return Err(err(
                    Some(header_line),
                    format!(
                        "column {:?} appears twice in the header (columns {} and {}{}); which \
                         one is meant cannot be told",
                        c.name,
                        j + 1,
                        i + 1,
                        if c.renamed() || header[j].renamed() {
                            format!(
                                ", from {:?} and {:?} after renaming",
                                header[j].original, c.original
                            )
                        } else {
                            String::new()
                        }
                    ),
                ));
            }
        }
        Ok(Reader {
            source: source.to_string(),
            skip_lines: opts.skip_lines,
            csv,
            record: ::csv::StringRecord::new(),
            header,
            selected: Vec::new(),
            line: header_line,
        })
    }

    /// The header's columns, after renaming.
    pub fn header(&self) -> &[HeaderColumn] {
        &self.header
    }

    /// The file as shown in errors.
    pub fn source(&self) -> &str {
        &self.source
    }

    /// The header column called `name` (after renaming).
    pub fn column(&self, name: &str) -> Option<&HeaderColumn> {
        self.header.iter().find(|c| c.name == name)
    }

    /// Choose the columns [`Reader::next_row`] returns: every name of `wanted` (an error names
    /// the missing one and lists the header), then those of `optional` that the file has, then
    /// `t` and `gap_before` when present and not already chosen. Returns the chosen names in
    /// that order.
    pub fn select(&mut self, wanted: &[&str], optional: &[&str]) -> Result<Vec<String>, CsvError> {
        let mut names: Vec<String> = Vec::new();
        for w in wanted {
            if !names.iter().any(|n| n == w) {
                names.push(w.to_string());
            }
        }
        for o in optional.iter().chain(&[TIME, GAP_BEFORE]) {
            if self.column(o).is_some() && !names.iter().any(|n| n == o) {
                names.push(o.to_string());
            }
        }
        let mut selected = Vec::with_capacity(names.len());
        for n in &names {
            let i = self
                .header
                .iter()
                .position(|c| &c.name == n)
                .ok_or_else(|| CsvError {
                    source: self.source.clone(),
                    line: Some(self.skip_lines + 1),
                    message: format!(
                    "no column named {n:?} in the header ({}); rename one onto it (OLD={n}) or \
                     skip the metadata lines above the header",
                    self.header
                        .iter()
                        .map(|c| c.original.as_str())
                        .collect::<Vec<_>>()
                        .join(", ")
                ),
                })?;
            selected.push((n.clone(), i));
        }
        self.selected = selected;
        Ok(names)
    }

    /// File line of the last row read (the header's before the first row).
    pub fn line(&self) -> usize {
        self.line
    }

    fn error(&self, line: Option<usize>, message: String) -> CsvError {
        CsvError {
            source: self.source.clone(),
            line,
            message,
        }
    }

    /// Read the next row's selected fields into `out` (one value per selected name). An empty
    /// field of a [`may_be_empty`] column reads as NaN; `gap_before` must be a whole number
    /// ≥ 0; every other field a finite number. `Ok(false)` at the end of the file.
    pub fn next_row(&mut self, out: &mut [f64]) -> Result<bool, CsvError> {
        match self.csv.read_record(&mut self.record) {
            Ok(false) => return Ok(false),
            Ok(true) => {}
            Err(e) => {
                let line = e.position().map(|p| p.line() as usize + self.skip_lines);
                return Err(self.error(line, format!("malformed CSV: {e}")));
            }
        }
        self.line = self
            .record
            .position()
            .map_or(self.line + 1, |p| p.line() as usize + self.skip_lines);
        for (k, (name, i)) in self.selected.iter().enumerate() {
            let field = self.record.get(*i).unwrap_or("");
            if field.is_empty() {
                if may_be_empty(name) {
                    out[k] = f64::NAN;
                    continue;
                }
                return Err(self.error(
                    Some(self.line),
                    format!(
                        "field {name:?} (column {}) is empty; only {} may be missing",
                        i + 1,
                        HEADER
                            .iter()
                            .filter(|h| may_be_empty(h))
                            .copied()
                            .collect::<Vec<_>>()
                            .join(", ")
                    ),
                ));
            }
            let v: f64 = match field.parse() {
                Ok(v) => v,
                Err(_) => {
                    return Err(self.error(
                        Some(self.line),
                        format!(
                            "field {name:?} (column {}) is {field:?}, not a number",
                            i + 1
                        ),
                    ))
                }
            };
            if !v.is_finite() {
                return Err(self.error(
                    Some(self.line),
                    format!(
                        "field {name:?} (column {}) is {field:?}, not a finite number",
                        i + 1
                    ),
                ));
            }
            if name == GAP_BEFORE && !(v >= 0.0 && v.fract() == 0.0 && v < 9.0e15) {
                return Err(self.error(
                    Some(self.line),
                    format!(
                        "field {name:?} (column {}) is {field:?}: samples lost must be a whole \
                         number ≥ 0",
                        i + 1
                    ),
                ));
            }
            out[k] = v;
        }
        Ok(true)
    }
}

/// How [`Writer`] prints numbers.
#[derive(Debug, Clone, Copy, Default)]
pub struct WriteOptions {
    /// Decimals of `t` (6 for µs stamps); `None`: the shortest text that reads back exactly.
    pub time_decimals: Option<usize>,
    /// Print the channels at f32 precision (shortest text; enough for 16-bit sensors).
    pub f32_values: bool,
}

/// Writes a recording in the contract: the header, then one row per call.
pub struct Writer<W: Write> {
    w: W,
    columns: Vec<&'static str>,
    opts: WriteOptions,
    line: String,
}

impl<W: Write> Writer<W> {
    /// Write the header for `columns` (contract names, each at most once; `t` first when
    /// present). An unknown or repeated name is refused.
    pub fn new(mut w: W, columns: &[&str], opts: WriteOptions) -> Result<Self, CsvError> {
        let err = |message: String| CsvError {
            source: "CSV writer".into(),
            line: None,
            message,
        };
        let mut cols: Vec<&'static str> = Vec::with_capacity(columns.len());
        for c in columns {
            let known = HEADER
                .iter()
                .find(|h| *h == c)
                .ok_or_else(|| err(format!("{c:?} is not a contract column")))?;
            if cols.contains(known) {
                return Err(err(format!("column {c:?} given twice")));
            }
            cols.push(known);
        }
        if cols.iter().position(|c| *c == TIME).is_some_and(|i| i != 0) {
            return Err(err("\"t\" must be the first column".into()));
        }
        writeln!(w, "{}", cols.join(",")).map_err(|e| err(format!("cannot write: {e}")))?;
        Ok(Writer {
            w,
            columns: cols,
            opts,
            line: String::new(),
        })
    }

    /// The columns, in order.
    pub fn columns(&self) -> &[&'static str] {
        &self.columns
    }

    /// Write one row: a value per column, `None` for a missing one (an empty field; only
    /// [`may_be_empty`] columns, and never `t`). `gap_before` is written as an integer.
    pub fn row(&mut self, values: &[Option<f64>]) -> std::io::Result<()> {
        use std::fmt::Write as _;
        let bad = |m: String| std::io::Error::new(std::io::ErrorKind::InvalidInput, m);
        if values.len() != self.columns.len() {
            return Err(bad(format!(
                "{} values for {} columns",
                values.len(),
                self.columns.len()
            )));
        }
        self.line.clear();
        for (k, (c, v)) in self.columns.iter().zip(values).enumerate() {
            if k > 0 {
                self.line.push(',');
            }
            let Some(v) = v else {
                if may_be_empty(c) {
                    continue;
                }
                return Err(bad(format!("column {c:?} may not be empty")));
            };
            if !v.is_finite() {
                return Err(bad(format!("column {c:?}: {v} is not a finite number")));
            }
            let _ = match *c {
                TIME => match self.opts.time_decimals {
                    Some(d) => write!(self.line, "{v:.d$}"),
                    None => write!(self.line, "{v}"),
                },
                GAP_BEFORE => write!(self.line, "{}", v.max(0.0).round() as u64),
                _ if self.opts.f32_values => write!(self.line, "{}", *v as f32),
                _ => write!(self.line, "{v}"),
            };
        }
        self.line.push('\n');
        self.w.write_all(self.line.as_bytes())
    }

    /// Flush and return the inner writer.
    pub fn finish(mut self) -> std::io::Result<W> {
        self.w.flush()?;
        Ok(self.w)
    }
}

/// How regular a time column is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Regularity {
    /// Every spacing is the nominal period (within [`JITTER_TOLERANCE`]) or a gap.
    Regular,
    /// A sample clock, but some spacings are off the period by more than [`JITTER_TOLERANCE`].
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
    let dts: Vec<f64> = t.windows(2).map(|w| w[1] - w[0]).collect();
    let mut sorted = dts.clone();
    let median = quantile(&mut sorted, 0.5);
    let p95 = quantile(&mut sorted, 0.95);
    let period = if median > 0.0 {
        median
    } else {
        span / (n - 1) as f64
    };
    let short = dts.iter().filter(|&&d| d > 0.0 && d < 0.5 * period).count();
    let off_grid = dts
        .iter()
        .enumerate()
        .filter(|&(i, &d)| {
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
        bursty: (short + off_grid) as f64 > BURSTY_FRACTION * dts.len() as f64,
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
        } else if !self.clock.bursty && d > GAP_FACTOR * p {
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
        } else if self.jittered > 0 {
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
/// A spacing over [`GAP_FACTOR`] periods is a gap of `round(spacing/period) − 1` samples; a
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

    fn read_all(
        text: &str,
        opts: &ReadOptions,
        wanted: &[&str],
    ) -> Result<Vec<Vec<f64>>, CsvError> {
        let mut r = Reader::new(text.as_bytes(), "mem.csv", opts)?;
        let names = r.select(wanted, &[])?;
        let mut rows = Vec::new();
        let mut buf = vec![0.0; names.len()];
        while r.next_row(&mut buf)? {
            rows.push(buf.clone());
        }
        Ok(rows)
    }

    #[test]
    fn header_matches_the_channels() {
        assert_eq!(&HEADER[..2], &[TIME, GAP_BEFORE]);
        for (h, c) in HEADER[2..].iter().zip(Channel::ALL) {
            assert_eq!(*h, c.name());
            assert_eq!(unit(h), Some(c.unit()));
        }
        assert_eq!(unit("t"), Some("s"));
        assert_eq!(unit("gyro_z"), None);
    }

    #[test]
    fn duplicated_columns_are_refused_with_both_places() {
        let e = read_all("t,gx,gx\n0,1,2\n", &ReadOptions::default(), &["gx"]).unwrap_err();
        assert_eq!(e.line, Some(1));
        assert!(
            e.message.contains("\"gx\" appears twice") && e.message.contains("columns 2 and 3"),
            "{e}"
        );
        let opts = ReadOptions {
            skip_lines: 0,
            renames: vec![("gyro_x".into(), "gx".into())],
        };
        let e = read_all("t,gx,gyro_x\n0,1,2\n", &opts, &["gx"]).unwrap_err();
        assert!(e.message.contains("\"gyro_x\""), "{e}");
    }

    #[test]
    fn empty_fields_are_missing_only_for_temperature() {
        let rows = read_all(
            "t,gx,temp\n0,1,25\n0.01,2,\n",
            &ReadOptions::default(),
            &["gx", "temp"],
        )
        .unwrap();
        assert_eq!(rows[0], vec![1.0, 25.0, 0.0]);
        assert!(rows[1][1].is_nan() && rows[1][0] == 2.0);
        let e = read_all(
            "t,gx,temp\n0,1,25\n0.01,,25\n",
            &ReadOptions::default(),
            &["gx"],
        )
        .unwrap_err();
        assert_eq!(e.line, Some(3));
        assert!(e.message.contains("\"gx\" (column 2) is empty"), "{e}");
    }

    #[test]
    fn gap_before_must_be_a_count() {
        let text = "t,gap_before,gz\n0,0,1\n0.001,2.5,1\n";
        let e = read_all(text, &ReadOptions::default(), &["gz"]).unwrap_err();
        assert_eq!(e.line, Some(3));
        assert!(e.message.contains("whole number"), "{e}");
        let e = read_all(
            "t,gap_before,gz\n0,-1,1\n",
            &ReadOptions::default(),
            &["gz"],
        )
        .unwrap_err();
        assert!(e.message.contains("whole number"), "{e}");
    }

    #[test]
    fn bom_crlf_and_blanks_are_read() {
        let text = "\u{feff}t , gz\r\n0, 1.5\r\n0.01 ,2.5\r\n";
        let rows = read_all(text, &ReadOptions::default(), &["gz"]).unwrap();
        assert_eq!(rows, vec![vec![1.5, 0.0], vec![2.5, 0.01]]);
    }

    #[test]
    fn writer_reads_back_with_gaps_and_missing_temperature() {
        let mut w = Writer::new(
            Vec::new(),
            &HEADER,
            WriteOptions {
                time_decimals: Some(6),
                f32_values: true,
            },
        )
        .unwrap();
        w.row(&[
            Some(0.001),
            Some(0.0),
            Some(0.5),
            Some(0.0),
            Some(9.81),
            Some(0.01),
            Some(-0.02),
            Some(0.0),
            Some(20.0),
            Some(-3.0),
            Some(40.0),
            None,
        ])
        .unwrap();
        w.row(&[
            Some(0.005),
            Some(3.0),
            Some(0.5),
            Some(0.0),
            Some(9.81),
            Some(0.01),
            Some(-0.02),
            Some(0.0),
            Some(20.0),
            Some(-3.0),
            Some(40.0),
            Some(25.5),
        ])
        .unwrap();
        let text = String::from_utf8(w.finish().unwrap()).unwrap();
        assert_eq!(text.lines().next().unwrap(), HEADER.join(","));
        assert_eq!(
            text.lines().nth(1).unwrap(),
            "0.001000,0,0.5,0,9.81,0.01,-0.02,0,20,-3,40,"
        );
        let rows = read_all(&text, &ReadOptions::default(), &["az", "temp"]).unwrap();
        // f32 shortest text of 9.81 is "9.81", which reads back as the f64 9.81.
        assert_eq!(rows[1], vec![9.81, 25.5, 0.005, 3.0]);
        assert!(rows[0][1].is_nan());
        assert!(Writer::new(Vec::new(), &["t", "gyro"], WriteOptions::default()).is_err());
        assert!(Writer::new(Vec::new(), &["gx", "t"], WriteOptions::default()).is_err());
    }

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
        assert_eq!(tm.regularity, Regularity::Jittered);
        assert!(tm.irregular());
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
    fn bad_time_columns() {
        assert_eq!(timing(&[1.0], None), Err(TimingError::TooFew { rows: 1 }));
        assert!(matches!(
            timing(&[0.0, 0.02, 0.01], None),
            Err(TimingError::Backwards { row: 2, .. })
        ));
        assert_eq!(timing(&[3.0, 3.0], None), Err(TimingError::NoSpan));
    }
}
