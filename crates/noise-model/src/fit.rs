//! Generalised least-squares fit of a sum of effects to a measured Allan curve.
//!
//! Model: σ²(τ) = Σ_k c_k·b_k(τ; θ_k), c_k ≥ 0 (see [`Effect::basis`]).
//!
//! **Weights.** The octave overlapping Allan estimates are correlated (neighbouring octaves share
//! most of their data) and, on long records, precise to 0.1 % at short τ. The fit minimises the
//! generalised χ² of the logs, rᵀR⁻¹r with r = ln σ̂² − ln σ²_model − β(ν) (β the bias of the log
//! of a χ²_ν/ν variable) and R = C/(mmᵀ), C the covariance of the estimates *under the model*
//! ([`crate::cov`], exact for Gaussian noise on this record's segments) — the weighting GMWM uses
//! in wavelet-variance space (Guerrier et al., JASA 2013), on the logs so that a model above the
//! data costs what one below does. Gauss–Newton: the residual linearised at the current model is
//! a variance-space problem with the same whitening, L⁻¹S⁻¹(t − b·c), C = S ρ S, ρ = L Lᵀ, solved
//! by Lawson–Hanson NNLS; C and the linearisation are recomputed from the new model (at most
//! [`OUTER_ITERATIONS`] times), each step damped until the log criterion falls.
//! When only points are known (e.g. a device's table without its record), C is diagonal from the
//! points' EDFs, var(σ̂²) = 2σ⁴/ν (NIST SP 1065 §5.3), the model's σ⁴ in place of the noisy
//! measurement's.
//!
//! **Non-linear parameters** (τ_c, f, a filter corner or length, a user effect's parameters) are
//! found on the profile χ² (NNLS inside): a dense grid over the effect's range, then a bounded
//! golden-section refinement, several parameters by coordinate descent.
//!
//! **Uncertainties.** Cov = (JᵀC⁻¹J)⁻¹ at the optimum over every coefficient and free non-linear
//! parameter, scaled by χ²/dof when that exceeds 1 (Bevington & Robinson, *Data Reduction and
//! Error Analysis*, §8.5). Every term reports its estimate, σ and interval whether or not it is
//! detected (its 95 % interval excludes 0); the model curve is exactly Σ c_k b_k with the reported values.
use crate::cov::{Component, CovCache, Design, Deterministic};
use crate::effect::{Basis, Context, Effect, Kind, ParamSpec};
use crate::nnls::nnls;
use nalgebra::{DMatrix, DVector};
use std::fmt;
use std::sync::Arc;

mod solve;
pub use crate::optim::golden_min;
pub use solve::fit_model;

/// Outer iterations of the covariance update.
pub const OUTER_ITERATIONS: usize = 4;
/// Golden-section iterations per non-linear parameter.
const GOLDEN_ITERATIONS: usize = 60;
/// Coordinate-descent rounds over several non-linear parameters.
const NONLINEAR_ROUNDS: usize = 4;

/// One measured Allan point: τ [s], the deviation and its 68.3 % bounds [u], its EDF (as the
/// estimator reported it), and the averaging factor m (0 when unknown: derived from τ/τ0).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Point {
    pub tau: f64,
    pub dev: f64,
    pub edf: f64,
    pub lo: f64,
    pub hi: f64,
    pub m: u64,
}

/// Why a fit could not be made.
#[derive(Debug, Clone, PartialEq)]
pub enum FitError {
    /// A point has a non-finite or non-positive τ, deviation, EDF or bounds.
    BadPoint { index: usize, what: String },
    /// Fewer usable points than parameters + 1.
    TooFewPoints { points: usize, params: usize },
    /// The same effect was listed twice, no effect at all, or a bad parameter.
    BadTerms(String),
    /// A numerical routine did not converge within its iteration cap.
    NoConvergence(String),
    /// A statistic of the fit came out NaN or infinite: the step failed, with its cause (never a
    /// verdict: a comparison with NaN is false, and must not read as a pass).
    NonFinite(String),
}

