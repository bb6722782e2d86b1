//! The accelerometer's calibration from static poses, in the live page: the user turns the
//! board to a face, asks for a capture, and holds it still; the server watches the decimated
//! stream (each 0.1 s window's mean and standard deviation, [`super::live::Window`]) and
//! captures the pose once the board has been still for [`HOLD_S`], with its mean and the
//! mean's σ per axis. Then the calibration lab's six-pose fit (`imu_cal::accel`, the walk of
//! `imu-lab calibrate accel --auto`) on the captured means, and the upload shared with the
//! magnetometer wizard.
//!
//! The poses are raw values (the nominal sensitivities, no corrections: what the calibration
//! applies to): the first capture switches the device to raw values, and it stays so until Fit,
//! Clear or Stop capturing; only raw windows are judged and captured (a switch starts the
//! stillness over).
//!
//! Still means, over the last [`STILL_WINDOWS`] windows (0.5 s): the accelerometer's variance
//! and the gyro's (pooled over the windows, summed over the three axes) within [`NOISE_K`]
//! times the noise's, and the gyro's mean rate under [`TURN_DPS`] (a turn at a constant rate
//! about the vertical leaves both variances at the noise). The noise is the device's own: the
//! Allan deviation at its shortest τ of each axis, from the tables it sends (for white noise it
//! is the sample's σ; a low-pass filter lowers it below the sample's σ, by up to a factor 2 in
//! σ for the MPU-6050's filters, which `NOISE_K` = 9 in variance leaves room for).
//!
//! Warnings: two poses whose gravity directions are within [`MERGE_DEG`] are the same
//! orientation captured twice (they add nothing but weight: merge them, or remove one); a face
//! of the six (±x, ±y, ±z up, within [`FACE_DEG`]) that no pose holds is missing (the fit can
//! still run on tilted poses, but a face pins each axis's scale best).
use std::collections::VecDeque;

use axum::body::Bytes;
use axum::extract::State;
use axum::http::StatusCode;
use axum::response::{IntoResponse, Response};
use axum::Json;
use serde::{Deserialize, Serialize};
use serde_json::{json, Value};

use super::live::{device, device_post, empty, send, WINDOW_S};
use super::{error, Shared};

/// Windows over which stillness is judged (0.5 s).
pub const STILL_WINDOWS: usize = 5;
/// Still time a capture takes, s of device time.
pub const HOLD_S: f64 = 1.0;
/// Stillness: variance within this many times the noise's (sum over the axes).
pub const NOISE_K: f64 = 9.0;
/// Stillness: the gyro's mean rate below this, deg/s.
pub const TURN_DPS: f64 = 5.0;
/// Two poses with gravity directions closer than this are the same orientation, degrees.
pub const MERGE_DEG: f64 = 20.0;
/// A pose within this of an axis holds that face, degrees.
pub const FACE_DEG: f64 = 30.0;
/// Most poses kept.
pub const MAX_POSES: usize = 30;

/// Windows a capture takes.
fn hold_windows() -> usize {
    (HOLD_S / WINDOW_S).round() as usize
}

/// One stream window's accelerometer and gyro: mean and variance per axis, samples.
#[derive(Clone, Copy, Debug)]
pub struct Win {
    pub t: f64,
    /// Raw values (the device's corrections off), not calibrated ones.
    pub raw: bool,
    pub n: f64,
    pub a: [f64; 3],
    pub a_var: [f64; 3],
    pub g: [f64; 3],
    pub g_var: [f64; 3],
}

impl Win {
    /// From a stream point (`mean`/`sd` per channel, ax…gz first); `None` when a value is
    /// missing.
    pub fn from_point(p: &Value) -> Option<Win> {
        let v = |key: &str, k: usize| p[key][k].as_f64().filter(|x| x.is_finite());
        let three = |key: &str, first: usize| -> Option<[f64; 3]> {
            Some([v(key, first)?, v(key, first + 1)?, v(key, first + 2)?])
        };
        Some(Win {
            t: p["t"].as_f64()?,
            raw: p["raw"] == true,
            n: p["n"].as_f64()?,
            a: three("mean", 0)?,
            a_var: three("sd", 0)?.map(|s| s * s),
            g: three("mean", 3)?,
            g_var: three("sd", 3)?.map(|s| s * s),
        })
    }
}

