//! `imu-lab fit`: fit the noise model to a column's overlapping Allan deviation, judge it, name
//! the missing effect, and show the step when the user adds it (issue 3 §2–§8).
use std::path::PathBuf;

use allan::{deviation_segments, Stat, TauSet};
use anyhow::{anyhow, bail, Context, Result};
use noise_model::{
    assess, diagnose, fit_with_data, practical, step, Assessment, Diagnosis, Effect, Fit, Point,
    Step, DEFAULT_TERMS,
};
use serde::Serialize;
use serde_json::{Map, Value};

use crate::input::{self, InputArgs};
use crate::render::{allan as plot, noise as report};

/// Arguments of `imu-lab fit`.
#[derive(clap::Args, Debug)]
pub struct Args {
    #[command(flatten)]
    pub input: InputArgs,
    /// Column to analyse (gx gy gz, ax ay az, …).
    #[arg(long)]
    pub column: String,
    /// Model terms, comma-separated, from quantization, white, flicker, rate_random_walk,
    /// rate_ramp, markov, sinusoid (default: the seed's five power-law terms).
    #[arg(long, value_delimiter = ',')]
    pub terms: Vec<String>,
    /// Add an effect to the model and show the step before → after (repeatable, comma-separated).
    #[arg(long, value_delimiter = ',')]
    pub add: Vec<String>,
    /// Bias tolerance in the column's unit: print the recalibration period from B, K and R.
    #[arg(long)]
    pub tolerance: Option<f64>,
    /// Print one JSON object on stdout instead of the report.
    #[arg(long)]
    pub json: bool,
    /// Write the Allan plot (with the residual panel) as SVG or PNG (by the name's extension);
    /// before and after side by side when --add is given.
    #[arg(long)]
    pub plot: Option<PathBuf>,
    /// Write a self-contained HTML report (one section per step).
    #[arg(long)]
    pub report: Option<PathBuf>,
}

fn parse_effects(list: &[String], flag: &str) -> Result<Vec<Effect>> {
    list.iter()
        .filter(|s| !s.trim().is_empty())
        .map(|s| {
            Effect::parse(s).ok_or_else(|| {
                anyhow!(
                    "{flag} {s:?}: unknown effect; expected one of quantization, white, flicker, \
                     rate_random_walk, rate_ramp, markov, sinusoid"
                )
            })
        })
        .collect()
}

/// One analysed model.
pub struct Stage {
    pub fit: Fit,
    pub assessment: Assessment,
    pub diagnosis: Diagnosis,
}

fn stage(points: &[Point], tau0: f64, effects: &[Effect], y: &[f64], rate: f64) -> Result<Stage> {
    let f = fit_with_data(points, tau0, effects, Some((y, rate)))
        .map_err(|e| anyhow!("fit of {}: {e}", names(effects)))?;
    let a = assess(&f);
    let d = diagnose(&f, &a, Some((y, rate)));
    Ok(Stage {
        fit: f,
        assessment: a,
        diagnosis: d,
    })
}

fn names(effects: &[Effect]) -> String {
    effects
        .iter()
        .map(|e| e.name())
        .collect::<Vec<_>>()
        .join(" + ")
}

#[derive(Serialize)]
struct JsonTerm {
    effect: &'static str,
    params: Map<String, Value>,
    sigma: Map<String, Value>,
    detected: bool,
    upper_bound: Map<String, Value>,
}

#[derive(Serialize)]
struct JsonDiag {
    adequate: bool,
    missing: Option<&'static str>,
    tau_range_s: Option<[f64; 2]>,
    explanation: String,
    evidence: Vec<String>,
}

#[derive(Serialize)]
struct JsonPoint {
    tau_s: f64,
    dev: f64,
    lo: f64,
    hi: f64,
    model: f64,
    residual: f64,
    edf: f64,
}

