//! The live device in the page: one thread reads the link (`imu_link`, as `imu-lab record`
//! does) and turns what the device sends into bounded updates, sent to every open page as
//! server-sent events:
//!
//! * `status`: the device's status frames (sensor states, samples taken and lost, the losses'
//!   causes from its `Gap` events, bus faults, CPU load), as they arrive (1 s);
//! * `tables`: the device's own Allan tables, every channel of a round, each with its rows
//!   (τ, deviation, 68.3 % bounds, EDF) derived on the host as `imu-lab device tables` does;
//! * `stream`: the stream decimated on the server — per [`WINDOW_S`] of device time and
//!   channel the mean, minimum and maximum, and whether the values are raw — so a page follows
//!   a 1 kHz stream with ten small messages a second whatever the rate;
//! * `record`: the recording's state (the rows go to a CSV in the contract, the same rows
//!   `imu-lab record` writes);
//! * `mag`: while the magnetometer wizard collects, each window's mean field with the count and
//!   the direction coverage; its fit and upload answer their own requests;
//! * `mode`: whether the server has the device stream raw values, and for which wizards.
//!
//! The wizards fit raw values (the nominal sensitivities, no corrections: what a calibration
//! applies to), so a fit is right on a device that holds a calibration already. The device
//! streams calibrated values unless a wizard needs raw ones ([`sync_mode`]): the magnetometer's
//! while it collects, the accelerometer's from its first capture until Fit, Clear or Stop
//! capturing, the verification while it records. Every batch says which kind it carries; a
//! stream window never mixes the two (it ends at a switch), and each wizard takes only the
//! raw windows.
//!
//! The server keeps only the last [`HISTORY`] stream windows and the latest tables, so neither
//! it nor the page grows with the length of the session.
use std::collections::VecDeque;
use std::convert::Infallible;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::PathBuf;
use std::sync::{mpsc, Arc, Mutex};
use std::time::Duration;

use anyhow::{bail, Context, Result};
use axum::body::Bytes;
use axum::extract::State;
use axum::http::StatusCode;
use axum::response::sse::{Event as SseEvent, KeepAlive, Sse};
use axum::response::{IntoResponse, Response};
use axum::Json;
use futures_util::stream::{self, Stream, StreamExt};
use imu_proto::csv::Writer;
use imu_proto::{Channel, DeviceMsg, Reply, Request, SensorState, Status, StreamMode};
use serde::Deserialize;
use serde_json::{json, Value};
use tokio::sync::{broadcast, oneshot};
use tokio_stream::wrappers::BroadcastStream;

use super::level::LEVEL_TILT_DEG;
use super::merge::Section;
use super::{error, Shared};
use crate::link::Link;
use imu_link::device::table_rows;
use imu_link::record::{self, DeviceLosses, Held, Rows, COLUMNS};

/// Device time per decimated stream point, s.
pub const WINDOW_S: f64 = 0.1;
/// Stream windows kept for a page that opens late (60 s).
pub const HISTORY: usize = 600;
/// Messages a slow page may fall behind before it skips ahead.
const QUEUE: usize = 256;

/// The live side: what the reader thread keeps, and the channel to the pages.
pub struct Live {
    pub port: String,
    pub(super) shared: Arc<Mutex<Snapshot>>,
    pub(super) tx: broadcast::Sender<(String, Value)>,
    record_dir: PathBuf,
    /// Requests for the device, sent by the reader thread (it owns the link).
    pub(super) requests: Mutex<mpsc::Sender<Pending>>,
    /// The stream mode the server last set on the device (held while it is changed, so that
    /// two requests cannot interleave their switches).
    mode: tokio::sync::Mutex<StreamMode>,
}

/// A request for the device and where its reply goes.
pub(super) type Pending = (Request, oneshot::Sender<Result<Reply, String>>);

/// A request sent: its id, where its reply goes, and until when it may come.
type Waiting = (
    u16,
    oneshot::Sender<Result<Reply, String>>,
    std::time::Instant,
);

/// How long the device has to answer a request (a flash write pauses it a few hundred ms).
const REPLY_WAIT: Duration = Duration::from_secs(10);

/// The latest of everything, for a page that connects now.
#[derive(Default)]
pub(super) struct Snapshot {
    identity: Value,
    status: Value,
    tables: Value,
    stream: VecDeque<Value>,
    record: Option<Recording>,
    /// The last finished recording: (path, summary).
    finished: Option<(PathBuf, String)>,
    losses: DeviceLosses,
    link_error: Option<String>,
    /// The magnetometer wizard's points.
    mag: MagPoints,
    /// The last fit's calibration (either wizard's), merged into the device's current one,
    /// checked and ready for the device, with the one-time code the page must send back to
    /// upload it.
    ready_cal: Option<ReadyCal>,
    /// The device's whole calibration after the last upload from this page (the verification
    /// applies it on the host).
    pub(super) uploaded: Option<Uploaded>,
    /// The accelerometer's pose wizard.
    pub(super) poses: super::poses::Wizard,
    /// The device's noise (from its tables), for the pose wizard's stillness.
    noise: Option<super::poses::Noise>,
    /// The verification recording, while it runs.
    pub(super) verify: Option<super::verify::Recording>,
}

impl Snapshot {
    /// Which wizards need the device's raw values now.
    pub(super) fn raw_for(&self) -> Vec<&'static str> {
        let mut v = Vec::new();
        if self.mag.on {
            v.push("the magnetometer wizard");
        }
        if self.poses.raw {
            v.push("the accelerometer wizard");
        }
        if self.verify.is_some() {
            v.push("the verification");
        }
        v
    }

    /// A wizard may not switch the stream to raw values while a recording to a file runs (its
    /// rows are the calibrated contract): the refusal (409), or `None`.
    pub(super) fn raw_refused(&self) -> Option<Response> {
        self.record.is_some().then(|| {
            error(
                StatusCode::CONFLICT,
                "a recording to a file is running: stop it first (the wizards switch the device \
                 to raw values, the recording holds calibrated ones)",
            )
        })
    }

    fn mode_state(&self) -> Value {
        let users = self.raw_for();
        json!({ "raw": !users.is_empty(), "for": users })
    }
}

/// A calibration the user may upload: the device's current calibration with the fitted part
/// replaced ([`super::merge`]), its blob, the device's blob it was merged into (an upload is
/// refused when the device holds another one by then) and the confirmation code.
struct ReadyCal {
    cal: imu_cal::device::Calibration,
    blob: Vec<u8>,
    device_blob: Vec<u8>,
    section: Section,
    /// The field magnitude of a magnetometer fit of the sphere, µT.
    field: Option<f64>,
    code: String,
}

/// The device's calibration after an upload from this page.
#[derive(Clone, Copy, Debug)]
pub(super) struct Uploaded {
    pub cal: imu_cal::device::Calibration,
    /// The field magnitude of the last magnetometer fit of the sphere uploaded, µT (none after
    /// a level turn's: its field is the horizontal one).
    pub field: Option<f64>,
}

