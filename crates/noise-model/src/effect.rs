//! The effect library: every noise or error effect the lab knows, its exact sampled-data Allan
//! variance, its canonical parameters and their units, the conventional display units, a
//! paragraph on the physics and its Allan-plot signature.
//!
//! Power-law terms follow IEEE Std 952-1997 Annex C and eqs. 10–14 of I. Jaime, F. Beck Ferrero,
//! M. L. Miretti, E. Bernardi, "Caracterización y calibración de unidades de medición inercial de
//! bajo costo" (UTN Facultad Regional San Francisco): σ²(τ) = 3Q²/τ², N²/τ, (2 ln2/π)B², K²τ/3,
//! R²τ²/2. The Gauss–Markov and sinusoid terms follow IEEE Std 952-1997 C.7/C.8.
//!
//! Every term is `coefficient × basis(τ)` with a non-negative coefficient (the square of the
//! amplitude parameter), which makes the fit a non-negative linear least-squares problem once the
//! non-linear parameters (τ_c, f, a filter's corner or length) are fixed. Stochastic effects are
//! defined by their structure function V(k) ([`crate::structure`]), which gives both the exact
//! expected overlapping Allan variance of the *sampled* process, σ²(m) = (4V(m) − V(2m))/(2m²),
//! and the covariance of the Allan estimates ([`crate::cov`]). Deterministic effects (a ramp, a
//! sinusoid, a bias step, a temperature-driven bias) have their exact expected Allan variance
//! computed over the record's own segments.
use crate::structure::{RTable, Structure};
use crate::user::UserEffect;
use core::fmt;
use std::sync::Arc;

mod avar;
use avar::octaves;
pub use avar::{
    markov_avar_continuous, markov_avar_unit, sinusoid_avar_unit, step_avar, warmup_avar, Basis,
};

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
    /// White noise through a one-pole low-pass filter (corner f_c).
    Lowpass,
    /// White noise through two cascaded one-pole sections (critically damped two-pole low-pass).
    Lowpass2,
    /// White noise through a moving average of L output samples (boxcar decimation filter).
    Boxcar,
    /// White noise through a triangular (Bartlett) filter, two boxcars of L samples in cascade.
    Bartlett,
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
pub const ALL_EFFECTS: [Effect; 14] = [
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
    Effect::Lowpass,
    Effect::Lowpass2,
    Effect::Boxcar,
    Effect::Bartlett,
];

/// One conventional display unit: `display = canonical × factor`.
#[derive(Debug, Clone, PartialEq)]
pub struct DisplayUnit {
    pub unit: String,
    pub factor: f64,
}

/// Standard gravity, m/s² (CGPM 1901), for µg conversions.
pub const G0: f64 = 9.806_65;

/// The channel's unit family, which decides the conventional display units.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum UnitFamily {
    /// deg/s (gyroscope)
    DegPerS,
    /// rad/s (gyroscope)
    RadPerS,
    /// m/s² (accelerometer)
    MPerS2,
    /// anything else: conventional = canonical
    Other,
}

impl UnitFamily {
    pub fn of(unit: &str) -> Self {
        match unit.trim() {
            "deg/s" | "°/s" | "dps" => UnitFamily::DegPerS,
            "rad/s" => UnitFamily::RadPerS,
            "m/s^2" | "m/s²" | "m/s2" => UnitFamily::MPerS2,
            _ => UnitFamily::Other,
        }
    }
}

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

/// A non-linear parameter of an effect and its search range.
#[derive(Debug, Clone, PartialEq)]
pub struct ParamSpec {
    pub name: String,
    pub unit: String,
    /// Search range [lo, hi] and whether the grid is logarithmic.
    pub lo: f64,
    pub hi: f64,
    pub log: bool,
    /// Grid points per decade (log) or in all (linear).
    pub density: f64,
}

/// What the bases of record-dependent effects need to know about the recording.
#[derive(Debug, Clone, Default)]
pub struct Context {
    /// Sample period [s].
    pub tau0: f64,
    /// Segments of uninterrupted samples: (index of the first sample counted from the start of
    /// the record as if there were no gaps, number of samples).
    pub segments: Vec<(u64, u64)>,
    /// The exact overlapping Allan variance of the temperature column [°C²] at averaging factors
    /// m (ascending), when the record has one.
    pub temp_avar: Option<Vec<(u64, f64)>>,
    /// Shortest and longest τ of the measured points [s] (search ranges).
    pub tau_min: f64,
    pub tau_max: f64,
}

