//! The calibration lab: fit a model (a set of named effects), compare its residual with the
//! noise floor estimated from the same data, and when it is not adequate name the missing effect
//! by one general rule. Equations of the paper are cited as "Jaime et al.": I. Jaime,
//! F. Beck Ferrero, M. L. Miretti, E. Bernardi, "Caracterización y calibración de unidades de
//! medición inercial de bajo costo", UTN Facultad Regional San Francisco.
//!
//! 1. **Robust fit.** Real recordings hold wild samples (a bumped sensor, a corrupted read), up
//!    to a quarter of a session. The fit starts from the problem's *robust start*
//!    ([`Problem::robust_start`]): for the magnetometer the least-median-of-squares sphere
//!    (circle for planar data) over random minimal subsets (Rousseeuw 1984; subsets drawn as in
//!    RANSAC, Fischler & Bolles 1981, from a generator keyed by the data, so the same data give
//!    the same fit), whose breakdown point is 50 %; the items within 2.5 robust scales of it are
//!    fitted by least squares. From there the loss is Tukey's redescending kind in its hard form,
//!    the truncated quadratic ρ(r) = min(r², c²) with c = [`OUTLIER_SIGMAS`]·σ̂ (σ̂ = 1.4826·MAD
//!    of the residuals, never below the noise floor): every item is judged again and least
//!    squares refitted on the items within c of the median residual until that set stops
//!    changing (at most [`ROBUST_ROUNDS`] rounds; if it never settles the last fit stands, with a
//!    warning). Items beyond c are outliers, excluded and named with their count; the
//!    parameters, their uncertainties, the residual RMS and every test below are those of the
//!    least-squares fit of the rest, so the reported residual is recomputable from the reported
//!    parameters. When more than [`MAX_OUTLIER_FRACTION`] of the items lie beyond c they are not
//!    outliers but a misfit, and nothing is excluded. (Sensor overflow sentinels are removed
//!    before, by [`crate::sentinel`].) A solver that stops at its iteration cap is not an
//!    error: the best point reached is the fit, with [`Fitted::not_converged`] saying so.
//! 2. **Uncertainty.** Every parameter gets a 1σ standard error from the least-squares
//!    covariance `s²·(JᵀJ)⁻¹` (s² = RSS/(N − p)), propagated to the reported form (degrees,
//!    matrices, ellipse axes) to first order.
//! 3. **Enough data: identifiability.** A model is *underdetermined* when the data do not
//!    identify its parameters: no residual degree of freedom (N ≤ p: every parameter), or a
//!    parameter whose σ is not finite (JᵀJ singular) or exceeds [`IDENTIFIED_FRACTION`] of its
//!    plausible half-range before any data ([`Problem::plausible_range`]: datasheet-sized
//!    spreads, e.g. an accelerometer offset of ±0.1 g). A near-singular JᵀJ shows up there as a
//!    σ far above the range, so the rule also covers ill-conditioning, and it names the
//!    parameters concerned. Such a model is never called adequate (a residual far above the
//!    floor is a failure whatever the identifiability, and is diagnosed as such), nor is a fit
//!    that did not converge: at the floor it is called underdetermined, with the reason.
//! 4. **Adequacy.** The residual variance per degree of freedom, `s² = RSS/(N − p)`, is compared
//!    with the noise-floor variance `σ²` estimated from the data itself on the same basis (per pose,
//!    per sample or per block). Under a complete model `s²/σ²` follows F(N − p, ν) (ν = degrees of
//!    freedom of the noise estimate). The model is adequate when the upper-tail probability is
//!    ≥ [`ALPHA_ADEQUATE`], or when the residual is within [`PRACTICAL_MARGIN`] of the floor
//!    (with thousands of samples the test alone would flag sub-percent excesses nobody can act on).
//!    Data without any noise (a floor of exactly 0) are adequate only for a residual at rounding
//!    level, and say so.
//! 5. **Which effect is missing.** Every effect of the sensor that is not yet in the model and is
//!    identifiable from this data is added in turn and the model refitted on the same items. The
//!    nested-model F-test (e.g. Seber & Wild, *Nonlinear Regression*, §5.3)
//!    `F = ((RSS₀ − RSS₁)/Δp) / (RSS₁/(N − p₁))` tells whether the drop is significant for the Δp
//!    extra parameters (p < [`ALPHA_EFFECT`]); the candidate model is then fitted with the robust
//!    loss on its own and judged. A significant candidate is *admissible* when the current
//!    model's residual is above the floor (a residual at the floor lacks nothing the data can
//!    show, however significant a drop); among the admissible ones the largest F comes first.
//!
//! The same rule serves all three sensors; nothing is written for one effect. The workflow
//! around it — candidates, the step before → after, the walk from model to model until adequate
//! or nothing helps — is the project's one lab workflow, [`model_lab`]: [`CalLab`] implements
//! [`model_lab::Lab`] with [`Model`] as its model, and its summary's `chi2_dof` is the variance
//! ratio `s²/σ²` of item 4 (1 for a residual at the floor), `rms_residual` the residual RMS in
//! the data's unit.
pub use crate::error::CalError;
use serde::Serialize;
use std::fmt;