/// Most magnetometer points the wizard keeps (ten a second: over 8 minutes).
pub const MAG_POINTS: usize = 5000;
/// Most magnetometer samples of level windows the level turn keeps (100 s at 200 Hz).
pub const LEVEL_SAMPLES: usize = 20_000;
/// Direction bins of the coverage: 6 bands of equal area in elevation × 12 in azimuth.
const BANDS: usize = 6;
const SECTORS: usize = 12;

/// The magnetometer wizard's collection: the mean field of every raw stream window while on,
/// with the board's tilt from level in that window and its rate about the horizontal axes (the
/// accelerometer's and the gyro's means; the level turn takes the points within
/// [`LEVEL_TILT_DEG`] and [`super::level::LEVEL_RATE_DPS`]).
#[derive(Default)]
struct MagPoints {
    on: bool,
    points: VecDeque<[f64; 3]>,
    /// The tilt of each point and the rate about x and y then, degrees and deg/s (`None`: no
    /// accelerometer or gyro mean in its window).
    tilts: VecDeque<Option<(f64, f64)>>,
    /// The magnetometer's samples of the level windows (each sample once): the level turn
    /// fits these, twenty a window at 200 Hz, so that the noise floor the lab estimates from
    /// the residuals' second differences holds thousands of them (from the 0.1 s means of one
    /// turn, about 140, it scatters by 12 % and the verdict with it).
    level_samples: VecDeque<[f64; 3]>,
}

impl MagPoints {
    /// One window's mean field and the board's tilt then; the oldest point goes beyond
    /// [`MAG_POINTS`].
    fn push(&mut self, m: [f64; 3], tilt: Option<(f64, f64)>, samples: &[[f64; 3]]) {
        if tilt.is_some_and(super::level::is_level) {
            self.level_samples.extend(samples);
            while self.level_samples.len() > LEVEL_SAMPLES {
                self.level_samples.pop_front();
            }
        }
        self.points.push_back(m);
        self.tilts.push_back(tilt);
        while self.points.len() > MAG_POINTS {
            self.points.pop_front();
            self.tilts.pop_front();
        }
    }

    fn clear(&mut self) {
        self.points.clear();
        self.tilts.clear();
        self.level_samples.clear();
    }

    /// Whether point `k` was taken with the board level and turning about the vertical only.
    fn is_level(&self, k: usize) -> bool {
        self.tilts
            .get(k)
            .copied()
            .flatten()
            .is_some_and(super::level::is_level)
    }

    /// The points taken level (the level turn's).
    fn level_points(&self) -> Vec<[f64; 3]> {
        (0..self.points.len())
            .filter(|&k| self.is_level(k))
            .map(|k| self.points[k])
            .collect()
    }

    /// The share of 10° heading bins the level points sweep (their x–y components).
    fn heading_coverage(&self) -> f64 {
        let xy: Vec<[f64; 2]> = self.level_points().iter().map(|p| [p[0], p[1]]).collect();
        super::level::heading_coverage(&xy)
    }

    /// The share of direction bins (around the points' mean, a first guess of the hard iron)
    /// that hold a point: how much of the sphere the turns have covered.
    fn coverage(&self) -> f64 {
        let n = self.points.len();
        if n < 2 {
            return 0.0;
        }
        let mut c = [0.0; 3];
        for p in &self.points {
            for k in 0..3 {
                c[k] += p[k] / n as f64;
            }
        }
        let mut hit = [false; BANDS * SECTORS];
        for p in &self.points {
            let d = [p[0] - c[0], p[1] - c[1], p[2] - c[2]];
            let r = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
            // a point at the centre (or not finite) has no direction
            if r.is_nan() || r <= 0.0 {
                continue;
            }
            // z/r is uniform on a sphere: equal-area bands
            let band = (((d[2] / r + 1.0) / 2.0 * BANDS as f64) as usize).min(BANDS - 1);
            let az = d[1].atan2(d[0]) + std::f64::consts::PI;
            let sector =
                ((az / (2.0 * std::f64::consts::PI) * SECTORS as f64) as usize).min(SECTORS - 1);
            hit[band * SECTORS + sector] = true;
        }
        hit.iter().filter(|h| **h).count() as f64 / hit.len() as f64
    }

    fn state(&self) -> Value {
        json!({
            "collecting": self.on,
            "points": self.points.len(),
            "coverage": self.coverage(),
            "level_points": self.level_points().len(),
            "heading_coverage": self.heading_coverage(),
            "tilt_deg": self.tilts.back().copied().flatten().map(|t| t.0),
            "level_tilt_deg": LEVEL_TILT_DEG,
            "level_rate_dps": super::level::LEVEL_RATE_DPS,
            "heading_bins": super::level::HEADING_BINS,
        })
    }
}

/// A recording in progress.
struct Recording {
    path: PathBuf,
    writer: Writer<BufWriter<File>>,
    rows: Rows,
    held: Held,
    losses: DeviceLosses,
    /// The first write that failed (reported when the recording stops).
    failed: Option<String>,
}

/// The channels of the decimated stream with their units: the ten calibrated columns of the
/// contract, then the device's attitude estimate (roll, pitch, heading), when it sends one.
pub const STREAM_CHANNELS: [(&str, &str); STREAM_N] = [
    ("ax", "m/s²"),
    ("ay", "m/s²"),
    ("az", "m/s²"),
    ("gx", "deg/s"),
    ("gy", "deg/s"),
    ("gz", "deg/s"),
    ("mx", "µT"),
    ("my", "µT"),
    ("mz", "µT"),
    ("temp", "°C"),
    ("roll", "deg"),
    ("pitch", "deg"),
    ("heading", "deg"),
];
/// Channels of a stream point.
pub const STREAM_N: usize = 13;
/// Index of the heading in [`STREAM_CHANNELS`] (an angle: averaged unwrapped).
const HEADING: usize = 12;

/// The decimator: per channel the count, sum, sum of squares, minimum and maximum over the
/// current window. Values are summed as offsets from the channel's first value in the window
/// (the variance without cancellation; the heading unwrapped across 0/360°).
pub(crate) struct Window {
    start: Option<f64>,
    /// The rows are raw values (the device's corrections off).
    raw: bool,
    /// Rows (IMU samples) in the window.
    rows: u32,
    n: [u32; STREAM_N],
    first: [f64; STREAM_N],
    sum: [f64; STREAM_N],
    sq: [f64; STREAM_N],
    min: [f64; STREAM_N],
    max: [f64; STREAM_N],
}

impl Window {
    pub(crate) fn new() -> Window {
        Window {
            start: None,
            raw: false,
            rows: 0,
            n: [0; STREAM_N],
            first: [0.0; STREAM_N],
            sum: [0.0; STREAM_N],
            sq: [0.0; STREAM_N],
            min: [f64::INFINITY; STREAM_N],
            max: [f64::NEG_INFINITY; STREAM_N],
        }
    }

    fn add(&mut self, k: usize, x: f64) {
        if !x.is_finite() {
            return;
        }
        if self.n[k] == 0 {
            self.first[k] = x;
        }
        let d = if k == HEADING {
            imu_cal::heading::angle_diff(x, self.first[k])
        } else {
            x - self.first[k]
        };
        self.n[k] += 1;
        self.sum[k] += d;
        self.sq[k] += d * d;
        self.min[k] = self.min[k].min(d);
        self.max[k] = self.max[k].max(d);
    }

