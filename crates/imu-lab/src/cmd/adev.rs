//! `imu-lab adev`: an Allan-family deviation table of one column.
use allan::{deviation_segments, Row, Stat, TauSet};
use anyhow::{anyhow, bail, Context, Result};
use imu_proto::csv::{self as contract, Timing, TimingScan, GAP_BEFORE, TIME};
use serde::Serialize;

use crate::input::{self, InputArgs};
use crate::render;

/// Arguments of `imu-lab adev`.
#[derive(clap::Args, Debug)]
pub struct Args {
    #[command(flatten)]
    pub input: InputArgs,
    /// Column to analyse (t, ax ay az, gx gy gz, mx my mz, temp).
    #[arg(long)]
    pub column: String,
    /// Averaging times: octave, decade, all, N/octave (e.g. 4/octave) or a list of m (1,2,5).
    #[arg(long, default_value = "octave")]
    pub taus: String,
    /// Statistic: adev, oadev, mdev, hdev, ohdev, tdev or totdev.
    #[arg(long, default_value = "oadev")]
    pub stat: String,
    /// Print one JSON object on stdout instead of the table.
    #[arg(long)]
    pub json: bool,
    /// Bounded memory: stream the file through the device's octave engine (P = 8) instead of
    /// holding the phase (8 bytes a sample). The column must hold integer counts (scale them
    /// with --scale); only oadev and ohdev, octave τ.
    #[arg(long)]
    pub bounded: bool,
}

#[derive(Serialize)]
struct JsonRow {
    tau_s: f64,
    m: u64,
    dev: f64,
    n: u64,
    edf: f64,
    lo: f64,
    hi: f64,
    alpha: i32,
    estimator: String,
}

#[derive(Serialize)]
struct JsonOut<'a> {
    column: &'a str,
    unit: &'a str,
    rate_hz: f64,
    samples: u64,
    stat: &'a str,
    /// What the time column says (absent without `t` or with --ignore-time).
    timing: Option<JsonTiming>,
    adev: Vec<JsonRow>,
}

/// The unit of the statistic for a column unit: TDEV is a time error, rate unit × s.
pub fn stat_unit(stat: Stat, unit: &str) -> String {
    if stat.is_time() {
        format!("{unit}·s")
    } else {
        unit.to_string()
    }
}

/// Compute the table (shared with other subcommands): every segment between gaps, no difference
/// spanning a gap. An empty table (no τ of the set fits the record) is an error.
pub fn table(
    input: &InputArgs,
    column: &str,
    stat: Stat,
    taus: &TauSet,
) -> Result<(input::Recording, Vec<Row>)> {
    let rec = input::load(input, &[column])?;
    let segments = rec
        .segments_of(column)
        .ok_or_else(|| anyhow!("column {column:?} missing"))?;
    let rows = deviation_segments(&segments, 1.0 / rec.rate_hz, stat, taus)
        .with_context(|| format!("{}: column {column:?}", input.file.display()))?;
    if rows.is_empty() {
        let longest = segments.iter().map(|s| s.len()).max().unwrap_or(0);
        bail!(
            "{}: no averaging time of --taus fits the record: its longest segment has {longest} \
             samples ({} s) and {} needs at least two terms at each τ",
            input.file.display(),
            render::sig(longest as f64 / rec.rate_hz, 4),
            stat.name()
        );
    }
    Ok((rec, rows))
}

/// A deviation table with what it was computed from.
pub struct Table {
    /// Sample rate, Hz.
    pub rate_hz: f64,
    /// Samples used.
    pub samples: u64,
    /// What the time column said.
    pub timing: Option<Timing>,
    /// The rows.
    pub rows: Vec<Row>,
    /// Unit of the column.
    pub unit: String,
}

/// Rows held back to read the sample clock before streaming (65,536 stamps: 65 s at 1 kHz).
const CLOCK_ROWS: usize = 1 << 16;

