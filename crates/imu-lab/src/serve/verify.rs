//! The verification recording: after a calibration is uploaded, a short recording of the board
//! turned, made with the device streaming its raw values (`SetMode(Raw)`: the nominal
//! sensitivities, no corrections, as `imu-lab record --raw`), and the heading it gives before
//! (the raw columns, the identity) and after (the uploaded calibration file applied on the host)
//! — the heading's consistency with the gyro, `imu_cal::heading::before_after`, the same
//! function `imu-lab heading` reports without a truth. The rows are the stream's 0.1 s windows
//! (their means: the gyro's mean times the window is its integral), at most [`MAX_ROWS`].
use axum::body::Bytes;
use axum::extract::State;
use axum::http::StatusCode;
use axum::response::{IntoResponse, Response};
use axum::Json;
use imu_cal::heading::{Rms, Row};
use serde_json::{json, Value};

use super::live::{device_post, send, sync_mode, WINDOW_S};
use super::{error, Shared};

/// Most rows a verification recording keeps (10 minutes of windows).
pub const MAX_ROWS: usize = 6000;
/// Windows of the consistency check, s.
pub const CHECK_WINDOW_S: f64 = 2.0;
/// Rows beyond this pitch are left out (the heading is ill-defined near the vertical), degrees.
pub const MAX_PITCH_DEG: f64 = 70.0;

/// A verification recording under way.
#[derive(Default)]
pub struct Recording {
    pub rows: Vec<Row>,
}

impl Recording {
    /// One stream window (its means); returns its progress to send once a second. Only raw
    /// windows count (those before the device's switch are calibrated; no window holds both).
    pub fn window(&mut self, p: &Value) -> Option<Value> {
        if p["raw"] != true {
            return None;
        }
        let m = |k: usize| p["mean"][k].as_f64().filter(|x| x.is_finite());
        let three = |k: usize| Some([m(k)?, m(k + 1)?, m(k + 2)?]);
        let (Some(t), Some(accel), Some(gyro), Some(mag)) =
            (p["t"].as_f64(), three(0), three(3), three(6))
        else {
            return None;
        };
        if self.rows.len() >= MAX_ROWS {
            return None;
        }
        self.rows.push(Row {
            t,
            accel,
            gyro,
            mag,
        });
        self.rows.len().is_multiple_of(10).then(|| self.state())
    }

    pub fn state(&self) -> Value {
        json!({ "recording": true, "windows": self.rows.len(), "seconds": self.rows.len() as f64 * WINDOW_S })
    }
}

fn rms_json(r: Option<Rms>) -> Value {
    match r {
        Some(r) => json!({ "rms_deg": r.rms, "sigma_deg": noise_model::session::num(r.sigma),
                           "max_deg": r.max, "windows": r.n }),
        None => Value::Null,
    }
}

/// POST /api/live/verify/start {}: switch the stream to raw values and record (after an upload
/// from this page: its calibration is the one judged).
pub async fn start(State(s): State<Shared>, bytes: Bytes) -> Response {
    let live = match device_post(&s, &bytes) {
        Ok(live) => live,
        Err(r) => return *r,
    };
    {
        let mut snap = live.shared.lock().expect("snapshot");
        if snap.cal_file.is_none() {
            return error(
                StatusCode::CONFLICT,
                "upload a calibration from this page first: the verification judges it",
            );
        }
        if snap.verify.is_some() {
            return error(StatusCode::CONFLICT, "already recording the verification");
        }
        if let Some(r) = snap.raw_refused() {
            return r;
        }
        snap.verify = Some(Recording::default());
    }
    if let Err(e) = sync_mode(live).await {
        live.shared.lock().expect("snapshot").verify = None;
        return error(StatusCode::BAD_GATEWAY, &e);
    }
    let v = Recording::default().state();
    send(&live.tx, "verify", v.clone());
    Json(v).into_response()
}

/// POST /api/live/verify/stop {}: back to calibrated values; the heading's consistency with the
/// gyro before (raw) and after (the uploaded calibration applied on the host), degrees rms
/// with their uncertainties.
pub async fn stop(State(s): State<Shared>, bytes: Bytes) -> Response {
    let live = match device_post(&s, &bytes) {
        Ok(live) => live,
        Err(r) => return *r,
    };
    let (rec, toml) = {
        let mut snap = live.shared.lock().expect("snapshot");
        let Some(rec) = snap.verify.take() else {
            return error(StatusCode::CONFLICT, "not recording the verification");
        };
        (rec, snap.cal_file.clone().unwrap_or_default())
    };
    let back = sync_mode(live).await;
    let file = match imu_cal::file::CalFile::from_toml(&toml) {
        Ok(f) => f,
        Err(e) => {
            return error(
                StatusCode::INTERNAL_SERVER_ERROR,
                &format!("the uploaded calibration: {e}"),
            )
        }
    };
    let rows = rec.rows;
    let seconds = rows.len() as f64 * WINDOW_S;
    let n = rows.len();
    let judged = tokio::task::spawn_blocking(move || {
        let cal = imu_cal::heading::Correction::of(&file);
        imu_cal::heading::before_after(&rows, &cal, CHECK_WINDOW_S, MAX_PITCH_DEG)
    })
    .await;
    let (before, after) = match judged {
        Ok(x) => x,
        Err(e) => return error(StatusCode::INTERNAL_SERVER_ERROR, &e.to_string()),
    };
    let v = json!({
        "recording": false,
        "seconds": seconds,
        "windows": n,
        "check_window_s": CHECK_WINDOW_S,
        "max_pitch_deg": MAX_PITCH_DEG,
        "before": rms_json(before),
        "after": rms_json(after),
        "calibrated_again": back.as_ref().err(),
    });
    send(&live.tx, "verify", v.clone());
    Json(v).into_response()
}
