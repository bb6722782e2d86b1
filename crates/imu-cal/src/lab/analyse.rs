//! The lab's rule (module docs of `lab`): the robust fit, the verdict, the candidates and the
//! diagnosis, with [`CalLab`], the calibration problem as an instance of the project's lab
//! workflow.
use model_lab::{Edit, Lab, Summary};

use super::{
    model_names, reading, CalError, Candidate, Diagnosis, Effect, Fitted, Model, NestedTest,
    NoiseFloor, NotTried, Problem, Report, Step, Verdict, ALPHA_ADEQUATE, ALPHA_EFFECT,
    IDENTIFIED_FRACTION, MAX_OUTLIER_FRACTION, OUTLIER_SIGMAS, PRACTICAL_MARGIN, ROBUST_ROUNDS,
};
use crate::solve::{mad_sigma, median};
use allan::confidence::f_sf;

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

/// Per-item keep flags of a fit (an item is used when all its residuals are).
fn kept_items(p: &dyn Problem, f: &Fitted) -> Vec<bool> {
    let k = p.residuals_per_item();
    f.used.chunks(k).map(|c| c.iter().all(|u| *u)).collect()
}

/// Fit `model` with the robust loss of the module docs, from the problem's robust start (or
/// from every item when it has none).
pub fn robust_fit(
    p: &dyn Problem,
    model: &[Effect],
    floor: &NoiseFloor,
) -> Result<Fitted, CalError> {
    let keep = p.robust_start(model).unwrap_or_else(|| vec![true; p.n()]);
    let first = p.fit_items(model, &keep)?;
    robust_from(p, model, floor, first)
}

/// [`robust_fit`] from `first`, a least-squares fit of some of the items (those it used).
fn robust_from(
    p: &dyn Problem,
    model: &[Effect],
    floor: &NoiseFloor,
    first: Fitted,
) -> Result<Fitted, CalError> {
    let n = p.n();
    let per = p.residuals_per_item();
    let mut keep = kept_items(p, &first);
    let mut fit = first;
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
            // A misfit, not outliers: the plain fit of every item stands.
            return if keep.iter().all(|k| *k) {
                Ok(fit)
            } else {
                p.fit_items(model, &vec![true; n])
            };
        }
        if next == keep {
            return Ok(fit);
        }
        keep = next;
        fit = p.fit_items(model, &keep)?;
    }
    // The last set stands, said so (an alternation between two sets of items, each the
    // other's outliers, is the usual cause).
    let note = format!(
        "the outlier rejection for the {} model {} did not settle in {ROBUST_ROUNDS} refits: the \
         fit is the last one's",
        p.sensor(),
        model_names(model)
    );
    fit.not_converged = Some(match fit.not_converged.take() {
        Some(lm) => format!("{note}; {lm}"),
        None => note,
    });
    Ok(fit)
}

/// The parameters that `fitted` does not determine (module docs, 3): those whose σ is not
/// finite or exceeds [`IDENTIFIED_FRACTION`] of their plausible half-range, each with its σ
/// and range.
fn unidentified(p: &dyn Problem, fitted: &Fitted) -> Vec<String> {
    let unit = p.unit();
    fitted
        .params
        .named_values()
        .into_iter()
        .zip(fitted.sigma.values())
        .filter_map(|((name, _), s)| {
            let range = p.plausible_range(&name, &fitted.params)?;
            let ok = s.is_finite() && s <= IDENTIFIED_FRACTION * range;
            (!ok).then(|| {
                let u = match name.split(['.', '[']).next().unwrap_or("") {
                    "offset" | "bias" | "hard_iron" | "field" => format!(" {unit}"),
                    "soft_iron_2d" if name.ends_with(".r") || name.ends_with(".q") => {
                        format!(" {unit}")
                    }
                    _ if name.contains("deg") => "°".to_string(),
                    _ => String::new(),
                };
                if s.is_finite() {
                    let s = if (1e-3..1e4).contains(&s) {
                        format!("{s:.4}")
                    } else {
                        format!("{s:.3e}")
                    };
                    format!("{name} (σ {s}{u} against a plausible ±{range:.3}{u})")
                } else {
                    format!("{name} (no finite σ: the data leave it free)")
                }
            })
        })
        .collect()
}