/// The bounded-memory table: rows streamed through the octave engine, integer-exact sums, a gap
/// (from `t` or `gap_before`) closing the engine's segment as on the device. The sample clock is
/// read from the first [`CLOCK_ROWS`] stamps.
pub fn bounded_table(input: &InputArgs, column: &str, stat: Stat) -> Result<Table> {
    let hadamard = match stat {
        Stat::Oadev => false,
        Stat::Ohdev => true,
        other => bail!(
            "--bounded computes oadev and ohdev only, not {}",
            other.name()
        ),
    };
    let scale = input::scale_of(input)?;
    let mut rows = input::open_with(input, &[column], &[])?;
    let shown = rows.shown().to_string();
    // The column must hold whole counts (checked row by row below).
    let unit = input::unit_of(
        input,
        rows.header_column(column).expect("selected"),
        Some(true),
    )
    .with_context(|| shown.clone())?;
    let ti = rows.position(TIME).filter(|_| !input.ignore_time);
    let gi = rows.position(GAP_BEFORE).filter(|_| !input.ignore_time);
    let mut engine = Box::new(allan::Engine::<8, 32, 12, 28>::new());
    let mut buf = vec![0.0f64; rows.names.len()];
    let mut held: Vec<(f64, f64, f64, usize)> = Vec::new();
    let mut scan: Option<TimingScan> = None;
    let push = |engine: &mut allan::Engine<8, 32, 12, 28>,
                scan: &mut Option<TimingScan>,
                (v, t, g, line): (f64, f64, f64, usize)|
     -> Result<()> {
        if let Some(sc) = scan {
            if sc
                .push(t, g)
                .map_err(|e| anyhow!("{shown}: line {line}: column \"t\": {e}"))?
                .is_some()
            {
                engine.gap();
            }
        }
        if v.fract() != 0.0 || v.abs() > i32::MAX as f64 {
            bail!("{shown}: line {line}: field {column:?} is {v}, not an integer count: --bounded needs raw counts (convert with --scale)");
        }
        engine.push(v as i32);
        Ok(())
    };
    let mut clock_read = ti.is_none();
    while rows.next_into(&mut buf)? {
        let row = (
            buf[0],
            ti.map_or(0.0, |i| buf[i]),
            gi.map_or(0.0, |i| buf[i]),
            rows.line(),
        );
        if clock_read {
            push(&mut engine, &mut scan, row)?;
            continue;
        }
        held.push(row);
        if held.len() == CLOCK_ROWS {
            scan = Some(start_scan(&shown, &held, gi.is_some())?);
            clock_read = true;
            for r in held.drain(..) {
                push(&mut engine, &mut scan, r)?;
            }
        }
    }
    if !held.is_empty() {
        if held.len() >= 2 {
            scan = Some(start_scan(&shown, &held, gi.is_some())?);
        }
        for r in held.drain(..) {
            push(&mut engine, &mut scan, r)?;
        }
    }
    let n = engine.samples();
    if n < 3 {
        bail!("{shown}: {n} samples, at least 3 needed");
    }
    let timing = scan
        .map(|s| s.finish())
        .transpose()
        .map_err(|e| anyhow!("{shown}: column \"t\": {e}"))?;
    let (rate, _) = input::rate_and_segments(input, &shown, timing.as_ref(), n as usize)?;
    if let Some(tm) = &timing {
        if tm.irregular() || !tm.gaps.is_empty() {
            eprintln!("note: {shown}: {}", tm.describe());
        }
    }
    let levels: Vec<_> = engine.levels().collect();
    Ok(Table {
        rate_hz: rate,
        samples: n,
        timing,
        rows: allan::batch::stream_rows(&levels, 1.0 / rate, scale, hadamard),
        unit,
    })
}

/// The sample clock from the rows held back.
fn start_scan(shown: &str, held: &[(f64, f64, f64, usize)], has_gap: bool) -> Result<TimingScan> {
    let t: Vec<f64> = held.iter().map(|r| r.1).collect();
    let g: Vec<f64> = held.iter().map(|r| r.2).collect();
    let clock = contract::read_clock(&t, has_gap.then_some(g.as_slice()))
        .map_err(|e| anyhow!("{shown}: column \"t\": {e}"))?;
    Ok(TimingScan::new(clock))
}

#[derive(Serialize)]
struct JsonGap {
    row: usize,
    missing_samples: u64,
    missing_s: f64,
    reported: bool,
}

