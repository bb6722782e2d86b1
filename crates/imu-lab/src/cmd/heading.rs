//! `imu-lab heading REC.csv --cal cal.toml [--truth STREAM.csv]`: what a calibration buys in
//! degrees of heading, on one recording. The recording's raw accelerometer and magnetometer
//! (`imu-lab record --raw`) give a tilt-compensated heading per row twice: as recorded (the
//! identity calibration) and through the calibration file's accelerometer and magnetometer
//! corrections. Each is judged
//! * against the truth, when there is one: `--truth` names the simulator's stream (the
//!   emulator's models play it from boot, repeating it; its `heading_true` column, magnetic,
//!   degrees, zero-order hold at the recording's time);
//! * by its consistency with the gyro otherwise (and as well): the heading's change over
//!   windows of `--window` s against the change the gyro integrates. It sees the errors that
//!   change as the board turns (hard and soft iron), not one that is the same at every attitude
//!   (declination, a turned mounting): only a truth shows those. A recording without turns
//!   shows nothing in it. The calibrated side's gyro has the file's bias taken out.
//!
//! The maths is `imu_cal::heading`.
use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use imu_cal::file::CalFile;
use imu_cal::heading::{
    angle_diff, before_after, no_window_reason, rms, tilt_compensated, Correction, Rms, Row,
    LITTLE_TURN_DEG,
};

use crate::input::{self, InputArgs};

#[derive(clap::Args, Debug)]
pub struct Args {
    #[command(flatten)]
    pub input: InputArgs,
    /// The calibration to judge (TOML, `imu-lab calibrate … --out`); its accelerometer and
    /// magnetometer sections are applied to the recording's raw values.
    #[arg(long)]
    pub cal: PathBuf,
    /// The simulator's stream the recording was made from (columns t, heading_true; repeated
    /// from the device's boot).
    #[arg(long)]
    pub truth: Option<PathBuf>,
    /// A recording made after the calibration was uploaded to the device (`imu-lab record`):
    /// its `heading` column, the device's own estimate, is judged against the truth beside the
    /// REC's (made with the calibration the device had then). Needs --truth.
    #[arg(long, requires = "truth")]
    pub device: Option<PathBuf>,
    /// Window of the gyro consistency check, s.
    #[arg(long, default_value_t = 2.0)]
    pub window: f64,
    /// Rows tilted beyond this pitch (degrees) are left out: the heading is ill-defined near
    /// the vertical.
    #[arg(long, default_value_t = 70.0)]
    pub max_pitch: f64,
}

const COLUMNS: [&str; 9] = ["ax", "ay", "az", "gx", "gy", "gz", "mx", "my", "mz"];

/// The truth: heading and pitch (degrees) at a time, from the stream, repeating.
struct Truth {
    t0: f64,
    rate: f64,
    heading: Vec<f64>,
    pitch: Vec<f64>,
}

impl Truth {
    fn read(path: &PathBuf) -> Result<Truth> {
        let shown = path.display();
        let (mut r, cols) = open_columns(path, &["t", "heading_true", "pitch_true"], "")?;
        let [it, ih, ip] = [cols[0], cols[1], cols[2]];
        let (mut t, mut heading, mut pitch) = (Vec::new(), Vec::new(), Vec::new());
        for (i, rec) in r.records().enumerate() {
            let rec = rec.with_context(|| format!("{shown}: row {}", i + 2))?;
            let num = |k: usize, name: &str| -> Result<f64> {
                let f = rec.get(k).unwrap_or("");
                f.trim()
                    .parse::<f64>()
                    .ok()
                    .filter(|v| v.is_finite())
                    .with_context(|| {
                        format!(
                            "{shown}: line {}: `{name}` is not a finite number: {f:?}",
                            i + 2
                        )
                    })
            };
            t.push(num(it, "t")?);
            heading.push(num(ih, "heading_true")?);
            pitch.push(num(ip, "pitch_true")?);
        }
        if t.len() < 2 {
            bail!("{shown}: needs at least 2 rows, has {}", t.len());
        }
        let step = (t[t.len() - 1] - t[0]) / (t.len() - 1) as f64;
        if step.is_nan() || step <= 0.0 {
            bail!("{shown}: the time column does not increase");
        }
        Ok(Truth {
            t0: t[0],
            rate: 1.0 / step,
            heading,
            pitch,
        })
    }

