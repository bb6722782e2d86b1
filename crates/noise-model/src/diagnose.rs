//! Diagnosis: when the model is inadequate, name the missing effect.
//!
//! General rule (issue 3 §4): every effect of the vocabulary that is not in the model is added in
//! turn and the model refitted. Each candidate's χ² reduction Δχ² is tested as a nested-model
//! likelihood-ratio statistic: with k extra parameters, Δχ²/s ~ χ²_k under "the candidate adds
//! nothing", where s = max(1, χ²_new/dof_new) absorbs any remaining over-dispersion (an F-type
//! test, Bevington & Robinson §11.4). Candidates are ranked by that p-value, so extra parameters are
//! penalised through k; the best one is named only if p < [`P_CANDIDATE`] and its added amplitude
//! is not pinned at zero (the likelihood ratio decides, not the term's own Wald test). Otherwise the diagnosis says plainly what is wrong and that no effect of
//! the vocabulary explains it.
use crate::assess::{assess, Assessment, TauRange, CORRELATION_INFLATION};
use crate::effect::{Effect, ALL_EFFECTS};
use crate::fit::{fit, Fit, FitOptions};
use crate::psd::{default_segment, find_line, line_near, welch, Line, LineTest};
use allan::ci::chi2_sf;

/// Significance level for naming a candidate.
pub const P_CANDIDATE: f64 = 1e-3;

/// One candidate's refit.
#[derive(Debug, Clone, PartialEq)]
pub struct Candidate {
    pub effect: Effect,
    pub fit: Fit,
    pub assessment: Assessment,
    pub delta_chi2: f64,
    pub extra_params: usize,
    /// p-value of the nested test (small = the candidate explains real structure).
    pub p_value: f64,
    pub significant: bool,
    /// For a sinusoid with the raw data available: the whole-record test for a line near the
    /// fitted frequency. A sinusoid without a line is not named.
    pub line_test: Option<LineTest>,
}

/// The diagnosis of a fit.
#[derive(Debug, Clone, PartialEq)]
pub struct Diagnosis {
    pub adequate: bool,
    /// The missing effect, when one is named.
    pub missing: Option<Effect>,
    /// The τ range [s] where the model fails (union of failing ranges), if any.
    pub tau_range: Option<(f64, f64)>,
    /// Plain-words explanation.
    pub explanation: String,
    /// Evidence lines (residual shape and slope, peak position, nulls, PSD line).
    pub evidence: Vec<String>,
    /// All candidates tried, best first.
    pub candidates: Vec<Candidate>,
    /// The strongest significant line of the Welch PSD, when the raw data were given.
    pub line: Option<Line>,
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

/// A p-value for people: "p = 2.5e-41", or "p < 1e-300" when it underflows.
fn fmt_p(p: f64) -> String {
    if p > 0.0 {
        format!("p = {p:.1e}")
    } else {
        "p < 1e-300".into()
    }
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
                "{}τ = {} – {}: measured σ {} the model by up to {:.1} CI half-widths; \
                 log-log slope measured {} vs model {}",
                if a.failing.is_empty() {
                    "not significant: "
                } else {
                    ""
                },
                fmt_s(r.lo),
                fmt_s(r.hi),
                if r.sign > 0 { "above" } else { "below" },
                r.worst,
                sm.map_or("n/a".into(), |s| format!("{s:+.2}")),
                sx.map_or("n/a".into(), |s| format!("{s:+.2}")),
            )
        })
        .collect()
}

