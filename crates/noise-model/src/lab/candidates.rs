//! Candidate edits of a model: the non-stationarity findings first, then the Allan-curve
//! candidates, each refitted and tested (nested χ², the time-domain likelihood ratio), gated by
//! their evidence and ranked by the penalised criterion.
use super::*;

/// One try of an edit: the specs to refit, the edit, and why it is tried (empty when the Allan
/// curve alone suggests it).
type Try = (Vec<TermSpec>, Edit<Effect>, String);

impl<'a> NoiseLab<'a> {
    /// Candidate edits of a model, refitted and tested, best first: the non-stationarity
    /// findings when one of them is admissible, else the Allan-curve candidates ranked, followed
    /// by the refused findings.
    pub fn candidate_edits(&self, cur: &Model) -> Result<Vec<Candidate<Effect, Model>>, FitError> {
        // 1. non-stationarity findings
        let found = self.finding_candidates(cur);
        if found.first().is_some_and(|c| c.admissible) {
            return Ok(found);
        }
        let refused_findings = found;
        // 2. Allan-curve candidates
        let cur_crit = Self::criterion(cur);
        let mut cands: Vec<Candidate<Effect, Model>> = self
            .allan_tries(cur)
            .into_iter()
            .filter_map(|t| self.test_try(cur, cur_crit, t))
            .collect();
        Self::rank(&mut cands);
        cands.extend(refused_findings);
        Ok(cands)
    }

    /// The non-stationarity findings of `cur` as candidates, judged by the same criterion as
    /// every other candidate: a finding is admissible only when the refit lowers it, and the
    /// findings compete with each other (one warm-up against the steps that would stand in for
    /// it). Admissible first, then by the criterion.
    fn finding_candidates(&self, cur: &Model) -> Vec<Candidate<Effect, Model>> {
        let have: Vec<Effect> = cur.specs.iter().map(|s| s.effect.clone()).collect();
        let cur_crit = Self::criterion(cur);
        let mut found: Vec<Candidate<Effect, Model>> = Vec::new();
        for f in &cur.findings {
            let mut specs = cur.specs.clone();
            specs.push(f.spec.clone());
            // a drift holds its own ramp: it replaces the model's
            let drift = matches!(f.effect, Effect::Drift { .. });
            let mut edits: Vec<(Vec<TermSpec>, Edit<Effect>)> = Vec::new();
            if !drift || !have.contains(&Effect::RateRamp) {
                edits.push((
                    specs.clone(),
                    Edit {
                        add: vec![f.effect.clone()],
                        remove: vec![],
                    },
                ));
            }
            // a physical cause found in the time domain replaces the ramp that stood in for it
            if (drift || f.effect == Effect::Temperature) && have.contains(&Effect::RateRamp) {
                let s2: Vec<TermSpec> = specs
                    .iter()
                    .filter(|s| s.effect != Effect::RateRamp)
                    .cloned()
                    .collect();
                edits.push((
                    s2,
                    Edit {
                        add: vec![f.effect.clone()],
                        remove: vec![Effect::RateRamp],
                    },
                ));
            }
            let mut best: Option<Candidate<Effect, Model>> = None;
            for (specs, edit) in edits {
                let Ok(m) = self.fit(&specs) else { continue };
                let mut c = self.candidate(cur, m, edit, f.p_value, false, f.text.clone());
                let k = c.model.fit.terms.iter().rposition(|t| t.effect == f.effect);
                let present = k.is_some_and(|k| c.model.fit.terms[k].coef > 0.0);
                let better = Self::criterion(&c.model) < cur_crit;
                c.admissible = present && better;
                if !present {
                    c.reason = format!("{}its amplitude is zero in the refit", prefix(&c.reason));
                } else if !better {
                    c.reason = format!(
                        "{}the refit does not lower the criterion (Δ = {:+.1})",
                        prefix(&c.reason),
                        Self::criterion(&c.model) - cur_crit
                    );
                }
                // the replacement goes first unless the ramp still stands beside the cause
                // found: its own likelihood ratio in the time domain, given the cause and the
                // noise model, is significant
                let replaces = !c.edit.remove.is_empty();
                let take = match &best {
                    None => true,
                    Some(b) if c.admissible != b.admissible => c.admissible,
                    Some(b) => replaces && !self.ramp_significant(&b.model),
                };
                if take {
                    best = Some(c);
                }
            }
            if let Some(b) = best {
                found.push(b);
            }
        }
        found.sort_by(|a, b| {
            b.admissible
                .cmp(&a.admissible)
                .then(Self::criterion(&a.model).total_cmp(&Self::criterion(&b.model)))
        });
        found
    }

