//! The pico-imu noise-model lab (issue 3): an effect library for Allan-variance curves, a weighted
//! non-negative least-squares fit with uncertainties, residuals and an adequacy verdict, a
//! diagnosis that names the missing physical effect, and practical outputs (recalibration period,
//! Kalibr noise values). Pure maths: no I/O. Inputs are measured Allan points (τ, σ, EDF, 68.3 %
//! bounds), e.g. rows of `allan::deviation(…, Stat::Oadev, …)`.
//!
//! ```
//! use noise_model::{fit, assess, Effect, FitOptions, Point};
//! // an exact white-noise curve, N = 0.01 u·√s, with a generous EDF
//! let pts: Vec<Point> = (0..12).map(|k| {
//!     let tau = 0.01 * 2f64.powi(k);
//!     let dev = 0.01 / tau.sqrt();
//!     Point { tau, dev, edf: 100.0, lo: dev * 0.93, hi: dev * 1.08 }
//! }).collect();
//! let f = fit(&pts, 0.01, &[Effect::White, Effect::Flicker], &FitOptions::default()).unwrap();
//! assert!((f.terms[0].amplitude() - 0.01).abs() < 1e-9);
//! assert!(!f.terms[1].detected);
//! assert!(assess(&f).adequate);
//! ```
// `!(x > 0.0)` is used on purpose: it is true for NaN as well, which must be rejected too.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod assess;
pub mod diagnose;
pub mod effect;
pub mod fit;
pub mod nnls;
pub mod practical;
pub mod psd;

pub use assess::{assess, Assessment, TauRange};
pub use diagnose::{diagnose, step, Candidate, Diagnosis, Step, StepSide};
pub use effect::{Effect, UnitFamily, ALL_EFFECTS, DEFAULT_TERMS};
pub use fit::{fit, fit_with_data, Fit, FitError, FitOptions, ParamValue, Point, TermFit};
pub use practical::{recalibration, KalibrImu, Recalibration};
pub use psd::{find_line, line_near, welch, Line, LineTest, Psd};
