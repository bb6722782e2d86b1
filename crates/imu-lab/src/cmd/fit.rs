//! `imu-lab fit`: fit a noise model to a column's overlapping Allan deviation, judge it against
//! the estimates' own covariance and the record's time series, name the missing effect, and
//! show the step when it is added — by hand (`--add`) or automatically (`--auto`).
use std::path::PathBuf;
use std::sync::Arc;

use anyhow::{anyhow, bail, Context, Result};
use noise_model::session::{self, names, Session, Stage};
use noise_model::user::UserEffect;
use noise_model::{Effect, Step};

use crate::input::{self, InputArgs};
use crate::render::session_report::{duration, recal_text, report_html, report_title};
use crate::render::{allan as plot, noise as report};

/// Arguments of `imu-lab fit`.
#[derive(clap::Args, Debug)]
pub struct Args {
    #[command(flatten)]
    pub input: InputArgs,
    /// Column to analyse (gx gy gz, ax ay az, …).
    #[arg(long)]
    pub column: String,
    /// Model terms, comma-separated (default: the five power-law terms of Jaime et al., eqs.
    /// 10–14, plus the data's resolution when its values sit on a lattice coarse enough to
    /// change the fit). Effects: quantization, white, flicker, rate_random_walk, rate_ramp,
    /// markov, sinusoid, resolution, lowpass, lowpass2, boxcar, bartlett, resonance, and user
    /// effects by their file's name (drift, bias_step and a warm-up come from --auto).
    #[arg(long, value_delimiter = ',')]
    pub terms: Vec<String>,
    /// Add an effect to the model and show the step before → after (repeatable, comma-separated).
    #[arg(long, value_delimiter = ',')]
    pub add: Vec<String>,
    /// Walk automatically: diagnose → add the named effect → refit, until the model is adequate
    /// or nothing helps, and print the step table.
    #[arg(long, conflicts_with = "add")]
    pub auto: bool,
    /// Most steps of `--auto`.
    #[arg(long, default_value_t = 6)]
    pub max_steps: usize,
    /// A user-described effect (TOML: its autocovariance or PSD as a formula of named parameters;
    /// see docs/noise-model.md). Repeatable. It becomes a candidate and may be named in --terms.
    #[arg(long = "effect")]
    pub effects: Vec<PathBuf>,
    /// Bias tolerance in the column's unit: print the recalibration period from B, K and R.
    #[arg(long)]
    pub tolerance: Option<f64>,
    /// Print one JSON object on stdout instead of the report.
    #[arg(long)]
    pub json: bool,
    /// Write the Allan plot (with the residual panel) as SVG or PNG (by the name's extension);
    /// before and after side by side when a step was taken.
    #[arg(long)]
    pub plot: Option<PathBuf>,
    /// Write a self-contained HTML report (one section per step).
    #[arg(long)]
    pub report: Option<PathBuf>,
}

fn load_user_effects(paths: &[PathBuf]) -> Result<Vec<Effect>> {
    paths
        .iter()
        .map(|p| {
            let text = std::fs::read_to_string(p)
                .with_context(|| format!("--effect {}: cannot read the file", p.display()))?;
            let u = UserEffect::parse(&text, &p.display().to_string())
                .map_err(|e| anyhow!("--effect {e}"))?;
            Ok(Effect::User(Arc::new(u)))
        })
        .collect()
}

/// `imu-lab fit`: read the column and build the lab, fit the start model and walk from it
/// (`--add` or `--auto`), analyse each model, then write the files and print the JSON or the
/// report.
pub fn run(args: Args) -> Result<()> {
    let opts = session::Options {
        terms: args.terms.clone(),
        add: args.add.clone(),
        auto: args.auto,
        max_steps: args.max_steps,
        user: Vec::new(),
        tolerance: args.tolerance,
        flags: session::Flags::CLI,
    };
    session::check_options(&opts).map_err(|e| anyhow!(e))?;
    let opts = session::Options {
        user: load_user_effects(&args.effects)?,
        ..opts
    };
    let rec = input::load_with(&args.input, &[&args.column], &["temp"])?;
    let shown = args.input.file.display().to_string();
    let series = rec
        .column(&args.column)
        .ok_or_else(|| anyhow!("{shown}: column {:?} missing", args.column))?;
    let label = format!("{shown}: column {:?}", args.column);
    let s = session::run(
        &session::Input {
            column: &args.column,
            unit: &series.unit,
            y: &series.values,
            rate_hz: rec.rate_hz,
            segments: &rec.segments,
            temp: rec.column("temp").map(|c| c.values.as_slice()),
            timing: rec.timing.as_ref(),
            label: &label,
        },
        &opts,
    )
    .map_err(|e| anyhow!(e))?;
    let out = Outcome {
        args: &args,
        shown,
        s,
    };
    out.write_files()?;
    if args.json {
        println!("{}", out.s.json_string());
    } else {
        out.print_text();
    }
    Ok(())
}

