//! The solver behind [`super::fit_model`]: whitening by the estimates' covariance, NNLS for the
//! coefficients, the profile χ² over the non-linear parameters (grid, then golden section), the
//! covariance update, and the uncertainties at the optimum (module docs of [`super`]).
use super::*;
use crate::cov::SignalShape;

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

/// Floor applied to the model variance in diagonal weights, relative to the measurement, so that
/// a model that is (for now) far too low cannot create infinite weights.
const MODEL_FLOOR: f64 = 1e-3;

/// The whitening of the residuals: W = L⁻¹ S⁻¹ with C = S ρ S, ρ = L Lᵀ.
#[derive(Clone)]
struct Whitener {
    inv_s: Vec<f64>,
    l: DMatrix<f64>,
}

impl Whitener {
    fn diagonal(var: &[f64]) -> Whitener {
        let n = var.len();
        Whitener {
            inv_s: var.iter().map(|v| 1.0 / v.max(1e-300).sqrt()).collect(),
            l: DMatrix::identity(n, n),
        }
    }

    fn from_cov(c: &DMatrix<f64>) -> Whitener {
        match crate::cov::correlation_factor(c) {
            (s, Some(l)) => Whitener {
                inv_s: s.iter().map(|v| 1.0 / v).collect(),
                l,
            },
            (_, None) => Whitener::diagonal(&(0..c.nrows()).map(|j| c[(j, j)]).collect::<Vec<_>>()),
        }
    }

    /// The same whitening with the points the model cannot reach down-weighted (Huber, 1981,
    /// *Robust Statistics*, ch. 7, in the log metric): a point whose log residual is more than
    /// [`HUBER_Z`] standard errors from the model has its scale widened by |z|/[`HUBER_Z`]. A
    /// complete model is untouched (its points sit within a few standard errors), but a model
    /// that cannot follow the data — the five terms against a sensor's filter — is no longer
    /// pulled by the few very precise points it cannot fit (ν ≈ 10⁵ at the shortest τ), and
    /// shows where it fails instead of bending through every point. The statistics (χ², the
    /// verdict, the uncertainties) use the covariance itself.
    fn robust(mut self, y: &[f64], model: &[f64], edf: &[f64]) -> Whitener {
        for (j, s) in self.inv_s.iter_mut().enumerate() {
            if !(model[j] > 0.0 && edf[j] > 0.0) {
                continue;
            }
            let z = ((y[j] / model[j]).ln() - log_chi2_bias(edf[j])) / (2.0 / edf[j]).sqrt();
            if z.abs() > HUBER_Z {
                *s *= HUBER_Z / z.abs();
            }
        }
        self
    }

    fn apply(&self, v: &[f64]) -> DVector<f64> {
        let x = DVector::from_iterator(v.len(), v.iter().zip(&self.inv_s).map(|(a, b)| a * b));
        self.l.solve_lower_triangular(&x).unwrap_or(x)
    }
}

/// Log residuals beyond this many standard errors are down-weighted in the fit ([`Whitener::robust`]).
const HUBER_Z: f64 = 4.0;

/// One term during the fit.
#[derive(Clone)]
struct Work {
    spec: TermSpec,
    specs: Vec<ParamSpec>,
    theta: Vec<f64>,
    basis: Basis,
    /// basis values at the points
    b: Vec<f64>,
}

struct Problem<'a> {
    meas: &'a Measurement,
    /// The measured Allan variances.
    y: Vec<f64>,
    /// What the linear solve fits: the log-space residual linearised at the current model,
    /// t = m₀·(1 + ln y − β(ν) − ln m₀) ([`log_target`]).
    target: Vec<f64>,
    ms: Vec<f64>,
}

/// E[ln(χ²_ν/ν)] = ψ(ν/2) − ln(ν/2): the bias of the log of an unbiased variance estimate with ν
/// degrees of freedom (−1/ν for large ν, −0.577 at ν = 2). Recurrence ψ(x) = ψ(x+1) − 1/x up to
/// x ≥ 6, then the asymptotic series of ψ(x) − ln x (Abramowitz & Stegun 6.3.18).
pub fn log_chi2_bias(nu: f64) -> f64 {
    if !(nu > 0.0 && nu.is_finite()) {
        return 0.0;
    }
    let x0 = nu / 2.0;
    let (mut x, mut acc) = (x0, 0.0);
    while x < 6.0 {
        acc -= 1.0 / x;
        x += 1.0;
    }
    let x2 = 1.0 / (x * x);
    let series = -0.5 / x - x2 * (1.0 / 12.0 - x2 * (1.0 / 120.0 - x2 / 252.0));
    // ψ(x0) − ln x0 = acc + ψ(x) − ln x0 = acc + series + ln(x/x0)
    acc + series + (x / x0).ln()
}

/// The fit's target at the model `model` with the points' EDFs `edf`: the log-space residual
/// r = ln y − β(ν) − ln m, linearised in the coefficients at m₀ = `model`, is (t − m)/m₀ with
/// t = m₀·(1 + ln y − β − ln m₀); the covariance of ln σ̂² is C/(m₀m₀ᵀ) (delta method), so the
/// generalised χ² of the linear problem is (t − Bc)ᵀC⁻¹(t − Bc), the same whitening as in variance
/// space. Fitting the logs makes a model 10× above the data cost what 10× below does: under the
/// model's own covariance in variance space a model that cannot follow the data drifts high,
/// where its predicted scatter is large and over-estimates cost little, and draws a curve nobody
/// would call the best fit.
fn log_target(y: &[f64], model: &[f64], edf: &[f64]) -> Vec<f64> {
    y.iter()
        .zip(model)
        .zip(edf)
        .map(|((&y, &m), &nu)| {
            let m0 = if m > MODEL_FLOOR * y { m } else { y };
            m0 * (1.0 + (y / m0).ln() - log_chi2_bias(nu))
        })
        .collect()
}