mod analyse;
mod reading;

pub use analyse::{analyse, normalise_model, robust_fit, CalLab};
pub use reading::reading;

/// Significance level of the adequacy test.
pub const ALPHA_ADEQUATE: f64 = 0.01;
/// Significance level for an added effect.
pub const ALPHA_EFFECT: f64 = 0.001;
/// Residual RMS within this factor of the floor counts as adequate regardless of the test.
pub const PRACTICAL_MARGIN: f64 = 1.10;
/// Residuals beyond this many robust σ are outliers (module docs).
pub const OUTLIER_SIGMAS: f64 = 6.0;
/// Most refits of the outlier rejection.
pub const ROBUST_ROUNDS: usize = 20;
/// Beyond this fraction of the items, residuals over the cut are a misfit, not outliers (the
/// robust start holds to 25 % of gross outliers and beyond: module docs, 1).
pub const MAX_OUTLIER_FRACTION: f64 = 0.3;
/// A parameter is identified when its σ is at most this fraction of its plausible half-range
/// (module docs, 3).
pub const IDENTIFIED_FRACTION: f64 = 0.1;

/// The deterministic error effects the lab knows.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Effect {
    Offset,
    Scale,
    Misalignment,
    Bias,
    Temperature,
    HardIron,
    SoftIron,
    SoftIron2d,
    Tilt,
}

impl fmt::Display for Effect {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl Effect {
    /// All effects.
    pub const ALL: [Effect; 9] = [
        Effect::Offset,
        Effect::Scale,
        Effect::Misalignment,
        Effect::Bias,
        Effect::Temperature,
        Effect::HardIron,
        Effect::SoftIron,
        Effect::SoftIron2d,
        Effect::Tilt,
    ];

    /// The name used on the command line and in JSON.
    pub fn name(self) -> &'static str {
        match self {
            Effect::Offset => "offset",
            Effect::Scale => "scale",
            Effect::Misalignment => "misalignment",
            Effect::Bias => "bias",
            Effect::Temperature => "temperature",
            Effect::HardIron => "hard_iron",
            Effect::SoftIron => "soft_iron",
            Effect::SoftIron2d => "soft_iron_2d",
            Effect::Tilt => "tilt",
        }
    }

    /// Parse a name (as printed by [`Effect::name`]).
    pub fn parse(s: &str) -> Result<Effect, CalError> {
        Effect::ALL
            .into_iter()
            .find(|e| e.name() == s.trim())
            .ok_or_else(|| {
                CalError::Input(format!(
                    "unknown effect '{s}'; expected one of {}",
                    Effect::ALL.map(|e| e.name()).join(", ")
                ))
            })
    }