    /// Add a row; returns the finished window's point when `t` starts a new one.
    pub(crate) fn push(&mut self, t: f64, v: &[Option<f64>; 10]) -> Option<Value> {
        let mut out = None;
        match self.start {
            Some(s) if t - s >= WINDOW_S || t < s => {
                out = self.point();
                *self = Window::new();
                self.start = Some(t);
            }
            None => self.start = Some(t),
            _ => {}
        }
        self.rows += 1;
        for (k, x) in v.iter().enumerate() {
            if let Some(x) = x {
                self.add(k, *x);
            }
        }
        out
    }

    /// Add the device's attitude estimates (they come in frames of their own, a few ms after
    /// the samples they cover: each counts in the window open when it arrives).
    pub(crate) fn orientation(&mut self, o: &[imu_proto::Orientation]) {
        for e in o {
            self.add(10, f64::from(e.roll_deg));
            self.add(11, f64::from(e.pitch_deg));
            self.add(HEADING, f64::from(e.heading_deg));
        }
    }

    /// The window's point: `t` (its first row, s of device time), `n` rows, `raw` (the values
    /// are raw, not calibrated), and per channel of [`STREAM_CHANNELS`] the mean, minimum,
    /// maximum and standard deviation (null: no value).
    pub(crate) fn point(&self) -> Option<Value> {
        let t = self.start?;
        if self.rows == 0 {
            return None;
        }
        let f = noise_model::session::num;
        let mut mean = Vec::with_capacity(STREAM_N);
        let (mut min, mut max, mut sd) = (mean.clone(), mean.clone(), mean.clone());
        for k in 0..STREAM_N {
            if self.n[k] == 0 {
                for v in [&mut mean, &mut min, &mut max, &mut sd] {
                    v.push(Value::Null);
                }
                continue;
            }
            let n = f64::from(self.n[k]);
            let m = self.sum[k] / n;
            // the heading's mean back in [0, 360), its extremes shifted with it
            let base = if k == HEADING {
                (self.first[k] + m).rem_euclid(360.0) - m
            } else {
                self.first[k]
            };
            mean.push(f(base + m));
            min.push(f(base + self.min[k]));
            max.push(f(base + self.max[k]));
            sd.push(f((self.sq[k] / n - m * m).max(0.0).sqrt()));
        }
        Some(
            json!({ "t": t, "n": self.rows, "raw": self.raw, "mean": mean, "min": min, "max": max, "sd": sd }),
        )
    }
}

fn state_name(s: SensorState) -> &'static str {
    match s {
        SensorState::Unknown => "not probed yet",
        SensorState::Ok => "ok",
        SensorState::Missing => "missing (retrying with bus recovery)",
        SensorState::Stalled => "stalled (re-initialising)",
    }
}

fn status_json(s: &Status, losses: &DeviceLosses) -> Value {
    json!({
        "uptime_s": s.uptime_us as f64 * 1e-6,
        "imu": { "state": state_name(s.imu), "taken": s.samples_taken, "lost": s.samples_dropped,
                 "fifo_overflows": s.fifo_overflows, "period_us": f64::from(s.imu_period_ns) * 1e-3,
                 "losses": &losses.imu },
        "mag": { "state": state_name(s.mag), "taken": s.mag_samples, "lost": s.mag_dropped,
                 "period_us": f64::from(s.mag_period_ns) * 1e-3, "losses": &losses.mag },
        "i2c_errors": s.i2c_errors,
        "bus_faults": s.bus_faults,
        "bus_recoveries": s.bus_recoveries,
        "frames_rejected": s.frames_rejected,
        "frames_unsent": s.frames_unsent,
        "cpu_percent": f64::from(s.cpu_load_permille) / 10.0,
        "temp_c": s.temp_milli_c.map(|t| f64::from(t) / 1000.0),
        "mode": format!("{:?}", s.mode),
        "calibration": match s.cal.source {
            imu_proto::CalSource::Identity => "identity (none stored)",
            imu_proto::CalSource::Flash => "from flash",
            imu_proto::CalSource::Host => "set by the host, not persisted",
        },
    })
}

fn table_json(t: &imu_proto::AllanTable) -> Value {
    let rows: Vec<Value> = table_rows(t)
        .iter()
        .map(|r| json!({ "tau_s": r.tau, "dev": r.dev, "lo": r.lo, "hi": r.hi, "edf": r.edf }))
        .collect();
    json!({
        "channel": t.channel.name(),
        "unit": t.channel.unit(),
        "round": t.snapshot,
        "t_s": t.t_us as f64 * 1e-6,
        "samples": t.pushed,
        "gaps": t.gaps,
        "rows": rows,
    })
}

impl Live {
    /// Open the link, ask who is there, switch the stream to calibrated samples, and start the
    /// reader thread.
    pub fn start(port: String, record_dir: PathBuf) -> Result<Live> {
        if !record_dir.is_dir() {
            bail!(
                "--record-dir {}: not a directory (recordings are written there)",
                record_dir.display()
            );
        }
        let mut link = Link::open(&port)?;
        let identity = match link.request(Request::Identify)? {
            Reply::Identity(id) => json!({
                "firmware": id.firmware.as_str(), "board": id.board.as_str(),
                "protocol": id.protocol, "imu_rate_hz": id.imu_rate_hz, "mag_rate_hz": id.mag_rate_hz,
                "channels": STREAM_CHANNELS.iter()
                    .map(|(name, unit)| json!({ "name": name, "unit": unit }))
                    .collect::<Vec<_>>(),
            }),
            other => bail!("{port}: unexpected reply to Identify: {other:?}"),
        };
        match link.request_with(
            Request::SetMode(StreamMode::Calibrated),
            imu_link::REPLY_TIMEOUT,
            |_| {},
        )? {
            Reply::Ok => {}
            other => bail!("{port}: the device did not accept the calibrated stream: {other:?}"),
        }
        let shared = Arc::new(Mutex::new(Snapshot {
            identity,
            ..Snapshot::default()
        }));
        let (tx, _) = broadcast::channel(QUEUE);
        let (req_tx, req_rx) = mpsc::channel();
        {
            let (shared, tx) = (shared.clone(), tx.clone());
            std::thread::Builder::new()
                .name("device link".into())
                .spawn(move || read_loop(link, &shared, &tx, &req_rx))
                .context("starting the link's reader")?;
        }
        Ok(Live {
            port,
            shared,
            tx,
            record_dir,
            requests: Mutex::new(req_tx),
            mode: tokio::sync::Mutex::new(StreamMode::Calibrated),
        })
    }
}

impl Live {
    /// On the server's exit (Ctrl-C): a device a wizard left on raw values is switched back to
    /// calibrated ones (what the next `imu-lab serve` does at its start too), said on stderr.
    pub async fn calibrated_on_exit(&self) {
        let mode = self.mode.lock().await;
        if *mode == StreamMode::Calibrated {
            return;
        }
        let wait = Duration::from_secs(3);
        let req = request(self, Request::SetMode(StreamMode::Calibrated));
        let problem = match tokio::time::timeout(wait, req).await {
            Ok(Ok(Reply::Ok)) => {
                eprintln!("imu-lab serve: the device streams calibrated values again");
                return;
            }
            Ok(Ok(other)) => format!("it answered {other:?}"),
            Ok(Err(e)) => e,
            Err(_) => format!("no answer within {} s", wait.as_secs()),
        };
        eprintln!(
            "imu-lab serve: warning: the device may still stream raw values ({problem}); \
             `imu-lab device --port {} mode calibrated` switches it back",
            self.port
        );
    }
}

