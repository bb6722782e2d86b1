//! The device link (`imu_link`, what `imu-lab record` and `imu-lab device` use) from Python: a
//! Pico running the firmware over its USB serial port, or the emulator over `tcp:HOST:PORT`.
//!
//! The protocol, the rows of a recording, the tables' rows and the calibration checks are the
//! crates' (`imu_link::device`, `imu_link::record`, `imu_cal::file::upload_blob`); this file
//! only converts. The GIL is released while the device is waited for; a recording checks for
//! Python signals (Ctrl-C) every [`SIGNAL_CHECK`]. Errors: `ValueError` for a bad argument or a
//! calibration refused (by the host's checks before anything is sent, or by the device),
//! `TimeoutError` when the device does not answer, `OSError` for any other failure of the port;
//! each names the port.
use std::collections::HashMap;
use std::fs::File;
use std::io::BufWriter;
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant};

use imu_link::device::{self, CalibrationRefused};
use imu_link::record::{self, Recorder, Row, COLUMNS};
use imu_link::{Link, NoReply};
use imu_proto::csv::{may_be_empty, timing, unit, GAP_BEFORE};
use imu_proto::{CalSource, Identity, OrientationConfig, SensorState, Status, StreamMode};
use numpy::{IntoPyArray, PyReadonlyArray1};
use pyo3::exceptions::{PyOSError, PyTimeoutError};
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict, PyList};

use crate::{guarded, value_error};

/// How often a recording gives Python the chance to raise `KeyboardInterrupt`.
const SIGNAL_CHECK: Duration = Duration::from_millis(100);

/// An open link to a device. Its methods release the GIL while they wait; one call at a time
/// (a second thread waits for the first).
#[pyclass(module = "pico_imu._native")]
pub struct NativeDevice {
    port: String,
    link: Mutex<Option<Link>>,
    identity: Identity,
    /// Rejected-frame summaries not yet handed to Python.
    warnings: Arc<Mutex<Vec<String>>>,
}

/// A failure of the link to `port` as the Python exception for it.
fn link_error(port: &str, e: anyhow::Error) -> PyErr {
    if let Some(r) = e.downcast_ref::<CalibrationRefused>() {
        return value_error(format!("{port}: {r}; the calibration in use is unchanged"));
    }
    let msg = format!("{port}: {e:#}");
    if e.downcast_ref::<NoReply>().is_some() {
        PyTimeoutError::new_err(msg)
    } else {
        PyOSError::new_err(msg)
    }
}

/// `port` checked for its form: a serial device path, or `tcp:HOST:PORT` with a port number.
fn check_port(port: &str) -> PyResult<()> {
    if port.trim().is_empty() {
        return Err(value_error(
            "port: empty; give a serial device (e.g. /dev/ttyACM0) or tcp:HOST:PORT",
        ));
    }
    if let Some(addr) = port.strip_prefix("tcp:") {
        let ok = addr
            .rsplit_once(':')
            .is_some_and(|(host, p)| !host.is_empty() && p.parse::<u16>().is_ok_and(|p| p > 0));
        if !ok {
            return Err(value_error(format!(
                "port={port:?}: expected tcp:HOST:PORT with a port number 1–65535 (e.g. tcp:127.0.0.1:5000)"
            )));
        }
    }
    Ok(())
}

/// A positive finite number of seconds named `what`.
fn seconds_of(what: &str, s: f64) -> PyResult<Duration> {
    if s > 0.0 && s.is_finite() && s < 1e9 {
        Ok(Duration::from_secs_f64(s))
    } else {
        Err(value_error(format!(
            "{what}={}: a positive number of seconds below 1e9",
            crate::dev::short_num(s)
        )))
    }
}

fn sensor_state(s: SensorState) -> &'static str {
    match s {
        SensorState::Unknown => "unknown",
        SensorState::Ok => "ok",
        SensorState::Missing => "missing",
        SensorState::Stalled => "stalled",
    }
}

fn mode_name(m: StreamMode) -> &'static str {
    match m {
        StreamMode::Off => "off",
        StreamMode::Calibrated => "calibrated",
        StreamMode::Raw => "raw",
    }
}

