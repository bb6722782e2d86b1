//! The JSON object of a session (what `imu-lab fit --json` prints and `pico_imu.Fit.to_dict()`
//! returns): the last model's terms with every estimate, its verdict and diagnosis, the points,
//! the walk's steps, timing, correlations and the recalibration period.
use serde::Serialize;
use serde_json::{Map, Value};

use super::Session;
use crate::diagnose::tradeoffs;
use crate::lab::{reading, tau_range};
use crate::{Effect, Fit, Step};

/// One term of the last model: its parameters' values, σ and 68.3 % intervals by name.
#[derive(Serialize)]
pub struct JsonTerm {
    pub effect: String,
    pub params: Map<String, Value>,
    pub sigma: Map<String, Value>,
    pub interval: Map<String, Value>,
    pub detected: bool,
    pub upper_bound: Map<String, Value>,
    /// Estimated in the time domain or from the data's lattice (a known term of the Allan fit).
    pub known: bool,
    pub tau_range_s: Option<[f64; 2]>,
    pub reading: String,
}

#[derive(Serialize)]
pub struct JsonDiag {
    pub adequate: bool,
    pub missing: Option<String>,
    pub replaces: Vec<String>,
    pub tau_range_s: Option<[f64; 2]>,
    pub explanation: String,
    pub evidence: Vec<String>,
}

#[derive(Serialize)]
pub struct JsonPoint {
    pub tau_s: f64,
    pub dev: f64,
    pub lo: f64,
    pub hi: f64,
    pub model: f64,
    /// 1σ of `model` from the parameters' covariance (null where the model's variance is 0).
    pub model_sigma: f64,
    pub residual: f64,
    pub z: f64,
    pub edf: f64,
    pub edf_model: f64,
}

#[derive(Serialize)]
pub struct JsonStep {
    pub added: Vec<String>,
    pub removed: Vec<String>,
    pub reading: String,
    pub p_value: f64,
    pub chi2_dof_before: f64,
    pub chi2_dof_after: f64,
    pub rms_log_residual_before: f64,
    pub rms_log_residual_after: f64,
    pub adequate_before: bool,
    pub adequate_after: bool,
}

#[derive(Serialize)]
pub struct JsonTau {
    pub tau_s: f64,
    pub dev: f64,
}

#[derive(Serialize)]
pub struct JsonRecal {
    pub tolerance: f64,
    pub period_s: Option<f64>,
    pub period_conservative_s: Option<f64>,
    pub flicker_floor: f64,
    pub possible: bool,
}

#[derive(Serialize)]
pub struct JsonTiming {
    pub median_dt_s: f64,
    pub mean_dt_s: f64,
    pub p95_dt_s: f64,
    pub gaps: usize,
    pub missing_samples: u64,
    pub duplicates: usize,
    pub irregular: bool,
}

#[derive(Serialize)]
pub struct JsonCorr {
    pub a: String,
    pub b: String,
    pub correlation: f64,
}

/// The whole object, fields in the order printed.
#[derive(Serialize)]
pub struct JsonOut {
    pub column: String,
    pub unit: String,
    pub rate_hz: f64,
    pub samples: usize,
    pub terms: Vec<JsonTerm>,
    pub chi2_dof: f64,
    pub dof: f64,
    pub p_value: f64,
    pub rms_log_residual: f64,
    pub correlations: Vec<JsonCorr>,
    pub tradeoffs: Vec<String>,
    pub diagnosis: JsonDiag,
    pub adev: Vec<JsonPoint>,
    pub steps: Vec<JsonStep>,
    /// The Allan deviation of the record with the final model's time-domain signals removed.
    pub adev_compensated: Vec<JsonTau>,
    pub stop: Option<String>,
    pub timing: Option<JsonTiming>,
    pub resolution_lsb: Option<f64>,
    pub recalibration: Option<JsonRecal>,
}

/// A JSON number, or null for NaN and ±inf.
pub fn num(v: f64) -> Value {
    serde_json::Number::from_f64(v).map_or(Value::Null, Value::Number)
}

/// The terms of `f` with their estimates; `unit` is the column's.
pub fn json_terms(f: &Fit, unit: &str) -> Vec<JsonTerm> {
    f.terms
        .iter()
        .enumerate()
        .map(|(k, t)| {
            let (mut params, mut sigma, mut interval, mut ub) =
                (Map::new(), Map::new(), Map::new(), Map::new());
            for p in t.params() {
                params.insert(p.name.clone(), num(p.value));
                sigma.insert(p.name.clone(), num(p.sigma));
                interval.insert(
                    p.name.clone(),
                    Value::Array(vec![num(p.interval.0), num(p.interval.1)]),
                );
                if let Some(u) = p.upper_bound {
                    ub.insert(p.name.clone(), num(u));
                }
            }
            JsonTerm {
                effect: t.effect.name().to_string(),
                params,
                sigma,
                interval,
                detected: t.detected,
                upper_bound: ub,
                known: t.known,
                tau_range_s: tau_range(f, k).map(|(a, b)| [a, b]),
                reading: reading(f, &t.effect, unit),
            }
        })
        .collect()
}