pub(super) fn send(tx: &broadcast::Sender<(String, Value)>, kind: &str, v: Value) {
    // no page open: nobody to tell
    let _ = tx.send((kind.to_string(), v));
}

/// The reader: every message from the device into the snapshot and out to the pages.
fn read_loop(
    mut link: Link,
    shared: &Mutex<Snapshot>,
    tx: &broadcast::Sender<(String, Value)>,
    requests: &mpsc::Receiver<Pending>,
) {
    let mut window = Window::new();
    let mut decim = Rows::default();
    // the window's magnetometer samples, each once (the rows hold a sample until the next),
    // for the level turn's fit
    let mut win_mag: Vec<[f64; 3]> = Vec::new();
    let mut last_mag: Option<[f64; 3]> = None;
    // the kind of values of the last batch (raw or calibrated)
    let mut raw: Option<bool> = None;
    let mut round: Option<u32> = None;
    let mut round_tables: Vec<Value> = Vec::new();
    // requests sent, waiting for their reply: (id, where it goes, until when)
    let mut waiting: Vec<Waiting> = Vec::new();
    loop {
        while let Ok((req, reply)) = requests.try_recv() {
            match link.send(req) {
                Ok(id) => waiting.push((id, reply, std::time::Instant::now() + REPLY_WAIT)),
                Err(e) => {
                    let _ = reply.send(Err(format!("{e:#}")));
                }
            }
        }
        let now = std::time::Instant::now();
        for (_, reply, _) in waiting.extract_if(.., |(_, _, until)| *until < now) {
            let _ = reply.send(Err(format!(
                "no reply from the device within {} s",
                REPLY_WAIT.as_secs()
            )));
        }
        let msg = match link.recv(Duration::from_millis(200)) {
            Ok(Some(m)) => m,
            Ok(None) => continue,
            Err(e) => {
                let text = format!("the link to {} failed: {e:#}", link.name());
                shared.lock().expect("snapshot").link_error = Some(text.clone());
                send(tx, "link", json!({ "error": text }));
                return;
            }
        };
        match msg {
            DeviceMsg::Samples(b) => {
                let mut points = Vec::new();
                // the stream switched between raw and calibrated values: the window so far
                // ends here, and the rows start again (none holds a magnetometer sample of the
                // other kind)
                if raw != Some(!b.calibrated) {
                    if raw.is_some() {
                        points.extend(window.point().map(|p| (p, std::mem::take(&mut win_mag))));
                    }
                    raw = Some(!b.calibrated);
                    window = Window::new();
                    decim = Rows::default();
                    win_mag.clear();
                    last_mag = None;
                }
                window.raw = !b.calibrated;
                decim.batch(&b, |r| {
                    if let Some(p) = window.push(r.t, &r.values) {
                        points.push((p, std::mem::take(&mut win_mag)));
                    }
                    if let (Some(x), Some(y), Some(z)) = (r.values[6], r.values[7], r.values[8]) {
                        if last_mag != Some([x, y, z]) {
                            win_mag.push([x, y, z]);
                            last_mag = Some([x, y, z]);
                        }
                    }
                });
                let mut s = shared.lock().expect("snapshot");
                if let Some(rec) = s.record.as_mut() {
                    let (rows, held, w) = (&mut rec.rows, &mut rec.held, &mut rec.writer);
                    let failed = &mut rec.failed;
                    rows.batch(&b, |r| held.row(*r));
                    held.release(false, |r| {
                        if failed.is_none() {
                            if let Err(e) = w.row(&r.fields()) {
                                *failed = Some(e.to_string());
                            }
                        }
                    });
                }
                for (p, samples) in points {
                    if let Some(v) = s.verify.as_mut().and_then(|r| r.window(&p)) {
                        send(tx, "verify", v);
                    }
                    if let Some(w) = super::poses::Win::from_point(&p) {
                        let noise = s.noise;
                        if let Some(v) = s.poses.window(w, noise) {
                            send(tx, "accel", v);
                        }
                    }
                    if s.mag.on && p["raw"] == true {
                        let m = |k: usize| p["mean"][k].as_f64().unwrap_or(f64::NAN);
                        let point = [m(6), m(7), m(8)];
                        if point.iter().all(|v| v.is_finite()) {
                            let tilt = super::level::tilt_deg([m(0), m(1), m(2)])
                                .zip(Some(m(3).hypot(m(4))).filter(|r| r.is_finite()));
                            s.mag.push(point, tilt, &samples);
                            let mut v = s.mag.state();
                            v["point"] = json!(point);
                            v["level"] = json!(tilt.is_some_and(super::level::is_level));
                            send(tx, "mag", v);
                        }
                    }
                    s.stream.push_back(p.clone());
                    while s.stream.len() > HISTORY {
                        s.stream.pop_front();
                    }
                    send(tx, "stream", p);
                }
            }
            DeviceMsg::Orientation(o) => {
                window.orientation(&o);
                if let Some(rec) = shared.lock().expect("snapshot").record.as_mut() {
                    rec.held.estimates(&o);
                }
            }
            DeviceMsg::Event(e) => {
                let mut s = shared.lock().expect("snapshot");
                s.losses.event(&e);
                if let Some(rec) = s.record.as_mut() {
                    rec.losses.event(&e);
                }
            }
            DeviceMsg::Status(st) => {
                let mut s = shared.lock().expect("snapshot");
                let v = status_json(&st, &s.losses);
                s.status = v.clone();
                drop(s);
                send(tx, "status", v);
            }
            DeviceMsg::Table(t) => {
                if round != Some(t.snapshot) {
                    round = Some(t.snapshot);
                    round_tables.clear();
                }
                round_tables.push(table_json(&t));
                // a round is ten tables, one per channel, sent one after the other
                if round_tables.len() == Channel::ALL.len() {
                    let v = json!({ "round": t.snapshot, "tables": round_tables });
                    let mut s = shared.lock().expect("snapshot");
                    s.noise = super::poses::noise_from_tables(&v).or(s.noise);
                    s.tables = v.clone();
                    drop(s);
                    send(tx, "tables", v);
                    round_tables = Vec::new();
                }
            }
            DeviceMsg::Reply { id, reply } => {
                if let Some(k) = waiting.iter().position(|(w, _, _)| *w == id) {
                    let (_, to, _) = waiting.swap_remove(k);
                    let _ = to.send(Ok(reply));
                }
            }
        }
    }
}