/// The device's counters as a dict, every key with its unit where it has one.
fn status_dict<'py>(py: Python<'py>, s: &Status) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("uptime_s", s.uptime_us as f64 * 1e-6)?;
    let period = |ns: u32| (ns > 0).then(|| f64::from(ns) * 1e-9);
    let imu = PyDict::new(py);
    imu.set_item("state", sensor_state(s.imu))?;
    imu.set_item("samples_taken", s.samples_taken)?;
    imu.set_item("samples_lost", s.samples_dropped)?;
    imu.set_item("fifo_overflows", s.fifo_overflows)?;
    imu.set_item("period_s", period(s.imu_period_ns))?;
    d.set_item("imu", imu)?;
    let mag = PyDict::new(py);
    mag.set_item("state", sensor_state(s.mag))?;
    mag.set_item("samples_taken", s.mag_samples)?;
    mag.set_item("samples_lost", s.mag_dropped)?;
    mag.set_item("period_s", period(s.mag_period_ns))?;
    d.set_item("mag", mag)?;
    d.set_item("i2c_errors", s.i2c_errors)?;
    d.set_item("bus_faults", s.bus_faults)?;
    d.set_item("bus_recoveries", s.bus_recoveries)?;
    d.set_item("host_frames_rejected", s.frames_rejected)?;
    d.set_item("frames_unsent", s.frames_unsent)?;
    d.set_item("cpu_load_percent", f64::from(s.cpu_load_permille) / 10.0)?;
    d.set_item(
        "temperature_c",
        s.temp_milli_c.map(|t| f64::from(t) / 1000.0),
    )?;
    d.set_item("calibration", device::format_cal(&s.cal))?;
    d.set_item("mode", mode_name(s.mode))?;
    Ok(d)
}

fn identity_dict<'py>(py: Python<'py>, id: &Identity) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("protocol", id.protocol)?;
    d.set_item("firmware", id.firmware.as_str())?;
    d.set_item("board", id.board.as_str())?;
    d.set_item("imu_rate_hz", id.imu_rate_hz)?;
    d.set_item("mag_rate_hz", id.mag_rate_hz)?;
    d.set_item("allan_overlap", id.allan_overlap)?;
    d.set_item("allan_levels", id.allan_levels)?;
    d.set_item("allan_levels_mag", id.allan_levels_mag)?;
    Ok(d)
}

fn orientation_dict<'py>(py: Python<'py>, c: &OrientationConfig) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("declination_deg", f64::from(c.declination_cdeg) * 0.01)?;
    d.set_item(
        "field_ut",
        c.reference.map(|r| f64::from(r.field_nt) * 1e-3),
    )?;
    d.set_item("dip_deg", c.reference.map(|r| f64::from(r.dip_cdeg) * 0.01))?;
    d.set_item("learnt", c.learnt)?;
    Ok(d)
}

/// The calibration in use: the blob, where it came from, and its corrections as numbers.
fn calibration_dict<'py>(
    py: Python<'py>,
    blob: &[u8],
    status: &imu_proto::CalStatus,
) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("blob", PyBytes::new(py, blob))?;
    d.set_item(
        "source",
        match status.source {
            CalSource::Identity => "identity",
            CalSource::Flash => "flash",
            CalSource::Host => "host",
        },
    )?;
    d.set_item("status", device::format_cal(status))?;
    let cal = imu_cal::device::decode_blob(blob)
        .map_err(|e| PyOSError::new_err(format!("the device sent an invalid blob: {e}")))?;
    let fitted = PyDict::new(py);
    match cal.fitted_for() {
        None => d.set_item("fitted_for", py.None())?,
        Some(f) => {
            fitted.set_item("imu", f.imu.name())?;
            fitted.set_item("mag", f.mag.name())?;
            fitted.set_item("accel_range_g", f.ranges.accel_g)?;
            fitted.set_item("gyro_range_dps", f.ranges.gyro_dps)?;
            fitted.set_item("mag_range_gauss", f.ranges.mag_gauss())?;
            d.set_item("fitted_for", fitted)?;
        }
    }
    let affine = |a: &imu_cal::device::Affine| -> PyResult<Bound<'py, PyDict>> {
        let x = PyDict::new(py);
        x.set_item("matrix", a.matrix().map(|r| r.to_vec()).to_vec())?;
        x.set_item("offset_lsb", a.folded_offset().to_vec())?;
        Ok(x)
    };
    d.set_item("accel", affine(cal.accel())?)?;
    let gyro = affine(cal.gyro().affine())?;
    gyro.set_item("kappa", cal.gyro().kappa().to_vec())?;
    gyro.set_item("t_ref_lsb", cal.gyro().t_ref())?;
    d.set_item("gyro", gyro)?;
    d.set_item("mag", affine(cal.mag())?)?;
    Ok(d)
}

