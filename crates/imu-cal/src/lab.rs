//! The calibration lab: fit a model (a set of named effects), compare its residual with the
//! noise floor estimated from the same data, and when it is not adequate name the missing effect
//! by one general rule (issue 4 §2):
//!
//! 1. **Adequacy.** The residual variance per degree of freedom, `s² = RSS/(N − p)`, is compared
//!    with the noise-floor variance `σ²` estimated from the data itself on the same basis (per pose,
//!    per sample or per block). Under a complete model `s²/σ²` follows F(N − p, ν) (ν = degrees of
//!    freedom of the noise estimate). The model is adequate when the upper-tail probability is
//!    ≥ [`ALPHA_ADEQUATE`], or when the residual is within [`PRACTICAL_MARGIN`] of the floor
//!    (with thousands of samples the test alone would flag sub-percent excesses nobody can act on).
//! 2. **Which effect is missing.** Every effect of the sensor that is not yet in the model and is
//!    identifiable from this data is added in turn and the model refitted. The nested-model
//!    F-test (e.g. Seber & Wild, *Nonlinear Regression*, §5.3)
//!    `F = ((RSS₀ − RSS₁)/Δp) / (RSS₁/(N − p₁))` tells whether the drop is significant for the Δp
//!    extra parameters (p < [`ALPHA_EFFECT`]); among the significant ones the largest F wins.
//!
//! The same rule serves all three sensors; nothing is written for one effect.
use crate::solve::f_sf;
use serde::Serialize;

/// Significance level of the adequacy test.
pub const ALPHA_ADEQUATE: f64 = 0.01;
/// Significance level for an added effect.
pub const ALPHA_EFFECT: f64 = 0.001;
/// Residual RMS within this factor of the floor counts as adequate regardless of the test.
pub const PRACTICAL_MARGIN: f64 = 1.10;

/// The deterministic error effects the lab knows (issue 4 §1).
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
}

impl Effect {
    /// All effects, in the order.
    pub const ALL: [Effect; 8] = [
        Effect::Offset,
        Effect::Scale,
        Effect::Misalignment,
        Effect::Bias,
        Effect::Temperature,
        Effect::HardIron,
        Effect::SoftIron,
        Effect::SoftIron2d,
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
            Effect::SoftIron2d => "soft iron seen in the rotation plane: the circle of planar measurements becomes a tilted ellipse (seed eqs. 4–5)",
        }
    }
}

/// Errors of the fitting side: what went wrong and where.
#[derive(Debug, Clone, PartialEq)]
pub enum CalError {
    /// Bad or insufficient input data.
    Input(String),
    /// The model cannot be fitted from this data.
    Fit(String),
}

impl std::fmt::Display for CalError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            CalError::Input(s) => write!(f, "input: {s}"),
            CalError::Fit(s) => write!(f, "fit: {s}"),
        }
    }
}
impl std::error::Error for CalError {}

/// The fitted parameters; only the effects in the model are `Some` (JSON schema of issue 4 §3).
/// Units: the CSV contract's (m/s², deg/s, µT, °C).
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct Params {
    /// Accelerometer offset (m/s²), subtracted first (seed eq. 1).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub offset: Option<[f64; 3]>,
    /// Accelerometer scale factors (dimensionless, multiply after the offset; seed eq. 1).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub scale: Option<[f64; 3]>,
    /// Non-orthogonality angles (deg): y-from-x, z-from-x, z-from-y of the lower-triangular T.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub misalignment_deg: Option<[f64; 3]>,
    /// Gyro bias at `temp_ref` (deg/s; seed eq. 2).
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
    /// Magnetometer hard iron (µT; seed eq. 3).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub hard_iron: Option<[f64; 3]>,
    /// Magnetometer soft-iron correction matrix (dimensionless), applied after the hard iron.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub soft_iron: Option<[[f64; 3]; 3]>,
    /// The seed's 2-D soft-iron parameters (eqs. 4–5), when that effect is in the model.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub soft_iron_2d: Option<SoftIron2d>,
    /// Field magnitude F (µT), fitted or given.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub field: Option<f64>,
    /// Gravity g (m/s²) used by the accelerometer fit.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub g: Option<f64>,
}

