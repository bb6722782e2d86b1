//! The lab's rule (module docs of `lab`): the robust fit, the verdict, the candidates and the
//! step.
use super::{
    CalError, Candidate, Diagnosis, Effect, Fitted, NoiseFloor, Problem, Report, Step, Verdict,
    ALPHA_ADEQUATE, ALPHA_EFFECT, DOF_PER_PARAMETER, MAX_OUTLIER_FRACTION, OUTLIER_SIGMAS,
    PRACTICAL_MARGIN, ROBUST_ROUNDS,
};
use crate::solve::{f_sf, mad_sigma, median};

/// Normalise a model: sorted, deduplicated, and checked against the sensor's effects.
pub fn normalise_model(p: &dyn Problem, model: &[Effect]) -> Result<Vec<Effect>, CalError> {
    let mut m: Vec<Effect> = model.to_vec();
    m.sort();
    m.dedup();
    for e in &m {
        if !p.effects().contains(e) {
            return Err(CalError::Input(format!(
                "effect '{}' does not apply to the {} (its effects: {})",
                e.name(),
                p.sensor(),
                p.effects()
                    .iter()
                    .map(|e| e.name())
                    .collect::<Vec<_>>()
                    .join(", ")
            )));
        }
    }
    Ok(m)
}

fn model_names(model: &[Effect]) -> String {
    if model.is_empty() {
        "(no correction)".into()
    } else {
        model.iter().map(|e| e.name()).collect::<Vec<_>>().join("+")
    }
}

/// Per-item keep flags of a fit (an item is used when all its residuals are).
fn kept_items(p: &dyn Problem, f: &Fitted) -> Vec<bool> {
    let k = p.residuals_per_item();
    f.used.chunks(k).map(|c| c.iter().all(|u| *u)).collect()
}

/// Fit `model` with the robust loss of the module docs.
pub fn robust_fit(
    p: &dyn Problem,
    model: &[Effect],
    floor: &NoiseFloor,
) -> Result<Fitted, CalError> {
    let n = p.n();
    let per = p.residuals_per_item();
    let all = vec![true; n];
    let first = p.fit_items(model, &all)?;
    let mut keep = all.clone();
    let mut fit = first.clone();
    for _ in 0..ROBUST_ROUNDS {
        let used: Vec<f64> = fit.used_residuals().collect();
        let centre = median(&used);
        let sigma = mad_sigma(&used).max(floor.sigma);
        if !(sigma > 0.0 && sigma.is_finite() && centre.is_finite()) {
            return Ok(fit);
        }
        let cut = OUTLIER_SIGMAS * sigma;
        let next: Vec<bool> = fit
            .residuals
            .chunks(per)
            .map(|c| c.iter().all(|r| (r - centre).abs() <= cut))
            .collect();
        let out = next.iter().filter(|k| !**k).count();
        if out as f64 > MAX_OUTLIER_FRACTION * n as f64 {
            // A misfit, not outliers: the plain fit stands.
            return Ok(first);
        }
        if next == keep {
            return Ok(fit);
        }
        keep = next;
        fit = p.fit_items(model, &keep)?;
    }
    Err(CalError::Fit(format!(
        "outlier rejection for the {} model {} did not settle in {ROBUST_ROUNDS} refits",
        p.sensor(),
        model_names(model)
    )))
}