    /// The physical cause, for the diagnosis text (scale and misalignment read differently for
    /// the gyro, whose reference is a rotation rather than |g|).
    pub fn physics_for(self, sensor: &str) -> &'static str {
        match (self, sensor) {
            (Effect::Scale, "gyro") => "a gyro scale-factor error: each axis reports a rotation rate a few per cent off, so integrating it over a turn between two poses over- or under-rotates the gravity direction",
            (Effect::Misalignment, "gyro") => "non-orthogonal gyro axes, tilted with respect to the accelerometer's: a rotation about one axis is partly seen by the others, so the integrated turn ends on the wrong axis",
            _ => self.physics(),
        }
    }

    /// The physical cause, for the diagnosis text.
    pub fn physics(self) -> &'static str {
        match self {
            Effect::Offset => "a zero-g offset: the proof mass rests off-centre (packaging stress, solder) so every axis reads a constant when its true input is zero",
            Effect::Scale => "a sensitivity (scale-factor) error: the gain of each axis differs from its nominal LSB per unit, so opposite poses give |a| too long on one side and too short on the other",
            Effect::Misalignment => "non-orthogonal sensing axes: the three axes are not mounted at exactly 90° (die placement, package tilt), so a pure input on one axis leaks into the others and |a| depends on the direction between the axes",
            Effect::Bias => "a constant rate offset of the MEMS gyro at rest (Coriolis drive imbalance, quadrature leakage)",
            Effect::Temperature => "the gyro bias moves with die temperature (thermal stress on the resonator and its electronics), so the residual follows the temperature column",
            Effect::HardIron => "hard iron: permanently magnetised parts on the board add a constant field vector, shifting the sphere of measurements off the origin",
            Effect::SoftIron => "soft iron: magnetically permeable material near the sensor distorts the local field direction-dependently, turning the sphere into a tilted ellipsoid",
            Effect::SoftIron2d => "soft iron seen in the rotation plane: the circle of planar measurements becomes a tilted ellipse (Jaime et al., eqs. 4–5)",
            Effect::Tilt => "out-of-plane motion: the turn was not level, so the rotation plane wobbled and part of the vertical field leaked into the horizontal axes; the in-plane magnitude then follows the out-of-plane component while the full 3-D magnitude stays constant (not soft iron: no ellipse explains it)",
        }
    }
}

/// A model's effects joined by `+`, for messages ("(no correction)" when it has none).
pub(crate) fn model_names(model: &[Effect]) -> String {
    if model.is_empty() {
        "(no correction)".into()
    } else {
        model.iter().map(|e| e.name()).collect::<Vec<_>>().join("+")
    }
}

/// The fitted parameters; only the effects in the model are `Some`. Units: the data's (the
/// contract's m/s², deg/s, µT, °C for files in physical units; LSB for raw counts).
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct Params {
    /// Accelerometer offset (m/s²), subtracted first (Jaime et al., eq. 1).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub offset: Option<[f64; 3]>,
    /// Accelerometer scale factors (dimensionless, multiply after the offset; Jaime et al., eq. 1).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub scale: Option<[f64; 3]>,
    /// Non-orthogonality angles (deg): y-from-x, z-from-x, z-from-y of the lower-triangular T.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub misalignment_deg: Option<[f64; 3]>,
    /// Gyro bias at `temp_ref` (deg/s; Jaime et al., eq. 2).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub bias: Option<[f64; 3]>,
    /// Gyro bias temperature coefficient (deg/s per °C).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub temp_coeff: Option<[f64; 3]>,
    /// Reference temperature of `bias` (°C).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub temp_ref: Option<f64>,
    /// Gyro non-orthogonality angles (deg) γ₁…γ₆, the off-diagonal of T_g (see `gyro_rot`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub gyro_misalignment_deg: Option<[f64; 6]>,
    /// Magnetometer hard iron (µT; Jaime et al., eq. 3).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub hard_iron: Option<[f64; 3]>,
    /// Magnetometer soft-iron correction matrix (dimensionless), applied after the hard iron.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub soft_iron: Option<[[f64; 3]; 3]>,
    /// The 2-D soft-iron parameters of Jaime et al. (eqs. 4–5), when that effect is in the model.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub soft_iron_2d: Option<SoftIron2d>,
    /// Field magnitude F (µT), fitted or given.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub field: Option<f64>,
    /// Gravity g (m/s²) used by the accelerometer fit.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub g: Option<f64>,
}

/// The ellipse parameters of Jaime et al.: major axis r, minor q, tilt θ; σ = q/r (eqs. 4–5).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct SoftIron2d {
    /// Semi-major axis r (µT).
    pub r: f64,
    /// Semi-minor axis q (µT).
    pub q: f64,
    /// Tilt θ of the major axis from +X (deg).
    pub theta_deg: f64,
    /// σ = q/r (Jaime et al., eq. 5).
    pub sigma: f64,
}