impl fmt::Display for FitError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            FitError::BadPoint { index, what } => write!(f, "Allan point {index}: {what}"),
            FitError::TooFewPoints { points, params } => write!(
                f,
                "{points} usable τ points cannot constrain {params} parameters (need at least \
                 {} — record longer or use fewer terms)",
                params + 1
            ),
            FitError::BadTerms(s) => write!(f, "{s}"),
            FitError::NoConvergence(s) => write!(f, "{s}"),
            FitError::NonFinite(s) => write!(f, "the fit failed: {s} is not a finite number"),
        }
    }
}

impl std::error::Error for FitError {}

/// How the covariance of the Allan estimates is obtained.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Weighting {
    /// The full covariance under the model, for points computed by the overlapping estimator
    /// from the record described by the context.
    Model,
    /// Independent points with the EDFs they came with.
    Diagonal,
}

/// What the fit is given: the points, what is known about the record, and how to weight.
#[derive(Debug, Clone)]
pub struct Measurement {
    pub points: Vec<Point>,
    pub ctx: Context,
    pub weighting: Weighting,
    /// The covariance pieces of this design, shared by every fit of the measurement.
    pub cache: Arc<CovCache>,
}

impl Measurement {
    /// A measurement; points without an averaging factor get m = round(τ/τ0).
    pub fn new(points: Vec<Point>, ctx: Context, weighting: Weighting) -> Measurement {
        let points = with_m(points, ctx.tau0);
        let cache = Arc::new(CovCache::new(Design {
            ms: points.iter().map(|p| p.m).collect(),
            segments: ctx.segments.iter().map(|s| s.1).collect(),
        }));
        Measurement {
            points,
            ctx,
            weighting,
            cache,
        }
    }

    /// Points from an uninterrupted record of `n` samples at `tau0` (full covariance).
    pub fn from_record(points: Vec<Point>, tau0: f64, n: u64) -> Measurement {
        let mut ctx = Context::uniform(tau0, n);
        set_range(&mut ctx, &points);
        Measurement::new(points, ctx, Weighting::Model)
    }

    /// Points alone (diagonal weights from their EDFs).
    pub fn from_points(points: Vec<Point>, tau0: f64) -> Measurement {
        let longest = points.iter().map(|p| p.tau).fold(tau0, f64::max);
        let mut ctx = Context::uniform(tau0, ((longest / tau0) * 4.0).ceil() as u64);
        set_range(&mut ctx, &points);
        Measurement::new(points, ctx, Weighting::Diagonal)
    }
}

fn with_m(mut points: Vec<Point>, tau0: f64) -> Vec<Point> {
    for p in &mut points {
        if p.m == 0 {
            p.m = (p.tau / tau0).round().max(1.0) as u64;
        }
    }
    points
}

/// Set the context's τ range from the points.
pub fn set_range(ctx: &mut Context, points: &[Point]) {
    if !points.is_empty() {
        ctx.tau_min = points.iter().map(|p| p.tau).fold(f64::INFINITY, f64::min);
        ctx.tau_max = points.iter().map(|p| p.tau).fold(0.0, f64::max);
    }
}

/// A term to fit: the effect, optional starting or fixed non-linear parameters, and optionally a
/// coefficient estimated elsewhere (time domain, data lattice) that the Allan fit takes as known.
#[derive(Debug, Clone, PartialEq)]
pub struct TermSpec {
    pub effect: Effect,
    /// Starting values of the non-linear parameters (searched from these when given).
    pub theta: Option<Vec<f64>>,
    /// Keep the non-linear parameters at `theta` (e.g. a sinusoid at its periodogram line).
    pub theta_fixed: bool,
    /// 1σ of fixed non-linear parameters, when known.
    pub theta_sigma: Option<Vec<f64>>,
    /// A known coefficient c with its 1σ and the sign of the amplitude (time-domain estimates).
    pub known: Option<Known>,
}

/// A coefficient estimated outside the Allan fit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Known {
    pub coef: f64,
    pub coef_sigma: f64,
    /// Sign of the amplitude (a step up or down, a positive or negative coefficient).
    pub sign: f64,
}

