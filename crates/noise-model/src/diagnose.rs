//! The diagnosis in words: what the model misses, where on the Allan curve, and the evidence.
use crate::assess::{Assessment, TauRange};
use crate::effect::Effect;
use crate::fit::{Fit, FitError};
use crate::lab::{misfit_range, Model, NoiseLab};
use model_lab::Candidate;

/// The diagnosis of a model.
#[derive(Debug, Clone)]
pub struct Diagnosis {
    pub adequate: bool,
    /// The missing effect, when one is named (the first admissible candidate's addition).
    pub missing: Option<Effect>,
    /// Effects the named edit removes (a filter replacing white noise, temperature replacing a
    /// ramp).
    pub replaces: Vec<Effect>,
    /// The τ range [s] where the model fails, if any.
    pub tau_range: Option<(f64, f64)>,
    /// Plain-words explanation.
    pub explanation: String,
    /// Evidence lines.
    pub evidence: Vec<String>,
    /// All candidates tried, in the lab's order (admissible first).
    pub candidates: Vec<Candidate<Effect, Model>>,
}

/// Least-squares slope of ln σ against ln τ over points `first..=last` (widened to ≥ 2 points).
pub fn loglog_slope(taus: &[f64], devs: &[f64], first: usize, last: usize) -> Option<f64> {
    let n = taus.len();
    if n < 2 {
        return None;
    }
    let (mut a, mut b) = (first, last.min(n - 1));
    if a == b {
        if b + 1 < n {
            b += 1;
        } else {
            a = a.saturating_sub(1);
        }
    }
    let xs: Vec<f64> = (a..=b).map(|i| taus[i].ln()).collect();
    let ys: Vec<f64> = (a..=b).map(|i| devs[i].ln()).collect();
    let mx = xs.iter().sum::<f64>() / xs.len() as f64;
    let my = ys.iter().sum::<f64>() / ys.len() as f64;
    let sxy: f64 = xs.iter().zip(&ys).map(|(x, y)| (x - mx) * (y - my)).sum();
    let sxx: f64 = xs.iter().map(|x| (x - mx).powi(2)).sum();
    (sxx > 0.0).then(|| sxy / sxx)
}

fn fmt_s(t: f64) -> String {
    if t < 1.0 {
        format!("{:.3} s", t)
    } else if t < 100.0 {
        format!("{:.2} s", t)
    } else {
        format!("{:.0} s", t)
    }
}

/// A p-value for people: "p = 2.5e-41", or "p < 1e-300" when it underflows.
pub fn fmt_p(p: f64) -> String {
    if p > 0.0 {
        format!("p = {p:.1e}")
    } else {
        "p < 1e-300".into()
    }
}

/// Describe the residual shape of a fit (one line per range outside the interval).
pub fn residual_evidence(fit: &Fit, a: &Assessment) -> Vec<String> {
    let taus: Vec<f64> = fit.points.iter().map(|p| p.tau).collect();
    let devs: Vec<f64> = fit.points.iter().map(|p| p.dev).collect();
    let mdev: Vec<f64> = fit
        .model_avar
        .iter()
        .map(|m| m.max(1e-300).sqrt())
        .collect();
    let ranges: &[TauRange] = if a.failing.is_empty() {
        &a.outside
    } else {
        &a.failing
    };
    ranges
        .iter()
        .map(|r| {
            let sm = loglog_slope(&taus, &devs, r.first, r.last);
            let sx = loglog_slope(&taus, &mdev, r.first, r.last);
            format!(
                "{}τ = {} – {}: measured σ {} the model by up to {:.1} CI half-widths (|z| up to \
                 {:.1}); log-log slope measured {} vs model {}",
                if a.failing.is_empty() {
                    "not significant: "
                } else {
                    ""
                },
                fmt_s(r.lo),
                fmt_s(r.hi),
                if r.sign > 0 { "above" } else { "below" },
                r.worst,
                r.worst_z,
                sm.map_or("n/a".into(), |s| format!("{s:+.2}")),
                sx.map_or("n/a".into(), |s| format!("{s:+.2}")),
            )
        })
        .collect()
}