    /// The Allan-curve tries for `cur`: the terms it lacks (power laws, the data's resolution,
    /// and unless the spectrum is blocked a Markov term, a resonance at an unfitted band of the
    /// spectrum, the strongest unfitted spectral line, the filters in place of white noise and
    /// the user's effects), each as its specs, its edit and why it is tried.
    fn allan_tries(&self, cur: &Model) -> Vec<Try> {
        let have: Vec<Effect> = cur.specs.iter().map(|s| s.effect.clone()).collect();
        let mut tries: Vec<Try> = Vec::new();
        for e in [
            Effect::Quantization,
            Effect::White,
            Effect::Flicker,
            Effect::RateRandomWalk,
            Effect::RateRamp,
        ] {
            // a drift holds its own ramp
            let drift = have.iter().any(|h| matches!(h, Effect::Drift { .. }));
            let held = have.contains(&e) || (drift && e == Effect::RateRamp);
            if !held {
                tries.push(added(cur, e.clone(), TermSpec::new(e), String::new()));
            }
        }
        if !have.contains(&Effect::Resolution) {
            if let Some(s) = self.resolution_spec() {
                tries.push(added(
                    cur,
                    Effect::Resolution,
                    s,
                    format!(
                        "the values sit on a lattice of {:.4e}",
                        self.lsb.unwrap_or(0.0)
                    ),
                ));
            }
        }
        let blocked = self.spectral_blocked();
        if !blocked {
            let n_markov = have.iter().filter(|e| **e == Effect::Markov).count();
            if n_markov < 3 {
                tries.push(added(
                    cur,
                    Effect::Markov,
                    TermSpec::new(Effect::Markov),
                    String::new(),
                ));
            }
            tries.extend(self.band_try(cur));
            tries.extend(self.line_try(cur));
            for e in [
                Effect::Lowpass,
                Effect::Lowpass2,
                Effect::Boxcar,
                Effect::Bartlett,
            ] {
                if have.contains(&e) {
                    continue;
                }
                let mut s: Vec<TermSpec> = cur
                    .specs
                    .iter()
                    .filter(|s| s.effect != Effect::White)
                    .cloned()
                    .collect();
                s.push(TermSpec::new(e.clone()));
                let remove = if have.contains(&Effect::White) {
                    vec![Effect::White]
                } else {
                    vec![]
                };
                tries.push((
                    s,
                    Edit {
                        add: vec![e],
                        remove,
                    },
                    String::new(),
                ));
            }
            for u in &self.record.user_effects {
                if !have.contains(u) {
                    tries.push(added(
                        cur,
                        u.clone(),
                        TermSpec::new(u.clone()),
                        String::new(),
                    ));
                }
            }
        }
        tries
    }

    /// A resonance at a band of excess power in the Welch PSD that the model does not fit yet.
    fn band_try(&self, cur: &Model) -> Option<Try> {
        // a band of excess power in the Welch PSD not yet fitted: a resonance there; the
        // spectrum resolves the band far better than the octave Allan points, so it pins f0
        // and ζ, as the periodogram pins a sinusoid's frequency
        let (seg, t0) = (self.longest_segment(), self.record.tau0);
        let b = welch(seg, 1.0 / t0, default_segment(seg.len()))
            .and_then(|p| crate::psd::find_band(&p, t0))
            .filter(|b| {
                !cur.fit.terms.iter().any(|t| {
                    t.effect == Effect::Resonance
                        && t.theta0().is_some_and(|f| (f / b.f0_hz - 1.0).abs() < 0.25)
                })
            })?;
        let why = format!(
            "the spectrum has a band of excess power at {:.2} Hz, ζ ≈ {:.2} \
             (Δχ² = {:.0}, peak {:.1}× the background)",
            b.f0_hz, b.zeta, b.delta_chi2, b.peak_ratio
        );
        let spec = TermSpec {
            theta: Some(vec![b.f0_hz, b.zeta]),
            theta_fixed: true,
            theta_sigma: Some(vec![b.f0_sigma, b.zeta_sigma]),
            ..TermSpec::new(Effect::Resonance)
        };
        Some(added(cur, Effect::Resonance, spec, why))
    }