impl TermSpec {
    pub fn new(effect: Effect) -> TermSpec {
        TermSpec {
            effect,
            theta: None,
            theta_fixed: false,
            theta_sigma: None,
            known: None,
        }
    }
}

impl From<Effect> for TermSpec {
    fn from(e: Effect) -> Self {
        TermSpec::new(e)
    }
}

/// Optional search hints, for the points-only entry point [`fit`].
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct FitOptions {
    /// A frequency [Hz] to include in the sinusoid search (e.g. the PSD line).
    pub freq_hint: Option<f64>,
    /// A correlation time [s] to include in the Markov search.
    pub tau_c_hint: Option<f64>,
    /// Fix the sinusoid frequency (value [Hz], 1σ [Hz]) instead of searching it.
    pub freq_fixed: Option<(f64, f64)>,
}

/// A fitted term.
#[derive(Debug, Clone, PartialEq)]
pub struct TermFit {
    pub effect: Effect,
    /// Linear coefficient c = amplitude² (canonical units squared), ≥ 0.
    pub coef: f64,
    /// 1σ of `coef`.
    pub coef_sigma: f64,
    /// Sign of the amplitude for signed effects (step size, temperature coefficient); +1 else.
    pub sign: f64,
    /// The non-linear parameters (names in `specs`).
    pub theta: Vec<f64>,
    pub theta_sigma: Vec<f64>,
    pub specs: Vec<ParamSpec>,
    /// The coefficient was estimated outside the Allan fit (time domain or data lattice).
    pub known: bool,
    /// Whether the data support the term: its 95 % interval excludes 0 ([`TermFit::supported`]).
    pub detected: bool,
}

/// A named parameter value in canonical units.
#[derive(Debug, Clone, PartialEq)]
pub struct ParamValue {
    pub name: String,
    /// Best estimate (the value the model uses).
    pub value: f64,
    /// 1σ uncertainty (NaN when not defined).
    pub sigma: f64,
    /// 95 % interval (2σ on the coefficient for amplitudes, bounded at 0).
    pub interval: (f64, f64),
    /// For a term not detected: the 2σ (≈ 97.7 % one-sided) upper bound of the amplitude.
    pub upper_bound: Option<f64>,
}

impl TermFit {
    /// The data support the term when its 95 % interval excludes 0: c > 2σ_c for a coefficient
    /// of the Allan fit, |A| > 2σ_A for an amplitude estimated in the time domain.
    pub fn supported(&self) -> bool {
        let (lo, hi) = self.amplitude_interval();
        self.coef > 0.0 && self.coef_sigma.is_finite() && lo * hi > 0.0
    }

    /// The amplitude parameter √c (Q, N, B, K, R, sigma, amplitude), signed where it has a sign.
    pub fn amplitude(&self) -> f64 {
        self.sign * self.coef.max(0.0).sqrt()
    }

    /// 1σ of the amplitude: half the width of [√(c − σ_c), √(c + σ_c)] (σ_c/(2A) when A ≫ σ_A;
    /// finite at c = 0). A known term's amplitude was estimated in the time domain, where it is
    /// Gaussian with σ_A and σ_c = 2|A|σ_A was derived from it: σ_A is given back exactly.
    pub fn amplitude_sigma(&self) -> f64 {
        let s = if self.coef_sigma.is_finite() {
            self.coef_sigma
        } else {
            return f64::NAN;
        };
        if self.known && self.coef > 0.0 {
            return s / (2.0 * self.coef.sqrt());
        }
        ((self.coef.max(0.0) + s).sqrt() - (self.coef - s).max(0.0).sqrt()) / 2.0
    }

    /// 95 % interval of |amplitude|: √ of c ± 2σ_c, bounded at 0; for a known term (Gaussian in
    /// its amplitude) |A| ± 2σ_A, bounded at 0.
    pub fn amplitude_interval(&self) -> (f64, f64) {
        let s = if self.coef_sigma.is_finite() {
            self.coef_sigma
        } else {
            0.0
        };
        let (lo, hi) = if self.known && self.coef > 0.0 {
            let (a, sa) = (self.coef.sqrt(), self.amplitude_sigma());
            ((a - 2.0 * sa).max(0.0), a + 2.0 * sa)
        } else {
            (
                (self.coef - 2.0 * s).max(0.0).sqrt(),
                (self.coef.max(0.0) + 2.0 * s).sqrt(),
            )
        };
        if self.sign < 0.0 {
            (-hi, -lo)
        } else {
            (lo, hi)
        }
    }

