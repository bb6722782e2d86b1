//! Weighted least-squares fit of a sum of effects to a measured Allan curve.
//!
//! Model: σ²(τ) = Σ_k c_k·b_k(τ; θ_k), c_k ≥ 0 (see [`Effect::basis`]).
//! Weights: an Allan-variance estimate with ν equivalent degrees of freedom is distributed as
//! σ²·χ²_ν/ν, so var(σ̂²) ≈ 2σ⁴/ν (NIST SP 1065 §5.3). The fit minimises
//! χ² = Σ_j ν_j (σ̂²_j − σ²_model,j)² / (2 σ⁴_model,j) by iteratively re-weighted non-negative least
//! squares: the weights use the model (not the noisy measurement, whose low points would otherwise
//! pull the fit down), starting from the measurement. The non-linear parameters τ_c (markov) and
//! f (sinusoid) are found by a dense logarithmic grid search of the profile χ² followed by a
//! golden-section refinement; several non-linear terms are refined by coordinate descent.
//! Uncertainties: the inverse of the Fisher matrix JᵀWJ at the optimum, scaled by χ²/dof when that
//! exceeds 1 (Bevington & Robinson, *Data Reduction and Error Analysis*, §8.5).
use crate::effect::Effect;
use crate::nnls::nnls;
use nalgebra::{DMatrix, DVector};
use std::fmt;

/// One measured Allan point: τ [s], the deviation and its 68.3 % bounds [u], and its EDF.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Point {
    pub tau: f64,
    pub dev: f64,
    pub edf: f64,
    pub lo: f64,
    pub hi: f64,
}

/// Why a fit could not be made.
#[derive(Debug, Clone, PartialEq)]
pub enum FitError {
    /// A point has a non-finite or non-positive τ, deviation, EDF or bounds.
    BadPoint { index: usize, what: String },
    /// Fewer usable points than parameters + 1.
    TooFewPoints { points: usize, params: usize },
    /// The same effect was listed twice, or no effect at all.
    BadTerms(String),
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
        }
    }
}

impl std::error::Error for FitError {}

/// Optional starting information for the non-linear parameters.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct FitOptions {
    /// A frequency [Hz] to include in the sinusoid search (e.g. the PSD line).
    pub freq_hint: Option<f64>,
    /// A correlation time [s] to include in the Markov search.
    pub tau_c_hint: Option<f64>,
    /// Fix the sinusoid frequency (value [Hz], 1σ [Hz]) instead of searching it, e.g. to the
    /// periodogram peak, which resolves f far better than octave-spaced Allan points.
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
    /// τ_c [s] or f [Hz] for markov / sinusoid, when the term is present.
    pub theta: Option<f64>,
    pub theta_sigma: Option<f64>,
    /// Whether the data support the term: c > 2σ_c.
    pub detected: bool,
}

/// A named parameter value in canonical units.
#[derive(Debug, Clone, PartialEq)]
pub struct ParamValue {
    pub name: &'static str,
    /// Best estimate (0 when not detected).
    pub value: f64,
    /// 1σ uncertainty (NaN when not defined).
    pub sigma: f64,
    /// For a term not detected: the 2σ (≈97.7 % one-sided) upper bound.
    pub upper_bound: Option<f64>,
}

impl TermFit {
    /// The amplitude parameter √c (Q, N, B, K, R, sigma, amplitude).
    pub fn amplitude(&self) -> f64 {
        self.coef.max(0.0).sqrt()
    }

    /// 1σ of the amplitude by propagation σ_A = σ_c / (2A).
    pub fn amplitude_sigma(&self) -> f64 {
        let a = self.amplitude();
        if a > 0.0 {
            self.coef_sigma / (2.0 * a)
        } else {
            f64::NAN
        }
    }

    /// Upper bound √(max(c,0) + 2σ_c) when the term is not detected.
    pub fn upper_bound(&self) -> Option<f64> {
        if self.detected {
            None
        } else {
            let s = if self.coef_sigma.is_finite() {
                self.coef_sigma
            } else {
                0.0
            };
            Some((self.coef.max(0.0) + 2.0 * s).sqrt())
        }
    }