/// The calibration lab over one problem: fits and judges models of named effects against the
/// noise floor of the data, and proposes the missing effect (module docs). It is the calibration
/// instance of [`model_lab::Lab`]: [`model_lab::walk`] on it adds the named effects one by one.
pub struct CalLab<'a> {
    problem: &'a dyn Problem,
    floor: NoiseFloor,
}

impl<'a> CalLab<'a> {
    /// The lab over `problem`, with its noise floor estimated once.
    pub fn new(problem: &'a dyn Problem) -> CalLab<'a> {
        CalLab {
            floor: problem.noise_floor(),
            problem,
        }
    }

    /// The problem.
    pub fn problem(&self) -> &'a dyn Problem {
        self.problem
    }

    /// Fit `model` (checked against the sensor's effects) with the robust loss and judge it.
    pub fn fit(&self, model: &[Effect]) -> Result<Model, CalError> {
        let model = normalise_model(self.problem, model)?;
        let fitted = robust_fit(self.problem, &model, &self.floor)?;
        Ok(self.judge(fitted, None))
    }

    /// The verdict on a fit (module docs, 3–4).
    fn judge(&self, fitted: Fitted, nested: Option<NestedTest>) -> Model {
        let floor = self.floor;
        let outliers = kept_items(self.problem, &fitted)
            .iter()
            .filter(|k| !**k)
            .count();
        let n = fitted.n_used() as f64;
        let k = fitted.n_params as f64;
        let dof = n - k;
        let unidentified = if k > 0.0 && dof < 1.0 {
            vec![format!(
                "every parameter: {} residuals for {} parameters leave no degree of freedom",
                fitted.n_used(),
                fitted.n_params
            )]
        } else {
            unidentified(self.problem, &fitted)
        };
        let underdetermined = !unidentified.is_empty();
        let dof1 = dof.max(1.0);
        let expected_rms = floor.sigma * (dof1 / n.max(1.0)).sqrt();
        let s2 = fitted.rss() / dof1;
        let rms = fitted.rms();
        let noiseless = floor.sigma == 0.0;
        let ratio = if noiseless {
            f64::NAN
        } else {
            s2 / (floor.sigma * floor.sigma)
        };
        let p_value = if noiseless || dof < 1.0 {
            f64::NAN
        } else {
            f_sf(ratio, dof1, floor.dof)
        };
        let fits_floor = if noiseless {
            rms < 1e-9
        } else {
            p_value >= ALPHA_ADEQUATE || rms <= PRACTICAL_MARGIN * expected_rms
        };
        // A fit that stopped short of its minimum is never called adequate: at the floor its
        // parameters are still not the least-squares ones.
        let converged = fitted.not_converged.is_none();
        let verdict = match (fits_floor, underdetermined || !converged) {
            (true, false) => Verdict::Adequate,
            (true, true) => Verdict::Underdetermined,
            (false, _) => Verdict::NotAdequate,
        };
        Model {
            fitted,
            floor,
            expected_rms,
            ratio,
            p_value,
            fits_floor,
            underdetermined,
            unidentified,
            verdict,
            outliers,
            nested,
        }
    }

    /// The workflow's summary of a model (module docs: `chi2_dof` is `s²/σ²`).
    pub fn summary_of(&self, m: &Model) -> Summary {
        Summary {
            chi2_dof: m.ratio,
            rms_residual: m.fitted.rms(),
            rms_unit: self.problem.unit().to_string(),
            adequate: m.adequate(),
            params: m.fitted.n_params,
        }
    }