impl NativeDevice {
    /// The open link, or an `OSError` after `close()`.
    fn lock(&self) -> PyResult<MutexGuard<'_, Option<Link>>> {
        let g = self
            .link
            .lock()
            .map_err(|_| PyOSError::new_err(format!("{}: the link is broken", self.port)))?;
        if g.is_none() {
            return Err(PyOSError::new_err(format!(
                "{}: the device was closed",
                self.port
            )));
        }
        Ok(g)
    }

    /// Runs `f` on the link without the GIL, a failure named with the port.
    fn with_link<T: Send>(
        &self,
        py: Python<'_>,
        what: &str,
        f: impl FnOnce(&mut Link) -> anyhow::Result<T> + Send,
    ) -> PyResult<T> {
        let mut g = self.lock()?;
        let port = &self.port;
        let link = g.as_mut().expect("checked open");
        py.detach(|| guarded(what, || f(link).map_err(|e| link_error(port, e))))
    }

    /// Sends the checked blob, then reads the calibration back: it must be the one sent.
    fn send_blob<'py>(
        &self,
        py: Python<'py>,
        blob: Vec<u8>,
        persist: bool,
    ) -> PyResult<Bound<'py, PyDict>> {
        let (back, status) = self.with_link(py, "Device.upload", |link| {
            device::upload_calibration(link, &blob, persist)?;
            device::calibration(link)
        })?;
        if back != blob {
            return Err(PyOSError::new_err(format!(
                "{}: the device answered Ok but reports another calibration ({} B) than the one sent ({} B)",
                self.port,
                back.len(),
                blob.len()
            )));
        }
        calibration_dict(py, &back, &status)
    }
}

#[pymethods]
impl NativeDevice {
    /// Opens `port` (a serial device, or `tcp:HOST:PORT`), sets the reply timeout (s) and asks
    /// the device who it is.
    #[new]
    #[pyo3(signature = (port, timeout=3.0))]
    fn new(py: Python<'_>, port: String, timeout: f64) -> PyResult<Self> {
        check_port(&port)?;
        let timeout = seconds_of("timeout", timeout)?;
        let warnings = Arc::new(Mutex::new(Vec::new()));
        let sink = warnings.clone();
        let (link, identity) = py.detach(|| {
            guarded("Device", || {
                let mut link = Link::open_with(&port, move |w| {
                    if let Ok(mut v) = sink.lock() {
                        v.push(w);
                    }
                })
                .map_err(|e| link_error(&port, e))?;
                link.set_reply_timeout(timeout);
                let id = device::identify(&mut link).map_err(|e| link_error(&port, e))?;
                Ok((link, id))
            })
        })?;
        Ok(NativeDevice {
            port,
            link: Mutex::new(Some(link)),
            identity,
            warnings,
        })
    }

    /// The port given when opening.
    #[getter]
    fn port(&self) -> &str {
        &self.port
    }

    /// Whether `close()` was called.
    #[getter]
    fn closed(&self) -> bool {
        self.link.lock().map(|g| g.is_none()).unwrap_or(true)
    }

    /// Closes the link (idempotent).
    fn close(&self) {
        if let Ok(mut g) = self.link.lock() {
            g.take();
        }
    }

    /// Requests written to the device since opening.
    #[getter]
    fn requests_sent(&self) -> PyResult<u64> {
        Ok(self.lock()?.as_ref().map_or(0, Link::requests_sent))
    }

    /// Frames from the device skipped as corrupt or unknown since opening.
    #[getter]
    fn frames_rejected(&self) -> PyResult<u64> {
        Ok(self
            .lock()?
            .as_ref()
            .map_or(0, |l| u64::from(l.rx_stats().rejected())))
    }

    /// The rejected-frame summaries since the last call (for `warnings.warn`).
    fn take_warnings(&self) -> Vec<String> {
        self.warnings
            .lock()
            .map(|mut v| std::mem::take(&mut *v))
            .unwrap_or_default()
    }

