//! The CSV input contract shared by every subcommand.
//!
//! * A header row, then one sample per row. Columns are chosen by name among
//!   `t` (s), `ax ay az` (m/s²), `gx gy gz` (deg/s), `mx my mz` (µT) and `temp` (°C);
//!   other columns are ignored.
//! * The sample rate comes from `--rate`, or else from `t` as (N − 1)/duration.
//! * Other layouts are read with flags: `--skip-lines N` skips metadata lines before the header,
//!   `--rename OLD=NEW` maps a column name onto the contract, `--scale K --unit U` converts raw
//!   counts (every selected column except `t` is multiplied by K and reported in U).
//! * A malformed file is refused with an error naming the line and the field.
use std::fs::File;
use std::io::{BufRead, BufReader, Read};
use std::path::PathBuf;

use anyhow::{anyhow, bail, Context, Result};

/// Flags for reading a recording (flattened into each subcommand).
#[derive(clap::Args, Debug, Clone)]
pub struct InputArgs {
    /// CSV recording (header row; columns t, ax ay az, gx gy gz, mx my mz, temp).
    pub file: PathBuf,
    /// Sample rate in Hz (default: from the `t` column).
    #[arg(long)]
    pub rate: Option<f64>,
    /// Metadata lines to skip before the header row.
    #[arg(long, default_value_t = 0)]
    pub skip_lines: usize,
    /// Multiply the selected columns (not `t`) by this factor, e.g. 0.0076336 for ±250 °/s counts.
    #[arg(long)]
    pub scale: Option<f64>,
    /// Unit of the selected columns after scaling (default: the contract's unit for the name).
    #[arg(long)]
    pub unit: Option<String>,
    /// Rename columns onto the contract, OLD=NEW (comma-separated or repeated), e.g. mx_gauss=mx.
    #[arg(long, value_delimiter = ',')]
    pub rename: Vec<String>,
}

/// One selected column.
#[derive(Debug, Clone)]
pub struct Series {
    /// Contract name (`gz`, `mx`, …).
    pub name: String,
    /// Unit of `values`.
    pub unit: String,
    /// The samples.
    pub values: Vec<f64>,
}

/// The columns read from a recording, with its rate.
#[derive(Debug, Clone)]
pub struct Recording {
    /// Sample rate in Hz.
    pub rate_hz: f64,
    /// The requested columns, in the order asked.
    pub columns: Vec<Series>,
}

impl Recording {
    /// The column called `name`.
    pub fn column(&self, name: &str) -> Option<&Series> {
        self.columns.iter().find(|c| c.name == name)
    }
}

/// The contract's unit for a column name, if it is a contract column.
pub fn contract_unit(name: &str) -> Option<&'static str> {
    Some(match name {
        "t" => "s",
        "ax" | "ay" | "az" => "m/s²",
        "gx" | "gy" | "gz" => "deg/s",
        "mx" | "my" | "mz" => "µT",
        "temp" => "°C",
        _ => return None,
    })
}

/// A recording opened for row-by-row reading: constant memory, whatever the file's length.
pub struct Rows {
    shown: String,
    skip_lines: usize,
    csv: csv::Reader<Box<dyn Read>>,
    record: csv::StringRecord,
    /// Contract names read, in order: the wanted columns, then `t` when present.
    pub names: Vec<String>,
    idx: Vec<usize>,
    progress: indicatif::ProgressBar,
    /// Whether a `t` column is read (it is then the last of `names`).
    pub has_t: bool,
    /// File line of the last row read.
    pub line: usize,
}

impl Rows {
    /// Read the next row into `out` (one value per name, unscaled). `Ok(false)` at the end.
    pub fn next_into(&mut self, out: &mut [f64]) -> Result<bool> {
        match self.csv.read_record(&mut self.record) {
            Ok(false) => {
                self.progress.finish_and_clear();
                return Ok(false);
            }
            Ok(true) => {}
            Err(e) => {
                let line = e
                    .position()
                    .map(|p| p.line() as usize + self.skip_lines)
                    .unwrap_or(0);
                bail!("{}: line {line}: malformed CSV: {e}", self.shown);
            }
        }
        self.line = self
            .record
            .position()
            .map(|p| p.line() as usize + self.skip_lines)
            .unwrap_or(0);
        for (k, &i) in self.idx.iter().enumerate() {
            let field = self.record.get(i).unwrap_or("");
            let v: f64 = field.parse().map_err(|_| {
                anyhow!(
                    "{}: line {}: field {:?} (column {}) is {field:?}, not a number",
                    self.shown,
                    self.line,
                    self.names[k],
                    i + 1
                )
            })?;
            if !v.is_finite() {
                bail!(
                    "{}: line {}: field {:?} (column {}) is {field:?}, not a finite number",
                    self.shown,
                    self.line,
                    self.names[k],
                    i + 1
                );
            }
            out[k] = v;
        }
        Ok(true)
    }
}

/// Open the recording and find the columns `wanted` (contract names, after renaming).
pub fn open(args: &InputArgs, wanted: &[&str]) -> Result<Rows> {
    open_with(args, wanted, &[])
}