impl Context {
    /// A context for an uninterrupted record of `n` samples.
    pub fn uniform(tau0: f64, n: u64) -> Context {
        Context {
            tau0,
            segments: vec![(0, n)],
            temp_avar: None,
            tau_min: tau0,
            tau_max: tau0 * (n as f64 / 4.0).max(1.0),
        }
    }

    /// Total number of samples.
    pub fn samples(&self) -> u64 {
        self.segments.iter().map(|s| s.1).sum()
    }

    /// Number of second differences at m over all segments.
    pub fn terms(&self, m: u64) -> u64 {
        self.segments
            .iter()
            .map(|&(_, l)| (l + 1).saturating_sub(2 * m))
            .sum()
    }
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
            Effect::Lowpass => "lowpass",
            Effect::Lowpass2 => "lowpass2",
            Effect::Boxcar => "boxcar",
            Effect::Bartlett => "bartlett",
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
                "lowpass" | "lowpass1" | "dlpf" => Effect::Lowpass,
                "lowpass2" => Effect::Lowpass2,
                "boxcar" | "moving_average" => Effect::Boxcar,
                "bartlett" | "triangular" => Effect::Bartlett,
                _ => return None,
            },
        )
    }

    /// How the effect enters the statistics.
    pub fn kind(&self) -> Kind {
        match self {
            Effect::RateRamp => Kind::Ramp,
            Effect::Sinusoid => Kind::Sine,
            Effect::BiasStep | Effect::Temperature => Kind::Signal,
            _ => Kind::Stochastic,
        }
    }

    /// Whether the amplitude is estimated outside the Allan fit (in the time domain or from the
    /// data's lattice) and enters the Allan model as a known term.
    pub fn time_domain(&self) -> bool {
        matches!(
            self,
            Effect::BiasStep | Effect::Temperature | Effect::Resolution
        )
    }

    /// Whether a model may hold more than one term of this effect.
    pub fn repeatable(&self) -> bool {
        matches!(self, Effect::Markov | Effect::Sinusoid | Effect::BiasStep)
    }

    /// A filter effect describes the white noise it shapes, so it takes the white term's place.
    pub fn replaces_white(&self) -> bool {
        matches!(
            self,
            Effect::Lowpass | Effect::Lowpass2 | Effect::Boxcar | Effect::Bartlett
        )
    }

    /// Name of the amplitude parameter (the square root of the linear coefficient).
    pub fn amp_name(&self) -> &str {
        match self {
            Effect::Quantization => "Q",
            Effect::White => "N",
            Effect::Flicker => "B",
            Effect::RateRandomWalk => "K",
            Effect::RateRamp => "R",
            Effect::Markov => "sigma",
            Effect::Sinusoid => "amplitude",
            Effect::Resolution => "lsb",
            Effect::BiasStep => "size",
            Effect::Temperature => "coefficient",
            Effect::Lowpass | Effect::Lowpass2 | Effect::Boxcar | Effect::Bartlett => "N",
            Effect::User(u) => &u.amplitude.name,
        }
    }

    /// Canonical unit of the amplitude parameter for a channel in unit `u` (τ in seconds).
    /// `warm_up`: the temperature effect without a temperature column (amplitude in u).
    pub fn amp_unit(&self, u: &str, warm_up: bool) -> String {
        match (self, u) {
            (Effect::Quantization, "deg/s") => return "deg".into(),
            (Effect::Quantization, "rad/s") => return "rad".into(),
            (Effect::Quantization, "m/s²" | "m/s^2") => return "m/s".into(),
            (Effect::RateRamp, "deg/s") => return "deg/s²".into(),
            (Effect::RateRamp, "rad/s") => return "rad/s²".into(),
            (Effect::RateRamp, "m/s²" | "m/s^2") => return "m/s³".into(),
            _ => {}
        }
        match self {
            Effect::Quantization => format!("{u}·s"),
            Effect::White
            | Effect::Lowpass
            | Effect::Lowpass2
            | Effect::Boxcar
            | Effect::Bartlett => {
                format!("{u}·√s")
            }
            Effect::Flicker
            | Effect::Markov
            | Effect::Sinusoid
            | Effect::Resolution
            | Effect::BiasStep => u.to_string(),
            Effect::Temperature => {
                if warm_up {
                    u.to_string()
                } else {
                    format!("{u}/°C")
                }
            }
            Effect::RateRandomWalk => format!("{u}/√s"),
            Effect::RateRamp => format!("{u}/s"),
            Effect::User(e) => e.amplitude.unit.replace('u', u),
        }
    }

    /// The non-linear parameters and their search ranges for a record (`ctx`). The temperature
    /// effect has none with a temperature column and a warm-up time constant without one.
    pub fn nonlinear(&self, ctx: &Context) -> Vec<ParamSpec> {
        let (tmin, tmax, tau0) = (
            ctx.tau_min.max(ctx.tau0),
            ctx.tau_max.max(ctx.tau0),
            ctx.tau0,
        );
        let spec = |name: &str, unit: &str, lo: f64, hi: f64, density: f64| ParamSpec {
            name: name.into(),
            unit: unit.into(),
            lo,
            hi,
            log: true,
            density,
        };
        let record = ctx.samples() as f64 * tau0;
        match self {
            Effect::Markov => vec![spec(
                "tau_c",
                "s",
                (tmin / 4.0).max(tau0 / 8.0),
                4.0 * tmax,
                16.0,
            )],
            Effect::Sinusoid => vec![spec("freq_hz", "Hz", 0.25 / tmax, 0.5 / tau0 * 0.999, 80.0)],
            // A sensor's own filter acts within a few hundred samples: corners from fs/2000 to
            // 2·fs, lengths up to 1024 samples. Slower correlation is a Markov process.
            Effect::Lowpass | Effect::Lowpass2 => vec![spec(
                "cutoff_hz",
                "Hz",
                1.0 / (2000.0 * tau0),
                2.0 / tau0,
                16.0,
            )],
            Effect::Boxcar | Effect::Bartlett => {
                let hi = (ctx.samples() as f64 / 16.0).clamp(2.0, 1024.0);
                vec![spec("length", "samples", 1.0, hi, 24.0)]
            }
            Effect::BiasStep => vec![ParamSpec {
                name: "time_s".into(),
                unit: "s".into(),
                lo: 0.0,
                hi: record,
                log: false,
                density: 0.0,
            }],
            Effect::Temperature if ctx.temp_avar.is_none() => {
                vec![spec(
                    "time_constant_s",
                    "s",
                    record / 300.0,
                    record * 3.0,
                    8.0,
                )]
            }
            Effect::User(u) => u.params.clone(),
            _ => Vec::new(),
        }
    }

    /// The basis for fixed non-linear parameters `theta` (as ordered by [`Effect::nonlinear`]).
    pub fn basis(&self, theta: &[f64], ctx: &Context) -> Result<Basis, String> {
        let tau0 = ctx.tau0;
        let th = |i: usize| theta.get(i).copied().unwrap_or(f64::NAN);
        let pi = std::f64::consts::PI;
        Ok(match self {
            Effect::Quantization => Basis::Stochastic {
                structure: Structure::PhaseWhite,
                factor: 1.0 / (tau0 * tau0),
            },
            Effect::White => Basis::Stochastic {
                structure: Structure::Linear,
                factor: 1.0 / tau0,
            },
            Effect::Resolution => Basis::Stochastic {
                structure: Structure::Linear,
                factor: 1.0 / 12.0,
            },
            Effect::Flicker => Basis::Stochastic {
                structure: Structure::Flicker,
                factor: 1.0,
            },
            Effect::RateRandomWalk => Basis::Stochastic {
                structure: Structure::Cubic,
                factor: tau0,
            },
            Effect::RateRamp => Basis::Ramp,
            Effect::Markov => {
                let tc = th(0);
                if !(tc > 0.0) {
                    return Ok(Basis::Zero);
                }
                Basis::Stochastic {
                    structure: Structure::Ar1 {
                        phi: (-tau0 / tc).exp(),
                    },
                    factor: 1.0,
                }
            }
            Effect::Sinusoid => {
                let f = th(0);
                if !(f > 0.0) {
                    return Ok(Basis::Zero);
                }
                Basis::Sine {
                    theta: 2.0 * pi * f * tau0,
                }
            }
            Effect::Lowpass => {
                let fc = th(0);
                if !(fc > 0.0) {
                    return Ok(Basis::Zero);
                }
                let phi = (-2.0 * pi * fc * tau0).exp();
                Basis::Stochastic {
                    structure: Structure::Ar1 { phi },
                    factor: (1.0 - phi) / (1.0 + phi) / tau0,
                }
            }
            Effect::Lowpass2 => {
                let fc = th(0);
                if !(fc > 0.0) {
                    return Ok(Basis::Zero);
                }
                let phi = (-2.0 * pi * fc * tau0).exp();
                let q = phi * phi;
                let g = (1.0 - phi).powi(4);
                let (a, b) = ((1.0 + q) / (1.0 - q).powi(3), 1.0 / (1.0 - q).powi(2));
                let t = RTable::from_fn(
                    |k| g * phi.powi(k as i32) * (a + k as f64 * b),
                    1e-13,
                    50_000_000,
                )?;
                Basis::Stochastic {
                    structure: Structure::Table(Arc::new(t)),
                    factor: 1.0 / tau0,
                }
            }
            Effect::Boxcar | Effect::Bartlett => {
                let l = th(0);
                if !(l >= 1.0) {
                    return Ok(Basis::Zero);
                }
                let bartlett = matches!(self, Effect::Bartlett);
                let r = |k: usize| {
                    let x = k as f64 / l;
                    let v = if bartlett {
                        crate::structure::bspline3(x)
                    } else {
                        (1.0 - x).max(0.0)
                    };
                    v / l
                };
                let len = if bartlett { 2.0 * l } else { l }.ceil() as usize + 1;
                let vals: Vec<f64> = (0..=len).map(r).collect();
                Basis::Stochastic {
                    structure: Structure::Table(Arc::new(RTable::new(&vals))),
                    factor: 1.0 / tau0,
                }
            }
            Effect::BiasStep => {
                let t = th(0);
                if !t.is_finite() {
                    return Ok(Basis::Zero);
                }
                let s = (t / tau0).round().max(0.0) as u64;
                Basis::Table(octaves(ctx).map(|m| (m, step_avar(s, m, ctx))).collect())
            }
            Effect::Temperature => match &ctx.temp_avar {
                Some(t) => Basis::Table(t.clone()),
                None => {
                    let tw = th(0);
                    if !(tw > 0.0) {
                        return Ok(Basis::Zero);
                    }
                    let kappa = tw / tau0;
                    Basis::Table(
                        octaves(ctx)
                            .map(|m| (m, warmup_avar(kappa, m, ctx)))
                            .collect(),
                    )
                }
            },
            Effect::User(u) => u.basis(theta, tau0)?,
        })
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

    /// Conventional display unit for the amplitude parameter, with `display = canonical × factor`.
    ///
    /// Conversions: 1 s = 1/3600 h, so deg·√s = deg/√h × 1/60 (N[°/√h] = 60·N[°/s·√s]);
    /// B[°/h] = 3600·B[°/s]; K[°/h/√h] = 3600·60·K[°/s/√s]; R[°/h²] = 3600²·R[°/s²];
    /// 1 µg = 9.80665e-6 m/s²; N[µg/√Hz] = N[m/s²·√s]/9.80665e-6 (a one-sided PSD level
    /// of white noise equals N², IEEE 952 C.2).
    pub fn amp_display(&self, family: UnitFamily, warm_up: bool) -> Option<DisplayUnit> {
        let d = |unit: &str, factor: f64| {
            Some(DisplayUnit {
                unit: unit.to_string(),
                factor,
            })
        };
        let ug = 1e6 / G0;
        let r2d = 180.0 / std::f64::consts::PI;
        match family {
            UnitFamily::DegPerS | UnitFamily::RadPerS => {
                let k = if family == UnitFamily::RadPerS {
                    r2d
                } else {
                    1.0
                };
                match self {
                    Effect::Quantization => d("arcsec", 3600.0 * k),
                    Effect::White
                    | Effect::Lowpass
                    | Effect::Lowpass2
                    | Effect::Boxcar
                    | Effect::Bartlett => d("°/√h", 60.0 * k),
                    Effect::Flicker | Effect::Markov | Effect::Sinusoid | Effect::BiasStep => {
                        d("°/h", 3600.0 * k)
                    }
                    Effect::Temperature if warm_up => d("°/h", 3600.0 * k),
                    Effect::Temperature => d("°/h/°C", 3600.0 * k),
                    Effect::RateRandomWalk => d("°/h/√h", 3600.0 * 60.0 * k),
                    Effect::RateRamp => d("°/h²", 3600.0 * 3600.0 * k),
                    Effect::Resolution | Effect::User(_) => None,
                }
            }
            UnitFamily::MPerS2 => match self {
                Effect::Quantization => d("m/s", 1.0),
                Effect::White
                | Effect::Lowpass
                | Effect::Lowpass2
                | Effect::Boxcar
                | Effect::Bartlett => d("µg/√Hz", ug),
                Effect::Flicker | Effect::Markov | Effect::Sinusoid | Effect::BiasStep => {
                    d("µg", ug)
                }
                Effect::Temperature if warm_up => d("µg", ug),
                Effect::Temperature => d("µg/°C", ug),
                Effect::RateRandomWalk => d("µg/√s", ug),
                Effect::RateRamp => d("µg/h", ug * 3600.0),
                Effect::Resolution | Effect::User(_) => None,
            },
            UnitFamily::Other => None,
        }
    }

    /// How the effect shows on the Allan plot — the signature used in the diagnosis text.
    pub fn signature(&self) -> &str {
        match self {
            Effect::Quantization => "slope −1 in σ(τ) at the shortest τ (phase/angle white noise)",
            Effect::White => "slope −½ in σ(τ); N is read at τ = 1 s",
            Effect::Flicker => "a flat floor, slope 0; the minimum of σ(τ) ≈ 0.664·B",
            Effect::RateRandomWalk => "slope +½ in σ(τ) at long τ; K is read at τ = 3 s",
            Effect::RateRamp => "slope +1 in σ(τ) at the longest τ; R is read at τ = √2 s",
            Effect::Markov => {
                "a bump: slope +½ for τ ≪ τ_c, a maximum σ ≈ 0.62·sigma at τ ≈ 1.89·τ_c, \
                 slope −½ for τ ≫ τ_c"
            }
            Effect::Sinusoid => {
                "an oscillation with envelope slope −1, a first maximum σ ≈ 0.725·A at \
                 τ ≈ 0.371/f and nulls at τ = k/f; a line at f in the PSD"
            }
            Effect::Resolution => {
                "a white floor of LSB²/12 per sample (slope −½), known from the spacing of the \
                 values: it sets how far below the white line the shortest τ can go"
            }
            Effect::BiasStep => {
                "slope +½ at long τ like a rate random walk (σ² ≈ Δ²τ/3T for a step Δ in a \
                 record of length T), but one large jump in the time series instead of many small \
                 ones; the robust Allan variance does not see it"
            }
            Effect::Temperature => {
                "slope +½ to +1 at long τ, following the Allan variance of the temperature \
                 column itself; in the time series the bias tracks the temperature"
            }
            Effect::Lowpass | Effect::Lowpass2 => {
                "σ(τ) below the white line at τ ≲ 1/(2πf_c) (slope +½ at the shortest τ for one \
                 pole, steeper for two), joining it for τ ≫ 1/f_c; the PSD falls off above f_c"
            }
            Effect::Boxcar | Effect::Bartlett => {
                "σ(τ) below the white line for τ shorter than the filter length L·τ0 and on it \
                 beyond; the PSD has the filter's sinc² (boxcar) or sinc⁴ (Bartlett) shape"
            }
            Effect::User(u) => &u.signature,
        }
    }

    /// A paragraph on the physics: cause in a MEMS IMU, typical MPU-6050 magnitude, Allan look.
    pub fn physics(&self) -> &str {
        match self {
            Effect::Quantization => {
                "Quantization noise is white noise on the integrated output (angle or velocity): \
                 the rounding error of a quantizer that accumulates rate into counts, or timing \
                 jitter of the samples. On a rate-output MEMS part such as the MPU-6050 the rate \
                 LSB (1/131 °/s at ±250 °/s) rounds each sample, which adds white rate noise \
                 (the resolution effect); a genuine Q term usually comes from sample-time jitter \
                 or from digital filtering/decimation. Typical fitted Q on an MPU-6050 at 100 Hz \
                 is a few 1e-4 °. It dominates only the first one or two octaves of τ."
            }
            Effect::White => {
                "White rate noise (angle/velocity random walk): thermo-mechanical (Brownian) \
                 noise of the proof mass and electronic noise of the capacitive readout, flat in \
                 frequency up to the filter bandwidth. Integrating it gives an angle that random \
                 walks as N·√t. The MPU-6050 datasheet gives 0.005 °/s/√Hz (N ≈ 0.3 °/√h) for the \
                 gyro and 400 µg/√Hz for the accelerometer; measured parts are often 1–2× that. \
                 It is the −½ slope that dominates short τ."
            }
            Effect::Flicker => {
                "Flicker (1/f) noise of the bias, called bias instability: produced by charge \
                 trapping in the electronics and slow fluctuations in the MEMS structure and its \
                 package. It sets the floor of the Allan curve, the best bias estimate the sensor \
                 allows by averaging. MPU-6050 gyros show B of roughly 5–30 °/h; accelerometers \
                 some tens of µg. Flat region of the Allan plot around its minimum."
            }
            Effect::RateRandomWalk => {
                "Rate random walk: the bias itself random walks (integrated white noise on the \
                 rate), driven by temperature changes, package stress relaxation and slow \
                 electronic drift. It decides how long a bias calibration stays valid (the use \
                 Jaime et al. make of it for recalibration planning). On an MPU-6050 at room \
                 conditions K is of order 0.001–0.01 °/s/√s and needs recordings of many minutes \
                 to hours to appear. Slope +½ at long τ. A bias step or a temperature-driven drift \
                 looks the same on the Allan plot; the lab checks the time series for those."
            }
            Effect::RateRamp => {
                "Rate ramp: a deterministic, monotonic bias drift over the record — warm-up after \
                 power-on, a steady temperature change, or a slow motion of the platform. Often \
                 the first minutes of an MPU-6050 recording drift by 0.01–0.1 °/s while the die \
                 warms. It appears as slope +1 at the longest τ, and a longer warm-up before \
                 recording usually removes it. It is a non-stationarity, not a noise: its value \
                 describes this record, not the sensor."
            }
            Effect::Markov => {
                "Exponentially correlated (first-order Gauss–Markov) noise: a noise with finite \
                 memory τ_c, from a mechanical or thermal relaxation with a time constant, or a \
                 slowly fluctuating defect. It makes a bump on the Allan curve (slope +½ rising to \
                 a maximum near τ ≈ 1.9·τ_c, then −½). White noise shaped by the sensor's own \
                 low-pass filter is the lowpass effect, which ties the correlated part to the \
                 white noise it filters."
            }
            Effect::Sinusoid => {
                "A sinusoidal disturbance: vibration of the bench or a fan, mains pickup \
                 (50/60 Hz aliased by the sampling), a periodic temperature cycle of an air \
                 conditioner or heater, or a beat between the sensor's internal clock and the \
                 host's sampling. It gives an oscillating Allan curve with nulls at τ = k/f and a \
                 single line in the power spectral density."
            }
            Effect::Resolution => {
                "Resolution: each rate sample is an integer number of LSBs, so rounding adds a \
                 white error of LSB²/12 per sample. The LSB is read from the spacing of the values \
                 (the lattice they sit on); the white term N then describes the sensor's own \
                 noise above that floor. When N² approaches LSB²·τ0/12, the channel is \
                 resolution-limited and a finer range or more gain would show more of its noise."
            }
            Effect::BiasStep => {
                "A bias step: the bias jumps at one instant — a mechanical shock, a change of \
                 the sensor's range or filter setting, a brown-out and re-initialisation, or a \
                 solder joint or connector that shifts. It is not noise: averaged over the record \
                 it looks like a rate random walk of K² ≈ Δ²/T, which says nothing about the \
                 sensor's long-term stability. The step is located by a change-point test on the \
                 time series and estimated there."
            }
            Effect::Temperature => {
                "Temperature sensitivity of the bias: the MEMS structure and its readout change \
                 with die temperature (thermal stress, the drive amplitude), so the bias follows \
                 the temperature — typically 0.01–0.05 °/s/°C for an MPU-6050 gyro and ~1 mg/°C \
                 for its accelerometer. With a temperature column the coefficient is regressed on \
                 it and the Allan curve is shown before and after compensation; without one, a \
                 warm-up after power-on shows as an exponential approach of the bias with a time \
                 constant of minutes. Like a ramp it is a non-stationarity of this record."
            }
            Effect::Lowpass => {
                "The sensor's own digital low-pass filter on its white noise, one pole at f_c: \
                 the MPU-6050's DLPF (DLPF_CFG 1–6: 188, 98, 42, 20, 10, 5 Hz gyro bandwidth in \
                 its register map) or an analog anti-alias filter. Sampled, it is a Gauss–Markov \
                 sequence with τ_c = 1/(2πf_c) whose variance is fixed by the white noise it \
                 filters, so it has one parameter fewer than a free Markov term."
            }
            Effect::Lowpass2 => {
                "A two-pole digital low-pass on the sensor's white noise (two cascaded \
                 first-order sections at f_c): many MEMS parts implement their DLPF as a \
                 second-order section; it falls off twice as steeply above f_c as one pole."
            }
            Effect::Boxcar => {
                "A moving-average (boxcar) decimation filter: the part samples its sensing \
                 element internally at a higher rate and outputs the mean of the last L output \
                 periods' worth of internal samples (CIC/sinc filters of sigma-delta readouts). \
                 Neighbouring output samples then share internal samples and are correlated for \
                 L samples."
            }
            Effect::Bartlett => {
                "A triangular (Bartlett, sinc²) decimation filter: two boxcar stages of L output \
                 samples in cascade, common in MEMS readouts (second-order CIC); it correlates the \
                 output for 2L samples with a smoother shape than a single boxcar."
            }
            Effect::User(u) => &u.physics,
        }
    }
}