impl Problem<'_> {
    fn eval_basis(&self, e: &Effect, theta: &[f64]) -> Result<(Basis, Vec<f64>), FitError> {
        let basis = e
            .basis(theta, &self.meas.ctx)
            .map_err(|m| FitError::BadTerms(format!("{e}: {m}")))?;
        let b = self
            .ms
            .iter()
            .map(|&m| {
                let v = basis.avar(m, self.meas.ctx.tau0);
                if v.is_finite() {
                    v.max(0.0)
                } else {
                    0.0
                }
            })
            .collect();
        Ok((basis, b))
    }

    /// NNLS for the free coefficients with the whitening fixed; returns (coefficients, χ²).
    fn solve(&self, work: &[Work], w: &Whitener) -> (Vec<f64>, f64) {
        let n = self.y.len();
        let mut target = self.target.clone();
        let free: Vec<usize> = (0..work.len())
            .filter(|&k| work[k].spec.known.is_none())
            .collect();
        for t in work.iter() {
            if let Some(k) = t.spec.known {
                for (j, v) in target.iter_mut().enumerate() {
                    *v -= k.coef * t.b[j];
                }
            }
        }
        let yw = w.apply(&target);
        let mut coef: Vec<f64> = work
            .iter()
            .map(|t| t.spec.known.map_or(0.0, |k| k.coef))
            .collect();
        if free.is_empty() {
            return (coef, yw.norm_squared());
        }
        let mut a = DMatrix::<f64>::zeros(n, free.len());
        let mut scale = vec![0.0; free.len()];
        for (c, &k) in free.iter().enumerate() {
            let col = w.apply(&work[k].b);
            let s = col.norm();
            scale[c] = s;
            if s > 0.0 && s.is_finite() {
                a.set_column(c, &(col / s));
            }
        }
        let x = nnls(&a, &yw);
        for (c, &k) in free.iter().enumerate() {
            coef[k] = if scale[c] > 0.0 && scale[c].is_finite() {
                x[c] / scale[c]
            } else {
                0.0
            };
        }
        let model = self.model(work, &coef);
        let r: Vec<f64> = self.target.iter().zip(&model).map(|(a, b)| a - b).collect();
        (coef, w.apply(&r).norm_squared())
    }

    /// The points' EDFs about the model: 2m²/var(σ̂²) from the covariance under the model, or
    /// the points' own when only they are known.
    fn edf_at(&self, work: &[Work], coef: &[f64], model: &[f64]) -> Vec<f64> {
        match self.meas.weighting {
            Weighting::Diagonal => self.meas.points.iter().map(|p| p.edf).collect(),
            Weighting::Model => {
                let c = self.point_cov(work, coef, model);
                (0..model.len())
                    .map(|j| 2.0 * model[j].max(MODEL_FLOOR * self.y[j]).powi(2) / c[(j, j)])
                    .collect()
            }
        }
    }

    /// The log-space criterion at coefficients `coef`, with the whitening `w` and the scale m₀
    /// of the linearisation point: ‖W·m₀(ln y − β − ln m)‖².
    fn log_criterion(
        &self,
        work: &[Work],
        coef: &[f64],
        m0: &[f64],
        edf: &[f64],
        w: &Whitener,
    ) -> f64 {
        let m = self.model(work, coef);
        let r: Vec<f64> = (0..m.len())
            .map(|j| {
                let s = if m0[j] > MODEL_FLOOR * self.y[j] {
                    m0[j]
                } else {
                    self.y[j]
                };
                let mj = m[j].max(MODEL_FLOOR * self.y[j]);
                s * ((self.y[j] / mj).ln() - log_chi2_bias(edf[j]))
            })
            .collect();
        w.apply(&r).norm_squared()
    }

    fn model(&self, work: &[Work], coef: &[f64]) -> Vec<f64> {
        (0..self.y.len())
            .map(|j| work.iter().zip(coef).map(|(t, c)| c * t.b[j]).sum())
            .collect()
    }

    fn whitener(&self, work: &[Work], coef: &[f64]) -> Whitener {
        let model = self.model(work, coef);
        match self.meas.weighting {
            Weighting::Diagonal => Whitener::diagonal(
                &self
                    .meas
                    .points
                    .iter()
                    .zip(&model)
                    .zip(&self.y)
                    .map(|((p, &m), &y)| 2.0 * m.max(MODEL_FLOOR * y).powi(2) / p.edf)
                    .collect::<Vec<_>>(),
            ),
            Weighting::Model => {
                let c = self.point_cov(work, coef, &model);
                Whitener::from_cov(&c)
            }
        }
    }

    fn point_cov(&self, work: &[Work], coef: &[f64], model: &[f64]) -> DMatrix<f64> {
        let n = self.y.len();
        if self.meas.weighting == Weighting::Diagonal {
            return DMatrix::from_fn(n, n, |a, b| {
                if a == b {
                    2.0 * model[a].max(MODEL_FLOOR * self.y[a]).powi(2) / self.meas.points[a].edf
                } else {
                    0.0
                }
            });
        }
        let mut comps = Vec::new();
        let mut det = Deterministic {
            mean_diff: vec![0.0; n],
            sines: Vec::new(),
        };
        // the ramp's Allan variance (every Δ the same), and the signals localised or shaped in
        // time (steps, warm-up, temperature), kept for the second pass
        let mut ramp_avar = vec![0.0; n];
        let mut noise_avar = vec![0.0; n];
        let mut signals = Vec::new();
        // the known signals' Allan variance moved by their own estimation error, per point:
        // σ_c·b(m) for an amplitude estimated from this record (below, `estimated_signals`)
        let mut estimated = Vec::new();
        for (t, &c) in work.iter().zip(coef) {
            if c <= 0.0 {
                continue;
            }
            if let (Some(k), Kind::Signal) = (t.spec.known, t.spec.effect.kind()) {
                if !matches!(t.spec.effect, Effect::Drift { .. }) && k.coef_sigma > 0.0 {
                    estimated.push(t.b.iter().map(|b| b * k.coef_sigma).collect::<Vec<f64>>());
                }
            }
            match (&t.basis, t.spec.effect.kind()) {
                (Basis::Stochastic { structure, factor }, _) => {
                    comps.push(Component {
                        coef: c * factor,
                        structure: structure.clone(),
                    });
                    add_scaled(&mut noise_avar, c, &t.b);
                }
                (Basis::Sine { theta }, _) => det.sines.push((c, *theta)),
                (_, Kind::Ramp) => add_scaled(&mut ramp_avar, c, &t.b),
                _ => signals.push((t, c)),
            }
        }
        for ((md, m), a) in det.mean_diff.iter_mut().zip(&self.ms).zip(&ramp_avar) {
            *md = m * (2.0 * a).sqrt();
        }
        let mut c = self.meas.cache.covariance(&comps, &det);
        let e = self.localised_variance(&signals, &comps, &noise_avar);
        localised_signals(&mut c, &e);
        estimated_signals(&mut c, &estimated);
        // A covariance the model's terms cannot give as finite numbers (a term's structure
        // function overflowing at an extreme parameter) is no basis for weights: the points'
        // own EDFs about the model then weight them, independently, as for a device's table.
        if c.iter().any(|v| !v.is_finite()) {
            c = DMatrix::from_fn(n, n, |a, b| {
                if a == b {
                    2.0 * model[a].max(MODEL_FLOOR * self.y[a]).powi(2) / self.meas.points[a].edf
                } else {
                    0.0
                }
            });
        }
        // Floor: a point the model cannot produce (model ≈ 0) keeps a finite weight.
        for j in 0..n {
            let floor = 2.0 * (MODEL_FLOOR * self.y[j]).powi(2) / self.meas.points[j].edf.max(1.0);
            if !(c[(j, j)] > floor) {
                c[(j, j)] = floor;
            }
        }
        c
    }

    fn grid(spec: &ParamSpec, start: Option<f64>) -> Vec<f64> {
        let mut g: Vec<f64> = if spec.log {
            let (lo, hi) = (spec.lo.max(1e-300), spec.hi.max(spec.lo * 1.0001));
            let n = ((hi / lo).log10() * spec.density).ceil().clamp(2.0, 2000.0) as usize + 1;
            (0..n)
                .map(|i| lo * (hi / lo).powf(i as f64 / (n - 1) as f64))
                .collect()
        } else {
            let n = spec.density.clamp(2.0, 2000.0) as usize;
            (0..n)
                .map(|i| spec.lo + (spec.hi - spec.lo) * i as f64 / (n - 1) as f64)
                .collect()
        };
        if let Some(s) = start {
            if s > spec.lo && s < spec.hi {
                g.push(s);
                g.sort_by(f64::total_cmp);
            }
        }
        g
    }

    /// Minimise χ² over non-linear parameter `i` of term `k`, others fixed.
    fn refine(
        &self,
        work: &mut [Work],
        k: usize,
        i: usize,
        w: &Whitener,
        full_grid: bool,
    ) -> Result<f64, FitError> {
        let spec = work[k].specs[i].clone();
        let start = work[k].theta.get(i).copied().filter(|v| v.is_finite());
        let grid = if full_grid || start.is_none() {
            Self::grid(&spec, start)
        } else {
            // local: ±1/2 decade (log) or ±10 % of the range around the current value
            let s = start.unwrap_or(spec.lo);
            let local = ParamSpec {
                lo: if spec.log {
                    (s / 3.2).max(spec.lo)
                } else {
                    (s - 0.1 * (spec.hi - spec.lo)).max(spec.lo)
                },
                hi: if spec.log {
                    (s * 3.2).min(spec.hi)
                } else {
                    (s + 0.1 * (spec.hi - spec.lo)).min(spec.hi)
                },
                density: if spec.log { spec.density * 2.0 } else { 9.0 },
                ..spec.clone()
            };
            Self::grid(&local, start)
        };
        let eval = |v: f64, work: &mut [Work]| -> Result<f64, FitError> {
            work[k].theta[i] = v;
            let (basis, b) = self.eval_basis(&work[k].spec.effect, &work[k].theta)?;
            work[k].basis = basis;
            work[k].b = b;
            Ok(self.solve(work, w).1)
        };
        let mut best = (f64::INFINITY, 0usize);
        for (gi, &v) in grid.iter().enumerate() {
            let c = eval(v, work).unwrap_or(f64::INFINITY);
            if c < best.0 {
                best = (c, gi);
            }
        }
        if !best.0.is_finite() {
            return Err(FitError::BadTerms(format!(
                "{}: no value of {} in [{}, {}] gives a finite fit",
                work[k].spec.effect, spec.name, spec.lo, spec.hi
            )));
        }
        let gi = best.1;
        let tr = |v: f64| if spec.log { v.ln() } else { v };
        let inv = |v: f64| if spec.log { v.exp() } else { v };
        let (a, b) = (
            tr(grid[gi.saturating_sub(1)]),
            tr(grid[(gi + 1).min(grid.len() - 1)]),
        );
        let mut best_v = grid[gi];
        let mut best_c = best.0;
        if b > a {
            let (xm, fm) = golden_min(
                |x| eval(inv(x), work).unwrap_or(f64::INFINITY),
                a,
                b,
                GOLDEN_ITERATIONS,
            );
            if fm < best_c {
                best_c = fm;
                best_v = inv(xm);
            }
        }
        eval(best_v, work)?;
        Ok(best_c)
    }
}