#[derive(Serialize)]
struct JsonStep {
    added: Vec<&'static str>,
    chi2_dof_before: f64,
    chi2_dof_after: f64,
    rms_log_residual_before: f64,
    rms_log_residual_after: f64,
    adequate_before: bool,
    adequate_after: bool,
}

#[derive(Serialize)]
struct JsonRecal {
    tolerance: f64,
    period_s: Option<f64>,
    period_conservative_s: Option<f64>,
    flicker_floor: f64,
    possible: bool,
}

#[derive(Serialize)]
struct JsonOut<'a> {
    column: &'a str,
    unit: &'a str,
    rate_hz: f64,
    samples: usize,
    terms: Vec<JsonTerm>,
    chi2_dof: f64,
    rms_log_residual: f64,
    diagnosis: JsonDiag,
    adev: Vec<JsonPoint>,
    steps: Vec<JsonStep>,
    recalibration: Option<JsonRecal>,
}

fn num(v: f64) -> Value {
    serde_json::Number::from_f64(v).map_or(Value::Null, Value::Number)
}

fn json_terms(f: &Fit) -> Vec<JsonTerm> {
    f.terms
        .iter()
        .map(|t| {
            let mut params = Map::new();
            let mut sigma = Map::new();
            let mut ub = Map::new();
            for p in t.params() {
                params.insert(p.name.into(), num(p.value));
                sigma.insert(p.name.into(), num(p.sigma));
                if let Some(u) = p.upper_bound {
                    ub.insert(p.name.into(), num(u));
                }
            }
            JsonTerm {
                effect: t.effect.name(),
                params,
                sigma,
                detected: t.detected,
                upper_bound: ub,
            }
        })
        .collect()
}

/// B, K, R with their conservative values (+1σ, or the upper bound when not detected).
fn drift_terms(f: &Fit) -> (f64, f64, f64, f64, f64) {
    let get = |e: Effect| -> (f64, f64) {
        match f.term(e) {
            Some(t) if t.detected => (t.amplitude(), t.amplitude() + t.amplitude_sigma()),
            Some(t) => (0.0, t.upper_bound().unwrap_or(0.0)),
            None => (0.0, 0.0),
        }
    };
    let (b, _) = get(Effect::Flicker);
    let (k, kc) = get(Effect::RateRandomWalk);
    let (r, rc) = get(Effect::RateRamp);
    (b, k, r, kc, rc)
}

fn duration(s: f64) -> String {
    if s < 120.0 {
        format!("{} s", report::sig(s, 3))
    } else if s < 7200.0 {
        format!("{} min", report::sig(s / 60.0, 3))
    } else if s < 172_800.0 {
        format!("{} h", report::sig(s / 3600.0, 3))
    } else {
        format!("{} days", report::sig(s / 86400.0, 3))
    }
}

