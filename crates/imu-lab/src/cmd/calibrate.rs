//! `imu-lab calibrate accel|gyro|mag FILE --model a,b,…`: fit a calibration model, compare its
//! residual with the noise floor measured from the same data, name the missing effect, and
//! report the step before → after (issue 4). All the maths is in `imu_cal`; this is I/O.
use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use imu_cal::accel::{detect_static, AccelProblem, StaticDetect, G_STANDARD};
use imu_cal::file::CalFile;
use imu_cal::gyro::GyroProblem;
use imu_cal::gyro_rot::GyroRotProblem;
use imu_cal::lab::{analyse, Effect, Params, Problem, Report};
use imu_cal::mag::MagProblem;
use nalgebra::{Matrix3, Vector3};
use serde::Serialize;

#[path = "../cal_plot.rs"]
mod cal_plot;
use crate::input::{self, InputArgs};
use cal_plot::{figure, Panel, Series};

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
    /// temperature}; mag {hard_iron, soft_iron, soft_iron_2d}. Default: offset,scale | bias |
    /// hard_iron.
    #[arg(long, value_delimiter = ',')]
    pub model: Vec<String>,
    /// Gravity for the accelerometer fit (m/s²).
    #[arg(long, default_value_t = G_STANDARD)]
    pub g: f64,
    /// Field magnitude for the magnetometer fit (µT); fitted when absent.
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
    /// Print one JSON object on stdout instead of the text report.
    #[arg(long)]
    pub json: bool,
    /// Write the figure (SVG): scatter before/after with the fitted ellipse and the circle,
    /// residuals against orientation or temperature.
    #[arg(long)]
    pub plot: Option<PathBuf>,
    /// Write a self-contained HTML report (text, parameters and the figure).
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// Write (or update this sensor's section of) a TOML calibration file.
    #[arg(long)]
    pub out: Option<PathBuf>,
}

#[derive(Serialize)]
struct JsonDiagnosis<'a> {
    adequate: bool,
    missing: Option<&'static str>,
    explanation: &'a str,
    p_value: f64,
    candidates: &'a [imu_cal::lab::Candidate],
}

#[derive(Serialize)]
struct JsonStep<'a> {
    added: &'static str,
    model: Vec<&'static str>,
    residual_rms_before: f64,
    residual_rms_after: f64,
    params: &'a Params,
}

#[derive(Serialize)]
struct JsonOut<'a> {
    sensor: &'static str,
    unit: &'static str,
    model: Vec<&'static str>,
    params: &'a Params,
    /// Residual RMS of the model (unit).
    residual_rms: f64,
    /// The residual RMS a complete model would leave, from the data's own noise (unit).
    noise_floor: f64,
    /// How many residuals (poses, samples or blocks × 3).
    n_residuals: usize,
    diagnosis: JsonDiagnosis<'a>,
    step: Option<JsonStep<'a>>,
}

/// The data of one run, kept for the plots.
enum Data {
    Accel(AccelProblem),
    Gyro(GyroProblem),
    GyroRot(GyroRotProblem),
    Mag(MagProblem),
}

impl Data {
    fn problem(&self) -> &dyn Problem {
        match self {
            Data::Accel(p) => p,
            Data::Gyro(p) => p,
            Data::GyroRot(p) => p,
            Data::Mag(p) => p,
        }
    }
}

fn default_model(s: SensorArg) -> Vec<Effect> {
    match s {
        SensorArg::Accel => vec![Effect::Offset, Effect::Scale],
        SensorArg::Gyro => vec![Effect::Bias],
        SensorArg::Mag => vec![Effect::HardIron],
    }
}

fn columns(in_: &InputArgs, names: [&str; 3]) -> Result<(input::Recording, [Vec<f64>; 3])> {
    let rec = input::load(in_, &names)?;
    let col = |n: &str| -> Result<Vec<f64>> {
        Ok(rec
            .column(n)
            .with_context(|| format!("column {n} missing"))?
            .values
            .clone())
    };
    let cols = [col(names[0])?, col(names[1])?, col(names[2])?];
    Ok((rec, cols))
}