/// The seed's ellipse parameters: major axis r, minor q, tilt θ; σ = q/r (eqs. 4–5).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct SoftIron2d {
    /// Semi-major axis r (µT).
    pub r: f64,
    /// Semi-minor axis q (µT).
    pub q: f64,
    /// Tilt θ of the major axis from +X (deg).
    pub theta_deg: f64,
    /// σ = q/r (seed eq. 5).
    pub sigma: f64,
}

/// One model fitted to one data set.
#[derive(Debug, Clone)]
pub struct Fitted {
    /// Effects in the model, sorted.
    pub model: Vec<Effect>,
    /// Parameters.
    pub params: Params,
    /// Residuals on the lab's basis (per pose / per sample / per block), in the sensor unit.
    pub residuals: Vec<f64>,
    /// Number of free parameters.
    pub n_params: usize,
}

impl Fitted {
    /// Residual sum of squares.
    pub fn rss(&self) -> f64 {
        self.residuals.iter().map(|r| r * r).sum()
    }
    /// Residual RMS.
    pub fn rms(&self) -> f64 {
        crate::solve::rms(&self.residuals)
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

/// A calibration problem: one sensor's data prepared on the lab's basis.
pub trait Problem {
    /// Sensor name ("accel", "gyro", "mag").
    fn sensor(&self) -> &'static str;
    /// Unit of the residuals.
    fn unit(&self) -> &'static str;
    /// The sensor's effects.
    fn effects(&self) -> &'static [Effect];
    /// Effects that can be added to `model` with this data, and for the others why not.
    fn identifiable(&self, model: &[Effect], e: Effect) -> Result<(), String>;
    /// Fit a model.
    fn fit(&self, model: &[Effect]) -> Result<Fitted, CalError>;
    /// Noise floor on the residuals' basis.
    fn noise_floor(&self) -> NoiseFloor;
    /// Number of residuals.
    fn n(&self) -> usize;
    /// What one residual is, for the report ("per-pose", "per-sample", …).
    fn basis(&self) -> &'static str {
        match self.sensor() {
            "accel" => "per-pose",
            "mag" => "per-sample",
            _ => "per-block",
        }
    }
}

/// Evidence for one candidate effect.
#[derive(Debug, Clone, Serialize)]
pub struct Candidate {
    /// The effect tried.
    pub effect: Effect,
    /// Residual RMS with it added (sensor unit), None when not identifiable.
    pub residual_rms: Option<f64>,
    /// The nested F statistic.
    pub f: Option<f64>,
    /// Its upper-tail probability.
    pub p_value: Option<f64>,
    /// Extra parameters.
    pub extra_params: usize,
    /// Why it was not tried, if so.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub skipped: Option<String>,
}

/// The verdict on a model.
#[derive(Debug, Clone, Serialize)]
pub struct Diagnosis {
    /// True when the residual is consistent with the noise floor.
    pub adequate: bool,
    /// The missing effect, if one was found significant.
    pub missing: Option<Effect>,
    /// Evidence and physical explanation, in words with numbers and units.
    pub explanation: String,
    /// P(residual variance ≥ observed | complete model).
    pub p_value: f64,
    /// Every candidate tried.
    pub candidates: Vec<Candidate>,
}

/// Residual RMS before → after adding the missing effect.
#[derive(Debug, Clone, Serialize)]
pub struct Step {
    /// The effect added.
    pub added: Effect,
    /// Model after the step.
    pub model: Vec<Effect>,
    /// Residual RMS before (sensor unit).
    pub residual_rms_before: f64,
    /// Residual RMS after (sensor unit).
    pub residual_rms_after: f64,
    /// Parameters after the step.
    pub params: Params,
}

/// A lab report: the fit, its residual against the floor, the diagnosis and the next step.
#[derive(Debug, Clone)]
pub struct Report {
    /// The fit of the requested model.
    pub fitted: Fitted,
    /// Noise floor.
    pub floor: NoiseFloor,
    /// Expected residual RMS for a complete model: σ·√((N − p)/N).
    pub expected_rms: f64,
    /// Verdict.
    pub diagnosis: Diagnosis,
    /// The step with the missing effect added, when one is missing.
    pub step: Option<Step>,
}

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

/// Run the lab on a problem and a model (module docs).
pub fn analyse(p: &dyn Problem, model: &[Effect]) -> Result<Report, CalError> {
    let model = normalise_model(p, model)?;
    let fitted = p.fit(&model)?;
    let floor = p.noise_floor();
    let n = fitted.residuals.len() as f64;
    let k = fitted.n_params as f64;
    let dof = (n - k).max(1.0);
    let expected_rms = floor.sigma * (dof / n).sqrt();
    let s2 = fitted.rss() / dof;
    let ratio = s2 / (floor.sigma * floor.sigma);
    let p_adequate = f_sf(ratio, dof, floor.dof);
    let rms = fitted.rms();
    // (A noiseless recording, e.g. constant counts, has a zero floor: then only a residual at
    // rounding level is adequate.)
    let adequate = p_adequate >= ALPHA_ADEQUATE
        || rms <= PRACTICAL_MARGIN * expected_rms
        || (floor.sigma == 0.0 && rms < 1e-9);
    let unit = p.unit();

    let mut candidates = Vec::new();
    let mut best: Option<(f64, Fitted)> = None;
    for &e in p.effects() {
        if model.contains(&e) {
            continue;
        }
        if let Err(why) = p.identifiable(&model, e) {
            candidates.push(Candidate {
                effect: e,
                residual_rms: None,
                f: None,
                p_value: None,
                extra_params: 0,
                skipped: Some(why),
            });
            continue;
        }
        let mut m1 = model.clone();
        m1.push(e);
        m1.sort();
        let f1 = match p.fit(&m1) {
            Ok(f) => f,
            Err(err) => {
                candidates.push(Candidate {
                    effect: e,
                    residual_rms: None,
                    f: None,
                    p_value: None,
                    extra_params: 0,
                    skipped: Some(err.to_string()),
                });
                continue;
            }
        };
        let dp = f1.n_params.saturating_sub(fitted.n_params).max(1) as f64;
        let dof1 = (n - f1.n_params as f64).max(1.0);
        let f = ((fitted.rss() - f1.rss()) / dp) / (f1.rss() / dof1).max(1e-300);
        let pv = f_sf(f, dp, dof1);
        candidates.push(Candidate {
            effect: e,
            residual_rms: Some(f1.rms()),
            f: Some(f),
            p_value: Some(pv),
            extra_params: dp as usize,
            skipped: None,
        });
        if pv < ALPHA_EFFECT && best.as_ref().is_none_or(|(bf, _)| f > *bf) {
            best = Some((f, f1));
        }
    }

    let verdict = format!(
        "residual RMS {rms:.4} {unit} vs noise floor {:.4} {unit} expected for a complete model \
         ({} {} residuals, {} fitted parameters; noise from {}); P(F ≥ {ratio:.2}) = {p_adequate:.3}",
        expected_rms,
        fitted.residuals.len(),
        p.basis(),
        fitted.n_params,
        floor.method
    );
    let (missing, explanation, step) =
        if adequate {
            (None, format!("adequate: {verdict}."), None)
        } else if let Some((f, f1)) = best {
            let e = *f1
                .model
                .iter()
                .find(|e| !model.contains(e))
                .expect("added effect");
            let c = candidates
                .iter()
                .find(|c| c.effect == e)
                .expect("candidate");
            let text = format!(
            "not adequate: {verdict}. Adding '{}' lowers the residual RMS {rms:.4} → {:.4} {unit} \
             (F = {f:.1} for {} extra parameters, p = {:.2e}), the most significant of the \
             candidates. Physically: {}.",
            e.name(),
            f1.rms(),
            c.extra_params,
            c.p_value.unwrap_or(f64::NAN),
            e.physics_for(p.sensor())
        );
            let step = Step {
                added: e,
                model: f1.model.clone(),
                residual_rms_before: rms,
                residual_rms_after: f1.rms(),
                params: f1.params.clone(),
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
                if tried.is_empty() { String::new() } else { format!(" ({})", tried.join(", ")) },
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
            adequate,
            missing,
            explanation,
            p_value: p_adequate,
            candidates,
        },
        step,
    })
}