    /// Parameters in canonical units, in the order amplitude, non-linear.
    pub fn params(&self) -> Vec<ParamValue> {
        let mut v = vec![ParamValue {
            name: self.effect.amp_name(),
            value: if self.detected { self.amplitude() } else { 0.0 },
            sigma: if self.detected {
                self.amplitude_sigma()
            } else {
                f64::NAN
            },
            upper_bound: self.upper_bound(),
        }];
        if let Some(name) = self.effect.nonlinear_name() {
            v.push(ParamValue {
                name,
                value: if self.detected {
                    self.theta.unwrap_or(f64::NAN)
                } else {
                    f64::NAN
                },
                sigma: if self.detected {
                    self.theta_sigma.unwrap_or(f64::NAN)
                } else {
                    f64::NAN
                },
                upper_bound: None,
            });
        }
        v
    }

    /// This term's Allan variance at τ.
    pub fn avar(&self, tau: f64, tau0: f64) -> f64 {
        self.coef.max(0.0) * self.effect.basis(tau, tau0, self.theta.unwrap_or(f64::NAN))
    }
}

/// The result of a fit.
#[derive(Debug, Clone, PartialEq)]
pub struct Fit {
    pub tau0: f64,
    pub points: Vec<Point>,
    pub terms: Vec<TermFit>,
    /// Model Allan variance at each point.
    pub model_avar: Vec<f64>,
    pub chi2: f64,
    pub dof: usize,
}

impl Fit {
    pub fn chi2_dof(&self) -> f64 {
        self.chi2 / self.dof.max(1) as f64
    }

    /// Model Allan deviation at any τ.
    pub fn model_dev(&self, tau: f64) -> f64 {
        self.terms
            .iter()
            .map(|t| t.avar(tau, self.tau0))
            .sum::<f64>()
            .sqrt()
    }

    pub fn effects(&self) -> Vec<Effect> {
        self.terms.iter().map(|t| t.effect).collect()
    }

    pub fn term(&self, e: Effect) -> Option<&TermFit> {
        self.terms.iter().find(|t| t.effect == e)
    }

    /// Number of fitted parameters.
    pub fn n_params(&self) -> usize {
        self.terms.iter().map(|t| t.effect.n_params()).sum()
    }
}

fn validate(points: &[Point]) -> Result<(), FitError> {
    for (i, p) in points.iter().enumerate() {
        let bad = |what: &str| {
            Err(FitError::BadPoint {
                index: i,
                what: format!("{what} (τ = {} s, dev = {}, edf = {})", p.tau, p.dev, p.edf),
            })
        };
        if !(p.tau.is_finite() && p.tau > 0.0) {
            return bad("τ is not a positive finite number");
        }
        if !(p.dev.is_finite() && p.dev > 0.0) {
            return bad("deviation is not a positive finite number");
        }
        if !(p.edf.is_finite() && p.edf > 0.0) {
            return bad("EDF is not a positive finite number");
        }
        if !(p.lo.is_finite() && p.hi.is_finite() && p.lo <= p.dev && p.dev <= p.hi) {
            return bad("confidence bounds do not bracket the deviation");
        }
    }
    Ok(())
}

/// Internal evaluation: coefficients, model, χ² for fixed non-linear parameters.
struct LinSol {
    coef: Vec<f64>,
    model: Vec<f64>,
    chi2: f64,
}

struct Problem<'a> {
    points: &'a [Point],
    tau0: f64,
    effects: &'a [Effect],
    meas: Vec<f64>,
}

/// Floor applied to the model variance in the weights, relative to the measurement, so that a
/// model that is (for now) far too low cannot create infinite weights.
const MODEL_FLOOR: f64 = 1e-3;