impl Params {
    /// Every number the parameters hold, in a fixed order (the effects present only). With
    /// [`Params::with_values`] this maps a parameter set to a vector and back, e.g. to propagate
    /// uncertainties.
    pub fn values(&self) -> Vec<f64> {
        let mut v = Vec::new();
        let mut a3 = |x: &Option<[f64; 3]>| {
            if let Some(x) = x {
                v.extend_from_slice(x)
            }
        };
        a3(&self.offset);
        a3(&self.scale);
        a3(&self.misalignment_deg);
        a3(&self.bias);
        a3(&self.temp_coeff);
        a3(&self.hard_iron);
        if let Some(t) = self.temp_ref {
            v.push(t);
        }
        if let Some(g) = &self.gyro_misalignment_deg {
            v.extend_from_slice(g);
        }
        if let Some(m) = &self.soft_iron {
            v.extend(m.iter().flatten());
        }
        if let Some(e) = &self.soft_iron_2d {
            v.extend_from_slice(&[e.r, e.q, e.theta_deg, e.sigma]);
        }
        if let Some(f) = self.field {
            v.push(f);
        }
        if let Some(g) = self.g {
            v.push(g);
        }
        v
    }

    /// The same effects as `self` holding `v` (in [`Params::values`] order).
    pub fn with_values(&self, v: &[f64]) -> Params {
        let mut k = 0;
        let mut next = || {
            k += 1;
            v.get(k - 1).copied().unwrap_or(f64::NAN)
        };
        let mut out = self.clone();
        for x in [
            &mut out.offset,
            &mut out.scale,
            &mut out.misalignment_deg,
            &mut out.bias,
            &mut out.temp_coeff,
            &mut out.hard_iron,
        ]
        .into_iter()
        .flatten()
        {
            *x = [next(), next(), next()];
        }
        if let Some(t) = &mut out.temp_ref {
            *t = next();
        }
        if let Some(g) = &mut out.gyro_misalignment_deg {
            *g = std::array::from_fn(|_| next());
        }
        if let Some(m) = &mut out.soft_iron {
            *m = std::array::from_fn(|_| std::array::from_fn(|_| next()));
        }
        if let Some(e) = &mut out.soft_iron_2d {
            *e = SoftIron2d {
                r: next(),
                q: next(),
                theta_deg: next(),
                sigma: next(),
            };
        }
        if let Some(f) = &mut out.field {
            *f = next();
        }
        if let Some(g) = &mut out.g {
            *g = next();
        }
        out
    }

    /// [`Params::values`] with a name each: the field, then `.x`/`.y`/`.z` for vectors,
    /// `[i][j]` for matrices, `[i]` for the gyro angles, `.r`/`.q`/`.theta_deg`/`.sigma` for
    /// the ellipse (e.g. `offset.z`, `soft_iron[0][1]`).
    pub fn named_values(&self) -> Vec<(String, f64)> {
        let mut names: Vec<String> = Vec::new();
        let xyz = |f: &str| ["x", "y", "z"].map(|a| format!("{f}.{a}"));
        for (f, on) in [
            ("offset", self.offset.is_some()),
            ("scale", self.scale.is_some()),
            ("misalignment_deg", self.misalignment_deg.is_some()),
            ("bias", self.bias.is_some()),
            ("temp_coeff", self.temp_coeff.is_some()),
            ("hard_iron", self.hard_iron.is_some()),
        ] {
            if on {
                names.extend(xyz(f));
            }
        }
        if self.temp_ref.is_some() {
            names.push("temp_ref".into());
        }
        if self.gyro_misalignment_deg.is_some() {
            names.extend((0..6).map(|i| format!("gyro_misalignment_deg[{i}]")));
        }
        if self.soft_iron.is_some() {
            names.extend((0..9).map(|i| format!("soft_iron[{}][{}]", i / 3, i % 3)));
        }
        if self.soft_iron_2d.is_some() {
            names.extend(["r", "q", "theta_deg", "sigma"].map(|a| format!("soft_iron_2d.{a}")));
        }
        if self.field.is_some() {
            names.push("field".into());
        }
        if self.g.is_some() {
            names.push("g".into());
        }
        names.into_iter().zip(self.values()).collect()
    }