    /// A sinusoid at the strongest spectral line the model does not fit yet.
    fn line_try(&self, cur: &Model) -> Option<Try> {
        // the strongest spectral line not yet in the model
        let fitted: Vec<f64> = cur
            .fit
            .terms
            .iter()
            .filter(|t| t.effect == Effect::Sinusoid)
            .filter_map(|t| t.theta0())
            .collect();
        let df_w = self.periodogram_df;
        let l = self.lines.iter().find(|l| {
            !fitted
                .iter()
                .any(|&f| (f - l.freq_hz).abs() < 4.0 * df_w.max(1e-12) + 0.02 * f)
        })?;
        // the whole-record periodogram pins the frequency
        let y = self.longest_segment();
        let fs = 1.0 / self.record.tau0;
        let (f, sf) = match line_near(y, fs, l.freq_hz, 0.05) {
            Some(t) if t.p_value < P_CANDIDATE => (t.freq_hz, self.periodogram_df / 2.0),
            _ => (l.freq_hz, self.periodogram_df * 8.0),
        };
        Some(added(
            cur,
            Effect::Sinusoid,
            TermSpec {
                theta: Some(vec![f]),
                theta_fixed: true,
                theta_sigma: Some(vec![sf]),
                ..TermSpec::new(Effect::Sinusoid)
            },
            format!(
                "the spectrum has a line at {:.4} Hz, {:.0}× the local background \
                 (threshold {:.1}×)",
                l.freq_hz, l.ratio, l.threshold
            ),
        ))
    }

    /// One try refitted and tested against `cur` (criterion `cur_crit`): two likelihood-ratio
    /// tests, its admissibility and, when refused, why. `None` when the refit fails.
    fn test_try(
        &self,
        cur: &Model,
        cur_crit: f64,
        (specs, edit, why): Try,
    ) -> Option<Candidate<Effect, Model>> {
        let Ok(m) = self.fit(&specs) else {
            return None;
        };
        let extra = m.fit.n_params() as i64 - cur.fit.n_params() as i64;
        // two likelihood-ratio tests on the same data, Bonferroni-combined: the Allan points
        // (every τ) and the block differences in the time domain (long τ)
        let s = m.fit.chi2_dof().max(1.0);
        // An edit that adds no free parameter (a known term such as the data's resolution, a
        // filter in place of the white noise it shapes) is tested as if it spent one: a
        // change of the likelihood by a hair is no evidence, however many points agree.
        let lr_p = |delta: f64| chi2_sf(delta.max(0.0) / s, extra.max(1) as f64);
        let d_time = self.time_lr(cur, &m, &edit);
        let p = (2.0 * lr_p(cur.neg2ll - m.neg2ll).min(lr_p(d_time))).min(1.0);
        let mut c = self.candidate(cur, m, edit, p, false, why);
        let added_present = c.edit.add.iter().all(|e| {
            c.model
                .fit
                .terms
                .iter()
                .any(|t| t.effect == *e && t.coef > 0.0)
        });
        let better = Self::criterion(&c.model) < cur_crit;
        c.admissible = p < P_CANDIDATE && added_present && better;
        if !c.admissible {
            c.reason = if !added_present {
                format!("{}the refit puts its amplitude at zero", prefix(&c.reason))
            } else if p >= P_CANDIDATE {
                format!("{}not significant (p = {:.1e})", prefix(&c.reason), p)
            } else {
                format!(
                    "{}it does not lower the criterion (over-fitting)",
                    prefix(&c.reason)
                )
            };
        }
        Some(c)
    }

    /// The Allan-curve candidates ranked: the line gate (a spectral line that explains the
    /// misfit refuses the smooth shapes), admissible first, the explaining line first, then by
    /// the criterion; among equals the simplest first.
    fn rank(cands: &mut [Candidate<Effect, Model>]) {
        let line_explains = |c: &Candidate<Effect, Model>| {
            c.edit.add.contains(&Effect::Sinusoid) && c.p_value < P_CANDIDATE
        };
        // A narrow line in the periodogram is direct evidence: when the sinusoid at that line
        // explains the misfit, the smooth-spectrum shapes (Markov, filters) that would absorb it
        // are not named in its place; it comes first.
        if cands.iter().any(|c| line_explains(c) && c.admissible) {
            for c in cands.iter_mut() {
                let smooth = c.edit.add.iter().any(|e| {
                    *e == Effect::Markov || e.replaces_white() || matches!(e, Effect::User(_))
                });
                if smooth && c.admissible {
                    c.admissible = false;
                    c.reason =
                        "a spectral line explains the misfit; the sinusoid is named first".into();
                }
            }
        }
        cands.sort_by(|a, b| {
            b.admissible
                .cmp(&a.admissible)
                .then(line_explains(b).cmp(&line_explains(a)))
                .then(Self::criterion(&a.model).total_cmp(&Self::criterion(&b.model)))
        });
        Self::prefer_simplest_of_equals(cands);
    }