/// GET /api/live/events: the current state, then every update, as server-sent events.
pub async fn events(State(s): State<Shared>) -> Response {
    let live = match device(&s) {
        Ok(live) => live,
        Err(r) => return *r,
    };
    let rx = live.tx.subscribe();
    let first: Vec<(String, Value)> = {
        let snap = live.shared.lock().expect("snapshot");
        let mut v = vec![
            ("identity".to_string(), snap.identity.clone()),
            ("mode".into(), snap.mode_state()),
            ("mag".into(), snap.mag.state()),
        ];
        if !snap.status.is_null() {
            v.push(("status".into(), snap.status.clone()));
        }
        if !snap.tables.is_null() {
            v.push(("tables".into(), snap.tables.clone()));
        }
        v.push((
            "history".into(),
            Value::Array(snap.stream.iter().cloned().collect()),
        ));
        v.push(("record".into(), record_state(&snap)));
        v.push(("accel".into(), snap.poses.state()));
        if let Some(e) = &snap.link_error {
            v.push(("link".into(), json!({ "error": e })));
        }
        v
    };
    let event = |(kind, v): (String, Value)| -> Result<SseEvent, Infallible> {
        Ok(SseEvent::default().event(kind).data(v.to_string()))
    };
    // a page that falls behind skips what it missed (the next update replaces it)
    let updates = BroadcastStream::new(rx).filter_map(|m| async move { m.ok() });
    let all: std::pin::Pin<Box<dyn Stream<Item = Result<SseEvent, Infallible>> + Send>> =
        Box::pin(stream::iter(first).chain(updates).map(event));
    Sse::new(all)
        .keep_alive(KeepAlive::default())
        .into_response()
}

fn record_state(s: &Snapshot) -> Value {
    match (&s.record, &s.finished) {
        (Some(r), _) => json!({
            "recording": true, "file": r.path.display().to_string(),
            "rows": r.rows.rows, "seconds": r.rows.span(),
        }),
        (None, Some((p, summary))) => json!({
            "recording": false, "file": p.display().to_string(), "summary": summary,
        }),
        (None, None) => json!({ "recording": false }),
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Empty {}

/// The body every live write takes: `{}` (anything else is a 400).
pub(super) fn empty(bytes: &Bytes) -> Option<Response> {
    super::noise::body::<Empty>(bytes)
        .err()
        .map(|e| error(StatusCode::BAD_REQUEST, &e))
}

/// The device behind the page, or 409 when serve was started on a recording.
pub(super) fn device(s: &Shared) -> Result<&Live, Box<Response>> {
    s.live.as_ref().ok_or_else(|| {
        Box::new(error(
            StatusCode::CONFLICT,
            "no device: started on a recording",
        ))
    })
}

/// A request to the device with an empty body: 400 for any other body, 409 without a device.
pub(super) fn device_post<'a>(s: &'a Shared, bytes: &Bytes) -> Result<&'a Live, Box<Response>> {
    if let Some(r) = empty(bytes) {
        return Err(Box::new(r));
    }
    device(s)
}

/// POST /api/live/record {}: start writing the stream to a new CSV in the recording directory
/// (a name the server chooses: the page cannot name a file).
pub async fn record(State(s): State<Shared>, bytes: Bytes) -> Response {
    let live = match device_post(&s, &bytes) {
        Ok(live) => live,
        Err(r) => return *r,
    };
    let mut snap = live.shared.lock().expect("snapshot");
    if snap.record.is_some() {
        return error(StatusCode::CONFLICT, "already recording");
    }
    let users = snap.raw_for();
    if !users.is_empty() {
        return error(
            StatusCode::CONFLICT,
            &format!(
                "the device streams raw values for {}: finish it first (a recording holds \
                 calibrated values)",
                users.join(" and ")
            ),
        );
    }
    let stamp = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs());
    let path = (0..1000)
        .map(|k| live.record_dir.join(format!("live-{stamp}-{k}.csv")))
        .find(|p| !p.exists());
    let Some(path) = path else {
        return error(StatusCode::CONFLICT, "no free recording name");
    };
    let opened = File::create(&path)
        .map_err(anyhow::Error::from)
        .and_then(|f| Ok(Writer::new(BufWriter::new(f), &COLUMNS, record::PRINT)?));
    let writer = match opened {
        Ok(w) => w,
        Err(e) => {
            return error(
                StatusCode::INTERNAL_SERVER_ERROR,
                &format!("creating {}: {e:#}", path.display()),
            )
        }
    };
    snap.record = Some(Recording {
        path,
        writer,
        rows: Rows::default(),
        held: Held::default(),
        losses: DeviceLosses::default(),
        failed: None,
    });
    let v = record_state(&snap);
    drop(snap);
    send(&live.tx, "record", v.clone());
    Json(v).into_response()
}

/// POST /api/live/stop {}: finish the recording (every row written) and say what it holds.
pub async fn stop(State(s): State<Shared>, bytes: Bytes) -> Response {
    let live = match device_post(&s, &bytes) {
        Ok(live) => live,
        Err(r) => return *r,
    };
    let mut snap = live.shared.lock().expect("snapshot");
    let Some(mut rec) = snap.record.take() else {
        return error(StatusCode::CONFLICT, "not recording");
    };
    let w = &mut rec.writer;
    let mut res = Ok(());
    rec.held.release(true, |r| {
        if res.is_ok() {
            res = w.row(&r.fields());
        }
    });
    let Recording {
        path,
        writer,
        rows,
        losses,
        failed,
        ..
    } = rec;
    let res = match failed {
        Some(e) => Err(std::io::Error::other(e)),
        None => res.and_then(|_| writer.finish().and_then(|mut f| f.flush())),
    };
    if let Err(e) = res {
        return error(
            StatusCode::INTERNAL_SERVER_ERROR,
            &format!("writing {}: {e}", path.display()),
        );
    }
    let summary = record::summary(&rows, &losses);
    snap.finished = Some((path, summary));
    let v = record_state(&snap);
    drop(snap);
    send(&live.tx, "record", v.clone());
    Json(v).into_response()
}

/// POST /api/live/open {}: the last finished recording in the noise lab.
pub async fn open_recording(State(s): State<Shared>, bytes: Bytes) -> Response {
    let live = match device_post(&s, &bytes) {
        Ok(live) => live,
        Err(r) => return *r,
    };
    let file = live
        .shared
        .lock()
        .expect("snapshot")
        .finished
        .as_ref()
        .map(|(p, _)| p.clone());
    let Some(file) = file else {
        return error(StatusCode::CONFLICT, "no finished recording yet");
    };
    match s.lab.set_file(file).await {
        Ok(()) => Json(s.lab.describe().await).into_response(),
        Err(e) => error(StatusCode::UNPROCESSABLE_ENTITY, &format!("{e:#}")),
    }
}

/// POST /api/live/mag/start {}: switch the device to raw values and collect the magnetometer's
/// field (the mean of every 0.1 s) for the calibration, from an empty set.
pub async fn mag_start(State(s): State<Shared>, bytes: Bytes) -> Response {
    mag_switch(s, bytes, true).await
}

/// POST /api/live/mag/stop {}: stop collecting (the points stay for the fit) and switch the
/// device back to calibrated values (unless another wizard still needs raw ones).
pub async fn mag_stop(State(s): State<Shared>, bytes: Bytes) -> Response {
    mag_switch(s, bytes, false).await
}