/// Run the lab on a problem and a model (module docs).
pub fn analyse(p: &dyn Problem, model: &[Effect]) -> Result<Report, CalError> {
    let model = normalise_model(p, model)?;
    let floor = p.noise_floor();
    let fitted = robust_fit(p, &model, &floor)?;
    let keep = kept_items(p, &fitted);
    let outliers = keep.iter().filter(|k| !**k).count();
    let n = fitted.n_used() as f64;
    let k = fitted.n_params as f64;
    let dof = n - k;
    let underdetermined = k > 0.0 && dof < DOF_PER_PARAMETER * k;
    let dof1 = dof.max(1.0);
    let expected_rms = floor.sigma * (dof1 / n.max(1.0)).sqrt();
    let s2 = fitted.rss() / dof1;
    let rms = fitted.rms();
    let unit = p.unit();
    let noiseless = floor.sigma == 0.0;
    let ratio = if noiseless {
        f64::NAN
    } else {
        s2 / (floor.sigma * floor.sigma)
    };
    let p_adequate = if noiseless || dof < 1.0 {
        f64::NAN
    } else {
        f_sf(ratio, dof1, floor.dof)
    };
    let fits_floor = if noiseless {
        rms < 1e-9
    } else {
        p_adequate >= ALPHA_ADEQUATE || rms <= PRACTICAL_MARGIN * expected_rms
    };
    let adequate = fits_floor && !underdetermined;

    let mut candidates = Vec::new();
    let mut best: Option<(f64, Effect)> = None;
    for &e in p.effects() {
        if model.contains(&e) {
            continue;
        }
        let skip = |why: String| Candidate {
            effect: e,
            residual_rms: None,
            f: None,
            p_value: None,
            extra_params: 0,
            skipped: Some(why),
            evidence: None,
        };
        if let Err(why) = p.identifiable(&model, e) {
            candidates.push(skip(why));
            continue;
        }
        let evidence = match p.evidence(&fitted, e) {
            Some(Err(why)) => {
                candidates.push(skip(why));
                continue;
            }
            Some(Ok(text)) => Some(text),
            None => None,
        };
        let mut m1 = model.clone();
        m1.push(e);
        m1.sort();
        let f1 = match p.fit_items(&m1, &keep) {
            Ok(f) => f,
            Err(err) => {
                candidates.push(skip(err.to_string()));
                continue;
            }
        };
        let dp = f1.n_params.saturating_sub(fitted.n_params).max(1) as f64;
        let dof_1 = f1.dof();
        if dof_1 < 1.0 {
            candidates.push(skip(format!(
                "{} residuals leave no degree of freedom for {} parameters",
                f1.n_used(),
                f1.n_params
            )));
            continue;
        }
        let f = ((fitted.rss() - f1.rss()) / dp) / (f1.rss() / dof_1).max(1e-300);
        let pv = f_sf(f, dp, dof_1);
        candidates.push(Candidate {
            effect: e,
            residual_rms: Some(f1.rms()),
            f: Some(f),
            p_value: Some(pv),
            extra_params: dp as usize,
            skipped: None,
            evidence,
        });
        if pv < ALPHA_EFFECT && best.is_none_or(|(bf, _)| f > bf) {
            best = Some((f, e));
        }
    }

    let excluded = if outliers > 0 {
        format!(
            "{outliers} {} beyond {OUTLIER_SIGMAS}σ excluded as outliers; ",
            p.items()
        )
    } else {
        String::new()
    };
    let verdict = if noiseless {
        format!(
            "{excluded}residual RMS {rms:.4} {unit}, and the data show no noise at all (noise \
             floor exactly 0 {unit}: every {} residual of a complete model would be 0); {}",
            p.basis(),
            if fits_floor {
                "the model reproduces them exactly".to_string()
            } else {
                "so any residual is a misfit".to_string()
            }
        )
    } else {
        format!(
            "{excluded}residual RMS {rms:.4} {unit} vs noise floor {:.4} {unit} expected for a \
             complete model ({} {} residuals, {} fitted parameters; noise from {}); {}",
            expected_rms,
            fitted.n_used(),
            p.basis(),
            fitted.n_params,
            floor.method,
            if p_adequate.is_finite() {
                format!("P(F ≥ {ratio:.2}) = {p_adequate:.3}")
            } else {
                "no degree of freedom left to test".to_string()
            }
        )
    };
    let need = (k * (1.0 + DOF_PER_PARAMETER)).ceil();
    let thin = if underdetermined {
        format!(
            " (and {} residuals for {} parameters leave {} degrees of freedom, fewer than \
             {DOF_PER_PARAMETER} per parameter)",
            fitted.n_used(),
            fitted.n_params,
            dof.max(0.0)
        )
    } else {
        String::new()
    };
    let verdict = format!("{verdict}{thin}");
    let (missing, explanation, step) = if underdetermined && fits_floor {
        (
            None,
            format!(
                "underdetermined: the residual is at the noise floor, but {} residuals for {} \
                 parameters leave {} degrees of freedom, fewer than {DOF_PER_PARAMETER} per \
                 parameter, so it cannot tell an adequate model from an overfitted one \
                 ({verdict}). Record at least {need} {} to judge this model.",
                fitted.n_used(),
                fitted.n_params,
                dof.max(0.0),
                p.items()
            ),
            None,
        )
    } else if adequate {
        (None, format!("adequate: {verdict}."), None)
    } else if let Some((f, e)) = best {
        let mut m1 = model.clone();
        m1.push(e);
        m1.sort();
        let f1 = robust_fit(p, &m1, &floor)?;
        let c = candidates
            .iter()
            .find(|c| c.effect == e)
            .expect("candidate");
        let text = format!(
            "not adequate: {verdict}. Adding '{}' lowers the residual RMS {rms:.4} → {:.4} {unit} \
             (F = {f:.1} for {} extra parameters, p = {:.2e}), the most significant of the \
             candidates{}. Physically: {}.",
            e.name(),
            c.residual_rms.unwrap_or(f64::NAN),
            c.extra_params,
            c.p_value.unwrap_or(f64::NAN),
            c.evidence
                .as_ref()
                .map_or(String::new(), |ev| format!("; {ev}")),
            e.physics_for(p.sensor())
        );
        let out1 = kept_items(p, &f1).iter().filter(|k| !**k).count();
        let step = Step {
            added: e,
            model: f1.model.clone(),
            residual_rms_before: rms,
            residual_rms_after: f1.rms(),
            params: f1.params.clone(),
            sigma: f1.sigma.clone(),
            outliers: out1,
        };
        (Some(e), text, Some(step))
    } else {
        let tried: Vec<String> = candidates
            .iter()
            .map(|c| match (&c.skipped, c.p_value) {
                (Some(why), _) => format!("{} (not tried: {why})", c.effect.name()),
                (None, Some(pv)) => format!("{} (p = {pv:.2e})", c.effect.name()),
                _ => c.effect.name().to_string(),
            })
            .collect();
        (
            None,
            format!(
                "not adequate: {verdict}. No effect of the catalogue gives a significant drop{}; \
                 the excess is something the {} models do not contain (nonlinearity, motion \
                 during the poses, time-varying disturbances, timing skew) or a noise floor \
                 underestimated by correlated noise.",
                if tried.is_empty() {
                    String::new()
                } else {
                    format!(" ({})", tried.join(", "))
                },
                p.sensor()
            ),
            None,
        )
    };
    Ok(Report {
        fitted,
        floor,
        expected_rms,
        diagnosis: Diagnosis {
            verdict: if adequate {
                Verdict::Adequate
            } else if underdetermined && fits_floor {
                Verdict::Underdetermined
            } else {
                Verdict::NotAdequate
            },
            adequate,
            underdetermined,
            outliers,
            missing,
            explanation,
            p_value: p_adequate,
            candidates,
        },
        step,
    })
}
