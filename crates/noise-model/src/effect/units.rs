//! Units of the amplitude parameters: their names, the canonical unit for a channel and the
//! conventional display unit of each unit family.
use super::Effect;

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
    /// Name of the amplitude parameter (the square root of the linear coefficient).
    pub fn amp_name(&self) -> &str {
        match self {
            Effect::Quantization => "Q",
            Effect::White => "N",
            Effect::Flicker => "B",
            Effect::RateRandomWalk => "K",
            Effect::RateRamp => "R",
            Effect::Markov | Effect::Resonance => "sigma",
            Effect::Sinusoid => "amplitude",
            Effect::Resolution => "lsb",
            Effect::BiasStep => "size",
            Effect::Temperature => "coefficient",
            Effect::Drift { .. } => "rms",
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
            | Effect::Resonance
            | Effect::Sinusoid
            | Effect::Resolution
            | Effect::BiasStep
            | Effect::Drift { .. } => u.to_string(),
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
                    Effect::Flicker
                    | Effect::Markov
                    | Effect::Resonance
                    | Effect::Sinusoid
                    | Effect::BiasStep
                    | Effect::Drift { .. } => d("°/h", 3600.0 * k),
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
                Effect::Flicker
                | Effect::Markov
                | Effect::Resonance
                | Effect::Sinusoid
                | Effect::BiasStep
                | Effect::Drift { .. } => d("µg", ug),
                Effect::Temperature if warm_up => d("µg", ug),
                Effect::Temperature => d("µg/°C", ug),
                Effect::RateRandomWalk => d("µg/√s", ug),
                Effect::RateRamp => d("µg/h", ug * 3600.0),
                Effect::Resolution | Effect::User(_) => None,
            },
            UnitFamily::Other => None,
        }
    }
}