/// As [`open`], also reading the columns of `optional` that the file has.
pub fn open_with(args: &InputArgs, wanted: &[&str], optional: &[&str]) -> Result<Rows> {
    let path = &args.file;
    let shown = path.display().to_string();
    let file = File::open(path).with_context(|| format!("cannot open {shown}"))?;
    let size = file.metadata().map(|m| m.len()).unwrap_or(0);
    let progress = progress_bar(size);
    let mut reader = BufReader::with_capacity(1 << 16, progress.wrap_read(file));
    let mut line = String::new();
    for i in 0..args.skip_lines {
        line.clear();
        if reader
            .read_line(&mut line)
            .with_context(|| format!("{shown}: reading line {}", i + 1))?
            == 0
        {
            bail!(
                "{shown}: the file has only {i} lines, but --skip-lines {} was given",
                args.skip_lines
            );
        }
    }
    let mut renames = Vec::new();
    for r in &args.rename {
        let (old, new) = r
            .split_once('=')
            .ok_or_else(|| anyhow!("--rename {r:?}: expected OLD=NEW"))?;
        renames.push((old.trim().to_string(), new.trim().to_string()));
    }
    let mut csv = csv::ReaderBuilder::new()
        .has_headers(true)
        .trim(csv::Trim::All)
        .from_reader(Box::new(reader) as Box<dyn Read>);
    let header_line = args.skip_lines + 1;
    let headers: Vec<String> = csv
        .headers()
        .with_context(|| format!("{shown}: line {header_line}: cannot read the header row"))?
        .iter()
        .map(|h| {
            renames
                .iter()
                .find(|(old, _)| old == h)
                .map(|(_, new)| new.clone())
                .unwrap_or_else(|| h.to_string())
        })
        .collect();
    let mut names: Vec<String> = wanted.iter().map(|w| w.to_string()).collect();
    for o in optional {
        if headers.iter().any(|h| h == o) && !names.iter().any(|n| n == o) {
            names.push(o.to_string());
        }
    }
    let has_t = headers.iter().any(|h| h == "t") && !names.iter().any(|n| n == "t");
    if has_t {
        names.push("t".into());
    }
    let mut idx = Vec::with_capacity(names.len());
    for w in &names {
        let i = headers.iter().position(|h| h == w).ok_or_else(|| {
            anyhow!(
                "{shown}: line {header_line}: no column named {w:?} in the header ({}); use --rename OLD={w} or --skip-lines to reach the header",
                headers.join(", ")
            )
        })?;
        idx.push(i);
    }
    Ok(Rows {
        shown,
        skip_lines: args.skip_lines,
        csv,
        record: csv::StringRecord::new(),
        names,
        idx,
        progress,
        has_t,
        line: header_line,
    })
}

/// Whether `--scale` and `--unit` apply to a column: every selected column but the time `t` (s)
/// and the temperature `temp` (°C), which are always in the contract's units.
pub fn is_scaled(name: &str) -> bool {
    name != "t" && name != "temp"
}

/// The unit of a selected column after the reading flags.
pub fn unit_of(args: &InputArgs, name: &str) -> Result<String> {
    let flag = if is_scaled(name) { &args.unit } else { &None };
    match (flag, contract_unit(name)) {
        (Some(u), _) => Ok(u.clone()),
        (None, Some(u)) => Ok(u.to_string()),
        (None, None) => bail!("column {name:?} is not in the contract: give its unit with --unit"),
    }
}

/// The `--scale` factor (1 when absent), refusing 0 and non-finite values.
pub fn scale_of(args: &InputArgs) -> Result<f64> {
    let scale = args.scale.unwrap_or(1.0);
    if !(scale.is_finite() && scale != 0.0) {
        bail!("--scale {scale}: must be a non-zero number");
    }
    Ok(scale)
}

/// The sample rate from `--rate`, or else from the first and last `t` of `n` rows.
pub fn rate_of(
    args: &InputArgs,
    shown: &str,
    t_first_last: Option<(f64, f64)>,
    n: usize,
) -> Result<f64> {
    match (args.rate, t_first_last) {
        (Some(r), _) if r > 0.0 && r.is_finite() => Ok(r),
        (Some(r), _) => bail!("--rate {r}: the rate must be a positive number of Hz"),
        (None, Some((t0, t1))) if n >= 2 && t1 > t0 => Ok((n - 1) as f64 / (t1 - t0)),
        (None, Some((t0, t1))) => bail!(
            "{shown}: cannot derive the rate from column \"t\" ({n} rows from {t0} s to {t1} s)"
        ),
        (None, None) => bail!("{shown}: no --rate given and no \"t\" column to derive it from"),
    }
}

/// Read the columns `wanted` (contract names, after renaming) from the recording.
pub fn load(args: &InputArgs, wanted: &[&str]) -> Result<Recording> {
    load_with(args, wanted, &[])
}

