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
use imu_cal::lab::{CalLab, Effect, Params, Problem};
use imu_cal::mag::MagProblem;
use imu_cal::sentinel::{self, Part, Sentinels};
use model_lab::walk;
use nalgebra::Vector3;
use serde::Serialize;

use crate::input::{self, InputArgs, COUNTS};
use crate::render::{self, calibration};
mod json;
mod load;
#[cfg(test)]
mod tests;
use json::json_out;
use load::{default_model, load_data};

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

pub use crate::calibration::{Data, Loaded, Outcome};

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
        // The device must be able to hold it, within the parts' datasheet bounds.
        file.to_device()
            .map_err(|e| anyhow::anyhow!("{}: refused, not written: {e}", path.display()))?;
        std::fs::write(path, file.to_toml())
            .with_context(|| format!("cannot write {}", path.display()))?;
        if !a.json {
            println!("wrote the {} section of {}", p.sensor(), path.display());
        }
    }
    Ok(())
}
