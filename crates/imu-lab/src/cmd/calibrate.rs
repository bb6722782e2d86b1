//! `imu-lab calibrate accel|gyro|mag FILE --model a,b,…`: fit a calibration model, compare its
//! residual with the noise floor measured from the same data, name the missing effect, and
//! report the step before → after. All the maths is in `imu_cal`; this reads the recording,
//! checks the options against the physics, removes the sensors' overflow sentinels, and hands
//! the rendering to `render::calibration`.
use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use imu_cal::accel::{detect_static_masked, AccelProblem, StaticDetect, G_STANDARD};
use imu_cal::file::CalFile;
use imu_cal::gyro::GyroProblem;
use imu_cal::gyro_rot::GyroRotProblem;
use imu_cal::lab::{CalLab, Effect, Model, Params, Problem, Report, Step};
use imu_cal::mag::MagProblem;
use imu_cal::sentinel::{self, Part, Sentinels};
use model_lab::{walk, Stop};
use nalgebra::Vector3;
use serde::Serialize;

use crate::input::{self, InputArgs, COUNTS};
use crate::render::{self, calibration};

/// Which sensor to calibrate.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum SensorArg {
    /// Accelerometer from static poses (columns ax ay az, m/s²).
    Accel,
    /// Gyroscope at rest (columns gx gy gz, deg/s; temp °C used when present).
    Gyro,
    /// Magnetometer rotated through many orientations (columns mx my mz, µT).
    Mag,
}

/// Arguments of `imu-lab calibrate`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Sensor: accel, gyro or mag.
    #[arg(value_enum)]
    pub sensor: SensorArg,
    #[command(flatten)]
    pub input: InputArgs,
    /// Effects in the model, comma-separated: accel {offset, scale, misalignment}; gyro {bias,
    /// temperature} at rest, {scale, misalignment} from rotations; mag {hard_iron, soft_iron,
    /// soft_iron_2d, tilt}. Default: offset,scale | bias | hard_iron.
    #[arg(long, value_delimiter = ',')]
    pub model: Vec<String>,
    /// Gravity for the accelerometer fit, in the columns' unit (default 9.80665 m/s²; give it
    /// for raw counts, e.g. 16384 LSB for a ±2 g MPU-6050).
    #[arg(long)]
    pub g: Option<f64>,
    /// Field magnitude for the magnetometer fit, in the columns' unit; fitted when absent.
    #[arg(long)]
    pub field: Option<f64>,
    /// Static detection window (s) for the accelerometer (Tedaldi et al. 2014).
    #[arg(long, default_value_t = 1.0)]
    pub window: f64,
    /// Static threshold: multiple of the at-rest window variance.
    #[arg(long, default_value_t = 6.0)]
    pub threshold_k: f64,
    /// Shortest static pose kept (s).
    #[arg(long, default_value_t = 1.5)]
    pub min_static: f64,
    /// Gyro saturation (deg/s, after --scale): moves reaching it are skipped by the gyro
    /// scale/misalignment fit (e.g. 250 for ±250 °/s).
    #[arg(long)]
    pub saturation: Option<f64>,
    /// Number of blocks the gyro recording is cut into.
    #[arg(long, default_value_t = 50)]
    pub blocks: usize,
    /// Walk automatically: diagnose → add the named effect → refit, until the model is adequate
    /// or no effect of the sensor helps (the same workflow as `fit --auto`).
    #[arg(long)]
    pub auto: bool,
    /// Most steps of `--auto`.
    #[arg(long, default_value_t = 4, requires = "auto")]
    pub max_steps: usize,
    /// Print one JSON object on stdout instead of the text report.
    #[arg(long)]
    pub json: bool,
    /// Write the figure (SVG or PNG, by the name's extension): scatter before/after with the
    /// fitted ellipse and the circle, residuals against orientation or temperature.
    #[arg(long)]
    pub plot: Option<PathBuf>,
    /// Write a self-contained HTML report (text, parameters and the figure).
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// Write (or update this sensor's section of) a TOML calibration file.
    #[arg(long)]
    pub out: Option<PathBuf>,
}