impl Problem<'_> {
    fn basis(&self, thetas: &[f64]) -> DMatrix<f64> {
        let n = self.points.len();
        let p = self.effects.len();
        DMatrix::from_fn(n, p, |j, k| {
            self.effects[k].basis(self.points[j].tau, self.tau0, thetas[k])
        })
    }

    fn chi2_of(&self, model: &[f64]) -> f64 {
        self.points
            .iter()
            .zip(model)
            .zip(&self.meas)
            .map(|((p, &m), &y)| {
                let v = m.max(MODEL_FLOOR * y);
                p.edf * (y - v).powi(2) / (2.0 * v * v)
            })
            .sum()
    }

    fn solve(&self, thetas: &[f64]) -> LinSol {
        let n = self.points.len();
        let p = self.effects.len();
        let bmat = self.basis(thetas);
        let mut var_w: Vec<f64> = self.meas.clone();
        let mut coef = vec![0.0; p];
        let mut model = vec![0.0; n];
        for _iter in 0..12 {
            let sw: Vec<f64> = (0..n)
                .map(|j| (self.points[j].edf / 2.0).sqrt() / var_w[j])
                .collect();
            let mut a = DMatrix::<f64>::zeros(n, p);
            let mut scale = vec![0.0; p];
            for k in 0..p {
                let mut s2 = 0.0;
                for j in 0..n {
                    let v = sw[j] * bmat[(j, k)];
                    a[(j, k)] = if v.is_finite() { v } else { 0.0 };
                    s2 += a[(j, k)] * a[(j, k)];
                }
                scale[k] = s2.sqrt();
                if scale[k] > 0.0 {
                    for j in 0..n {
                        a[(j, k)] /= scale[k];
                    }
                }
            }
            let b = DVector::from_iterator(n, (0..n).map(|j| sw[j] * self.meas[j]));
            let x = nnls(&a, &b);
            let new_coef: Vec<f64> = (0..p)
                .map(|k| if scale[k] > 0.0 { x[k] / scale[k] } else { 0.0 })
                .collect();
            for (j, mj) in model.iter_mut().enumerate() {
                *mj = (0..p)
                    .map(|k| new_coef[k] * bmat[(j, k)])
                    .filter(|v| v.is_finite())
                    .sum();
            }
            let change = new_coef
                .iter()
                .zip(&coef)
                .map(|(a, b)| (a - b).abs() / a.abs().max(b.abs()).max(1e-300))
                .fold(0.0, f64::max);
            coef = new_coef;
            for j in 0..n {
                var_w[j] = model[j].max(MODEL_FLOOR * self.meas[j]);
            }
            if change < 1e-9 {
                break;
            }
        }
        let chi2 = self.chi2_of(&model);
        LinSol { coef, model, chi2 }
    }

    fn tau_range(&self) -> (f64, f64) {
        let lo = self
            .points
            .iter()
            .map(|p| p.tau)
            .fold(f64::INFINITY, f64::min);
        let hi = self.points.iter().map(|p| p.tau).fold(0.0, f64::max);
        (lo, hi)
    }

    /// Logarithmic search grid for the non-linear parameter of effect k.
    fn grid(&self, e: Effect, opts: &FitOptions) -> Vec<f64> {
        let (tmin, tmax) = self.tau_range();
        let (lo, hi, per_decade, hint) = match e {
            Effect::Markov => (
                (tmin / 4.0).max(self.tau0 / 8.0),
                tmax * 4.0,
                16.0,
                opts.tau_c_hint,
            ),
            Effect::Sinusoid => {
                if let Some((f, _)) = opts.freq_fixed {
                    return vec![f];
                }
                (
                    0.25 / tmax,
                    0.5 / self.tau0.max(tmin * 1e-3),
                    80.0,
                    opts.freq_hint,
                )
            }
            _ => return vec![f64::NAN],
        };
        let hi = hi * 0.999;
        let decades = (hi / lo).log10().max(0.1);
        let n = (decades * per_decade).ceil() as usize + 1;
        let mut g: Vec<f64> = (0..n)
            .map(|i| lo * (hi / lo).powf(i as f64 / (n - 1) as f64))
            .collect();
        if let Some(h) = hint {
            if h > lo && h < hi {
                g.push(h);
                g.sort_by(f64::total_cmp);
            }
        }
        g
    }

    /// Minimise χ² over θ_k with the others fixed: grid, then golden section around the best.
    fn refine(&self, k: usize, thetas: &mut [f64], opts: &FitOptions) -> f64 {
        let g = self.grid(self.effects[k], opts);
        let eval = |th: &mut Vec<f64>, v: f64| {
            th[k] = v;
            self.solve(th).chi2
        };
        let mut th = thetas.to_vec();
        let mut best = (f64::INFINITY, 0usize);
        for (i, &v) in g.iter().enumerate() {
            let c = eval(&mut th, v);
            if c < best.0 {
                best = (c, i);
            }
        }
        let i = best.1;
        if g.len() == 1 {
            thetas[k] = g[0];
            return best.0;
        }
        let (mut a, mut b) = (
            g[i.saturating_sub(1)].ln(),
            g[(i + 1).min(g.len() - 1)].ln(),
        );
        let r = 0.618_033_988_749_895;
        let mut x1 = b - r * (b - a);
        let mut x2 = a + r * (b - a);
        let mut f1 = eval(&mut th, x1.exp());
        let mut f2 = eval(&mut th, x2.exp());
        for _ in 0..40 {
            if f1 < f2 {
                b = x2;
                x2 = x1;
                f2 = f1;
                x1 = b - r * (b - a);
                f1 = eval(&mut th, x1.exp());
            } else {
                a = x1;
                x1 = x2;
                f1 = f2;
                x2 = a + r * (b - a);
                f2 = eval(&mut th, x2.exp());
            }
            if (b - a).abs() < 1e-7 {
                break;
            }
        }
        let (xm, fm) = if f1 < f2 { (x1, f1) } else { (x2, f2) };
        if fm <= best.0 {
            thetas[k] = xm.exp();
            fm
        } else {
            thetas[k] = g[i];
            best.0
        }
    }
}

