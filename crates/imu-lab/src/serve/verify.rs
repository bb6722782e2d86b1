//! The verification recording: after a calibration is uploaded, a short recording of the board
//! turned, made with the device streaming its raw values (`SetMode(Raw)`: the nominal
//! sensitivities, no corrections, as `imu-lab record --raw`), and the heading it gives before
//! (the raw columns, the identity) and after (the device's whole calibration after the upload,
//! applied on the host) — the heading's consistency with the gyro,
//! `imu_cal::heading::before_after`, the same function `imu-lab heading` reports without a
//! truth — and the data on the sphere ([`Magnitudes`]): |B| around the field magnitude and |a|
//! around g, before and after, with the corrected points. The rows are the stream's 0.1 s
//! windows (their means: the gyro's mean times the window is its integral), at most
//! [`MAX_ROWS`].
use axum::body::Bytes;
use axum::extract::State;
use axum::http::StatusCode;
use axum::response::{IntoResponse, Response};
use axum::Json;
use imu_cal::accel::G_STANDARD;
use imu_cal::heading::{Correction, Rms, Row};
use serde_json::{json, Value};

use super::live::{device_post, send, sync_mode, WINDOW_S};
use super::{error, Shared};

/// Most rows a verification recording keeps (10 minutes of windows).
pub const MAX_ROWS: usize = 6000;
/// Windows of the consistency check, s.
pub const CHECK_WINDOW_S: f64 = 2.0;
/// Rows beyond this pitch are left out (the heading is ill-defined near the vertical), degrees.
pub const MAX_PITCH_DEG: f64 = 70.0;
/// Windows per block of the magnitudes' rms uncertainty (1 s: consecutive windows of a turn
/// are correlated, blocks much less).
pub const SPREAD_BLOCK: usize = 10;
/// Most corrected magnetometer points the page is sent (evenly spaced over the recording).
pub const CLOUD_POINTS: usize = 2000;

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
        if snap.uploaded.is_none() {
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
    let (rec, uploaded) = {
        let mut snap = live.shared.lock().expect("snapshot");
        let Some(rec) = snap.verify.take() else {
            return error(StatusCode::CONFLICT, "not recording the verification");
        };
        let Some(uploaded) = snap.uploaded else {
            return error(
                StatusCode::CONFLICT,
                "no calibration uploaded from this page",
            );
        };
        (rec, uploaded)
    };
    let back = sync_mode(live).await;
    let rows = rec.rows;
    let seconds = rows.len() as f64 * WINDOW_S;
    let n = rows.len();
    let judged = tokio::task::spawn_blocking(move || {
        let cal = correction(&uploaded.cal);
        let heading = imu_cal::heading::before_after(&rows, &cal, CHECK_WINDOW_S, MAX_PITCH_DEG);
        (heading, Magnitudes::of(&rows, &cal, uploaded.field))
    })
    .await;
    let (heading, magnitudes) = match judged {
        Ok(x) => x,
        Err(e) => return error(StatusCode::INTERNAL_SERVER_ERROR, &e.to_string()),
    };
    let v = json!({
        "recording": false,
        "seconds": seconds,
        "windows": n,
        "check_window_s": CHECK_WINDOW_S,
        "max_pitch_deg": MAX_PITCH_DEG,
        "before": rms_json(heading.before),
        "after": rms_json(heading.after),
        "turned": rms_json(heading.turned),
        "little_turn": heading.little_turn(),
        "little_turn_deg": imu_cal::heading::LITTLE_TURN_DEG,
        "magnitudes": magnitudes.json(),
        "calibrated_again": back.as_ref().err(),
    });
    send(&live.tx, "verify", v.clone());
    Json(v).into_response()
}

/// The uploaded calibration (the device's whole one after the upload) as the host applies it
/// to raw rows: the accelerometer's matrix and offset, the magnetometer's soft and hard iron,
/// the gyro's bias (its temperature term left out: the recording is short).
pub fn correction(cal: &imu_cal::device::Calibration) -> Correction {
    let p = super::merge::physical(cal);
    Correction {
        accel: (cal.accel().matrix(), p.accel_offset),
        mag: (p.soft_iron, p.hard_iron),
        gyro_bias: p.gyro_bias,
    }
}

/// The magnitudes on the sphere before (raw) and after (corrected): the spread of |B| around
/// the field magnitude (the uploaded fit's, else the corrected points' median) and of |a|
/// around standard gravity, each an rms with its uncertainty; and the corrected magnetometer
/// points (at most [`CLOUD_POINTS`]).
pub struct Magnitudes {
    pub field: f64,
    pub field_fitted: bool,
    pub mag: (Option<Rms>, Option<Rms>),
    pub accel: (Option<Rms>, Option<Rms>),
    pub cloud: Vec<[f64; 3]>,
}