/// The prepared data of one run (kept for the report and the figures), with what was excluded
/// before fitting.
pub enum Data {
    /// Static poses.
    Accel(AccelProblem),
    /// Block means at rest.
    Gyro(GyroProblem),
    /// Moves between static poses.
    GyroRot(GyroRotProblem),
    /// Samples of the field.
    Mag(MagProblem),
}

impl Data {
    /// The problem behind it.
    pub fn problem(&self) -> &dyn Problem {
        match self {
            Data::Accel(p) => p,
            Data::Gyro(p) => p,
            Data::GyroRot(p) => p,
            Data::Mag(p) => p,
        }
    }
}

/// A loaded run: the data, the sentinels excluded, and notes about the input for the report.
pub struct Loaded {
    /// The problem's data.
    pub data: Data,
    /// Sentinels found (and excluded) in the sensor's columns.
    pub sentinels: Sentinels,
    /// Other notes on the input (gaps, missing temperature, …).
    pub notes: Vec<String>,
}

fn default_model(s: SensorArg) -> Vec<Effect> {
    match s {
        SensorArg::Accel => vec![Effect::Offset, Effect::Scale],
        SensorArg::Gyro => vec![Effect::Bias],
        SensorArg::Mag => vec![Effect::HardIron],
    }
}

/// Three columns of one sensor, their common unit, and the recording.
fn columns(
    in_: &InputArgs,
    names: [&str; 3],
    optional: &[&str],
) -> Result<(input::Recording, [Vec<f64>; 3], String)> {
    let rec = input::load_with(in_, &names, optional)?;
    let col = |n: &str| rec.column(n).with_context(|| format!("column {n} missing"));
    let units: Vec<&str> = names
        .iter()
        .map(|n| col(n).map(|c| c.unit.as_str()))
        .collect::<Result<_>>()?;
    if units.iter().any(|u| *u != units[0]) {
        bail!(
            "{}: columns {} are in different units ({}): one sensor's axes must share one",
            in_.file.display(),
            names.join(", "),
            units.join(", ")
        );
    }
    let unit = units[0].to_string();
    let cols = [
        col(names[0])?.values.clone(),
        col(names[1])?.values.clone(),
        col(names[2])?.values.clone(),
    ];
    Ok((rec, cols, unit))
}

/// Gravity in the accelerometer's unit: Earth's surface gravity is 9.76–9.84 m/s²; in raw
/// counts it must be given (the sensitivity is the user's to state).
fn gravity(g: Option<f64>, unit: &str) -> Result<f64> {
    let (lo, hi, default) = match unit {
        "m/s²" | "m/s^2" => (9.7, 9.9, Some(G_STANDARD)),
        "g" => (0.99, 1.01, Some(1.0)),
        COUNTS => (1.0, 1e6, None),
        _ => (f64::MIN_POSITIVE, 1e12, None),
    };
    let g = match (g, default) {
        (Some(g), _) => g,
        (None, Some(d)) => d,
        (None, None) if unit == COUNTS => bail!(
            "the accelerometer columns are raw counts (LSB): give gravity in counts with --g \
             (e.g. --g 16384 for a ±2 g MPU-6050), or convert them to m/s² with --scale"
        ),
        (None, None) => {
            bail!("the accelerometer columns are in {unit}: give gravity in {unit} with --g")
        }
    };
    if !(g.is_finite() && (lo..=hi).contains(&g)) {
        bail!(
            "--g {g} {unit}: gravity must be between {lo} and {hi} {unit}{}",
            if unit == "m/s²" {
                " (Earth's surface gravity is 9.76–9.84 m/s²)"
            } else {
                ""
            }
        );
    }
    Ok(g)
}

