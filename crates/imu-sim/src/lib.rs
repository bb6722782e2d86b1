//! IMU rate-data simulator with the exact theoretical Allan curve of what it generates.
//!
//! Every effect of the noise-model vocabulary can be mixed at any rate and length, from a seeded
//! PRNG (xoshiro256++ seeded by SplitMix64; normals by the Marsaglia polar method), plus a hidden
//! "DLPF" option: white noise through the MPU-6050-style digital low-pass filter (first order, or
//! two cascaded first-order sections), which correlates the noise at short τ.
//!
//! The theoretical curve is exact for the discrete process generated (expected value of the
//! overlapping Allan variance), not the continuous-time approximation:
//! - white: N²/τ; quantization (white phase error of std Q, y_i = (e_{i+1} − e_i)/τ0): 3Q²/τ²;
//! - rate random walk (b_i = b_{i−1} + K√τ0·w_i): K²(τ/3 + τ0²/(6τ)) (sum of the squared
//!   triangular weights of the increments, Σc_j² = m(2m²+1)/3);
//! - rate ramp: R²τ²/2 (every second difference of averages is exactly Rτ);
//! - Gauss–Markov and the first-order DLPF (both AR(1) sequences) and flicker, made as a sum of
//!   independent AR(1) sequences with log-spaced τ_c: the sampled AR(1) formula of
//!   [`noise_model::effect::markov_avar_unit`], summed;
//! - sinusoid with random phase: the sampled formula [`noise_model::effect::sinusoid_avar_unit`];
//! - second-order DLPF: σ²(m) = (4S(m) − S(2m))/(2m²), S(n) = Σ_{|k|<n}(n−|k|)R(k), with R(k)
//!   the autocovariance of the filter output computed from its impulse response.
use noise_model::effect::{markov_avar_unit, sinusoid_avar_unit};
use std::io::{self, Write};

/// xoshiro256++ (Blackman & Vigna 2019), seeded through SplitMix64.
#[derive(Debug, Clone)]
pub struct Rng {
    s: [u64; 4],
    spare: Option<f64>,
}