/// Evidence specific to an effect found by the refit.
fn effect_evidence(c: &Candidate, line: Option<&Line>) -> Vec<String> {
    let mut ev = Vec::new();
    let Some(t) = c.fit.term(c.effect) else {
        return ev;
    };
    let (tmin, tmax) = (
        c.fit.points.first().map_or(0.0, |p| p.tau),
        c.fit.points.last().map_or(0.0, |p| p.tau),
    );
    match c.effect {
        Effect::Markov => {
            if let Some(tc) = t.theta {
                ev.push(format!(
                    "the added Markov term has τ_c = {} and peaks at τ ≈ 1.89·τ_c = {} with \
                     σ ≈ 0.62·sigma = {:.3e}; a first-order low-pass at f_c = 1/(2π·τ_c) = {:.2} Hz \
                     on white noise produces exactly this (the seed's 5 Hz DLPF gives τ_c ≈ 0.032 s)",
                    fmt_s(tc),
                    fmt_s(1.89 * tc),
                    0.618 * t.amplitude(),
                    1.0 / (2.0 * std::f64::consts::PI * tc)
                ));
            }
        }
        Effect::Sinusoid => {
            if let Some(f) = t.theta {
                let nulls: Vec<String> = (1..=6)
                    .map(|k| k as f64 / f)
                    .filter(|&x| x >= tmin && x <= tmax)
                    .map(fmt_s)
                    .collect();
                ev.push(format!(
                    "the added sinusoid has f = {:.4} Hz (period {}); its first Allan peak is at \
                     τ ≈ 0.371/f = {} and σ has nulls at τ = k/f{}",
                    f,
                    fmt_s(1.0 / f),
                    fmt_s(0.371 / f),
                    if nulls.is_empty() {
                        " (none inside the measured τ range)".to_string()
                    } else {
                        format!(": {}", nulls.join(", "))
                    }
                ));
                if let Some(lt) = c.line_test {
                    ev.push(format!(
                        "the periodogram of the whole record has its strongest bin near f at \
                         {:.4} Hz, {:.1}× the local background (p = {:.1e} over {} bins searched)",
                        lt.freq_hz, lt.ratio, lt.p_value, lt.bins
                    ));
                }
                match line {
                    Some(l) => {
                        let agree = (l.freq_hz - f).abs() <= 0.05 * f.max(l.freq_hz);
                        ev.push(format!(
                            "the Welch PSD of the data has a line at {:.4} Hz, {:.0}× the local \
                             background (significance threshold {:.1}×), amplitude ≈ {:.3e}; {}",
                            l.freq_hz,
                            l.ratio,
                            l.threshold,
                            l.amplitude,
                            if agree {
                                "it agrees with the fitted frequency"
                            } else {
                                "its frequency differs from the Allan fit (octave-spaced τ cannot \
                                 pin f well; trust the PSD)"
                            }
                        ));
                    }
                    None => ev.push(
                        "no significant line was found in the Welch PSD (or the data were not \
                         available), so the sinusoid rests on the Allan curve alone"
                            .into(),
                    ),
                }
            }
        }
        e => {
            if let Some(s) = e.adev_slope() {
                ev.push(format!(
                    "the added {} term has σ(τ) slope {:+.1} ({})",
                    e,
                    s,
                    e.signature()
                ));
            }
        }
    }
    ev
}

