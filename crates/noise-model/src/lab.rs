//! The noise lab: a recording's Allan curve against a model of named effects, with the record's
//! own evidence (time series, spectrum, timestamps) where the Allan curve alone cannot tell
//! effects apart. It implements the project's lab workflow ([`model_lab::Lab`]): fit, assess,
//! rank candidate edits, add the best, watch the error fall.
//!
//! What the lab looks at, in order:
//! 1. **Timing.** Irregular or bursty timestamps (host read times rather than sample times) are
//!    named first: the samples are taken as uniformly spaced at the mean rate, and spectral
//!    effects (sinusoids, Markov and filter shapes) are not named while the timing cannot
//!    support them.
//! 2. **Non-stationarity** ([`crate::nonstat`]): a bias step, a bias following the temperature
//!    column, a warm-up transient — tested in the time domain with the noise model's covariance,
//!    estimated there, and entered into the Allan model as known terms with their exact Allan
//!    variance. While one is found and not in the model, the model is not adequate, whatever its
//!    χ² says: a step or a warm-up absorbed into rate random walk or a ramp is not a noise density.
//! 3. **The Allan curve**: the generalised χ² fit and verdict ([`crate::fit`], [`crate::assess`]).
//!    Candidates are refitted and tested (likelihood ratios on the Allan points and on the
//!    block differences); every candidate, a time-domain finding included, is judged by one
//!    criterion ([`NoiseLab::criterion`]) that must fall for it to be added, and the admissible
//!    ones are ranked by it. Spectral evidence gates the spectral names: a sinusoid needs a line
//!    in the periodogram (its frequency is fixed there), and when a line explains the misfit a
//!    Markov term is not named in its place.
use crate::assess::{assess, Assessment};
use crate::effect::{Context, Effect, DEFAULT_TERMS};
use crate::fit::{
    fit_model, set_range, Fit, FitError, Known, Measurement, Point, TermSpec, Weighting,
};
use crate::nonstat::{self, Blocks, Signal};
use crate::psd::{default_segment, find_lines, line_near, welch, Line};
use allan::ci::chi2_sf;
use model_lab::{Candidate, Edit, Summary};

mod candidates;
mod reading;

use reading::fmt_s;
pub use reading::{misfit_range, reading, tau_range};

/// Significance level for naming a candidate.
pub const P_CANDIDATE: f64 = 1e-3;
/// Significance level of the time-domain tests (temperature, warm-up) per test.
pub const P_SIGNAL: f64 = 1e-3;
/// Most steps of a walk.
pub const MAX_STEPS: usize = 6;
/// Candidates whose criterion is within this of the best one's are equally supported by the data
/// (a likelihood ratio below e: "substantial support" for both, Burnham & Anderson 2002, §2.6).
pub const EQUAL_SUPPORT: f64 = 2.0;
/// Candidates within this of the best one's criterion (relative likelihood above e⁻² ≈ 0.14) are
/// named beside it as fitting nearly as well.
pub const NEAR_SUPPORT: f64 = 4.0;

/// What the timestamps say: the CSV contract's timing analysis (median, mean and 95th-percentile
/// spacing, bursts, jitter, duplicates, gaps).
pub use imu_proto::csv::Timing;

/// The recording the lab works from.
#[derive(Debug, Clone)]
pub struct Record<'a> {
    /// The rate samples of every segment, concatenated in time order.
    pub y: &'a [f64],
    /// Sample period [s].
    pub tau0: f64,
    /// Segments (first sample's index counted as if there were no gaps, length).
    pub segments: Vec<(u64, u64)>,
    /// The temperature column, aligned with `y` [°C].
    pub temp: Option<&'a [f64]>,
    /// The timestamps' analysis, when the file had them.
    pub timing: Option<Timing>,
    /// The Allan points (overlapping ADEV at octave τ over the segments).
    pub points: Vec<Point>,
    /// User-described effects to consider as candidates.
    pub user_effects: Vec<Effect>,
}

/// A finding of the time-domain or spectral checks that the model does not account for.
#[derive(Debug, Clone, PartialEq)]
pub struct Finding {
    pub effect: Effect,
    /// The term that would account for it (parameters estimated).
    pub spec: TermSpec,
    pub p_value: f64,
    pub text: String,
}