    /// Every effect of the sensor not in `cur`: the ones identifiable from these data and
    /// supported by their evidence are added in turn, refitted and tested (module docs, 5); the
    /// others are returned with the reason they were not tried. Candidates come in the lab's
    /// order of preference: admissible first, then by decreasing F.
    pub fn examine(&self, cur: &Model) -> Result<(Vec<Candidate>, Vec<NotTried>), CalError> {
        let p = self.problem;
        let model = &cur.fitted.model;
        let keep = kept_items(p, &cur.fitted);
        let all_kept = keep.iter().all(|k| *k);
        let mut cands: Vec<Candidate> = Vec::new();
        let mut not_tried = Vec::new();
        let mut skip = |effect: Effect, reason: String| not_tried.push(NotTried { effect, reason });
        let before = self.summary_of(cur);
        for &e in p.effects() {
            if model.contains(&e) {
                continue;
            }
            if let Err(why) = p.identifiable(model, e) {
                skip(e, why);
                continue;
            }
            let evidence = match p.evidence(&cur.fitted, e) {
                Some(Err(why)) => {
                    skip(e, why);
                    continue;
                }
                Some(Ok(text)) => Some(text),
                None => None,
            };
            let mut m1 = model.clone();
            m1.push(e);
            m1.sort();
            // The nested test compares both models on the items the current one kept.
            let same = match p.fit_items(&m1, &keep) {
                Ok(f) => f,
                Err(err) => {
                    skip(e, err.to_string());
                    continue;
                }
            };
            let dp = same.n_params.saturating_sub(cur.fitted.n_params).max(1);
            let dof_1 = same.dof();
            if dof_1 < 1.0 {
                skip(
                    e,
                    format!(
                        "{} residuals leave no degree of freedom for {} parameters",
                        same.n_used(),
                        same.n_params
                    ),
                );
                continue;
            }
            let f =
                ((cur.fitted.rss() - same.rss()) / dp as f64) / (same.rss() / dof_1).max(1e-300);
            let pv = f_sf(f, dp as f64, dof_1);
            let nested = NestedTest {
                f,
                extra_params: dp,
                dof: dof_1,
                p_value: pv,
            };
            // The candidate model is fitted with the robust loss on its own.
            let refit = if all_kept {
                robust_from(p, &m1, &self.floor, same)
            } else {
                robust_fit(p, &m1, &self.floor)
            };
            let refit = match refit {
                Ok(f) => f,
                Err(err) => {
                    skip(e, err.to_string());
                    continue;
                }
            };
            let next = self.judge(refit, Some(nested));
            let significant = pv < ALPHA_EFFECT;
            let admissible = significant && !cur.fits_floor;
            let test = format!(
                "F = {f:.1} for {dp} extra parameters, p = {pv:.2e}{}",
                if significant {
                    String::new()
                } else {
                    format!(" (not significant: p ≥ {ALPHA_EFFECT})")
                }
            );
            let reason = [
                evidence,
                Some(test),
                (significant && !admissible)
                    .then(|| "the residual is already at the noise floor".to_string()),
            ]
            .into_iter()
            .flatten()
            .collect::<Vec<_>>()
            .join("; ");
            let summary = self.summary_of(&next);
            cands.push(Candidate {
                edit: Edit {
                    add: vec![e],
                    remove: vec![],
                },
                delta: before.chi2_dof - summary.chi2_dof,
                extra_params: dp as i64,
                p_value: pv,
                admissible,
                reason,
                reading: reading(e, &next.fitted.params, &next.fitted.sigma, p.unit()),
                summary,
                model: next,
            });
        }
        let f_of = |c: &Candidate| {
            c.model.nested.map_or(f64::NEG_INFINITY, |t| {
                if t.f.is_nan() {
                    f64::NEG_INFINITY
                } else {
                    t.f
                }
            })
        };
        // Stable: among equal F the sensor's order of effects stands.
        cands.sort_by(|a, b| {
            b.admissible
                .cmp(&a.admissible)
                .then(f_of(b).total_cmp(&f_of(a)))
        });
        Ok((cands, not_tried))
    }

    /// The verdict on a model in words with numbers and units.
    fn verdict_text(&self, m: &Model) -> String {
        let p = self.problem;
        let unit = p.unit();
        let rms = m.fitted.rms();
        let excluded = if m.outliers > 0 {
            format!(
                "{} {} beyond {OUTLIER_SIGMAS}σ excluded as outliers; ",
                m.outliers,
                p.items()
            )
        } else {
            String::new()
        };
        let verdict = if m.floor.sigma == 0.0 {
            format!(
                "{excluded}residual RMS {rms:.4} {unit}, and the data show no noise at all (noise \
                 floor exactly 0 {unit}: every {} residual of a complete model would be 0); {}",
                p.basis(),
                if m.fits_floor {
                    "the model reproduces them exactly".to_string()
                } else {
                    "so any residual is a misfit".to_string()
                }
            )
        } else {
            format!(
                "{excluded}residual RMS {rms:.4} {unit} vs noise floor {:.4} {unit} expected for a \
                 complete model ({} {} residuals, {} fitted parameters; noise from {}); {}",
                m.expected_rms,
                m.fitted.n_used(),
                p.basis(),
                m.fitted.n_params,
                m.floor.method,
                if m.p_value.is_finite() {
                    format!("P(F ≥ {:.2}) = {:.3}", m.ratio, m.p_value)
                } else {
                    "no degree of freedom left to test".to_string()
                }
            )
        };
        let mut out = verdict;
        if m.underdetermined {
            out += &format!(
                " (and the data do not determine {})",
                m.unidentified.join(", ")
            );
        }
        if let Some(why) = &m.fitted.not_converged {
            out += &format!(" (warning: {why})");
        }
        out
    }