impl fmt::Display for Effect {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Direct sum σ²(m) = Σ_d C(d) R(|d|) / (2m²) for an AR(1) with coefficient φ.
    fn brute(m: usize, phi: f64) -> f64 {
        let mut s = 0.0;
        let mm = m as i64;
        for d in -(2 * mm - 1)..=(2 * mm - 1) {
            let ad = d.abs();
            let c = if ad == 0 {
                2 * mm
            } else if ad < mm {
                2 * mm - 3 * ad
            } else {
                -(2 * mm - ad)
            };
            s += c as f64 * phi.powi(ad as i32);
        }
        s / (2.0 * (m * m) as f64)
    }

    #[test]
    fn markov_sampled_matches_direct_sum() {
        for &tc in &[0.3, 2.0, 31.8, 5000.0] {
            let phi = (-1.0f64 / tc).exp();
            for &m in &[1usize, 2, 3, 7, 64, 1000] {
                let a = markov_avar_unit(m as f64, 1.0, tc);
                let b = brute(m, phi);
                assert!(
                    (a - b).abs() <= 1e-7 * b.abs().max(1e-12),
                    "tc {tc} m {m}: {a} vs {b}"
                );
            }
        }
    }

    #[test]
    fn markov_tends_to_continuous() {
        for &x in &[1e-4, 1e-2, 0.4, 0.6, 1.0, 10.0, 1e3] {
            let c = markov_avar_continuous(x, 1.0);
            let s = markov_avar_unit(x, x.min(1.0) / 1e4, 1.0);
            assert!((c - s).abs() < 1e-6 * c, "x {x}: {c} vs {s}");
        }
        let h = |x: f64| 2.0 / x - (3.0 - 4.0 * (-x).exp() + (-2.0 * x).exp()) / (x * x);
        assert!((markov_avar_continuous(0.4999999, 1.0) - h(0.4999999)).abs() < 1e-12);
        let (mut best, mut bt) = (0.0, 0.0);
        for i in 0..2000 {
            let t = 0.5 + i as f64 * 0.002;
            let v = markov_avar_continuous(t, 1.0);
            if v > best {
                best = v;
                bt = t;
            }
        }
        assert!((bt - 1.89).abs() < 0.01 && (best.sqrt() - 0.618).abs() < 0.002);
    }