    /// The same effects with every value 0 (the uncertainty of given or fixed values).
    pub fn zeros_like(&self) -> Params {
        self.with_values(&vec![0.0; self.values().len()])
    }
}

/// Standard errors of `params` from a least-squares fit: the covariance of the free vector `x`
/// (None without residual degrees of freedom: every σ is then NaN) propagated through
/// `to_params`, which must give the same effects for every `x`.
pub fn params_sigma<G>(
    to_params: G,
    x: &nalgebra::DVector<f64>,
    cov: Option<&nalgebra::DMatrix<f64>>,
) -> Params
where
    G: Fn(&nalgebra::DVector<f64>) -> Params,
{
    let p = to_params(x);
    match cov {
        Some(c) if !x.is_empty() => {
            let s = crate::solve::propagate(|v| to_params(v).values(), x, c);
            p.with_values(&s)
        }
        Some(_) => p.zeros_like(),
        None => p.with_values(&vec![f64::NAN; p.values().len()]),
    }
}

/// One model fitted to one data set.
#[derive(Debug, Clone)]
pub struct Fitted {
    /// Effects in the model, sorted.
    pub model: Vec<Effect>,
    /// Parameters.
    pub params: Params,
    /// Their 1σ standard errors, same layout (0 for given values such as g, NaN when the data
    /// leave no degree of freedom).
    pub sigma: Params,
    /// Residuals on the lab's basis (per pose / per sample / per block), in the sensor unit,
    /// for every item, the excluded ones too (computed from `params`).
    pub residuals: Vec<f64>,
    /// Which residuals the fit used (false: the item was excluded as an outlier).
    pub used: Vec<bool>,
    /// Number of free parameters.
    pub n_params: usize,
    /// None when the solver converged; else why the parameters are only the best point it
    /// reached (reported, and the verdict accounts for it: module docs, 3).
    pub not_converged: Option<String>,
}

impl Fitted {
    /// A fit of every item: `used` all true.
    pub fn all_used(
        model: &[Effect],
        params: Params,
        sigma: Params,
        residuals: Vec<f64>,
        n_params: usize,
    ) -> Fitted {
        let used = vec![true; residuals.len()];
        Fitted {
            model: model.to_vec(),
            params,
            sigma,
            residuals,
            used,
            n_params,
            not_converged: None,
        }
    }

    /// The residuals the fit used.
    pub fn used_residuals(&self) -> impl Iterator<Item = f64> + '_ {
        self.residuals
            .iter()
            .zip(&self.used)
            .filter(|(_, u)| **u)
            .map(|(r, _)| *r)
    }
    /// Number of residuals used.
    pub fn n_used(&self) -> usize {
        self.used.iter().filter(|u| **u).count()
    }
    /// Residual sum of squares over the residuals used.
    pub fn rss(&self) -> f64 {
        self.used_residuals().map(|r| r * r).sum()
    }
    /// Residual RMS over the residuals used.
    pub fn rms(&self) -> f64 {
        let n = self.n_used();
        if n == 0 {
            return f64::NAN;
        }
        (self.rss() / n as f64).sqrt()
    }
    /// Residual degrees of freedom.
    pub fn dof(&self) -> f64 {
        self.n_used() as f64 - self.n_params as f64
    }
}

/// The noise floor of one data set: the variance each residual would have if the model were
/// complete, and how many degrees of freedom back that estimate.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct NoiseFloor {
    /// σ of one residual (sensor unit).
    pub sigma: f64,
    /// Degrees of freedom of the estimate (∞ written as a large number).
    pub dof: f64,
    /// How it was estimated.
    pub method: &'static str,
}

