//! The bounded streaming engine (`allan::Engine`, the device's) fed from Python chunk by chunk.
use allan::Engine;
use numpy::{IntoPyArray, PyReadonlyArray1};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::dev::tau0_of;
use crate::{guarded, value_error};

/// The host's engine configuration, as `imu-lab adev --bounded` uses: overlap 8, 32 octave
/// levels (m up to 2^31).
type HostEngine = Engine<8, 32, 12, 28>;

/// Overlapping Allan and Hadamard deviations at octave τ in constant memory (a few KiB,
/// whatever the length), integer-exact. Samples are whole counts (raw LSB); `scale` converts
/// counts to the unit of the tables.
#[pyclass(module = "pico_imu._native")]
pub struct Stream {
    engine: Box<HostEngine>,
    tau0: f64,
    scale: f64,
}

#[pymethods]
impl Stream {
    /// A new engine for samples every 1/`rate` s, each count worth `scale` units.
    #[new]
    #[pyo3(signature = (rate, scale=1.0))]
    fn new(rate: f64, scale: f64) -> PyResult<Self> {
        let tau0 = tau0_of(rate)?;
        if !(scale > 0.0 && scale.is_finite()) {
            return Err(value_error(format!(
                "scale={}: the value of one count must be a positive finite number",
                crate::dev::short_num(scale)
            )));
        }
        Ok(Stream {
            engine: Box::new(HostEngine::new()),
            tau0,
            scale,
        })
    }

    /// Feeds a chunk of whole counts (any numeric array; each value must be an integer of the
    /// engine's i32, −2^31 … 2^31 − 1). The GIL is released while the chunk is summed.
    fn push(&mut self, py: Python<'_>, chunk: PyReadonlyArray1<'_, f64>) -> PyResult<()> {
        let mut owned = Vec::new();
        let y = crate::dev::contiguous(&chunk, &mut owned);
        // Checked before any sample enters the engine: a refused chunk leaves it unchanged.
        if let Some(i) = y
            .iter()
            .position(|v| !(v.fract() == 0.0 && (i32::MIN as f64..=i32::MAX as f64).contains(v)))
        {
            let total = self.engine.samples() + i as u64;
            return Err(value_error(format!(
                "chunk[{i}] (sample {total} of the stream) is {}, not a whole count from −2^31 to \
                 2^31 − 1; \
                 the streaming engine takes raw counts (convert with scale=)",
                y[i]
            )));
        }
        let engine = &mut self.engine;
        py.detach(|| {
            guarded("Stream.push", || {
                for &v in y {
                    engine.push(v as i32);
                }
                Ok(())
            })
        })
    }

    /// Marks a gap (samples lost): no difference spans it.
    fn gap(&mut self) {
        self.engine.gap();
    }

    /// Samples pushed so far.
    #[getter]
    fn samples(&self) -> u64 {
        self.engine.samples()
    }

    /// Gaps marked so far.
    #[getter]
    fn gaps(&self) -> u32 {
        self.engine.gaps()
    }

    /// The table so far: `stat` is `"oadev"` or `"ohdev"`. A dict of arrays `tau` (s), `m`,
    /// `dev` (count × scale), `n`, `alpha`, `edf`, `lo`, `hi` (68.3 % bounds), `stride`.
    #[pyo3(signature = (stat="oadev"))]
    fn table<'py>(&self, py: Python<'py>, stat: &str) -> PyResult<Bound<'py, PyDict>> {
        let hadamard = match stat {
            "oadev" => false,
            "ohdev" => true,
            other => {
                return Err(value_error(format!(
                    "stat={other:?}: the streaming engine computes \"oadev\" and \"ohdev\""
                )))
            }
        };
        let rows = guarded("Stream.table", || {
            let levels: Vec<_> = self.engine.levels().collect();
            Ok(allan::batch::stream_rows(
                &levels, self.tau0, self.scale, hadamard,
            ))
        })?;
        let out = crate::dev::rows_dict(py, &rows)?;
        let stride = rows
            .iter()
            .map(|r| match r.estimator {
                allan::batch::Estimator::Stride { stride } => stride,
                allan::batch::Estimator::Exact => 1,
            })
            .collect::<Vec<u64>>();
        out.set_item("stride", stride.into_pyarray(py))?;
        Ok(out)
    }
}
