//! Gyroscope bias at rest (Jaime et al., eq. 2) and its temperature dependence.
//!
//! Model per axis j, from a recording at rest:
//!
//! ```text
//! ω_j = b_j + k_j · (T − T_ref) + noise        (T_ref = mean temperature of the recording)
//! ```
//!
//! The lab works on **blocks**: the recording is cut into B equal blocks and the residual of a
//! block is its mean rate minus the model at its mean temperature (3 residuals per block). Per
//! sample the temperature effect is buried in white noise; on block means it is visible, and the
//! noise floor of a block mean is measured from the data: the difference d of a block's two half
//! means has variance 4·var(block mean) for white noise (an Allan-type estimate at τ = half a
//! block). Earth rate (≤ 0.0042 °/s) is part of the "bias" of a fixed pose.
use crate::lab::{CalError, Effect, Fitted, NoiseFloor, Params, Problem};
use crate::solve::mean;

const EFFECTS: [Effect; 2] = [Effect::Bias, Effect::Temperature];

/// The gyro problem, on block means.
#[derive(Debug, Clone)]
pub struct GyroProblem {
    /// Block means of the rate per axis (deg/s).
    pub blocks: [Vec<f64>; 3],
    /// Block means of the temperature (°C), if a temperature column exists.
    pub temp: Option<Vec<f64>>,
    /// Half-block differences per axis (deg/s).
    pub half_diff: [Vec<f64>; 3],
    /// Samples per block.
    pub block_len: usize,
    /// The data's unit (deg/s for the contract; LSB for raw counts).
    pub unit: String,
    /// Blocks without any temperature reading (the temperature column has empty fields), when
    /// that made the temperature unusable.
    pub blocks_without_temp: usize,
}

impl GyroProblem {
    /// Cut a recording at rest into `n_blocks` blocks (the tail that does not fill a block is
    /// dropped), in deg/s. Non-finite rates are an error naming the sample; a temperature of NaN
    /// is a missing reading; an axis that never changes is refused (a gyro at rest always
    /// shows noise: a constant column is a stuck sensor or the wrong column).
    pub fn new(g: [&[f64]; 3], temp: Option<&[f64]>, n_blocks: usize) -> Result<Self, CalError> {
        Self::with_unit(g, temp, n_blocks, "deg/s")
    }

    /// As [`GyroProblem::new`], for rates in `unit`.
    pub fn with_unit(
        g: [&[f64]; 3],
        temp: Option<&[f64]>,
        n_blocks: usize,
        unit: &str,
    ) -> Result<Self, CalError> {
        let n = g[0].len();
        if g.iter().any(|a| a.len() != n) || temp.is_some_and(|t| t.len() != n) {
            return Err(CalError::Input(
                "gyro/temperature columns have different lengths".into(),
            ));
        }
        for (k, a) in g.iter().enumerate() {
            if let Some(i) = a.iter().position(|v| !v.is_finite()) {
                return Err(CalError::Input(format!(
                    "gyro sample {i} (axis {}) is not finite",
                    ["x", "y", "z"][k]
                )));
            }
            if n > 1 && a.iter().all(|v| *v == a[0]) {
                return Err(CalError::Input(format!(
                    "gyro axis {} is constant (all {n} samples are {} {unit}): a gyro at rest \
                     always shows noise, so this is a stuck sensor or the wrong column; there \
                     is no noise to judge a calibration against",
                    ["x", "y", "z"][k],
                    a[0]
                )));
            }
        }
        if let Some(i) = temp.and_then(|t| t.iter().position(|v| v.is_infinite())) {
            return Err(CalError::Input(format!(
                "temperature sample {i} is not finite"
            )));
        }
        let nb = n_blocks.max(4);
        let len = n / nb;
        if len < 4 {
            return Err(CalError::Input(format!(
                "{n} samples cannot make {nb} blocks of at least 4 samples"
            )));
        }
        let blocks_of = |x: &[f64]| -> (Vec<f64>, Vec<f64>) {
            (0..nb)
                .map(|b| {
                    let s = &x[b * len..(b + 1) * len];
                    (
                        mean(s),
                        mean(&s[..len / 2]) - mean(&s[len / 2..2 * (len / 2)]),
                    )
                })
                .unzip()
        };
        // Block temperature: the mean of the readings it has.
        let temp_blocks = temp.map(|t| {
            (0..nb)
                .map(|b| {
                    let r: Vec<f64> = t[b * len..(b + 1) * len]
                        .iter()
                        .copied()
                        .filter(|v| v.is_finite())
                        .collect();
                    if r.is_empty() {
                        f64::NAN
                    } else {
                        mean(&r)
                    }
                })
                .collect::<Vec<f64>>()
        });
        let without = temp_blocks
            .as_ref()
            .map_or(0, |t| t.iter().filter(|v| v.is_nan()).count());
        let (bx, dx) = blocks_of(g[0]);
        let (by, dy) = blocks_of(g[1]);
        let (bz, dz) = blocks_of(g[2]);
        Ok(GyroProblem {
            blocks: [bx, by, bz],
            temp: temp_blocks.filter(|_| without == 0),
            half_diff: [dx, dy, dz],
            block_len: len,
            unit: unit.into(),
            blocks_without_temp: without,
        })
    }

    /// The lab residual of block `i` of axis `j` under `params`: block mean − b − k·(T − T_ref).
    pub fn residual(&self, params: &Params, j: usize, i: usize) -> f64 {
        let b = params.bias.map_or(0.0, |b| b[j]);
        let k = params.temp_coeff.map_or(0.0, |k| k[j]);
        let t = match (&self.temp, params.temp_ref) {
            (Some(t), Some(r)) => t[i] - r,
            _ => 0.0,
        };
        self.blocks[j][i] - b - k * t
    }
}