/// The time column's report in JSON.
#[derive(Serialize)]
pub struct JsonTiming {
    regularity: &'static str,
    period_s: f64,
    median_dt_s: f64,
    p95_dt_s: f64,
    mean_dt_s: f64,
    duplicates: usize,
    jittered: usize,
    jitter_rms_s: f64,
    gaps: usize,
    missing_samples: u64,
    missing_s: f64,
    largest_gap_s: f64,
    gap_list: Vec<JsonGap>,
}

impl JsonTiming {
    /// From the report.
    pub fn of(t: &Timing) -> Self {
        JsonTiming {
            regularity: t.regularity.name(),
            period_s: t.period_s,
            median_dt_s: t.median_dt_s,
            p95_dt_s: t.p95_dt_s,
            mean_dt_s: t.mean_dt_s,
            duplicates: t.duplicates,
            jittered: t.jittered,
            jitter_rms_s: t.jitter_rms_s,
            gaps: t.gaps.len(),
            missing_samples: t.missing_samples(),
            missing_s: t.missing_s,
            largest_gap_s: t.largest_gap_s,
            gap_list: t
                .gaps
                .iter()
                .map(|g| JsonGap {
                    row: g.row,
                    missing_samples: g.missing_samples,
                    missing_s: g.missing_s,
                    reported: g.reported,
                })
                .collect(),
        }
    }
}

pub fn run(args: Args) -> Result<()> {
    let stat = Stat::parse(&args.stat).ok_or_else(|| {
        anyhow!(
            "--stat {:?}: expected one of adev, oadev, mdev, hdev, ohdev, tdev, totdev",
            args.stat
        )
    })?;
    let taus = TauSet::parse(&args.taus).map_err(|e| anyhow!("--taus {:?}: {e}", args.taus))?;
    let t = if args.bounded {
        if taus != TauSet::Octave {
            bail!(
                "--bounded computes octave τ only (got --taus {})",
                args.taus
            );
        }
        bounded_table(&args.input, &args.column, stat)?
    } else {
        let (rec, rows) = table(&args.input, &args.column, stat, &taus)?;
        Table {
            rate_hz: rec.rate_hz,
            samples: rec.samples() as u64,
            unit: rec.columns[0].unit.clone(),
            timing: rec.timing,
            rows,
        }
    };
    let Table {
        rate_hz,
        samples: n_samples,
        timing,
        rows,
        unit,
    } = t;
    let unit = stat_unit(stat, &unit);
    if args.json {
        let out = JsonOut {
            column: &args.column,
            unit: &unit,
            rate_hz,
            samples: n_samples,
            stat: stat.name(),
            timing: timing.as_ref().map(JsonTiming::of),
            adev: rows
                .iter()
                .map(|r| JsonRow {
                    tau_s: r.tau,
                    m: r.m,
                    dev: r.dev,
                    n: r.n,
                    edf: r.edf,
                    lo: r.lo,
                    hi: r.hi,
                    alpha: r.alpha,
                    estimator: r.estimator.label(),
                })
                .collect(),
        };
        println!("{}", serde_json::to_string(&out)?);
        return Ok(());
    }
    let gaps = timing.as_ref().map_or(0, |t| t.gaps.len());
    println!(
        "{} of {} [{}] — {} samples at {:.6} Hz ({:.1} s of data{}); bounds are 68.3 % (Greenhall EDF, χ²)",
        stat.name().to_uppercase(),
        args.column,
        unit,
        n_samples,
        rate_hz,
        n_samples as f64 / rate_hz,
        if gaps > 0 {
            format!(" in {} segments: no difference spans a gap", gaps + 1)
        } else {
            String::new()
        }
    );
    let u = format!("[{unit}]");
    println!(
        "{:>12} {:>9} {:>13} {:>13} {:>13} {:>9} {:>5} {:>10}  estimator",
        "tau [s]",
        "m",
        format!("dev {u}"),
        format!("lo {u}"),
        format!("hi {u}"),
        "n",
        "alpha",
        "edf"
    );
    for r in &rows {
        println!(
            "{:>12.6} {:>9} {:>13.6e} {:>13.6e} {:>13.6e} {:>9} {:>5} {:>10.2}  {}",
            r.tau,
            r.m,
            r.dev,
            r.lo,
            r.hi,
            r.n,
            r.alpha,
            r.edf,
            r.estimator.label()
        );
    }
    Ok(())
}
