//! Reading a recording for the subcommands: the CSV contract ([`imu_proto::csv`]) plus the flags
//! that read other layouts, the physical checks on them, the time column and the units.
//!
//! * **Layout**: the contract (`t`, `gap_before`, `ax ay az` m/s², `gx gy gz` deg/s, `mx my mz`
//!   µT, `temp` °C). `--skip-lines N` skips metadata lines above the header, `--rename OLD=NEW`
//!   maps a column onto a contract name.
//! * **Time is read, not assumed.** With a `t` column the rate is 1/median spacing; gaps (a
//!   spacing of 2 ± ¼ or more than 2.5 periods, `imu_proto::csv::is_gap`, or reported in
//!   `gap_before`) split the record into segments that no Allan difference spans; duplicated, jittered and bursty stamps are reported (stderr). `--rate`
//!   must agree with `t` within [`RATE_AGREEMENT`] unless `--ignore-time`, which takes the rows
//!   as consecutive samples at `--rate` and ignores `t`. Rates outside
//!   [`RATE_MIN_HZ`]…[`RATE_MAX_HZ`] are refused.
//! * **Units never lie.** A column's unit is, in order: `--unit U`; with `--scale K` alone the
//!   contract unit of its name (the factor converts into it); else a column of whole numbers
//!   is raw counts, labelled [`COUNTS`] (even under a contract name: no MEMS part resolves
//!   whole deg/s, m/s² or µT, and the contract's writers print fractions); else the contract
//!   unit if the file is a contract file for that column (its own name is the contract name
//!   and there are no metadata lines). Otherwise the file does not say, and it is refused
//!   until `--unit` or `--scale` says.
//!   `t` is always in s and `temp` in °C (neither is scaled).
//! * A malformed file is refused with an error naming the line and the field.
use std::fs::File;
use std::io::Read;
use std::ops::Range;
use std::path::PathBuf;

use anyhow::{anyhow, bail, Context, Result};
use imu_proto::csv::{self as contract, HeaderColumn, ReadOptions, Timing, GAP_BEFORE, TIME};

/// Lowest sample rate accepted, Hz (one sample in 17 minutes).
pub const RATE_MIN_HZ: f64 = 1e-3;
/// Highest sample rate accepted, Hz (no MEMS inertial sensor samples faster).
pub const RATE_MAX_HZ: f64 = 1e7;
/// Largest relative disagreement between `--rate` and the rate read from `t`.
pub const RATE_AGREEMENT: f64 = 0.01;
/// Accepted magnitudes of `--scale` (a count is worth between 1e-12 and 1e12 units).
pub const SCALE_RANGE: (f64, f64) = (1e-12, 1e12);
/// Largest magnitude of a value after scaling: beyond it squares of sums would overflow.
pub const VALUE_MAX: f64 = 1e100;
/// The label of raw counts.
pub const COUNTS: &str = "LSB";

/// Flags for reading a recording (flattened into each subcommand).
#[derive(clap::Args, Debug, Clone)]
pub struct InputArgs {
    /// CSV recording (header row; columns t, gap_before, ax ay az, gx gy gz, mx my mz, temp).
    pub file: PathBuf,
    /// Sample rate in Hz (default: from the `t` column; must agree with it within 1 %).
    #[arg(long)]
    pub rate: Option<f64>,
    /// Ignore the `t` column: the rows are consecutive samples at --rate.
    #[arg(long)]
    pub ignore_time: bool,
    /// Metadata lines to skip before the header row.
    #[arg(long, default_value_t = 0)]
    pub skip_lines: usize,
    /// Multiply the selected columns (not `t`, not `temp`) by this factor, e.g. 0.0076336 for
    /// ±250 °/s counts; without --unit the result is in the contract's unit for the name.
    #[arg(long)]
    pub scale: Option<f64>,
    /// Unit of the selected columns (after --scale), e.g. deg/s, LSB.
    #[arg(long)]
    pub unit: Option<String>,
    /// Rename columns onto the contract, OLD=NEW (comma-separated or repeated), e.g. mx_gauss=mx.
    #[arg(long, value_delimiter = ',')]
    pub rename: Vec<String>,
}

