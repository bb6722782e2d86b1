//! The noise lab's HTML report of a session (`imu-lab fit --report` and `imu-lab serve`'s export):
//! one section per model with its figure, table, verdict and diagnosis, then the effects' physics.
use noise_model::practical;
use noise_model::session::{names, Session};

use super::{allan as plot, noise as report};

/// A duration in the largest unit that keeps it readable (s, min, h, days).
pub fn duration(s: f64) -> String {
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

/// The report's title: column, unit and the file's name.
pub fn report_title(s: &Session, file: &std::path::Path) -> String {
    let base_name = file.file_name().map_or(file.display().to_string(), |n| {
        n.to_string_lossy().into_owned()
    });
    format!("{} [{}] — {}", s.column, s.unit, base_name)
}

/// The self-contained HTML report of a session (`--report`, and `imu-lab serve`'s export): one
/// section per model with its figure, table, verdict and diagnosis, then the effects' physics.
/// `shown` names the input file in the introduction.
pub fn report_html(s: &Session, title: &str, shown: &str) -> String {
    let (stages, steps, unit) = (&s.stages, &s.steps, s.unit.as_str());
    let (samples, rate_hz, recal, stop) = (s.samples, s.rate_hz, s.recal.as_ref(), s.stop);
    let mut sections = Vec::new();
    for (i, st) in stages.iter().enumerate() {
        let svg = if i == 0 {
            plot::document(&[plot::figure(
                &st.model.fit,
                &st.model.assessment,
                st.diagnosis.adequate,
                &st.compensated,
                &names(&st.model.fit.effects()),
                unit,
                0.0,
            )])
        } else {
            let prev = &stages[i - 1];
            plot::document(&[
                plot::figure(
                    &prev.model.fit,
                    &prev.model.assessment,
                    prev.diagnosis.adequate,
                    &prev.compensated,
                    "before",
                    unit,
                    0.0,
                ),
                plot::figure(
                    &st.model.fit,
                    &st.model.assessment,
                    st.diagnosis.adequate,
                    &st.compensated,
                    &format!("after: {}", steps[i - 1].edit),
                    unit,
                    plot::W,
                ),
            ])
        };
        sections.push(report::Section {
            title: if i == 0 {
                format!("Step 0 — model: {}", names(&st.model.fit.effects()))
            } else {
                format!("Step {i} — {}", steps[i - 1].edit)
            },
            table: report::html_table(&report::param_rows(&st.model.fit, unit))
                + &format!(
                    "<pre>{}</pre>",
                    report::tau_table(&st.model.fit, &st.model.assessment, unit)
                ),
            verdict: report::verdict(&st.model.fit, &st.model.assessment, st.diagnosis.adequate),
            diagnosis: Some(st.diagnosis.clone()),
            step: (i > 0).then(|| report::step_line(&steps[i - 1])),
            svg,
        });
    }
    let last = stages.last().expect("one stage");
    let mut physics: Vec<(String, String)> = Vec::new();
    for e in last
        .model
        .fit
        .effects()
        .iter()
        .chain(last.diagnosis.missing.iter())
    {
        if !physics.iter().any(|(n, _)| n == e.name()) {
            physics.push((e.name().to_string(), e.physics().to_string()));
        }
    }
    let intro = format!(
        "{samples} samples at {} Hz ({}) from {shown}, column {} in {unit}. Overlapping Allan \
         deviation at octave τ with 68.3 % bounds; generalised least-squares fit on the Allan \
         variance with the estimates' covariance under the model; non-stationarity (steps, \
         temperature, warm-up) tested on the time series. Residual r = (measured − model)/(CI \
         half-width).{}{}",
        report::sig(rate_hz, 6),
        duration(samples as f64 / rate_hz),
        s.column,
        stop.map_or(String::new(), |s| format!(" Automatic walk: {s}.")),
        recal.map_or(String::new(), |r| format!(" {}", recal_text(r, unit)))
    );
    report::html(title, &intro, &sections, &physics)
}

/// The recalibration period's sentence (printed by `imu-lab fit` with a bias tolerance, and in the report).
pub fn recal_text(r: &practical::Recalibration, unit: &str) -> String {
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
         from B, K and R), recalibrate every {} (conservative, K and R at +1σ or their 95 % \
         upper ends: {}); flicker floor {} {unit}.",
        p(r.period_s),
        p(r.period_conservative_s),
        report::sig(r.floor, 3)
    )
}