    /// Whether the model's rate ramp is significant in the time domain (its likelihood ratio
    /// among the model's signals, with the model's noise, at [`P_SIGNAL`]).
    fn ramp_significant(&self, m: &Model) -> bool {
        let signals: Vec<Signal> = m.specs.iter().flat_map(|s| self.signals_of(s)).collect();
        let Some(k) = signals.iter().position(|s| *s == Signal::Ramp) else {
            return false;
        };
        let est = nonstat::estimate(
            &nonstat::gls_scale(&self.blocks),
            &m.fit.components(),
            &signals,
        );
        est.get(k).is_some_and(|e| chi2_sf(e.lr, 1.0) < P_SIGNAL)
    }

    /// Among the admissible candidates the data cannot tell apart from the best — the criterion within
    /// [`EQUAL_SUPPORT`] — the one with the fewest added parameters, then the earliest in the
    /// vocabulary (the simpler physics: a one-pole filter before a two-pole one) goes first. The
    /// first candidate's reading names the others that fit nearly as well
    /// ([`NEAR_SUPPORT`]), so a user sees which physical forms the record cannot tell apart.
    fn prefer_simplest_of_equals(cands: &mut [Candidate<Effect, Model>]) {
        let Some(best) = cands.first().filter(|c| c.admissible) else {
            return;
        };
        let top = Self::criterion(&best.model);
        let equal = cands
            .iter()
            .take_while(|c| c.admissible && Self::criterion(&c.model) <= top + EQUAL_SUPPORT)
            .count();
        let rank = |c: &Candidate<Effect, Model>| {
            let order = c
                .edit
                .add
                .iter()
                .map(|e| {
                    crate::effect::ALL_EFFECTS
                        .iter()
                        .position(|v| v == e)
                        .unwrap_or(crate::effect::ALL_EFFECTS.len())
                })
                .min()
                .unwrap_or(crate::effect::ALL_EFFECTS.len());
            (c.extra_params, order)
        };
        cands[..equal].sort_by_key(rank);
        let top = Self::criterion(&cands[0].model);
        let others: Vec<String> = cands[1..]
            .iter()
            .filter(|c| c.admissible && Self::criterion(&c.model) <= top + NEAR_SUPPORT)
            .map(|c| {
                format!(
                    "{} (Δ criterion = {:+.1})",
                    c.reading,
                    Self::criterion(&c.model) - top
                )
            })
            .collect();
        if !others.is_empty() {
            cands[0].reading = format!(
                "{}; the record fits nearly as well: {}",
                cands[0].reading,
                others.join("; ")
            );
        }
    }