    /// Upper bound √(max(c,0) + 2σ_c) when the term is not detected.
    pub fn upper_bound(&self) -> Option<f64> {
        (!self.detected).then(|| self.amplitude_interval().1.abs())
    }

    /// τ_c / f / corner / length: the first non-linear parameter, if any.
    pub fn theta0(&self) -> Option<f64> {
        self.theta.first().copied()
    }

    /// Parameters in canonical units: amplitude, then the non-linear ones.
    pub fn params(&self) -> Vec<ParamValue> {
        let mut v = vec![ParamValue {
            name: self.effect.amp_name().to_string(),
            value: self.amplitude(),
            sigma: self.amplitude_sigma(),
            interval: self.amplitude_interval(),
            upper_bound: self.upper_bound(),
        }];
        for (i, s) in self.specs.iter().enumerate() {
            let val = self.theta.get(i).copied().unwrap_or(f64::NAN);
            let sig = self.theta_sigma.get(i).copied().unwrap_or(f64::NAN);
            v.push(ParamValue {
                name: s.name.clone(),
                value: val,
                sigma: sig,
                interval: if sig.is_finite() {
                    (val - 2.0 * sig, val + 2.0 * sig)
                } else {
                    (f64::NAN, f64::NAN)
                },
                upper_bound: None,
            });
        }
        v
    }
}

/// The result of a fit.
#[derive(Debug, Clone)]
pub struct Fit {
    pub tau0: f64,
    pub points: Vec<Point>,
    pub ctx: Context,
    pub weighting: Weighting,
    pub terms: Vec<TermFit>,
    /// Model Allan variance at each point (Σ c·b with the reported parameters).
    pub model_avar: Vec<f64>,
    /// Covariance of the Allan variance estimates under the model [u⁴].
    pub point_cov: DMatrix<f64>,
    /// EDF of each point under the model, 2σ⁴/var(σ̂²).
    pub model_edf: Vec<f64>,
    /// The goodness-of-fit statistic T = zᵀρ⁻¹z of the points' exact z-scores
    /// ([`crate::assess::statistic`]), χ² with `dof` degrees of freedom for a complete model.
    pub chi2: f64,
    /// The fit's criterion, the generalised χ² rᵀC⁻¹r in variance space, at the optimum.
    pub objective: f64,
    /// Degrees of freedom of the goodness-of-fit statistic: points minus free parameters, a
    /// parameter at its bound counting ½ (at least 1).
    pub dof: f64,
    /// Covariance of the free parameters, in the order of `param_index`.
    pub param_cov: DMatrix<f64>,
    /// (term, 0 = coefficient / i+1 = non-linear parameter i) for each row of `param_cov`.
    pub param_index: Vec<(usize, usize)>,
    per_term_basis: Vec<Vec<f64>>,
}

impl PartialEq for Fit {
    fn eq(&self, o: &Self) -> bool {
        self.terms == o.terms && self.model_avar == o.model_avar && self.chi2 == o.chi2
    }
}

impl Fit {
    /// z-scores of the points against the model and the statistic T ([`crate::zscore`]): with
    /// the model's EDFs and the estimates' correlation under model weighting, the points' own
    /// EDFs and no correlation under diagonal weighting.
    pub fn statistic(&self) -> (Vec<f64>, f64) {
        let dev = self.points.iter().map(|p| p.dev);
        match self.weighting {
            Weighting::Model => crate::zscore::t_statistic(
                dev,
                &self.model_edf,
                &self.model_avar,
                Some(&self.point_cov),
            ),
            Weighting::Diagonal => {
                let edf: Vec<f64> = self.points.iter().map(|p| p.edf).collect();
                crate::zscore::t_statistic(dev, &edf, &self.model_avar, None)
            }
        }
    }