async fn mag_switch(s: Shared, bytes: Bytes, on: bool) -> Response {
    let live = match device_post(&s, &bytes) {
        Ok(live) => live,
        Err(r) => return *r,
    };
    {
        let mut snap = live.shared.lock().expect("snapshot");
        if on {
            if let Some(r) = snap.raw_refused() {
                return r;
            }
            snap.mag.clear();
        }
        snap.mag.on = on;
    }
    let switched = sync_mode(live).await;
    let mut snap = live.shared.lock().expect("snapshot");
    if let Err(e) = switched {
        if on {
            // no raw values: nothing collected
            snap.mag.on = false;
            send(&live.tx, "mode", snap.mode_state());
            return error(StatusCode::BAD_GATEWAY, &e);
        }
        let mut v = snap.mag.state();
        v["calibrated_again"] = json!(e);
        return Json(v).into_response();
    }
    Json(snap.mag.state()).into_response()
}

/// A request to the device through the link's reader, and its reply.
pub(super) async fn request(live: &Live, req: Request) -> Result<Reply, String> {
    let (tx, rx) = oneshot::channel();
    live.requests
        .lock()
        .expect("requests")
        .send((req, tx))
        .map_err(|_| "the link to the device is closed".to_string())?;
    rx.await
        .map_err(|_| "the link's reader stopped".to_string())?
}

/// Bring the device's stream to what the wizards need now ([`Snapshot::raw_for`]): raw values
/// while any needs them, calibrated otherwise; every page hears of it (`mode`). A failed switch
/// is returned (and tried again at the next change).
pub(super) async fn sync_mode(live: &Live) -> Result<(), String> {
    let mut mode = live.mode.lock().await;
    let (want, state) = {
        let snap = live.shared.lock().expect("snapshot");
        let raw = !snap.raw_for().is_empty();
        (
            if raw {
                StreamMode::Raw
            } else {
                StreamMode::Calibrated
            },
            snap.mode_state(),
        )
    };
    let res = if *mode == want {
        Ok(())
    } else {
        match request(live, Request::SetMode(want)).await {
            Ok(Reply::Ok) => {
                *mode = want;
                Ok(())
            }
            Ok(other) => Err(format!("the device refused SetMode({want:?}): {other:?}")),
            Err(e) => Err(format!("switching the device to {want:?} values: {e}")),
        }
    };
    send(&live.tx, "mode", state);
    res
}

/// The magnetometer wizard's method.
#[derive(Deserialize, Clone, Copy, Debug, Default, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum MagMethod {
    /// The full sphere (3-D): every point, the calibration lab's walk in 3-D.
    #[default]
    Sphere,
    /// The level turn (2-D, Jaime et al.): the points taken level, the planar problem.
    Level,
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct MagFitBody {
    #[serde(default)]
    method: MagMethod,
}

/// POST /api/live/mag/fit {"method": "sphere" | "level"} (`{}`: the sphere): the calibration
/// lab's walk on the points collected (what `imu-lab calibrate mag --auto --json` does on a
/// recording of them): the model, its parameters with σ, the residual, the diagnosis. The
/// level turn fits only the points taken level ([`super::level`]), as planar data in x–y.
pub async fn mag_fit(State(s): State<Shared>, bytes: Bytes) -> Response {
    let b: MagFitBody = match super::noise::body(&bytes) {
        Ok(b) => b,
        Err(e) => return error(StatusCode::BAD_REQUEST, &e),
    };
    let live = match device(&s) {
        Ok(live) => live,
        Err(r) => return *r,
    };
    // the sphere: the 0.1 s means; the level turn: the samples of the level windows (at the
    // magnetometer's rate)
    let (points, rate_hz, coverage, heading_coverage, level_windows, all) = {
        let snap = live.shared.lock().expect("snapshot");
        let m = &snap.mag;
        match b.method {
            MagMethod::Sphere => (
                m.points.iter().copied().collect::<Vec<[f64; 3]>>(),
                1.0 / WINDOW_S,
                m.coverage(),
                None,
                0,
                m.points.len(),
            ),
            MagMethod::Level => (
                m.level_samples.iter().copied().collect(),
                snap.identity["mag_rate_hz"].as_f64().unwrap_or(200.0),
                m.coverage(),
                Some(m.heading_coverage()),
                m.level_points().len(),
                m.points.len(),
            ),
        }
    };
    let enough = match b.method {
        MagMethod::Sphere => points.len() >= 20,
        MagMethod::Level => level_windows >= 20,
    };
    if !enough {
        return error(
            StatusCode::CONFLICT,
            &match b.method {
                MagMethod::Sphere => format!(
                    "{} magnetometer points: collect 20 at least, turning the board",
                    points.len()
                ),
                MagMethod::Level => format!(
                    "{level_windows} of the {all} magnetometer points were taken level (within \
                     {LEVEL_TILT_DEG}° of tilt, turning about the vertical only: under {} deg/s \
                     about x and y): collect 20 at least, turning the board flat",
                    super::level::LEVEL_RATE_DPS
                ),
            },
        );
    }
    let method = b.method;
    let fitted = tokio::task::spawn_blocking(move || {
        use imu_cal::session::{self as cal, Sensor};
        let col = |k: usize| points.iter().map(|p| p[k]).collect::<Vec<f64>>();
        let (x, y, z) = (col(0), col(1), col(2));
        // one segment: consecutive windows (a level turn's points skip the tilted ones, which
        // only the noise floor's second differences see)
        let segments = vec![std::ops::Range {
            start: 0,
            end: points.len(),
        }];
        let input = cal::Input {
            columns: vec![
                cal::Column {
                    name: "mx",
                    unit: "µT",
                    values: &x,
                },
                cal::Column {
                    name: "my",
                    unit: "µT",
                    values: &y,
                },
                cal::Column {
                    name: "mz",
                    unit: "µT",
                    values: &z,
                },
            ],
            rate_hz,
            segments: &segments,
            shown: "the page's magnetometer points",
        };
        let o = cal::Options {
            auto: true,
            ..cal::Options::new(Sensor::Mag)
        };
        let loaded = cal::prepare(&input, &o)?;
        let (plane, sd) = match &loaded.data {
            cal::Data::Mag(p) => (p.plane, p.principal_sd),
            _ => (None, [f64::NAN; 3]),
        };
        if method == MagMethod::Level && plane != Some([0, 1]) {
            return Err(shape_problem(method, plane, sd).unwrap_or_default());
        }
        let run = cal::run(&loaded, &o)?;
        let (v, mut fit) = calibration(&loaded, &run);
        if let Some(p) = shape_problem(method, plane, sd) {
            fit = Err(p);
        }
        Ok::<_, String>((v, fit))
    })
    .await;
    let (v, fit) = match fitted {
        Ok(Ok(t)) => t,
        Ok(Err(e)) => return error(StatusCode::UNPROCESSABLE_ENTITY, &e),
        Err(e) => return error(StatusCode::INTERNAL_SERVER_ERROR, &e.to_string()),
    };
    let (section, field) = match method {
        MagMethod::Sphere => (Section::Mag, v["params"]["field"].as_f64()),
        MagMethod::Level => (Section::MagPlane, None),
    };
    let upload = offer(live, fit, section, field).await;
    Json(json!({
        "method": match method { MagMethod::Sphere => "sphere", MagMethod::Level => "level" },
        "coverage": coverage,
        "heading_coverage": heading_coverage,
        "level_windows": level_windows,
        "level_tilt_deg": LEVEL_TILT_DEG,
        "level_rate_dps": super::level::LEVEL_RATE_DPS,
        "fit": v,
        "upload": upload,
    }))
    .into_response()
}

