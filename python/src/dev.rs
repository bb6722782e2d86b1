//! The batch Allan-family estimators (`allan::batch`) on numpy arrays.
use allan::batch::{plain_deviations as plain, Stat, TauSet};
use allan::AllanError;
use numpy::{IntoPyArray, PyReadonlyArray1};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::{guarded, value_error};

/// The statistic named `name`, or a `ValueError` listing the seven.
pub(crate) fn stat_of(name: &str) -> PyResult<Stat> {
    Stat::parse(name).ok_or_else(|| {
        value_error(format!(
            "stat={name:?}: expected one of adev, oadev, mdev, hdev, ohdev, tdev, totdev"
        ))
    })
}

/// Whether `data_type` says phase (`"phase"`) or rate (`"freq"`).
fn is_phase(data_type: &str) -> PyResult<bool> {
    match data_type {
        "phase" => Ok(true),
        "freq" => Ok(false),
        other => Err(value_error(format!(
            "data_type={other:?}: expected \"phase\" (s) or \"freq\" (rate samples)"
        ))),
    }
}

/// The sample period 1/rate, checked.
pub(crate) fn tau0_of(rate: f64) -> PyResult<f64> {
    // A positive rate whose inverse is not finite (1e-310 Hz) is no rate either.
    if rate > 0.0 && rate.is_finite() && (1.0 / rate).is_finite() {
        Ok(1.0 / rate)
    } else {
        Err(value_error(format!(
            "rate={}: the sample rate must be a positive finite number of Hz",
            short_num(rate)
        )))
    }
}

/// `x` for a message: 6 significant digits, trailing zeros dropped (0.009999999999999787 →
/// 0.01), in scientific form beyond the ordinary sizes (`1e-310`, not 310 digits).
pub(crate) fn short_num(x: f64) -> String {
    if x != 0.0 && x.is_finite() && !(1e-4..1e16).contains(&x.abs()) {
        return format!("{x:e}");
    }
    let e = if x == 0.0 || !x.is_finite() {
        0
    } else {
        x.abs().log10().floor() as i32
    };
    let decimals = (5 - e).max(0) as usize;
    let s = format!("{x:.decimals$}");
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    }
}

/// An `AllanError` as a `ValueError` naming the argument.
pub(crate) fn allan_error(e: AllanError) -> PyErr {
    match e {
        AllanError::NotFinite { index } => value_error(format!(
            "data[{index}] is not a finite number (NaN or infinite); remove or fill it"
        )),
        AllanError::TooShort { samples, needed } => value_error(format!(
            "data has {samples} samples, at least {needed} are needed"
        )),
        AllanError::BadTau0(t) => value_error(format!(
            "sample period {t} s (the rate's inverse) is not a positive finite number"
        )),
        AllanError::BadTauSet(why) => value_error(format!("taus: {why}")),
        AllanError::Unsupported(why) => value_error(why.to_string()),
    }
}

/// The array as a contiguous slice, copying only when numpy's is strided.
pub(crate) fn contiguous<'a>(
    a: &'a PyReadonlyArray1<'_, f64>,
    owned: &'a mut Vec<f64>,
) -> &'a [f64] {
    match a.as_slice() {
        Ok(s) => s,
        Err(_) => {
            *owned = a.as_array().to_vec();
            owned
        }
    }
}