/// The noise the stillness is judged against: the sum over the axes of σ², accelerometer
/// ((m/s²)²) and gyro ((deg/s)²).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Noise {
    pub accel: f64,
    pub gyro: f64,
}

/// The noise from the device's tables (the `tables` event: each channel's rows): the Allan
/// deviation at the shortest τ of ax, ay, az and gx, gy, gz; `None` until every one is there
/// and positive.
pub fn noise_from_tables(tables: &Value) -> Option<Noise> {
    let list = tables["tables"].as_array()?;
    let sigma0 = |name: &str| -> Option<f64> {
        let t = list.iter().find(|t| t["channel"] == name)?;
        let rows = t["rows"].as_array()?;
        let r = rows
            .iter()
            .filter(|r| r["dev"].as_f64().is_some_and(|d| d > 0.0))
            .min_by(|a, b| {
                let tau = |r: &Value| r["tau_s"].as_f64().unwrap_or(f64::INFINITY);
                tau(a).total_cmp(&tau(b))
            })?;
        r["dev"].as_f64()
    };
    let sum = |names: [&str; 3]| -> Option<f64> {
        names
            .iter()
            .map(|n| sigma0(n).map(|s| s * s))
            .sum::<Option<f64>>()
    };
    Some(Noise {
        accel: sum(["ax", "ay", "az"])?,
        gyro: sum(["gx", "gy", "gz"])?,
    })
}

/// Mean and pooled variance per axis of windows (weighted by their samples): the variance
/// within the windows plus that of their means.
fn pooled(ws: &[Win], pick: impl Fn(&Win) -> ([f64; 3], [f64; 3])) -> ([f64; 3], [f64; 3]) {
    let n: f64 = ws.iter().map(|w| w.n).sum();
    let mut mean = [0.0; 3];
    let mut var = [0.0; 3];
    for w in ws {
        let (m, v) = pick(w);
        for k in 0..3 {
            mean[k] += w.n * m[k] / n;
            var[k] += w.n * v[k] / n;
        }
    }
    for w in ws {
        let (m, _) = pick(w);
        for k in 0..3 {
            var[k] += w.n * (m[k] - mean[k]).powi(2) / n;
        }
    }
    (mean, var)
}

/// A captured pose: the accelerometer's mean (m/s²), its σ per axis, how long and how many
/// samples it took, and the radial difference of its two halves' means (the calibration lab's
/// noise floor, `imu_cal::accel::Pose::half_diff`).
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct Captured {
    pub mean: [f64; 3],
    pub sigma: [f64; 3],
    pub seconds: f64,
    pub samples: f64,
    pub half_diff: f64,
    /// Device time of its first window, s.
    pub t: f64,
}

impl Captured {
    /// From the windows of a still run (at least two).
    pub fn from_windows(ws: &[Win]) -> Captured {
        let (mean, _) = pooled(ws, |w| (w.a, w.a_var));
        // the mean's σ from the scatter of the window means: it counts the noise's correlation
        // beyond a window (a low-pass filter), which the samples' σ/√n would not
        let k = ws.len() as f64;
        let sigma = [0, 1, 2].map(|j| {
            let s2 = ws.iter().map(|w| (w.a[j] - mean[j]).powi(2)).sum::<f64>() / (k - 1.0);
            (s2 / k).sqrt()
        });
        let half = ws.len() / 2;
        let (m1, _) = pooled(&ws[..half], |w| (w.a, w.a_var));
        let (m2, _) = pooled(&ws[half..], |w| (w.a, w.a_var));
        let norm = mean.iter().map(|x| x * x).sum::<f64>().sqrt();
        let half_diff = (0..3).map(|j| (m1[j] - m2[j]) * mean[j]).sum::<f64>() / norm;
        Captured {
            mean,
            sigma,
            seconds: k * WINDOW_S,
            samples: ws.iter().map(|w| w.n).sum(),
            half_diff,
            t: ws[0].t,
        }
    }

    /// Two captures of one orientation as one pose: the means weighted by their samples.
    pub fn merge(&self, o: &Captured) -> Captured {
        let (a, b) = (self.samples, o.samples);
        let w = |x: f64, y: f64| (a * x + b * y) / (a + b);
        let q = |x: f64, y: f64| ((a * x).powi(2) + (b * y).powi(2)).sqrt() / (a + b);
        Captured {
            mean: [0, 1, 2].map(|k| w(self.mean[k], o.mean[k])),
            sigma: [0, 1, 2].map(|k| q(self.sigma[k], o.sigma[k])),
            seconds: self.seconds + o.seconds,
            samples: a + b,
            half_diff: q(self.half_diff, o.half_diff),
            t: self.t.min(o.t),
        }
    }

