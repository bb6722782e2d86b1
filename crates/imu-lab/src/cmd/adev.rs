//! `imu-lab adev`: an Allan-family deviation table of one column.
use allan::{deviation, Row, Stat, TauSet};
use anyhow::{anyhow, bail, Context, Result};
use serde::Serialize;

use crate::input::{self, InputArgs};

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
    stat: &'a str,
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

/// Compute the table (shared with other subcommands).
pub fn table(
    input: &InputArgs,
    column: &str,
    stat: Stat,
    taus: &TauSet,
) -> Result<(input::Recording, Vec<Row>)> {
    let rec = input::load(input, &[column])?;
    let series = rec
        .column(column)
        .ok_or_else(|| anyhow!("column {column:?} missing"))?;
    let rows = deviation(&series.values, 1.0 / rec.rate_hz, stat, taus)
        .with_context(|| format!("{}: column {column:?}", input.file.display()))?;
    Ok((rec, rows))
}

/// The bounded-memory table: rows streamed through the octave engine, integer-exact sums.
/// Returns (rate in Hz, samples, rows).
pub fn bounded_table(input: &InputArgs, column: &str, stat: Stat) -> Result<(f64, u64, Vec<Row>)> {
    let hadamard = match stat {
        Stat::Oadev => false,
        Stat::Ohdev => true,
        other => bail!(
            "--bounded computes oadev and ohdev only, not {}",
            other.name()
        ),
    };
    let mut rows = input::open(input, &[column])?;
    let shown = input.file.display().to_string();
    let mut engine = Box::new(allan::Engine::<8, 32, 12, 28>::new());
    let mut buf = [0.0f64; 2];
    let (mut t_first, mut t_last) = (None, 0.0);
    while rows.next_into(&mut buf)? {
        let v = buf[0];
        if v.fract() != 0.0 || v.abs() > i32::MAX as f64 {
            bail!("{shown}: line {}: field {column:?} is {v}, not an integer count: --bounded needs raw counts (convert with --scale)", rows.line);
        }
        engine.push(v as i32);
        if rows.has_t {
            t_first.get_or_insert(buf[1]);
            t_last = buf[1];
        }
    }
    let n = engine.samples();
    if n < 3 {
        bail!("{shown}: {n} samples, at least 3 needed");
    }
    let rate = input::rate_of(input, &shown, t_first.map(|t0| (t0, t_last)), n as usize)?;
    let scale = input::scale_of(input)?;
    let levels: Vec<_> = engine.levels().collect();
    Ok((
        rate,
        n,
        allan::batch::stream_rows(&levels, 1.0 / rate, scale, hadamard),
    ))
}

pub fn run(args: Args) -> Result<()> {
    let stat = Stat::parse(&args.stat).ok_or_else(|| {
        anyhow!(
            "--stat {:?}: expected one of adev, oadev, mdev, hdev, ohdev, tdev, totdev",
            args.stat
        )
    })?;
    let taus = TauSet::parse(&args.taus).map_err(|e| anyhow!("--taus {:?}: {e}", args.taus))?;
    let (rate_hz, n_samples, rows) = if args.bounded {
        if taus != TauSet::Octave {
            bail!(
                "--bounded computes octave τ only (got --taus {})",
                args.taus
            );
        }
        bounded_table(&args.input, &args.column, stat)?
    } else {
        let (rec, rows) = table(&args.input, &args.column, stat, &taus)?;
        (rec.rate_hz, rec.columns[0].values.len() as u64, rows)
    };
    let unit = stat_unit(stat, &input::unit_of(&args.input, &args.column)?);
    if args.json {
        let out = JsonOut {
            column: &args.column,
            unit: &unit,
            rate_hz,
            stat: stat.name(),
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
    println!(
        "{} of {} [{}] — {} samples at {:.6} Hz ({:.1} s); bounds are 68.3 % (Greenhall EDF, χ²)",
        stat.name().to_uppercase(),
        args.column,
        unit,
        n_samples,
        rate_hz,
        n_samples as f64 / rate_hz
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