    /// Who the device is, as it answered when opened.
    fn identity<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        identity_dict(py, &self.identity)
    }

    /// The device's counters and health now.
    fn status<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let s = self.with_link(py, "Device.status", device::status)?;
        status_dict(py, &s)
    }

    /// Records `seconds` of device time (`raw`: uncorrected counts): a dict with `columns`
    /// (the CSV's names, in order), `data` (name → float array, NaN where the device had no
    /// value), the accounts and the device's counters after the recording.
    #[pyo3(signature = (seconds, raw=false))]
    fn record<'py>(
        &self,
        py: Python<'py>,
        seconds: f64,
        raw: bool,
    ) -> PyResult<Bound<'py, PyDict>> {
        seconds_of("seconds", seconds)?;
        let mut g = self.lock()?;
        let port = self.port.as_str();
        let link = g.as_mut().expect("checked open");
        let mut cols: Vec<Vec<f64>> = vec![Vec::new(); COLUMNS.len()];
        let mut rec = py.detach(|| {
            guarded("Device.record", || {
                Recorder::start(link, raw).map_err(|e| link_error(port, e))
            })
        })?;
        let push = |cols: &mut Vec<Vec<f64>>, r: &Row| {
            for (c, v) in cols.iter_mut().zip(r.fields()) {
                c.push(v.unwrap_or(f64::NAN));
            }
        };
        loop {
            let step = py.detach(|| {
                guarded("Device.record", || {
                    let until = Instant::now() + SIGNAL_CHECK;
                    while rec.span() < seconds && Instant::now() < until {
                        let left = until.saturating_duration_since(Instant::now());
                        rec.poll(link, left, |r| push(&mut cols, r), |_| {})
                            .map_err(|e| link_error(port, e))?;
                    }
                    Ok(rec.span() >= seconds)
                })
            });
            let stop = match step {
                Ok(done) => {
                    if done {
                        break;
                    }
                    py.check_signals().err()
                }
                Err(e) => Some(e),
            };
            if let Some(e) = stop {
                // Ctrl-C or a failure: the stream is switched off before the exception leaves.
                py.detach(|| rec.finish(link, |_| {}));
                return Err(e);
            }
        }
        let done = py.detach(|| rec.finish(link, |r| push(&mut cols, r)));
        let n = cols[0].len();
        let tm = if n >= 2 {
            let gaps = &cols[COLUMNS
                .iter()
                .position(|c| *c == GAP_BEFORE)
                .expect("a column")];
            Some(timing(&cols[0], Some(gaps)).map_err(|e| {
                PyOSError::new_err(format!("{port}: the device's time stamps: {e}"))
            })?)
        } else {
            None
        };
        let out = PyDict::new(py);
        out.set_item("names", COLUMNS.to_vec())?;
        out.set_item("t", cols[0].clone().into_pyarray(py))?;
        let data = PyDict::new(py);
        let units = PyDict::new(py);
        for (name, c) in COLUMNS.iter().zip(cols) {
            units.set_item(name, unit(name).unwrap_or(""))?;
            data.set_item(name, c.into_pyarray(py))?;
        }
        out.set_item("columns", data)?;
        out.set_item("units", units)?;
        crate::record::set_timing(py, &out, tm.as_ref(), n)?;
        out.set_item("summary", record::summary(&done.rows, &done.losses))?;
        out.set_item("span_s", done.rows.span())?;
        out.set_item("before_mag", done.rows.before_mag)?;
        let losses = PyDict::new(py);
        for (name, device_losses, missing, received) in [
            ("imu", &done.losses.imu, done.rows.missing, done.rows.rows),
            (
                "mag",
                &done.losses.mag,
                done.rows.mag_missing,
                done.rows.mag_received,
            ),
        ] {
            let on_device: u64 = device_losses.values().sum();
            let lost = missing.max(on_device);
            let d = PyDict::new(py);
            d.set_item("received", received)?;
            d.set_item("lost", lost)?;
            let causes = PyDict::new(py);
            for (c, n) in device_losses {
                causes.set_item(c, n)?;
            }
            d.set_item("causes", causes)?;
            d.set_item("link", missing.saturating_sub(on_device))?;
            losses.set_item(name, d)?;
        }
        out.set_item("losses", losses)?;
        let events = PyList::empty(py);
        for e in &done.events {
            events.append(format!("{e:?}"))?;
        }
        out.set_item("events", events)?;
        match &done.status {
            Some(s) => out.set_item("device_status", status_dict(py, s)?)?,
            None => out.set_item("device_status", py.None())?,
        }
        Ok(out)
    }

    /// The device's Allan tables of one snapshot, for `channels` (names; all ten when empty),
    /// waiting at most `timeout` s for them: a list of dicts, one per channel.
    #[pyo3(signature = (channels=Vec::new(), timeout=30.0))]
    fn tables<'py>(
        &self,
        py: Python<'py>,
        channels: Vec<String>,
        timeout: f64,
    ) -> PyResult<Bound<'py, PyList>> {
        let wanted =
            device::channels(&channels).map_err(|e| value_error(format!("channels: {e}")))?;
        let wait = seconds_of("timeout", timeout)?;
        let got = self.with_link(py, "Device.tables", |link| {
            device::fetch_tables(link, &wanted, wait)
        })?;
        let out = PyList::empty(py);
        for t in got.values() {
            let rows = device::table_rows(t);
            let d = PyDict::new(py);
            d.set_item("channel", t.channel.name())?;
            d.set_item("unit", t.channel.unit())?;
            d.set_item("snapshot", t.snapshot)?;
            d.set_item("t_s", t.t_us as f64 * 1e-6)?;
            d.set_item("tau0_s", f64::from(t.tau0_ns) * 1e-9)?;
            d.set_item("scale", f64::from(t.scale))?;
            d.set_item("pushed", t.pushed)?;
            d.set_item("gaps", t.gaps)?;
            let col = |f: fn(&device::TableRow) -> f64| rows.iter().map(f).collect::<Vec<f64>>();
            d.set_item("tau", col(|r| r.tau).into_pyarray(py))?;
            d.set_item(
                "m",
                t.levels
                    .iter()
                    .map(|l| u64::from(l.m))
                    .collect::<Vec<u64>>()
                    .into_pyarray(py),
            )?;
            d.set_item(
                "stride",
                t.levels
                    .iter()
                    .map(|l| u64::from(l.stride))
                    .collect::<Vec<u64>>()
                    .into_pyarray(py),
            )?;
            d.set_item(
                "n",
                t.levels
                    .iter()
                    .map(|l| l.n2)
                    .collect::<Vec<u64>>()
                    .into_pyarray(py),
            )?;
            d.set_item("dev", col(|r| r.dev).into_pyarray(py))?;
            d.set_item(
                "alpha",
                rows.iter()
                    .map(|r| r.alpha)
                    .collect::<Vec<i32>>()
                    .into_pyarray(py),
            )?;
            d.set_item("edf", col(|r| r.edf).into_pyarray(py))?;
            d.set_item("lo", col(|r| r.lo).into_pyarray(py))?;
            d.set_item("hi", col(|r| r.hi).into_pyarray(py))?;
            out.append(d)?;
        }
        Ok(out)
    }

    /// Forgets the Allan state on the device.
    fn reset_allan(&self, py: Python<'_>) -> PyResult<()> {
        self.with_link(py, "Device.reset_allan", device::reset_allan)
    }

    /// The calibration in use (blob, source, corrections).
    fn calibration<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let (blob, status) = self.with_link(py, "Device.calibration", device::calibration)?;
        calibration_dict(py, &blob, &status)
    }

    /// Uploads a calibration file's `content` (TOML text, or a blob with `is_blob`) after the
    /// host's checks (`imu_cal::file::upload_blob`; a refusal is a `ValueError` and nothing is
    /// sent), then reads the calibration back. `what` names the calibration in messages.
    #[pyo3(signature = (content, is_blob, persist, what))]
    fn upload<'py>(
        &self,
        py: Python<'py>,
        content: Vec<u8>,
        is_blob: bool,
        persist: bool,
        what: &str,
    ) -> PyResult<Bound<'py, PyDict>> {
        // Closed: refused before the checks, as every other call.
        drop(self.lock()?);
        let blob = imu_cal::file::upload_blob(&content, is_blob)
            .map_err(|e| value_error(format!("{what}: {e}")))?;
        self.send_blob(py, blob, persist)
    }

    /// The attitude filter's declination and expected field.
    fn orientation<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let c = self.with_link(py, "Device.orientation", device::orientation)?;
        orientation_dict(py, &c)
    }

    /// Sets the attitude filter's declination (deg) and expected field (µT, dip deg) or asks
    /// the device to learn it; returns the settings the device then reports.
    #[pyo3(signature = (declination_deg=None, field_ut=None, dip_deg=None, learn=false))]
    fn set_orientation<'py>(
        &self,
        py: Python<'py>,
        declination_deg: Option<f64>,
        field_ut: Option<f64>,
        dip_deg: Option<f64>,
        learn: bool,
    ) -> PyResult<Bound<'py, PyDict>> {
        let field = match (field_ut, dip_deg) {
            (Some(b), Some(d)) => Some((b, d)),
            (None, None) => None,
            _ => {
                return Err(value_error(
                    "field_ut and dip_deg: give both (the expected field) or neither",
                ))
            }
        };
        // The values are checked before anything is sent (the defaults taken from the device's
        // settings below are in range).
        let unset = OrientationConfig {
            declination_cdeg: 0,
            reference: None,
            learnt: true,
        };
        device::orientation_request(&unset, declination_deg, field, learn).map_err(value_error)?;
        let current = self.with_link(py, "Device.set_orientation", device::orientation)?;
        let req = device::orientation_request(&current, declination_deg, field, learn)
            .map_err(value_error)?;
        let c = self.with_link(py, "Device.set_orientation", |link| {
            device::set_orientation(link, req)
        })?;
        orientation_dict(py, &c)
    }
}