/// Fit `effects` to the measured points (`tau0` = sampling interval [s]).
pub fn fit(
    points: &[Point],
    tau0: f64,
    effects: &[Effect],
    opts: &FitOptions,
) -> Result<Fit, FitError> {
    validate(points)?;
    if effects.is_empty() {
        return Err(FitError::BadTerms("no terms to fit".into()));
    }
    for (i, e) in effects.iter().enumerate() {
        if effects[..i].contains(e) {
            return Err(FitError::BadTerms(format!("term {e} listed twice")));
        }
    }
    if !(tau0 > 0.0 && tau0.is_finite()) {
        return Err(FitError::BadTerms(format!(
            "sampling interval τ0 = {tau0} s is not positive"
        )));
    }
    let n_params: usize = effects.iter().map(|e| e.n_params()).sum();
    if points.len() < n_params + 1 {
        return Err(FitError::TooFewPoints {
            points: points.len(),
            params: n_params,
        });
    }
    let prob = Problem {
        points,
        tau0,
        effects,
        meas: points.iter().map(|p| p.dev * p.dev).collect(),
    };
    let nl: Vec<usize> = (0..effects.len())
        .filter(|&k| effects[k].nonlinear_name().is_some())
        .collect();
    let mut thetas: Vec<f64> = effects
        .iter()
        .map(|e| match e {
            Effect::Markov => opts.tau_c_hint.unwrap_or(1.0),
            Effect::Sinusoid => opts
                .freq_fixed
                .map(|f| f.0)
                .or(opts.freq_hint)
                .unwrap_or(0.1),
            _ => f64::NAN,
        })
        .collect();
    if !nl.is_empty() {
        // Initialise each non-linear term alone (the others absent: θ = NaN gives b = 0).
        let saved = thetas.clone();
        for &k in &nl {
            let mut th = saved.clone();
            for &o in &nl {
                if o != k {
                    th[o] = f64::NAN;
                }
            }
            prob.refine(k, &mut th, opts);
            thetas[k] = th[k];
        }
        let rounds = if nl.len() > 1 { 4 } else { 1 };
        if nl.len() > 1 {
            for _ in 0..rounds {
                for &k in &nl {
                    prob.refine(k, &mut thetas, opts);
                }
            }
        }
    }
    let sol = prob.solve(&thetas);
    let dof = points.len() - n_params;
    let chi2_dof = sol.chi2 / dof as f64;

    // Fisher matrix at the optimum, model-based weights.
    let n = points.len();
    let mut cols: Vec<Vec<f64>> = Vec::new();
    enum Col {
        Coef(usize),
        Theta(usize),
    }
    let mut col_ids = Vec::new();
    for k in 0..effects.len() {
        cols.push(
            points
                .iter()
                .map(|p| {
                    let v = effects[k].basis(p.tau, tau0, thetas[k]);
                    if v.is_finite() {
                        v
                    } else {
                        0.0
                    }
                })
                .collect(),
        );
        col_ids.push(Col::Coef(k));
    }
    for &k in &nl {
        let fixed = effects[k] == Effect::Sinusoid && opts.freq_fixed.is_some();
        if sol.coef[k] > 0.0 && !fixed {
            let h = 1e-4;
            let col = points
                .iter()
                .map(|p| {
                    let up = effects[k].basis(p.tau, tau0, thetas[k] * (1.0 + h));
                    let dn = effects[k].basis(p.tau, tau0, thetas[k] * (1.0 - h));
                    sol.coef[k] * (up - dn) / (2.0 * h * thetas[k])
                })
                .collect();
            cols.push(col);
            col_ids.push(Col::Theta(k));
        }
    }
    let q = cols.len();
    let w: Vec<f64> = (0..n)
        .map(|j| {
            let v = sol.model[j].max(MODEL_FLOOR * prob.meas[j]);
            points[j].edf / (2.0 * v * v)
        })
        .collect();
    let mut f = DMatrix::<f64>::zeros(q, q);
    for a in 0..q {
        for b in 0..q {
            f[(a, b)] = (0..n).map(|j| w[j] * cols[a][j] * cols[b][j]).sum();
        }
    }
    // Scale to unit diagonal before inverting (the columns span many decades).
    let d: Vec<f64> = (0..q)
        .map(|a| {
            let v = f[(a, a)];
            if v > 0.0 {
                1.0 / v.sqrt()
            } else {
                0.0
            }
        })
        .collect();
    let fs = DMatrix::from_fn(q, q, |a, b| f[(a, b)] * d[a] * d[b]);
    let inv = fs
        .clone()
        .try_inverse()
        .or_else(|| fs.pseudo_inverse(1e-12).ok());
    let infl = chi2_dof.max(1.0);
    let var_of = |a: usize| -> f64 {
        match &inv {
            Some(m) if d[a] > 0.0 => (m[(a, a)] * d[a] * d[a] * infl).max(0.0),
            _ => f64::NAN,
        }
    };
    let mut terms: Vec<TermFit> = effects
        .iter()
        .enumerate()
        .map(|(k, &e)| TermFit {
            effect: e,
            coef: sol.coef[k],
            coef_sigma: f64::NAN,
            theta: if e.nonlinear_name().is_some() && sol.coef[k] > 0.0 {
                Some(thetas[k])
            } else {
                None
            },
            theta_sigma: None,
            detected: false,
        })
        .collect();
    for (a, id) in col_ids.iter().enumerate() {
        match *id {
            Col::Coef(k) => terms[k].coef_sigma = var_of(a).sqrt(),
            Col::Theta(k) => terms[k].theta_sigma = Some(var_of(a).sqrt()),
        }
    }
    if let Some((_, fs)) = opts.freq_fixed {
        for t in &mut terms {
            if t.effect == Effect::Sinusoid && t.theta.is_some() {
                t.theta_sigma = Some(fs);
            }
        }
    }
    for t in &mut terms {
        t.detected = t.coef > 0.0 && t.coef > 2.0 * t.coef_sigma;
        if !t.detected {
            t.theta = if t.coef > 0.0 { t.theta } else { None };
        }
    }
    Ok(Fit {
        tau0,
        points: points.to_vec(),
        terms,
        model_avar: sol.model,
        chi2: sol.chi2,
        dof,
    })
}