/// Diagnose a fit. `data` is the raw rate record and its rate [Hz], when available: its Welch PSD
/// line (if any) seeds the sinusoid search and is reported, and a sinusoid candidate is checked for
/// a line in the whole-record periodogram.
pub fn diagnose(base: &Fit, base_a: &Assessment, data: Option<(&[f64], f64)>) -> Diagnosis {
    let line: Option<Line> = data.and_then(|(y, fs)| {
        let p = welch(y, fs, default_segment(y.len()))?;
        find_line(&p)
    });
    let line = line.as_ref();
    let union = |rs: &[TauRange]| {
        if rs.is_empty() {
            None
        } else {
            Some((
                rs.iter().map(|r| r.lo).fold(f64::INFINITY, f64::min),
                rs.iter().map(|r| r.hi).fold(0.0, f64::max),
            ))
        }
    };
    if base_a.adequate {
        return Diagnosis {
            adequate: true,
            missing: None,
            tau_range: None,
            explanation: format!(
                "The model describes the measurement: χ²/dof = {:.2} (p = {:.2} after the \
                 correlation allowance) and no τ where the model leaves the confidence interval \
                 significantly (all |z| ≤ {:.1}). No effect is missing.",
                base.chi2_dof(),
                base_a.p_value,
                base_a.threshold
            ),
            evidence: residual_evidence(base, base_a),
            candidates: Vec::new(),
            line: line.copied(),
        };
    }
    let opts = FitOptions {
        freq_hint: line.map(|l| l.freq_hz),
        ..FitOptions::default()
    };
    let have = base.effects();
    let mut candidates: Vec<Candidate> = ALL_EFFECTS
        .iter()
        .filter(|e| !have.contains(e))
        .filter_map(|&e| {
            let mut effects = have.clone();
            effects.push(e);
            let f = fit(&base.points, base.tau0, &effects, &opts).ok()?;
            let a = assess(&f);
            let k = e.n_params();
            let delta = base.chi2 - f.chi2;
            let s = (f.chi2_dof()).max(CORRELATION_INFLATION);
            let p = chi2_sf(delta.max(0.0) / s, k as f64);
            let coef_positive = f.term(e).is_some_and(|t| t.coef > 0.0);
            let line_test = match (e, data, f.term(e).and_then(|t| t.theta)) {
                (Effect::Sinusoid, Some((y, fs)), Some(freq)) => line_near(y, fs, freq, 0.15),
                _ => None,
            };
            let line_ok = line_test.is_none_or(|lt| lt.p_value < P_CANDIDATE);
            Some(Candidate {
                effect: e,
                delta_chi2: delta,
                extra_params: k,
                p_value: p,
                // The likelihood-ratio test (Δχ² for k extra parameters) decides; the term's own
                // Wald test (c > 2σ_c) is not required, because a term whose parameters trade off
                // against another (a Markov τ_c near τ0 against white noise) can be poorly
                // constrained on its own while the data need it overwhelmingly (a one-pole DLPF
                // on the emulated MPU-6050: χ²/dof 212 → 2.8, p ≈ 1e-148). An amplitude pinned
                // at zero is still refused.
                significant: p < P_CANDIDATE && coef_positive && line_ok,
                line_test,
                fit: f,
                assessment: a,
            })
        })
        .collect();
    candidates.sort_by(|a, b| {
        b.significant
            .cmp(&a.significant)
            .then(a.p_value.total_cmp(&b.p_value))
            .then(b.delta_chi2.total_cmp(&a.delta_chi2))
    });
    let tau_range = union(&base_a.failing).or_else(|| union(&base_a.outside));
    let mut evidence = residual_evidence(base, base_a);
    let best = candidates.first().filter(|c| c.significant);
    let explanation = match best {
        Some(c) => {
            evidence.extend(effect_evidence(c, line));
            let others: Vec<String> = candidates[1..]
                .iter()
                .map(|o| format!("{} ({})", o.effect, fmt_p(o.p_value)))
                .collect();
            format!(
                "The model misses a {} effect. Adding it lowers χ² by {:.1} for {} extra \
                 parameter{} ({}; other candidates: {}); with it χ²/dof goes {:.2} → {:.2} \
                 and the fit is {}. Signature: {}. Physics: {}",
                c.effect,
                c.delta_chi2,
                c.extra_params,
                if c.extra_params == 1 { "" } else { "s" },
                fmt_p(c.p_value),
                if others.is_empty() {
                    "none".to_string()
                } else {
                    others.join(", ")
                },
                base.chi2_dof(),
                c.fit.chi2_dof(),
                if c.assessment.adequate {
                    "adequate"
                } else {
                    "better but still not adequate — more than one effect may be missing"
                },
                c.effect.signature(),
                c.effect.physics()
            )
        }
        None => {
            for c in &candidates {
                if let (Some(lt), Some(f)) =
                    (c.line_test, c.fit.term(c.effect).and_then(|t| t.theta))
                {
                    if c.p_value < P_CANDIDATE && lt.p_value >= P_CANDIDATE {
                        evidence.push(format!(
                            "a sinusoid at {:.4} Hz would lower χ² by {:.1} (p = {:.1e}), but the \
                             periodogram of the record shows no line near it (best bin {:.1}× \
                             background, p = {:.2}), so it is not named",
                            f, c.delta_chi2, c.p_value, lt.ratio, lt.p_value
                        ));
                    }
                }
            }
            // Residual signs alternating between neighbouring octaves at short τ: no stationary
            // noise does that; repeated or irregularly timed samples do.
            let r = &base_a.residuals;
            let mut run = 1usize;
            let mut best_run = 1usize;
            for j in 1..r.len().min(8) {
                if r[j] * r[j - 1] < 0.0 && r[j].abs() > 1.0 && r[j - 1].abs() > 1.0 {
                    run += 1;
                    best_run = best_run.max(run);
                } else {
                    run = 1;
                }
            }
            if best_run >= 3 {
                evidence.push(format!(
                    "at short τ the residual alternates in sign from one octave to the next over {} \
                     points: a zig-zag that no stationary noise produces, typical of repeated or \
                     irregularly timed samples (buffered host reads, a sample-rate mismatch)",
                    best_run
                ));
            }
            let best_try = candidates
                .first()
                .map(|c| format!("{} ({})", c.effect, fmt_p(c.p_value)))
                .unwrap_or_else(|| "none left to try".into());
            format!(
                "The model does not describe the measurement (χ²/dof = {:.2}), and no effect of \
                 the vocabulary explains the misfit significantly (best candidate: {}). Look at \
                 the data rather than the model: non-stationary behaviour (warm-up, a temperature \
                 change, motion of the bench), gaps, glitches or saturated samples, or a record \
                 too short for the longest τ all bend the Allan curve in ways no stationary noise \
                 term can.",
                base.chi2_dof(),
                best_try
            )
        }
    };
    Diagnosis {
        adequate: false,
        missing: best.map(|c| c.effect),
        tau_range,
        explanation,
        evidence,
        candidates,
        line: line.copied(),
    }
}

/// One side of a step report.
#[derive(Debug, Clone, PartialEq)]
pub struct StepSide {
    pub effects: Vec<Effect>,
    pub chi2_dof: f64,
    pub rms_log_residual: f64,
    pub adequate: bool,
}

/// The before → after of adding effects (issue 3 §4, last bullet).
#[derive(Debug, Clone, PartialEq)]
pub struct Step {
    pub added: Vec<Effect>,
    pub before: StepSide,
    pub after: StepSide,
}

/// Build the step report from two fits and their assessments.
pub fn step(before: &Fit, ba: &Assessment, after: &Fit, aa: &Assessment) -> Step {
    let side = |f: &Fit, a: &Assessment| StepSide {
        effects: f.effects(),
        chi2_dof: f.chi2_dof(),
        rms_log_residual: a.rms_log_residual,
        adequate: a.adequate,
    };
    let bef = before.effects();
    Step {
        added: after
            .effects()
            .into_iter()
            .filter(|e| !bef.contains(e))
            .collect(),
        before: side(before, ba),
        after: side(after, aa),
    }
}