/// A fitted noise model with its assessment and the record's checks.
#[derive(Debug, Clone)]
pub struct Model {
    pub specs: Vec<TermSpec>,
    pub fit: Fit,
    pub assessment: Assessment,
    /// Non-stationarity the model does not account for.
    pub findings: Vec<Finding>,
    /// Allan-adequate and no finding.
    pub adequate: bool,
    /// −2 log-likelihood of the Allan points under the model.
    pub neg2ll: f64,
    /// −2 log-likelihood of the block differences at the time-domain scale.
    pub neg2ll_time: f64,
}

impl Model {
    /// Parameters the model spends: the Allan fit's free ones and those its time-domain terms
    /// estimated (a step's size and instant, a warm-up's amplitude and time constant, a
    /// temperature coefficient). The resolution is known from the data's lattice: none.
    pub fn spent_params(&self) -> usize {
        let td: usize = self
            .fit
            .terms
            .iter()
            .filter(|t| t.known && t.effect != Effect::Resolution)
            .map(|t| 1 + t.theta.len())
            .sum();
        self.fit.n_params() + td
    }
}

/// The lab over one recording.
pub struct NoiseLab<'a> {
    pub record: Record<'a>,
    pub meas: Measurement,
    /// Block means for the time-domain tests.
    pub blocks: Blocks,
    /// The data's LSB, when the values sit on a lattice.
    pub lsb: Option<f64>,
    /// Significant spectral lines of the Welch PSD, strongest first.
    pub lines: Vec<Line>,
    /// Frequency resolution of the whole-record periodogram [Hz].
    pub periodogram_df: f64,
}

/// The step between neighbouring values if the samples sit on a lattice (integer counts times a
/// scale), else None. Looks at up to 2^17 values spread over the record.
pub fn lattice(y: &[f64]) -> Option<f64> {
    if y.len() < 16 {
        return None;
    }
    let stride = (y.len() / 131_072).max(1);
    let mut v: Vec<f64> = y.iter().step_by(stride).copied().collect();
    v.sort_by(f64::total_cmp);
    v.dedup();
    if v.len() < 3 {
        return None;
    }
    let d: Vec<f64> = v.windows(2).map(|w| w[1] - w[0]).collect();
    let delta = d.iter().copied().fold(f64::INFINITY, f64::min);
    let scale = v.iter().map(|x| x.abs()).fold(0.0, f64::max);
    if !(delta > 0.0) || scale / delta > 1e9 {
        return None;
    }
    // counts printed with 8–9 significant digits (a scaled column) land within ~1e-5 of an
    // integer multiple; values off a lattice land anywhere
    d.iter()
        .all(|x| {
            let k = x / delta;
            (k - k.round()).abs() < 1e-3 + 1e-9 * k
        })
        .then_some(delta)
}

/// Exact overlapping Allan variance of `x` (segments concatenated) at averaging factor m.
fn oavar(x: &[f64], segments: &[(u64, u64)], m: u64) -> Option<f64> {
    let (mut acc, mut n) = (0.0, 0u64);
    let mut off = 0usize;
    let m = m as usize;
    for &(_, len) in segments {
        let s = &x[off..off + len as usize];
        off += len as usize;
        if s.len() < 2 * m {
            continue;
        }
        let mut pre = Vec::with_capacity(s.len() + 1);
        let mut a = 0.0;
        pre.push(0.0);
        let mean = s.iter().sum::<f64>() / s.len() as f64;
        for v in s {
            a += v - mean;
            pre.push(a);
        }
        for i in 0..=s.len() - 2 * m {
            let d = pre[i + 2 * m] - 2.0 * pre[i + m] + pre[i];
            acc += d * d;
            n += 1;
        }
    }
    (n > 0).then(|| acc / (2.0 * (m * m) as f64 * n as f64))
}

