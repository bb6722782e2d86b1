//! A contract recording read in chunks of rows, with the gaps found on the way: a file of any
//! length in bounded memory (for the streaming engine).
use std::collections::VecDeque;
use std::fs::File;
use std::io::BufReader;

use imu_proto::csv::{read_clock, ReadOptions, Reader, TimingScan, GAP_BEFORE, HEADER, TIME};
use numpy::IntoPyArray;
use pyo3::exceptions::{PyOSError, PyStopIteration};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::{guarded, value_error};

/// Stamps read before the first chunk to learn the sample clock (as `imu-lab adev --bounded`).
const CLOCK_ROWS: usize = 1 << 16;

/// Rows of a recording, `rows` at a time: each chunk a dict with `start` (the index of its
/// first row in the file), `columns` (name → array, contract units), `gaps` (offsets in the
/// chunk of the rows a gap precedes: each starts a new segment). The sample clock is read from
/// the first 65 536 stamps, so `rate_hz` is known before the first chunk.
#[pyclass(module = "pico_imu._native")]
pub struct CsvChunks {
    path: String,
    reader: Reader<BufReader<File>>,
    names: Vec<String>,
    /// Rows read to learn the clock and not yet handed out: (values, file line).
    held: VecDeque<(Vec<f64>, usize)>,
    scan: Option<TimingScan>,
    time: Option<usize>,
    gap: Option<usize>,
    rows: usize,
    chunk: usize,
    rate_hz: Option<f64>,
    done: bool,
}

impl CsvChunks {
    /// The next row (values, file line), from the held rows first.
    fn next_row(&mut self) -> PyResult<Option<(Vec<f64>, usize)>> {
        if let Some(r) = self.held.pop_front() {
            return Ok(Some(r));
        }
        let mut buf = vec![0.0; self.names.len()];
        if self
            .reader
            .next_row(&mut buf)
            .map_err(|e| value_error(e.to_string()))?
        {
            Ok(Some((buf, self.reader.line())))
        } else {
            Ok(None)
        }
    }

    fn read_chunk(&mut self) -> PyResult<(usize, Vec<Vec<f64>>, Vec<u64>)> {
        let start = self.rows;
        // Reserved up to 65 536 rows, grown beyond as rows come: `rows` is a most, and a huge
        // one (10¹²) reserved at once aborted the interpreter.
        let mut cols: Vec<Vec<f64>> =
            vec![Vec::with_capacity(self.chunk.min(1 << 16)); self.names.len()];
        let mut gaps = Vec::new();
        while cols[0].len() < self.chunk {
            let Some((row, line)) = self.next_row()? else {
                self.done = true;
                break;
            };
            if let (Some(scan), Some(ti)) = (self.scan.as_mut(), self.time) {
                let g = self.gap.map_or(0.0, |gi| row[gi]);
                let found = scan.push(row[ti], g).map_err(|e| {
                    value_error(format!("{}: line {line}: column \"t\": {e}", self.path))
                })?;
                if found.is_some() {
                    gaps.push(cols[0].len() as u64);
                }
            }
            for (c, v) in cols.iter_mut().zip(&row) {
                c.push(*v);
            }
            self.rows += 1;
        }
        Ok((start, cols, gaps))
    }
}

#[pymethods]
impl CsvChunks {
    /// Opens `path`, chooses `columns` (default: every contract column it has; `t` and
    /// `gap_before` are always added when present) and reads the sample clock.
    #[new]
    #[pyo3(signature = (path, columns=None, rows=65536, skip_lines=0))]
    fn new(
        py: Python<'_>,
        path: &str,
        columns: Option<Vec<String>>,
        rows: usize,
        skip_lines: usize,
    ) -> PyResult<Self> {
        if rows == 0 {
            return Err(value_error("rows=0: a chunk needs at least one row"));
        }
        let file = File::open(path).map_err(|e| PyOSError::new_err(format!("{path}: {e}")))?;
        py.detach(|| {
            guarded("read_csv_chunks", || {
                let opts = ReadOptions {
                    skip_lines,
                    renames: Vec::new(),
                };
                let mut reader = Reader::new(BufReader::new(file), path, &opts)
                    .map_err(|e| value_error(e.to_string()))?;
                let wanted: Vec<String> = match columns {
                    Some(c) => c,
                    None => HEADER
                        .iter()
                        .filter(|h| reader.column(h).is_some())
                        .map(|h| h.to_string())
                        .collect(),
                };
                if wanted.is_empty() {
                    return Err(value_error(format!(
                        "{path}: no contract column in the header (expected some of {})",
                        HEADER.join(", ")
                    )));
                }
                let refs: Vec<&str> = wanted.iter().map(String::as_str).collect();
                let names = reader
                    .select(&refs, &[])
                    .map_err(|e| value_error(e.to_string()))?;
                let time = names.iter().position(|n| n == TIME);
                let gap = names.iter().position(|n| n == GAP_BEFORE);
                let mut me = CsvChunks {
                    path: path.to_string(),
                    reader,
                    names,
                    held: VecDeque::new(),
                    scan: None,
                    time,
                    gap,
                    rows: 0,
                    chunk: rows,
                    rate_hz: None,
                    done: false,
                };
                if let Some(ti) = time {
                    while me.held.len() < CLOCK_ROWS {
                        let mut buf = vec![0.0; me.names.len()];
                        if !me
                            .reader
                            .next_row(&mut buf)
                            .map_err(|e| value_error(e.to_string()))?
                        {
                            break;
                        }
                        me.held.push_back((buf, me.reader.line()));
                    }
                    if me.held.len() >= 2 {
                        let t: Vec<f64> = me.held.iter().map(|(r, _)| r[ti]).collect();
                        let g: Option<Vec<f64>> =
                            gap.map(|gi| me.held.iter().map(|(r, _)| r[gi]).collect());
                        let clock = read_clock(&t, g.as_deref())
                            .map_err(|e| value_error(format!("{path}: column \"t\": {e}")))?;
                        me.rate_hz = Some(1.0 / clock.period_s);
                        me.scan = Some(TimingScan::new(clock));
                    }
                }
                Ok(me)
            })
        })
    }

    /// The column names each chunk holds, in order.
    #[getter]
    fn names(&self) -> Vec<String> {
        self.names.clone()
    }

    /// The contract unit of each chosen column (name → unit).
    #[getter]
    fn units(&self) -> std::collections::HashMap<String, &'static str> {
        self.names
            .iter()
            .filter_map(|n| imu_proto::csv::unit(n).map(|u| (n.clone(), u)))
            .collect()
    }

    /// The sample rate from the median spacing of the first stamps (Hz), or None without `t`.
    #[getter]
    fn rate_hz(&self) -> Option<f64> {
        self.rate_hz
    }

    fn __iter__(slf: PyRef<'_, Self>) -> PyRef<'_, Self> {
        slf
    }

    fn __next__<'py>(&mut self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        if self.done {
            return Err(PyStopIteration::new_err(()));
        }
        let (start, cols, gaps) = py.detach(|| guarded("read_csv_chunks", || self.read_chunk()))?;
        if cols[0].is_empty() {
            return Err(PyStopIteration::new_err(()));
        }
        let out = PyDict::new(py);
        out.set_item("start", start)?;
        let columns = PyDict::new(py);
        for (n, c) in self.names.iter().zip(cols) {
            columns.set_item(n, c.into_pyarray(py))?;
        }
        out.set_item("columns", columns)?;
        out.set_item("gaps", gaps.into_pyarray(py))?;
        Ok(out)
    }
}
