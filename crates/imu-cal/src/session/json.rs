//! The JSON object of a calibration session (`imu-lab calibrate --json`,
//! `pico_imu.Calibration.to_dict()`): the report on the last model, the walk's steps and what was
//! excluded.
use serde::Serialize;

use super::{Loaded, Outcome};
use crate::lab::{Effect, Params};

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
    verdict: crate::lab::Verdict,
    adequate: bool,
    underdetermined: bool,
    /// The parameters the data cannot identify (σ not small against their plausible range).
    unidentified: &'a [String],
    /// Why the fit stopped before its minimum (an iteration cap), when it did.
    not_converged: Option<&'a str>,
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
    /// The fitted model against the parts' datasheet bounds: `null` within them, else why
    /// `--out` and an upload would refuse it (or why it cannot be judged).
    implausible: Option<String>,
    /// The part the plausibility was judged for (the magnetometer's says when it was assumed).
    judged_part: String,
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
pub fn json_out(l: &Loaded, run: &Outcome) -> String {
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
        implausible: match super::plausibility(l, run) {
            Ok(why) => why,
            Err(why) => Some(why),
        },
        judged_part: super::judged_part(l),
        diagnosis: JsonDiagnosis {
            verdict: m.verdict,
            adequate: m.adequate(),
            underdetermined: m.underdetermined,
            unidentified: &m.unidentified,
            not_converged: m.fitted.not_converged.as_deref(),
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
    serde_json::to_string(&out).expect("the calibration's JSON serialises")
}

#[cfg(test)]
mod tests {
    use super::super::{outcome, Data};
    use super::*;
    use crate::mag::MagProblem;
    use crate::sentinel::Sentinels;
    use nalgebra::Vector3;

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
            mag_part: None,
        };
        let v: serde_json::Value = serde_json::from_str(&json_out(&l, &r)).unwrap();
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
        assert!(d["unidentified"].is_array() && d.get("not_converged").is_some());
        assert!(d["missing"].is_null() || d["missing"].is_string());
        assert!(v["residual_rms"].as_f64().unwrap() < 0.2);
    }
}
