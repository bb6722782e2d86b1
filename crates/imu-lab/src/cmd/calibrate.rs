//! `imu-lab calibrate accel|gyro|mag FILE --model a,b,…`: fit a calibration model, compare its
//! residual with the noise floor measured from the same data, name the missing effect, and
//! report the step before → after. All the maths is in `imu_cal`; this reads the recording,
//! checks the options against the physics, removes the sensors' overflow sentinels, and hands
//! the rendering to `render::calibration`.
use std::path::PathBuf;

use anyhow::{anyhow, Context, Result};
use imu_cal::lab::Effect;
use imu_cal::session::{self, json_out, Sensor};

use crate::input::{self, InputArgs};
use crate::render::{self, calibration};
#[cfg(test)]
mod tests;

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
    /// The part the recording was made with: MPU-6050 (accel, gyro); QMC5883L or HMC5883L
    /// (mag). The plausibility bounds are that part's, and `--out` writes it as the file's
    /// `part` (and its power-on sensitivity unless the file's is one of its ranges). Default:
    /// the file's, else the firmware's parts (MPU-6050, QMC5883L).
    #[arg(long)]
    pub part: Option<String>,
}

use crate::calibration::Loaded;

fn sensor(a: &Args) -> Sensor {
    match a.sensor {
        SensorArg::Accel => Sensor::Accel,
        SensorArg::Gyro => Sensor::Gyro,
        SensorArg::Mag => Sensor::Mag,
    }
}

/// The session's options from the flags.
fn options(a: &Args) -> Result<session::Options> {
    let model: Vec<Effect> = a
        .model
        .iter()
        .filter(|s| !s.trim().is_empty())
        .map(|s| Effect::parse(s))
        .collect::<Result<_, _>>()?;
    Ok(session::Options {
        sensor: sensor(a),
        model,
        g: a.g,
        field: a.field,
        window: a.window,
        threshold_k: a.threshold_k,
        min_static: a.min_static,
        saturation: a.saturation,
        blocks: a.blocks,
        auto: a.auto,
        max_steps: a.max_steps,
        cli: true,
        mag_part: match &a.part {
            Some(name) => {
                session::stated_part(sensor(a), name, "--part").map_err(|e| anyhow!(e))?
            }
            None => None,
        },
    })
}

/// The recording's columns for the session and the data prepared from them.
fn load_data(a: &Args, o: &session::Options) -> Result<Loaded> {
    let (wanted, optional) = o.columns();
    let rec = input::load_with(&a.input, &wanted, &optional)?;
    let shown = a.input.file.display().to_string();
    let input = session::Input {
        columns: rec
            .columns
            .iter()
            .map(|c| session::Column {
                name: &c.name,
                unit: &c.unit,
                values: &c.values,
            })
            .collect(),
        rate_hz: rec.rate_hz,
        segments: &rec.segments,
        shown: &shown,
    };
    session::prepare(&input, o).map_err(|e| anyhow!(e))
}

/// Run `imu-lab calibrate`.
pub fn run(a: Args) -> Result<()> {
    let o = options(&a)?;
    let loaded = load_data(&a, &o)?;
    let p = loaded.data.problem();
    let run = session::run(&loaded, &o).map_err(|e| anyhow!(e))?;

    if a.json {
        println!("{}", json_out(&loaded, &run));
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
        let existing = if path.exists() {
            Some(
                std::fs::read_to_string(path)
                    .with_context(|| format!("cannot read {}", path.display()))?,
            )
        } else {
            None
        };
        let text = session::update_file(existing.as_deref(), &loaded, &run)
            .map_err(|e| anyhow!("--out {}: {e}", path.display()))?;
        std::fs::write(path, text).with_context(|| format!("cannot write {}", path.display()))?;
        if !a.json {
            println!("wrote the {} section of {}", p.sensor(), path.display());
        }
    }
    Ok(())
}