/// The parameter pairs of `f` correlated beyond ±0.5.
pub fn correlations(f: &Fit) -> Vec<JsonCorr> {
    let name = |a: usize| {
        let (k, i) = f.param_index[a];
        let t = &f.terms[k];
        if i == 0 {
            format!("{}.{}", t.effect, t.effect.amp_name())
        } else {
            format!("{}.{}", t.effect, t.specs[i - 1].name)
        }
    };
    let mut out = Vec::new();
    for a in 0..f.param_index.len() {
        for b in a + 1..f.param_index.len() {
            let r = f.param_corr(a, b);
            if r.abs() > 0.5 {
                out.push(JsonCorr {
                    a: name(a),
                    b: name(b),
                    correlation: r,
                });
            }
        }
    }
    out
}

/// One step of the walk.
pub fn json_step(s: &Step<Effect>) -> JsonStep {
    JsonStep {
        added: s.edit.add.iter().map(|e| e.name().to_string()).collect(),
        removed: s.edit.remove.iter().map(|e| e.name().to_string()).collect(),
        reading: s.reading.clone(),
        p_value: s.p_value,
        chi2_dof_before: s.before.chi2_dof,
        chi2_dof_after: s.after.chi2_dof,
        rms_log_residual_before: s.before.rms_residual,
        rms_log_residual_after: s.after.rms_residual,
        adequate_before: s.before.adequate,
        adequate_after: s.after.adequate,
    }
}

impl Session {
    /// The last model, its diagnosis and the steps as one JSON object (`imu-lab fit --json`).
    pub fn json(&self) -> JsonOut {
        let last = self.last();
        let f = &last.model.fit;
        JsonOut {
            column: self.column.clone(),
            unit: self.unit.clone(),
            rate_hz: self.rate_hz,
            samples: self.samples,
            terms: json_terms(f, &self.unit),
            chi2_dof: f.chi2_dof(),
            dof: f.dof,
            p_value: last.model.assessment.p_value,
            rms_log_residual: last.model.assessment.rms_log_residual,
            correlations: correlations(f),
            tradeoffs: tradeoffs(f),
            diagnosis: JsonDiag {
                adequate: last.diagnosis.adequate,
                missing: last
                    .diagnosis
                    .missing
                    .as_ref()
                    .map(|e| e.name().to_string()),
                replaces: last
                    .diagnosis
                    .replaces
                    .iter()
                    .map(|e| e.name().to_string())
                    .collect(),
                tau_range_s: last.diagnosis.tau_range.map(|(a, b)| [a, b]),
                explanation: last.diagnosis.explanation.clone(),
                evidence: last.diagnosis.evidence.clone(),
            },
            adev: f
                .points
                .iter()
                .enumerate()
                .map(|(i, p)| JsonPoint {
                    tau_s: p.tau,
                    dev: p.dev,
                    lo: p.lo,
                    hi: p.hi,
                    model: f.model_avar[i].max(0.0).sqrt(),
                    model_sigma: f.model_dev_sigma(i),
                    residual: last.model.assessment.residuals[i],
                    z: last.model.assessment.z[i],
                    edf: p.edf,
                    edf_model: f.model_edf[i],
                })
                .collect(),
            steps: self.steps.iter().map(json_step).collect(),
            adev_compensated: last
                .compensated
                .iter()
                .map(|&(tau_s, dev)| JsonTau { tau_s, dev })
                .collect(),
            stop: self.stop.map(|s| s.to_string()),
            timing: self.timing.as_ref().map(|t| JsonTiming {
                median_dt_s: t.median_dt_s,
                mean_dt_s: t.mean_dt_s,
                p95_dt_s: t.p95_dt_s,
                gaps: t.gaps.len(),
                missing_samples: t.missing_samples(),
                duplicates: t.duplicates,
                irregular: t.irregular(),
            }),
            resolution_lsb: self.lsb,
            recalibration: self.recal.as_ref().map(|r| JsonRecal {
                tolerance: r.tolerance,
                period_s: r.period_s,
                period_conservative_s: r.period_conservative_s,
                flicker_floor: r.floor,
                possible: r.possible,
            }),
        }
    }

    /// The JSON object as text (one line, as `imu-lab fit --json` prints it).
    pub fn json_string(&self) -> String {
        serde_json::to_string(&self.json()).expect("the session's JSON serialises")
    }
}