/// Why points of this shape (the plane the lab found in them, if any, and their principal
/// standard deviations, µT) cannot give the method's upload: the level turn needs a turn in
/// x–y; the sphere's points that lie in a plane (a turn about one axis) determine no
/// out-of-plane terms, and their upload would set the device's to zero and identity.
fn shape_problem(method: MagMethod, plane: Option<[usize; 2]>, sd: [f64; 3]) -> Option<String> {
    match (method, plane) {
        (MagMethod::Level, Some([0, 1])) | (MagMethod::Sphere, None) => None,
        (MagMethod::Level, _) => Some(format!(
            "the level points are not a turn in the x–y plane (principal s.d. \
             {:.2}/{:.2}/{:.2} µT): turn the board flat about its z axis through a full turn, \
             or fit the full sphere",
            sd[0], sd[1], sd[2]
        )),
        (MagMethod::Sphere, Some(_)) => Some(format!(
            "the points lie in a plane (principal s.d. {:.2}/{:.2}/{:.2} µT): a turn about one \
             axis does not determine the out-of-plane terms; choose the level turn (which keeps \
             them from the device) or turn the board through more orientations",
            sd[0], sd[1], sd[2]
        )),
    }
}

/// A fit's answer: the object `imu-lab calibrate --json` prints, and a calibration file with
/// this sensor's section set as `calibrate --out` writes it, through the plausibility checks
/// `imu-lab device calibrate --upload` applies — or why not.
pub(super) fn calibration(
    loaded: &imu_cal::session::Loaded,
    run: &imu_cal::session::Outcome,
) -> (Value, Result<imu_cal::file::CalFile, String>) {
    use imu_cal::session as cal;
    let v = serde_json::from_str(&cal::json_out(loaded, run)).unwrap_or(Value::Null);
    let file = cal::update_file(None, loaded, run)
        .and_then(|toml| imu_cal::file::CalFile::from_toml(&toml).map_err(|e| e.to_string()));
    (v, file)
}

/// The calibration the device uses now: its blob as sent, decoded, and where it came from.
pub(super) async fn device_calibration(
    live: &Live,
) -> Result<(Vec<u8>, imu_cal::device::Calibration, String), String> {
    match request(live, Request::GetCalibration).await {
        Ok(Reply::Calibration { blob, status }) => {
            let cal = imu_cal::device::decode_blob(&blob)
                .map_err(|e| format!("the device's calibration: {e}"))?;
            Ok((blob.to_vec(), cal, imu_link::device::format_cal(&status)))
        }
        Ok(other) => Err(format!("unexpected reply to GetCalibration: {other:?}")),
        Err(e) => Err(format!("reading the device's calibration: {e}")),
    }
}

/// GET /api/live/calibration: the calibration the device uses now (read from it), every
/// parameter in the calibration file's units, and where it came from.
pub async fn get_calibration(State(s): State<Shared>) -> Response {
    let live = match device(&s) {
        Ok(live) => live,
        Err(r) => return *r,
    };
    match device_calibration(live).await {
        Ok((_, cal, source)) => {
            let mut v = super::merge::physical_json(&cal);
            v["source"] = json!(source);
            Json(v).into_response()
        }
        Err(e) => error(StatusCode::BAD_GATEWAY, &e),
    }
}