/// What `imu-lab fit` reports: the session and where its data came from.
struct Outcome<'a> {
    args: &'a Args,
    /// The input file as shown in messages.
    shown: String,
    s: Session,
}

impl Outcome<'_> {
    fn last(&self) -> &Stage {
        self.s.last()
    }

    /// The plot (--plot) and the HTML report (--report).
    fn write_files(&self) -> Result<()> {
        let args = self.args;
        let title = report_title(&self.s, &args.input.file);
        if let Some(path) = &args.plot {
            write_plot(path, &self.s.stages, &self.s.steps, &title, &self.s.unit)?;
        }
        if let Some(path) = &args.report {
            std::fs::write(path, report_html(&self.s, &title, &self.shown))
                .with_context(|| format!("writing {}", path.display()))?;
        }
        Ok(())
    }

    /// The human report on stdout.
    fn print_text(&self) {
        let (args, unit, shown) = (self.args, &self.s.unit, &self.shown);
        let (points, skipped, stages, steps) = (
            &self.s.points,
            self.s.skipped,
            &self.s.stages,
            &self.s.steps,
        );
        let last = self.last();
        println!(
            "Noise-model fit of {} [{unit}] — {shown}: {} samples at {} Hz ({})",
            args.column,
            self.s.samples,
            report::sig(self.s.rate_hz, 6),
            duration(self.s.samples as f64 / self.s.rate_hz)
        );
        println!(
            "Overlapping Allan deviation at {} octave τ ({}–{} s); generalised least squares with the \
             estimates' covariance under the model{}.",
            points.len(),
            report::sig(points.first().map_or(0.0, |p| p.tau), 3),
            report::sig(points.last().map_or(0.0, |p| p.tau), 4),
            if skipped > 0 {
                format!("; {skipped} row(s) without an EDF left out")
            } else {
                String::new()
            },
        );
        if let Some(t) = self
            .s
            .timing
            .as_ref()
            .filter(|t| t.irregular() || !t.gaps.is_empty())
        {
            println!("Timing: {}.", t.describe());
        }
        if let Some(l) = self.s.lsb {
            println!(
                "Resolution: the values sit on a lattice of {} {unit} (the data's LSB).",
                report::sig(l, 4)
            );
        }
        if args.auto {
            println!();
            println!("== Automatic walk: diagnose → add the named effect → refit");
            print!("{}", step_table(steps));
            println!(
                "Stop: {}.",
                self.s.stop.map_or(String::new(), |s| s.to_string())
            );
        }
        for (i, st) in stages.iter().enumerate() {
            if args.auto && i + 1 != stages.len() && i != 0 {
                continue;
            }
            println!();
            if i == 0 {
                println!("== Model: {}", names(&st.model.fit.effects()));
            } else if args.auto {
                println!("== Final model: {}", names(&st.model.fit.effects()));
            } else {
                println!("== Step {}: {}", i, report::step_line(&steps[i - 1]));
            }
            print_stage(st, unit);
        }
        println!();
        println!("Per-τ comparison of the last model (r = (measured − model)/CI half-width; * outside the 68.3 % interval, ! significant):");
        print!(
            "{}",
            report::tau_table(&last.model.fit, &last.model.assessment, unit)
        );
        if let Some(e) = &last.diagnosis.missing {
            if !args.auto {
                let mut cmd: Vec<String> = std::env::args().collect();
                cmd.push(format!("--add {e}"));
                println!();
                println!(
                    "Next: add the term and refit, e.g. `{}` (or walk with --auto)",
                    cmd.join(" ")
                );
            }
        }
        if let Some(r) = &self.s.recal {
            println!();
            println!("{}", recal_text(r, unit));
        }
    }
}