    pub fn chi2_dof(&self) -> f64 {
        self.chi2 / self.dof.max(1.0)
    }

    /// Model Allan deviation at any τ, from the reported parameters.
    pub fn model_dev(&self, tau: f64) -> f64 {
        self.model_avar_at(tau).max(0.0).sqrt()
    }

    /// Model Allan variance at any τ.
    pub fn model_avar_at(&self, tau: f64) -> f64 {
        self.terms
            .iter()
            .map(|t| t.avar(tau, &self.ctx))
            .sum::<f64>()
    }

    pub fn effects(&self) -> Vec<Effect> {
        self.terms.iter().map(|t| t.effect.clone()).collect()
    }

    pub fn term(&self, e: &Effect) -> Option<&TermFit> {
        self.terms.iter().find(|t| t.effect == *e)
    }

    /// Number of free parameters.
    pub fn n_params(&self) -> usize {
        self.param_index.len()
    }

    /// 1σ of the model's Allan deviation at point `i`, propagated from the free parameters'
    /// covariance (`param_cov`: a coefficient's derivative is its basis at the point, a
    /// non-linear parameter's a central difference) plus each known term's own σ (estimated
    /// outside the Allan fit, independent of it): δσ = δ(σ²)/(2σ). NaN when the model's
    /// variance is not positive or an uncertainty it rests on is not finite.
    pub fn model_dev_sigma(&self, i: usize) -> f64 {
        let avar = self.model_avar[i];
        if !(avar > 0.0) {
            return f64::NAN;
        }
        let tau = self.points[i].tau;
        let g: Vec<f64> = self
            .param_index
            .iter()
            .map(|&(k, j)| {
                let t = &self.terms[k];
                if j == 0 {
                    return self.per_term_basis[k][i];
                }
                let mut tt = t.clone();
                let x = t.theta[j - 1];
                let h = (x.abs() * 1e-6).max(1e-12);
                tt.theta[j - 1] = x + h;
                let up = tt.avar(tau, &self.ctx);
                tt.theta[j - 1] = x - h;
                let down = tt.avar(tau, &self.ctx);
                (up - down) / (2.0 * h)
            })
            .collect();
        let mut var = 0.0;
        for (a, ga) in g.iter().enumerate() {
            for (b, gb) in g.iter().enumerate() {
                var += ga * self.param_cov[(a, b)] * gb;
            }
        }
        for (k, t) in self.terms.iter().enumerate() {
            // A known term in the model whose σ is not finite leaves the model's σ unknown.
            if t.known && (t.coef_sigma.is_finite() || t.coef > 0.0) {
                var += (self.per_term_basis[k][i] * t.coef_sigma).powi(2);
            }
        }
        // A covariance with NaN in it gives NaN here, which must stay NaN: `f64::max` would
        // turn it into 0, a model reported as exactly known.
        if !var.is_finite() {
            return f64::NAN;
        }
        var.max(0.0).sqrt() / (2.0 * avar.sqrt())
    }

    /// This term's share of the model variance at each point.
    pub fn term_avar(&self, k: usize) -> Vec<f64> {
        let t = &self.terms[k];
        self.per_term_basis[k].iter().map(|b| t.coef * b).collect()
    }

    /// The stochastic part of the model as structure-function components (for the covariance of
    /// Allan estimates and the time-domain tests).
    pub fn components(&self) -> Vec<Component> {
        self.terms
            .iter()
            .filter(|t| t.coef > 0.0)
            .filter_map(|t| match t.effect.basis(&t.theta, &self.ctx) {
                Ok(Basis::Stochastic { structure, factor }) => Some(Component {
                    coef: t.coef * factor,
                    structure,
                }),
                _ => None,
            })
            .collect()
    }

    /// Correlation between two free parameters (rows of `param_cov`).
    pub fn param_corr(&self, a: usize, b: usize) -> f64 {
        let c = &self.param_cov;
        c[(a, b)] / (c[(a, a)] * c[(b, b)]).sqrt()
    }
}

