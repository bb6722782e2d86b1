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
use allan::confidence::chi2_sf;
use model_lab::{Candidate, Edit, Summary};
use nalgebra::DMatrix;

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
    /// Their unit (`deg/s`, `m/s²`, …), for the readings.
    pub unit: &'a str,
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
            // a drift's size and unit shape are its J cosine amplitudes
            .map(|t| match t.effect {
                Effect::Drift { .. } => t.theta.len(),
                _ => 1 + t.theta.len(),
            })
            .sum();
        self.fit.n_params() + td
    }
}

/// Enter a time-domain term's estimates into its spec as a known coefficient: a step, a warm-up
/// or a temperature coefficient as its amplitude v (coefficient v², σ 2|v|σ_v, sign of v); a
/// drift as its size a, the rms about its mean of the curve its estimates draw (a ramp R̂ [u/s]
/// and cosine amplitudes ê_j [u], [`crate::effect::drift_norm`]), coefficient a², with the
/// unit-size shape (R̂τ0, ê_1, …)/a as its fixed parameters. `value` and `cov` are the term's
/// estimates and their joint covariance.
fn set_known(spec: &mut TermSpec, value: &[f64], cov: &DMatrix<f64>, ctx: &Context) {
    let finite = |v: f64| if v.is_finite() { v } else { 0.0 };
    if let Effect::Drift { .. } = spec.effect {
        // per sample: the ramp's estimate is per second
        let unit = |j: usize| if j == 0 { ctx.tau0 } else { 1.0 };
        let e: Vec<f64> = value
            .iter()
            .enumerate()
            .map(|(j, v)| finite(*v) * unit(j))
            .collect();
        if cov.nrows() != e.len() {
            return;
        }
        // The curve the estimates draw carries the noise's projection on the drift's components,
        // whose Allan variance the noise terms already hold: each independent direction of the
        // estimate (whitened by its covariance) is shrunk to its unbiased size, z → z·√(1 − 1/z²)
        // (zero where |z| ≤ 1), so the known term is the drift's and not drift + noise twice.
        let cs = DMatrix::from_fn(e.len(), e.len(), |j, k| {
            finite(cov[(j, k)]) * unit(j) * unit(k)
        });
        let e = match cs.clone().cholesky() {
            Some(ch) => {
                let l = ch.l();
                let z = l
                    .solve_lower_triangular(&nalgebra::DVector::from_column_slice(&e))
                    .unwrap_or_else(|| nalgebra::DVector::zeros(e.len()));
                let shrunk = z.map(|v| v * (1.0 - 1.0 / (v * v)).max(0.0).sqrt());
                (l * shrunk).iter().copied().collect::<Vec<f64>>()
            }
            None => e,
        };
        let span = crate::effect::drift_span(ctx);
        let a = crate::effect::drift_norm(&e, span);
        if !(a > 0.0) {
            return;
        }
        // σ of a by the delta method with the estimates' joint covariance: ∂a/∂e = G·e/a
        let g = crate::effect::drift_gram(e.len(), span);
        let grad: Vec<f64> = g
            .iter()
            .enumerate()
            .map(|(j, gj)| gj.iter().zip(&e).map(|(x, y)| x * y).sum::<f64>() / a * unit(j))
            .collect();
        let mut var = 0.0;
        for (j, gj) in grad.iter().enumerate() {
            for (k, gk) in grad.iter().enumerate() {
                var += gj * finite(cov[(j, k)]) * gk;
            }
        }
        spec.theta = Some(e.iter().map(|v| v / a).collect());
        spec.theta_sigma = Some(
            (0..e.len())
                .map(|j| finite(cov[(j, j)]).max(0.0).sqrt() * unit(j) / a)
                .collect(),
        );
        spec.theta_fixed = true;
        spec.known = Some(Known {
            coef: a * a,
            coef_sigma: 2.0 * a * var.max(0.0).sqrt(),
            sign: 1.0,
        });
    } else if let Some(&v) = value.first() {
        let v = finite(v);
        spec.known = Some(Known {
            coef: v * v,
            coef_sigma: 2.0 * v.abs() * finite(cov[(0, 0)]).max(0.0).sqrt(),
            sign: v.signum(),
        });
    }
}

/// Rounds of [`NoiseLab::signal_rounds`]: a time-domain estimate, then the Allan fit.
const SIGNAL_ROUNDS: usize = 3;

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
    /// Stuck stretches and glitches in the samples ([`crate::defects`]): while there are any,
    /// no model is adequate.
    pub defects: crate::defects::Defects,
}