fn add_scaled(acc: &mut [f64], c: f64, b: &[f64]) {
    for (a, v) in acc.iter_mut().zip(b) {
        *a += c * v;
    }
}

/// The gain g of the noise projected on a localised signal whose shape the lab neither knows in
/// closed form nor has measured (a user's signal), as a bound:
/// Var(Σ D_i N_i) ≤ g·m²·q·Σ D_i² for white noise of q per sample, g the peak of the Allan
/// difference's power gain |H|²/m² = 4 sin⁴x/x² ≈ 2.1 at x ≈ 1.17. Steps and warm-ups have
/// their exact sum instead ([`crate::cov::signal_noise_sum`]), a drift its cosines' and a bias
/// following the temperature its column's measured profile ([`crate::diff_profile`]).
const SIGNAL_GAIN: f64 = 2.1;

/// The variance the deterministic signals localised in time (a bias step, a warm-up, a bias
/// following the temperature) add to each Allan estimate. With D_i the signal's part of the Allan
/// difference Δ_i and N_i the noise's, σ̂²(m) = Σ(N_i + D_i)²/(2m²M) varies through the noise
/// projected on the signal, 4·Var(Σ D_i N_i)/(2m²M)² — large where the signal is concentrated:
/// a step's D is a triangle 2m wide around its instant, which the noise's differences at lags
/// below 2m do not average out (the coherent mean a ramp has would make this term vanish, and
/// the model's covariance would then claim a precision the data do not have where the step
/// dominates). Var(Σ D_i N_i) = Σ D_i²·Σ_d c(d)ρ(d), c the noise's covariance of the
/// differences and ρ the signal's normalised autocorrelation (exact for a step and an
/// exponential warm-up, [`crate::cov::signal_noise_sum`]; a drift's from its cosines; a bias
/// following the temperature column's as measured on the column at the nearest octave,
/// [`crate::cov::profile_noise_sum`]); with Σ D_i² = 2m²M·a(m) for a signal of Allan variance
/// a(m), the added variance is e = 2·a(m)·Σ_d c(d)ρ(d)/(m²M). Other shapes take the bound
/// [`SIGNAL_GAIN`] on the noise taken as white of the model's variance at m.
impl Problem<'_> {
    fn localised_variance(
        &self,
        signals: &[(&Work, f64)],
        comps: &[Component],
        noise_avar: &[f64],
    ) -> Vec<f64> {
        let n = self.ms.len();
        let mut e = vec![0.0; n];
        let design = self.meas.cache.design();
        let span = design.segments.iter().copied().max().unwrap_or(0) as f64;
        let tau0 = self.meas.ctx.tau0;
        for &(t, c) in signals {
            let shape = match t.spec.effect {
                Effect::BiasStep => Some(SignalShape::Step),
                Effect::Temperature if t.theta.len() == 1 && t.theta[0] > 0.0 => {
                    Some(SignalShape::Exponential {
                        kappa: t.theta[0] / tau0,
                    })
                }
                _ => None,
            };
            // a drift's differences are its ramp's constant and its cosines
            let drift_shape: Option<&[f64]> = match t.spec.effect {
                Effect::Drift { .. } if !t.theta.is_empty() => Some(&t.theta),
                _ => None,
            };
            // a bias following the temperature column: its differences' autocorrelation as
            // measured on the column
            let profiles = match t.spec.effect {
                Effect::Temperature if t.theta.is_empty() => self.meas.ctx.temp_profile.as_deref(),
                _ => None,
            };
            for j in 0..n {
                let m = self.ms[j];
                let terms = design.terms(m as u64).max(1) as f64;
                let a = (c * t.b[j]).max(0.0);
                if a == 0.0 {
                    continue;
                }
                let bound = SIGNAL_GAIN * m * noise_avar[j].max(0.0);
                let sum = match (shape, drift_shape, profiles) {
                    (Some(sh), _, _) => crate::cov::signal_noise_sum(comps, m, sh, span) / (m * m),
                    (_, Some(sh), _) => drift_noise_sum(comps, m, sh, &self.meas.ctx) / (m * m),
                    (_, _, Some(p)) => match nearest_profile(p, m) {
                        Some(prof) => crate::cov::profile_noise_sum(comps, m, &prof) / (m * m),
                        None => bound,
                    },
                    _ => bound,
                };
                // a sum that is not a number (a structure function overflowing) takes the bound
                let sum = if sum.is_finite() { sum } else { bound };
                let add = 2.0 * a * sum / terms;
                if add.is_finite() && add > 0.0 {
                    e[j] += add;
                }
            }
        }
        e
    }
}