    /// The lab's report on a model: its candidates, the diagnosis in words and the step.
    pub fn report(&self, m: Model) -> Result<Report, CalError> {
        let (candidates, not_tried) = self.examine(&m)?;
        let p = self.problem;
        let unit = p.unit();
        let verdict = self.verdict_text(&m);
        let best = candidates.iter().find(|c| c.admissible);
        let explanation = match (m.verdict, best) {
            (Verdict::Underdetermined, _) if !m.underdetermined => format!(
                "underdetermined: the residual is at the noise floor, but the fit did not reach \
                 its minimum, so its parameters are not the least-squares ones ({verdict})."
            ),
            (Verdict::Underdetermined, _) => format!(
                "underdetermined: the residual is at the noise floor, but the data do not \
                 determine every parameter ({verdict}). Record {}.",
                if m.fitted.dof() < 1.0 {
                    format!("more than {} {}", m.fitted.n_params, p.items())
                } else {
                    format!(
                        "{} that excite {}",
                        p.items(),
                        if m.unidentified.len() == 1 {
                            "it"
                        } else {
                            "them"
                        }
                    )
                }
            ),
            (Verdict::Adequate, _) => format!("adequate: {verdict}."),
            (Verdict::NotAdequate, Some(c)) => {
                let e = c.edit.add[0];
                format!(
                    "not adequate: {verdict}. Adding '{}' lowers the residual RMS {:.4} → {:.4} \
                     {unit}, the most significant of the candidates: {}. Physically: {}.",
                    e.name(),
                    m.fitted.rms(),
                    c.summary.rms_residual,
                    c.reason,
                    e.physics_for(p.sensor())
                )
            }
            (Verdict::NotAdequate, None) => {
                let tried: Vec<String> = candidates
                    .iter()
                    .map(|c| format!("{} (p = {:.2e})", c.edit.add[0].name(), c.p_value))
                    .chain(
                        not_tried
                            .iter()
                            .map(|n| format!("{} (not tried: {})", n.effect.name(), n.reason)),
                    )
                    .collect();
                format!(
                    "not adequate: {verdict}. No effect of the catalogue gives a significant \
                     drop{}; the excess is something the {} models do not contain (nonlinearity, \
                     motion during the poses, time-varying disturbances, timing skew) or a noise \
                     floor underestimated by correlated noise.",
                    if tried.is_empty() {
                        String::new()
                    } else {
                        format!(" ({})", tried.join(", "))
                    },
                    p.sensor()
                )
            }
        };
        let step = best.map(|c| Step::of(self.summary_of(&m), c));
        let missing = best.map(|c| c.edit.add[0]);
        Ok(Report {
            model: m,
            diagnosis: Diagnosis {
                missing,
                explanation,
                candidates,
                not_tried,
            },
            step,
        })
    }
}

impl Lab for CalLab<'_> {
    type Effect = Effect;
    type Model = Model;
    type Error = CalError;

    fn summary(&self, m: &Model) -> Summary {
        self.summary_of(m)
    }

    fn candidates(&self, m: &Model) -> Result<Vec<Candidate>, CalError> {
        Ok(self.examine(m)?.0)
    }
}

/// Run the lab on a problem and a model (module docs): the model's fit, verdict, candidates and
/// the step that adds the missing effect.
pub fn analyse(p: &dyn Problem, model: &[Effect]) -> Result<Report, CalError> {
    let lab = CalLab::new(p);
    let m = lab.fit(model)?;
    lab.report(m)
}