    /// The face it holds (`+z`: gravity's reaction along +z, the board lying level), or
    /// `tilted`.
    pub fn face(&self) -> &'static str {
        let norm = self.mean.iter().map(|x| x * x).sum::<f64>().sqrt();
        let k = (0..3)
            .max_by(|&i, &j| self.mean[i].abs().total_cmp(&self.mean[j].abs()))
            .unwrap_or(2);
        let cos = self.mean[k].abs() / norm;
        if cos.is_nan() || cos < FACE_DEG.to_radians().cos() {
            return "tilted";
        }
        FACES[2 * k + usize::from(self.mean[k] < 0.0)]
    }
}

/// The six faces, in the order the page lists them.
pub const FACES: [&str; 6] = ["+x", "-x", "+y", "-y", "+z", "-z"];

/// The angle between two poses' gravity directions, degrees.
pub fn angle_deg(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    let dot: f64 = (0..3).map(|k| a[k] * b[k]).sum();
    let na = a.iter().map(|x| x * x).sum::<f64>().sqrt();
    let nb = b.iter().map(|x| x * x).sum::<f64>().sqrt();
    (dot / (na * nb)).clamp(-1.0, 1.0).acos().to_degrees()
}

/// The wizard's state: the poses, a capture under way, the stillness of the last windows.
#[derive(Default)]
pub struct Wizard {
    /// A capture is wanted: the next still run of [`HOLD_S`] becomes a pose.
    pub armed: bool,
    /// Capture every hold: after each pose, the next still run that follows a motion (one pose
    /// a hold), until stopped.
    pub continuous: bool,
    /// The board has moved since the last pose (continuous captures wait for it).
    moved: bool,
    /// The wizard has the device stream raw values (from the first capture until Fit, Clear or
    /// Stop capturing).
    pub raw: bool,
    recent: VecDeque<Win>,
    run: Vec<Win>,
    pub poses: Vec<Captured>,
    /// The last stillness verdict (`None`: not judged yet, no noise known).
    still: Option<bool>,
    /// The last window's ratios: accelerometer and gyro variance over the noise's, gyro rate.
    ratios: Option<[f64; 3]>,
    noise: Option<Noise>,
}

impl Wizard {
    /// One stream window. Returns the state to send when the page should hear of it (a capture
    /// under way, the stillness changing, a pose captured).
    pub fn window(&mut self, w: Win, noise: Option<Noise>) -> Option<Value> {
        self.noise = noise;
        // raw and calibrated windows are never judged or captured together
        if self.recent.back().is_some_and(|r| r.raw != w.raw) {
            self.recent.clear();
            self.run.clear();
        }
        self.recent.push_back(w);
        while self.recent.len() > STILL_WINDOWS {
            self.recent.pop_front();
        }
        let before = self.still;
        self.still = None;
        self.ratios = None;
        if let (Some(noise), true) = (noise, self.recent.len() == STILL_WINDOWS) {
            let ws: Vec<Win> = self.recent.iter().copied().collect();
            let (_, av) = pooled(&ws, |w| (w.a, w.a_var));
            let (gm, gv) = pooled(&ws, |w| (w.g, w.g_var));
            let ra = av.iter().sum::<f64>() / noise.accel;
            let rg = gv.iter().sum::<f64>() / noise.gyro;
            let rate = gm.iter().map(|x| x * x).sum::<f64>().sqrt();
            self.ratios = Some([ra, rg, rate]);
            self.still = Some(ra <= NOISE_K && rg <= NOISE_K && rate <= TURN_DPS);
        }
        // the current still stretch, its last HOLD_S at most
        if self.still == Some(true) {
            self.run.push(w);
            let keep = hold_windows();
            if self.run.len() > keep {
                self.run.drain(..self.run.len() - keep);
            }
        } else {
            self.run.clear();
        }
        if self.still == Some(false) {
            self.moved = true;
        }
        let captured = self.try_capture();
        (self.armed || captured || before != self.still).then(|| self.state())
    }