/// The temperature column in °C, if the file has one (--scale and --unit never apply to it).
fn temperature(in_: &InputArgs) -> Result<Option<Vec<f64>>> {
    let rec = input::load_with(in_, &[], &["temp"])?;
    Ok(rec.column("temp").map(|c| c.values.clone()))
}

fn load_data(a: &Args, model: &[Effect]) -> Result<Data> {
    let rotation = model.contains(&Effect::Scale) || model.contains(&Effect::Misalignment);
    Ok(match a.sensor {
        SensorArg::Gyro if rotation => {
            // Gyro scale/misalignment: rotations between static poses, gravity as reference.
            // Only the direction of the accelerometer is used, so one --scale for both is fine.
            let (rec, c) = columns(&a.input, ["ax", "ay", "az"])?;
            let (_, w) = columns(&a.input, ["gx", "gy", "gz"])?;
            let cfg = StaticDetect {
                window_s: a.window,
                k: a.threshold_k,
                min_static_s: a.min_static,
            };
            let poses = detect_static([&c[0], &c[1], &c[2]], rec.rate_hz, cfg)?;
            Data::GyroRot(GyroRotProblem::new(
                [&c[0], &c[1], &c[2]],
                [&w[0], &w[1], &w[2]],
                rec.rate_hz,
                &poses,
                a.saturation,
            )?)
        }
        SensorArg::Accel => {
            let (rec, c) = columns(&a.input, ["ax", "ay", "az"])?;
            let cfg = StaticDetect {
                window_s: a.window,
                k: a.threshold_k,
                min_static_s: a.min_static,
            };
            let poses = detect_static([&c[0], &c[1], &c[2]], rec.rate_hz, cfg)?;
            if a.g.is_nan() || a.g <= 0.0 {
                bail!("--g {}: gravity must be positive (m/s²)", a.g);
            }
            Data::Accel(AccelProblem { poses, g: a.g })
        }
        SensorArg::Gyro => {
            let (_, c) = columns(&a.input, ["gx", "gy", "gz"])?;
            let t = temperature(&a.input)?;
            Data::Gyro(GyroProblem::new(
                [&c[0], &c[1], &c[2]],
                t.as_deref(),
                a.blocks,
            )?)
        }
        SensorArg::Mag => {
            let (_, c) = columns(&a.input, ["mx", "my", "mz"])?;
            let m = (0..c[0].len())
                .map(|i| Vector3::new(c[0][i], c[1][i], c[2][i]))
                .collect();
            Data::Mag(MagProblem::new(m, a.field)?)
        }
    })
}