pub fn run(args: Args) -> Result<()> {
    let base_terms = if args.terms.is_empty() {
        DEFAULT_TERMS.to_vec()
    } else {
        parse_effects(&args.terms, "--terms")?
    };
    let adds = parse_effects(&args.add, "--add")?;
    for e in &adds {
        if base_terms.contains(e) {
            bail!("--add {e}: the model already has it");
        }
    }
    let rec = input::load(&args.input, &[&args.column])?;
    let shown = args.input.file.display().to_string();
    let series = rec
        .column(&args.column)
        .ok_or_else(|| anyhow!("{shown}: column {:?} missing", args.column))?;
    let unit = series.unit.clone();
    let y = &series.values;
    let tau0 = 1.0 / rec.rate_hz;
    let segments = rec.segments_of(&args.column).unwrap_or_default();
    let rows = deviation_segments(&segments, tau0, Stat::Oadev, &TauSet::Octave)
        .with_context(|| format!("{shown}: column {:?}", args.column))?;
    let (points, skipped) = Point::from_rows(&rows);

    let mut stages = vec![stage(&points, tau0, &base_terms, y, rec.rate_hz)?];
    let mut steps: Vec<Step> = Vec::new();
    let mut terms = base_terms.clone();
    for e in &adds {
        terms.push(*e);
        let next = stage(&points, tau0, &terms, y, rec.rate_hz)?;
        let prev = stages.last().expect("one stage");
        steps.push(step(
            &prev.fit,
            &prev.assessment,
            &next.fit,
            &next.assessment,
        ));
        stages.push(next);
    }
    let last = stages.last().expect("one stage");
    let recal = args.tolerance.map(|tol| {
        let (b, k, r, kc, rc) = drift_terms(&last.fit);
        practical::recalibration(b, k, r, kc, rc, tol)
    });
    if let Some(tol) = args.tolerance {
        if !(tol > 0.0 && tol.is_finite()) {
            bail!("--tolerance {tol}: must be a positive number in {unit}");
        }
    }

    let base_name = args
        .input
        .file
        .file_name()
        .map_or(shown.clone(), |n| n.to_string_lossy().into_owned());
    let title = format!("{} [{unit}] — {}", args.column, base_name);
    if let Some(path) = &args.plot {
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase);
        if !matches!(ext.as_deref(), Some("svg") | Some("png")) {
            bail!("--plot {}: give a .svg or .png name", path.display());
        }
        let figs: Vec<String> = if stages.len() == 1 {
            vec![plot::figure(
                &last.fit,
                &last.assessment,
                &title,
                &unit,
                0.0,
            )]
        } else {
            let first = &stages[stages.len() - 2];
            vec![
                plot::figure(
                    &first.fit,
                    &first.assessment,
                    &format!("before: {}", names(&first.fit.effects())),
                    &unit,
                    0.0,
                ),
                plot::figure(
                    &last.fit,
                    &last.assessment,
                    &format!("after: + {}", adds.last().map_or("", |e| e.name())),
                    &unit,
                    plot::W,
                ),
            ]
        };
        let svg = plot::document(&figs);
        let bytes = if ext.as_deref() == Some("png") {
            plot::svg_to_png(&svg).with_context(|| format!("rendering {}", path.display()))?
        } else {
            svg.into_bytes()
        };
        std::fs::write(path, bytes).with_context(|| format!("writing {}", path.display()))?;
    }
    if let Some(path) = &args.report {
        let mut sections = Vec::new();
        for (i, st) in stages.iter().enumerate() {
            let svg = if i == 0 {
                plot::document(&[plot::figure(
                    &st.fit,
                    &st.assessment,
                    &names(&st.fit.effects()),
                    &unit,
                    0.0,
                )])
            } else {
                let prev = &stages[i - 1];
                plot::document(&[
                    plot::figure(&prev.fit, &prev.assessment, "before", &unit, 0.0),
                    plot::figure(
                        &st.fit,
                        &st.assessment,
                        &format!("after: + {}", adds[i - 1]),
                        &unit,
                        plot::W,
                    ),
                ])
            };
            sections.push(report::Section {
                title: if i == 0 {
                    format!("Step 1 — model: {}", names(&st.fit.effects()))
                } else {
                    format!("Step {} — add {}", i + 1, adds[i - 1])
                },
                table: report::html_table(&report::param_rows(&st.fit, &unit))
                    + &format!(
                        "<pre>{}</pre>",
                        report::tau_table(&st.fit, &st.assessment, &unit)
                    ),
                verdict: report::verdict(&st.fit, &st.assessment),
                diagnosis: Some(st.diagnosis.clone()),
                step: (i > 0).then(|| report::step_line(&steps[i - 1])),
                svg,
            });
        }
        let physics = last
            .fit
            .effects()
            .iter()
            .chain(last.diagnosis.missing.iter())
            .map(|e| (e.name().to_string(), e.physics().to_string()))
            .collect::<Vec<_>>();
        let intro = format!(
            "{} samples at {} Hz ({}) from {shown}, column {} in {unit}. Overlapping Allan \
             deviation at octave τ with 68.3 % bounds (Greenhall EDF); weighted fit on the Allan \
             variance (weights ν/(2σ⁴)). Residual r = (measured − model)/(CI half-width).{}",
            y.len(),
            report::sig(rec.rate_hz, 6),
            duration(y.len() as f64 / rec.rate_hz),
            args.column,
            recal
                .as_ref()
                .map_or(String::new(), |r| format!(" {}", recal_text(r, &unit)))
        );
        std::fs::write(path, report::html(&title, &intro, &sections, &physics))
            .with_context(|| format!("writing {}", path.display()))?;
    }

    if args.json {
        let out = JsonOut {
            column: &args.column,
            unit: &unit,
            rate_hz: rec.rate_hz,
            samples: y.len(),
            terms: json_terms(&last.fit),
            chi2_dof: last.fit.chi2_dof(),
            rms_log_residual: last.assessment.rms_log_residual,
            diagnosis: JsonDiag {
                adequate: last.diagnosis.adequate,
                missing: last.diagnosis.missing.map(|e| e.name()),
                tau_range_s: last.diagnosis.tau_range.map(|(a, b)| [a, b]),
                explanation: last.diagnosis.explanation.clone(),
                evidence: last.diagnosis.evidence.clone(),
            },
            adev: last
                .fit
                .points
                .iter()
                .enumerate()
                .map(|(i, p)| JsonPoint {
                    tau_s: p.tau,
                    dev: p.dev,
                    lo: p.lo,
                    hi: p.hi,
                    model: last.fit.model_avar[i].max(0.0).sqrt(),
                    residual: last.assessment.residuals[i],
                    edf: p.edf,
                })
                .collect(),
            steps: steps
                .iter()
                .map(|s| JsonStep {
                    added: s.added.iter().map(|e| e.name()).collect(),
                    chi2_dof_before: s.before.chi2_dof,
                    chi2_dof_after: s.after.chi2_dof,
                    rms_log_residual_before: s.before.rms_log_residual,
                    rms_log_residual_after: s.after.rms_log_residual,
                    adequate_before: s.before.adequate,
                    adequate_after: s.after.adequate,
                })
                .collect(),
            recalibration: recal.as_ref().map(|r| JsonRecal {
                tolerance: r.tolerance,
                period_s: r.period_s,
                period_conservative_s: r.period_conservative_s,
                flicker_floor: r.floor,
                possible: r.possible,
            }),
        };
        println!("{}", serde_json::to_string(&out)?);
        return Ok(());
    }

    // Human report
    println!(
        "Noise-model fit of {} [{unit}] — {shown}: {} samples at {} Hz ({})",
        args.column,
        y.len(),
        report::sig(rec.rate_hz, 6),
        duration(y.len() as f64 / rec.rate_hz)
    );
    println!(
        "Overlapping Allan deviation at {} octave τ ({}–{} s), 68.3 % bounds from Greenhall's EDF{}.",
        points.len(),
        report::sig(points.first().map_or(0.0, |p| p.tau), 3),
        report::sig(points.last().map_or(0.0, |p| p.tau), 4),
        if skipped > 0 {
            format!("; {skipped} row(s) without an EDF left out")
        } else {
            String::new()
        },
    );
    for (i, st) in stages.iter().enumerate() {
        println!();
        if i == 0 {
            println!("== Model: {}", names(&st.fit.effects()));
        } else {
            println!("== Step {}: {}", i, report::step_line(&steps[i - 1]));
        }
        print!(
            "{}",
            report::text_table(&report::param_rows(&st.fit, &unit))
        );
        println!(
            "  χ²/dof = {} ({} dof), RMS log-residual = {}",
            report::sig(st.fit.chi2_dof(), 3),
            st.fit.dof,
            report::sig(st.assessment.rms_log_residual, 3)
        );
        println!("Verdict: {}", report::verdict(&st.fit, &st.assessment));
        let d = &st.diagnosis;
        println!(
            "Diagnosis{}: {}",
            d.missing
                .map_or(String::new(), |e| format!(" — missing effect: {e}")),
            d.explanation
        );
        for e in &d.evidence {
            println!("  - {e}");
        }
    }
    println!();
    println!("Per-τ comparison of the last model (r = (measured − model)/CI half-width; * outside the 68.3 % interval, ! significant):");
    print!("{}", report::tau_table(&last.fit, &last.assessment, &unit));
    if let Some(e) = last.diagnosis.missing {
        let mut cmd: Vec<String> = std::env::args().collect();
        cmd.push(format!("--add {e}"));
        println!();
        println!("Next: add the term and refit, e.g. `{}`", cmd.join(" "));
    }
    if let Some(r) = &recal {
        println!();
        println!("{}", recal_text(r, &unit));
    }
    Ok(())
}