/// The profile measured at the octave nearest to m (in log m), its lags scaled to m.
fn nearest_profile(
    profiles: &[(u64, crate::diff_profile::DiffProfile)],
    m: f64,
) -> Option<crate::diff_profile::DiffProfile> {
    let (at, p) = profiles.iter().min_by(|a, b| {
        let da = (a.0 as f64 / m).ln().abs();
        let db = (b.0 as f64 / m).ln().abs();
        da.total_cmp(&db)
    })?;
    Some(p.rescaled(*at as f64, m))
}

/// Σ_d c(d)·ρ(d) for a drift of unit shape `theta` (its ramp per sample, then its cosines'
/// coefficients) at averaging factor m: in partial-sum units the ramp's Allan differences are the
/// constant c₀m², a cosine's are a cosine of the same ω_j = πj/T and amplitude
/// 2c_j·sin²(mω_j/2)/sin(ω_j/2) (docs/noise-model.md §5), so ρ is their mix weighted by each one's
/// share of Σ D_i² (the constant in full, a cosine by half its amplitude squared), and the sum is
/// the same mix of [`crate::cov::cosine_noise_sums`].
fn drift_noise_sum(comps: &[Component], m: f64, theta: &[f64], ctx: &Context) -> f64 {
    let span = crate::effect::drift_span(ctx);
    if !(span > 0.0) {
        return f64::NAN;
    }
    let mut omegas = Vec::with_capacity(theta.len());
    let mut weights = Vec::with_capacity(theta.len());
    for (j, cj) in theta.iter().enumerate() {
        if j == 0 {
            omegas.push(0.0);
            weights.push((cj * m * m).powi(2));
        } else {
            let w = std::f64::consts::PI * j as f64 / span;
            let amp = 2.0 * cj * (m * w / 2.0).sin().powi(2) / (w / 2.0).sin();
            omegas.push(w);
            weights.push(0.5 * amp * amp);
        }
    }
    let total: f64 = weights.iter().sum();
    if !(total > 0.0 && total.is_finite()) {
        return f64::NAN;
    }
    let sums = crate::cov::cosine_noise_sums(comps, m, &omegas, span);
    weights.iter().zip(&sums).map(|(w, s)| w * s).sum::<f64>() / total
}