impl InputArgs {
    /// A file in the contract, read with every flag at its default.
    pub fn for_file(file: impl Into<PathBuf>) -> InputArgs {
        InputArgs {
            file: file.into(),
            rate: None,
            ignore_time: false,
            skip_lines: 0,
            scale: None,
            unit: None,
            rename: vec![],
        }
    }
}

/// One selected column.
#[derive(Debug, Clone)]
pub struct Series {
    /// Contract name (`gz`, `mx`, …).
    pub name: String,
    /// Unit of `values` ([`COUNTS`] for raw counts).
    pub unit: String,
    /// The samples (NaN where a `temp` field is empty).
    pub values: Vec<f64>,
}

/// The columns read from a recording, with its rate and what its time column says.
#[derive(Debug, Clone)]
pub struct Recording {
    /// Sample rate in Hz.
    pub rate_hz: f64,
    /// The requested columns, in the order asked.
    pub columns: Vec<Series>,
    /// The time column's report (None without `t`, or with --ignore-time).
    pub timing: Option<Timing>,
    /// Row ranges between gaps (at least one).
    pub segments: Vec<Range<usize>>,
}

impl Recording {
    /// The column called `name`.
    pub fn column(&self, name: &str) -> Option<&Series> {
        self.columns.iter().find(|c| c.name == name)
    }

    /// Samples read.
    pub fn samples(&self) -> usize {
        self.columns.first().map_or(0, |c| c.values.len())
    }

    /// The segments of column `name` (one slice per run between gaps).
    pub fn segments_of(&self, name: &str) -> Option<Vec<&[f64]>> {
        let c = self.column(name)?;
        Some(self.segments.iter().map(|r| &c.values[r.clone()]).collect())
    }
}

/// The `--scale` factor (1 when absent), refusing zero, non-finite and absurd values.
pub fn scale_of(args: &InputArgs) -> Result<f64> {
    let Some(scale) = args.scale else {
        return Ok(1.0);
    };
    let (lo, hi) = SCALE_RANGE;
    if !(scale.is_finite() && (lo..=hi).contains(&scale.abs())) {
        bail!(
            "--scale {}: a count must be worth between {lo:e} and {hi:e} units (e.g. \
             0.0076336 deg/s per LSB)",
            num(scale)
        );
    }
    Ok(scale)
}

/// Check a rate against the physical range.
pub fn check_rate(rate: f64, what: &str) -> Result<f64> {
    if !(rate.is_finite() && (RATE_MIN_HZ..=RATE_MAX_HZ).contains(&rate)) {
        bail!(
            "{what} {} Hz: a sample rate must be between {RATE_MIN_HZ:e} Hz and \
             {RATE_MAX_HZ:e} Hz",
            num(rate)
        );
    }
    Ok(rate)
}

/// Whether `--scale` and `--unit` apply to a column: every selected column but the time `t` (s),
/// `gap_before` (samples) and the temperature `temp` (°C), which are always in the contract's
/// units.
pub fn is_scaled(name: &str) -> bool {
    name != TIME && name != GAP_BEFORE && name != "temp"
}

/// The unit of a column (module docs, "Units never lie"). `integers`: every value read is a
/// whole number (unknown yet: `None`, then raw counts cannot be recognised).
pub fn unit_of(args: &InputArgs, col: &HeaderColumn, integers: Option<bool>) -> Result<String> {
    let name = col.name.as_str();
    if !is_scaled(name) {
        return Ok(contract::unit(name).unwrap_or("").to_string());
    }
    if let Some(u) = &args.unit {
        return Ok(u.clone());
    }
    let contract_unit = contract::unit(name);
    if args.scale.is_some() {
        return contract_unit.map(str::to_string).ok_or_else(|| {
            anyhow!(
                "column {name:?} is not in the contract: give its unit after --scale with --unit"
            )
        });
    }
    let contract_file = !col.renamed() && args.skip_lines == 0;
    match (contract_unit, contract_file, integers) {
        // Whole numbers only: raw counts, even under a contract name (no MEMS part's physical
        // resolution is a whole deg/s, m/s² or µT, and the contract's writers print fractions).
        (_, _, Some(true)) => Ok(COUNTS.to_string()),
        (Some(u), true, _) => Ok(u.to_string()),
        (_, _, None) => bail!(
            "column {name:?}: the file does not state its unit{}; give --unit (e.g. --unit {}) \
             or --scale to convert counts into {}",
            origin(args, col),
            contract_unit.unwrap_or(COUNTS),
            contract_unit.unwrap_or("a unit")
        ),
        (_, _, Some(false)) => bail!(
            "column {name:?} holds fractional values, so it is not raw counts, and the file does \
             not state its unit{}; give --unit (e.g. --unit {}), or --scale K to convert it \
             into {}",
            origin(args, col),
            contract_unit.unwrap_or("deg/s"),
            contract_unit.unwrap_or("the contract's unit")
        ),
    }
}