    #[test]
    fn sinusoid_sampled_matches_continuous_for_slow_sines() {
        let a = sinusoid_avar_unit(0.37, 1e-5, 1.0);
        let b = sinusoid_avar_unit(0.37, 0.0, 1.0);
        assert!((a - b).abs() < 1e-6 * b);
        assert!(sinusoid_avar_unit(2.0, 0.01, 1.0) < 1e-25);
    }

    /// Direct OADEV expectation of a deterministic signal: mean over differences of (ȳ2 − ȳ1)²/2.
    fn signal_avar(x: &[f64], segs: &[(u64, u64)], m: usize) -> f64 {
        let (mut acc, mut n) = (0.0, 0usize);
        for &(a, l) in segs {
            let (a, l) = (a as usize, l as usize);
            for i in a..=(a + l).saturating_sub(2 * m) {
                if i + 2 * m > a + l {
                    break;
                }
                let y1: f64 = x[i..i + m].iter().sum::<f64>() / m as f64;
                let y2: f64 = x[i + m..i + 2 * m].iter().sum::<f64>() / m as f64;
                acc += (y2 - y1).powi(2);
                n += 1;
            }
        }
        acc / (2.0 * n as f64)
    }

    #[test]
    fn step_and_warmup_bases_are_exact() {
        let segs = vec![(0u64, 700u64), (750, 500)];
        let ctx = Context {
            tau0: 0.01,
            segments: segs.clone(),
            ..Context::default()
        };
        for s in [1u64, 40, 350, 699, 760, 1100] {
            let x: Vec<f64> = (0..1250)
                .map(|k| if k as u64 >= s { 1.0 } else { 0.0 })
                .collect();
            for m in [1usize, 3, 16, 100, 240] {
                let want = signal_avar(&x, &segs, m);
                let got = step_avar(s, m as u64, &ctx);
                assert!(
                    (got - want).abs() <= 1e-12 + 1e-9 * want,
                    "s {s} m {m}: {got} vs {want}"
                );
            }
        }
        let kappa = 180.0;
        let x: Vec<f64> = (0..1250).map(|k| (-(k as f64) / kappa).exp()).collect();
        for m in [1usize, 5, 64, 200] {
            let want = signal_avar(&x, &segs, m);
            let got = warmup_avar(kappa, m as u64, &ctx);
            assert!((got - want).abs() <= 1e-9 * want, "m {m}: {got} vs {want}");
        }
    }