    /// Ask for a capture — the current still hold once it has lasted [`HOLD_S`] (at once
    /// when it has), and with `continuous` one at every hold after it, each after a motion — or
    /// cancel (`on` false).
    pub fn arm(&mut self, on: bool, continuous: bool) -> Result<(), String> {
        if on && self.poses.len() >= MAX_POSES {
            return Err(format!(
                "{MAX_POSES} poses already: remove or merge some first"
            ));
        }
        self.armed = on;
        self.continuous = on && continuous;
        // the first capture takes the hold the board is in, moved or not
        self.moved = true;
        self.try_capture();
        Ok(())
    }

    /// Capture the current still stretch's last [`HOLD_S`] when armed, it is that long, of raw
    /// values, and (continuous captures) the board has moved since the last pose.
    fn try_capture(&mut self) -> bool {
        if !self.armed
            || !self.moved
            || self.run.len() < hold_windows()
            || !self.run.iter().all(|w| w.raw)
        {
            return false;
        }
        self.poses.push(Captured::from_windows(&self.run));
        self.moved = false;
        self.armed = self.continuous && self.poses.len() < MAX_POSES;
        self.continuous = self.armed;
        true
    }

    /// Merge pose `b` into pose `a` (indices from 0).
    pub fn merge(&mut self, a: usize, b: usize) -> Result<(), String> {
        let n = self.poses.len();
        if a == b || a >= n || b >= n {
            return Err(format!(
                "merge {a} and {b}: two different poses of the {n} captured (numbered from 0)"
            ));
        }
        let m = self.poses[a].merge(&self.poses[b]);
        self.poses[a] = m;
        self.poses.remove(b);
        Ok(())
    }

    pub fn remove(&mut self, i: usize) -> Result<(), String> {
        if i >= self.poses.len() {
            return Err(format!(
                "remove {i}: no such pose ({} captured, numbered from 0)",
                self.poses.len()
            ));
        }
        self.poses.remove(i);
        Ok(())
    }

    /// Pairs of poses of the same orientation: (a, b, angle in degrees).
    pub fn same_orientation(&self) -> Vec<(usize, usize, f64)> {
        let mut v = Vec::new();
        for a in 0..self.poses.len() {
            for b in a + 1..self.poses.len() {
                let d = angle_deg(&self.poses[a].mean, &self.poses[b].mean);
                if d < MERGE_DEG {
                    v.push((a, b, d));
                }
            }
        }
        v
    }

    /// The faces no pose holds.
    pub fn missing_faces(&self) -> Vec<&'static str> {
        FACES
            .iter()
            .copied()
            .filter(|f| !self.poses.iter().any(|p| p.face() == *f))
            .collect()
    }

    /// Everything the page shows.
    pub fn state(&self) -> Value {
        let progress = if self.moved {
            (self.run.len() as f64 / hold_windows() as f64).min(1.0)
        } else {
            0.0
        };
        json!({
            "armed": self.armed,
            "raw": self.raw,
            "continuous": self.continuous,
            "waiting_for_motion": self.armed && self.continuous && !self.moved,
            "still": self.still,
            "progress": progress,
            "accel_ratio": self.ratios.map(|r| r[0]),
            "gyro_ratio": self.ratios.map(|r| r[1]),
            "gyro_rate_dps": self.ratios.map(|r| r[2]),
            "noise": self.noise.map(|n| json!({
                "accel_sigma": (n.accel / 3.0).sqrt(), "accel_unit": "m/s²",
                "gyro_sigma": (n.gyro / 3.0).sqrt(), "gyro_unit": "deg/s",
            })),
            "rules": {
                "window_s": STILL_WINDOWS as f64 * WINDOW_S, "hold_s": HOLD_S,
                "noise_k": NOISE_K, "turn_dps": TURN_DPS, "merge_deg": MERGE_DEG,
            },
            "poses": self.poses.iter().map(|p| {
                let norm = p.mean.iter().map(|x| x * x).sum::<f64>().sqrt();
                json!({ "mean": p.mean, "sigma": p.sigma, "unit": "m/s²", "norm": norm,
                        "seconds": p.seconds, "samples": p.samples, "t": p.t, "face": p.face() })
            }).collect::<Vec<_>>(),
            "same": self.same_orientation().iter()
                .map(|(a, b, d)| json!({ "a": a, "b": b, "angle_deg": d }))
                .collect::<Vec<_>>(),
            "missing": self.missing_faces(),
        })
    }

    /// The calibration lab's problem on the poses (m/s², standard gravity).
    pub fn problem(&self) -> imu_cal::accel::AccelProblem {
        let mut at = 0usize;
        let poses = self
            .poses
            .iter()
            .map(|p| {
                let start = at;
                at += p.samples as usize;
                imu_cal::accel::Pose {
                    start,
                    end: at,
                    mean: p.mean,
                    half_diff: p.half_diff,
                }
            })
            .collect();
        imu_cal::accel::AccelProblem::new(poses, imu_cal::accel::G_STANDARD)
    }
}