    fn index(&self, t: f64) -> usize {
        (((t - self.t0) * self.rate + 1e-9).floor().max(0.0) as usize) % self.heading.len()
    }

    /// The heading at `t` s (zero-order hold; the stream repeats).
    fn at(&self, t: f64) -> f64 {
        self.heading[self.index(t)]
    }

    fn pitch_at(&self, t: f64) -> f64 {
        self.pitch[self.index(t)]
    }
}

/// The device's heading column of a recording against the truth: rows with an estimate, the
/// filter not converging (`ahrs` ≠ 0), the truth's pitch within `max_pitch`.
fn device_errors(path: &PathBuf, truth: &Truth, max_pitch: f64) -> Result<Vec<f64>> {
    let shown = path.display();
    let (mut r, cols) = open_columns(
        path,
        &["t", "heading", "ahrs"],
        ": not a recording of `imu-lab record` with the device's estimates",
    )?;
    let [it, ih, is] = [cols[0], cols[1], cols[2]];
    let mut out = Vec::new();
    for (i, rec) in r.records().enumerate() {
        let rec = rec.with_context(|| format!("{shown}: row {}", i + 2))?;
        let field = |k: usize| rec.get(k).unwrap_or("").trim();
        if field(ih).is_empty() || field(is) == "0" {
            continue;
        }
        let num = |k: usize, name: &str| -> Result<f64> {
            field(k)
                .parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .with_context(|| {
                    format!(
                        "{shown}: line {}: `{name}` is not a finite number: {:?}",
                        i + 2,
                        field(k)
                    )
                })
        };
        let t = num(it, "t")?;
        if truth.pitch_at(t).abs() <= max_pitch {
            out.push(angle_diff(num(ih, "heading")?, truth.at(t)));
        }
    }
    Ok(out)
}

