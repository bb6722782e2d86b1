//! The effect library: every noise or error effect the lab knows, its exact sampled-data Allan
//! variance, its canonical parameters and their units, the conventional display units, a
//! paragraph on the physics and its Allan-plot signature.
//!
//! Power-law terms follow IEEE Std 952-1997 Annex C and eqs. 10–14 of I. Jaime, F. Beck Ferrero,
//! M. L. Miretti, E. Bernardi, "Caracterización y calibración de unidades de medición inercial de
//! bajo costo" (UTN Facultad Regional San Francisco): σ²(τ) = 3Q²/τ², N²/τ, (2 ln2/π)B², K²τ/3,
//! R²τ²/2. The Gauss–Markov and sinusoid terms follow IEEE Std 952-1997 C.7/C.8; the resonance
//! (second-order Gauss–Markov) term P. S. Maybeck, *Stochastic Models, Estimation and Control*,
//! vol. 1 (1979), ch. 4 (shaping filters), sampled exactly ([`crate::structure::oscillator_v`]).
//!
//! Every term is `coefficient × basis(τ)` with a non-negative coefficient (the square of the
//! amplitude parameter), which makes the fit a non-negative linear least-squares problem once the
//! non-linear parameters (τ_c, f, a filter's corner or length) are fixed. Stochastic effects are
//! defined by their structure function V(k) ([`crate::structure`]), which gives both the exact
//! expected overlapping Allan variance of the *sampled* process, σ²(m) = (4V(m) − V(2m))/(2m²),
//! and the covariance of the Allan estimates ([`crate::cov`]). Deterministic effects (a ramp, a
//! sinusoid, a bias step, a temperature-driven bias, a smooth drift) have their exact expected
//! Allan variance computed over the record's own segments.
use core::fmt;
use std::sync::Arc;

mod avar;
mod params;
mod text;
mod units;
pub mod user;
use avar::octaves;
pub use avar::{
    drift_at, drift_avar, drift_gram, drift_norm, drift_span, markov_avar_continuous,
    markov_avar_unit, resonance_avar_unit, resonance_psd_unit, resonance_structure,
    sinusoid_avar_unit, step_avar, warmup_avar, Basis, DRIFT_MAX_COMPONENTS, RESONANCE_ZETA_MAX,
    RESONANCE_ZETA_START,
};
pub use params::{Context, ParamSpec};
pub use units::{DisplayUnit, UnitFamily, G0};
use user::UserEffect;

/// An effect of the vocabulary. Built-ins are named in [`Effect::name`]; user effects come from a
/// description file ([`crate::user`]).
#[derive(Debug, Clone)]
pub enum Effect {
    Quantization,
    White,
    Flicker,
    RateRandomWalk,
    RateRamp,
    Markov,
    Sinusoid,
    /// Rounding of the rate samples to the data's LSB: white, variance LSB²/12 per sample.
    Resolution,
    /// A jump of the bias at one instant.
    BiasStep,
    /// The bias following the temperature column, or a warm-up transient when there is none.
    Temperature,
    /// A smooth drift of the bias over the record: a ramp and `components` cosines of the
    /// record's length (periods 2T, 2T/2, …), their shape found in the time domain.
    Drift {
        components: u8,
    },
    /// White noise through a one-pole low-pass filter (corner f_c).
    Lowpass,
    /// White noise through two cascaded one-pole sections (critically damped two-pole low-pass).
    Lowpass2,
    /// White noise through a moving average of L output samples (boxcar decimation filter).
    Boxcar,
    /// White noise through a triangular (Bartlett) filter, two boxcars of L samples in cascade.
    Bartlett,
    /// White noise driving a damped harmonic oscillator (second-order Gauss–Markov): a mount or
    /// structural mode at f0 with damping ratio ζ < 1.
    Resonance,
    /// A user-described effect.
    User(Arc<UserEffect>),
}

impl PartialEq for Effect {
    fn eq(&self, other: &Self) -> bool {
        self.name() == other.name()
    }
}
impl Eq for Effect {}

impl std::hash::Hash for Effect {
    fn hash<H: std::hash::Hasher>(&self, state: &mut H) {
        self.name().hash(state)
    }
}

/// The five power-law terms of eqs. 10–14 (Jaime et al.), the default model.
pub const DEFAULT_TERMS: [Effect; 5] = [
    Effect::Quantization,
    Effect::White,
    Effect::Flicker,
    Effect::RateRandomWalk,
    Effect::RateRamp,
];

/// Every built-in effect, in vocabulary order.
pub const ALL_EFFECTS: [Effect; 16] = [
    Effect::Quantization,
    Effect::White,
    Effect::Flicker,
    Effect::RateRandomWalk,
    Effect::RateRamp,
    Effect::Markov,
    Effect::Sinusoid,
    Effect::Resolution,
    Effect::BiasStep,
    Effect::Temperature,
    Effect::Drift { components: 0 },
    Effect::Lowpass,
    Effect::Lowpass2,
    Effect::Boxcar,
    Effect::Bartlett,
    Effect::Resonance,
];