/// Why a column's name says nothing about its unit.
fn origin(args: &InputArgs, col: &HeaderColumn) -> String {
    if col.renamed() {
        format!(" (it is {:?} renamed)", col.original)
    } else if args.skip_lines > 0 {
        " (metadata lines precede the header: not a contract file)".into()
    } else {
        " (not a contract column name)".into()
    }
}

/// A recording opened for row-by-row reading: constant memory, whatever the file's length.
pub struct Rows {
    reader: contract::Reader<Box<dyn Read>>,
    /// Names read, in order: the wanted columns, the optional ones present, then `t` and
    /// `gap_before` when present.
    pub names: Vec<String>,
    progress: indicatif::ProgressBar,
    /// File size in bytes (0 when unknown).
    size: u64,
}

impl Rows {
    /// Read the next row into `out` (one value per name, unscaled). `Ok(false)` at the end.
    pub fn next_into(&mut self, out: &mut [f64]) -> Result<bool> {
        let more = self.reader.next_row(out)?;
        if !more {
            self.progress.finish_and_clear();
        }
        Ok(more)
    }

    /// File line of the last row read.
    pub fn line(&self) -> usize {
        self.reader.line()
    }

    /// The file as shown in errors.
    pub fn shown(&self) -> &str {
        self.reader.source()
    }

    /// Position of `name` among [`Rows::names`].
    pub fn position(&self, name: &str) -> Option<usize> {
        self.names.iter().position(|n| n == name)
    }

    /// The header column of a selected name.
    pub fn header_column(&self, name: &str) -> Option<&HeaderColumn> {
        self.reader.column(name)
    }
}

/// Open the recording and find the columns `wanted` (contract names, after renaming), the
/// columns of `optional` the file has, then `t` and `gap_before`.
pub fn open_with(args: &InputArgs, wanted: &[&str], optional: &[&str]) -> Result<Rows> {
    let path = &args.file;
    let shown = path.display().to_string();
    if let Some(w) = wanted.iter().find(|w| [TIME, GAP_BEFORE].contains(w)) {
        bail!("--column {w}: `{w}` says when the samples were taken, it is not a measurement to analyse; choose a sensor column (e.g. gz)");
    }
    let file = File::open(path).with_context(|| format!("cannot open {shown}"))?;
    let size = file.metadata().map(|m| m.len()).unwrap_or(0);
    let progress = progress_bar(size);
    let renames = contract::parse_renames(&args.rename).map_err(|e| anyhow!("--{e}"))?;
    let opts = ReadOptions {
        skip_lines: args.skip_lines,
        renames,
    };
    let mut reader = contract::Reader::new(
        Box::new(progress.wrap_read(file)) as Box<dyn Read>,
        &shown,
        &opts,
    )?;
    let names = reader.select(wanted, optional)?;
    Ok(Rows {
        reader,
        names,
        progress,
        size,
    })
}