/// Offer a plausible fit for upload: the device's calibration is read now and the fit merged
/// into it ([`super::merge`]: only the fitted part replaced), kept under a new one-time code
/// that the page shows with the confirmation; what the page is told: `{plausible, code,
/// replaces, keeps, device}` or `{plausible: false, problem}`. Anything else withdraws the last
/// offer.
pub(super) async fn offer(
    live: &Live,
    fit: Result<imu_cal::file::CalFile, String>,
    section: Section,
    field: Option<f64>,
) -> Value {
    let merged = match fit {
        Ok(file) => match device_calibration(live).await {
            Ok((device_blob, device, source)) => {
                super::merge::merge(&device, &file, section).map(|m| (m, device_blob, source))
            }
            Err(e) => Err(format!("{e}: nothing to merge the fit into")),
        },
        Err(e) => Err(e),
    };
    let mut snap = live.shared.lock().expect("snapshot");
    match merged {
        Ok((m, device_blob, source)) => {
            let code = super::guard::new_token()[..8].to_string();
            snap.ready_cal = Some(ReadyCal {
                cal: m.cal,
                blob: m.blob,
                device_blob,
                section,
                field,
                code: code.clone(),
            });
            json!({ "plausible": true, "code": code, "replaces": m.replaces, "keeps": m.keeps,
                    "device": source })
        }
        Err(problem) => {
            snap.ready_cal = None;
            json!({ "plausible": false, "problem": problem })
        }
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct UploadBody {
    /// The code the fit gave: the user's explicit confirmation of this calibration.
    confirm: String,
    /// Also write it to the device's flash (else RAM only, until a reset).
    persist: bool,
}

/// POST /api/live/upload {"confirm": CODE, "persist": false}: send the last fit's calibration
/// (either wizard's, merged into the device's) to the device, once, with the code its fit gave
/// (403 without it: nothing is written to a device without the user's confirmation of that
/// very calibration). The device's calibration is read again first: when it is no longer the
/// one the fit was merged into (uploaded from elsewhere meanwhile), 409 and nothing is sent.
pub async fn upload(State(s): State<Shared>, bytes: Bytes) -> Response {
    let b: UploadBody = match super::noise::body(&bytes) {
        Ok(b) => b,
        Err(e) => return error(StatusCode::BAD_REQUEST, &e),
    };
    let live = match device(&s) {
        Ok(live) => live,
        Err(r) => return *r,
    };
    let ready = {
        let mut snap = live.shared.lock().expect("snapshot");
        match &snap.ready_cal {
            None => return error(StatusCode::CONFLICT, "no plausible calibration fitted yet"),
            Some(c) if c.code != b.confirm => {
                return error(
                    StatusCode::FORBIDDEN,
                    "the confirmation code is not the one of the last fit: nothing uploaded",
                )
            }
            Some(_) => snap.ready_cal.take().expect("checked"),
        }
    };
    match device_calibration(live).await {
        Ok((now, _, _)) if now == ready.device_blob => {}
        Ok((_, _, source)) => {
            return error(
                StatusCode::CONFLICT,
                &format!(
                    "the device's calibration ({source}) changed since the fit was merged into \
                     it: nothing uploaded; fit again"
                ),
            )
        }
        Err(e) => return error(StatusCode::BAD_GATEWAY, &format!("{e}: nothing uploaded")),
    }
    let Ok(blob) = imu_proto::Vec::from_slice(&ready.blob) else {
        return error(StatusCode::UNPROCESSABLE_ENTITY, "the blob is too long");
    };
    match request(
        live,
        Request::SetCalibration {
            blob,
            persist: b.persist,
        },
    )
    .await
    {
        Ok(Reply::Ok) => {
            let mut snap = live.shared.lock().expect("snapshot");
            let field = match ready.section {
                Section::Mag => ready.field,
                Section::MagPlane => None,
                Section::Accel => snap.uploaded.and_then(|u| u.field),
            };
            snap.uploaded = Some(Uploaded {
                cal: ready.cal,
                field,
            });
            Json(json!({ "applied": true, "persisted": b.persist })).into_response()
        }
        Ok(Reply::Error(imu_proto::ErrorCode::BadCalibration(p))) => error(
            StatusCode::UNPROCESSABLE_ENTITY,
            &format!(
                "the device refused the calibration: {}",
                imu_link::device::cal_problem(&p)
            ),
        ),
        Ok(other) => error(
            StatusCode::BAD_GATEWAY,
            &format!("the device did not apply the calibration: {other:?}"),
        ),
        Err(e) => error(StatusCode::BAD_GATEWAY, &e),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn orientation(t_us: u64, heading_deg: f32) -> imu_proto::Orientation {
        imu_proto::Orientation {
            seq: 0,
            t_us,
            q: [1.0, 0.0, 0.0, 0.0],
            roll_deg: 1.0,
            pitch_deg: -2.0,
            heading_deg,
            state: imu_proto::AhrsState::Tracking,
        }
    }

    /// A window's point: each channel's mean, extremes and standard deviation (a random offset
    /// and spread); the heading averaged across north (358° and 4° give 1°, not 181°); a
    /// channel without values (no attitude estimate) is null.
    #[test]
    fn a_window_decimates_every_channel_and_the_heading_across_north() {
        let key = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .unwrap()
            .subsec_nanos();
        let (offset, spread) = (
            1e3 * f64::from(key % 1000) / 1000.0,
            0.1 + f64::from(key % 7),
        );
        let mut w = Window::new();
        let xs = [-1.0, 1.0, -1.0, 1.0];
        for (i, x) in xs.iter().enumerate() {
            let mut v = [None; 10];
            v[3] = Some(offset + spread * x);
            assert!(w.push(i as f64 * 1e-3, &v).is_none());
        }
        let p = w.point().unwrap();
        assert_eq!(p["n"], 4);
        let close = |v: &Value, x: f64| (v.as_f64().unwrap() - x).abs() < 1e-9 * (1.0 + x.abs());
        assert!(close(&p["mean"][3], offset), "key {key}: {p}");
        assert!(close(&p["sd"][3], spread), "key {key}: {p}");
        assert!(close(&p["min"][3], offset - spread) && close(&p["max"][3], offset + spread));
        assert!(p["mean"][0].is_null() && p["mean"][12].is_null());
        w.orientation(&[orientation(0, 358.0), orientation(5_000, 4.0)]);
        let p = w.point().unwrap();
        assert!(close(&p["mean"][12], 1.0), "{p}");
        assert!(
            close(&p["min"][12], -2.0) && close(&p["max"][12], 4.0),
            "{p}"
        );
        assert!(close(&p["sd"][12], 3.0), "{p}");
        assert!(close(&p["mean"][10], 1.0) && close(&p["mean"][11], -2.0));
        // the next window starts 0.1 s later and hands this one out
        assert!(w.push(0.1, &[Some(0.0); 10]).is_some());
    }

    /// The level turn needs a turn in x–y; a sphere's points in a plane get no upload (it
    /// would zero the out-of-plane terms), each with the shape named.
    #[test]
    fn points_of_the_wrong_shape_get_no_upload() {
        let sd = [25.0, 24.0, 0.05];
        assert_eq!(shape_problem(MagMethod::Level, Some([0, 1]), sd), None);
        assert_eq!(shape_problem(MagMethod::Sphere, None, sd), None);
        let side = shape_problem(MagMethod::Level, Some([0, 2]), sd).unwrap();
        assert!(side.contains("not a turn in the x–y plane") && side.contains("25.00/24.00/0.05"));
        assert!(shape_problem(MagMethod::Level, None, sd).is_some());
        let flat = shape_problem(MagMethod::Sphere, Some([0, 1]), sd).unwrap();
        assert!(
            flat.contains("lie in a plane") && flat.contains("level turn"),
            "{flat}"
        );
    }

    /// The level turn takes a window's samples only when the board was level and turned
    /// about the vertical: tilted windows (over 5°), windows turning about x or y (over
    /// 5 deg/s) and windows without an accelerometer mean are shown but not fitted; the heading
    /// coverage counts the level windows only.
    #[test]
    fn the_level_turn_takes_the_level_windows_only() {
        let key = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .unwrap()
            .subsec_nanos();
        let tilt = 0.1 + 4.8 * f64::from(key % 1000) / 1000.0;
        let mut m = MagPoints::default();
        for k in 0..36 {
            let a = f64::from(k * 10 + 5).to_radians();
            let p = [20.0 + 25.0 * a.cos(), -10.0 + 25.0 * a.sin(), -40.0];
            let samples = [p, [p[0] + 0.1, p[1], p[2]]];
            // a quarter of the turn level, the rest tilted, turning about x, or unknown
            let levelness = match k {
                0..=8 => Some((tilt, 1.0)),
                9..=17 => Some((10.0 - tilt, 1.0)),
                18..=26 => Some((tilt, 6.0)),
                _ => None,
            };
            m.push(p, levelness, &samples);
        }
        assert_eq!(m.points.len(), 36, "key {key}");
        assert_eq!(m.level_points().len(), 9, "key {key}");
        assert_eq!(m.level_samples.len(), 18, "key {key}");
        assert!(
            (m.heading_coverage() - 9.0 / 36.0).abs() < 1e-12,
            "key {key}: {}",
            m.heading_coverage()
        );
        m.clear();
        assert!(m.level_samples.is_empty() && m.points.is_empty() && m.tilts.is_empty());
    }

    /// Directions drawn at random around a random hard-iron offset: the whole sphere is covered;
    /// a turn in one plane covers only the equatorial band (12 of 72 bins).
    #[test]
    fn coverage_counts_the_directions_reached() {
        let key = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .unwrap()
            .as_nanos() as u64;
        let mut state = key | 1;
        let mut next = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        let c = [
            60.0 * next() - 30.0,
            60.0 * next() - 30.0,
            60.0 * next() - 30.0,
        ];
        let mut sphere = MagPoints::default();
        let mut circle = MagPoints::default();
        for _ in 0..4000 {
            let z = 2.0 * next() - 1.0;
            let a = 2.0 * std::f64::consts::PI * next();
            let r = (1.0 - z * z).sqrt();
            sphere.points.push_back([
                c[0] + 50.0 * r * a.cos(),
                c[1] + 50.0 * r * a.sin(),
                c[2] + 50.0 * z,
            ]);
            circle
                .points
                .push_back([c[0] + 50.0 * a.cos(), c[1] + 50.0 * a.sin(), c[2]]);
        }
        assert_eq!(sphere.coverage(), 1.0, "key {key}");
        assert!(
            (circle.coverage() - 12.0 / 72.0).abs() < 1e-12,
            "key {key}: {}",
            circle.coverage()
        );
        assert_eq!(MagPoints::default().coverage(), 0.0);
    }
}