/// The field magnitude, if given, checked against the physics (Earth's field is 22–67 µT;
/// indoors near steel a few hundred).
fn field(f: Option<f64>, unit: &str) -> Result<Option<f64>> {
    let Some(f) = f else { return Ok(None) };
    let (lo, hi) = match unit {
        "µT" | "uT" => (1.0, 1000.0),
        "G" | "gauss" => (0.01, 10.0),
        "nT" => (1e3, 1e6),
        COUNTS => (1.0, 1e6),
        _ => (f64::MIN_POSITIVE, 1e12),
    };
    if !(f.is_finite() && (lo..=hi).contains(&f)) {
        bail!(
            "--field {f} {unit}: the field magnitude must be between {lo} and {hi} {unit} \
             (Earth's field is 22–67 µT)"
        );
    }
    Ok(Some(f))
}

fn static_detect(a: &Args) -> Result<StaticDetect> {
    for (v, name, lo, hi) in [
        (a.window, "--window", 1e-3, 3600.0),
        (a.threshold_k, "--threshold-k", 1.0, 1e6),
        (a.min_static, "--min-static", 0.0, 86400.0),
    ] {
        if !(v.is_finite() && (lo..=hi).contains(&v)) {
            bail!("{name} {v}: must be between {lo} and {hi}");
        }
    }
    Ok(StaticDetect {
        window_s: a.window,
        k: a.threshold_k,
        min_static_s: a.min_static,
    })
}

/// Samples to exclude: the sentinels, plus the first sample after each gap (a pose or a move
/// must not span a gap).
fn flags(s: &Sentinels, rec: &input::Recording) -> Vec<bool> {
    let mut f = s.flagged.clone();
    for seg in rec.segments.iter().skip(1) {
        if let Some(x) = f.get_mut(seg.start) {
            *x = true;
        }
    }
    f
}

fn gap_note(rec: &input::Recording) -> Option<String> {
    (rec.segments.len() > 1).then(|| {
        format!(
            "the record has {} gaps: no pose or move spans one",
            rec.segments.len() - 1
        )
    })
}

/// Keep the samples not flagged.
fn keep(v: &[f64], flagged: &[bool]) -> Vec<f64> {
    v.iter()
        .zip(flagged)
        .filter(|(_, f)| !**f)
        .map(|(x, _)| *x)
        .collect()
}