/// The rate and the segments from the flags and the time report (module docs).
pub fn rate_and_segments(
    args: &InputArgs,
    shown: &str,
    timing: Option<&Timing>,
    rows: usize,
) -> Result<(f64, Vec<Range<usize>>)> {
    let whole = std::iter::once(0..rows).collect::<Vec<_>>();
    match (args.rate, timing, args.ignore_time) {
        (None, _, true) => bail!("--ignore-time: give the sample rate with --rate"),
        (Some(r), _, true) => Ok((check_rate(r, "--rate")?, whole)),
        (Some(r), Some(tm), false) => {
            let r = check_rate(r, "--rate")?;
            let from_t = tm.rate_hz();
            let off = r / from_t - 1.0;
            if off.abs() > RATE_AGREEMENT {
                bail!(
                    "--rate {r} Hz disagrees with the time column of {shown} by {:+.1} %: its {} \
                     spacing is {} ms, i.e. {} Hz. Fix --rate, or give --ignore-time to take the \
                     rows as consecutive samples at --rate",
                    off * 100.0,
                    if tm.regularity == contract::Regularity::Bursty {
                        "mean"
                    } else {
                        "median"
                    },
                    short(tm.period_s * 1e3),
                    short(from_t)
                );
            }
            Ok((r, tm.segments()))
        }
        (Some(r), None, false) => Ok((check_rate(r, "--rate")?, whole)),
        (None, Some(tm), false) => Ok((
            check_rate(
                tm.rate_hz(),
                &format!("{shown}: the rate read from column \"t\" is"),
            )?,
            tm.segments(),
        )),
        (None, None, false) => {
            bail!("{shown}: no --rate given and no \"t\" column to read the rate from")
        }
    }
}

/// Read the columns `wanted` (contract names, after renaming) from the recording.
pub fn load(args: &InputArgs, wanted: &[&str]) -> Result<Recording> {
    load_with(args, wanted, &[])
}

/// As [`load`], also reading the columns of `optional` that the file has (e.g. `temp`); they
/// follow the wanted ones in `columns`. Timing findings (gaps, duplicates, jitter, bursts) are
/// reported on stderr.
pub fn load_with(args: &InputArgs, wanted: &[&str], optional: &[&str]) -> Result<Recording> {
    let scale = scale_of(args)?;
    let mut rows = open_with(args, wanted, optional)?;
    let shown = rows.shown().to_string();
    let names = rows.names.clone();
    let mut data: Vec<Vec<f64>> = vec![Vec::new(); names.len()];
    let mut buf = vec![0.0; names.len()];
    // Reserve from the file's size and the first rows' length (2 % margin), then grow by an
    // eighth: a long recording is not held at up to twice its size by Vec doubling.
    let mut reserved = false;
    while rows.next_into(&mut buf)? {
        for (col, v) in data.iter_mut().zip(&buf) {
            if reserved && col.len() == col.capacity() {
                // later rows are longer (more digits in t): grow by an eighth, not by doubling
                col.reserve_exact((col.len() / 8).max(4096));
            }
            col.push(*v);
        }
        if !reserved && data[0].len() == 4096 {
            reserved = true;
            let read = rows.reader.byte().max(1);
            let est = (rows.size as f64 / read as f64 * 4096.0 * 1.02).min(1e10) as usize;
            for col in &mut data {
                col.reserve(est.saturating_sub(col.len()));
            }
        }
    }
    let n = data.first().map_or(0, Vec::len);
    if n == 0 {
        bail!(
            "{shown}: no data rows after the header (line {})",
            args.skip_lines + 1
        );
    }
    let t = rows.position(TIME).map(|i| &data[i]);
    let gap = rows.position(GAP_BEFORE).map(|i| data[i].as_slice());
    let timing = match (t, args.ignore_time) {
        (Some(t), false) => {
            Some(contract::timing(t, gap).with_context(|| format!("{shown}: column \"t\""))?)
        }
        _ => None,
    };
    let (rate_hz, segments) = rate_and_segments(args, &shown, timing.as_ref(), n)?;
    if let Some(tm) = &timing {
        if tm.irregular() || !tm.gaps.is_empty() {
            eprintln!("note: {shown}: {}", tm.describe());
        }
    }
    let mut columns = Vec::with_capacity(wanted.len() + optional.len());
    for (name, values) in names.iter().zip(data) {
        let keep = wanted.contains(&name.as_str()) || optional.contains(&name.as_str());
        if !keep {
            continue;
        }
        let col = rows
            .header_column(name)
            .expect("selected columns are in the header")
            .clone();
        let integers = values.iter().all(|v| v.is_nan() || v.fract() == 0.0);
        let unit = unit_of(args, &col, Some(integers)).with_context(|| shown.clone())?;
        let missing = values.iter().filter(|v| v.is_nan()).count();
        if missing > 0 {
            eprintln!(
                "note: {shown}: column {name:?} has {missing} empty fields (missing readings)"
            );
        }
        let mut values = values;
        if scale != 1.0 && is_scaled(name) {
            values.iter_mut().for_each(|v| *v *= scale);
        }
        values.shrink_to_fit();
        if let Some((i, v)) = values.iter().enumerate().find(|(_, v)| v.abs() > VALUE_MAX) {
            bail!(
                "{shown}: column {name:?}, data row {}: {v:e} {unit} after --scale {}: no \
                 sensor reads that much; check --scale",
                i + 1,
                num(scale)
            );
        }
        columns.push(Series {
            name: name.clone(),
            unit,
            values,
        });
    }
    Ok(Recording {
        rate_hz,
        columns,
        timing,
        segments,
    })
}

