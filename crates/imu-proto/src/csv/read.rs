//! Reading a recording row by row (constant memory whatever the file's length).
use std::io::{BufRead, BufReader, Read};

use super::{may_be_empty, CsvError, GAP_BEFORE, HEADER, TIME};

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
        // Fields are trimmed where they are read: the csv crate's own trimming builds a new
        // record for every row (an allocation per row, a third of the parse time on long files).
        let mut csv = ::csv::ReaderBuilder::new()
            .has_headers(true)
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
            .map(|h| h.trim().to_string())
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

    /// Byte offset (after the skipped lines) of the last row read.
    pub fn byte(&self) -> u64 {
        self.record.position().map_or(0, |p| p.byte())
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
                // The line is named once, by `error`: the csv crate's text repeats it.
                let what = match e.kind() {
                    csv::ErrorKind::UnequalLengths {
                        expected_len, len, ..
                    } => format!(
                        "{len} field{} where the rows before have {expected_len}",
                        if *len == 1 { "" } else { "s" }
                    ),
                    csv::ErrorKind::Utf8 { .. } => "not UTF-8 text".to_string(),
                    _ => format!("malformed CSV: {e}"),
                };
                return Err(self.error(line, what));
            }
        }
        self.line = self
            .record
            .position()
            .map_or(self.line + 1, |p| p.line() as usize + self.skip_lines);
        for (k, (name, i)) in self.selected.iter().enumerate() {
            let field = self.record.get(*i).unwrap_or("").trim();
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

#[cfg(test)]
mod tests {
    use super::super::{WriteOptions, Writer};
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

    /// A row short of fields names its line once and the counts (the csv crate's text
    /// repeated the line: "line 106: … record 105 (line: 106, byte: 3972): …").
    #[test]
    fn a_short_row_names_its_line_once() {
        let e = read_all("t,gx,gy\n0,1,2\n0.01,3\n", &ReadOptions::default(), &["gx"]).unwrap_err();
        assert_eq!(e.line, Some(3));
        assert_eq!(e.message, "2 fields where the rows before have 3", "{e}");
        assert_eq!(e.to_string().matches('3').count(), 2, "{e}");
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
        // t, gap_before, then the same values on both rows but for the temperature.
        let row = |t: f64, gap: f64, temp: Option<f64>| {
            let mut r = [0.5, 0.0, 9.81, 0.01, -0.02, 0.0, 20.0, -3.0, 40.0]
                .map(Some)
                .to_vec();
            r.splice(0..0, [Some(t), Some(gap)]);
            r.push(temp);
            r
        };
        w.row(&row(0.001, 0.0, None)).unwrap();
        w.row(&row(0.005, 3.0, Some(25.5))).unwrap();
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
}