fn load_data(a: &Args, model: &[Effect]) -> Result<Loaded> {
    let rotation = model.contains(&Effect::Scale) || model.contains(&Effect::Misalignment);
    if let Some(s) = a.saturation {
        if !(s.is_finite() && s > 0.0) {
            bail!("--saturation {s}: must be a positive rate");
        }
    }
    let mut notes = Vec::new();
    Ok(match a.sensor {
        SensorArg::Gyro if rotation => {
            // Gyro scale/misalignment: rotations between static poses, gravity as reference.
            // Only the direction of the accelerometer is used, so its unit does not matter.
            let (rec, c, au) = columns(&a.input, ["ax", "ay", "az"], &[])?;
            let (_, w, gu) = columns(&a.input, ["gx", "gy", "gz"], &[])?;
            if gu != "deg/s" {
                bail!(
                    "the gyro columns are in {gu}: the rotation fit integrates rates, so convert \
                     them to deg/s with --scale (e.g. 0.0076336 for ±250 °/s counts)"
                );
            }
            let sa = sentinel::find([&c[0], &c[1], &c[2]], &au, Part::for_sensor("accel"));
            let sg = sentinel::find([&w[0], &w[1], &w[2]], &gu, Part::for_sensor("gyro"));
            let mut fl = flags(&sa, &rec);
            for (f, g) in fl.iter_mut().zip(&sg.flagged) {
                *f |= *g;
            }
            notes.extend(gap_note(&rec));
            let poses =
                detect_static_masked([&c[0], &c[1], &c[2]], rec.rate_hz, static_detect(a)?, &fl)?;
            let both: Vec<bool> = sa
                .flagged
                .iter()
                .zip(&sg.flagged)
                .map(|(a, g)| *a || *g)
                .collect();
            let sentinels = Sentinels {
                samples: both.iter().filter(|f| **f).count(),
                found: sa.found.into_iter().chain(sg.found).collect(),
                flagged: both,
            };
            Loaded {
                data: Data::GyroRot(GyroRotProblem::new_flagged(
                    [&c[0], &c[1], &c[2]],
                    [&w[0], &w[1], &w[2]],
                    rec.rate_hz,
                    &poses,
                    a.saturation,
                    &fl,
                )?),
                sentinels,
                notes,
            }
        }
        SensorArg::Accel => {
            let (rec, c, unit) = columns(&a.input, ["ax", "ay", "az"], &[])?;
            let g = gravity(a.g, &unit)?;
            let s = sentinel::find([&c[0], &c[1], &c[2]], &unit, Part::for_sensor("accel"));
            notes.extend(gap_note(&rec));
            let poses = detect_static_masked(
                [&c[0], &c[1], &c[2]],
                rec.rate_hz,
                static_detect(a)?,
                &flags(&s, &rec),
            )?;
            Loaded {
                data: Data::Accel(AccelProblem::with_unit(poses, g, &unit)),
                sentinels: s,
                notes,
            }
        }
        SensorArg::Gyro => {
            let (rec, c, unit) = columns(&a.input, ["gx", "gy", "gz"], &["temp"])?;
            let s = sentinel::find([&c[0], &c[1], &c[2]], &unit, Part::for_sensor("gyro"));
            let t = rec.column("temp").map(|c| keep(&c.values, &s.flagged));
            if let Some(t) = &t {
                let missing = t.iter().filter(|v| v.is_nan()).count();
                if missing > 0 {
                    notes.push(format!("{missing} temperature readings are missing"));
                }
            }
            let g = [0, 1, 2].map(|k| keep(&c[k], &s.flagged));
            Loaded {
                data: Data::Gyro(GyroProblem::with_unit(
                    [&g[0], &g[1], &g[2]],
                    t.as_deref(),
                    a.blocks,
                    &unit,
                )?),
                sentinels: s,
                notes,
            }
        }
        SensorArg::Mag => {
            let (_, c, unit) = columns(&a.input, ["mx", "my", "mz"], &[])?;
            let f = field(a.field, &unit)?;
            let s = sentinel::find([&c[0], &c[1], &c[2]], &unit, Part::for_sensor("mag"));
            let m = (0..c[0].len())
                .filter(|&i| !s.flagged[i])
                .map(|i| Vector3::new(c[0][i], c[1][i], c[2][i]))
                .collect();
            Loaded {
                data: Data::Mag(MagProblem::with_unit(m, f, &unit)?),
                sentinels: s,
                notes,
            }
        }
    })
}

/// What a run produced: the report on the last model, and for `--auto` the walk that led to it.
pub struct Outcome {
    /// The model the run started from (`--model`).
    pub start: Model,
    /// The steps of the walk (`--auto`), in order.
    pub steps: Vec<Step>,
    /// Why the walk ended (`None` without `--auto`).
    pub stop: Option<Stop>,
    /// The last model's report: verdict, candidates, diagnosis, the next step.
    pub report: Report,
}

#[derive(Serialize)]
struct JsonCandidate<'a> {
    added: Vec<&'static str>,
    admissible: bool,
    p_value: Option<f64>,
    residual_rms: f64,
    ratio: f64,
    reason: &'a str,
    reading: &'a str,
}

#[derive(Serialize)]
struct JsonDiagnosis<'a> {
    verdict: imu_cal::lab::Verdict,
    adequate: bool,
    underdetermined: bool,
    missing: Option<&'static str>,
    explanation: &'a str,
    p_value: Option<f64>,
    candidates: Vec<JsonCandidate<'a>>,
}

