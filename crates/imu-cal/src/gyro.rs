//! Gyroscope bias at rest (seed eq. 2) and its temperature dependence.
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
use nalgebra::{Matrix2, Vector2};

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
}

impl GyroProblem {
    /// Cut a recording at rest into `n_blocks` blocks (the tail that does not fill a block is
    /// dropped). Non-finite values are an error naming the sample.
    pub fn new(g: [&[f64]; 3], temp: Option<&[f64]>, n_blocks: usize) -> Result<Self, CalError> {
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
        }
        if let Some(i) = temp.and_then(|t| t.iter().position(|v| !v.is_finite())) {
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
        let (bx, dx) = blocks_of(g[0]);
        let (by, dy) = blocks_of(g[1]);
        let (bz, dz) = blocks_of(g[2]);
        Ok(GyroProblem {
            blocks: [bx, by, bz],
            temp: temp.map(|t| blocks_of(t).0),
            half_diff: [dx, dy, dz],
            block_len: len,
        })
    }
}

impl Problem for GyroProblem {
    fn sensor(&self) -> &'static str {
        "gyro"
    }
    fn unit(&self) -> &'static str {
        "deg/s"
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
                return Err("no temperature column".into());
            };
            let lo = t.iter().cloned().fold(f64::INFINITY, f64::min);
            let hi = t.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
            if hi - lo < 0.05 {
                return Err(format!("temperature spans only {:.3} °C", hi - lo));
            }
        }
        Ok(())
    }

    fn fit(&self, model: &[Effect]) -> Result<Fitted, CalError> {
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
        let mut bias = [0.0; 3];
        let mut kc = [0.0; 3];
        let mut residuals = Vec::with_capacity(3 * nb);
        for j in 0..3 {
            let y = &self.blocks[j];
            let (b, k) = match (has_b, has_t) {
                (false, false) => (0.0, 0.0),
                (true, false) => (mean(y), 0.0),
                (false, true) => {
                    let sxx: f64 = dt.iter().map(|d| d * d).sum();
                    (0.0, dt.iter().zip(y).map(|(d, y)| d * y).sum::<f64>() / sxx)
                }
                (true, true) => {
                    // Normal equations of y = b + k·dt.
                    let n = nb as f64;
                    let sx: f64 = dt.iter().sum();
                    let sxx: f64 = dt.iter().map(|d| d * d).sum();
                    let sy: f64 = y.iter().sum();
                    let sxy: f64 = dt.iter().zip(y).map(|(d, y)| d * y).sum();
                    let sol = Matrix2::new(n, sx, sx, sxx)
                        .lu()
                        .solve(&Vector2::new(sy, sxy))
                        .ok_or_else(|| CalError::Fit("temperature fit is singular".into()))?;
                    (sol.x, sol.y)
                }
            };
            bias[j] = b;
            kc[j] = k;
            residuals.extend(y.iter().zip(&dt).map(|(y, d)| y - b - k * d));
        }
        let params = Params {
            bias: has_b.then_some(bias),
            temp_coeff: has_t.then_some(kc),
            temp_ref: has_t.then_some(t_ref),
            ..Params::default()
        };
        Ok(Fitted {
            model: model.to_vec(),
            params,
            residuals,
            n_params: 3 * (has_b as usize + has_t as usize),
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