/// A calibration problem: one sensor's data prepared on the lab's basis. The data are cut into
/// *items* (poses, samples, block means or moves), each giving [`Problem::residuals_per_item`]
/// residuals, item after item.
pub trait Problem {
    /// Sensor name ("accel", "gyro", "mag").
    fn sensor(&self) -> &'static str;
    /// Unit of the residuals.
    fn unit(&self) -> &str;
    /// The sensor's effects.
    fn effects(&self) -> &'static [Effect];
    /// Effects that can be added to `model` with this data, and for the others why not.
    fn identifiable(&self, model: &[Effect], e: Effect) -> Result<(), String>;
    /// Fit a model to the items with `keep[i]` (one flag per item); residuals for every item.
    fn fit_items(&self, model: &[Effect], keep: &[bool]) -> Result<Fitted, CalError>;
    /// Fit a model to every item.
    fn fit(&self, model: &[Effect]) -> Result<Fitted, CalError> {
        self.fit_items(model, &vec![true; self.n()])
    }
    /// Noise floor on the residuals' basis.
    fn noise_floor(&self) -> NoiseFloor;
    /// Number of items.
    fn n(&self) -> usize;
    /// Residuals per item.
    fn residuals_per_item(&self) -> usize {
        1
    }
    /// What one residual is, for the report ("per-pose", "per-sample", …).
    fn basis(&self) -> &'static str {
        match self.sensor() {
            "accel" => "per-pose",
            "mag" => "per-sample",
            _ => "per-block",
        }
    }
    /// What one item is, plural ("poses", "samples", …).
    fn items(&self) -> &'static str {
        match self.sensor() {
            "accel" => "poses",
            "mag" => "samples",
            _ => "block means",
        }
    }
    /// The items to start the robust fit from (module docs, 1): those a fit that tolerates
    /// gross outliers finds consistent, one flag per item. None: no such start for this problem
    /// or model, and the robust fit starts from the least-squares fit of every item.
    fn robust_start(&self, _model: &[Effect]) -> Option<Vec<bool>> {
        None
    }
    /// The plausible half-range of the parameter `name` (a [`Params::named_values`] name such as
    /// `offset.z` or `soft_iron_2d.theta_deg`) before any data, in the data's unit, for the
    /// identifiability rule (module docs, 3); `params` is the fit, for ranges that scale with
    /// it (the magnetometer's field). None: the parameter is not judged.
    fn plausible_range(&self, _name: &str, _params: &Params) -> Option<f64> {
        None
    }
    /// Evidence outside the residual variance for a candidate effect (e.g. a correlation in the
    /// time domain), given the fit of the current model: `Ok(text)` supports trying it,
    /// `Err(text)` says why the data do not show it (it is then not tried); `None` when the
    /// effect needs none.
    fn evidence(&self, _fitted: &Fitted, _e: Effect) -> Option<Result<String, String>> {
        None
    }
}

/// The one-word verdict.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Verdict {
    /// The residual is consistent with the noise floor, every parameter is identified and the
    /// fit converged.
    Adequate,
    /// The residual exceeds the floor.
    NotAdequate,
    /// The residual is at the floor, but the data leave some parameter undetermined (named in
    /// [`Model::unidentified`]) or the fit stopped before its minimum.
    Underdetermined,
}

impl Verdict {
    /// Upper-case word for reports.
    pub fn word(self) -> &'static str {
        match self {
            Verdict::Adequate => "ADEQUATE",
            Verdict::NotAdequate => "NOT ADEQUATE",
            Verdict::Underdetermined => "UNDERDETERMINED",
        }
    }
}

/// The nested-model F-test of an effect added to a model (module docs, 5): both fitted on the
/// items the smaller model kept.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct NestedTest {
    /// `F = ((RSS₀ − RSS₁)/Δp) / (RSS₁/(N − p₁))`.
    pub f: f64,
    /// Δp, the extra parameters.
    pub extra_params: usize,
    /// N − p₁, the larger model's residual degrees of freedom.
    pub dof: f64,
    /// Upper-tail probability of `f` under F(Δp, N − p₁).
    pub p_value: f64,
}