#[derive(Serialize)]
struct JsonNext<'a> {
    added: Vec<&'static str>,
    model: Vec<&'static str>,
    residual_rms_before: f64,
    residual_rms_after: f64,
    params: &'a Params,
    sigma: &'a Params,
    outliers: usize,
}

/// One step of the walk: the same keys as `fit --auto`'s, the statistic being s²/σ² (the
/// residual variance over the noise floor's, χ²/ν-distributed for an adequate model) and the
/// residual RMS in the data's unit.
#[derive(Serialize)]
struct JsonWalkStep<'a> {
    added: Vec<&'static str>,
    removed: Vec<&'static str>,
    reading: &'a str,
    p_value: Option<f64>,
    chi2_dof_before: f64,
    chi2_dof_after: f64,
    rms_residual_before: f64,
    rms_residual_after: f64,
    rms_unit: &'a str,
    adequate_before: bool,
    adequate_after: bool,
}

#[derive(Serialize)]
struct JsonExcluded<'a> {
    /// Samples excluded as sensor sentinels before fitting.
    sentinels: usize,
    sentinel_kinds: &'a [String],
    /// Items (poses, samples, block means, moves) excluded as outliers by the robust fit.
    outliers: usize,
}

#[derive(Serialize)]
struct JsonOut<'a> {
    sensor: &'static str,
    unit: &'a str,
    model: Vec<&'static str>,
    params: &'a Params,
    /// 1σ standard errors of `params`, same layout.
    sigma: &'a Params,
    /// Residual RMS of the model over the residuals used (unit).
    residual_rms: f64,
    /// The residual RMS a complete model would leave, from the data's own noise (unit).
    noise_floor: f64,
    /// How many residuals (poses, samples or blocks × 3, moves × 2) the fit used.
    n_residuals: usize,
    excluded: JsonExcluded<'a>,
    notes: &'a [String],
    diagnosis: JsonDiagnosis<'a>,
    /// The step the diagnosis proposes from this model (what `--auto` would add next).
    step: Option<JsonNext<'a>>,
    /// The walk of `--auto`, every step (absent without `--auto`).
    #[serde(skip_serializing_if = "Option::is_none")]
    steps: Option<Vec<JsonWalkStep<'a>>>,
    /// Why the walk ended (absent without `--auto`).
    #[serde(skip_serializing_if = "Option::is_none")]
    stop: Option<String>,
}

fn names(m: &[Effect]) -> Vec<&'static str> {
    m.iter().map(|e| e.name()).collect()
}

/// The one JSON object of `--json`.
fn json_out(l: &Loaded, run: &Outcome) -> Result<String> {
    let p = l.data.problem();
    let finite = |v: f64| v.is_finite().then_some(v);
    let report = &run.report;
    let m = &report.model;
    let d = &report.diagnosis;
    let out = JsonOut {
        sensor: p.sensor(),
        unit: p.unit(),
        model: names(m.effects()),
        params: &m.fitted.params,
        sigma: &m.fitted.sigma,
        residual_rms: m.fitted.rms(),
        noise_floor: m.expected_rms,
        n_residuals: m.fitted.n_used(),
        excluded: JsonExcluded {
            sentinels: l.sentinels.samples,
            sentinel_kinds: &l.sentinels.found,
            outliers: m.outliers,
        },
        notes: &l.notes,
        diagnosis: JsonDiagnosis {
            verdict: m.verdict,
            adequate: m.adequate(),
            underdetermined: m.underdetermined,
            missing: d.missing.map(|e| e.name()),
            explanation: &d.explanation,
            p_value: finite(m.p_value),
            candidates: d
                .candidates
                .iter()
                .map(|c| JsonCandidate {
                    added: names(&c.edit.add),
                    admissible: c.admissible,
                    p_value: finite(c.p_value),
                    residual_rms: c.summary.rms_residual,
                    ratio: c.summary.chi2_dof,
                    reason: &c.reason,
                    reading: &c.reading,
                })
                .collect(),
        },
        step: report
            .step
            .as_ref()
            .zip(report.next())
            .map(|(s, next)| JsonNext {
                added: names(&s.edit.add),
                model: names(next.effects()),
                residual_rms_before: s.before.rms_residual,
                residual_rms_after: s.after.rms_residual,
                params: &next.fitted.params,
                sigma: &next.fitted.sigma,
                outliers: next.outliers,
            }),
        steps: run.stop.map(|_| {
            run.steps
                .iter()
                .map(|s| JsonWalkStep {
                    added: names(&s.edit.add),
                    removed: names(&s.edit.remove),
                    reading: &s.reading,
                    p_value: finite(s.p_value),
                    chi2_dof_before: s.before.chi2_dof,
                    chi2_dof_after: s.after.chi2_dof,
                    rms_residual_before: s.before.rms_residual,
                    rms_residual_after: s.after.rms_residual,
                    rms_unit: p.unit(),
                    adequate_before: s.before.adequate,
                    adequate_after: s.after.adequate,
                })
                .collect()
        }),
        stop: run.stop.map(|s| s.to_string()),
    };
    Ok(serde_json::to_string(&out)?)
}

