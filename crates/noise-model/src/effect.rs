//! The effect library: every noise or error effect the lab knows, its Allan-variance contribution,
//! its canonical parameters and their units, the conventional display units with the conversions,
//! a paragraph on the physics and its Allan-plot signature.
//!
//! Power-law terms follow IEEE Std 952-1997 Annex C and the seed paper's eqs. 10–14:
//! σ²(τ) = 3Q²/τ², N²/τ, (2 ln2/π)B², K²τ/3, R²τ²/2. The Gauss–Markov and sinusoid terms follow
//! IEEE Std 952-1997 C.7/C.8 (σ(τ) = A·sin²(πfτ)/(πfτ) for a sinusoid).
//!
//! Every term is written as `coefficient × basis(τ)` with a non-negative coefficient (the square
//! of the canonical amplitude parameter), which is what makes the fit a non-negative linear least
//! squares problem once the non-linear parameters (τ_c, f) are fixed.
use core::fmt;

/// The fixed vocabulary of effects.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Effect {
    Quantization,
    White,
    Flicker,
    RateRandomWalk,
    RateRamp,
    Markov,
    Sinusoid,
}

/// The seed paper's five terms (eqs. 10–14), the default model.
pub const DEFAULT_TERMS: [Effect; 5] = [
    Effect::Quantization,
    Effect::White,
    Effect::Flicker,
    Effect::RateRandomWalk,
    Effect::RateRamp,
];