/// Correlated parameter pairs (|ρ| > 0.9) with the combination the data do determine.
pub fn tradeoffs(fit: &Fit) -> Vec<String> {
    let mut out = Vec::new();
    let idx = &fit.param_index;
    let name = |a: usize| {
        let (k, i) = idx[a];
        let t = &fit.terms[k];
        if i == 0 {
            format!("{} {}²", t.effect, t.effect.amp_name())
        } else {
            format!("{} {}", t.effect, t.specs[i - 1].name)
        }
    };
    for a in 0..idx.len() {
        for b in a + 1..idx.len() {
            let r = fit.param_corr(a, b);
            if !(r.abs() > 0.9) || idx[a].1 != 0 || idx[b].1 != 0 {
                continue;
            }
            // the best-determined combination c_a + w·c_b: the eigenvector of the smaller
            // eigenvalue of the 2×2 covariance, scaled to a unit weight on c_a
            let c = &fit.param_cov;
            let (saa, sbb, sab) = (c[(a, a)], c[(b, b)], c[(a, b)]);
            let tr = saa + sbb;
            let det = saa * sbb - sab * sab;
            let lmin = tr / 2.0 - ((tr / 2.0).powi(2) - det).max(0.0).sqrt();
            let (va, vb) = if sab.abs() > 0.0 {
                (sab, lmin - saa)
            } else {
                (1.0, 0.0)
            };
            if va == 0.0 {
                continue;
            }
            let w = vb / va;
            let (ca, cb) = (fit.terms[idx[a].0].coef, fit.terms[idx[b].0].coef);
            let val = ca + w * cb;
            let sig = (saa + w * w * sbb + 2.0 * w * sab).max(0.0).sqrt();
            out.push(format!(
                "{} and {} trade off (correlation {:+.2}): separately they are loosely determined, \
                 but {} {:+.4e}·{} = {:.4e} ± {:.1e}",
                name(a),
                name(b),
                r,
                name(a),
                w,
                name(b),
                val,
                sig
            ));
        }
    }
    out
}