/// Fit `model`, and with `auto` walk from it; the report is on the last model.
fn outcome(p: &dyn Problem, model: &[Effect], auto: bool, max_steps: usize) -> Result<Outcome> {
    let lab = CalLab::new(p);
    let start = lab.fit(model)?;
    if !auto {
        return Ok(Outcome {
            start: start.clone(),
            steps: Vec::new(),
            stop: None,
            report: lab.report(start)?,
        });
    }
    let w = walk(&lab, start.clone(), max_steps)?;
    let last = w.last().clone();
    Ok(Outcome {
        start,
        steps: w.steps,
        stop: Some(w.stop),
        report: lab.report(last)?,
    })
}

/// Run `imu-lab calibrate`.
pub fn run(a: Args) -> Result<()> {
    let model: Vec<Effect> = if a.model.is_empty() {
        default_model(a.sensor)
    } else {
        a.model
            .iter()
            .filter(|s| !s.trim().is_empty())
            .map(|s| Effect::parse(s))
            .collect::<Result<_, _>>()?
    };
    let loaded = load_data(&a, &model)?;
    let mut model = model;
    if let Data::GyroRot(_) = loaded.data {
        // The rotation fit always removes the bias at rest first; temperature is a block fit.
        if model.contains(&Effect::Temperature) {
            bail!(
                "fit temperature with --model bias,temperature and scale/misalignment separately"
            );
        }
        model.retain(|e| *e != Effect::Bias);
    }
    if !(1..=20).contains(&a.max_steps) {
        bail!("--max-steps {}: give 1 to 20", a.max_steps);
    }
    let p = loaded.data.problem();
    let run = outcome(p, &model, a.auto, a.max_steps)?;

    if a.json {
        println!("{}", json_out(&loaded, &run)?);
    } else {
        print!("{}", calibration::text_report(&loaded, &run));
    }

    let svg = if a.plot.is_some() || a.report.is_some() {
        // Before → after: the walk's start and end, or the model and its next step.
        let (before, after) = if run.stop.is_some() {
            (
                &run.start,
                Some(&run.report.model).filter(|_| !run.steps.is_empty()),
            )
        } else {
            (&run.report.model, run.report.next())
        };
        Some(calibration::plot(&loaded.data, before, after))
    } else {
        None
    };
    if let (Some(path), Some(svg)) = (&a.plot, &svg) {
        render::write_figure(path, svg)?;
    }
    if let Some(path) = &a.report {
        let html = calibration::html_report(&loaded, &run, svg.as_deref().unwrap_or(""));
        std::fs::write(path, html).with_context(|| format!("cannot write {}", path.display()))?;
    }
    if let Some(path) = &a.out {
        let contract = match a.sensor {
            SensorArg::Accel => "m/s²",
            SensorArg::Gyro => "deg/s",
            SensorArg::Mag => "µT",
        };
        let unit = match &loaded.data {
            // The rotation fit's parameters are dimensionless; its bias is in deg/s.
            Data::GyroRot(_) => "deg/s",
            _ => p.unit(),
        };
        if unit != contract {
            bail!(
                "--out {}: the calibration file holds {contract}, but this fit is in {unit}; \
                 convert the columns with --scale",
                path.display()
            );
        }
        let mut file = if path.exists() {
            let text = std::fs::read_to_string(path)
                .with_context(|| format!("cannot read {}", path.display()))?;
            CalFile::from_toml(&text).with_context(|| format!("{}", path.display()))?
        } else {
            CalFile::default()
        };
        let section = match loaded.data {
            Data::GyroRot(_) => "gyro-rot",
            _ => p.sensor(),
        };
        file.set(section, &run.report.model.fitted.params)?;
        // The device must be able to hold it.
        file.to_device()
            .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
        std::fs::write(path, file.to_toml())
            .with_context(|| format!("cannot write {}", path.display()))?;
        if !a.json {
            println!("wrote the {} section of {}", p.sensor(), path.display());
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Matrix3;
    use std::io::Write;

    fn args(file: &std::path::Path, sensor: SensorArg, model: &[&str]) -> Args {
        Args {
            sensor,
            input: InputArgs {
                file: file.to_path_buf(),
                rate: Some(50.0),
                ignore_time: false,
                skip_lines: 0,
                scale: None,
                unit: None,
                rename: vec![],
            },
            model: model.iter().map(|s| s.to_string()).collect(),
            g: None,
            field: None,
            window: 1.0,
            threshold_k: 6.0,
            min_static: 1.5,
            blocks: 50,
            saturation: None,
            auto: false,
            max_steps: 4,
            json: true,
            plot: None,
            report: None,
            out: None,
        }
    }

    /// A magnetometer turned over the whole sphere through a symmetric soft-iron distortion.
    fn mag_csv() -> tempfile::NamedTempFile {
        let mut f = tempfile::NamedTempFile::new().unwrap();
        writeln!(f, "mx,my,mz").unwrap();
        let d = Matrix3::new(1.1, 0.05, 0.0, 0.05, 0.9, 0.02, 0.0, 0.02, 1.0);
        let n = 3000;
        for k in 0..n {
            let z = 1.0 - 2.0 * (k as f64 + 0.5) / n as f64;
            let r = (1.0 - z * z).sqrt();
            let phi = 0.05 * k as f64;
            // Deterministic ±0.1 µT dither in place of noise.
            let e = 0.1 * ((k * 7919 % 13) as f64 / 6.0 - 1.0);
            let m = d * Vector3::new(r * phi.cos(), r * phi.sin(), z) * 45.0
                + Vector3::new(5.0, -3.0, 12.0);
            writeln!(f, "{},{},{}", m.x + e, m.y - e, m.z + 0.5 * e).unwrap();
        }
        f
    }

    #[test]
    fn mag_run_writes_toml_svg_and_html() {
        let csv = mag_csv();
        let dir = tempfile::tempdir().unwrap();
        let mut a = args(csv.path(), SensorArg::Mag, &["hard_iron", "soft_iron"]);
        a.plot = Some(dir.path().join("m.svg"));
        a.report = Some(dir.path().join("m.html"));
        a.out = Some(dir.path().join("cal.toml"));
        run(a).unwrap();
        let svg = std::fs::read_to_string(dir.path().join("m.svg")).unwrap();
        assert!(svg.starts_with("<svg") && svg.contains("circle F ="));
        assert!(std::fs::read_to_string(dir.path().join("m.html"))
            .unwrap()
            .contains("<svg"));
        let cal =
            CalFile::from_toml(&std::fs::read_to_string(dir.path().join("cal.toml")).unwrap())
                .unwrap();
        for (k, t) in [5.0, -3.0, 12.0].iter().enumerate() {
            assert!(
                (cal.mag.hard_iron[k] - t).abs() < 0.05,
                "{:?}",
                cal.mag.hard_iron
            );
        }
        // A second run for another sensor keeps the mag section.
        let mut a = args(csv.path(), SensorArg::Mag, &["hard_iron"]);
        a.out = Some(dir.path().join("cal.toml"));
        run(a).unwrap();
        let cal2 =
            CalFile::from_toml(&std::fs::read_to_string(dir.path().join("cal.toml")).unwrap())
                .unwrap();
        assert_eq!(
            cal2.mag.soft_iron,
            [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
        );
        assert_eq!(cal2.accel, cal.accel);
    }

    #[test]
    fn bad_inputs_give_clear_errors() {
        let csv = mag_csv();
        let e = run(args(csv.path(), SensorArg::Mag, &["offset"]))
            .unwrap_err()
            .to_string();
        assert!(e.contains("does not apply to the mag"), "{e}");
        let e = run(args(csv.path(), SensorArg::Mag, &["hardiron"]))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("unknown effect") && e.contains("hard_iron"),
            "{e}"
        );
        let mut f = tempfile::NamedTempFile::new().unwrap();
        writeln!(f, "mx,my,mz\n1,2,3\n4,x,6").unwrap();
        let e = format!(
            "{:#}",
            run(args(f.path(), SensorArg::Mag, &[])).unwrap_err()
        );
        assert!(e.contains("line 3"), "{e}");
        // Accelerometer columns absent from a magnetometer file.
        let e = format!(
            "{:#}",
            run(args(csv.path(), SensorArg::Accel, &[])).unwrap_err()
        );
        assert!(e.contains("ax"), "{e}");
    }
}

#[cfg(test)]
mod json_tests {
    use super::*;

    #[test]
    fn json_has_the_documented_keys_and_only_the_models_params() {
        // A planar turn of a 25 µT horizontal field with hard iron only.
        let m: Vec<Vector3<f64>> = (0..600)
            .map(|k| {
                let a = k as f64 * 0.02;
                let e = 0.05 * ((k * 31 % 7) as f64 - 3.0);
                Vector3::new(25.0 * a.cos() + 4.0 + e, 25.0 * a.sin() - 2.0 - e, -30.0)
            })
            .collect();
        let p = MagProblem::new(m, None).unwrap();
        let r = outcome(&p, &[Effect::HardIron], false, 4).unwrap();
        let l = Loaded {
            data: Data::Mag(p),
            sentinels: Sentinels::default(),
            notes: vec![],
        };
        let v: serde_json::Value = serde_json::from_str(&json_out(&l, &r).unwrap()).unwrap();
        let keys: Vec<&str> = v.as_object().unwrap().keys().map(|k| k.as_str()).collect();
        for k in [
            "sensor",
            "model",
            "params",
            "residual_rms",
            "noise_floor",
            "diagnosis",
        ] {
            assert!(keys.contains(&k), "missing {k} in {keys:?}");
        }
        assert_eq!(v["sensor"], "mag");
        assert_eq!(v["model"], serde_json::json!(["hard_iron"]));
        let params: Vec<&str> = v["params"]
            .as_object()
            .unwrap()
            .keys()
            .map(|k| k.as_str())
            .collect();
        assert_eq!(
            params,
            ["field", "hard_iron"],
            "only the model's effects (+ F)"
        );
        let h = v["params"]["hard_iron"].as_array().unwrap();
        assert!(
            (h[0].as_f64().unwrap() - 4.0).abs() < 0.05
                && (h[1].as_f64().unwrap() + 2.0).abs() < 0.05
        );
        let d = &v["diagnosis"];
        assert!(d["adequate"].is_boolean() && d["explanation"].is_string());
        assert!(d["missing"].is_null() || d["missing"].is_string());
        assert!(v["residual_rms"].as_f64().unwrap() < 0.2);
    }
}
