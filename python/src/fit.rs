//! The noise lab (`noise_model::session`, what `imu-lab fit` runs) on numpy arrays.
use std::sync::Arc;

use imu_proto::csv::timing;
use noise_model::session::{self, Flags, Options, Session};
use noise_model::user::UserEffect;
use noise_model::Effect;
use numpy::{IntoPyArray, PyReadonlyArray1};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};

use crate::{guarded, value_error};

/// A finished session: its JSON object (`imu-lab fit --json`) and the curves of every model.
#[pyclass(frozen, module = "pico_imu._native")]
pub struct NativeFit {
    session: Session,
}

#[pymethods]
impl NativeFit {
    /// The JSON object `imu-lab fit --json` prints, as text.
    fn json(&self) -> String {
        self.session.json_string()
    }

    /// The verdict sentence on the last model, as the CLI prints it.
    fn verdict(&self) -> String {
        self.session.verdict()
    }

    /// Per term of the last model: (parameter name, unit), the amplitude first.
    fn param_units(&self) -> Vec<Vec<(String, String)>> {
        self.session.param_units()
    }

    /// Effect name → its physical mechanism, for the last model's effects and the missing one.
    fn physics(&self) -> Vec<(String, String)> {
        self.session.physics()
    }

    /// One dict per model analysed (the start model first): `effects` (names), `tau` (s),
    /// `dev`, `lo`, `hi` (68.3 %), `model` (the model's deviation), `residual` ((measured −
    /// model)/CI half-width), `terms` (name → each term's deviation at the points), `adequate`.
    fn stages<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyList>> {
        let out = PyList::empty(py);
        for st in &self.session.stages {
            let f = &st.model.fit;
            let d = PyDict::new(py);
            let names: Vec<String> = f.effects().iter().map(|e| e.name().to_string()).collect();
            d.set_item("effects", names)?;
            let col = |g: &dyn Fn(&noise_model::Point) -> f64| -> Vec<f64> {
                f.points.iter().map(g).collect()
            };
            d.set_item("tau", col(&|p| p.tau).into_pyarray(py))?;
            d.set_item("dev", col(&|p| p.dev).into_pyarray(py))?;
            d.set_item("lo", col(&|p| p.lo).into_pyarray(py))?;
            d.set_item("hi", col(&|p| p.hi).into_pyarray(py))?;
            let model: Vec<f64> = f.model_avar.iter().map(|v| v.max(0.0).sqrt()).collect();
            d.set_item("model", model.into_pyarray(py))?;
            d.set_item(
                "residual",
                st.model.assessment.residuals.clone().into_pyarray(py),
            )?;
            let terms = PyDict::new(py);
            for (k, t) in f.terms.iter().enumerate() {
                let dev: Vec<f64> = f.term_avar(k).iter().map(|v| v.max(0.0).sqrt()).collect();
                terms.set_item(t.effect.name(), dev.into_pyarray(py))?;
            }
            d.set_item("terms", terms)?;
            d.set_item("adequate", st.diagnosis.adequate)?;
            out.append(d)?;
        }
        Ok(out)
    }
}

/// The first index of `a` holding NaN or ±inf.
fn first_bad(a: &[f64]) -> Option<usize> {
    a.iter().position(|v| !v.is_finite())
}

/// Fits the noise model to `y` (rate samples in `unit`) as `imu-lab fit` does: `rate` in Hz
/// (from `t` when None), `t` (s) and `gap_before` the recording's time columns (timing, gaps,
/// segments), `temp` (°C, NaN where missing) beside each sample; `terms`, `add`, `auto`,
/// `max_steps`, `tolerance` (in `unit`) as the CLI's flags; `effects` a list of (TOML text,
/// name shown in messages) of user effects. Bad data and options raise `ValueError` naming them.
#[pyfunction]
#[pyo3(signature = (y, rate=None, unit="", column="y", t=None, gap_before=None, temp=None,
    terms=Vec::new(), add=Vec::new(), effects=Vec::new(), auto=false, max_steps=6, tolerance=None))]