/// The one JSON object of `--json` (issue 4 §3 schema, plus `unit`, `n_residuals`, the
/// candidates' evidence and the step).
fn json_out(p: &dyn Problem, report: &Report) -> Result<String> {
    let unit = p.unit();
    let names = |m: &[Effect]| m.iter().map(|e| e.name()).collect::<Vec<_>>();
    let out = JsonOut {
        sensor: p.sensor(),
        unit,
        model: names(&report.fitted.model),
        params: &report.fitted.params,
        residual_rms: report.fitted.rms(),
        noise_floor: report.expected_rms,
        n_residuals: report.fitted.residuals.len(),
        diagnosis: JsonDiagnosis {
            adequate: report.diagnosis.adequate,
            missing: report.diagnosis.missing.map(|e| e.name()),
            explanation: &report.diagnosis.explanation,
            p_value: report.diagnosis.p_value,
            candidates: &report.diagnosis.candidates,
        },
        step: report.step.as_ref().map(|s| JsonStep {
            added: s.added.name(),
            model: names(&s.model),
            residual_rms_before: s.residual_rms_before,
            residual_rms_after: s.residual_rms_after,
            params: &s.params,
        }),
    };
    Ok(serde_json::to_string(&out)?)
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
    let data = load_data(&a, &model)?;
    let mut model = model;
    if let Data::GyroRot(_) = data {
        // The rotation fit always removes the bias at rest first; temperature is a block fit.
        if model.contains(&Effect::Temperature) {
            bail!(
                "fit temperature with --model bias,temperature and scale/misalignment separately"
            );
        }
        model.retain(|e| *e != Effect::Bias);
    }
    let p = data.problem();
    let report = analyse(p, &model)?;

    if a.json {
        println!("{}", json_out(p, &report)?);
    } else {
        print!("{}", text_report(&data, &report));
    }

    let svg = if a.plot.is_some() || a.report.is_some() {
        Some(plot(&data, &report))
    } else {
        None
    };
    if let (Some(path), Some(svg)) = (&a.plot, &svg) {
        std::fs::write(path, svg).with_context(|| format!("cannot write {}", path.display()))?;
    }
    if let Some(path) = &a.report {
        let html = html_report(&data, &report, svg.as_deref().unwrap_or(""));
        std::fs::write(path, html).with_context(|| format!("cannot write {}", path.display()))?;
    }
    if let Some(path) = &a.out {
        let mut file = if path.exists() {
            let text = std::fs::read_to_string(path)
                .with_context(|| format!("cannot read {}", path.display()))?;
            CalFile::from_toml(&text).with_context(|| format!("{}", path.display()))?
        } else {
            CalFile::default()
        };
        let section = match data {
            Data::GyroRot(_) => "gyro-rot",
            _ => p.sensor(),
        };
        file.set(section, &report.fitted.params)?;
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

fn v3(v: &[f64; 3], prec: usize) -> String {
    format!("[{:.prec$}, {:.prec$}, {:.prec$}]", v[0], v[1], v[2])
}

/// The parameters, one per line, with units.
pub fn params_text(p: &Params) -> String {
    let mut s = String::new();
    if let Some(v) = &p.offset {
        s += &format!("  offset           = {} m/s²\n", v3(v, 5));
    }
    if let Some(v) = &p.scale {
        s += &format!("  scale            = {} (dimensionless)\n", v3(v, 6));
    }
    if let Some(v) = &p.misalignment_deg {
        s += &format!("  misalignment     = {} deg\n", v3(v, 4));
    }
    if let Some(v) = &p.gyro_misalignment_deg {
        s += &format!(
            "  misalignment     = [{:.4}, {:.4}, {:.4}, {:.4}, {:.4}, {:.4}] deg (γ₁…γ₆)\n",
            v[0], v[1], v[2], v[3], v[4], v[5]
        );
    }
    if let Some(g) = p.g {
        s += &format!("  g                = {g} m/s² (given)\n");
    }
    if let Some(v) = &p.bias {
        s += &format!("  bias             = {} deg/s\n", v3(v, 5));
    }
    if let Some(v) = &p.temp_coeff {
        s += &format!("  temp_coeff       = {} deg/s per °C\n", v3(v, 6));
    }
    if let Some(t) = p.temp_ref {
        s += &format!("  temp_ref         = {t:.3} °C\n");
    }
    if let Some(v) = &p.hard_iron {
        s += &format!("  hard_iron        = {} µT\n", v3(v, 4));
    }
    if let Some(m) = &p.soft_iron {
        s += &format!(
            "  soft_iron        = [{},\n                      {},\n                      {}] (dimensionless)\n",
            v3(&m[0], 5),
            v3(&m[1], 5),
            v3(&m[2], 5)
        );
    }
    if let Some(e) = &p.soft_iron_2d {
        s += &format!(
            "  soft_iron_2d     = r {:.4} µT, q {:.4} µT, θ {:.3} deg, σ = q/r {:.5}\n",
            e.r, e.q, e.theta_deg, e.sigma
        );
    }
    if let Some(f) = p.field {
        s += &format!("  field F          = {f:.4} µT\n");
    }
    s
}

fn text_report(data: &Data, r: &Report) -> String {
    let p = data.problem();
    let unit = p.unit();
    let mut s = String::new();
    let names = |m: &[Effect]| m.iter().map(|e| e.name()).collect::<Vec<_>>().join(", ");
    match data {
        Data::Accel(a) => {
            s += &format!(
                "calibrate accel: {} static poses found (g = {} m/s²)\n",
                a.poses.len(),
                a.g
            )
        }
        Data::Gyro(g) => {
            s += &format!(
                "calibrate gyro: {} blocks of {} samples{}\n",
                g.blocks[0].len(),
                g.block_len,
                if g.temp.is_some() {
                    ", with temperature"
                } else {
                    ", no temperature column"
                }
            )
        }
        Data::GyroRot(g) => {
            s += &format!(
                "calibrate gyro (scale/misalignment from rotations): {} moves between static \
                 poses, {} skipped as saturated; bias removed {} deg/s\n",
                g.moves.len(),
                g.skipped_saturated,
                v3(&g.bias, 5)
            )
        }
        Data::Mag(m) => {
            s += &format!(
                "calibrate mag: {} samples, principal s.d. {:.2}/{:.2}/{:.2} µT ({})\n",
                m.m.len(),
                m.principal_sd[0],
                m.principal_sd[1],
                m.principal_sd[2],
                match m.plane {
                    Some([i, j]) => format!(
                        "planar in the {}{} plane",
                        ["x", "y", "z"][i],
                        ["x", "y", "z"][j]
                    ),
                    None => "3-D".into(),
                }
            )
        }
    }
    let model = if r.fitted.model.is_empty() {
        "(none)".to_string()
    } else {
        names(&r.fitted.model)
    };
    s += &format!("model: {model}\nparams:\n{}", params_text(&r.fitted.params));
    s += &format!(
        "residual RMS {:.5} {unit} over {} residuals; noise floor {:.5} {unit} (σ {:.5} {unit} from {})\n",
        r.fitted.rms(),
        r.fitted.residuals.len(),
        r.expected_rms,
        r.floor.sigma,
        r.floor.method
    );
    s += &format!(
        "verdict: {}\n",
        if r.diagnosis.adequate {
            "ADEQUATE"
        } else {
            "NOT ADEQUATE"
        }
    );
    if !r.diagnosis.candidates.is_empty() {
        s += "candidates:\n";
        for c in &r.diagnosis.candidates {
            match (&c.skipped, c.residual_rms, c.f, c.p_value) {
                (Some(why), ..) => s += &format!("  {:<13} not tried: {why}\n", c.effect.name()),
                (None, Some(rms), Some(f), Some(pv)) => s += &format!(
                    "  {:<13} residual RMS {rms:.5} {unit}, F = {f:.2} for {} extra parameters, p = {pv:.3e}\n",
                    c.effect.name(),
                    c.extra_params
                ),
                _ => {}
            }
        }
    }
    s += &format!("diagnosis: {}\n", r.diagnosis.explanation);
    if let Some(st) = &r.step {
        s += &format!(
            "step: + {} → model {}: residual RMS {:.5} → {:.5} {unit}\nparams after the step:\n{}",
            st.added.name(),
            names(&st.model),
            st.residual_rms_before,
            st.residual_rms_after,
            params_text(&st.params)
        );
    }
    s
}

fn html_report(data: &Data, r: &Report, svg: &str) -> String {
    let esc = |t: &str| {
        t.replace('&', "&amp;")
            .replace('<', "&lt;")
            .replace('>', "&gt;")
    };
    format!(
        "<!DOCTYPE html><html><head><meta charset=\"utf-8\"><title>imu-lab calibrate {}</title>\
         <style>body{{font-family:sans-serif;max-width:1300px;margin:2em auto}}pre{{background:#f6f6f6;padding:1em;white-space:pre-wrap}}</style>\
         </head><body><h1>Calibration lab: {}</h1><pre>{}</pre>{svg}</body></html>\n",
        data.problem().sensor(),
        data.problem().sensor(),
        esc(&text_report(data, r))
    )
}

/// The model to draw as "after": the step's when a missing effect was found.
fn after_params(r: &Report) -> (&Params, String) {
    match &r.step {
        Some(s) => (
            &s.params,
            s.model
                .iter()
                .map(|e| e.name())
                .collect::<Vec<_>>()
                .join("+"),
        ),
        None => (
            &r.fitted.params,
            r.fitted
                .model
                .iter()
                .map(|e| e.name())
                .collect::<Vec<_>>()
                .join("+"),
        ),
    }
}

fn mag_matrix(p: &Params) -> Matrix3<f64> {
    p.soft_iron
        .map(|s| Matrix3::from_row_slice(&s.concat()))
        .unwrap_or_else(Matrix3::identity)
}

/// Central section of the fitted ellipsoid {m : |S(m − h)| = F} by the plane of axes (i, j)
/// through h: the radius along a direction d of that plane is F/|S·d|.
fn section(p: &Params, i: usize, j: usize) -> Vec<(f64, f64)> {
    let s = mag_matrix(p);
    let h = p.hard_iron.unwrap_or([0.0; 3]);
    let f = p.field.unwrap_or(1.0);
    (0..=180)
        .map(|k| {
            let a = 2.0 * std::f64::consts::PI * k as f64 / 180.0;
            let mut d = Vector3::zeros();
            d[i] = a.cos();
            d[j] = a.sin();
            let r = f / (s * d).norm();
            (h[i] + r * d[i], h[j] + r * d[j])
        })
        .collect()
}

fn circle(r: f64) -> Vec<(f64, f64)> {
    (0..=180)
        .map(|k| {
            let a = 2.0 * std::f64::consts::PI * k as f64 / 180.0;
            (r * a.cos(), r * a.sin())
        })
        .collect()
}

const AX: [&str; 3] = ["X", "Y", "Z"];

/// Without a step, "after" is the same model as "before": keep one copy of each residual set.
fn residual_series(r: &Report, before: Series, after: Series) -> Vec<Series> {
    if r.step.is_some() {
        vec![before, after]
    } else {
        vec![before]
    }
}

fn plot(data: &Data, r: &Report) -> String {
    let (after, after_name) = after_params(r);
    let before_name = r
        .fitted
        .model
        .iter()
        .map(|e| e.name())
        .collect::<Vec<_>>()
        .join("+");
    let before_name = if before_name.is_empty() {
        "no correction".to_string()
    } else {
        before_name
    };
    match data {
        Data::Mag(m) => {
            let corr: Vec<Vector3<f64>> =
                m.m.iter().map(|v| MagProblem::correct(after, *v)).collect();
            let before_corr: Vec<Vector3<f64>> =
                m.m.iter()
                    .map(|v| MagProblem::correct(&r.fitted.params, *v))
                    .collect();
            let f = after.field.unwrap_or(1.0);
            let fb = r.fitted.params.field.unwrap_or(1.0);
            // Planar data are fitted (and so drawn) in their plane; 3-D data in XY and YZ.
            let pairs: Vec<(usize, usize)> = match m.plane {
                Some([i, j]) => vec![(i, j)],
                None => vec![(0, 1), (1, 2)],
            };
            let mut panels = Vec::new();
            for &(i, j) in &pairs {
                let (ni, nj) = (AX[i].to_lowercase(), AX[j].to_lowercase());
                panels.push(Panel {
                    title: format!("{}{} before (raw) with the fitted ellipse", AX[i], AX[j]),
                    xlabel: format!("m{ni} (µT)"),
                    ylabel: format!("m{nj} (µT)"),
                    series: vec![
                        Series {
                            label: "measured".into(),
                            color: "#1f77b4",
                            points: m.m.iter().map(|v| (v[i], v[j])).collect(),
                            line: false,
                        },
                        Series {
                            label: format!("fitted ({after_name}) section"),
                            color: "#d62728",
                            points: section(after, i, j),
                            line: true,
                        },
                    ],
                    equal: true,
                });
                panels.push(Panel {
                    title: format!("{}{} after ({after_name})", AX[i], AX[j]),
                    xlabel: format!("m{ni} (µT)"),
                    ylabel: format!("m{nj} (µT)"),
                    series: vec![
                        Series {
                            label: "corrected".into(),
                            color: "#2ca02c",
                            points: corr.iter().map(|v| (v[i], v[j])).collect(),
                            line: false,
                        },
                        Series {
                            label: format!("circle F = {f:.2} µT"),
                            color: "#d62728",
                            points: circle(f),
                            line: true,
                        },
                    ],
                    equal: true,
                });
            }
            // Residuals on the lab's basis (in-plane magnitude for planar data) against the
            // orientation of the corrected field.
            type VecFn<'a> = Box<dyn Fn(&Vector3<f64>) -> f64 + 'a>;
            type Ang<'a> = (&'static str, VecFn<'a>);
            let (mag, angles): (VecFn, Vec<Ang>) = match m.plane {
                Some([i, j]) => (
                    Box::new(move |v: &Vector3<f64>| (v[i] * v[i] + v[j] * v[j]).sqrt()),
                    vec![(
                        "in-plane angle",
                        Box::new(move |v: &Vector3<f64>| v[j].atan2(v[i]).to_degrees()),
                    )],
                ),
                None => (
                    Box::new(|v: &Vector3<f64>| v.norm()),
                    vec![
                        (
                            "azimuth",
                            Box::new(|v: &Vector3<f64>| v.y.atan2(v.x).to_degrees()),
                        ),
                        (
                            "elevation",
                            Box::new(|v: &Vector3<f64>| (v.z / v.norm()).asin().to_degrees()),
                        ),
                    ],
                ),
            };
            for (name, ang) in &angles {
                panels.push(Panel {
                    title: format!("residual |m| − F against {name}"),
                    xlabel: format!("{name} of the corrected field (deg)"),
                    ylabel: "|m| − F (µT)".into(),
                    series: residual_series(
                        r,
                        Series {
                            label: before_name.clone(),
                            color: "#ff7f0e",
                            points: before_corr.iter().map(|v| (ang(v), mag(v) - fb)).collect(),
                            line: false,
                        },
                        Series {
                            label: after_name.clone(),
                            color: "#2ca02c",
                            points: corr.iter().map(|v| (ang(v), mag(v) - f)).collect(),
                            line: false,
                        },
                    ),
                    equal: false,
                });
            }
            figure("imu-lab calibrate mag", &panels, 2)
        }
        Data::Accel(a) => {
            let g = a.g;
            let raw: Vec<[f64; 3]> = a.poses.iter().map(|p| p.mean).collect();
            let corr: Vec<[f64; 3]> = raw
                .iter()
                .map(|v| AccelProblem::correct(after, *v))
                .collect();
            let bef: Vec<[f64; 3]> = raw
                .iter()
                .map(|v| AccelProblem::correct(&r.fitted.params, *v))
                .collect();
            let mut panels = Vec::new();
            for (i, j) in [(0, 1), (1, 2)] {
                panels.push(Panel {
                    title: format!("{}{} pose means before / after", AX[i], AX[j]),
                    xlabel: format!("a{} (m/s²)", AX[i].to_lowercase()),
                    ylabel: format!("a{} (m/s²)", AX[j].to_lowercase()),
                    series: vec![
                        Series {
                            label: "raw".into(),
                            color: "#1f77b4",
                            points: raw.iter().map(|v| (v[i], v[j])).collect(),
                            line: false,
                        },
                        Series {
                            label: format!("corrected ({after_name})"),
                            color: "#2ca02c",
                            points: corr.iter().map(|v| (v[i], v[j])).collect(),
                            line: false,
                        },
                        Series {
                            label: format!("circle g = {g} m/s²"),
                            color: "#d62728",
                            points: circle(g),
                            line: true,
                        },
                    ],
                    equal: true,
                });
            }
            let el = |v: &[f64; 3]| (v[2] / Vector3::from(*v).norm()).asin().to_degrees();
            let az = |v: &[f64; 3]| v[1].atan2(v[0]).to_degrees();
            for (name, ang) in [
                ("elevation", &el as &dyn Fn(&[f64; 3]) -> f64),
                ("azimuth", &az),
            ] {
                panels.push(Panel {
                    title: format!("pose residual |a| − g against {name}"),
                    xlabel: format!("{name} of gravity in the sensor frame (deg)"),
                    ylabel: "|a| − g (m/s²)".into(),
                    series: residual_series(
                        r,
                        Series {
                            label: before_name.clone(),
                            color: "#ff7f0e",
                            points: bef
                                .iter()
                                .map(|v| (ang(v), Vector3::from(*v).norm() - g))
                                .collect(),
                            line: false,
                        },
                        Series {
                            label: after_name.clone(),
                            color: "#2ca02c",
                            points: corr
                                .iter()
                                .map(|v| (ang(v), Vector3::from(*v).norm() - g))
                                .collect(),
                            line: false,
                        },
                    ),
                    equal: false,
                });
            }
            figure("imu-lab calibrate accel", &panels, 2)
        }
        Data::GyroRot(gp) => {
            // Residual per move (two components, deg) against the turn angle of the move.
            let angle = |mv: &imu_cal::gyro_rot::Move| mv.u0.angle(&mv.u1).to_degrees();
            let pts = |res: &[f64]| -> Vec<(f64, f64)> {
                gp.moves
                    .iter()
                    .enumerate()
                    .flat_map(|(k, mv)| [(angle(mv), res[2 * k]), (angle(mv), res[2 * k + 1])])
                    .collect()
            };
            let after_res = match &r.step {
                Some(_) => analyse(
                    gp,
                    &r.step.as_ref().map(|s| s.model.clone()).unwrap_or_default(),
                )
                .map(|x| x.fitted.residuals)
                .unwrap_or_default(),
                None => vec![],
            };
            let mut series = vec![Series {
                label: before_name.clone(),
                color: "#ff7f0e",
                points: pts(&r.fitted.residuals),
                line: false,
            }];
            if after_res.len() == r.fitted.residuals.len() {
                series.push(Series {
                    label: after_name.clone(),
                    color: "#2ca02c",
                    points: pts(&after_res),
                    line: false,
                });
            }
            let panels = vec![Panel {
                title: "gravity-direction residual per move".into(),
                xlabel: "tilt change of the move (deg)".into(),
                ylabel: "residual component (deg)".into(),
                series,
                equal: false,
            }];
            figure("imu-lab calibrate gyro (rotations)", &panels, 1)
        }
        Data::Gyro(gp) => {
            let nb = gp.blocks[0].len();
            let t: Vec<f64> = gp
                .temp
                .clone()
                .unwrap_or_else(|| (0..nb).map(|i| i as f64).collect());
            let xl = if gp.temp.is_some() {
                "block mean temperature (°C)"
            } else {
                "block index (no temperature column)"
            };
            let resid = |p: &Params, j: usize| -> Vec<(f64, f64)> {
                let b = p.bias.map(|b| b[j]).unwrap_or(0.0);
                let k = p.temp_coeff.map(|k| k[j]).unwrap_or(0.0);
                let tr = p.temp_ref.unwrap_or(0.0);
                (0..nb)
                    .map(|i| (t[i], gp.blocks[j][i] - b - k * (t[i] - tr)))
                    .collect()
            };
            let panels: Vec<Panel> = (0..3)
                .map(|j| Panel {
                    title: format!("g{} residual against temperature", AX[j].to_lowercase()),
                    xlabel: xl.into(),
                    ylabel: "block-mean residual (deg/s)".into(),
                    series: residual_series(
                        r,
                        Series {
                            label: before_name.clone(),
                            color: "#ff7f0e",
                            points: resid(&r.fitted.params, j),
                            line: false,
                        },
                        Series {
                            label: after_name.clone(),
                            color: "#2ca02c",
                            points: resid(after, j),
                            line: false,
                        },
                    ),
                    equal: false,
                })
                .collect();
            figure("imu-lab calibrate gyro", &panels, 3)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
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
            g: G_STANDARD,
            field: None,
            window: 1.0,
            threshold_k: 6.0,
            min_static: 1.5,
            blocks: 50,
            saturation: None,
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
    fn json_has_the_issue_schema_and_only_the_models_params() {
        // A planar turn of a 25 µT horizontal field with hard iron only.
        let m: Vec<Vector3<f64>> = (0..600)
            .map(|k| {
                let a = k as f64 * 0.02;
                let e = 0.05 * ((k * 31 % 7) as f64 - 3.0);
                Vector3::new(25.0 * a.cos() + 4.0 + e, 25.0 * a.sin() - 2.0 - e, -30.0)
            })
            .collect();
        let p = MagProblem::new(m, None).unwrap();
        let r = analyse(&p, &[Effect::HardIron]).unwrap();
        let v: serde_json::Value = serde_json::from_str(&json_out(&p, &r).unwrap()).unwrap();
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