    /// The time-domain likelihood ratio of a candidate that adds one stochastic term: the block
    /// differences' −2ℓ of the candidate's other terms (at its Allan refit), or of the current
    /// model where that is less, minus that of the candidate, with the added term's amplitude
    /// (and non-linear parameter) re-estimated on the block differences themselves (profile
    /// likelihood). The other terms are the candidate's: the refit moves them too (a random
    /// walk the current model carried drops to zero beside a Markov process), and what the time
    /// domain gains from that move is no evidence for the added term — the current model's walk
    /// was the Allan fit's, not the time domain's. Terms that live below the block scale
    /// (filters) are left to the Allan points: their ratio is what they add at the block scale
    /// at their Allan amplitude. An edit that replaces terms (a filter in place of the white
    /// noise it shapes) is tested against the candidate's other terms with the replaced ones
    /// as the current model has them; one that adds several, or adds a signal, on the whole
    /// change from the current model.
    fn time_lr(&self, cur: &Model, m: &Model, edit: &Edit<Effect>) -> f64 {
        let base = cur.neg2ll_time - m.neg2ll_time;
        let [e] = edit.add.as_slice() else {
            return base;
        };
        let Some(k) = m.fit.terms.iter().rposition(|t| t.effect == *e) else {
            return base;
        };
        let t = &m.fit.terms[k];
        if e.kind() != crate::effect::Kind::Stochastic || t.known {
            return base;
        }
        let gls = nonstat::gls_scale(&self.blocks);
        let block_tau = gls.size as f64 * self.record.tau0;
        let signals: Vec<Signal> = m.specs.iter().flat_map(|s| self.signals_of(s)).collect();
        let component = |t: &crate::fit::TermFit, ctx| match t.effect.basis(&t.theta, ctx) {
            Ok(crate::effect::Basis::Stochastic { structure, factor }) if t.coef > 0.0 => {
                Some(crate::cov::Component {
                    coef: t.coef * factor,
                    structure,
                })
            }
            _ => None,
        };
        let mut others: Vec<crate::cov::Component> = m
            .fit
            .terms
            .iter()
            .enumerate()
            .filter(|(j, _)| *j != k)
            .filter_map(|(_, t)| component(t, &m.fit.ctx))
            .collect();
        // the nested model the ratio is taken against: the candidate without the added term
        // (with the terms it replaces, as the current model has them), or the current model
        // where that is likelier (the refit may have handed the added term another's part — a
        // Markov process of τ_c below a sample standing in for the white noise — and the
        // candidate without it then lacks that part). A swap's other terms are the
        // candidate's too: a filter in place of the white noise, refitted, moved a random walk
        // and the step's estimate, and the whole change from the current model read 12.4 where
        // the Allan points gave 2.1 (a filter above the Nyquist frequency on white noise, named
        // at p = 8.5e-4).
        others.extend(
            cur.fit
                .terms
                .iter()
                .filter(|t| edit.remove.contains(&t.effect))
                .filter_map(|t| component(t, &cur.fit.ctx)),
        );
        let without = nonstat::neg2_loglik(&gls, &others, &signals).min(cur.neg2ll_time);
        let own = without - m.neg2ll_time;
        if !edit.remove.is_empty() {
            return own;
        }
        if tau_range(&m.fit, k).is_none_or(|(_, hi)| hi < 2.0 * block_tau) {
            return own;
        }
        let eval = |theta: &[f64], c: f64| -> f64 {
            let Ok(crate::effect::Basis::Stochastic { structure, factor }) =
                e.basis(theta, &m.fit.ctx)
            else {
                return f64::INFINITY;
            };
            let mut comps = others.clone();
            comps.push(crate::cov::Component {
                coef: c * factor,
                structure,
            });
            nonstat::neg2_loglik(&gls, &comps, &signals)
        };
        // scale of the coefficient: the Allan estimate, or where the term would equal the model
        let c0 = if t.coef > 0.0 {
            t.coef
        } else {
            let b = e
                .basis(&t.theta, &m.fit.ctx)
                .map(|b| b.avar(gls.size as f64, self.record.tau0))
                .unwrap_or(0.0);
            let mv = m.fit.model_avar_at(block_tau);
            if b > 0.0 && mv > 0.0 {
                mv / b
            } else {
                return own;
            }
        };
        let thetas: Vec<Vec<f64>> = if t.theta.is_empty() {
            vec![Vec::new()]
        } else {
            [0.25, 0.5, 1.0, 2.0, 4.0]
                .iter()
                .map(|f| {
                    let mut th = t.theta.clone();
                    th[0] *= f;
                    th
                })
                .collect()
        };
        let mut best = f64::INFINITY;
        for th in &thetas {
            // golden section on ln c over [c0/1e3, c0·1e3]
            let (_, fm) =
                crate::fit::golden_min(|x| eval(th, x.exp()), (c0 / 1e3).ln(), (c0 * 1e3).ln(), 30);
            best = best.min(fm);
        }
        own.max(without - best)
    }

    fn candidate(
        &self,
        cur: &Model,
        m: Model,
        edit: Edit<Effect>,
        p: f64,
        td: bool,
        why: String,
    ) -> Candidate<Effect, Model> {
        let reading = edit
            .add
            .iter()
            .map(|e| reading(&m.fit, e, self.record.unit))
            .collect::<Vec<_>>()
            .join("; ");
        Candidate {
            summary: self.summary_of(&m),
            delta: cur.neg2ll - m.neg2ll,
            extra_params: m.fit.n_params() as i64 - cur.fit.n_params() as i64,
            p_value: p,
            admissible: td,
            reason: why,
            reading,
            edit,
            model: m,
        }
    }
}

/// The try adding `spec` (of effect `e`) to the model `cur`, tried for the reason `why`.
fn added(cur: &Model, e: Effect, spec: TermSpec, why: String) -> Try {
    let mut s = cur.specs.clone();
    s.push(spec);
    (
        s,
        Edit {
            add: vec![e],
            remove: vec![],
        },
        why,
    )
}

fn prefix(s: &str) -> String {
    if s.is_empty() {
        String::new()
    } else {
        format!("{s}; ")
    }
}
