//! Rendering of noise-model fits for people: parameter tables with canonical and conventional
//! units (text and HTML), the step line, and the offline HTML report.
// SVG/HTML fragments are raw multi-line strings that end in a newline.
#![allow(clippy::write_with_newline)]

use super::esc;
pub use super::sig;
use noise_model::{Assessment, Diagnosis, Effect, Fit, Standing, Step, UnitFamily};
use std::fmt::Write;

fn pm(v: f64, s: f64) -> String {
    if s.is_finite() && s > 0.0 {
        format!("{} ± {}", sig(v, 4), sig(s, 2))
    } else {
        sig(v, 4)
    }
}

/// One row of the parameter table.
pub struct ParamRow {
    pub effect: String,
    pub param: String,
    pub canonical: String,
    pub conventional: String,
    pub status: String,
}

/// The parameter rows of a fit for a channel in `unit`: every estimate with its 1σ, whether or
/// not the data detect it (then its 95 % interval says how far it may go).
pub fn param_rows(fit: &Fit, unit: &str) -> Vec<ParamRow> {
    let fam = UnitFamily::of(unit);
    let warm_up = fit.ctx.temp_avar.is_none();
    let mut out = Vec::new();
    for t in &fit.terms {
        let e = &t.effect;
        let disp = e.amp_display(fam, warm_up);
        let cu = e.amp_unit(unit, warm_up);
        let (a, s) = (t.amplitude(), t.amplitude_sigma());
        let (lo, hi) = t.amplitude_interval();
        let canon = format!("{} {cu}", pm(a, s));
        let conv = disp.as_ref().map_or(String::new(), |d| {
            format!("{} {}", pm(a * d.factor, s * d.factor), d.unit)
        });
        let status = if t.known {
            match e {
                Effect::Resolution => "from the data's lattice".to_string(),
                _ => format!(
                    "{}time-domain estimate; a non-stationarity, not noise",
                    if t.detected { "" } else { "not detected; " }
                ),
            }
        } else if t.detected && *e == Effect::RateRamp {
            "detected: a drift of this record (non-stationary), not a noise of the sensor".into()
        } else if t.detected {
            "detected".into()
        } else {
            format!(
                "not detected: 95 % in [{}, {}] {cu}",
                sig(lo, 2),
                sig(hi, 2)
            )
        };
        out.push(ParamRow {
            effect: e.name().into(),
            param: e.amp_name().into(),
            canonical: canon,
            conventional: conv,
            status,
        });
        for (i, spec) in t.specs.iter().enumerate() {
            let (v, s) = (
                t.theta.get(i).copied().unwrap_or(f64::NAN),
                t.theta_sigma.get(i).copied().unwrap_or(f64::NAN),
            );
            let conv = match (e, spec.name.as_str()) {
                (Effect::Markov, "tau_c") => format!(
                    "peak at τ ≈ {} s; f_c = 1/(2π τ_c) = {} Hz",
                    sig(1.89 * v, 3),
                    sig(1.0 / (2.0 * std::f64::consts::PI * v), 3)
                ),
                (Effect::Sinusoid, _) => format!("period {} s", sig(1.0 / v, 4)),
                (Effect::Resonance, "f0_hz") => format!("period {} s", sig(1.0 / v, 4)),
                (Effect::Resonance, "zeta") => format!("Q = 1/(2ζ) = {}", sig(0.5 / v, 3)),
                (Effect::Lowpass | Effect::Lowpass2, _) => {
                    format!(
                        "τ_c = 1/(2π f_c) = {} s",
                        sig(1.0 / (2.0 * std::f64::consts::PI * v), 3)
                    )
                }
                (Effect::Boxcar | Effect::Bartlett, _) => format!("{} s", sig(v * fit.tau0, 3)),
                _ => String::new(),
            };
            out.push(ParamRow {
                effect: String::new(),
                param: spec.name.clone(),
                canonical: format!("{} {}", pm(v, s), spec.unit),
                conventional: conv,
                status: String::new(),
            });
        }
    }
    out
}

/// The rows as an aligned text table.
pub fn text_table(rows: &[ParamRow]) -> String {
    let head = [
        "effect",
        "param",
        "value ± 1σ (canonical)",
        "conventional",
        "status",
    ];
    let cells: Vec<[&str; 5]> = rows
        .iter()
        .map(|r| {
            [
                r.effect.as_str(),
                r.param.as_str(),
                r.canonical.as_str(),
                r.conventional.as_str(),
                r.status.as_str(),
            ]
        })
        .collect();
    let mut w = head.map(|h| h.chars().count());
    for c in &cells {
        for i in 0..5 {
            w[i] = w[i].max(c[i].chars().count());
        }
    }
    let line = |c: [&str; 5]| {
        let mut s = String::from("  ");
        for i in 0..5 {
            s += c[i];
            s += &" ".repeat(w[i] - c[i].chars().count() + 2);
        }
        s.trim_end().to_string() + "\n"
    };
    let mut s = line(head);
    s += &format!("  {}\n", "-".repeat(w.iter().sum::<usize>() + 8));
    for c in cells {
        s += &line(c);
    }
    s
}

