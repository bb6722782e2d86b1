//! The host's side of the end-to-end run: the link session that collects what the device says,
//! and the calibration round trip.
use std::fmt::Write as _;
use std::time::Duration;

use anyhow::{bail, Result};
use imu_cal::device::{
    encode_blob, Affine, Calibration, Fitted, GyroCorrection, Sensor as CalSensor,
};
use imu_proto::{Channel, Reply, Request, StreamMode, Vec as HVec};

use super::*;
use crate::emu_link::Link;

/// A calibration far enough from identity that its effect on every channel is visible, within
/// the datasheet bounds the device checks (docs/calibration.md, "Plausibility").
fn test_calibration() -> Result<Calibration> {
    let m = [[1.02, 0.01, 0.0], [0.0, 0.98, -0.02], [0.005, 0.0, 1.01]];
    // The accelerometer's model is lower-triangular (T·K).
    let lower = [[1.02, 0.0, 0.0], [0.01, 0.98, 0.0], [0.005, -0.02, 1.01]];
    let accel = Affine::from_float(CalSensor::Accel, lower, [12.0, -30.0, 250.0])
        .map_err(|e| anyhow::anyhow!("{e:?}"))?;
    let gyro = GyroCorrection::from_float(m, [-40.0, 25.0, 13.0], [0.01, -0.02, 0.0], -3000)
        .map_err(|e| anyhow::anyhow!("{e:?}"))?;
    let mag = Affine::from_float(CalSensor::Mag, m, [100.0, -200.0, 50.0])
        .map_err(|e| anyhow::anyhow!("{e:?}"))?;
    // Fitted at the ranges the firmware runs, as the host's calibration file would say.
    let s = pico_imu_core::config::scales();
    let (imu, mag_part) = pico_imu_core::config::PARTS;
    let fitted = Fitted::new(imu, mag_part, [1.0 / s.accel, 1.0 / s.gyro, 1.0 / s.mag])
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    Calibration::fitted(accel, gyro, mag, fitted).map_err(|e| anyhow::anyhow!("{e}"))
}

pub(super) fn session(port: u16, seconds: f64, calibrate: bool) -> Result<Session> {
    let long = Duration::from_secs(300);
    let mut link = Link::connect(port, Duration::from_secs(30))?;
    let id = link.request(Request::Identify, long)?;
    let Reply::Identity(ident) = id else {
        bail!("Identify answered {id:?}")
    };
    eprintln!("xtask: device: {ident:?}");
    if link.request(
        Request::SetIntervals {
            status_ms: 1000,
            tables_ms: 0,
        },
        long,
    )? != Reply::Ok
    {
        bail!("SetIntervals refused");
    }
    link.wait_until(
        Duration::from_secs(900),
        "the device's uptime to reach the end of the run",
        |g| {
            g.statuses
                .last()
                .is_some_and(|s| s.uptime_us as f64 * 1e-6 >= seconds - 1.0)
        },
    )?;
    link.got.tables.clear();
    let snapshot = match link.request(Request::GetTables, long)? {
        Reply::Tables { snapshot } => snapshot,
        other => bail!("GetTables answered {other:?}"),
    };
    link.wait_until(long, "all channel tables of the round", |g| {
        g.tables.len() == Channel::ALL.len() && g.tables.values().all(|t| t.snapshot == snapshot)
    })?;
    let tables = std::mem::take(&mut link.got.tables);
    let events = link.got.events.clone();
    let status = match link.request(Request::GetStatus, long)? {
        Reply::Status(s) => s,
        other => bail!("GetStatus answered {other:?}"),
    };
    let batches = std::mem::take(&mut link.got.batches);
    let mut s = Session {
        tables,
        snapshot,
        events,
        all_events: Vec::new(),
        batches,
        status,
        cal_batches: Vec::new(),
        cal: Calibration::identity(),
        cal_report: String::new(),
        persisted: false,
    };
    if calibrate {
        calibration_round_trip(&mut link, &mut s)?;
    }
    s.all_events = std::mem::take(&mut link.got.events);
    Ok(s)
}

/// Upload a calibration, read it back, see it applied to the streamed samples, persist it.
fn calibration_round_trip(link: &mut Link, s: &mut Session) -> Result<()> {
    let long = Duration::from_secs(300);
    let cal = test_calibration()?;
    let mut buf = [0u8; 256];
    let blob = encode_blob(&cal, &mut buf).map_err(|e| anyhow::anyhow!("{e:?}"))?;
    let hblob = HVec::from_slice(blob).map_err(|_| anyhow::anyhow!("blob too large"))?;
    let r = link.request(
        Request::SetCalibration {
            blob: hblob.clone(),
            persist: false,
        },
        long,
    )?;
    writeln!(s.cal_report, "SetCalibration → {r:?}")?;
    if r != Reply::Ok {
        bail!("SetCalibration answered {r:?}");
    }
    match link.request(Request::GetCalibration, long)? {
        Reply::Calibration { blob: b, status } => {
            writeln!(
                s.cal_report,
                "GetCalibration → {} bytes, {status:?}; equal to the upload: {}",
                b.len(),
                b == hblob
            )?;
            if b != hblob {
                bail!("the calibration read back differs from the one uploaded");
            }
        }
        other => bail!("GetCalibration answered {other:?}"),
    }
    if link.request(Request::SetMode(StreamMode::Calibrated), long)? != Reply::Ok {
        bail!("SetMode(Calibrated) refused");
    }
    link.got.batches.clear();
    if let Err(e) = link.wait_until(Duration::from_secs(90), "calibrated sample batches", |g| {
        g.batches.iter().filter(|b| b.calibrated).count() >= 10
    }) {
        writeln!(s.cal_report, "{e:#}")?;
    }
    let r = link.request(
        Request::SetCalibration {
            blob: hblob.clone(),
            persist: true,
        },
        long,
    )?;
    writeln!(s.cal_report, "SetCalibration(persist) → {r:?}")?;
    let back = link.request(Request::GetCalibration, long)?;
    s.persisted = matches!(&back, Reply::Calibration { blob: b, status } if *b == hblob && status.source == imu_proto::CalSource::Flash);
    writeln!(
        s.cal_report,
        "GetCalibration after persisting → source Flash and same blob: {}",
        s.persisted
    )?;
    s.cal_batches = link
        .got
        .batches
        .iter()
        .filter(|b| b.calibrated)
        .cloned()
        .collect();
    s.cal = cal;
    Ok(())
}