    #[test]
    fn filters_join_the_white_line_and_match_their_impulse_responses() {
        let ctx = Context::uniform(0.01, 1 << 16);
        let white = Effect::White.basis(&[], &ctx).unwrap();
        for (e, th) in [
            (Effect::Lowpass, 5.0),
            (Effect::Lowpass2, 5.0),
            (Effect::Boxcar, 8.0),
            (Effect::Bartlett, 8.0),
        ] {
            let b = e.basis(&[th], &ctx).unwrap();
            let (lo, hi) = (b.avar(1.0, 0.01), b.avar(4096.0, 0.01));
            assert!(lo < 0.7 * white.avar(1.0, 0.01), "{e}: {lo}");
            assert!(
                (hi / white.avar(4096.0, 0.01) - 1.0).abs() < 0.01,
                "{e}: {hi}"
            );
        }
        // two cascaded sections: the direct impulse-response sum
        let (fc, tau0) = (5.0, 0.01);
        let phi = (-2.0 * std::f64::consts::PI * fc * tau0).exp();
        let h: Vec<f64> = (0..5000)
            .map(|n| (1.0 - phi).powi(2) * (n as f64 + 1.0) * phi.powi(n))
            .collect();
        let r = |k: usize| h.iter().zip(&h[k..]).map(|(a, b)| a * b).sum::<f64>() / tau0;
        let v =
            |n: usize| n as f64 * r(0) + 2.0 * (1..n).map(|k| (n - k) as f64 * r(k)).sum::<f64>();
        let b = Effect::Lowpass2.basis(&[fc], &ctx).unwrap();
        for m in [1usize, 3, 10, 77] {
            let want = (4.0 * v(m) - v(2 * m)) / (2.0 * (m * m) as f64);
            let got = b.avar(m as f64, tau0);
            assert!((got - want).abs() < 1e-9 * want, "m {m}: {got} vs {want}");
        }
    }

    #[test]
    fn names_roundtrip() {
        for e in ALL_EFFECTS {
            assert_eq!(Effect::parse(e.name()), Some(e.clone()));
        }
    }
}
