//! Overflow sentinels: the values a sensor writes when it has no measurement to give. A
//! calibration must exclude them (one HMC5883L overflow sample among a tilt sphere moves the
//! fitted hard iron by tens of thousands of µT) and say how many it excluded.
//!
//! | part | sentinel | source |
//! |---|---|---|
//! | HMC5883L (magnetometer) | −4096 counts on the axis that over- or underflowed | datasheet, data output registers |
//! | QMC5883L (magnetometer) | output saturated at −32768 / 32767 counts (the OVL flag) | datasheet, status register |
//! | MPU-6050 accelerometer | −32768 / 32767 counts at full scale (±2, 4, 8, 16 g) | register map, ACCEL_XOUT |
//! | MPU-6050 gyroscope | −32768 / 32767 counts at full scale (±250, 500, 1000, 2000 °/s) | register map, GYRO_XOUT |
//!
//! In raw counts (unit `LSB`) a sentinel is the exact value. In physical units the count is
//! unknown, so a value is a sentinel when it equals the sentinel count times one of the part's
//! sensitivities within [`REL_TOLERANCE`] (files print 4–7 digits), and — for the saturation
//! sentinels, which a strong genuine input can approach — when no sample of that column lies
//! beyond it (clipping is the column's extreme).
use serde::Serialize;

/// Relative tolerance of a physical-unit match.
pub const REL_TOLERANCE: f64 = 2e-4;

/// A sensor part whose sentinels are known.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Part {
    /// Honeywell HMC5883L magnetometer.
    Hmc5883l,
    /// QST QMC5883L magnetometer.
    Qmc5883l,
    /// InvenSense MPU-6050 accelerometer.
    Mpu6050Accel,
    /// InvenSense MPU-6050 gyroscope.
    Mpu6050Gyro,
}

/// Standard gravity, m/s² per g (the MPU-6050 sensitivities are in LSB/g).
const G0: f64 = 9.80665;

impl Part {
    /// The part's name as printed.
    pub fn name(self) -> &'static str {
        match self {
            Part::Hmc5883l => "HMC5883L",
            Part::Qmc5883l => "QMC5883L",
            Part::Mpu6050Accel => "MPU-6050 accelerometer",
            Part::Mpu6050Gyro => "MPU-6050 gyroscope",
        }
    }

    /// The parts that may have produced a sensor's column ("accel", "gyro", "mag").
    pub fn for_sensor(sensor: &str) -> &'static [Part] {
        match sensor {
            "mag" => &[Part::Hmc5883l, Part::Qmc5883l],
            "accel" => &[Part::Mpu6050Accel],
            "gyro" => &[Part::Mpu6050Gyro],
            _ => &[],
        }
    }

    /// What the sentinel means.
    pub fn meaning(self) -> &'static str {
        match self {
            Part::Hmc5883l => "overflow (−4096 counts)",
            Part::Qmc5883l => "overflow (output saturated, OVL)",
            Part::Mpu6050Accel | Part::Mpu6050Gyro => "saturated at full scale",
        }
    }

    /// Sentinel counts, and whether they are saturation (a column extreme) rather than a code.
    fn counts(self) -> (&'static [f64], bool) {
        match self {
            Part::Hmc5883l => (&[-4096.0], false),
            _ => (&[-32768.0, 32767.0], true),
        }
    }

    /// Physical units per count for every range setting, in `unit` (None: unit not known).
    fn units_per_count(self, unit: &str) -> Option<Vec<f64>> {
        // The sensitivities of every range setting: the datasheet tables of
        // `device::plausible` (LSB per gauss, per g, per deg/s).
        use crate::device::plausible::{ImuPart, MagPart};
        let lsb = |table: &[(u16, f64)]| table.iter().map(|(_, l)| *l).collect::<Vec<f64>>();
        let gauss_per_unit = match unit {
            "G" | "gauss" | "Gs" => Some(1.0),
            "µT" | "uT" | "microtesla" => Some(0.01),
            "mG" => Some(1e-3),
            "nT" => Some(1e-5),
            "T" => Some(1e4),
            _ => None,
        };
        let g_per_unit = match unit {
            "m/s²" | "m/s^2" | "m/s2" => Some(1.0 / G0),
            "g" => Some(1.0),
            "mg" => Some(1e-3),
            _ => None,
        };
        let dps_per_unit = match unit {
            "deg/s" | "°/s" | "dps" => Some(1.0),
            "rad/s" => Some(180.0 / std::f64::consts::PI),
            _ => None,
        };
        let per = |lsb_per: &[f64], per_unit: Option<f64>| {
            per_unit.map(|k| lsb_per.iter().map(|l| 1.0 / (l * k)).collect())
        };
        match self {
            Part::Hmc5883l => per(&lsb(MagPart::Hmc5883l.ranges()), gauss_per_unit),
            Part::Qmc5883l => per(&lsb(MagPart::Qmc5883l.ranges()), gauss_per_unit),
            Part::Mpu6050Accel => per(&lsb(&ImuPart::Mpu6050.accel_ranges()), g_per_unit),
            Part::Mpu6050Gyro => per(&lsb(&ImuPart::Mpu6050.gyro_ranges()), dps_per_unit),
        }
    }
}

/// The sentinels found in one sensor's three columns.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct Sentinels {
    /// Per sample: whether any axis holds a sentinel.
    #[serde(skip)]
    pub flagged: Vec<bool>,
    /// Samples flagged.
    pub samples: usize,
    /// What was found, one entry per (part, value): e.g. "1 HMC5883L overflow (−4096 counts)
    /// sample: −375.8 µT on mz".
    pub found: Vec<String>,
}