/// Every effect, in vocabulary order.
pub const ALL_EFFECTS: [Effect; 7] = [
    Effect::Quantization,
    Effect::White,
    Effect::Flicker,
    Effect::RateRandomWalk,
    Effect::RateRamp,
    Effect::Markov,
    Effect::Sinusoid,
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

impl Effect {
    /// The name used in the vocabulary, the CLI and the JSON output.
    pub fn name(self) -> &'static str {
        match self {
            Effect::Quantization => "quantization",
            Effect::White => "white",
            Effect::Flicker => "flicker",
            Effect::RateRandomWalk => "rate_random_walk",
            Effect::RateRamp => "rate_ramp",
            Effect::Markov => "markov",
            Effect::Sinusoid => "sinusoid",
        }
    }

    /// Parse a vocabulary name (a few common aliases accepted).
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
                _ => return None,
            },
        )
    }

    /// Number of parameters (1 amplitude + 0 or 1 non-linear).
    pub fn n_params(self) -> usize {
        if self.nonlinear_name().is_some() {
            2
        } else {
            1
        }
    }

    /// Name of the amplitude parameter (the square root of the linear coefficient).
    pub fn amp_name(self) -> &'static str {
        match self {
            Effect::Quantization => "Q",
            Effect::White => "N",
            Effect::Flicker => "B",
            Effect::RateRandomWalk => "K",
            Effect::RateRamp => "R",
            Effect::Markov => "sigma",
            Effect::Sinusoid => "amplitude",
        }
    }

    /// Name of the non-linear parameter, if the effect has one.
    pub fn nonlinear_name(self) -> Option<&'static str> {
        match self {
            Effect::Markov => Some("tau_c"),
            Effect::Sinusoid => Some("freq_hz"),
            _ => None,
        }
    }

    /// Canonical unit of the amplitude parameter for a channel in unit `u` (τ in seconds).
    pub fn amp_unit(self, u: &str) -> String {
        // u·s and u/s simplified for the usual channel units (deg/s·s = deg, m/s²/s = m/s³)
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
            Effect::White => format!("{u}·√s"),
            Effect::Flicker | Effect::Markov | Effect::Sinusoid => u.to_string(),
            Effect::RateRandomWalk => format!("{u}/√s"),
            Effect::RateRamp => format!("{u}/s"),
        }
    }

    /// Canonical unit of the non-linear parameter.
    pub fn nonlinear_unit(self) -> Option<&'static str> {
        match self {
            Effect::Markov => Some("s"),
            Effect::Sinusoid => Some("Hz"),
            _ => None,
        }
    }

    /// Conventional display unit for the amplitude parameter, with `display = canonical × factor`.
    ///
    /// Conversions: 1 s = 1/3600 h, so deg·√s = deg/√h × 1/60 (N[°/√h] = 60·N[°/s·√s]);
    /// B[°/h] = 3600·B[°/s]; K[°/h/√h] = 3600·60·K[°/s/√s]; R[°/h²] = 3600²·R[°/s²];
    /// 1 µg = 9.80665e-6 m/s²; N[µg/√Hz] = N[m/s²·√s]/9.80665e-6 (a one-sided PSD level
    /// of white noise equals N², IEEE 952 C.2).
    pub fn amp_display(self, family: UnitFamily) -> Option<DisplayUnit> {
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
                    Effect::White => d("°/√h", 60.0 * k),
                    Effect::Flicker | Effect::Markov | Effect::Sinusoid => d("°/h", 3600.0 * k),
                    Effect::RateRandomWalk => d("°/h/√h", 3600.0 * 60.0 * k),
                    Effect::RateRamp => d("°/h²", 3600.0 * 3600.0 * k),
                }
            }
            UnitFamily::MPerS2 => match self {
                Effect::Quantization => d("m/s", 1.0),
                Effect::White => d("µg/√Hz", ug),
                Effect::Flicker | Effect::Markov | Effect::Sinusoid => d("µg", ug),
                Effect::RateRandomWalk => d("µg/√s", ug),
                Effect::RateRamp => d("µg/h", ug * 3600.0),
            },
            UnitFamily::Other => None,
        }
    }

    /// Allan-variance basis b(τ) so that σ²(τ) = c·b(τ), c = amplitude².
    ///
    /// `tau0` is the sampling interval: the Markov and sinusoid terms use the exact expression for
    /// point-sampled data (see [`markov_avar_unit`], [`sinusoid_avar_unit`]) which tends to the
    /// issue's continuous formula as τ0 → 0. `theta` is τ_c [s] or f [Hz]; ignored otherwise.
    pub fn basis(self, tau: f64, tau0: f64, theta: f64) -> f64 {
        match self {
            Effect::Quantization => 3.0 / (tau * tau),
            Effect::White => 1.0 / tau,
            Effect::Flicker => 2.0 * std::f64::consts::LN_2 / std::f64::consts::PI,
            Effect::RateRandomWalk => tau / 3.0,
            Effect::RateRamp => tau * tau / 2.0,
            Effect::Markov => markov_avar_unit(tau, tau0, theta),
            Effect::Sinusoid => sinusoid_avar_unit(tau, tau0, theta),
        }
    }

    /// Log-log slope of σ(τ) for the power-law terms (None for markov/sinusoid).
    pub fn adev_slope(self) -> Option<f64> {
        match self {
            Effect::Quantization => Some(-1.0),
            Effect::White => Some(-0.5),
            Effect::Flicker => Some(0.0),
            Effect::RateRandomWalk => Some(0.5),
            Effect::RateRamp => Some(1.0),
            _ => None,
        }
    }

    /// How the effect shows on the Allan plot — the signature used in the diagnosis text.
    pub fn signature(self) -> &'static str {
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
        }
    }

    /// A paragraph on the physics: cause in a MEMS IMU, typical MPU-6050 magnitude, Allan look.
    pub fn physics(self) -> &'static str {
        match self {
            Effect::Quantization => {
                "Quantization noise is white noise on the integrated output (angle or velocity): \
                 the rounding error of a quantizer that accumulates rate into counts, or timing \
                 jitter of the samples. On a rate-output MEMS part such as the MPU-6050 the rate \
                 LSB (1/131 °/s at ±250 °/s) rounds each sample, which mostly adds white rate \
                 noise of LSB/√12 per sample; a genuine Q term usually comes from sample-time \
                 jitter or from digital filtering/decimation. Typical fitted Q on an MPU-6050 at \
                 100 Hz is a few 1e-4 °. It dominates only the first one or two octaves of τ."
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
                 electronic drift. It decides how long a bias calibration stays valid (the seed's \
                 use for recalibration planning). On an MPU-6050 at room conditions K is of order \
                 0.001–0.01 °/s/√s and needs recordings of many minutes to hours to appear. \
                 Slope +½ at long τ."
            }
            Effect::RateRamp => {
                "Rate ramp: a deterministic, monotonic bias drift over the record — warm-up after \
                 power-on, a steady temperature change, or a slow motion of the platform. Often \
                 the first minutes of an MPU-6050 recording drift by 0.01–0.1 °/s while the die \
                 warms. It appears as slope +1 at the longest τ, and a longer warm-up before \
                 recording usually removes it."
            }
            Effect::Markov => {
                "Exponentially correlated (first-order Gauss–Markov) noise: a noise with finite \
                 memory τ_c. In a MEMS IMU it arises from a low-pass filter applied to white noise \
                 — the MPU-6050 digital low-pass filter (DLPF; the seed uses 5 Hz, τ_c = \
                 1/(2π·5 Hz) ≈ 32 ms) — or from mechanical/thermal relaxations with a time \
                 constant. It makes the short-τ deviation fall below the white-noise line (a \
                 bump of slope +½ rising to a maximum near τ ≈ 1.9·τ_c, then −½)."
            }
            Effect::Sinusoid => {
                "A sinusoidal disturbance: vibration of the bench or a fan, mains pickup \
                 (50/60 Hz aliased by the sampling), a periodic temperature cycle of an air \
                 conditioner or heater, or a beat between the sensor's internal clock and the \
                 host's sampling. It gives an oscillating Allan curve with nulls at τ = k/f and a \
                 single line in the power spectral density."
            }
        }
    }
}

