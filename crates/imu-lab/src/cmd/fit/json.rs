//! The JSON object of `imu-lab fit --json` (and the report's numbers): the terms with every
//! estimate, the verdict, the points, the walk's steps, timing, correlations.
use super::*;

#[derive(Serialize)]
pub(super) struct JsonTerm {
    pub(super) effect: String,
    pub(super) params: Map<String, Value>,
    pub(super) sigma: Map<String, Value>,
    pub(super) interval: Map<String, Value>,
    pub(super) detected: bool,
    pub(super) upper_bound: Map<String, Value>,
    /// Estimated in the time domain or from the data's lattice (a known term of the Allan fit).
    pub(super) known: bool,
    pub(super) tau_range_s: Option<[f64; 2]>,
    pub(super) reading: String,
}

#[derive(Serialize)]
pub(super) struct JsonDiag {
    pub(super) adequate: bool,
    pub(super) missing: Option<String>,
    pub(super) replaces: Vec<String>,
    pub(super) tau_range_s: Option<[f64; 2]>,
    pub(super) explanation: String,
    pub(super) evidence: Vec<String>,
}

#[derive(Serialize)]
pub(super) struct JsonPoint {
    pub(super) tau_s: f64,
    pub(super) dev: f64,
    pub(super) lo: f64,
    pub(super) hi: f64,
    pub(super) model: f64,
    pub(super) residual: f64,
    pub(super) z: f64,
    pub(super) edf: f64,
    pub(super) edf_model: f64,
}

#[derive(Serialize)]
pub(super) struct JsonStep {
    pub(super) added: Vec<String>,
    pub(super) removed: Vec<String>,
    pub(super) reading: String,
    pub(super) p_value: f64,
    pub(super) chi2_dof_before: f64,
    pub(super) chi2_dof_after: f64,
    pub(super) rms_log_residual_before: f64,
    pub(super) rms_log_residual_after: f64,
    pub(super) adequate_before: bool,
    pub(super) adequate_after: bool,
}

#[derive(Serialize)]
pub(super) struct JsonTau {
    pub(super) tau_s: f64,
    pub(super) dev: f64,
}

#[derive(Serialize)]
pub(super) struct JsonRecal {
    pub(super) tolerance: f64,
    pub(super) period_s: Option<f64>,
    pub(super) period_conservative_s: Option<f64>,
    pub(super) flicker_floor: f64,
    pub(super) possible: bool,
}

#[derive(Serialize)]
pub(super) struct JsonTiming {
    pub(super) median_dt_s: f64,
    pub(super) mean_dt_s: f64,
    pub(super) p95_dt_s: f64,
    pub(super) gaps: usize,
    pub(super) missing_samples: u64,
    pub(super) duplicates: usize,
    pub(super) irregular: bool,
}

#[derive(Serialize)]
pub(super) struct JsonCorr {
    pub(super) a: String,
    pub(super) b: String,
    pub(super) correlation: f64,
}

#[derive(Serialize)]
pub(super) struct JsonOut<'a> {
    pub(super) column: &'a str,
    pub(super) unit: &'a str,
    pub(super) rate_hz: f64,
    pub(super) samples: usize,
    pub(super) terms: Vec<JsonTerm>,
    pub(super) chi2_dof: f64,
    pub(super) dof: f64,
    pub(super) p_value: f64,
    pub(super) rms_log_residual: f64,
    pub(super) correlations: Vec<JsonCorr>,
    pub(super) tradeoffs: Vec<String>,
    pub(super) diagnosis: JsonDiag,
    pub(super) adev: Vec<JsonPoint>,
    pub(super) steps: Vec<JsonStep>,
    /// The Allan deviation of the record with the final model's time-domain signals removed.
    pub(super) adev_compensated: Vec<JsonTau>,
    pub(super) stop: Option<String>,
    pub(super) timing: Option<JsonTiming>,
    pub(super) resolution_lsb: Option<f64>,
    pub(super) recalibration: Option<JsonRecal>,
}

pub(super) fn num(v: f64) -> Value {
    serde_json::Number::from_f64(v).map_or(Value::Null, Value::Number)
}

pub(super) fn json_terms(f: &Fit) -> Vec<JsonTerm> {
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
                reading: reading(f, &t.effect),
            }
        })
        .collect()
}

pub(super) fn correlations(f: &Fit) -> Vec<JsonCorr> {
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

/// B, K, R with their conservative values (+1σ, or the 95 % upper end when not detected).
pub(super) fn drift_terms(f: &Fit) -> (f64, f64, f64, f64, f64) {
    let get = |e: Effect| -> (f64, f64) {
        match f.term(&e) {
            Some(t) if t.detected => (t.amplitude(), t.amplitude() + t.amplitude_sigma()),
            Some(t) => (0.0, t.amplitude_interval().1),
            None => (0.0, 0.0),
        }
    };
    let (b, _) = get(Effect::Flicker);
    let (k, kc) = get(Effect::RateRandomWalk);
    let (r, rc) = get(Effect::RateRamp);
    (b, k, r, kc, rc)
}

pub(super) fn duration(s: f64) -> String {
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

pub(super) fn json_step(s: &Step<Effect>) -> JsonStep {
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