impl<'a> NoiseLab<'a> {
    /// Prepare the lab: the measurement, block means, the lattice and the spectral lines.
    pub fn new(record: Record<'a>) -> Result<NoiseLab<'a>, FitError> {
        let tau0 = record.tau0;
        if !(tau0 > 0.0 && tau0.is_finite()) {
            return Err(FitError::BadTerms(format!(
                "sample period {tau0} s is not positive"
            )));
        }
        let total: u64 = record.segments.iter().map(|s| s.1).sum();
        if total as usize != record.y.len() {
            return Err(FitError::BadTerms(format!(
                "the segments hold {total} samples but {} were given",
                record.y.len()
            )));
        }
        if let Some(i) = record.y.iter().position(|v| !v.is_finite()) {
            return Err(FitError::BadTerms(format!("sample {i} is {}", record.y[i])));
        }
        let mut ctx = Context {
            tau0,
            segments: record.segments.clone(),
            temp_avar: None,
            tau_min: tau0,
            tau_max: tau0,
        };
        if let Some(t) = record.temp {
            if t.len() != record.y.len() {
                return Err(FitError::BadTerms(
                    "the temperature column is not aligned with the data".into(),
                ));
            }
            let longest = record.segments.iter().map(|s| s.1).max().unwrap_or(0);
            let mut v = Vec::new();
            let mut m = 1u64;
            while 2 * m < longest {
                if let Some(a) = oavar(t, &record.segments, m) {
                    v.push((m, a));
                }
                m *= 2;
            }
            // A constant temperature column carries no information.
            if v.iter().any(|p| p.1 > 0.0) {
                ctx.temp_avar = Some(v);
            }
        }
        set_range(&mut ctx, &record.points);
        let meas = Measurement::new(record.points.clone(), ctx, Weighting::Model);
        let longest = record.segments.iter().map(|s| s.1).max().unwrap_or(0);
        let base = (longest / 8192).max(1);
        let temp = if meas.ctx.temp_avar.is_some() {
            record.temp
        } else {
            None
        };
        let blocks = Blocks::new(record.y, temp, &record.segments, base, tau0);
        let lsb = lattice(record.y);
        // Spectral lines from the longest segment.
        let (mut off, mut best) = (0usize, (0usize, 0usize));
        for &(_, len) in &record.segments {
            if len as usize > best.1 {
                best = (off, len as usize);
            }
            off += len as usize;
        }
        let seg_y = &record.y[best.0..best.0 + best.1];
        let lines = welch(seg_y, 1.0 / tau0, default_segment(seg_y.len()))
            .map(|p| find_lines(&p))
            .unwrap_or_default();
        let periodogram_df = 1.0 / (tau0 * seg_y.len().next_power_of_two() as f64);
        Ok(NoiseLab {
            record,
            meas,
            blocks,
            lsb,
            lines,
            periodogram_df,
        })
    }

    fn longest_segment(&self) -> &[f64] {
        let (mut off, mut best) = (0usize, (0usize, 0usize));
        for &(_, len) in &self.record.segments {
            if len as usize > best.1 {
                best = (off, len as usize);
            }
            off += len as usize;
        }
        &self.record.y[best.0..best.0 + best.1]
    }

    /// The default model: the five terms of eqs. 10–14 (Jaime et al.), plus the data's
    /// resolution when its values sit on a lattice (a known white floor, no free parameter).
    pub fn default_specs(&self) -> Vec<TermSpec> {
        let mut v: Vec<TermSpec> = DEFAULT_TERMS.iter().cloned().map(TermSpec::new).collect();
        if let Some(s) = self.resolution_spec() {
            v.push(s);
        }
        v
    }

    fn resolution_spec(&self) -> Option<TermSpec> {
        let lsb = self.lsb?;
        Some(TermSpec {
            known: Some(Known {
                coef: lsb * lsb,
                coef_sigma: 0.0,
                sign: 1.0,
            }),
            ..TermSpec::new(Effect::Resolution)
        })
    }

    /// The record with the model's time-domain signals removed (its bias steps, the temperature
    /// coefficient times the temperature column, or the warm-up), when it has any: the data whose
    /// Allan curve the noise terms describe. The ramp stays (its sign is not estimated).
    pub fn compensated(&self, m: &Model) -> Option<Vec<f64>> {
        let tau0 = self.record.tau0;
        let mut y = self.record.y.to_vec();
        let mut any = false;
        for t in &m.fit.terms {
            if !t.known || t.effect == Effect::Resolution {
                continue;
            }
            let a = t.amplitude();
            // the nominal sample index of every stored sample
            let mut k = 0usize;
            for &(start, len) in &self.record.segments {
                for i in 0..len {
                    let n = (start + i) as f64;
                    y[k] -= match (&t.effect, self.record.temp) {
                        (Effect::BiasStep, _) if n * tau0 >= t.theta[0] - 0.5 * tau0 => a,
                        (Effect::Temperature, Some(temp)) if t.theta.is_empty() => a * temp[k],
                        (Effect::Temperature, _) => a * (-n * tau0 / t.theta[0]).exp(),
                        _ => 0.0,
                    };
                    k += 1;
                }
            }
            any = true;
        }
        any.then_some(y)
    }

    /// The time-domain signal of a term, if it has one.
    fn signal_of(&self, s: &TermSpec) -> Option<Signal> {
        let tau0 = self.record.tau0;
        match s.effect {
            Effect::RateRamp => Some(Signal::Ramp),
            Effect::BiasStep => s.theta.as_ref().map(|t| Signal::Step { at: t[0] / tau0 }),
            Effect::Temperature => {
                if self.meas.ctx.temp_avar.is_some() {
                    Some(Signal::Temperature)
                } else {
                    s.theta
                        .as_ref()
                        .map(|t| Signal::WarmUp { kappa: t[0] / tau0 })
                }
            }
            _ => None,
        }
    }

    /// Fit a model: time-domain terms are estimated on the record with the current noise model
    /// and enter the Allan fit as known terms; two rounds let the noise model settle.
    pub fn fit(&self, specs: &[TermSpec]) -> Result<Model, FitError> {
        let mut specs = specs.to_vec();
        let td: Vec<usize> = (0..specs.len())
            .filter(|&k| matches!(specs[k].effect, Effect::BiasStep | Effect::Temperature))
            .collect();
        let mut fit = if td.is_empty() {
            fit_model(&self.meas, &specs)?
        } else {
            let noise: Vec<TermSpec> = specs
                .iter()
                .filter(|s| !matches!(s.effect, Effect::BiasStep | Effect::Temperature))
                .cloned()
                .collect();
            let mut f = fit_model(&self.meas, &noise)?;
            for _ in 0..3 {
                let comps = f.components();
                let sig_idx: Vec<usize> = (0..specs.len())
                    .filter(|&k| self.signal_of(&specs[k]).is_some())
                    .collect();
                let signals: Vec<Signal> = sig_idx
                    .iter()
                    .map(|&k| self.signal_of(&specs[k]).expect("signal"))
                    .collect();
                let est = nonstat::estimate(&nonstat::gls_scale(&self.blocks), &comps, &signals);
                for (e, &k) in est.iter().zip(&sig_idx) {
                    if td.contains(&k) {
                        let v = if e.value.is_finite() { e.value } else { 0.0 };
                        specs[k].known = Some(Known {
                            coef: v * v,
                            coef_sigma: 2.0 * v.abs() * e.sigma,
                            sign: v.signum(),
                        });
                    }
                }
                f = fit_model(&self.meas, &specs)?;
            }
            f
        };
        // time-domain σ of the known amplitudes, as amplitude σ: keep coef_sigma = 2|v|σ_v
        for (t, s) in fit.terms.iter_mut().zip(&specs) {
            if let Some(k) = s.known {
                t.coef_sigma = k.coef_sigma;
                t.detected = t.coef > 0.0 && t.coef > 2.0 * t.coef_sigma;
            }
        }
        let assessment = assess(&fit);
        let findings = self.findings(&specs, &fit);
        let adequate = assessment.adequate && findings.is_empty();
        let neg2ll = crate::assess::neg2_loglik(&fit);
        let signals: Vec<Signal> = specs.iter().filter_map(|s| self.signal_of(s)).collect();
        let neg2ll_time = nonstat::neg2_loglik(
            &nonstat::gls_scale(&self.blocks),
            &fit.components(),
            &signals,
        );
        for (what, v) in [
            ("the −2 log-likelihood of the Allan points", neg2ll),
            (
                "the −2 log-likelihood of the block differences",
                neg2ll_time,
            ),
            ("the verdict's p-value", assessment.p_value),
        ] {
            if !v.is_finite() {
                return Err(FitError::NonFinite(format!("{what} ({v})")));
            }
        }
        Ok(Model {
            specs,
            fit,
            assessment,
            findings,
            adequate,
            neg2ll,
            neg2ll_time,
        })
    }

    /// The record's non-stationarity that the model does not account for.
    pub fn findings(&self, specs: &[TermSpec], fit: &Fit) -> Vec<Finding> {
        let comps = fit.components();
        if comps.is_empty() {
            return Vec::new();
        }
        let signals: Vec<Signal> = specs.iter().filter_map(|s| self.signal_of(s)).collect();
        let mut out = Vec::new();
        let segs = &self.record.segments;
        for st in nonstat::find_steps(&self.blocks, &comps, &signals, Some((self.record.y, segs))) {
            let t = st.at as f64 * self.record.tau0;
            out.push(Finding {
                effect: Effect::BiasStep,
                spec: TermSpec {
                    theta: Some(vec![t]),
                    theta_fixed: true,
                    theta_sigma: Some(vec![st.scale as f64 * self.record.tau0 / 2.0]),
                    ..TermSpec::new(Effect::BiasStep)
                },
                p_value: st.p_value,
                text: format!(
                    "a bias step of {:+.4e} ± {:.1e} at t ≈ {} (change-point test on the time \
                     series, likelihood ratio {:.0}, p = {:.1e} after the search over positions \
                     and scales)",
                    st.size,
                    st.sigma,
                    fmt_s(t),
                    st.lr,
                    st.p_value
                ),
            });
        }
        let has_temp = specs.iter().any(|s| s.effect == Effect::Temperature);
        if !has_temp {
            let gls = nonstat::gls_scale(&self.blocks);
            if self.meas.ctx.temp_avar.is_some() {
                let mut sig = signals.clone();
                sig.push(Signal::Temperature);
                let est = nonstat::estimate(&gls, &comps, &sig);
                let e = est.last().expect("temperature");
                let p = chi2_sf(e.lr, 1.0);
                if p < P_SIGNAL {
                    out.push(Finding {
                        effect: Effect::Temperature,
                        spec: TermSpec::new(Effect::Temperature),
                        p_value: p,
                        text: format!(
                            "the bias follows the temperature column: {:+.4e} ± {:.1e} per °C \
                             (GLS on the time series with the noise model's covariance, \
                             likelihood ratio {:.1}, p = {:.1e})",
                            e.value, e.sigma, e.lr, p
                        ),
                    });
                }
            } else {
                // warm-up: an exponential beyond what the model's signals (a ramp) explain
                let record = self.record.y.len() as f64 * self.record.tau0;
                let mut best: Option<(f64, nonstat::Estimate)> = None;
                let grid = 24;
                for i in 0..grid {
                    let tw = record / 300.0 * (900.0f64).powf(i as f64 / (grid - 1) as f64);
                    let mut sig = signals.clone();
                    sig.push(Signal::WarmUp {
                        kappa: tw / self.record.tau0,
                    });
                    let est = nonstat::estimate(&gls, &comps, &sig);
                    let e = est.last().expect("warm-up").clone();
                    if e.lr.is_finite() && best.as_ref().is_none_or(|b| e.lr > b.1.lr) {
                        best = Some((tw, e));
                    }
                }
                if let Some((tw, e)) = best {
                    let p = (chi2_sf(e.lr, 1.0) * grid as f64).min(1.0);
                    if p < P_SIGNAL {
                        out.push(Finding {
                            effect: Effect::Temperature,
                            spec: TermSpec {
                                theta: Some(vec![tw]),
                                theta_fixed: true,
                                ..TermSpec::new(Effect::Temperature)
                            },
                            p_value: p,
                            text: format!(
                                "a warm-up transient: the bias approaches its final value \
                                 exponentially, amplitude {:+.4e} ± {:.1e}, time constant ≈ {} \
                                 (no temperature column; likelihood ratio {:.1}, p = {:.1e} after \
                                 the search over time constants)",
                                e.value,
                                e.sigma,
                                fmt_s(tw),
                                e.lr,
                                p
                            ),
                        });
                    }
                }
            }
        }
        out
    }

    fn summary_of(&self, m: &Model) -> Summary {
        Summary {
            chi2_dof: m.fit.chi2_dof(),
            rms_residual: m.assessment.rms_log_residual,
            rms_unit: String::new(),
            adequate: m.adequate,
            params: m.fit.n_params(),
        }
    }

    /// The one criterion every candidate is judged by, spectral, time-domain and user-described
    /// alike: the −2 log-likelihood of the record's two summaries under the model — the Allan
    /// points ([`crate::assess::neg2_loglik`]) and the block differences of the time series
    /// ([`nonstat::neg2_loglik`]) — plus 2 for every parameter the model spends
    /// ([`Model::spent_params`]): the Allan fit's free ones and those estimated in the time domain
    /// (a step's size and instant, a warm-up's amplitude and time constant, a temperature
    /// coefficient), so a staircase of steps pays for each of them against one warm-up. A
    /// statistic that is not finite makes the criterion +∞ (never better than anything).
    pub fn criterion(m: &Model) -> f64 {
        let c = m.neg2ll + m.neg2ll_time + 2.0 * m.spent_params() as f64;
        if c.is_finite() {
            c
        } else {
            f64::INFINITY
        }
    }

    fn spectral_blocked(&self) -> bool {
        self.record.timing.as_ref().is_some_and(|t| t.irregular())
    }
}

impl model_lab::Lab for NoiseLab<'_> {
    type Effect = Effect;
    type Model = Model;
    type Error = FitError;

    fn summary(&self, m: &Model) -> Summary {
        self.summary_of(m)
    }

    fn candidates(&self, m: &Model) -> Result<Vec<Candidate<Effect, Model>>, FitError> {
        self.candidate_edits(m)
    }
}