impl Sentinels {
    /// One sentence for reports, or None when nothing was found.
    pub fn describe(&self) -> Option<String> {
        (self.samples > 0).then(|| {
            format!(
                "{} sample(s) excluded as sensor sentinels: {}",
                self.samples,
                self.found.join("; ")
            )
        })
    }
}

/// Find the sentinels of `parts` in the three axes of a sensor, values in `unit` (module docs).
pub fn find(axes: [&[f64]; 3], unit: &str, parts: &[Part]) -> Sentinels {
    let n = axes[0].len();
    let mut flagged = vec![false; n];
    let mut found = Vec::new();
    let raw = unit == "LSB";
    for &part in parts {
        let (codes, saturation) = part.counts();
        let scales = if raw {
            Some(vec![1.0])
        } else {
            part.units_per_count(unit)
        };
        let Some(scales) = scales else { continue };
        for (k, col) in axes.iter().enumerate() {
            let lo = col.iter().copied().fold(f64::INFINITY, f64::min);
            let hi = col.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            for &code in codes {
                // The one scale (if any) this column's value matches.
                let hit = |v: f64, s: f64| {
                    let target = code * s;
                    if raw {
                        v == target
                    } else {
                        (v - target).abs() <= REL_TOLERANCE * target.abs()
                    }
                };
                for &s in &scales {
                    let target = code * s;
                    // Saturation is the column's extreme: nothing beyond it.
                    if saturation {
                        let extreme = if target < 0.0 { lo } else { hi };
                        let beyond = if raw {
                            extreme != target
                        } else {
                            (extreme - target).abs() > REL_TOLERANCE * target.abs()
                        };
                        if beyond {
                            continue;
                        }
                    }
                    let rows: Vec<usize> = (0..n).filter(|&i| hit(col[i], s)).collect();
                    if rows.is_empty() {
                        continue;
                    }
                    for &i in &rows {
                        flagged[i] = true;
                    }
                    found.push(format!(
                        "{} {} {} sample(s) at {} {unit} ({} counts) on {}",
                        rows.len(),
                        part.name(),
                        part.meaning(),
                        fmt(target),
                        code,
                        ["x", "y", "z"][k]
                    ));
                    break;
                }
            }
        }
    }
    let samples = flagged.iter().filter(|f| **f).count();
    Sentinels {
        flagged,
        samples,
        found,
    }
}

fn fmt(v: f64) -> String {
    let s = format!("{v:.6}");
    s.trim_end_matches('0').trim_end_matches('.').to_string()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn col(n: usize, f: impl Fn(usize) -> f64) -> Vec<f64> {
        (0..n).map(f).collect()
    }

    #[test]
    fn hmc_overflow_in_counts_and_in_physical_units() {
        let mut z = col(100, |i| (i as f64 * 0.3).sin() * 400.0);
        z[37] = -4096.0;
        let x = col(100, |i| (i as f64 * 0.3).cos() * 400.0);
        let s = find([&x, &x, &z], "LSB", Part::for_sensor("mag"));
        assert_eq!(s.samples, 1);
        assert!(s.flagged[37]);
        assert!(s.found[0].contains("HMC5883L overflow"), "{:?}", s.found);
        // The same sample converted at gain 1090 LSB/G: −3.757798 G, −375.7798 µT.
        let zg: Vec<f64> = z.iter().map(|v| v / 1090.0).collect();
        let xg: Vec<f64> = x.iter().map(|v| v / 1090.0).collect();
        let s = find([&xg, &xg, &zg], "G", Part::for_sensor("mag"));
        assert_eq!((s.samples, s.flagged[37]), (1, true), "{:?}", s.found);
        let zu: Vec<f64> = zg
            .iter()
            .map(|v| ((v * 100.0) * 1e4).round() / 1e4)
            .collect();
        let xu: Vec<f64> = xg.iter().map(|v| v * 100.0).collect();
        let s = find([&xu, &xu, &zu], "µT", Part::for_sensor("mag"));
        assert_eq!((s.samples, s.flagged[37]), (1, true), "{:?}", s.found);
        // A genuine −375 µT reading elsewhere in a file without the sentinel is kept.
        let mut ok = xu.clone();
        ok[5] = -375.0;
        assert_eq!(
            find([&ok, &ok, &ok], "µT", Part::for_sensor("mag")).samples,
            0
        );
    }

    #[test]
    fn saturation_is_the_columns_extreme() {
        // MPU-6050 gyro at ±250 °/s: 32767/131 = 250.13 deg/s.
        let mut g = col(50, |i| (i as f64).sin() * 100.0);
        g[10] = 32767.0 / 131.0;
        g[11] = 32767.0 / 131.0;
        let s = find([&g, &g, &g], "deg/s", Part::for_sensor("gyro"));
        assert_eq!(s.samples, 2);
        // The same value when the column goes beyond it (a ±500 °/s range): not a sentinel.
        g[20] = 400.0;
        assert_eq!(
            find([&g, &g, &g], "deg/s", Part::for_sensor("gyro")).samples,
            0
        );
        // Raw counts: exact codes only.
        let mut a = col(50, |i| i as f64 * 100.0);
        a[3] = -32768.0;
        let s = find([&a, &a, &a], "LSB", Part::for_sensor("accel"));
        assert_eq!((s.samples, s.flagged[3]), (1, true));
        // Unknown units: nothing can be said.
        assert_eq!(
            find([&a, &a, &a], "furlong", Part::for_sensor("accel")).samples,
            0
        );
    }
}