impl Point {
    /// Convert deviation rows of the `allan` crate (OADEV is what the fit expects), in τ order.
    ///
    /// Rows whose EDF or bounds are not finite cannot be weighted and are left out (the second
    /// value counts them). The EDFs are taken as the allan crate gives them: it already keeps
    /// the noise exponent from rising with τ, which is what stops a long-τ row with few clusters
    /// from being trusted blindly.
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
            });
        }
        (pts, skipped)
    }
}
/// Fit with the raw data at hand: as [`fit`], and when the model has a sinusoid whose frequency
/// shows a line in the whole-record periodogram (p < 1e-3, [`crate::psd::line_near`] within
/// ±15 %), refit with f fixed at the periodogram peak (1σ = half a periodogram bin, f_s/(2N)).
pub fn fit_with_data(
    points: &[Point],
    tau0: f64,
    effects: &[Effect],
    data: Option<(&[f64], f64)>,
) -> Result<Fit, FitError> {
    let first = fit(points, tau0, effects, &FitOptions::default())?;
    let (Some((y, fs)), Some(f)) = (data, first.term(Effect::Sinusoid).and_then(|t| t.theta))
    else {
        return Ok(first);
    };
    match crate::psd::line_near(y, fs, f, 0.15) {
        Some(lt) if lt.p_value < 1e-3 => {
            let half_bin = fs / (2.0 * y.len().next_power_of_two() as f64);
            let opts = FitOptions {
                freq_fixed: Some((lt.freq_hz, half_bin)),
                ..FitOptions::default()
            };
            let second = fit(points, tau0, effects, &opts)?;
            Ok(if second.chi2 <= first.chi2 * 1.5 + 10.0 {
                second
            } else {
                first
            })
        }
        _ => Ok(first),
    }
}
