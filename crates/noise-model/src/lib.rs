//! The pico-imu noise-model lab: an effect library for Allan-variance curves (power-law noise,
//! Gauss–Markov, sinusoids, mount resonances, the sensor's own filters, resolution, bias steps,
//! temperature, user-described effects), the covariance of overlapping Allan estimates, a
//! generalised least-squares fit with an uncertainty for every estimate, an adequacy verdict,
//! time-domain tests for non-stationarity, and the lab workflow (diagnose → add → refit) on a
//! recording. Pure maths: no I/O. Inputs are measured Allan points (τ, σ, EDF, 68.3 % bounds,
//! m), e.g. rows of `allan::deviation(…, Stat::Oadev, …)`, and for the lab the record's samples.
//!
//! ```
//! use noise_model::{assess, fit_model, Effect, Measurement, Point, TermSpec};
//! // an exact white-noise curve, N = 0.01 u·√s, from a record of 2^16 samples at 100 Hz
//! let pts: Vec<Point> = (0..12).map(|k| {
//!     let m = 1u64 << k;
//!     let tau = 0.01 * m as f64;
//!     let dev = 0.01 / tau.sqrt();
//!     Point { tau, dev, edf: 100.0, lo: dev * 0.93, hi: dev * 1.08, m }
//! }).collect();
//! let meas = Measurement::from_record(pts, 0.01, 1 << 16);
//! let f = fit_model(&meas, &[TermSpec::new(Effect::White), TermSpec::new(Effect::Flicker)]).unwrap();
//! // the fit is on the logs with their χ² bias corrected: exact expectations come back to 1e-3
//! assert!((f.terms[0].amplitude() / 0.01 - 1.0).abs() < 1e-3);
//! assert!(!f.terms[1].detected);
//! assert!(assess(&f).adequate);
//! ```
// `!(x > 0.0)` is used on purpose: it is true for NaN as well, which must be rejected too.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod assess;
pub mod cov;
pub mod defects;
pub mod diagnose;
pub mod diff_profile;
pub mod effect;
pub mod fit;
pub mod lab;
pub mod nnls;
pub mod nonstat;
pub mod optim;
pub mod practical;
pub mod psd;
pub mod session;
pub mod structure;
/// User-defined effects (their own module under [`effect`]).
pub use effect::user;
pub mod zscore;

pub use assess::{assess, assess_at, Assessment, Standing, TauRange};
pub use diagnose::{diagnose, Diagnosis};
pub use effect::{Context, Effect, UnitFamily, ALL_EFFECTS, DEFAULT_TERMS};
pub use fit::{
    fit, fit_model, Fit, FitError, FitOptions, Known, Measurement, ParamValue, Point, TermFit,
    TermSpec, Weighting,
};
pub use lab::{Model, NoiseLab, Record, Timing, EQUAL_SUPPORT, NEAR_SUPPORT};
pub use model_lab::{walk, Candidate, Edit, Step, Stop, Summary, Walk};
pub use practical::{recalibration, KalibrImu, Recalibration};
pub use psd::{find_line, line_near, welch, Line, LineTest, Psd};

/// Deterministic approximately Gaussian noise for the unit tests: the sum of twelve uniforms from
/// a 64-bit LCG, minus 6 (unit variance).
#[cfg(test)]
pub(crate) fn test_noise(seed: u64) -> impl FnMut() -> f64 {
    let mut s = seed;
    move || {
        let mut u = 0.0;
        for _ in 0..12 {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            u += (s >> 11) as f64 / (1u64 << 53) as f64;
        }
        u - 6.0
    }
}