/// Adds the localised signals' variances `e` to the covariance; between points they carry the
/// noise's own correlation (a Schur product with a rank-one matrix: the covariance stays
/// positive definite).
fn localised_signals(c: &mut DMatrix<f64>, e: &[f64]) {
    if e.iter().all(|&v| v <= 0.0) {
        return;
    }
    let n = e.len();
    let sd: Vec<f64> = (0..n).map(|j| c[(j, j)].max(0.0).sqrt()).collect();
    for a in 0..n {
        for b in 0..n {
            let rho = if a == b {
                1.0
            } else if sd[a] > 0.0 && sd[b] > 0.0 {
                (c[(a, b)] / (sd[a] * sd[b])).clamp(-1.0, 1.0)
            } else {
                0.0
            };
            c[(a, b)] += rho * (e[a] * e[b]).sqrt();
        }
    }
}

/// Take out of the covariance what the known signals' own estimates share with the data. A
/// signal's amplitude θ̂ = θ + ε is estimated from this record by GLS on the time series, so the
/// model's signal term a(m; θ̂) moves with the noise projected on the signal, the same projection
/// that moves σ̂²(m) ([`localised_signals`]). For a best linear unbiased ε the two are correlated
/// exactly: with X_m = Σ D_i N_i/(m²M) the data's part and Y_m = ∂a/∂θ·ε the model's,
/// Cov(X_m, ε) = ∂a/∂θ·Var(ε) (the GLS normal equations: Cov(uᵀN, ε) = uᵀP·Var(ε) for the
/// signal's pattern P, and Σ D_i ∂D_i/∂θ/(m²M) = ∂a/∂θ), so the residual X − Y has covariance
/// Cov(X) − J·Var(ε)·Jᵀ, J_m = ∂a(m)/∂θ. For a term c·b(m) with c = θ² known to σ_c, J·σ_θ =
/// σ_c·b(m): each column of `estimated`. Without this the true model's χ²/dof sits near 0.66
/// under a step. A drift is left out: its estimate is shrunk (lab.rs, `set_known`), not BLUE.
/// The identity holds for the estimate made under the noise this model has, and that noise is
/// itself estimated: along each signal's column v the subtraction takes at most
/// [`MAX_ESTIMATE_SHARE`] of the variance (s·vᵀC⁻¹v ≤ that share, so every direction keeps at
/// least the rest of its variance and the covariance stays positive definite). Taken nearly in
/// full, it leaves the covariance nearly singular along v, and small departures there read as
/// large statistics: with the right step in white noise, χ²/dof rose to 8–25 in 6 of 40
/// realisations (`session`'s `step_precision_sweep`).
fn estimated_signals(c: &mut DMatrix<f64>, estimated: &[Vec<f64>]) {
    let n = c.nrows();
    for col in estimated {
        if col.len() != n || col.iter().any(|v| !v.is_finite()) {
            return;
        }
        let v = DVector::from_column_slice(col);
        let Some(ch) = c.clone().cholesky() else {
            return;
        };
        let q = v.dot(&ch.solve(&v));
        if !(q > 0.0 && q.is_finite()) {
            continue;
        }
        let s = (MAX_ESTIMATE_SHARE / q).min(1.0);
        *c -= &v * v.transpose() * s;
    }
}