/// The table of `stat` over `data` (rate samples, or phase in s with `data_type="phase"`),
/// sampled at `rate` Hz, at the averaging factors `ms` (a list) or the named set `taus`
/// (`octave`, `decade`, `all`, `N/octave`). Returns a dict of arrays: `tau` (s), `m`, `dev`,
/// `n`, `alpha`, `edf`, `lo`, `hi` (68.3 % bounds), in the data's unit (TDEV: unit × s).
#[pyfunction]
#[pyo3(signature = (data, rate, stat, data_type="freq", taus="octave", ms=None))]
pub fn deviation<'py>(
    py: Python<'py>,
    data: PyReadonlyArray1<'py, f64>,
    rate: f64,
    stat: &str,
    data_type: &str,
    taus: &str,
    ms: Option<Vec<u64>>,
) -> PyResult<Bound<'py, PyDict>> {
    let stat = stat_of(stat)?;
    let phase = is_phase(data_type)?;
    let tau0 = tau0_of(rate)?;
    let set = match ms {
        Some(ms) => TauSet::List(ms),
        None => TauSet::parse(taus).map_err(allan_error)?,
    };
    let mut owned = Vec::new();
    let x = contiguous(&data, &mut owned);
    let rows = py.detach(|| {
        guarded("deviation", || {
            if phase {
                allan::batch::deviation_from_phase(x, tau0, stat, &set)
            } else {
                allan::batch::deviation(x, tau0, stat, &set)
            }
            .map_err(allan_error)
        })
    })?;
    if rows.is_empty() {
        // As `imu-lab adev`: an empty table would read as a result.
        return Err(value_error(format!(
            "taus: no averaging time fits the {} samples ({} needs at least two terms at each τ)",
            x.len(),
            stat.name()
        )));
    }
    rows_dict(py, &rows)
}

/// A table's rows as a dict of arrays: `tau` (s), `m`, `dev`, `n`, `alpha`, `edf`, `lo`, `hi`
/// (68.3 % bounds), as `deviation` and `Stream.table` return them.
pub(crate) fn rows_dict<'py>(py: Python<'py>, rows: &[allan::Row]) -> PyResult<Bound<'py, PyDict>> {
    let out = PyDict::new(py);
    let col = |f: fn(&allan::Row) -> f64| rows.iter().map(f).collect::<Vec<f64>>();
    out.set_item("tau", col(|r| r.tau).into_pyarray(py))?;
    let m: Vec<u64> = rows.iter().map(|r| r.m).collect();
    out.set_item("m", m.into_pyarray(py))?;
    out.set_item("dev", col(|r| r.dev).into_pyarray(py))?;
    let n: Vec<u64> = rows.iter().map(|r| r.n).collect();
    out.set_item("n", n.into_pyarray(py))?;
    let alpha: Vec<i32> = rows.iter().map(|r| r.alpha).collect();
    out.set_item("alpha", alpha.into_pyarray(py))?;
    out.set_item("edf", col(|r| r.edf).into_pyarray(py))?;
    out.set_item("lo", col(|r| r.lo).into_pyarray(py))?;
    out.set_item("hi", col(|r| r.hi).into_pyarray(py))?;
    Ok(out)
}

/// The plain estimate of `stat` at each m of `ms`: (deviations, term counts), NaN and 0 where
/// an m has no term; what AllanTools computes (`allan::batch::plain_deviations`).
#[pyfunction]
#[pyo3(signature = (data, rate, stat, data_type, ms))]
#[allow(clippy::type_complexity)]
pub fn plain_deviations<'py>(
    py: Python<'py>,
    data: PyReadonlyArray1<'py, f64>,
    rate: f64,
    stat: &str,
    data_type: &str,
    ms: Vec<u64>,
) -> PyResult<(
    Bound<'py, numpy::PyArray1<f64>>,
    Bound<'py, numpy::PyArray1<u64>>,
)> {
    let stat = stat_of(stat)?;
    let phase = is_phase(data_type)?;
    let tau0 = tau0_of(rate)?;
    let mut owned = Vec::new();
    let x = contiguous(&data, &mut owned);
    let out = py.detach(|| {
        guarded("plain_deviations", || {
            plain(x, tau0, stat, &ms, phase).map_err(allan_error)
        })
    })?;
    let (devs, ns): (Vec<f64>, Vec<u64>) = out.into_iter().unzip();
    Ok((devs.into_pyarray(py), ns.into_pyarray(py)))
}