/// Whether `t` is `y` up to a scale and an offset (|correlation| = 1 to within rounding): the
/// temperature column beside the temperature column itself.
fn affine_copy(y: &[f64], t: &[f64]) -> bool {
    let n = y.len() as f64;
    if y.len() != t.len() || y.len() < 2 {
        return false;
    }
    let (my, mt) = (y.iter().sum::<f64>() / n, t.iter().sum::<f64>() / n);
    let (mut syy, mut stt, mut syt) = (0.0, 0.0, 0.0);
    for (a, b) in y.iter().zip(t) {
        let (dy, dt) = (a - my, b - mt);
        syy += dy * dy;
        stt += dt * dt;
        syt += dy * dt;
    }
    // 1 − r² is the fraction of y's variance a regression on t leaves; rounding leaves ≈ 1e-16.
    syy > 0.0 && stt > 0.0 && 1.0 - syt * syt / (syy * stt) < 1e-10
}

/// The 1σ of a parameter scanned on a log grid, from its likelihood-ratio profile (θ, LR): half
/// the width of the interval where the LR is within 1 of its largest, `lr` at `best` (χ²₁'s
/// 68.3 %), interpolated in log θ between grid points; a side that never falls by 1 ends at the
/// grid's end. NaN without two points.
fn profile_sigma(profile: &[(f64, f64)], best: f64, lr: f64) -> f64 {
    let Some(b) = profile.iter().position(|p| p.0 == best) else {
        return f64::NAN;
    };
    if profile.len() < 2 {
        return f64::NAN;
    }
    let target = lr - 1.0;
    let cross = |i: usize, j: usize| {
        // between grid points i (below the target) and j (above it)
        let (a, b) = (profile[i], profile[j]);
        let f = ((target - a.1) / (b.1 - a.1)).clamp(0.0, 1.0);
        (a.0.ln() + f * (b.0.ln() - a.0.ln())).exp()
    };
    let lo = (1..=b)
        .rev()
        .find(|&i| profile[i - 1].1 < target)
        .map_or(profile[0].0, |i| cross(i - 1, i));
    let hi = (b..profile.len() - 1)
        .find(|&i| profile[i + 1].1 < target)
        .map_or(profile[profile.len() - 1].0, |i| cross(i + 1, i));
    (hi - lo) / 2.0
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
            temp_profile: None,
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
            let lengths: Vec<u64> = record.segments.iter().map(|s| s.1).collect();
            let (mut v, mut profiles) = (Vec::new(), Vec::new());
            let mut m = 1u64;
            while 2 * m < longest {
                if let Some((a, p)) = crate::diff_profile::allan_profile(t, &lengths, m) {
                    v.push((m, a));
                    profiles.push((m, p));
                }
                m *= 2;
            }
            // A constant temperature column carries no information, and one that is the data
            // itself (the column analysed is the temperature, up to a unit or an offset) is no
            // regressor for it: the fit would explain the data by itself.
            if v.iter().any(|p| p.1 > 0.0) && !affine_copy(record.y, t) {
                ctx.temp_avar = Some(v);
                ctx.temp_profile = Some(std::sync::Arc::new(profiles));
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
        let lengths: Vec<usize> = record.segments.iter().map(|s| s.1 as usize).collect();
        let defects = crate::defects::find(record.y, &lengths, lsb);
        Ok(NoiseLab {
            record,
            meas,
            blocks,
            lsb,
            lines,
            periodogram_df,
            defects,
        })
    }

    /// The nominal time [s] of sample `k` of the concatenated data.
    fn time_of(&self, k: usize) -> f64 {
        let mut off = 0usize;
        for &(start, len) in &self.record.segments {
            if k < off + len as usize {
                return (start as usize + k - off) as f64 * self.record.tau0;
            }
            off += len as usize;
        }
        k as f64 * self.record.tau0
    }

    /// The data defects in words, one line each.
    pub fn defect_texts(&self) -> Vec<String> {
        let d = &self.defects;
        let mut out: Vec<String> = d
            .stuck
            .iter()
            .map(|&(k, len, _)| {
                let (a, b) = (self.time_of(k), self.time_of(k + len - 1));
                format!(
                    "samples {k}–{} (t = {:.3}–{:.3} s, {:.3} s) hold one value, where the \
                     record's noise repeats a value only a few samples in a row: a stuck \
                     reading (a frozen sensor or bus), whose Allan statistics are not the \
                     sensor's noise; cut the stretch out, or split the record there, and fit again",
                    k + len - 1,
                    a,
                    b,
                    b - a + self.record.tau0
                )
            })
            .collect();
        if !d.glitches.is_empty() {
            out.push(format!(
                "{} far off {} neighbours: {}; a glitch (a bus error, a knock) adds the \
                 variance of white noise at every τ, so the fit reads it as noise; remove {} \
                 and fit again",
                if d.glitches.len() == 1 {
                    "a sample is"
                } else {
                    "samples are"
                },
                if d.glitches.len() == 1 {
                    "its"
                } else {
                    "their"
                },
                d.glitches
                    .iter()
                    .map(|&(k, z)| format!(
                        "sample {k} (t = {:.3} s) by {} robust σ of the sample-to-sample change",
                        self.time_of(k),
                        if z < 1e6 {
                            format!("{z:.0}")
                        } else {
                            format!("{z:.1e}")
                        }
                    ))
                    .collect::<Vec<_>>()
                    .join(", "),
                if d.glitches.len() == 1 { "it" } else { "them" }
            ));
        }
        out
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
    /// resolution when its values sit on a lattice coarse enough to change the fit (a known white
    /// floor, no free parameter): its variance LSB²/12/m at the shortest τ at least one standard
    /// error of that point's estimate. A finer lattice (a CSV written with a fixed number of
    /// decimals) is left out; the walk still adds it if it lowers the criterion.
    pub fn default_specs(&self) -> Vec<TermSpec> {
        let mut v: Vec<TermSpec> = DEFAULT_TERMS.iter().cloned().map(TermSpec::new).collect();
        if let (Some(s), Some(p), Some(share)) = (
            self.resolution_spec(),
            self.meas.points.first(),
            self.resolution_share(),
        ) {
            if share >= (2.0 / p.edf).sqrt() {
                v.push(s);
            }
        }
        v
    }

    /// The share of the shortest τ's measured Allan variance that rounding to the lattice
    /// would make as noise of its own, LSB²/12/m over σ̂² (None without a lattice).
    fn resolution_share(&self) -> Option<f64> {
        let (lsb, p) = (self.lsb?, self.meas.points.first()?);
        Some(lsb * lsb / 12.0 / p.m.max(1) as f64 / (p.dev * p.dev))
    }

    /// The noise below the lattice: rounding is noise of its own, LSB²/12 independent of the
    /// signal, only while the signal's noise spans a few LSB (Widrow's condition, σ ≳ LSB/2).
    /// Below that the record is mostly one level and the rounding error is minus the signal:
    /// the rounded samples are still independent, their variance far below LSB²/12 (σ = LSB/5
    /// keeps 1.2 % of the samples off zero), and a known LSB²/12 floor put every point below
    /// the model (χ²/dof 332). The lattice is then no term: the white noise describes the
    /// rounded values. Some((LSB, the shortest τ's σ̂)) when its share would pass one half.
    pub fn below_lsb(&self) -> Option<(f64, f64)> {
        let share = self.resolution_share()?;
        (share > 0.5).then(|| (self.lsb.unwrap_or(0.0), self.meas.points[0].dev))
    }

    fn resolution_spec(&self) -> Option<TermSpec> {
        if self.below_lsb().is_some() {
            return None;
        }
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
        let span = crate::effect::drift_span(&self.meas.ctx);
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
                        (Effect::Drift { .. }, _) => a * crate::effect::drift_at(&t.theta, n, span),
                        _ => 0.0,
                    };
                    k += 1;
                }
            }
            any = true;
        }
        any.then_some(y)
    }

    /// The time-domain signals of a term: none for a noise, one for a ramp, a step, the
    /// temperature or a warm-up, one cosine per component for a drift.
    fn signals_of(&self, s: &TermSpec) -> Vec<Signal> {
        let tau0 = self.record.tau0;
        match s.effect {
            Effect::RateRamp => vec![Signal::Ramp],
            Effect::BiasStep => s
                .theta
                .iter()
                .map(|t| Signal::Step { at: t[0] / tau0 })
                .collect(),
            Effect::Temperature => {
                if self.meas.ctx.temp_avar.is_some() {
                    vec![Signal::Temperature]
                } else {
                    s.theta
                        .iter()
                        .map(|t| Signal::WarmUp { kappa: t[0] / tau0 })
                        .collect()
                }
            }
            Effect::Drift { components } => self.drift_signals(components),
            _ => Vec::new(),
        }
    }

    /// The signals of a drift of `components` cosines over this record: the ramp, then the
    /// cosines.
    fn drift_signals(&self, components: u8) -> Vec<Signal> {
        let span = crate::effect::drift_span(&self.meas.ctx);
        std::iter::once(Signal::Ramp)
            .chain((1..=components).map(|j| Signal::Cosine { j, span }))
            .collect()
    }

    /// Fit a model: time-domain terms are estimated on the record with the current noise model
    /// and enter the Allan fit as known terms, in rounds that let the noise model settle
    /// ([`Self::signal_rounds`]).
    pub fn fit(&self, specs: &[TermSpec]) -> Result<Model, FitError> {
        let mut specs = specs.to_vec();
        let is_td = |s: &TermSpec| s.effect.kind() == crate::effect::Kind::Signal;
        let td: Vec<usize> = (0..specs.len()).filter(|&k| is_td(&specs[k])).collect();
        let mut fit = if td.is_empty() {
            fit_model(&self.meas, &specs)?
        } else {
            let noise: Vec<TermSpec> = specs.iter().filter(|s| !is_td(s)).cloned().collect();
            let (f, s) = self.signal_rounds(fit_model(&self.meas, &noise)?, &specs, &td)?;
            specs = s;
            f
        };
        // time-domain σ of the known amplitudes, as amplitude σ: keep coef_sigma = 2|v|σ_v
        for (t, s) in fit.terms.iter_mut().zip(&specs) {
            if let Some(k) = s.known {
                t.coef_sigma = k.coef_sigma;
                t.detected = t.supported();
            }
        }
        let assessment = assess(&fit);
        let findings = self.findings(&specs, &fit);
        let adequate = assessment.adequate && findings.is_empty() && self.defects.is_empty();
        let neg2ll = crate::assess::neg2_loglik(&fit);
        let signals: Vec<Signal> = specs.iter().flat_map(|s| self.signals_of(s)).collect();
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

    /// The time-domain terms `td` of `specs` estimated by GLS on the record under the current
    /// noise model, then the Allan fit with them known, in [`SIGNAL_ROUNDS`] rounds from the
    /// noise-only fit `start`; of the rounds after the first, the one whose model fits the
    /// Allan curve best (least χ²/dof) is kept.
    ///
    /// The rounds need not settle. Under a random walk too small to be detected (K² ≈ 2e-7
    /// beside white noise of 0.02 deg/s) a step is estimated from the samples near it, with
    /// 3–8 times the σ of the estimate under white noise alone, and 1–2 % larger or smaller;
    /// the Allan fit with that estimate drops the walk, the next estimate is white noise's, the
    /// walk comes back: the rounds alternate, and the last one was kept whichever it was, χ²/dof
    /// rising with the right step (0.65 → 6.75) when it was the worse.
    fn signal_rounds(
        &self,
        start: Fit,
        specs: &[TermSpec],
        td: &[usize],
    ) -> Result<(Fit, Vec<TermSpec>), FitError> {
        let mut specs = specs.to_vec();
        let mut f = start;
        let mut best: Option<(Fit, Vec<TermSpec>)> = None;
        // every term's signals, flattened, with the term each belongs to
        let (owner, signals): (Vec<usize>, Vec<Signal>) = (0..specs.len())
            .flat_map(|k| self.signals_of(&specs[k]).into_iter().map(move |g| (k, g)))
            .unzip();
        for round in 0..SIGNAL_ROUNDS {
            let (value, cov) =
                nonstat::joint(&nonstat::gls_scale(&self.blocks), &f.components(), &signals);
            for &k in td {
                let mine: Vec<usize> = (0..owner.len()).filter(|&i| owner[i] == k).collect();
                let v: Vec<f64> = mine.iter().map(|&i| value[i]).collect();
                let c = cov.select_rows(&mine).select_columns(&mine);
                set_known(&mut specs[k], &v, &c, &self.meas.ctx);
            }
            f = fit_model(&self.meas, &specs)?;
            // the first estimate was made under the noise fitted without the signals (a step
            // taken for a random walk): not a candidate; a round whose χ² is not a number is
            // never preferred to one whose χ² is
            let better = |b: &Fit| !b.chi2_dof().is_finite() || f.chi2_dof() < b.chi2_dof();
            if round > 0 && best.as_ref().is_none_or(|(b, _)| better(b)) {
                best = Some((f.clone(), specs.clone()));
            }
        }
        Ok(best.unwrap_or((f, specs)))
    }

    /// The record's non-stationarity that the model does not account for.
    pub fn findings(&self, specs: &[TermSpec], fit: &Fit) -> Vec<Finding> {
        let comps = fit.components();
        if comps.is_empty() {
            return Vec::new();
        }
        let signals: Vec<Signal> = specs.iter().flat_map(|s| self.signals_of(s)).collect();
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
                    "a bias step of {:+.4e} ± {:.1e} {} at t ≈ {} (change-point test on the \
                     time series, likelihood ratio {:.0}, p = {:.1e} after the search over \
                     positions and scales)",
                    st.size,
                    st.sigma,
                    self.record.unit,
                    fmt_s(t),
                    st.lr,
                    st.p_value
                ),
            });
        }
        let has_temp = specs.iter().any(|s| s.effect == Effect::Temperature);
        let has_drift_term = specs
            .iter()
            .any(|s| matches!(s.effect, Effect::Drift { .. }));
        if !has_temp && !has_drift_term {
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
                            "the bias follows the temperature column: {:+.4e} ± {:.1e} {}/°C \
                             (GLS on the time series with the noise model's covariance, \
                             likelihood ratio {:.1}, p = {:.1e})",
                            e.value, e.sigma, self.record.unit, e.lr, p
                        ),
                    });
                }
            } else {
                // warm-up: an exponential beyond what the model's signals (a ramp) explain
                let record = self.record.y.len() as f64 * self.record.tau0;
                let mut best: Option<(f64, nonstat::Estimate)> = None;
                let grid = 24;
                let mut profile = Vec::with_capacity(grid);
                for i in 0..grid {
                    let tw = record / 300.0 * (900.0f64).powf(i as f64 / (grid - 1) as f64);
                    let mut sig = signals.clone();
                    sig.push(Signal::WarmUp {
                        kappa: tw / self.record.tau0,
                    });
                    let est = nonstat::estimate(&gls, &comps, &sig);
                    let e = est.last().expect("warm-up").clone();
                    profile.push((tw, e.lr));
                    if e.lr.is_finite() && best.as_ref().is_none_or(|b| e.lr > b.1.lr) {
                        best = Some((tw, e));
                    }
                }
                // The grid's step (×1.34) misfits a strong exponential, and a drift's cosines
                // then fit it better: the best time constant is refined between its neighbours
                // by golden section on the likelihood ratio (log τ).
                if let Some(b) = best
                    .as_ref()
                    .and_then(|b| profile.iter().position(|p| p.0 == b.0))
                {
                    let warm = |tw: f64| {
                        let mut sig = signals.clone();
                        sig.push(Signal::WarmUp {
                            kappa: tw / self.record.tau0,
                        });
                        nonstat::estimate(&gls, &comps, &sig)
                            .last()
                            .expect("warm-up")
                            .clone()
                    };
                    let (mut lo, mut hi) = (
                        profile[b.saturating_sub(1)].0.ln(),
                        profile[(b + 1).min(grid - 1)].0.ln(),
                    );
                    let g = (5f64.sqrt() - 1.0) / 2.0;
                    let mut seen = |x: f64, e: nonstat::Estimate| {
                        profile.push((x.exp(), e.lr));
                        let lr = e.lr;
                        if lr.is_finite() && best.as_ref().is_none_or(|b| lr > b.1.lr) {
                            best = Some((x.exp(), e));
                        }
                        lr
                    };
                    // one new evaluation a step: the surviving inner point is kept
                    let (mut x1, mut x2) = (hi - g * (hi - lo), lo + g * (hi - lo));
                    let (mut f1, mut f2) = (seen(x1, warm(x1.exp())), seen(x2, warm(x2.exp())));
                    for _ in 0..16 {
                        if f1 > f2 {
                            hi = x2;
                            (x2, f2) = (x1, f1);
                            x1 = hi - g * (hi - lo);
                            f1 = seen(x1, warm(x1.exp()));
                        } else {
                            lo = x1;
                            (x1, f1) = (x2, f2);
                            x2 = lo + g * (hi - lo);
                            f2 = seen(x2, warm(x2.exp()));
                        }
                    }
                    profile.sort_by(|a, b| a.0.total_cmp(&b.0));
                }
                if let Some((tw, e)) = best {
                    let tw_sigma = profile_sigma(&profile, tw, e.lr);
                    let p = (chi2_sf(e.lr, 1.0) * grid as f64).min(1.0);
                    if p < P_SIGNAL {
                        out.push(Finding {
                            effect: Effect::Temperature,
                            spec: TermSpec {
                                theta: Some(vec![tw]),
                                theta_fixed: true,
                                theta_sigma: Some(vec![tw_sigma]),
                                ..TermSpec::new(Effect::Temperature)
                            },
                            p_value: p,
                            text: format!(
                                "a warm-up transient: the bias approaches its final value \
                                 exponentially, amplitude {:+.4e} ± {:.1e} {}, time constant \
                                 {} ± {} (no temperature column; likelihood ratio {:.1}, p = \
                                 {:.1e} after the search over time constants)",
                                e.value,
                                e.sigma,
                                self.record.unit,
                                fmt_s(tw),
                                fmt_s(tw_sigma),
                                e.lr,
                                p
                            ),
                        });
                    }
                }
            }
        }
        // one smooth description of the record's slow change: a drift or a warm-up/temperature,
        // not both (their Allan variances would add where the curves overlap)
        let has_drift = specs
            .iter()
            .any(|s| matches!(s.effect, Effect::Drift { .. }));
        if !has_drift && !has_temp {
            if let Some(f) = self.drift_finding(&signals, &comps) {
                out.push(f);
            }
        }
        out
    }

    /// A smooth drift beyond the model's signals: a ramp and the cosines of the record's length
    /// cos(πjk/T), j = 1 … J, tested in the time domain with the noise model's covariance for
    /// what the cosines add to the ramp. J is the one that maximises the likelihood ratio less
    /// ln(differences) per component (a Schwarz penalty: the smoothest drift the data allow); its
    /// likelihood ratio is tested against χ²_J with a Bonferroni factor for the orders tried.
    fn drift_finding(
        &self,
        signals: &[Signal],
        comps: &[crate::cov::Component],
    ) -> Option<Finding> {
        let gls = nonstat::gls_scale(&self.blocks);
        let n = gls.diffs();
        let jmax = crate::effect::DRIFT_MAX_COMPONENTS.min((n / 8).min(255) as u8);
        if jmax == 0 {
            return None;
        }
        let base: Vec<Signal> = signals
            .iter()
            .filter(|s| **s != Signal::Ramp)
            .copied()
            .collect();
        let extra = self.drift_signals(jmax);
        let lrs = nonstat::nested_lrs(&gls, comps, &base, &extra);
        let pen = (n as f64).ln();
        let (j, lr) = lrs[1..]
            .iter()
            .enumerate()
            .map(|(i, &lr)| (i + 1, lr - lrs[0]))
            .max_by(|a, b| (a.1 - pen * a.0 as f64).total_cmp(&(b.1 - pen * b.0 as f64)))?;
        let p = (chi2_sf(lr, j as f64) * jmax as f64).min(1.0);
        if !(p < P_SIGNAL) {
            return None;
        }
        let mut all = base.clone();
        all.extend_from_slice(&extra[..=j]);
        let (value, cov) = nonstat::joint(&gls, comps, &all);
        let mine: Vec<usize> = (base.len()..all.len()).collect();
        let mut spec = TermSpec::new(Effect::Drift {
            components: j as u8,
        });
        // the shape from this estimate; the size is estimated again with the model's noise
        set_known(
            &mut spec,
            &value[base.len()..],
            &cov.select_rows(&mine).select_columns(&mine),
            &self.meas.ctx,
        );
        let a = spec.known.take()?.coef.sqrt();
        let record = self.record.y.len() as f64 * self.record.tau0;
        Some(Finding {
            effect: spec.effect.clone(),
            spec,
            p_value: p,
            text: format!(
                "a smooth drift of the bias, {:.4e} {} rms over the record: a ramp and {} cosine \
                 component{} of the record's length (the shortest period {}); no step, \
                 exponential or temperature describes it (likelihood ratio {:.1} on {} degrees \
                 of freedom beyond the ramp, p = {:.1e} after the search over orders)",
                a,
                self.record.unit,
                j,
                if j == 1 { "" } else { "s" },
                fmt_s(2.0 * record / j as f64),
                lr,
                j,
                p
            ),
        })
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

    /// Adequate when the Allan test passes and no candidate is admissible: a time-domain finding
    /// the criterion refuses (its refit does not lower it) is reported, not a veto.
    fn settled(&self, m: &Model, refused: &[Candidate<Effect, Model>]) -> bool {
        m.adequate
            || (m.assessment.adequate
                && !refused.iter().any(|c| c.admissible)
                && self.defects.is_empty())
    }
}