fn recal_text(r: &practical::Recalibration, unit: &str) -> String {
    let tol = report::sig(r.tolerance, 3);
    if !r.possible {
        return format!(
            "Recalibration: a bias tolerance of {tol} {unit} is below the flicker floor \
             √2·0.664·B = {} {unit}; no recalibration period can meet it.",
            report::sig(r.floor, 3)
        );
    }
    let p = |v: Option<f64>| {
        v.map_or(
            "— no limit: neither K nor R is detected in this record".into(),
            duration,
        )
    };
    format!(
        "Recalibration: to keep the bias within {tol} {unit} (1σ, predicted drift √2·σ_BKR(T) \
         from B, K and R), recalibrate every {} (conservative, K and R at +1σ or their upper \
         bounds: {}); flicker floor {} {unit}.",
        p(r.period_s),
        p(r.period_conservative_s),
        report::sig(r.floor, 3)
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The real MPU-6050 recording (tomisuarez2/ImuCalibration, MIT; provenance in
    /// crates/allan/tests/data), gz in raw LSB → deg/s with 1/131.
    fn static_gz() -> (Vec<f64>, f64) {
        let args = InputArgs {
            file: PathBuf::from(concat!(
                env!("CARGO_MANIFEST_DIR"),
                "/../allan/tests/data/mpu6050_static_449s.csv"
            )),
            rate: Some(100.0),
            ignore_time: false,
            skip_lines: 4,
            scale: Some(0.0076336),
            unit: Some("deg/s".into()),
            rename: vec![],
        };
        let rec = input::load(&args, &["gz"]).unwrap();
        (rec.columns[0].values.clone(), rec.rate_hz)
    }

    #[test]
    fn real_static_recording_is_white_noise_dominated_and_adequate() {
        let (y, rate) = static_gz();
        let rows = allan::deviation(&y, 1.0 / rate, Stat::Oadev, &TauSet::Octave).unwrap();
        let (pts, _) = Point::from_rows(&rows);
        let st = stage(&pts, 1.0 / rate, &DEFAULT_TERMS, &y, rate).unwrap();
        assert!(st.assessment.adequate, "{}", st.diagnosis.explanation);
        assert_eq!(st.diagnosis.missing, None);
        // Independent check: AllanTools 2024.06 gives OADEV(τ = 1 s) = 1.2093 LSB = 9.231e-3 °/s
        // for gz (shared/reference/README.md). With white noise dominating at 1 s, N ≈ σ(1 s):
        // within 3 % (the fit uses every τ, not only 1 s).
        let n = st.fit.term(Effect::White).unwrap();
        assert!(n.detected);
        assert!(
            (n.amplitude() / 9.231e-3 - 1.0).abs() < 0.03,
            "N = {}",
            n.amplitude()
        );
        // 7.5 min cannot show the drift terms: they must be upper bounds, never negative
        for e in [Effect::RateRandomWalk, Effect::RateRamp] {
            let t = st.fit.term(e).unwrap();
            assert!(!t.detected && t.upper_bound().unwrap() > 0.0, "{e}");
        }
    }
}