/// Writes a recording's `columns` (name → array, NaN for an empty field) to `path` as
/// `imu-lab record` writes its CSV (`imu_link::record::csv_writer`): `t`, `gap_before` and the
/// nine sensor columns are needed; `temp` and the attitude columns may be absent (empty
/// fields).
#[pyfunction]
pub fn write_record_csv(
    py: Python<'_>,
    path: &str,
    columns: HashMap<String, PyReadonlyArray1<'_, f64>>,
) -> PyResult<()> {
    let n = columns.get("t").map_or(0, |a| a.as_array().len());
    let mut cols: Vec<Option<Vec<f64>>> = Vec::with_capacity(COLUMNS.len());
    for name in COLUMNS {
        match columns.get(name) {
            Some(a) if a.as_array().len() != n => {
                return Err(value_error(format!(
                    "column {name} has {} rows, t has {n}",
                    a.as_array().len()
                )))
            }
            Some(a) => cols.push(Some(a.as_array().to_vec())),
            None if may_be_empty(name) => cols.push(None),
            None => {
                return Err(value_error(format!(
                    "no column {name}: a device recording's CSV needs {}",
                    COLUMNS
                        .iter()
                        .filter(|c| !may_be_empty(c))
                        .copied()
                        .collect::<Vec<_>>()
                        .join(", ")
                )))
            }
        }
    }
    // Every value checked before the file is created: what the reader would refuse, or what
    // the writer would change, is refused here by column and row (was written, truncating the
    // file first, and found by the reader or not at all).
    for (name, c) in COLUMNS.iter().zip(&cols) {
        let Some(c) = c else { continue };
        let bad = |k: usize, why: &str| {
            Err(value_error(format!(
                "Recording.to_csv: column {name} row {k} = {}: {why}",
                c[k]
            )))
        };
        for k in 0..n {
            let v = c[k];
            match *name {
                "t" if !v.is_finite() => return bad(k, "not a time"),
                "t" if k > 0 && v < c[k - 1] => return bad(k, "before the row above it"),
                "gap_before" if !(v.is_nan() || (0.0..1e15).contains(&v) && v.fract() == 0.0) => {
                    return bad(k, "not a count of missing samples (a whole number ≥ 0)")
                }
                _ if v.is_infinite() => {
                    return bad(
                        k,
                        "not a value (a missing one is NaN, written as an empty field)",
                    )
                }
                _ if v.abs() > f64::from(f32::MAX) => {
                    return bad(k, "beyond the file's single precision")
                }
                _ => {}
            }
        }
    }
    let file = File::create(path).map_err(|e| PyOSError::new_err(format!("{path}: {e}")))?;
    py.detach(|| {
        guarded("Recording.to_csv", || {
            let io = |e: std::io::Error| PyOSError::new_err(format!("{path}: {e}"));
            let mut w =
                record::csv_writer(BufWriter::new(file)).map_err(|e| value_error(e.to_string()))?;
            let mut row = [None; 20];
            for k in 0..n {
                for (f, c) in row.iter_mut().zip(&cols) {
                    *f = c.as_ref().and_then(|c| c[k].is_finite().then_some(c[k]));
                }
                w.row(&row).map_err(io)?;
            }
            w.finish().map_err(io)?;
            Ok(())
        })
    })
}