pub fn run(a: Args) -> Result<()> {
    if !(a.window > 0.0 && a.window.is_finite()) {
        bail!(
            "--window must be a positive number of seconds, got {}",
            a.window
        );
    }
    if !(0.0..=90.0).contains(&a.max_pitch) {
        bail!(
            "--max-pitch must be within 0 to 90 degrees, got {}",
            a.max_pitch
        );
    }
    let text = std::fs::read_to_string(&a.cal)
        .with_context(|| format!("cannot read {}", a.cal.display()))?;
    let cal = CalFile::from_toml(&text).map_err(|e| anyhow::anyhow!("{}: {e}", a.cal.display()))?;
    // The same checks as an upload: a correction the device would refuse is not evaluated.
    cal.to_device()
        .map_err(|e| anyhow::anyhow!("{}: refused: {e}", a.cal.display()))?;
    let corr = Correction::of(&cal);
    let truth = a.truth.as_ref().map(Truth::read).transpose()?;
    let mut rows_in = input::open_with(&a.input, &COLUMNS, &[])?;
    let Some(it) = rows_in.position("t") else {
        bail!(
            "{}: no `t` column: the heading lab needs the rows' times",
            a.input.file.display()
        );
    };
    let mut buf = vec![0.0; rows_in.names.len()];
    let (mut raw, mut fitted) = (Vec::new(), Vec::new());
    while rows_in.next_into(&mut buf)? {
        let v = |k: usize| buf[k];
        let row = Row {
            t: v(it),
            accel: [v(0), v(1), v(2)],
            gyro: [v(3), v(4), v(5)],
            mag: [v(6), v(7), v(8)],
        };
        raw.push(row);
        fitted.push(corr.apply(&row));
    }
    if raw.len() < 2 {
        bail!(
            "{}: needs at least 2 rows, has {}",
            a.input.file.display(),
            raw.len()
        );
    }
    let rate = raw.len() as f64 / (raw[raw.len() - 1].t - raw[0].t).max(1e-9);
    // Uncertainties from 1 s blocks.
    let block = rate.round().max(1.0) as usize;
    println!(
        "heading lab: {} rows of {} ({:.1} s), tilt-compensated heading per row from its accelerometer and magnetometer; rows beyond ±{}° of pitch left out",
        raw.len(),
        a.input.file.display(),
        raw[raw.len() - 1].t - raw[0].t,
        a.max_pitch
    );
    let show = |r: Option<Rms>| match r {
        Some(r) => format!(
            "{:.2} ± {:.2}° rms (max {:.1}°, {} values)",
            r.rms, r.sigma, r.max, r.n
        ),
        None => "no values".into(),
    };
    if let Some(truth) = &truth {
        let errors = |rows: &[Row]| -> Vec<f64> {
            rows.iter()
                .filter_map(|r| tilt_compensated(r.accel, r.mag))
                .zip(rows.iter().map(|r| r.t))
                .filter(|(h, _)| h.pitch.abs() <= a.max_pitch)
                .map(|(h, t)| angle_diff(h.heading, truth.at(t)))
                .collect()
        };
        let (e0, e1) = (rms(&errors(&raw), block), rms(&errors(&fitted), block));
        println!(
            "against the truth ({}):",
            a.truth
                .as_ref()
                .map_or(String::new(), |p| p.display().to_string())
        );
        println!("  identity calibration:   {}", show(e0));
        println!("  {}:   {}", a.cal.display(), show(e1));
        if let (Some(b), Some(f)) = (e0, e1) {
            println!(
                "heading error before → after calibration: {:.2} → {:.2}° rms (against the truth)",
                b.rms, f.rms
            );
        }
    }
    if let (Some(dev), Some(truth)) = (&a.device, &truth) {
        let (e0, e1) = (
            rms(&device_errors(&a.input.file, truth, a.max_pitch)?, block),
            rms(&device_errors(dev, truth, a.max_pitch)?, block),
        );
        println!("the device's own attitude filter (its `heading` column; converging rows left out) against the truth:");
        println!(
            "  {} (the calibration the device had):   {}",
            a.input.file.display(),
            show(e0)
        );
        println!("  {} (after the upload):   {}", dev.display(), show(e1));
        if let (Some(b), Some(f)) = (e0, e1) {
            println!("device heading error before → after calibration: {:.2} → {:.2}° rms (against the truth)", b.rms, f.rms);
        }
    }
    let w = a.window;
    let judged = before_after(&raw, &corr, w, a.max_pitch);
    let (c0, c1) = (judged.before, judged.after);
    println!("consistency with the gyro (heading change over {w} s windows minus the gyro's; blind to an error that is the same at every attitude):");
    println!("  identity calibration:   {}", show(c0));
    println!("  {}:   {}", a.cal.display(), show(c1));
    if c0.is_none() || c1.is_none() {
        let rows = if c0.is_none() { &raw } else { &fitted };
        println!("  (no values: {})", no_window_reason(rows, w, a.max_pitch));
    }
    if let Some(t) = judged.turned {
        println!(
            "  the board turned {:.2} ± {:.2}° rms a window (the gyro's heading change, its bias out){}",
            t.rms,
            t.sigma,
            if judged.little_turn() {
                format!(": under {LITTLE_TURN_DEG}°, the check says little (a few µT of hard iron \
                         move the heading by less than the gyro's noise); turn the board through \
                         all headings")
            } else {
                String::new()
            }
        );
    }
    if truth.is_none() {
        if let (Some(b), Some(f)) = (c0, c1) {
            println!("heading inconsistency before → after calibration: {:.2} → {:.2}° rms (no truth given)", b.rms, f.rms);
        }
    }
    Ok(())
}

/// A CSV file (lines starting with `#` skipped) and the positions of the columns `names`; a
/// missing one is named with the file's columns and `why` appended.
fn open_columns(
    path: &PathBuf,
    names: &[&str],
    why: &str,
) -> Result<(csv::Reader<std::fs::File>, Vec<usize>)> {
    let shown = path.display();
    let mut r = csv::ReaderBuilder::new()
        .comment(Some(b'#'))
        .from_path(path)
        .with_context(|| format!("cannot open {shown}"))?;
    let header = r
        .headers()
        .with_context(|| format!("{shown}: header"))?
        .clone();
    let cols = names
        .iter()
        .map(|name| {
            header
                .iter()
                .position(|h| h.trim() == *name)
                .with_context(|| {
                    format!(
                        "{shown}: no `{name}` column (has: {}){why}",
                        header.iter().collect::<Vec<_>>().join(", ")
                    )
                })
        })
        .collect::<Result<Vec<_>>>()?;
    Ok((r, cols))
}
