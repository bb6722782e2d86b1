//! Writing a recording in the contract.
use std::io::Write;

use super::{may_be_empty, CsvError, GAP_BEFORE, HEADER, ORIENTATION, TIME};

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
                .chain(&ORIENTATION)
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
                GAP_BEFORE | "ahrs" => write!(self.line, "{}", v.max(0.0).round() as u64),
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