/// The largest share of a point covariance's variance along an estimated signal's column that
/// [`estimated_signals`] takes out.
const MAX_ESTIMATE_SHARE: f64 = 0.5;

/// Fit the terms `specs` to the measurement: the problem built from the data and the specs, the
/// initial search, the outer Gauss–Newton/covariance iterations, then the statistics and the
/// uncertainties at the optimum.
pub fn fit_model(meas: &Measurement, specs: &[TermSpec]) -> Result<Fit, FitError> {
    let (mut prob, mut work, nl) = build_problem(meas, specs)?;
    let coef = initial_search(&mut prob, &mut work, &nl)?;
    let coef = outer_iterations(&mut prob, &mut work, &nl, coef)?;
    uncertainties(&prob, &work, &nl, coef)
}

/// The problem of fitting `specs` to `meas`: the points and specs validated, the measured
/// variances, each term's working state (its non-linear parameters as given, or NaN where they
/// are searched, and its basis at the points when they are known), and the free non-linear
/// parameters as (term, parameter) indices.
#[allow(clippy::type_complexity)]
fn build_problem<'a>(
    meas: &'a Measurement,
    specs: &[TermSpec],
) -> Result<(Problem<'a>, Vec<Work>, Vec<(usize, usize)>), FitError> {
    let points = &meas.points;
    validate(points)?;
    let tau0 = meas.ctx.tau0;
    if !(tau0 > 0.0 && tau0.is_finite()) {
        return Err(FitError::BadTerms(format!(
            "sampling interval τ0 = {tau0} s is not positive"
        )));
    }
    if specs.is_empty() {
        return Err(FitError::BadTerms("no terms to fit".into()));
    }
    for (i, s) in specs.iter().enumerate() {
        if !s.effect.repeatable() && specs[..i].iter().any(|o| o.effect == s.effect) {
            return Err(FitError::BadTerms(format!(
                "term {} listed twice",
                s.effect
            )));
        }
        if let Some(k) = s.known {
            if !(k.coef.is_finite() && k.coef >= 0.0) {
                return Err(FitError::BadTerms(format!(
                    "{}: the known coefficient {} is not a non-negative number",
                    s.effect, k.coef
                )));
            }
        }
    }
    let n_params: usize = specs
        .iter()
        .map(|s| {
            usize::from(s.known.is_none())
                + if s.theta_fixed {
                    0
                } else {
                    s.effect.nonlinear(&meas.ctx).len()
                }
        })
        .sum();
    if points.len() < n_params + 1 {
        return Err(FitError::TooFewPoints {
            points: points.len(),
            params: n_params,
        });
    }
    let prob = Problem {
        meas,
        y: points.iter().map(|p| p.dev * p.dev).collect(),
        target: Vec::new(),
        ms: points.iter().map(|p| p.m as f64).collect(),
    };
    let mut work: Vec<Work> = Vec::with_capacity(specs.len());
    for s in specs {
        let pspecs = s.effect.nonlinear(&meas.ctx);
        let theta: Vec<f64> = match &s.theta {
            Some(t) if t.len() == pspecs.len() => t.clone(),
            Some(t) => {
                return Err(FitError::BadTerms(format!(
                    "{}: {} non-linear parameter(s) given, {} expected ({})",
                    s.effect,
                    t.len(),
                    pspecs.len(),
                    pspecs
                        .iter()
                        .map(|p| p.name.as_str())
                        .collect::<Vec<_>>()
                        .join(", ")
                )))
            }
            None => vec![f64::NAN; pspecs.len()],
        };
        if s.theta_fixed && theta.iter().any(|v| !v.is_finite()) {
            return Err(FitError::BadTerms(format!(
                "{}: fixed non-linear parameters must be given",
                s.effect
            )));
        }
        let (basis, b) = if theta.iter().all(|v| v.is_finite()) {
            prob.eval_basis(&s.effect, &theta)?
        } else {
            (Basis::Zero, vec![0.0; points.len()])
        };
        work.push(Work {
            spec: s.clone(),
            specs: pspecs,
            theta,
            basis,
            b,
        });
    }
    let nl: Vec<(usize, usize)> = work
        .iter()
        .enumerate()
        .filter(|(_, t)| !t.spec.theta_fixed)
        .flat_map(|(k, t)| (0..t.specs.len()).map(move |i| (k, i)))
        .collect();
    Ok((prob, work, nl))
}

/// The start: diagonal weights from the measurement's own EDFs with the target linearised at the
/// data, a grid search of each free non-linear parameter with the other searched terms absent,
/// then coordinate rounds over all of them jointly. Returns the coefficients there.
fn initial_search(
    prob: &mut Problem,
    work: &mut [Work],
    nl: &[(usize, usize)],
) -> Result<Vec<f64>, FitError> {
    let points = &prob.meas.points;
    // Start: diagonal weights from the measurement's own EDFs, linearised at the data.
    let point_edf: Vec<f64> = points.iter().map(|p| p.edf).collect();
    prob.target = log_target(&prob.y, &prob.y, &point_edf);
    let w = Whitener::diagonal(
        &points
            .iter()
            .map(|p| 2.0 * (p.dev * p.dev).powi(2) / p.edf)
            .collect::<Vec<_>>(),
    );
    // Initialise each searched term alone (the others' searched terms absent), then jointly.
    for &(k, i) in nl {
        let saved: Vec<(Basis, Vec<f64>)> = work
            .iter()
            .map(|t| (t.basis.clone(), t.b.clone()))
            .collect();
        for &(o, _) in nl {
            if o != k && work[o].theta.iter().any(|v| !v.is_finite()) {
                work[o].b = vec![0.0; points.len()];
            }
        }
        prob.refine(work, k, i, &w, true)?;
        for (o, (bs, b)) in saved.into_iter().enumerate() {
            if o != k {
                work[o].basis = bs;
                work[o].b = b;
            }
        }
    }
    for &(k, _) in nl {
        let (basis, b) = prob.eval_basis(&work[k].spec.effect, &work[k].theta.clone())?;
        work[k].basis = basis;
        work[k].b = b;
    }
    let rounds = if nl.len() > 1 { NONLINEAR_ROUNDS } else { 0 };
    for _ in 0..rounds {
        for &(k, i) in nl {
            prob.refine(work, k, i, &w, true)?;
        }
    }
    let (coef, _) = prob.solve(work, &w);
    Ok(coef)
}