/// Weighted-free straight line y = b + k·x over the points, with the standard errors of b and k
/// (s² = RSS/(n − 2)): (b, k, σ_b, σ_k). Singular when every x is equal.
fn line(x: &[f64], y: &[f64]) -> Option<(f64, f64, f64, f64)> {
    let n = x.len() as f64;
    let (sx, sy) = (x.iter().sum::<f64>(), y.iter().sum::<f64>());
    let sxx: f64 = x.iter().map(|v| v * v).sum();
    let sxy: f64 = x.iter().zip(y).map(|(a, b)| a * b).sum();
    let det = n * sxx - sx * sx;
    if !(det.abs() > 1e-12 * (n * sxx).max(1e-300)) {
        return None;
    }
    let k = (n * sxy - sx * sy) / det;
    let b = (sy - k * sx) / n;
    let rss: f64 = x.iter().zip(y).map(|(a, v)| (v - b - k * a).powi(2)).sum();
    let s2 = if n > 2.0 { rss / (n - 2.0) } else { f64::NAN };
    Some((b, k, (s2 * sxx / det).sqrt(), (s2 * n / det).sqrt()))
}

impl Problem for GyroProblem {
    fn sensor(&self) -> &'static str {
        "gyro"
    }
    fn unit(&self) -> &str {
        &self.unit
    }
    fn effects(&self) -> &'static [Effect] {
        &EFFECTS
    }
    fn n(&self) -> usize {
        3 * self.blocks[0].len()
    }

    fn identifiable(&self, _model: &[Effect], e: Effect) -> Result<(), String> {
        if e == Effect::Temperature {
            let Some(t) = &self.temp else {
                return Err(if self.blocks_without_temp > 0 {
                    format!(
                        "{} of {} blocks have no temperature reading (empty fields)",
                        self.blocks_without_temp,
                        self.blocks[0].len()
                    )
                } else {
                    "no temperature column".into()
                });
            };
            let lo = t.iter().cloned().fold(f64::INFINITY, f64::min);
            let hi = t.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
            if hi - lo < 0.05 {
                return Err(format!("temperature spans only {:.3} °C", hi - lo));
            }
        }
        Ok(())
    }

    fn fit_items(&self, model: &[Effect], keep: &[bool]) -> Result<Fitted, CalError> {
        let has_b = model.contains(&Effect::Bias);
        let has_t = model.contains(&Effect::Temperature);
        if has_t {
            self.identifiable(model, Effect::Temperature)
                .map_err(CalError::Fit)?;
        }
        let nb = self.blocks[0].len();
        let t = self.temp.clone().unwrap_or_else(|| vec![0.0; nb]);
        let t_ref = mean(&t);
        let dt: Vec<f64> = t.iter().map(|v| v - t_ref).collect();
        let (mut bias, mut kc, mut sb, mut sk) = ([0.0; 3], [0.0; 3], [0.0; 3], [0.0; 3]);
        let p_axis = has_b as usize + has_t as usize;
        for j in 0..3 {
            let idx: Vec<usize> = (0..nb).filter(|&i| keep[j * nb + i]).collect();
            if idx.len() <= p_axis + 1 {
                return Err(CalError::Fit(format!(
                    "axis {}: {} block means left, too few for {p_axis} parameters",
                    ["x", "y", "z"][j],
                    idx.len()
                )));
            }
            let y: Vec<f64> = idx.iter().map(|&i| self.blocks[j][i]).collect();
            let x: Vec<f64> = idx.iter().map(|&i| dt[i]).collect();
            let n = y.len() as f64;
            (bias[j], kc[j], sb[j], sk[j]) = match (has_b, has_t) {
                (false, false) => (0.0, 0.0, 0.0, 0.0),
                (true, false) => {
                    let b = mean(&y);
                    let s2 = y.iter().map(|v| (v - b).powi(2)).sum::<f64>() / (n - 1.0);
                    (b, 0.0, (s2 / n).sqrt(), 0.0)
                }
                (false, true) => {
                    let sxx: f64 = x.iter().map(|d| d * d).sum();
                    let k = x.iter().zip(&y).map(|(d, y)| d * y).sum::<f64>() / sxx;
                    let s2 = x
                        .iter()
                        .zip(&y)
                        .map(|(d, v)| (v - k * d).powi(2))
                        .sum::<f64>()
                        / (n - 1.0);
                    (0.0, k, 0.0, (s2 / sxx).sqrt())
                }
                (true, true) => line(&x, &y).ok_or_else(|| {
                    CalError::Fit("temperature fit is singular (one temperature only)".into())
                })?,
            };
        }
        let params = Params {
            bias: has_b.then_some(bias),
            temp_coeff: has_t.then_some(kc),
            temp_ref: has_t.then_some(t_ref),
            ..Params::default()
        };
        let sigma = Params {
            bias: has_b.then_some(sb),
            temp_coeff: has_t.then_some(sk),
            temp_ref: has_t.then_some(0.0),
            ..Params::default()
        };
        let residuals = (0..3)
            .flat_map(|j| (0..nb).map(move |i| (j, i)))
            .map(|(j, i)| self.residual(&params, j, i))
            .collect();
        Ok(Fitted {
            model: model.to_vec(),
            params,
            sigma,
            residuals,
            used: keep.to_vec(),
            n_params: 3 * p_axis,
            not_converged: None,
        })
    }

    fn noise_floor(&self) -> NoiseFloor {
        let d2: Vec<f64> = self.half_diff.iter().flatten().map(|d| d * d).collect();
        NoiseFloor {
            sigma: (mean(&d2) / 4.0).sqrt(),
            dof: d2.len() as f64,
            method: "half-block mean differences",
        }
    }
}