#[allow(clippy::too_many_arguments)]
pub fn fit(
    py: Python<'_>,
    y: PyReadonlyArray1<'_, f64>,
    rate: Option<f64>,
    unit: &str,
    column: &str,
    t: Option<PyReadonlyArray1<'_, f64>>,
    gap_before: Option<PyReadonlyArray1<'_, f64>>,
    temp: Option<PyReadonlyArray1<'_, f64>>,
    terms: Vec<String>,
    add: Vec<String>,
    effects: Vec<(String, String)>,
    auto: bool,
    max_steps: usize,
    tolerance: Option<f64>,
) -> PyResult<NativeFit> {
    let y = y.as_array().to_vec();
    let t = t.map(|a| a.as_array().to_vec());
    let gap_before = gap_before.map(|a| a.as_array().to_vec());
    let temp = temp.map(|a| a.as_array().to_vec());
    let (unit, column) = (unit.to_string(), column.to_string());
    py.detach(move || {
        guarded("fit", || {
            if let Some(i) = first_bad(&y) {
                return Err(value_error(format!(
                    "y[{i}] = {}: not a finite sample; remove or fill it",
                    y[i]
                )));
            }
            for (name, a) in [("t", &t), ("gap_before", &gap_before), ("temp", &temp)] {
                if let Some(a) = a {
                    if a.len() != y.len() {
                        return Err(value_error(format!(
                            "{name}: {} values for {} samples of y; give one per sample",
                            a.len(),
                            y.len()
                        )));
                    }
                }
            }
            let tm = match &t {
                Some(t) => Some(
                    timing(t, gap_before.as_deref()).map_err(|e| value_error(format!("t: {e}")))?,
                ),
                None => None,
            };
            let rate_hz = match (rate, &tm) {
                // Both: they must agree, as `imu-lab fit --rate` must with the time column
                // (a rate 10× the stamps' gave N off by √10, silently).
                (Some(r), Some(tm)) => {
                    let from_t = tm.rate_hz();
                    let agree = (r / from_t - 1.0).abs() <= 0.01;
                    if !agree {
                        return Err(value_error(format!(
                            "rate={}: disagrees with t, whose spacing is {} s ({} Hz); give \
                             one of them, or both agreeing within 1 %",
                            crate::dev::short_num(r),
                            crate::dev::short_num(tm.period_s),
                            crate::dev::short_num(from_t)
                        )));
                    }
                    r
                }
                (Some(r), None) => r,
                (None, Some(tm)) => tm.rate_hz(),
                (None, None) => {
                    return Err(value_error(
                        "rate: give the sample rate in Hz (or t, the sample times in s)",
                    ))
                }
            };
            if !(rate_hz > 0.0 && rate_hz.is_finite()) {
                return Err(value_error(format!(
                    "rate={}: the sample rate must be a positive finite number of Hz",
                    crate::dev::short_num(rate_hz)
                )));
            }
            let segments = match &tm {
                Some(tm) => tm.segments(),
                None => std::iter::once(0..y.len()).collect(),
            };
            let user = effects
                .iter()
                .map(|(text, shown)| {
                    UserEffect::parse(text, shown)
                        .map(|u| Effect::User(Arc::new(u)))
                        .map_err(|e| value_error(format!("effects: {e}")))
                })
                .collect::<PyResult<Vec<_>>>()?;
            let opts = Options {
                terms,
                add,
                auto,
                max_steps,
                user,
                tolerance,
                flags: Flags::PYTHON,
            };
            let label = format!("column {column:?}");
            let s = session::run(
                &session::Input {
                    column: &column,
                    unit: &unit,
                    y: &y,
                    rate_hz,
                    segments: &segments,
                    temp: temp.as_deref(),
                    timing: tm.as_ref(),
                    label: &label,
                },
                &opts,
            )
            .map_err(value_error)?;
            Ok(NativeFit { session: s })
        })
    })
}