/// Outer iterations from `coef`: covariance (or diagonal weights) from the model, and the
/// log-space residual linearised there (Gauss–Newton, each step damped until the log criterion
/// falls), until the coefficients stop moving or the iterations run out. Returns the last
/// iterate.
fn outer_iterations(
    prob: &mut Problem,
    work: &mut [Work],
    nl: &[(usize, usize)],
    mut coef: Vec<f64>,
) -> Result<Vec<f64>, FitError> {
    let mut converged = false;
    for it in 0..OUTER_ITERATIONS.max(if prob.meas.weighting == Weighting::Diagonal {
        12
    } else {
        0
    }) {
        let model = prob.model(work, &coef);
        let edf = prob.edf_at(work, &coef, &model);
        let w = prob.whitener(work, &coef).robust(&prob.y, &model, &edf);
        prob.target = log_target(&prob.y, &model, &edf);
        for _ in 0..if nl.len() > 1 { 2 } else { 1 } {
            for &(k, i) in nl {
                prob.refine(work, k, i, &w, it == 0)?;
            }
        }
        let (mut new_coef, _) = prob.solve(work, &w);
        let log_crit = |c: &[f64]| prob.log_criterion(work, c, &model, &edf, &w);
        let old_crit = log_crit(&coef);
        // halve the step towards the old coefficients, at most four times
        for _ in 0..4 {
            if log_crit(&new_coef) <= old_crit {
                break;
            }
            new_coef = coef
                .iter()
                .zip(&new_coef)
                .map(|(a, b)| a + 0.5 * (b - a))
                .collect();
        }
        // converged when no coefficient that matters moved by more than 1e-4 of the largest
        // contribution it makes (the covariance, hence the weights, then no longer changes)
        let change = new_coef
            .iter()
            .zip(&coef)
            .zip(work.iter())
            .map(|((a, b), t)| {
                let peak =
                    t.b.iter()
                        .zip(&prob.y)
                        .map(|(bv, y)| bv / y)
                        .fold(0.0, f64::max);
                (a - b).abs() * peak
            })
            .fold(0.0, f64::max);
        coef = new_coef;
        if change < 1e-4 {
            converged = true;
            break;
        }
    }
    let _ = converged; // the last iterate is used either way; χ² is evaluated at it
    Ok(coef)
}

/// The fit at the coefficients `coef`: the model, its covariance and EDFs, the generalised χ²,
/// then the Fisher matrix over the free parameters, the degrees of freedom, the parameter
/// covariance and each term's result with its uncertainties.
fn uncertainties(
    prob: &Problem,
    work: &[Work],
    nl: &[(usize, usize)],
    coef: Vec<f64>,
) -> Result<Fit, FitError> {
    let meas = prob.meas;
    let points = &meas.points;
    let model = prob.model(work, &coef);
    let point_cov = prob.point_cov(work, &coef, &model);
    let wf = match meas.weighting {
        Weighting::Model => Whitener::from_cov(&point_cov),
        Weighting::Diagonal => prob.whitener(work, &coef),
    };
    let model_edf: Vec<f64> = (0..points.len())
        .map(|j| 2.0 * model[j].max(1e-300).powi(2) / point_cov[(j, j)])
        .collect();
    let t = log_target(&prob.y, &model, &model_edf);
    let r: Vec<f64> = t.iter().zip(&model).map(|(a, b)| a - b).collect();
    let chi2 = wf.apply(&r).norm_squared();

    let (cols, index) = fisher_columns(prob, work, nl, &coef, &wf)?;
    let q = cols.len();
    // A coefficient held at its bound 0 by the constraint counts half: the χ² reduction of a
    // boundary parameter is 0 or 1 degree of freedom with probability ½ each (the chi-bar-square
    // mixture; Self & Liang, JASA 1987).
    let interior = index
        .iter()
        .filter(|&&(k, i)| i > 0 || coef[k] > 0.0)
        .count();
    let boundary = index.len() - interior;
    let dof = (points.len() as f64 - interior as f64 - 0.5 * boundary as f64).max(1.0);
    let chi2_dof = chi2 / dof;
    let fisher = DMatrix::from_fn(q, q, |a, b| cols[a].dot(&cols[b]));
    let d: Vec<f64> = (0..q)
        .map(|a| {
            let v = fisher[(a, a)];
            if v > 0.0 {
                1.0 / v.sqrt()
            } else {
                0.0
            }
        })
        .collect();
    let fs = DMatrix::from_fn(q, q, |a, b| fisher[(a, b)] * d[a] * d[b]);
    let inv = fs.clone().try_inverse().or_else(|| crate::nnls::pinv(&fs));
    let infl = chi2_dof.max(1.0);
    let param_cov = match &inv {
        Some(m) => DMatrix::from_fn(q, q, |a, b| m[(a, b)] * d[a] * d[b] * infl),
        None => DMatrix::from_element(q, q, f64::NAN),
    };
    let terms = term_fits(work, &coef, &index, &param_cov);
    let per_term_basis = work.iter().map(|t| t.b.clone()).collect();
    let mut out = Fit {
        tau0: meas.ctx.tau0,
        points: points.clone(),
        ctx: meas.ctx.clone(),
        weighting: meas.weighting,
        terms,
        model_avar: model,
        point_cov,
        model_edf,
        chi2: f64::NAN,
        objective: chi2,
        dof,
        param_cov,
        param_index: index,
        per_term_basis,
    };
    out.chi2 = out.statistic().1;
    out.check_finite()?;
    Ok(out)
}