// ---------- the page's requests ----------

/// Apply `f` to the wizard; its new state to the page (and every page), or the refusal (409).
fn change(s: &Shared, f: impl FnOnce(&mut Wizard) -> Result<(), String>) -> Response {
    let live = match device(s) {
        Ok(l) => l,
        Err(r) => return *r,
    };
    let mut snap = live.shared.lock().expect("snapshot");
    if let Err(e) = f(&mut snap.poses) {
        return error(StatusCode::CONFLICT, &e);
    }
    let v = snap.poses.state();
    drop(snap);
    send(&live.tx, "accel", v.clone());
    Json(v).into_response()
}

/// Capture (`continuous`: every hold) or stop capturing (`on` false, `clear`: forgetting the
/// poses): the device streams raw values from the first capture, calibrated ones again when
/// capturing stops; the wizard's new state to every page, or why not (409 refused, 502 the
/// device did not switch to raw values).
async fn capturing(s: &Shared, on: bool, continuous: bool, clear: bool) -> Response {
    let live = match device(s) {
        Ok(l) => l,
        Err(r) => return *r,
    };
    let was_raw = {
        let mut snap = live.shared.lock().expect("snapshot");
        if on {
            if let Some(r) = snap.raw_refused() {
                return r;
            }
        }
        let w = &mut snap.poses;
        let was_raw = w.raw;
        if clear {
            w.poses.clear();
        }
        if let Err(e) = w.arm(on, continuous) {
            return error(StatusCode::CONFLICT, &e);
        }
        w.raw = on;
        was_raw
    };
    let switched = super::live::sync_mode(live).await;
    let mut snap = live.shared.lock().expect("snapshot");
    if let (Err(e), true) = (&switched, on) {
        // no raw values: no capture
        let w = &mut snap.poses;
        w.raw = was_raw;
        let _ = w.arm(false, false);
        let v = w.state();
        drop(snap);
        send(&live.tx, "accel", v);
        return error(StatusCode::BAD_GATEWAY, e);
    }
    let mut v = snap.poses.state();
    drop(snap);
    send(&live.tx, "accel", v.clone());
    if let Err(e) = switched {
        v["calibrated_again"] = json!(e);
    }
    Json(v).into_response()
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct CaptureBody {
    /// Capture every hold (each after a motion) until cancelled, not only the next.
    continuous: bool,
}

/// POST /api/live/accel/capture {"continuous": false}: switch the device to raw values and
/// capture the next still hold as a pose (`true`: and every hold after it, one a hold, until
/// cancelled).
pub async fn capture(State(s): State<Shared>, bytes: Bytes) -> Response {
    let b: CaptureBody = match super::noise::body(&bytes) {
        Ok(b) => b,
        Err(e) => return error(StatusCode::BAD_REQUEST, &e),
    };
    capturing(&s, true, b.continuous, false).await
}

/// POST /api/live/accel/cancel {}: stop waiting for a hold; the device back to calibrated
/// values.
pub async fn cancel(State(s): State<Shared>, bytes: Bytes) -> Response {
    if let Some(r) = empty(&bytes) {
        return r;
    }
    capturing(&s, false, false, false).await
}

/// POST /api/live/accel/clear {}: forget every pose; the device back to calibrated values.
pub async fn clear(State(s): State<Shared>, bytes: Bytes) -> Response {
    if let Some(r) = empty(&bytes) {
        return r;
    }
    capturing(&s, false, false, true).await
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct MergeBody {
    a: usize,
    b: usize,
}

/// POST /api/live/accel/merge {"a": I, "b": J}: two captures of one orientation as one pose.
pub async fn merge(State(s): State<Shared>, bytes: Bytes) -> Response {
    let b: MergeBody = match super::noise::body(&bytes) {
        Ok(b) => b,
        Err(e) => return error(StatusCode::BAD_REQUEST, &e),
    };
    change(&s, |w| w.merge(b.a, b.b))
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RemoveBody {
    index: usize,
}

/// POST /api/live/accel/remove {"index": I}: drop a pose.
pub async fn remove(State(s): State<Shared>, bytes: Bytes) -> Response {
    let b: RemoveBody = match super::noise::body(&bytes) {
        Ok(b) => b,
        Err(e) => return error(StatusCode::BAD_REQUEST, &e),
    };
    change(&s, |w| w.remove(b.index))
}

/// POST /api/live/accel/fit {}: the calibration lab's walk on the poses (what `imu-lab
/// calibrate accel --auto --json` does on a recording holding them): the model, its parameters
/// with σ, each pose's residual, the diagnosis; and the calibration for upload when plausible.
pub async fn fit(State(s): State<Shared>, bytes: Bytes) -> Response {
    let live = match device_post(&s, &bytes) {
        Ok(l) => l,
        Err(r) => return *r,
    };
    let (problem, state) = {
        let snap = live.shared.lock().expect("snapshot");
        (snap.poses.problem(), snap.poses.state())
    };
    if problem.poses.len() < 6 {
        return error(
            StatusCode::CONFLICT,
            &format!(
                "{} poses: capture six at least (each face of the board up once)",
                problem.poses.len()
            ),
        );
    }
    // capturing ends: the device back to calibrated values (the poses stay, raw)
    let back = capturing(&s, false, false, false).await;
    if !back.status().is_success() {
        return back;
    }
    let fitted = tokio::task::spawn_blocking(move || {
        use imu_cal::session::{self as cal, Sensor};
        let o = cal::Options {
            auto: true,
            ..cal::Options::new(Sensor::Accel)
        };
        let loaded = cal::Loaded {
            data: cal::Data::Accel(problem),
            sentinels: imu_cal::sentinel::Sentinels::default(),
            notes: vec!["poses captured on the page (each the mean of a still hold)".into()],
            mag_part: None,
        };
        let run = cal::run(&loaded, &o)?;
        let residuals = run.report.model.fitted.residuals.clone();
        Ok::<_, String>((super::live::calibration(&loaded, &run), residuals))
    })
    .await;
    let ((v, ready), residuals) = match fitted {
        Ok(Ok(t)) => t,
        Ok(Err(e)) => return error(StatusCode::UNPROCESSABLE_ENTITY, &e),
        Err(e) => return error(StatusCode::INTERNAL_SERVER_ERROR, &e.to_string()),
    };
    let upload = super::live::offer(live, ready, super::merge::Section::Accel, None).await;
    Json(json!({
        "fit": v,
        "residuals": residuals,
        "residual_unit": "m/s²",
        "warnings": { "same": state["same"], "missing": state["missing"] },
        "upload": upload,
    }))
    .into_response()
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::serve::tests::rng;

    fn win(t: f64, a: [f64; 3], a_sd: f64, g: [f64; 3], g_sd: f64) -> Win {
        Win {
            t,
            raw: true,
            n: 100.0,
            a,
            a_var: [a_sd * a_sd; 3],
            g,
            g_var: [g_sd * g_sd; 3],
        }
    }

    const NOISE: Noise = Noise {
        accel: 3.0 * 0.04 * 0.04,
        gyro: 3.0 * 0.05 * 0.05,
    };

    /// Still at the noise: captured after the window fills and the hold passes, with the mean
    /// of the windows; asked again while still, captured at once; moving (the accelerometer's
    /// variance up, or a steady turn) resets the progress; continuous captures take one pose a
    /// hold; without the device's noise nothing is judged.
    #[test]
    fn a_pose_is_captured_after_a_still_hold_and_motion_resets_it() {
        let (key, mut u) = rng();
        let a0 = [9.0 * u() - 4.5, 9.0 * u() - 4.5, 5.0 + 3.0 * u()];
        let mut w = Wizard::default();
        assert!(w.window(win(0.0, a0, 0.04, [0.0; 3], 0.05), None).is_none());
        assert_eq!(w.state()["still"], Value::Null);
        w.arm(true, false).unwrap();
        let mut t = 0.0;
        let mut feed = |w: &mut Wizard, a: [f64; 3], a_sd: f64, g: [f64; 3], k: usize| {
            let mut last = None;
            for _ in 0..k {
                t += WINDOW_S;
                // the window means scatter as the noise's mean over 100 samples
                let a = a.map(|x| x + 0.004 * (2.0 * u() - 1.0));
                last = w.window(win(t, a, a_sd, g, 0.05), Some(NOISE));
            }
            last
        };
        // moving: a variance far above the noise
        feed(&mut w, a0, 2.0, [0.0; 3], 8);
        assert_eq!(w.state()["still"], false, "key {key}");
        // a steady turn about the vertical: variances at the noise, a rate of 20 deg/s
        feed(&mut w, a0, 0.04, [0.0, 0.0, 20.0], 8);
        assert_eq!(w.state()["still"], false, "key {key}");
        assert!(w.poses.is_empty());
        // still: 4 windows for the stillness window to clear the turn, then the hold's 10
        let s = feed(&mut w, a0, 0.04, [0.3, -0.2, 0.1], 13).unwrap();
        assert!(
            w.poses.is_empty() && s["progress"].as_f64().unwrap() > 0.85,
            "{s}"
        );
        feed(&mut w, a0, 0.04, [0.3, -0.2, 0.1], 1);
        assert_eq!(w.poses.len(), 1, "key {key}");
        assert!(!w.armed);
        let p = &w.poses[0];
        for ((m, s), a) in p.mean.iter().zip(p.sigma).zip(a0) {
            assert!((m - a).abs() < 0.004, "key {key}: {p:?}");
            // the σ of the mean of ten windows scattered uniformly by ±0.004: 0.0023/√10
            assert!(s > 2e-4 && s < 1.5e-3, "key {key}: {p:?}");
        }
        assert_eq!(p.samples, 1000.0);
        // asked again while the board stays still: the hold's last second at once (the same
        // orientation twice)
        w.arm(true, false).unwrap();
        assert_eq!(w.poses.len(), 2, "key {key}");
        assert_eq!(w.same_orientation().len(), 1);
        w.remove(1).unwrap();
        // motion during a hold starts the hold again
        feed(&mut w, a0, 1.0, [0.0; 3], 1);
        w.arm(true, false).unwrap();
        feed(&mut w, a0, 0.04, [0.0; 3], 5);
        feed(&mut w, a0, 1.0, [0.0; 3], 1);
        assert_eq!(w.state()["progress"], 0.0);
        // continuous: one pose a hold — the hold goes on without a second pose; a motion and
        // another hold give the next
        w.arm(true, true).unwrap();
        feed(&mut w, a0, 0.04, [0.0; 3], 15);
        assert_eq!(w.poses.len(), 2, "key {key}");
        feed(&mut w, a0, 0.04, [0.0; 3], 30);
        assert_eq!(w.poses.len(), 2, "key {key}");
        assert_eq!(w.state()["waiting_for_motion"], true);
        feed(&mut w, a0, 1.0, [0.0; 3], 3);
        feed(&mut w, a0, 0.04, [0.0; 3], 15);
        assert_eq!(w.poses.len(), 3, "key {key}");
        assert!(w.armed && w.continuous);
        w.arm(false, false).unwrap();
        assert!(!w.armed && !w.continuous);
    }

    /// Only raw windows become a pose: calibrated ones (the stream before the device switched)
    /// are judged for stillness but never captured, and a switch starts the hold again (no
    /// pose mixes the two kinds of values).
    #[test]
    fn only_raw_windows_are_captured_and_a_switch_starts_the_hold_again() {
        let (key, mut u) = rng();
        let a0 = [9.0 * u() - 4.5, 9.0 * u() - 4.5, 5.0 + 3.0 * u()];
        // the calibrated values differ from the raw ones by a correction of up to 0.5 m/s²
        let cal = a0.map(|x| x + 0.5 * (2.0 * u() - 1.0));
        let mut w = Wizard::default();
        let mut t = 0.0;
        let mut feed = |w: &mut Wizard, a: [f64; 3], raw: bool, k: usize| {
            for _ in 0..k {
                t += WINDOW_S;
                let a = a.map(|x| x + 0.004 * (2.0 * u() - 1.0));
                w.window(
                    Win {
                        raw,
                        ..win(t, a, 0.04, [0.0; 3], 0.05)
                    },
                    Some(NOISE),
                );
            }
        };
        // still and calibrated for 3 s: asked for a pose, none is taken at once
        feed(&mut w, cal, false, 30);
        assert_eq!(w.state()["still"], true, "key {key}");
        w.arm(true, false).unwrap();
        assert!(w.poses.is_empty(), "key {key}");
        // two calibrated windows still come before the switch
        feed(&mut w, cal, false, 2);
        assert!(w.poses.is_empty(), "key {key}");
        // raw: the stillness is judged over raw windows only, then the hold
        feed(&mut w, a0, true, 4 + 9);
        assert!(w.poses.is_empty(), "key {key}: {}", w.state());
        feed(&mut w, a0, true, 1);
        assert_eq!(w.poses.len(), 1, "key {key}");
        for (m, a) in w.poses[0].mean.iter().zip(a0) {
            assert!((m - a).abs() < 0.004, "key {key}: {:?}", w.poses[0]);
        }
        // after a calibrated window, asked again: not at once; a calibrated window in the
        // middle of the hold starts it again
        feed(&mut w, cal, false, 1);
        w.arm(true, false).unwrap();
        assert_eq!(w.poses.len(), 1, "key {key}");
        feed(&mut w, a0, true, 8);
        assert!(
            w.state()["progress"].as_f64().unwrap() > 0.3,
            "key {key}: {}",
            w.state()
        );
        feed(&mut w, cal, false, 1);
        assert_eq!(w.state()["progress"], 0.0, "key {key}");
        feed(&mut w, a0, true, 4 + 9);
        assert_eq!(w.poses.len(), 1, "key {key}");
        feed(&mut w, a0, true, 1);
        assert_eq!(w.poses.len(), 2, "key {key}");
    }

    /// The same orientation twice is flagged (and a merge keeps one pose, the weighted mean);
    /// faces never captured are listed; a tilted pose holds no face.
    #[test]
    fn the_same_orientation_twice_warns_and_missing_faces_are_named() {
        let (key, mut u) = rng();
        let g = 9.80665;
        let mut w = Wizard::default();
        let pose = |m: [f64; 3], n: f64| Captured {
            mean: m,
            sigma: [1e-3; 3],
            seconds: n / 1000.0,
            samples: n,
            half_diff: 1e-3,
            t: 0.0,
        };
        let tilt = 1.0 + 10.0 * u();
        let (s, c) = tilt.to_radians().sin_cos();
        w.poses.push(pose([0.0, 0.0, g], 1000.0));
        w.poses.push(pose([0.0, -g, 0.0], 1000.0));
        w.poses.push(pose([g * s, 0.0, g * c], 3000.0));
        w.poses.push(pose([g * 0.5, g * 0.5, g * 0.707], 1000.0));
        let same = w.same_orientation();
        assert_eq!(same.len(), 1, "key {key}: {same:?}");
        assert_eq!((same[0].0, same[0].1), (0, 2));
        assert!((same[0].2 - tilt).abs() < 1e-9);
        assert_eq!(w.missing_faces(), ["+x", "-x", "+y", "-z"]);
        assert_eq!(w.poses[3].face(), "tilted");
        w.merge(0, 2).unwrap();
        assert_eq!(w.poses.len(), 3);
        assert!((w.poses[0].mean[0] - 0.75 * g * s).abs() < 1e-12);
        assert_eq!(w.poses[0].samples, 4000.0);
        assert!(w.same_orientation().is_empty());
        assert!(w.merge(1, 1).is_err() && w.merge(0, 3).is_err() && w.remove(3).is_err());
    }

    /// The noise from the device's tables: the deviation at the shortest τ, σ² summed.
    #[test]
    fn the_noise_is_the_tables_shortest_tau() {
        let table = |ch: &str, d: f64| {
            json!({ "channel": ch, "rows": [
                { "tau_s": 0.002, "dev": d / 1.4 }, { "tau_s": 0.001, "dev": d }, { "tau_s": 0.0005, "dev": 0.0 },
            ]})
        };
        let mut tables: Vec<Value> = ["ax", "ay", "az"].iter().map(|c| table(c, 0.04)).collect();
        assert_eq!(
            noise_from_tables(&json!({ "tables": tables.clone() })),
            None
        );
        tables.extend(["gx", "gy", "gz"].iter().map(|c| table(c, 0.05)));
        let n = noise_from_tables(&json!({ "tables": tables })).unwrap();
        assert!((n.accel - 3.0 * 0.0016).abs() < 1e-15 && (n.gyro - 3.0 * 0.0025).abs() < 1e-15);
    }
}