/// A calibration model fitted and judged against the noise floor: the lab's model in the
/// project's lab workflow ([`model_lab::Lab`], implemented by [`CalLab`]).
#[derive(Debug, Clone)]
pub struct Model {
    /// The robust fit (module docs, 1).
    pub fitted: Fitted,
    /// Noise floor of the data.
    pub floor: NoiseFloor,
    /// Expected residual RMS for a complete model: σ·√((N − p)/N).
    pub expected_rms: f64,
    /// The residual variance per degree of freedom over the floor's variance, `s²/σ²`: the
    /// statistic of the adequacy test, F(N − p, ν)-distributed under a complete model (NaN for
    /// data without noise).
    pub ratio: f64,
    /// P(F ≥ `ratio`); NaN when it cannot be computed (no noise in the data, no degree of
    /// freedom).
    pub p_value: f64,
    /// The residual is at the floor (by the test or within the practical margin).
    pub fits_floor: bool,
    /// Some parameter is not identified by the data (module docs, 3): named in
    /// [`Model::unidentified`].
    pub underdetermined: bool,
    /// The parameters the data do not determine, each with its σ and plausible range (or
    /// "every parameter" when the residuals leave no degree of freedom); empty otherwise.
    pub unidentified: Vec<String>,
    /// Adequate, not adequate or underdetermined.
    pub verdict: Verdict,
    /// Items excluded as outliers.
    pub outliers: usize,
    /// The test of the effect added last against the model it was added to, when this model
    /// was reached by adding one (a candidate, a step); None for a model fitted directly.
    pub nested: Option<NestedTest>,
}

impl Model {
    /// True when the verdict is adequate (module docs, 3–4): never for an underdetermined model
    /// nor for a fit that did not converge.
    pub fn adequate(&self) -> bool {
        self.verdict == Verdict::Adequate
    }

    /// The effects in the model, sorted.
    pub fn effects(&self) -> &[Effect] {
        &self.fitted.model
    }
}

/// A candidate edit of a calibration model, refitted and tested: the workflow's candidate.
pub type Candidate = model_lab::Candidate<Effect, Model>;
/// One step of the calibration lab: the workflow's step record.
pub type Step = model_lab::Step<Effect>;

/// An effect of the sensor that was not tried on a model, and why (not identifiable from these
/// data, no evidence for it in the time domain, or its fit failed).
#[derive(Debug, Clone, Serialize)]
pub struct NotTried {
    /// The effect.
    pub effect: Effect,
    /// Why it was not tried, in words with numbers.
    pub reason: String,
}

/// What the lab says of a model.
#[derive(Debug, Clone)]
pub struct Diagnosis {
    /// The missing effect: the first admissible candidate's, if any.
    pub missing: Option<Effect>,
    /// Evidence and physical explanation, in words with numbers and units.
    pub explanation: String,
    /// Every candidate tried, in the lab's order of preference (admissible ones first, then by
    /// decreasing F).
    pub candidates: Vec<Candidate>,
    /// The sensor's other effects, not tried, with the reason.
    pub not_tried: Vec<NotTried>,
}

/// A lab report: the model, the diagnosis and the next step.
#[derive(Debug, Clone)]
pub struct Report {
    /// The judged model.
    pub model: Model,
    /// Verdict, explanation and candidates.
    pub diagnosis: Diagnosis,
    /// The step with the missing effect added, when one is missing.
    pub step: Option<Step>,
}

impl Report {
    /// The model after the step (the first admissible candidate's), when one is missing.
    pub fn next(&self) -> Option<&Model> {
        self.step.as_ref()?;
        self.diagnosis
            .candidates
            .iter()
            .find(|c| c.admissible)
            .map(|c| &c.model)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn params_values_round_trip() {
        let p = Params {
            offset: Some([1.0, 2.0, 3.0]),
            temp_ref: Some(25.0),
            soft_iron: Some([[1.0, 0.1, 0.0], [0.1, 0.9, 0.0], [0.0, 0.0, 1.0]]),
            soft_iron_2d: Some(SoftIron2d {
                r: 50.0,
                q: 40.0,
                theta_deg: 30.0,
                sigma: 0.8,
            }),
            field: Some(45.0),
            ..Params::default()
        };
        let v = p.values();
        assert_eq!(v.len(), 3 + 1 + 9 + 4 + 1);
        assert_eq!(p.with_values(&v), p);
        let z = p.zeros_like();
        assert!(z.values().iter().all(|x| *x == 0.0));
        assert_eq!(z.offset, Some([0.0; 3]));
        assert_eq!(z.scale, None);
    }
}