fn norm(v: [f64; 3]) -> f64 {
    (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
}

impl Magnitudes {
    pub fn of(rows: &[Row], cal: &Correction, field: Option<f64>) -> Magnitudes {
        let fixed: Vec<Row> = rows.iter().map(|r| cal.apply(r)).collect();
        let reference = field.unwrap_or_else(|| {
            let mut m: Vec<f64> = fixed.iter().map(|r| norm(r.mag)).collect();
            m.sort_by(f64::total_cmp);
            m.get(m.len() / 2).copied().unwrap_or(f64::NAN)
        });
        let spread = |rs: &[Row], pick: fn(&Row) -> [f64; 3], to: f64| {
            let e: Vec<f64> = rs.iter().map(|r| norm(pick(r)) - to).collect();
            imu_cal::heading::rms(&e, SPREAD_BLOCK)
        };
        let step = fixed.len().div_ceil(CLOUD_POINTS).max(1);
        Magnitudes {
            field: reference,
            field_fitted: field.is_some(),
            mag: (
                spread(rows, |r| r.mag, reference),
                spread(&fixed, |r| r.mag, reference),
            ),
            accel: (
                spread(rows, |r| r.accel, G_STANDARD),
                spread(&fixed, |r| r.accel, G_STANDARD),
            ),
            cloud: fixed.iter().step_by(step).map(|r| r.mag).collect(),
        }
    }

    pub fn json(&self) -> Value {
        let one = |r: Option<Rms>| match r {
            Some(r) => json!({ "rms": r.rms, "sigma": noise_model::session::num(r.sigma),
                               "max": r.max, "windows": r.n }),
            None => Value::Null,
        };
        json!({
            "field_ut": self.field,
            "field_from": if self.field_fitted { "the magnetometer fit uploaded" }
                          else { "the median |B| of the corrected points (no fit of the sphere uploaded)" },
            "mag_unit": "µT",
            "mag_before": one(self.mag.0),
            "mag_after": one(self.mag.1),
            "g": G_STANDARD,
            "accel_unit": "m/s²",
            "accel_before": one(self.accel.0),
            "accel_after": one(self.accel.1),
            "block_windows": SPREAD_BLOCK,
            "cloud": self.cloud,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Rows of a board turned through random attitudes, read by a part with hard and soft
    /// iron and an accelerometer offset: corrected with the part's own inverse, |B| sits on
    /// the field and |a| on g (the spread at the noise), raw both spread by the errors; the
    /// cloud is bounded.
    #[test]
    fn the_corrected_magnitudes_sit_on_the_sphere() {
        let key = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .unwrap()
            .as_nanos() as u64;
        let mut s = key | 1;
        let mut u = move || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            ((s >> 11) as f64 + 0.5) / (1u64 << 53) as f64
        };
        let f = 30.0 + 30.0 * u();
        // each error of either sign, at least a third of its largest
        let mut signed = |lo: f64, hi: f64| {
            let x = lo + (hi - lo) * u();
            if u() < 0.5 {
                -x
            } else {
                x
            }
        };
        let h = [signed(5.0, 20.0), signed(5.0, 20.0), signed(5.0, 20.0)];
        let o = [signed(0.1, 0.3), signed(0.1, 0.3), signed(0.1, 0.3)];
        let k = 1.0 + 0.1 * (u() - 0.5);
        let rows: Vec<Row> = (0..3000)
            .map(|i| {
                let z = 2.0 * u() - 1.0;
                let a = 2.0 * std::f64::consts::PI * u();
                let r = (1.0 - z * z).sqrt();
                let b = [f * r * a.cos(), f * r * a.sin(), f * z];
                let z2 = 2.0 * u() - 1.0;
                let a2 = 2.0 * std::f64::consts::PI * u();
                let r2 = (1.0 - z2 * z2).sqrt();
                let g = [
                    G_STANDARD * r2 * a2.cos(),
                    G_STANDARD * r2 * a2.sin(),
                    G_STANDARD * z2,
                ];
                let e = 0.05 * (u() - 0.5);
                Row {
                    t: 0.1 * i as f64,
                    // soft iron: a scale of 1/k on x (the correction multiplies by k)
                    mag: [b[0] / k + h[0] + e, b[1] + h[1] - e, b[2] + h[2]],
                    accel: [g[0] + o[0], g[1] + o[1], g[2] + o[2] + 0.1 * e],
                    gyro: [0.0; 3],
                }
            })
            .collect();
        let cal = Correction {
            accel: ([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]], o),
            mag: ([[k, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]], h),
            gyro_bias: [0.0; 3],
        };
        for field in [Some(f), None] {
            let m = Magnitudes::of(&rows, &cal, field);
            let (mb, ma) = (m.mag.0.unwrap(), m.mag.1.unwrap());
            let (ab, aa) = (m.accel.0.unwrap(), m.accel.1.unwrap());
            assert!(ma.rms < 0.05, "key {key}: after {ma:?}");
            assert!(mb.rms > 20.0 * ma.rms, "key {key}: {mb:?} → {ma:?}");
            assert!(
                aa.rms < 0.01 && ab.rms > 3.0 * aa.rms,
                "key {key}: {ab:?} → {aa:?}"
            );
            assert!(ma.sigma > 0.0 && ma.sigma < ma.rms, "key {key}: {ma:?}");
            assert!((m.field - f).abs() < 0.05, "key {key}: {} vs {f}", m.field);
            assert!(m.cloud.len() <= CLOUD_POINTS && m.cloud.len() >= CLOUD_POINTS / 2);
        }
    }
}
