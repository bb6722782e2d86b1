//! How an effect enters the fit: what the record tells the bases, the non-linear parameters and
//! their search ranges, and the basis for fixed parameters.
use super::{drift_avar, octaves, step_avar, warmup_avar, Basis, Effect};
use crate::structure::{RTable, Structure};
use std::sync::Arc;

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
    /// The autocorrelation of the temperature column's Allan differences at the same factors
    /// (the noise projected on a bias following it, `fit/solve.rs`).
    pub temp_profile: Option<std::sync::Arc<Vec<(u64, crate::diff_profile::DiffProfile)>>>,
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
            temp_profile: None,
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
            // A mode between fs/1000 and just below Nyquist (the sampled form needs f0 < fs/2);
            // ζ < 1: a critically damped or overdamped second-order process has no peak and is a
            // two-pole low-pass shape (lowpass2, or two Markov terms).
            Effect::Resonance => vec![
                spec(
                    "f0_hz",
                    "Hz",
                    1.0 / (1000.0 * tau0),
                    0.5 / tau0 * 0.999,
                    40.0,
                ),
                spec("zeta", "", 0.01, super::RESONANCE_ZETA_MAX, 12.0),
            ],
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
            // the drift's shape: a ramp (per sample) and cosine coefficients, of unit size (its
            // rms about its mean over the record is 1), found in the time domain and held fixed
            // in the Allan fit
            Effect::Drift { components } => (0..=*components)
                .map(|j| ParamSpec {
                    name: if j == 0 {
                        "shape_ramp".into()
                    } else {
                        format!("shape_cos{j}")
                    },
                    unit: if j == 0 { "1/sample" } else { "" }.into(),
                    lo: f64::NEG_INFINITY,
                    hi: f64::INFINITY,
                    log: false,
                    density: 0.0,
                })
                .collect(),
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
            Effect::Resonance => {
                let f0 = th(0);
                if !(f0 > 0.0) {
                    return Ok(Basis::Zero);
                }
                // the frequency is searched first, with the damping not yet set: a middling ζ
                let zeta = if th(1).is_nan() {
                    super::RESONANCE_ZETA_START
                } else {
                    th(1)
                };
                Basis::Stochastic {
                    structure: super::resonance_structure(f0, zeta, tau0)?,
                    factor: 1.0,
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
            Effect::Drift { .. } => {
                if theta.is_empty() || theta.iter().any(|v| !v.is_finite()) {
                    return Ok(Basis::Zero);
                }
                Basis::Table(
                    octaves(ctx)
                        .map(|m| (m, drift_avar(theta, m, ctx)))
                        .collect(),
                )
            }
            Effect::User(u) => u.basis(theta, tau0)?,
        })
    }
}