/// The step table of a walk.
pub fn step_table(steps: &[Step<Effect>]) -> String {
    crate::render::steps::table(steps, "χ²/dof", "RMS log-residual")
}

fn print_stage(st: &Stage, unit: &str) {
    let m = &st.model;
    print!("{}", report::text_table(&report::param_rows(&m.fit, unit)));
    println!(
        "  χ²/dof = {} ({} dof), RMS log-residual = {}",
        report::sig(m.fit.chi2_dof(), 3),
        m.fit.dof,
        report::sig(m.assessment.rms_log_residual, 3)
    );
    println!(
        "Verdict: {}",
        report::verdict(&m.fit, &m.assessment, st.diagnosis.adequate)
    );
    let d = &st.diagnosis;
    println!(
        "Diagnosis{}: {}",
        d.missing
            .as_ref()
            .map_or(String::new(), |e| format!(" — missing effect: {e}")),
        d.explanation
    );
    for e in &d.evidence {
        println!("  - {e}");
    }
}

fn write_plot(
    path: &std::path::Path,
    stages: &[Stage],
    steps: &[Step<Effect>],
    title: &str,
    unit: &str,
) -> Result<()> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    if !matches!(ext.as_deref(), Some("svg") | Some("png")) {
        bail!("--plot {}: give a .svg or .png name", path.display());
    }
    let last = stages.last().expect("one stage");
    let figs: Vec<String> = if stages.len() == 1 {
        vec![plot::figure(
            &last.model.fit,
            &last.model.assessment,
            last.diagnosis.adequate,
            &last.compensated,
            title,
            unit,
            0.0,
        )]
    } else {
        let first = &stages[0];
        vec![
            plot::figure(
                &first.model.fit,
                &first.model.assessment,
                first.diagnosis.adequate,
                &first.compensated,
                &format!("before: {}", names(&first.model.fit.effects())),
                unit,
                0.0,
            ),
            plot::figure(
                &last.model.fit,
                &last.model.assessment,
                last.diagnosis.adequate,
                &last.compensated,
                &format!(
                    "after: {}",
                    steps
                        .iter()
                        .map(|s| s.edit.to_string())
                        .collect::<Vec<_>>()
                        .join(", ")
                ),
                unit,
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
    std::fs::write(path, bytes).with_context(|| format!("writing {}", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use allan::{Stat, TauSet};
    use noise_model::{diagnose, NoiseLab, Point, Record};

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
        let lab = NoiseLab::new(Record {
            y: &y,
            unit: "deg/s",
            tau0: 1.0 / rate,
            segments: vec![(0, y.len() as u64)],
            temp: None,
            timing: None,
            points: pts,
            user_effects: vec![],
        })
        .unwrap();
        // the counts × 0.0076336 sit on a lattice: resolution is known
        assert!((lab.lsb.unwrap() - 0.0076336).abs() < 1e-9, "{:?}", lab.lsb);
        let m = lab.fit(&lab.default_specs()).unwrap();
        let d = diagnose(&lab, &m).unwrap();
        assert!(d.adequate, "{}", d.explanation);
        // Independent check: AllanTools 2024.06 gives OADEV(τ = 1 s) = 1.2093 LSB = 9.231e-3 °/s
        // for gz (shared/reference/README.md). With white noise dominating at 1 s, N ≈ σ(1 s):
        // within 3 % (the fit uses every τ, not only 1 s).
        let n = m.fit.term(&Effect::White).unwrap();
        assert!(n.detected);
        assert!(
            (n.amplitude() / 9.231e-3 - 1.0).abs() < 0.03,
            "N = {}",
            n.amplitude()
        );
        // 7.5 min cannot show a rate random walk: reported with its interval, not detected
        let t = m.fit.term(&Effect::RateRandomWalk).unwrap();
        assert!(!t.detected && t.amplitude_interval().1 > 0.0);
    }
}