impl Rng {
    pub fn new(seed: u64) -> Self {
        let mut z = seed;
        let mut next = || {
            z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let mut x = z;
            x = (x ^ (x >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            x = (x ^ (x >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            x ^ (x >> 31)
        };
        Rng {
            s: [next(), next(), next(), next()],
            spare: None,
        }
    }

    pub fn next_u64(&mut self) -> u64 {
        let r = (self.s[0].wrapping_add(self.s[3]))
            .rotate_left(23)
            .wrapping_add(self.s[0]);
        let t = self.s[1] << 17;
        self.s[2] ^= self.s[0];
        self.s[3] ^= self.s[1];
        self.s[1] ^= self.s[2];
        self.s[0] ^= self.s[3];
        self.s[2] ^= t;
        self.s[3] = self.s[3].rotate_left(45);
        r
    }

    /// Uniform in [0, 1) with 53 random bits.
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    /// Standard normal (Marsaglia polar method).
    pub fn normal(&mut self) -> f64 {
        if let Some(v) = self.spare.take() {
            return v;
        }
        loop {
            let u = 2.0 * self.uniform() - 1.0;
            let v = 2.0 * self.uniform() - 1.0;
            let s = u * u + v * v;
            if s > 0.0 && s < 1.0 {
                let f = (-2.0 * s.ln() / s).sqrt();
                self.spare = Some(v * f);
                return u * f;
            }
        }
    }
}

/// One simulated effect, parameters in the noise lab's canonical units (u = channel unit).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SimEffect {
    /// Q [u·s]: white phase error of standard deviation Q.
    Quantization { q: f64 },
    /// N [u·√s].
    White { n: f64 },
    /// B [u], made as a sum of AR(1) terms spanning the record's τ range.
    Flicker { b: f64 },
    /// K [u/√s].
    RateRandomWalk { k: f64 },
    /// R [u/s].
    RateRamp { r: f64 },
    /// sigma [u], tau_c [s].
    Markov { sigma: f64, tau_c: f64 },
    /// amplitude [u] (peak), freq_hz [Hz], random phase.
    Sinusoid { amplitude: f64, freq_hz: f64 },
    /// White noise of density N [u·√s] through a low-pass filter with corner `cutoff_hz`:
    /// order 1 = y_k = φy_{k−1} + (1−φ)w_k, φ = e^{−2π f_c τ0}; order 2 = two such sections.
    /// The DC gain is 1, so the long-τ Allan curve is the white line N²/τ.
    LowPassWhite { n: f64, cutoff_hz: f64, order: u8 },
    /// White noise of density N through a decimation filter of `length` output samples:
    /// internally sampled 16× faster, averaged over 16·length internal samples (boxcar) or
    /// through two such boxcars in cascade (Bartlett), output every 16th internal sample.
    Decimated {
        n: f64,
        length: usize,
        bartlett: bool,
    },
    /// A bias step of `size` [u] at `at_s` [s].
    BiasStep { at_s: f64, size: f64 },
    /// A bias of `coef` [u/°C] times the temperature, which warms from `start_c` by `rise_c`
    /// with time constant `tau_s` [s]; the temperature column is returned by
    /// [`SimConfig::generate_with_temp`].
    Temperature {
        coef: f64,
        start_c: f64,
        rise_c: f64,
        tau_s: f64,
    },
    /// A warm-up transient A·e^{−t/τ} [u] (no temperature column).
    WarmUp { amplitude: f64, tau_s: f64 },
}

/// A simulation: what to generate.
#[derive(Debug, Clone, PartialEq)]
pub struct SimConfig {
    pub rate_hz: f64,
    pub n_samples: usize,
    pub seed: u64,
    pub effects: Vec<SimEffect>,
    /// Round every output sample to a multiple of this LSB (the part's resolution).
    pub lsb: Option<f64>,
}

/// Components (sigma, tau_c) of the AR(1) sum used for flicker of level B at sampling τ0 over a
/// record of n samples: τ_c log-spaced 4 per decade from τ0/2 to 4·n·τ0; the common variance is
/// set so that the exact combined Allan variance equals (2 ln2/π)B² at the geometric centre of
/// [τ0, n·τ0/2]. The combined curve is flat within ±2.5 % from τ = 2τ0 to nτ0/4 and 13 % high at
/// τ0 (the exact curve is what [`SimConfig::avar`] returns).
pub fn flicker_components(b: f64, tau0: f64, n: usize) -> Vec<(f64, f64)> {
    let lo = tau0 / 2.0;
    let hi = 4.0 * n as f64 * tau0;
    let k = ((hi / lo).log10() * 4.0).ceil() as usize + 1;
    let taus: Vec<f64> = (0..k)
        .map(|i| lo * (hi / lo).powf(i as f64 / (k - 1) as f64))
        .collect();
    let mid = (tau0 * n as f64 * tau0 / 2.0).sqrt().max(tau0);
    let mid = (mid / tau0).round().max(1.0) * tau0;
    let unit: f64 = taus.iter().map(|&tc| markov_avar_unit(mid, tau0, tc)).sum();
    let target = 2.0 * std::f64::consts::LN_2 / std::f64::consts::PI * b * b;
    let s = (target / unit).sqrt();
    taus.into_iter().map(|tc| (s, tc)).collect()
}

/// Impulse response of the low-pass filter, truncated where it falls below 1e-17 of its peak.
fn lowpass_impulse(cutoff_hz: f64, tau0: f64, order: u8) -> Vec<f64> {
    let phi = (-2.0 * std::f64::consts::PI * cutoff_hz * tau0).exp();
    let g = 1.0 - phi;
    let mut h = Vec::new();
    let mut k = 0usize;
    loop {
        let v = if order <= 1 {
            g * phi.powi(k as i32)
        } else {
            g * g * (k as f64 + 1.0) * phi.powi(k as i32)
        };
        h.push(v);
        if (k > 4 && v < 1e-17 * g) || k > 10_000_000 {
            break;
        }
        k += 1;
    }
    h
}

/// Exact expected Allan variance of white noise of per-sample variance `var_w` through the FIR
/// `h`, at m samples: (4S(m) − S(2m))/(2m²) with S from the output autocovariance.
fn filtered_white_avar(h: &[f64], var_w: f64, m: usize) -> f64 {
    let l = h.len();
    let r = |k: usize| -> f64 {
        if k >= l {
            0.0
        } else {
            var_w
                * h[..l - k]
                    .iter()
                    .zip(&h[k..])
                    .map(|(a, b)| a * b)
                    .sum::<f64>()
        }
    };
    let s = |n: usize| -> f64 {
        let mut acc = n as f64 * r(0);
        for k in 1..n.min(l) {
            acc += 2.0 * (n - k) as f64 * r(k);
        }
        acc
    };
    (4.0 * s(m) - s(2 * m)) / (2.0 * (m * m) as f64)
}

/// Internal oversampling of the decimation filters.
pub const DECIMATION: usize = 16;

/// Expected Allan variance at m output samples of white noise (per-sample variance `var_w` at
/// the internal rate) through the FIR `h` at the internal rate, output every `r` internal
/// samples: R(k) = var_w Σ_i h_i h_{i+kr}.
fn decimated_white_avar(h: &[f64], var_w: f64, r: usize, m: usize) -> f64 {
    let r_out = |k: usize| -> f64 {
        let lag = k * r;
        if lag >= h.len() {
            0.0
        } else {
            var_w
                * h[..h.len() - lag]
                    .iter()
                    .zip(&h[lag..])
                    .map(|(a, b)| a * b)
                    .sum::<f64>()
        }
    };
    let s = |n: usize| -> f64 {
        let mut acc = n as f64 * r_out(0);
        for k in 1..n {
            let v = r_out(k);
            if v == 0.0 {
                break;
            }
            acc += 2.0 * (n - k) as f64 * v;
        }
        acc
    };
    (4.0 * s(m) - s(2 * m)) / (2.0 * (m * m) as f64)
}

/// Overlapping Allan variance of a deterministic series at m samples (its exact value).
fn exact_oavar(x: &[f64], m: usize) -> f64 {
    let mut pre = Vec::with_capacity(x.len() + 1);
    pre.push(0.0);
    let mut a = 0.0;
    for v in x {
        a += v;
        pre.push(a);
    }
    if x.len() < 2 * m {
        return f64::NAN;
    }
    let n = x.len() + 1 - 2 * m;
    let s: f64 = (0..n)
        .map(|i| (pre[i + 2 * m] - 2.0 * pre[i + m] + pre[i]).powi(2))
        .sum();
    s / (2.0 * (m * m) as f64 * n as f64)
}

impl SimConfig {
    /// `n_samples` at `rate_hz` of the sum of `effects`, the output not rounded to an LSB.
    pub fn new(rate_hz: f64, n_samples: usize, seed: u64, effects: Vec<SimEffect>) -> SimConfig {
        SimConfig {
            rate_hz,
            n_samples,
            seed,
            effects,
            lsb: None,
        }
    }

    pub fn tau0(&self) -> f64 {
        1.0 / self.rate_hz
    }

    /// Generate the rate samples (length `n_samples`).
    pub fn generate(&self) -> Vec<f64> {
        self.generate_with_temp().0
    }

    /// The temperature profile [°C] of a `Temperature` effect, if any.
    pub fn temperature(&self) -> Option<Vec<f64>> {
        self.effects.iter().find_map(|e| match *e {
            SimEffect::Temperature {
                start_c,
                rise_c,
                tau_s,
                ..
            } => Some(
                (0..self.n_samples)
                    .map(|i| start_c + rise_c * -(-(i as f64) * self.tau0() / tau_s).exp_m1())
                    .collect(),
            ),
            _ => None,
        })
    }

    /// Generate the rate samples and, when a `Temperature` effect is present, the temperature.
    pub fn generate_with_temp(&self) -> (Vec<f64>, Option<Vec<f64>>) {
        let n = self.n_samples;
        let tau0 = self.tau0();
        let mut rng = Rng::new(self.seed);
        let mut y = vec![0.0; n];
        let ar1 = |y: &mut [f64], rng: &mut Rng, sigma: f64, tau_c: f64| {
            let phi = (-tau0 / tau_c).exp();
            let innov = sigma * (1.0 - phi * phi).sqrt();
            let mut x = sigma * rng.normal();
            for v in y.iter_mut() {
                *v += x;
                x = phi * x + innov * rng.normal();
            }
        };
        for e in &self.effects {
            match *e {
                SimEffect::Quantization { q } => {
                    let mut prev = q * rng.normal();
                    for v in y.iter_mut() {
                        let next = q * rng.normal();
                        *v += (next - prev) / tau0;
                        prev = next;
                    }
                }
                SimEffect::White { n: nd } => {
                    let s = nd / tau0.sqrt();
                    for v in y.iter_mut() {
                        *v += s * rng.normal();
                    }
                }
                SimEffect::Flicker { b } => {
                    for (s, tc) in flicker_components(b, tau0, n) {
                        ar1(&mut y, &mut rng, s, tc);
                    }
                }
                SimEffect::RateRandomWalk { k } => {
                    let s = k * tau0.sqrt();
                    let mut bias = 0.0;
                    for v in y.iter_mut() {
                        bias += s * rng.normal();
                        *v += bias;
                    }
                }
                SimEffect::RateRamp { r } => {
                    for (i, v) in y.iter_mut().enumerate() {
                        *v += r * i as f64 * tau0;
                    }
                }
                SimEffect::Markov { sigma, tau_c } => ar1(&mut y, &mut rng, sigma, tau_c),
                SimEffect::Sinusoid { amplitude, freq_hz } => {
                    let ph = 2.0 * std::f64::consts::PI * rng.uniform();
                    let w = 2.0 * std::f64::consts::PI * freq_hz * tau0;
                    for (i, v) in y.iter_mut().enumerate() {
                        *v += amplitude * (w * i as f64 + ph).sin();
                    }
                }
                SimEffect::LowPassWhite {
                    n: nd,
                    cutoff_hz,
                    order,
                } => {
                    let phi = (-2.0 * std::f64::consts::PI * cutoff_hz * tau0).exp();
                    let s = nd / tau0.sqrt();
                    // start in steady state: run the filter over a warm-up of 20 time constants
                    let warm = ((20.0 / (1.0 - phi)) as usize).min(10_000_000);
                    let (mut a, mut b) = (0.0, 0.0);
                    for i in 0..warm + n {
                        let w = s * rng.normal();
                        a = phi * a + (1.0 - phi) * w;
                        b = phi * b + (1.0 - phi) * a;
                        if i >= warm {
                            y[i - warm] += if order <= 1 { a } else { b };
                        }
                    }
                }
                SimEffect::Decimated {
                    n: nd,
                    length,
                    bartlett,
                } => {
                    let r = DECIMATION;
                    let m = length * r;
                    let s = nd / (tau0 / r as f64).sqrt();
                    // running sums over the last m internal samples, once or twice
                    let stages = if bartlett { 2 } else { 1 };
                    let warm = stages * m;
                    let mut ring1 = vec![0.0; m];
                    let mut ring2 = vec![0.0; m];
                    let (mut s1, mut s2) = (0.0, 0.0);
                    for i in 0..(warm + n * r) {
                        let w = s * rng.normal();
                        let k = i % m;
                        s1 += w - ring1[k];
                        ring1[k] = w;
                        let a = s1 / m as f64;
                        let out = if bartlett {
                            s2 += a - ring2[k];
                            ring2[k] = a;
                            s2 / m as f64
                        } else {
                            a
                        };
                        if i >= warm && (i - warm) % r == r - 1 {
                            y[(i - warm) / r] += out;
                        }
                    }
                }
                SimEffect::BiasStep { at_s, size } => {
                    let k0 = (at_s / tau0).round().max(0.0) as usize;
                    for v in y.iter_mut().skip(k0) {
                        *v += size;
                    }
                }
                SimEffect::Temperature { coef, .. } => {
                    let t = self.temperature().expect("temperature effect");
                    for (v, c) in y.iter_mut().zip(&t) {
                        *v += coef * c;
                    }
                }
                SimEffect::WarmUp { amplitude, tau_s } => {
                    for (i, v) in y.iter_mut().enumerate() {
                        *v += amplitude * (-(i as f64) * tau0 / tau_s).exp();
                    }
                }
            }
        }
        if let Some(q) = self.lsb {
            for v in y.iter_mut() {
                *v = (*v / q).round() * q;
            }
        }
        (y, self.temperature())
    }

    /// Exact expected overlapping Allan variance at τ = m·τ0 of the generated process (the
    /// rounding of `lsb` adds its white floor LSB²/12 per sample, exact when the noise spans
    /// many LSBs).
    pub fn avar(&self, m: usize) -> f64 {
        let tau0 = self.tau0();
        let tau = m as f64 * tau0;
        let ctx = noise_model::Context::uniform(tau0, self.n_samples as u64);
        let round = self.lsb.map_or(0.0, |q| q * q / 12.0 / m as f64);
        round
            + self
                .effects
                .iter()
                .map(|e| match *e {
                    SimEffect::Quantization { q } => 3.0 * q * q / (tau * tau),
                    SimEffect::White { n } => n * n / tau,
                    SimEffect::Flicker { b } => flicker_components(b, tau0, self.n_samples)
                        .iter()
                        .map(|&(s, tc)| s * s * markov_avar_unit(tau, tau0, tc))
                        .sum(),
                    SimEffect::RateRandomWalk { k } => {
                        k * k * (tau / 3.0 + tau0 * tau0 / (6.0 * tau))
                    }
                    SimEffect::RateRamp { r } => r * r * tau * tau / 2.0,
                    SimEffect::Markov { sigma, tau_c } => {
                        sigma * sigma * markov_avar_unit(tau, tau0, tau_c)
                    }
                    SimEffect::Sinusoid { amplitude, freq_hz } => {
                        amplitude * amplitude * sinusoid_avar_unit(tau, tau0, freq_hz)
                    }
                    SimEffect::LowPassWhite {
                        n,
                        cutoff_hz,
                        order,
                    } => {
                        if order <= 1 {
                            // AR(1) with φ = e^{−2πf_cτ0}: variance (N²/τ0)(1−φ)/(1+φ), τ_c = 1/(2πf_c)
                            let phi = (-2.0 * std::f64::consts::PI * cutoff_hz * tau0).exp();
                            let var = n * n / tau0 * (1.0 - phi) / (1.0 + phi);
                            var * markov_avar_unit(
                                tau,
                                tau0,
                                1.0 / (2.0 * std::f64::consts::PI * cutoff_hz),
                            )
                        } else {
                            let h = lowpass_impulse(cutoff_hz, tau0, order);
                            filtered_white_avar(&h, n * n / tau0, m)
                        }
                    }
                    SimEffect::Decimated {
                        n,
                        length,
                        bartlett,
                    } => {
                        // the discrete construction's own impulse response at the internal rate
                        let r = DECIMATION;
                        let len = length * r;
                        let boxcar = vec![1.0 / len as f64; len];
                        let h = if bartlett {
                            let mut c = vec![0.0; 2 * len - 1];
                            for (i, a) in boxcar.iter().enumerate() {
                                for (j, b) in boxcar.iter().enumerate() {
                                    c[i + j] += a * b;
                                }
                            }
                            c
                        } else {
                            boxcar
                        };
                        decimated_white_avar(&h, n * n / (tau0 / r as f64), r, m)
                    }
                    SimEffect::BiasStep { at_s, size } => {
                        size * size
                            * noise_model::effect::step_avar(
                                (at_s / tau0).round() as u64,
                                m as u64,
                                &ctx,
                            )
                    }
                    SimEffect::Temperature { coef, .. } => {
                        let t = self.temperature().expect("temperature");
                        coef * coef * exact_oavar(&t, m)
                    }
                    SimEffect::WarmUp { amplitude, tau_s } => {
                        amplitude
                            * amplitude
                            * noise_model::effect::warmup_avar(tau_s / tau0, m as u64, &ctx)
                    }
                })
                .sum::<f64>()
    }

    /// Exact expected overlapping Allan deviation at each m.
    pub fn adev(&self, ms: &[usize]) -> Vec<f64> {
        ms.iter().map(|&m| self.avar(m).sqrt()).collect()
    }
}

/// The power-law background of a gyro like the MPU-6050 (deg/s): Q 2e-4 °, N 5e-3 °/s·√s
/// (0.3 °/√h) when `white`, B 3e-3 °/s (11 °/h), K 1e-4 °/s/√s — the tests' and studies' control.
pub fn gyro_background(white: bool) -> Vec<SimEffect> {
    let mut v = vec![
        SimEffect::Quantization { q: 2e-4 },
        SimEffect::Flicker { b: 3e-3 },
        SimEffect::RateRandomWalk { k: 1e-4 },
    ];
    if white {
        v.push(SimEffect::White { n: 5e-3 });
    }
    v
}

/// A simulated record ready for the noise lab: the samples, the temperature column when the
/// configuration has one, and the octave overlapping Allan points, as `imu-lab fit` computes them.
#[derive(Debug, Clone)]
pub struct Analysed {
    pub tau0: f64,
    pub y: Vec<f64>,
    pub temp: Option<Vec<f64>>,
    pub points: Vec<noise_model::Point>,
}

impl SimConfig {
    /// Generate the record and its Allan points.
    pub fn analyse(&self) -> Analysed {
        let (y, temp) = self.generate_with_temp();
        let rows = allan::deviation(&y, self.tau0(), allan::Stat::Oadev, &allan::TauSet::Octave)
            .expect("a simulated record long enough for one octave");
        let (points, _) = noise_model::Point::from_rows(&rows);
        Analysed {
            tau0: self.tau0(),
            y,
            temp,
            points,
        }
    }
}

impl Analysed {
    /// The lab's input (one uninterrupted segment), with the timestamps' analysis when given.
    pub fn record(&self, timing: Option<noise_model::Timing>) -> noise_model::Record<'_> {
        noise_model::Record {
            y: &self.y,
            tau0: self.tau0,
            segments: vec![(0, self.y.len() as u64)],
            temp: self.temp.as_deref(),
            timing,
            points: self.points.clone(),
            user_effects: Vec::new(),
        }
    }
}

/// Write columns as CSV in the project's contract: a header row `t,<names…>` and one row per
/// sample, t = i/rate [s], values in the channel's contract unit (gx gy gz in deg/s, ax ay az in
/// m/s², mx my mz in µT). Values are written with Rust's shortest round-trip representation.
pub fn write_csv<W: Write>(mut w: W, rate_hz: f64, columns: &[(&str, &[f64])]) -> io::Result<()> {
    let n = columns.iter().map(|c| c.1.len()).min().unwrap_or(0);
    write!(w, "t")?;
    for (name, _) in columns {
        write!(w, ",{name}")?;
    }
    writeln!(w)?;
    for i in 0..n {
        write!(w, "{}", i as f64 / rate_hz)?;
        for (_, v) in columns {
            write!(w, ",{}", v[i])?;
        }
        writeln!(w)?;
    }
    w.flush()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn normals_have_unit_variance() {
        let mut r = Rng::new(7);
        let n = 200_000;
        let xs: Vec<f64> = (0..n).map(|_| r.normal()).collect();
        let m = xs.iter().sum::<f64>() / n as f64;
        let v = xs.iter().map(|x| (x - m).powi(2)).sum::<f64>() / n as f64;
        // mean ~ N(0, 1/n): 5σ = 0.011; variance ~ 1 ± √(2/n): 5σ = 0.016
        assert!(m.abs() < 0.011 && (v - 1.0).abs() < 0.016, "{m} {v}");
    }

    #[test]
    fn second_order_filter_formula_reduces_to_first_order() {
        // the generic autocorrelation path must reproduce the closed AR(1) form for order 1
        let cfg = SimConfig::new(
            100.0,
            1000,
            1,
            vec![SimEffect::LowPassWhite {
                n: 0.01,
                cutoff_hz: 5.0,
                order: 1,
            }],
        );
        let h = lowpass_impulse(5.0, 0.01, 1);
        for m in [1usize, 2, 5, 40, 300] {
            let a = cfg.avar(m);
            let b = filtered_white_avar(&h, 0.01f64.powi(2) / 0.01, m);
            assert!((a - b).abs() < 1e-9 * a, "m {m}: {a} vs {b}");
            // long τ: the white line N²/τ
        }
        let tau = 300.0 * 0.01;
        assert!((cfg.avar(300) - 1e-4 / tau).abs() < 0.02 * 1e-4 / tau);
    }

    #[test]
    fn flicker_is_flat_within_ripple() {
        let b = 0.01;
        let cfg = SimConfig::new(100.0, 1 << 18, 1, vec![SimEffect::Flicker { b }]);
        let target = 2.0 * std::f64::consts::LN_2 / std::f64::consts::PI * b * b;
        for k in 0..17 {
            let v = cfg.avar(1 << k);
            // measured ripple of this construction: +13 % at m = 1 (aliasing of the fastest
            // components), within ±2.5 % from m = 2 to n/4
            let tol = if k == 0 { 0.15 } else { 0.03 };
            assert!((v / target - 1.0).abs() < tol, "m=2^{k}: {}", v / target);
        }
    }

    #[test]
    fn csv_layout() {
        let mut out = Vec::new();
        write_csv(&mut out, 100.0, &[("gz", &[0.5, -1.25][..])]).unwrap();
        assert_eq!(String::from_utf8(out).unwrap(), "t,gz\n0,0.5\n0.01,-1.25\n");
    }
}
