//! The calibration lab (`imu_cal::session`, what `imu-lab calibrate` runs) on numpy arrays.
use std::collections::HashMap;
use std::ops::Range;

use imu_cal::lab::Effect;
use imu_cal::session::{self, json_out, Loaded, Options, Outcome, Sensor};
use numpy::PyReadonlyArray1;
use pyo3::prelude::*;

use crate::{guarded, value_error};

/// A finished calibration session: its JSON object and the calibration file's text.
#[pyclass(unsendable, module = "pico_imu._native")]
pub struct NativeCalibration {
    loaded: Loaded,
    run: Outcome,
}

#[pymethods]
impl NativeCalibration {
    /// The JSON object `imu-lab calibrate --json` prints, as text.
    fn json(&self) -> String {
        json_out(&self.loaded, &self.run)
    }

    /// The calibration file (TOML) `existing` (or a new one) with this run's section set; a
    /// `ValueError` naming the key, axis, value and bound when the device could not hold it.
    #[pyo3(signature = (existing=None))]
    fn toml(&self, existing: Option<&str>) -> PyResult<String> {
        guarded("Calibration.save", || {
            session::update_file(existing, &self.loaded, &self.run).map_err(value_error)
        })
    }

    /// The calibration file's section this run writes (`accel`, `gyro`, `gyro-rot`, `mag`).
    fn section(&self) -> &'static str {
        self.loaded.data.section()
    }
}

/// Calibrates `sensor` (`accel`, `gyro`, `mag`) from `columns` (name → samples, e.g. mx my mz)
/// in `units` (name → unit), sampled at `rate` Hz with `segments` the row ranges between gaps:
/// `imu-lab calibrate`'s session with its options (`g` and `field` in the columns' unit,
/// `window` and `min_static` in s, `saturation` in deg/s). Bad data and options raise
/// `ValueError` naming them.
#[pyfunction]
#[pyo3(signature = (sensor, columns, units, rate, segments, model=Vec::new(), g=None, field=None,
    window=1.0, threshold_k=6.0, min_static=1.5, saturation=None, blocks=50, auto=false,
    max_steps=4, part=None))]
#[allow(clippy::too_many_arguments)]
pub fn calibrate(
    py: Python<'_>,
    sensor: &str,
    columns: HashMap<String, PyReadonlyArray1<'_, f64>>,
    units: HashMap<String, String>,
    rate: f64,
    segments: Vec<(usize, usize)>,
    model: Vec<String>,
    g: Option<f64>,
    field: Option<f64>,
    window: f64,
    threshold_k: f64,
    min_static: f64,
    saturation: Option<f64>,
    blocks: usize,
    auto: bool,
    max_steps: usize,
    part: Option<String>,
) -> PyResult<NativeCalibration> {
    let sensor = Sensor::parse(sensor).ok_or_else(|| {
        value_error(format!(
            "sensor={sensor:?}: expected \"accel\", \"gyro\" or \"mag\""
        ))
    })?;
    let mut cols: Vec<(String, String, Vec<f64>)> = columns
        .into_iter()
        .map(|(n, a)| {
            let u = units.get(&n).cloned().unwrap_or_default();
            (n, u, a.as_array().to_vec())
        })
        .collect();
    // by name, so that messages do not depend on the dict's hashing
    cols.sort_by(|a, b| a.0.cmp(&b.0));
    py.detach(move || {
        guarded("calibrate", || {
            let model = model
                .iter()
                .filter(|s| !s.trim().is_empty())
                .map(|s| Effect::parse(s).map_err(|e| value_error(format!("model: {e}"))))
                .collect::<PyResult<Vec<_>>>()?;
            let o = Options {
                sensor,
                model,
                g,
                field,
                window,
                threshold_k,
                min_static,
                saturation,
                blocks,
                auto,
                max_steps,
                cli: false,
                mag_part: match &part {
                    Some(name) => session::stated_part(sensor, name, "part=").map_err(value_error)?,
                    None => None,
                },
            };
            let n = cols.first().map_or(0, |c| c.2.len());
            if let Some(c) = cols.iter().find(|c| c.2.len() != n) {
                return Err(value_error(format!(
                    "columns: {} has {} samples, {} has {n}; give one value per row in each",
                    c.0,
                    c.2.len(),
                    cols[0].0
                )));
            }
            let segments: Vec<Range<usize>> = segments.iter().map(|&(a, b)| a..b).collect();
            let mut end = 0;
            for (i, r) in segments.iter().enumerate() {
                if r.start < end || r.start >= r.end || r.end > n {
                    return Err(value_error(format!(
                        "segments[{i}] = ({}, {}): must lie in the {n} rows, in order, without overlap",
                        r.start, r.end
                    )));
                }
                end = r.end;
            }
            let input = session::Input {
                columns: cols
                    .iter()
                    .map(|(n, u, v)| session::Column {
                        name: n,
                        unit: u,
                        values: v,
                    })
                    .collect(),
                rate_hz: rate,
                segments: &segments,
                shown: "samples",
            };
            let loaded = session::prepare(&input, &o).map_err(value_error)?;
            let run = session::run(&loaded, &o).map_err(value_error)?;
            Ok(NativeCalibration { loaded, run })
        })
    })
}