/// The rows as an HTML table.
pub fn html_table(rows: &[ParamRow]) -> String {
    let mut s = String::from(
        "<table><tr><th>effect</th><th>param</th><th>value ± 1σ (canonical)</th><th>conventional</th><th>status</th></tr>\n",
    );
    for r in rows {
        let _ = writeln!(
            s,
            "<tr><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>",
            esc(&r.effect),
            esc(&r.param),
            esc(&r.canonical),
            esc(&r.conventional),
            esc(&r.status)
        );
    }
    s + "</table>\n"
}

/// A per-τ table: τ, measured σ and its 68.3 % bounds, the model and its 1σ (all in the
/// data's unit, named in the σ column's head), residual, EDF.
pub fn tau_table(fit: &Fit, a: &Assessment, unit: &str) -> String {
    let mut s = format!(
        "  {:>10}  {:>13}  {:>13}  {:>13}  {:>13}  {:>13}  {:>7}  {:>6}\n",
        "τ [s]",
        format!("σ [{unit}]"),
        format!("lo [{unit}]"),
        format!("hi [{unit}]"),
        format!("model [{unit}]"),
        format!("± 1σ [{unit}]"),
        "r",
        "edf"
    );
    for (i, p) in fit.points.iter().enumerate() {
        let _ = writeln!(
            s,
            "  {:>10}  {:>13.4e}  {:>13.4e}  {:>13.4e}  {:>13.4e}  {:>13.2e}  {:>7.2}{} {:>6}",
            sig(p.tau, 4),
            p.dev,
            p.lo,
            p.hi,
            fit.model_avar[i].max(0.0).sqrt(),
            fit.model_dev_sigma(i),
            a.residuals[i],
            match a.standing(i) {
                Standing::Failing => "!",
                Standing::Outside => "*",
                Standing::Fine => " ",
            },
            sig(p.edf, 3)
        );
    }
    s
}

/// "+ effect: χ²/dof a → b, RMS log-residual c → d, adequate no → yes".
pub fn step_line(st: &Step<Effect>) -> String {
    let yn = |b: bool| if b { "yes" } else { "no" };
    format!(
        "{}: χ²/dof {} → {}, RMS log-residual {} → {}, adequate {} → {}",
        st.edit,
        sig(st.before.chi2_dof, 3),
        sig(st.after.chi2_dof, 3),
        sig(st.before.rms_residual, 3),
        sig(st.after.rms_residual, 3),
        yn(st.before.adequate),
        yn(st.after.adequate)
    )
}

pub use noise_model::session::verdict;

/// One section of the HTML report.
pub struct Section {
    pub title: String,
    pub table: String,
    pub verdict: String,
    pub diagnosis: Option<Diagnosis>,
    pub step: Option<String>,
    /// The figure(s), side by side.
    pub svg: String,
}

/// A self-contained HTML page (inline CSS and SVG, no external resources).
pub fn html(
    title: &str,
    intro: &str,
    sections: &[Section],
    physics: &[(String, String)],
) -> String {
    let mut s = format!(
        r#"<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>{t}</title>
<style>
body {{ font-family: sans-serif; max-width: 1320px; margin: 2em auto; color: #222; line-height: 1.45; }}
table {{ border-collapse: collapse; margin: 0.8em 0; }}
td, th {{ border: 1px solid #bbb; padding: 3px 8px; text-align: left; font-size: 0.92em; }}
th {{ background: #f0f0f0; }}
section {{ border-top: 2px solid #888; margin-top: 2em; padding-top: 0.5em; }}
.ok {{ color: #060; font-weight: bold; }} .bad {{ color: #a00; font-weight: bold; }}
.fig {{ overflow-x: auto; }} code {{ background: #f4f4f4; padding: 1px 4px; }}
</style></head><body>
<h1>{t}</h1>
<p>{intro}</p>
"#,
        t = esc(title),
        intro = esc(intro)
    );
    for sec in sections {
        let cls = if sec.verdict.starts_with("ADEQUATE") {
            "ok"
        } else {
            "bad"
        };
        let _ = write!(
            s,
            "<section><h2>{}</h2>\n{}<p class=\"{cls}\">{}</p>\n",
            esc(&sec.title),
            sec.step.as_ref().map_or(String::new(), |st| format!(
                "<p><b>Step:</b> {}</p>\n",
                esc(st)
            )),
            esc(&sec.verdict)
        );
        s += &sec.table;
        if let Some(d) = &sec.diagnosis {
            let _ = write!(
                s,
                "<p><b>Diagnosis{}:</b> {}</p>\n",
                d.missing
                    .as_ref()
                    .map_or(String::new(), |e| format!(" — missing effect: {e}")),
                esc(&d.explanation)
            );
            if !d.evidence.is_empty() {
                s += "<ul>\n";
                for e in &d.evidence {
                    let _ = writeln!(s, "<li>{}</li>", esc(e));
                }
                s += "</ul>\n";
            }
        }
        let _ = write!(s, "<div class=\"fig\">{}</div></section>\n", sec.svg);
    }
    if !physics.is_empty() {
        s += "<section><h2>The effects in these models</h2>\n";
        for (name, text) in physics {
            let _ = writeln!(s, "<p><b>{}</b> — {}</p>", esc(name), esc(text));
        }
        s += "</section>\n";
    }
    s + "</body></html>\n"
}