/// How an effect enters the Allan variance and the covariance of the estimates.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// A Gaussian noise with a structure function.
    Stochastic,
    /// A constant rate ramp: every second difference is the same.
    Ramp,
    /// A random-phase sinusoid.
    Sine,
    /// A deterministic signal localised or shaped in time (step, temperature, warm-up).
    Signal,
}

impl Effect {
    /// The name used in the vocabulary, the CLI and the JSON output.
    pub fn name(&self) -> &str {
        match self {
            Effect::Quantization => "quantization",
            Effect::White => "white",
            Effect::Flicker => "flicker",
            Effect::RateRandomWalk => "rate_random_walk",
            Effect::RateRamp => "rate_ramp",
            Effect::Markov => "markov",
            Effect::Sinusoid => "sinusoid",
            Effect::Resolution => "resolution",
            Effect::BiasStep => "bias_step",
            Effect::Temperature => "temperature",
            Effect::Drift { .. } => "drift",
            Effect::Lowpass => "lowpass",
            Effect::Lowpass2 => "lowpass2",
            Effect::Boxcar => "boxcar",
            Effect::Bartlett => "bartlett",
            Effect::Resonance => "resonance",
            Effect::User(u) => &u.name,
        }
    }

    /// Parse a built-in vocabulary name (a few common aliases accepted).
    pub fn parse(s: &str) -> Option<Effect> {
        Some(
            match s.trim().to_ascii_lowercase().replace('-', "_").as_str() {
                "quantization" | "quantisation" | "q" => Effect::Quantization,
                "white" | "arw" | "vrw" | "angle_random_walk" | "n" => Effect::White,
                "flicker" | "bias_instability" | "b" => Effect::Flicker,
                "rate_random_walk" | "rrw" | "k" => Effect::RateRandomWalk,
                "rate_ramp" | "ramp" | "r" => Effect::RateRamp,
                "markov" | "gauss_markov" | "correlated" => Effect::Markov,
                "sinusoid" | "sine" | "sinusoidal" => Effect::Sinusoid,
                "resolution" | "lsb" | "rounding" => Effect::Resolution,
                "bias_step" | "step" => Effect::BiasStep,
                "temperature" | "temp" | "warm_up" | "warmup" => Effect::Temperature,
                "drift" | "smooth_drift" | "trend" => Effect::Drift { components: 0 },
                "lowpass" | "lowpass1" | "dlpf" => Effect::Lowpass,
                "lowpass2" => Effect::Lowpass2,
                "boxcar" | "moving_average" => Effect::Boxcar,
                "bartlett" | "triangular" => Effect::Bartlett,
                "resonance" | "second_order_markov" | "gauss_markov2" | "gm2" | "oscillator" => {
                    Effect::Resonance
                }
                _ => return None,
            },
        )
    }

    /// How the effect enters the statistics.
    pub fn kind(&self) -> Kind {
        match self {
            Effect::RateRamp => Kind::Ramp,
            Effect::Sinusoid => Kind::Sine,
            Effect::BiasStep | Effect::Temperature | Effect::Drift { .. } => Kind::Signal,
            _ => Kind::Stochastic,
        }
    }

    /// Whether the amplitude is estimated outside the Allan fit (in the time domain or from the
    /// data's lattice) and enters the Allan model as a known term.
    pub fn time_domain(&self) -> bool {
        matches!(
            self,
            Effect::BiasStep | Effect::Temperature | Effect::Drift { .. } | Effect::Resolution
        )
    }

    /// Whether a model may hold more than one term of this effect.
    pub fn repeatable(&self) -> bool {
        matches!(
            self,
            Effect::Markov | Effect::Sinusoid | Effect::BiasStep | Effect::Resonance
        )
    }

    /// A filter effect describes the white noise it shapes, so it takes the white term's place.
    pub fn replaces_white(&self) -> bool {
        matches!(
            self,
            Effect::Lowpass | Effect::Lowpass2 | Effect::Boxcar | Effect::Bartlett
        )
    }

    /// Log-log slope of σ(τ) for the power-law terms (None otherwise).
    pub fn adev_slope(&self) -> Option<f64> {
        match self {
            Effect::Quantization => Some(-1.0),
            Effect::White | Effect::Resolution => Some(-0.5),
            Effect::Flicker => Some(0.0),
            Effect::RateRandomWalk => Some(0.5),
            Effect::RateRamp => Some(1.0),
            _ => None,
        }
    }
}

impl fmt::Display for Effect {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}
#[cfg(test)]
mod tests;