/// Diagnose a model: if it is not adequate, try the lab's candidates and name the missing effect.
pub fn diagnose(lab: &NoiseLab, m: &Model) -> Result<Diagnosis, FitError> {
    let mut evidence = Vec::new();
    if let Some(t) = lab.record.timing.as_ref().filter(|t| t.irregular()) {
        evidence.push(format!(
            "the timestamps are irregular — {}; spectral effects (sinusoids, Markov and filter \
             shapes) are not named from such data, since bursty reads and a mismatch between the \
             assumed and the true sample clock bend the short-τ Allan curve by themselves",
            t.describe()
        ));
    }
    if let Some((lsb, dev)) = lab.below_lsb() {
        evidence.push(format!(
            "the noise is below the data's LSB ({lsb:.4e}): the shortest τ's σ = {dev:.4e} is under \
             LSB/√12 = {:.4e}, so most samples sit on one level and rounding is not noise of its \
             own; the white term describes the rounded values, and the sensor's noise under them \
             is not resolved (a finer range or more bits would show it)",
            lsb / 12f64.sqrt()
        ));
    }
    let defects = lab.defect_texts();
    evidence.extend(defects.iter().cloned());
    evidence.extend(m.findings.iter().map(|f| f.text.clone()));
    evidence.extend(residual_evidence(&m.fit, &m.assessment));
    evidence.extend(tradeoffs(&m.fit));
    let candidates = lab.candidate_edits(m)?;
    let best = candidates.iter().find(|c| c.admissible);
    if m.adequate && best.is_none() {
        return Ok(Diagnosis {
            adequate: true,
            missing: None,
            replaces: Vec::new(),
            tau_range: None,
            explanation: format!(
                "The model describes the measurement: χ²/dof = {:.2} ({} with {} dof, from the \
                 estimates' own covariance), no τ where it leaves the confidence interval \
                 significantly (largest |z| = {:.1}, below the threshold {:.1}), and no step, \
                 temperature dependence, warm-up or drift in the time series. No effect is \
                 missing.",
                m.fit.chi2_dof(),
                fmt_p(m.assessment.p_value),
                m.fit.dof,
                m.assessment.largest_z(),
                m.assessment.threshold
            ),
            evidence,
            candidates,
        });
    }
    // A defect with no effect to name is the explanation; with one, the effect is named and the
    // defect said beside it (the model cannot be adequate while the defect is in the data).
    let defect_note = if defects.is_empty() {
        String::new()
    } else {
        format!(
            " The record also holds a defect no noise model describes, so the model cannot be \
             adequate while it is in the data: {}.",
            defects.join("; ")
        )
    };
    let explanation = match best {
        _ if !defects.is_empty() && best.is_none() => format!(
            "The record holds a defect no noise model describes: {}. {}",
            defects.join("; "),
            if m.assessment.adequate {
                format!(
                    "The Allan curve alone passes (χ²/dof = {:.2}, {}), which is what such a \
                     defect does: the model is not adequate while it is in the data.",
                    m.fit.chi2_dof(),
                    fmt_p(m.assessment.p_value)
                )
            } else {
                format!(
                    "The model does not describe the measurement (χ²/dof = {:.2}), and no \
                     effect of the vocabulary explains the misfit significantly.",
                    m.fit.chi2_dof()
                )
            }
        ),
        Some(c) => {
            let e = &c.edit.add[0];
            let others: Vec<String> = candidates
                .iter()
                .filter(|o| !std::ptr::eq(*o, c))
                .take(6)
                .map(|o| format!("{} ({})", o.edit, fmt_p(o.p_value)))
                .collect();
            format!(
                "{}The model misses {} effect{}: {}. With it χ²/dof goes {:.2} → {:.2} ({}; other \
                 candidates: {}) and the model is {}. Signature: {}. Physics: {}{defect_note}",
                if m.assessment.adequate && m.findings.is_empty() {
                    "The goodness-of-fit test alone passes, but a specific alternative fits \
                     significantly better. "
                } else {
                    ""
                },
                if e.kind() == crate::effect::Kind::Signal {
                    "a non-stationary"
                } else {
                    "an"
                },
                if c.edit.remove.is_empty() {
                    format!(" ({e})")
                } else {
                    format!(
                        " ({e}, in place of {})",
                        c.edit
                            .remove
                            .iter()
                            .map(|r| r.to_string())
                            .collect::<Vec<_>>()
                            .join(", ")
                    )
                },
                c.reading,
                m.fit.chi2_dof(),
                c.model.fit.chi2_dof(),
                fmt_p(c.p_value),
                if others.is_empty() {
                    "none".into()
                } else {
                    others.join(", ")
                },
                if c.model.adequate {
                    "adequate"
                } else {
                    "better but still not adequate — more than one effect may be missing"
                },
                e.signature(),
                e.physics()
            )
        }
        None if m.assessment.adequate && !m.findings.is_empty() => {
            // what is left is in the time series alone, and the criterion does not take it
            let refused: Vec<String> = candidates
                .iter()
                .filter(|c| {
                    c.edit
                        .add
                        .first()
                        .is_some_and(|e| e.kind() == crate::effect::Kind::Signal)
                })
                .map(|c| format!("{} ({}: {})", c.edit, fmt_p(c.p_value), c.reason))
                .collect();
            format!(
                "The model is adequate on the one criterion: the Allan curve passes (χ²/dof = \
                 {:.2}, {}), and what is left is in the time series alone: {}. Added to the \
                 model, {} — the record cannot tell {} from the model's own noise at this \
                 length. Nothing else is missing; a longer record or a repeated run decides.",
                m.fit.chi2_dof(),
                fmt_p(m.assessment.p_value),
                m.findings
                    .iter()
                    .map(|f| f.text.as_str())
                    .collect::<Vec<_>>()
                    .join("; "),
                if refused.is_empty() {
                    "it could not be refitted".to_string()
                } else {
                    format!("it does not lower the criterion: {}", refused.join(", "))
                },
                if m.findings.len() == 1 { "it" } else { "them" }
            )
        }
        None => {
            let blocked = lab.record.timing.as_ref().is_some_and(|t| t.irregular());
            format!(
                "The model does not describe the measurement (χ²/dof = {:.2}), and no effect of \
                 the vocabulary explains the misfit significantly{}. {}",
                m.fit.chi2_dof(),
                candidates
                    .first()
                    .map(|c| format!(
                        " (best candidate: {}, {}: {})",
                        c.edit,
                        fmt_p(c.p_value),
                        c.reason
                    ))
                    .unwrap_or_default(),
                if blocked {
                    "The timestamps are irregular (see the evidence): spectral effects are not \
                     named from such data; record with sample-clock timestamps to go further."
                } else {
                    "Look at the data rather than the model: glitches or saturated samples, motion \
                     of the bench, or a record too short for the longest τ bend the Allan curve in \
                     ways no effect of the vocabulary describes; a user-described effect \
                     (--effect FILE) can add one."
                }
            )
        }
    };
    Ok(Diagnosis {
        // the one criterion decides: a time-domain finding it refuses is said, not a veto
        adequate: best.is_none() && m.assessment.adequate && defects.is_empty(),
        missing: best.map(|c| c.edit.add[0].clone()),
        replaces: best.map(|c| c.edit.remove.clone()).unwrap_or_default(),
        tau_range: misfit_range(&m.assessment),
        explanation,
        evidence,
        candidates,
    })
}
