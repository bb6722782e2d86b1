//! Allan-family deviations for IMU characterisation.
//!
//! Two places compute them and they must agree:
//!
//! * [`stream`] — the `no_std`, allocation-free, integer-exact streaming octave engine that runs
//!   on the RP2040 for 9 channels at 1 kHz in bounded memory ([`stream::DeviceEngine`]).
//! * `batch` (feature `std`) — exact estimators over a recording (ADEV, OADEV, MDEV, HDEV,
//!   OHDEV, TDEV, TOTDEV) with 68.3 % confidence bounds from Greenhall's EDF, and the host-side
//!   "stride" estimator that computes exactly what the streaming engine computes.
//!
//! All estimators work through the phase `θ`, the integral of the rate (Jaime et al., eqs. 8–9):
//! cluster averages are `(θ[k+m] − θ[k])/τ`, so every Allan-type variance is a sum of squared
//! finite differences of `θ`. References: NIST SP 1065 (Riley, *Handbook of Frequency Stability
//! Analysis*, 2008) for each estimator, Greenhall & Riley (PTTI 2003) for the EDF; each function
//! cites its equation. docs/allan.md explains the conventions and the streaming design.
//!
//! ```
//! use allan::{stream::DEVICE_PARAMS, Engine};
//!
//! // The device's engine (8 differences per cluster, 24 octaves) on a rate that alternates
//! // +1, −1 LSB: clusters of one sample differ by 2 LSB, so σ²(τ₀) = 2²/2 and σ(τ₀) = √2 LSB;
//! // clusters of two (or any even number of) samples all average 0, so σ(2τ₀) = 0.
//! const P: [usize; 4] = DEVICE_PARAMS;
//! let mut e = Engine::<{ P[0] }, { P[1] }, { P[2] }, { P[3] }>::new();
//! for i in 0..1000 {
//!     e.push(if i % 2 == 0 { 1 } else { -1 });
//! }
//! assert_eq!(e.samples(), 1000);
//! let l0 = e.level(0).unwrap();
//! assert_eq!(l0.m, 1);
//! assert!((l0.oadev(1.0).unwrap() - 2f64.sqrt()).abs() < 1e-12);
//! assert_eq!(e.level(1).unwrap().oadev(1.0), Some(0.0));
//! // In deg/s for a ±250 °/s gyro (131 LSB per °/s):
//! assert!((l0.oadev(1.0 / 131.0).unwrap() - 2f64.sqrt() / 131.0).abs() < 1e-12);
//! ```
#![cfg_attr(not(feature = "std"), no_std)]
#![deny(missing_docs)]

pub mod confidence;
pub mod stream;

#[cfg(feature = "std")]
pub mod batch;
#[cfg(feature = "std")]
pub mod noise_id;

/// Deterministic test input shared by the unit tests: xorshift32 mapped to [−0.5, 0.5).
#[cfg(all(test, feature = "std"))]
mod test_rng {
    pub fn rng(key: u32) -> impl FnMut() -> f64 {
        let mut s = key;
        move || {
            s ^= s << 13;
            s ^= s >> 17;
            s ^= s << 5;
            s as f64 / 4_294_967_296.0 - 0.5
        }
    }
}

pub use stream::{DeviceEngine, Engine, LevelSums, MagEngine};

#[cfg(feature = "std")]
pub use batch::{deviation, deviation_segments, stride_sums, Estimator, Row, Stat, TauSet};

/// Errors of the batch estimators. Each names what was wrong and where.
#[derive(Clone, Debug, PartialEq)]
pub enum AllanError {
    /// Fewer samples than the statistic needs.
    TooShort {
        /// Samples given.
        samples: usize,
        /// Samples needed for even one row.
        needed: usize,
    },
    /// A sample is NaN or infinite.
    NotFinite {
        /// Index of the first bad sample.
        index: usize,
    },
    /// The sample period is not a positive finite number.
    BadTau0(f64),
    /// A tau-set parameter is invalid (e.g. 0 points per octave, m = 0 in a list).
    BadTauSet(&'static str),
    /// The statistic is not defined for this input (why).
    Unsupported(&'static str),
}

impl core::fmt::Display for AllanError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            AllanError::TooShort { samples, needed } => {
                write!(f, "{samples} samples given, at least {needed} needed")
            }
            AllanError::NotFinite { index } => write!(f, "sample {index} is not a finite number"),
            AllanError::BadTau0(t) => write!(f, "sample period {t} s is not positive and finite"),
            AllanError::BadTauSet(why) => write!(f, "invalid tau set: {why}"),
            AllanError::Unsupported(why) => write!(f, "not computable: {why}"),
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for AllanError {}