/// A number as typed: plain for everyday magnitudes, scientific for huge or tiny ones.
pub fn num(x: f64) -> String {
    if x != 0.0 && x.is_finite() && !(1e-4..1e7).contains(&x.abs()) {
        format!("{x:e}")
    } else {
        format!("{x}")
    }
}

/// Six significant digits without trailing zeros.
fn short(x: f64) -> String {
    let s = crate::render::sig(x, 6);
    if s.contains('.') && !s.contains('e') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    }
}

fn progress_bar(bytes: u64) -> indicatif::ProgressBar {
    use std::io::IsTerminal;
    if bytes < 8 << 20 || !std::io::stderr().is_terminal() {
        return indicatif::ProgressBar::hidden();
    }
    let pb = indicatif::ProgressBar::new(bytes);
    pb.set_style(
        indicatif::ProgressStyle::with_template("reading {bytes}/{total_bytes} [{bar:40}] {eta}")
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    );
    pb
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Write;

    fn args(file: &tempfile::NamedTempFile) -> InputArgs {
        InputArgs::for_file(file.path())
    }

    fn csv(text: &str) -> tempfile::NamedTempFile {
        let mut f = tempfile::NamedTempFile::new().unwrap();
        f.write_all(text.as_bytes()).unwrap();
        f
    }

    fn err(a: &InputArgs, wanted: &[&str]) -> String {
        format!("{:#}", load(a, wanted).unwrap_err())
    }

    fn clock_csv(n: usize, rate: f64, shift: impl Fn(usize) -> f64) -> tempfile::NamedTempFile {
        let mut s = String::from("t,gz\n");
        for i in 0..n {
            s += &format!(
                "{},{}\n",
                i as f64 / rate + shift(i),
                (i * 7 % 5) as f64 * 0.1
            );
        }
        csv(&s)
    }

    #[test]
    fn rate_from_t_and_units() {
        let f = csv("t,gz,other\n0.0,1.5,x\n0.01,2.5,y\n0.02,3.5,z\n");
        let r = load(&args(&f), &["gz"]).unwrap();
        assert!((r.rate_hz - 100.0).abs() < 1e-9);
        let gz = r.column("gz").unwrap();
        assert_eq!(gz.unit, "deg/s");
        assert_eq!(gz.values, vec![1.5, 2.5, 3.5]);
        assert_eq!(r.columns.len(), 1, "t is read but not returned");
    }

    #[test]
    fn malformed_field_names_line_and_field() {
        let f = csv("t,gz\n0,1\n0.01,abc\n");
        let e = err(&args(&f), &["gz"]);
        assert!(
            e.contains("line 3") && e.contains("\"gz\"") && e.contains("abc"),
            "{e}"
        );
    }

    #[test]
    fn nan_is_refused_with_its_place() {
        let f = csv("t,gz\n0,1\n0.01,NaN\n");
        let e = err(&args(&f), &["gz"]);
        assert!(
            e.contains("line 3") && e.contains("not a finite number"),
            "{e}"
        );
    }

    #[test]
    fn ragged_row_is_refused() {
        let f = csv("t,gz\n0,1\n0.01\n");
        let e = err(&args(&f), &["gz"]);
        assert!(
            e.contains("line 3: 1 field where the rows before have 2"),
            "{e}"
        );
    }

    #[test]
    fn skip_lines_scale_unit_and_rename() {
        let f = csv("Fs,100\nmeta,1\nax,gyro_z\n1,131\n2,262\n");
        let mut a = args(&f);
        a.skip_lines = 2;
        a.rate = Some(100.0);
        a.scale = Some(1.0 / 131.0);
        a.rename = vec!["gyro_z=gz".into()];
        let r = load(&a, &["gz"]).unwrap();
        let gz = r.column("gz").unwrap();
        assert_eq!(gz.unit, "deg/s");
        assert!((gz.values[1] - 2.0).abs() < 1e-12);
    }

    #[test]
    fn raw_counts_without_scale_are_counts() {
        // Metadata lines above a contract-named header, whole numbers: counts, not deg/s.
        let f = csv("Fs,100\nmeta,1\nax,gz\n1,131\n2,262\n");
        let mut a = args(&f);
        a.skip_lines = 2;
        a.rate = Some(100.0);
        let r = load(&a, &["gz"]).unwrap();
        assert_eq!(r.column("gz").unwrap().unit, COUNTS);
        // The time column is not a measurement.
        let f = csv("t,gz\n0,1.5\n0.01,2.5\n");
        assert!(err(&args(&f), &["t"]).contains("not a measurement"));
        // A contract file whose column holds only whole numbers: counts, not deg/s; with a
        // fraction anywhere, the contract's unit.
        let f = csv("t,gz\n0,131\n0.01,-262\n");
        assert_eq!(load(&args(&f), &["gz"]).unwrap().columns[0].unit, COUNTS);
        let f = csv("t,gz\n0,131\n0.01,-2.5\n");
        assert_eq!(load(&args(&f), &["gz"]).unwrap().columns[0].unit, "deg/s");
        // A renamed column of whole numbers too.
        let f = csv("t,gyro_z\n0,131\n0.01,262\n");
        let mut a = args(&f);
        a.rename = vec!["gyro_z=gz".into()];
        assert_eq!(load(&a, &["gz"]).unwrap().columns[0].unit, COUNTS);
        // A renamed column of fractions states no unit: refused until --unit says.
        let f = csv("t,mx_gauss\n0,0.21\n0.01,0.22\n");
        let mut a = args(&f);
        a.rename = vec!["mx_gauss=mx".into()];
        let e = err(&a, &["mx"]);
        assert!(
            e.contains("does not state its unit") && e.contains("mx_gauss"),
            "{e}"
        );
        a.unit = Some("G".into());
        assert_eq!(load(&a, &["mx"]).unwrap().columns[0].unit, "G");
        a.unit = None;
        a.scale = Some(100.0);
        assert_eq!(load(&a, &["mx"]).unwrap().columns[0].unit, "µT");
    }

    #[test]
    fn temperature_is_optional_never_scaled_and_may_be_empty() {
        let f = csv("gx,temp\n131,25.5\n262,\n393,25.7\n");
        let mut a = args(&f);
        a.rate = Some(10.0);
        a.scale = Some(1.0 / 131.0);
        a.unit = Some("deg/s".into());
        let r = load_with(&a, &["gx"], &["temp", "mx"]).unwrap();
        assert_eq!(r.columns.len(), 2, "mx is absent and optional");
        let temp = r.column("temp").unwrap();
        assert_eq!((temp.unit.as_str(), temp.values[2]), ("°C", 25.7));
        assert!(temp.values[1].is_nan());
        assert!((r.column("gx").unwrap().values[1] - 2.0).abs() < 1e-12);
    }

    #[test]
    fn missing_column_lists_the_header() {
        let f = csv("t,gx\n0,1\n1,2\n");
        let e = err(&args(&f), &["gz"]);
        assert!(
            e.contains("no column named \"gz\"") && e.contains("t, gx"),
            "{e}"
        );
    }

    #[test]
    fn backwards_time_is_refused() {
        let f = csv("t,gz\n0,1\n0.02,2\n0.01,3\n");
        let e = err(&args(&f), &["gz"]);
        assert!(e.contains("time goes backwards"), "{e}");
    }

    #[test]
    fn duplicated_column_names_are_refused() {
        let f = csv("t,gx,gx\n0,1,2\n0.01,2,3\n");
        let e = err(&args(&f), &["gx"]);
        assert!(e.contains("\"gx\" appears twice"), "{e}");
    }

    #[test]
    fn rate_must_agree_with_t_unless_time_is_ignored() {
        let f = clock_csv(500, 100.0, |_| 0.0);
        let mut a = args(&f);
        for bad in [102.0, 50.0] {
            a.rate = Some(bad);
            let e = err(&a, &["gz"]);
            assert!(
                e.contains("disagrees with the time column") && e.contains("100 Hz"),
                "{e}"
            );
        }
        a.rate = Some(100.5);
        assert_eq!(load(&a, &["gz"]).unwrap().rate_hz, 100.5);
        a.rate = Some(50.0);
        a.ignore_time = true;
        let r = load(&a, &["gz"]).unwrap();
        assert_eq!((r.rate_hz, r.segments.len()), (50.0, 1));
        assert!(r.timing.is_none());
        a.rate = None;
        assert!(err(&a, &["gz"]).contains("--ignore-time"));
    }

    #[test]
    fn absurd_rates_and_scales_are_refused() {
        let f = clock_csv(50, 100.0, |_| 0.0);
        let mut a = args(&f);
        a.ignore_time = true;
        for r in [1e300, 1e200, 1e-100, 1e-300, 0.0, -5.0, 2e7] {
            a.rate = Some(r);
            assert!(err(&a, &["gz"]).contains("between"), "rate {r}");
        }
        a.rate = Some(100.0);
        for s in [1e308, 1e-300, 0.0] {
            a.scale = Some(s);
            assert!(err(&a, &["gz"]).contains("--scale"), "scale {s}");
        }
        // The rate read from t is checked too: stamps 1e-9 s apart.
        let f = clock_csv(50, 1e9, |_| 0.0);
        assert!(err(&args(&f), &["gz"]).contains("between"));
    }

    #[test]
    fn gaps_split_the_record_and_keep_the_rate() {
        // A 0.5 s gap (row 300 on) in 100 Hz: 49 samples missing, 100 Hz still.
        let f = clock_csv(1000, 100.0, |i| if i >= 300 { 0.49 } else { 0.0 });
        let r = load(&args(&f), &["gz"]).unwrap();
        assert!((r.rate_hz - 100.0).abs() < 1e-6, "{}", r.rate_hz);
        assert_eq!(r.segments, vec![0..300, 300..1000]);
        let tm = r.timing.unwrap();
        assert_eq!((tm.gaps.len(), tm.missing_samples()), (1, 49));
        // A 1000 s gap: 10 s of data, not 1010 s.
        let f = clock_csv(1000, 100.0, |i| if i >= 500 { 1000.0 } else { 0.0 });
        let r = load(&args(&f), &["gz"]).unwrap();
        assert!((r.rate_hz - 100.0).abs() < 1e-6);
        assert!((r.samples() as f64 / r.rate_hz - 10.0).abs() < 1e-9);
        assert_eq!(r.segments.len(), 2);
    }

    #[test]
    fn device_reported_gaps_are_the_segments() {
        let mut s = String::from("t,gap_before,gz\n");
        let mut t_us = 0u64;
        for i in 0..200 {
            let gap = if i == 120 { 32 } else { 0 };
            t_us += 1000 * (1 + gap);
            s += &format!("{:.6},{gap},{}\n", t_us as f64 * 1e-6, i % 3);
        }
        let f = csv(&s);
        let r = load(&args(&f), &["gz"]).unwrap();
        assert!((r.rate_hz - 1000.0).abs() < 1e-6, "{}", r.rate_hz);
        assert_eq!(r.segments, vec![0..120, 120..200]);
        let tm = r.timing.unwrap();
        assert!(tm.gaps[0].reported && tm.gaps[0].missing_samples == 32);
    }
}