/// As [`load`], also reading the columns of `optional` that the file has (e.g. `temp`); they
/// follow the wanted ones in `columns`.
pub fn load_with(args: &InputArgs, wanted: &[&str], optional: &[&str]) -> Result<Recording> {
    let mut rows = open_with(args, wanted, optional)?;
    let shown = rows.shown.clone();
    let mut data: Vec<Vec<f64>> = vec![Vec::new(); rows.names.len()];
    let mut buf = vec![0.0; rows.names.len()];
    let mut n = 0usize;
    while rows.next_into(&mut buf)? {
        for (col, v) in data.iter_mut().zip(&buf) {
            col.push(*v);
        }
        n += 1;
    }
    if n == 0 {
        bail!(
            "{shown}: no data rows after the header (line {})",
            args.skip_lines + 1
        );
    }
    let names: Vec<String> = rows.names.clone();
    let t = if rows.has_t {
        data.pop()
    } else {
        names.iter().position(|w| w == "t").map(|i| data[i].clone())
    };
    if let Some(t) = &t {
        check_time(t).with_context(|| format!("{shown}: column \"t\""))?;
    }
    let rate_hz = rate_of(args, &shown, t.as_ref().map(|t| (t[0], t[t.len() - 1])), n)?;
    let scale = scale_of(args)?;
    let mut columns = Vec::with_capacity(names.len());
    for (w, values) in names.iter().zip(data) {
        let unit = unit_of(args, w)?;
        let values = if scale == 1.0 || !is_scaled(w) {
            values
        } else {
            values.iter().map(|v| v * scale).collect()
        };
        columns.push(Series {
            name: w.to_string(),
            unit,
            values,
        });
    }
    Ok(Recording { rate_hz, columns })
}

/// Refuse a time column that goes backwards.
fn check_time(t: &[f64]) -> Result<()> {
    if let Some(i) = t.windows(2).position(|w| w[1] < w[0]) {
        bail!(
            "time goes backwards between data rows {} and {} ({} s → {} s)",
            i + 1,
            i + 2,
            t[i],
            t[i + 1]
        );
    }
    Ok(())
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
        InputArgs {
            file: file.path().to_path_buf(),
            rate: None,
            skip_lines: 0,
            scale: None,
            unit: None,
            rename: vec![],
        }
    }

    fn csv(text: &str) -> tempfile::NamedTempFile {
        let mut f = tempfile::NamedTempFile::new().unwrap();
        f.write_all(text.as_bytes()).unwrap();
        f
    }

    #[test]
    fn rate_from_t_and_units() {
        let f = csv("t,gz,other\n0.0,1.5,x\n0.01,2.5,y\n0.02,3.5,z\n");
        let r = load(&args(&f), &["gz"]).unwrap();
        assert!((r.rate_hz - 100.0).abs() < 1e-9);
        let gz = r.column("gz").unwrap();
        assert_eq!(gz.unit, "deg/s");
        assert_eq!(gz.values, vec![1.5, 2.5, 3.5]);
    }

    #[test]
    fn malformed_field_names_line_and_field() {
        let f = csv("t,gz\n0,1\n0.01,abc\n");
        let e = format!("{:#}", load(&args(&f), &["gz"]).unwrap_err());
        assert!(
            e.contains("line 3") && e.contains("\"gz\"") && e.contains("abc"),
            "{e}"
        );
    }

    #[test]
    fn nan_is_refused_with_its_place() {
        let f = csv("t,gz\n0,1\n0.01,NaN\n");
        let e = format!("{:#}", load(&args(&f), &["gz"]).unwrap_err());
        assert!(
            e.contains("line 3") && e.contains("not a finite number"),
            "{e}"
        );
    }

    #[test]
    fn ragged_row_is_refused() {
        let f = csv("t,gz\n0,1\n0.01\n");
        let e = format!("{:#}", load(&args(&f), &["gz"]).unwrap_err());
        assert!(e.contains("line 3") && e.contains("malformed"), "{e}");
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
    fn temperature_is_optional_and_never_scaled() {
        let f = csv("gx,temp\n131,25.5\n262,25.6\n");
        let mut a = args(&f);
        a.rate = Some(10.0);
        a.scale = Some(1.0 / 131.0);
        a.unit = Some("deg/s".into());
        let r = load_with(&a, &["gx"], &["temp", "mx"]).unwrap();
        assert_eq!(r.columns.len(), 2, "mx is absent and optional");
        let temp = r.column("temp").unwrap();
        assert_eq!((temp.unit.as_str(), temp.values[1]), ("°C", 25.6));
        assert!((r.column("gx").unwrap().values[1] - 2.0).abs() < 1e-12);
    }

    #[test]
    fn missing_column_lists_the_header() {
        let f = csv("t,gx\n0,1\n1,2\n");
        let e = format!("{:#}", load(&args(&f), &["gz"]).unwrap_err());
        assert!(
            e.contains("no column named \"gz\"") && e.contains("t, gx"),
            "{e}"
        );
    }

    #[test]
    fn backwards_time_is_refused() {
        let f = csv("t,gz\n0,1\n0.02,2\n0.01,3\n");
        let e = format!("{:#}", load(&args(&f), &["gz"]).unwrap_err());
        assert!(e.contains("time goes backwards"), "{e}");
    }
}
