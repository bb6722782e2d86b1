//! `pico_imu._native`: the Rust side of the `pico_imu` Python package. Thin bindings over the
//! workspace crates — the Allan engine (`allan`), the recording contract (`imu-proto`), the
//! noise lab (`noise-model`), the calibration lab (`imu-cal`) and the device link
//! (`imu-link`) — on numpy arrays. The Python package (`python/pico_imu/`) adds the
//! AllanTools-compatible signatures, the documentation and the type stubs.
//!
//! Every entry point releases the GIL while it computes, turns bad arguments into `ValueError`
//! naming the argument (and the index of a bad sample), and turns a Rust panic into a
//! `RuntimeError` instead of letting it cross into Python.
use std::panic::{catch_unwind, AssertUnwindSafe};

use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;

mod cal;
mod chunks;
mod dev;
mod device;
mod fit;
mod record;
mod stream;

/// Runs `f` (without the GIL when the caller detached), a panic becoming a `RuntimeError`.
pub(crate) fn guarded<T>(what: &str, f: impl FnOnce() -> PyResult<T>) -> PyResult<T> {
    match catch_unwind(AssertUnwindSafe(f)) {
        Ok(r) => r,
        Err(p) => {
            let msg = p
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| p.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "unknown panic".into());
            Err(PyRuntimeError::new_err(format!(
                "{what}: internal error in pico_imu ({msg}); please report it"
            )))
        }
    }
}

/// A `ValueError` with `msg`.
pub(crate) fn value_error(msg: impl Into<String>) -> PyErr {
    PyValueError::new_err(msg.into())
}

#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(dev::deviation, m)?)?;
    m.add_function(wrap_pyfunction!(dev::plain_deviations, m)?)?;
    m.add_function(wrap_pyfunction!(record::read_csv, m)?)?;
    m.add_function(wrap_pyfunction!(fit::fit, m)?)?;
    m.add_class::<fit::NativeFit>()?;
    m.add_function(wrap_pyfunction!(cal::calibrate, m)?)?;
    m.add_class::<cal::NativeCalibration>()?;
    m.add_function(wrap_pyfunction!(panic_for_test, m)?)?;
    m.add_class::<stream::Stream>()?;
    m.add_class::<chunks::CsvChunks>()?;
    m.add_class::<device::NativeDevice>()?;
    m.add_function(wrap_pyfunction!(device::write_record_csv, m)?)?;
    Ok(())
}

/// Panics inside the guard: lets the tests check that a panic arrives as a `RuntimeError`.
#[pyfunction]
fn panic_for_test() -> PyResult<()> {
    guarded("panic_for_test", || panic!("deliberate"))
}