impl TermFit {
    /// This term's Allan variance at τ.
    pub fn avar(&self, tau: f64, ctx: &Context) -> f64 {
        if self.coef <= 0.0 {
            return 0.0;
        }
        match self.effect.basis(&self.theta, ctx) {
            Ok(b) => self.coef * b.avar(tau / ctx.tau0, ctx.tau0),
            Err(_) => f64::NAN,
        }
    }
}

/// Fit `effects` to points alone (diagonal weights from their EDFs), e.g. a device's table.
pub fn fit(
    points: &[Point],
    tau0: f64,
    effects: &[Effect],
    opts: &FitOptions,
) -> Result<Fit, FitError> {
    let meas = Measurement::from_points(points.to_vec(), tau0);
    let specs: Vec<TermSpec> = effects
        .iter()
        .map(|e| {
            let mut s = TermSpec::new(e.clone());
            match e {
                Effect::Sinusoid => {
                    if let Some((f, sf)) = opts.freq_fixed {
                        s.theta = Some(vec![f]);
                        s.theta_fixed = true;
                        s.theta_sigma = Some(vec![sf]);
                    } else if let Some(f) = opts.freq_hint {
                        s.theta = Some(vec![f]);
                    }
                }
                Effect::Markov => s.theta = opts.tau_c_hint.map(|t| vec![t]),
                _ => {}
            }
            s
        })
        .collect();
    fit_model(&meas, &specs)
}

impl Point {
    /// Convert deviation rows of the `allan` crate (OADEV is what the fit expects), in τ order.
    ///
    /// Rows whose EDF or bounds are not finite cannot be weighted and are left out (the second
    /// value counts them).
    pub fn from_rows(rows: &[allan::Row]) -> (Vec<Point>, usize) {
        let mut skipped = 0;
        let mut pts = Vec::new();
        for r in rows {
            let ok = r.tau > 0.0
                && r.dev > 0.0
                && r.dev.is_finite()
                && r.edf.is_finite()
                && r.edf > 0.0
                && r.lo.is_finite()
                && r.hi.is_finite();
            if !ok {
                skipped += 1;
                continue;
            }
            pts.push(Point {
                tau: r.tau,
                dev: r.dev,
                edf: r.edf,
                lo: r.lo,
                hi: r.hi,
                m: r.m,
            });
        }
        (pts, skipped)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn term(coef: f64, coef_sigma: f64, known: bool, sign: f64) -> TermFit {
        TermFit {
            effect: Effect::BiasStep,
            coef,
            coef_sigma,
            sign,
            theta: vec![],
            theta_sigma: vec![],
            specs: vec![],
            known,
            detected: false,
        }
    }

    /// A time-domain amplitude is Gaussian: at |A| = 3σ_A (random A, either sign) it is detected,
    /// its σ is σ_A and its interval |A| ± 2σ_A; an Allan coefficient keeps c > 2σ_c; a σ that
    /// is not a number never detects.
    #[test]
    fn a_term_is_detected_when_its_interval_excludes_zero() {
        let mut x = 0x2545_f491_4f6c_dd1du64;
        for _ in 0..50 {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            let a = 1e-4 * (1.0 + (x % 1000) as f64);
            let sign = if x & 1 == 0 { 1.0 } else { -1.0 };
            for (k, expect) in [(3.0, true), (1.5, false)] {
                let sa = a / k;
                let t = term(a * a, 2.0 * a * sa, true, sign);
                assert!((t.amplitude_sigma() / sa - 1.0).abs() < 1e-12);
                let (lo, hi) = t.amplitude_interval();
                assert!((hi.abs().max(lo.abs()) - (a + 2.0 * sa)).abs() < 1e-12 * a);
                assert_eq!(t.supported(), expect, "A = {a}, σ_A = {sa}, sign {sign}");
                // the same numbers as an Allan coefficient: c > 2σ_c, i.e. A > 4σ_A
                assert!(!term(a * a, 2.0 * a * sa, false, sign).supported());
            }
            assert!(term(a * a, 0.1 * a * a, false, 1.0).supported());
            assert!(!term(a * a, f64::NAN, true, sign).supported());
            assert!(!term(0.0, 0.0, true, sign).supported());
        }
    }
}