impl fmt::Display for Effect {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// Allan variance of unit-variance first-order Gauss–Markov noise with correlation time `tau_c`,
/// point-sampled every `tau0`, at τ = m·τ0 (m may be fractional).
///
/// Derivation: for a stationary sequence with autocovariance R(k) = φ^|k|, φ = e^{−τ0/τ_c},
/// σ²(m) = (4S(m) − S(2m)) / (2m²) with S(n) = Σ_{|k|<n}(n−|k|)R(k)
/// = n(1+φ)/(1−φ) − 2φ(1−φⁿ)/(1−φ)². With a = 1−φ, b = 1−φ^m:
/// σ²(m) = [2m(2−a)a − 2(1−a)b(2+b)] / (2m²a²). As τ0 → 0 this is IEEE 952 eq. C.7 (the issue's
/// formula). For x = τ/τ_c < 1e-4 the cancellation is avoided by the expansion
/// σ² = β(2m²+1)/(3m) − x²/2 + 7x³/30 (β = τ0/τ_c), whose first term is the sampled
/// rate-random-walk form with K² = 2/τ_c. Relative accuracy ≈ 1e-8 or better everywhere.
pub fn markov_avar_unit(tau: f64, tau0: f64, tau_c: f64) -> f64 {
    if !(tau_c > 0.0) || !(tau > 0.0) {
        return 0.0;
    }
    if tau0 <= 0.0 {
        return markov_avar_continuous(tau, tau_c);
    }
    let m = tau / tau0;
    let beta = tau0 / tau_c;
    let x = tau / tau_c;
    if x < 1e-4 {
        return beta * (2.0 * m * m + 1.0) / (3.0 * m) - x * x / 2.0 + 7.0 * x * x * x / 30.0;
    }
    let a = -(-beta).exp_m1();
    let b = -(-x).exp_m1();
    let num = 2.0 * m * (2.0 - a) * a - 2.0 * (1.0 - a) * b * (2.0 + b);
    (num / (2.0 * m * m * a * a)).max(0.0)
}

/// The continuous-time Gauss–Markov Allan variance (IEEE 952 C.7), unit steady-state variance:
/// σ²(τ) = (2τ_c/τ)[1 − (τ_c/2τ)(3 − 4e^{−τ/τ_c} + e^{−2τ/τ_c})], with a series for τ ≪ τ_c.
pub fn markov_avar_continuous(tau: f64, tau_c: f64) -> f64 {
    let x = tau / tau_c;
    if x < 0.5 {
        // σ² = Σ_{k≥3} (−1)^{k+1} (2^k − 4)/k! · x^{k−2}
        let mut sum = 0.0;
        let mut fact = 2.0; // 2!
        let mut p2 = 4.0; // 2^2
        let mut xp = 1.0; // x^{k−2}, built incrementally from k = 2
        for k in 3..40 {
            fact *= k as f64;
            p2 *= 2.0;
            xp *= x;
            let sign = if k % 2 == 1 { 1.0 } else { -1.0 };
            let t = sign * (p2 - 4.0) / fact * xp;
            sum += t;
            if t.abs() < 1e-18 * sum.abs() {
                break;
            }
        }
        sum
    } else {
        let h = 3.0 - 4.0 * (-x).exp() + (-2.0 * x).exp();
        2.0 / x - h / (x * x)
    }
}

/// Allan variance of a unit-amplitude sinusoid of frequency `f` point-sampled every `tau0`,
/// averaged over phase (the overlapping estimator averages over all starting phases):
/// σ²(m) = sin⁴(mθ/2) / (m² sin²(θ/2)), θ = 2πfτ0, from the Fejér kernel
/// S(n) = ½·sin²(nθ/2)/sin²(θ/2). As τ0 → 0 it is IEEE 952 C.8, σ = A·sin²(πfτ)/(πfτ).
pub fn sinusoid_avar_unit(tau: f64, tau0: f64, f: f64) -> f64 {
    if !(f > 0.0) || !(tau > 0.0) {
        return 0.0;
    }
    let x = std::f64::consts::PI * f * tau;
    if tau0 <= 0.0 {
        let s = x.sin();
        return s.powi(4) / (x * x);
    }
    let m = tau / tau0;
    let h = std::f64::consts::PI * f * tau0; // θ/2
    let s = x.sin();
    s.powi(4) / (m * m * h.sin().powi(2))
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
        // continuous series and closed form agree at the switch point
        let h = |x: f64| 2.0 / x - (3.0 - 4.0 * (-x).exp() + (-2.0 * x).exp()) / (x * x);
        assert!((markov_avar_continuous(0.4999999, 1.0) - h(0.4999999)).abs() < 1e-12);
        // peak of σ at τ ≈ 1.89 τ_c with σ ≈ 0.618·sigma
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
        // nulls at τ = k/f
        assert!(sinusoid_avar_unit(2.0, 0.01, 1.0) < 1e-25);
    }

    #[test]
    fn names_roundtrip() {
        for e in ALL_EFFECTS {
            assert_eq!(Effect::parse(e.name()), Some(e));
        }
    }
}
