//! The CSV recording contract (`imu_proto::csv`) read into numpy arrays.
use std::fs::File;
use std::io::BufReader;

use imu_proto::csv::{timing, ReadOptions, Reader, GAP_BEFORE, HEADER, TIME};
use numpy::IntoPyArray;
use pyo3::exceptions::PyOSError;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};

use crate::{guarded, value_error};

/// Largest magnitude of a value read (as `imu-lab`'s `VALUE_MAX`).
const VALUE_MAX: f64 = 1e100;

/// Reads a recording that follows the contract (docs: README, "The lab"): a dict with
/// `columns` (name → float array, in the contract's unit), `units` (name → unit), `t` (s, or
/// None), `rate_hz` (from the median spacing of `t`, or None without `t`), `segments`
/// (list of (start, stop) row ranges between gaps) and `timing` (a dict: `median_dt_s`,
/// `gaps`, `missing_samples`, `irregular`, `summary`). A malformed file raises `ValueError`
/// naming the line and field; a file that cannot be opened, `OSError`.
#[pyfunction]
#[pyo3(signature = (path, skip_lines=0))]
pub fn read_csv<'py>(
    py: Python<'py>,
    path: &str,
    skip_lines: usize,
) -> PyResult<Bound<'py, PyDict>> {
    let file = File::open(path).map_err(|e| PyOSError::new_err(format!("{path}: {e}")))?;
    let (names, data, tm) = py.detach(|| {
        guarded("read_csv", || {
            let opts = ReadOptions {
                skip_lines,
                renames: Vec::new(),
            };
            let mut r = Reader::new(BufReader::new(file), path, &opts)
                .map_err(|e| value_error(e.to_string()))?;
            let wanted: Vec<&str> = HEADER
                .iter()
                .copied()
                .filter(|h| r.column(h).is_some())
                .collect();
            if wanted.is_empty() {
                return Err(value_error(format!(
                    "{path}: no contract column in the header (expected some of {})",
                    HEADER.join(", ")
                )));
            }
            let names = r
                .select(&wanted, &[])
                .map_err(|e| value_error(e.to_string()))?;
            let mut buf = vec![0.0; names.len()];
            let mut cols: Vec<Vec<f64>> = vec![Vec::new(); names.len()];
            while r
                .next_row(&mut buf)
                .map_err(|e| value_error(e.to_string()))?
            {
                for (c, v) in cols.iter_mut().zip(&buf) {
                    c.push(*v);
                }
            }
            // As `imu-lab`'s reader: a value no sensor reads is a corrupt field or a wrong unit
            // (squared in a deviation it would overflow).
            for (n, c) in names.iter().zip(&cols) {
                if let Some((i, v)) = c.iter().enumerate().find(|(_, v)| v.abs() > VALUE_MAX) {
                    return Err(value_error(format!(
                        "{path}: column {n:?}, data row {}: {v:e}: no sensor reads that much",
                        i + 1
                    )));
                }
            }
            let col = |n: &str| names.iter().position(|x| x == n).map(|i| &cols[i]);
            let tm = match col(TIME) {
                Some(t) => Some(
                    timing(t, col(GAP_BEFORE).map(Vec::as_slice))
                        .map_err(|e| value_error(format!("{path}: column \"t\": {e}")))?,
                ),
                None => None,
            };
            Ok((names, cols, tm))
        })
    })?;
    let rows = data.first().map_or(0, Vec::len);
    let out = PyDict::new(py);
    let columns = PyDict::new(py);
    let units = PyDict::new(py);
    for (n, c) in names.iter().zip(data) {
        if n == TIME {
            out.set_item("t", c.clone().into_pyarray(py))?;
        }
        if let Some(u) = imu_proto::csv::unit(n) {
            units.set_item(n, u)?;
        }
        columns.set_item(n, c.into_pyarray(py))?;
    }
    if !names.iter().any(|n| n == TIME) {
        out.set_item("t", py.None())?;
    }
    out.set_item("columns", columns)?;
    out.set_item("units", units)?;
    set_timing(py, &out, tm.as_ref(), rows)?;
    Ok(out)
}

/// Sets `rate_hz` (Hz), `segments` (row ranges between gaps) and `timing` in `out` from the
/// time column's timing (`None` without a time column: one segment of `rows` rows).
pub(crate) fn set_timing(
    py: Python<'_>,
    out: &Bound<'_, PyDict>,
    tm: Option<&imu_proto::csv::Timing>,
    rows: usize,
) -> PyResult<()> {
    let segments = PyList::empty(py);
    match tm {
        Some(t) => {
            out.set_item("rate_hz", t.rate_hz())?;
            for s in t.segments() {
                segments.append((s.start, s.end))?;
            }
            let d = PyDict::new(py);
            d.set_item("median_dt_s", t.median_dt_s)?;
            d.set_item("gaps", t.gaps.len())?;
            d.set_item("missing_samples", t.missing_samples())?;
            d.set_item("irregular", t.irregular())?;
            d.set_item("summary", t.describe())?;
            out.set_item("timing", d)?;
        }
        None => {
            out.set_item("rate_hz", py.None())?;
            segments.append((0usize, rows))?;
            out.set_item("timing", py.None())?;
        }
    }
    out.set_item("segments", segments)
}