/// The whitened columns of the Fisher matrix over the free parameters, with each column's
/// (term, parameter) index: 0 for the term's coefficient, i + 1 for its non-linear parameter i
/// (a central difference of the basis at the optimum).
#[allow(clippy::type_complexity)]
fn fisher_columns(
    prob: &Problem,
    work: &[Work],
    nl: &[(usize, usize)],
    coef: &[f64],
    wf: &Whitener,
) -> Result<(Vec<DVector<f64>>, Vec<(usize, usize)>), FitError> {
    // Fisher matrix over the free parameters: coefficients of non-known terms and the searched
    // non-linear parameters of terms present.
    let mut cols: Vec<DVector<f64>> = Vec::new();
    let mut index = Vec::new();
    for (k, t) in work.iter().enumerate() {
        if t.spec.known.is_none() {
            cols.push(wf.apply(&t.b));
            index.push((k, 0));
        }
    }
    for &(k, i) in nl {
        if coef[k] <= 0.0 {
            continue;
        }
        let v = work[k].theta[i];
        let spec = &work[k].specs[i];
        let h = if spec.log {
            1e-4 * v.abs()
        } else {
            1e-4 * (spec.hi - spec.lo)
        };
        if !(h > 0.0) {
            continue;
        }
        let mut up = work[k].theta.clone();
        let mut dn = work[k].theta.clone();
        up[i] = v + h;
        dn[i] = v - h;
        let (_, bu) = prob.eval_basis(&work[k].spec.effect, &up)?;
        let (_, bd) = prob.eval_basis(&work[k].spec.effect, &dn)?;
        let d: Vec<f64> = bu
            .iter()
            .zip(&bd)
            .map(|(a, b)| coef[k] * (a - b) / (2.0 * h))
            .collect();
        if d.iter().all(|x| *x == 0.0) {
            continue;
        }
        cols.push(wf.apply(&d));
        index.push((k, i + 1));
    }
    Ok((cols, index))
}

/// Each term's result at the optimum: its coefficient and non-linear parameters with the standard
/// errors of the free ones from `param_cov` (indexed by `index`), the known ones' as given, and
/// whether it is detected (above twice its standard error).
fn term_fits(
    work: &[Work],
    coef: &[f64],
    index: &[(usize, usize)],
    param_cov: &DMatrix<f64>,
) -> Vec<TermFit> {
    let mut terms: Vec<TermFit> = work
        .iter()
        .zip(coef)
        .map(|(t, &c)| TermFit {
            effect: t.spec.effect.clone(),
            coef: c,
            coef_sigma: t.spec.known.map_or(f64::NAN, |k| k.coef_sigma),
            sign: t
                .spec
                .known
                .map_or(1.0, |k| if k.sign < 0.0 { -1.0 } else { 1.0 }),
            theta: t.theta.clone(),
            theta_sigma: t
                .spec
                .theta_sigma
                .clone()
                .unwrap_or_else(|| vec![f64::NAN; t.theta.len()]),
            specs: t.specs.clone(),
            known: t.spec.known.is_some(),
            detected: false,
        })
        .collect();
    for (a, &(k, i)) in index.iter().enumerate() {
        let s = param_cov[(a, a)].max(0.0).sqrt();
        if i == 0 {
            terms[k].coef_sigma = s;
        } else {
            terms[k].theta_sigma[i - 1] = s;
        }
    }
    for t in &mut terms {
        t.detected = t.supported();
    }
    terms
}

impl Fit {
    /// Every statistic of the fit is a finite number, or the fit fails naming the first that is
    /// not ([`FitError::NonFinite`]).
    pub fn check_finite(&self) -> Result<(), FitError> {
        let bad = |what: String| Err(FitError::NonFinite(what));
        for (name, v) in [
            ("the goodness-of-fit statistic T", self.chi2),
            ("the fit's generalised χ²", self.objective),
            ("the degrees of freedom", self.dof),
        ] {
            if !v.is_finite() {
                return bad(format!("{name} ({v})"));
            }
        }
        for (j, p) in self.points.iter().enumerate() {
            for (name, v) in [
                ("the model Allan variance", self.model_avar[j]),
                ("the model EDF", self.model_edf[j]),
            ] {
                if !v.is_finite() {
                    return bad(format!("{name} at τ = {} s ({v})", p.tau));
                }
            }
        }
        for t in &self.terms {
            if !t.coef.is_finite() || t.theta.iter().any(|v| !v.is_finite()) {
                return bad(format!(
                    "a parameter of {} (c = {}, θ = {:?})",
                    t.effect, t.coef, t.theta
                ));
            }
        }
        Ok(())
    }
}
