//! `imu-lab serve`: the lab as a local web app. An axum server on a loopback address serves one
//! page (HTML, script, style and the vendored plotting library, all embedded in the binary) and
//! a small JSON API over the library sessions: the noise lab ([`noise`]) on a recording, and the
//! live device ([`live`]) over the same link `imu-lab record` uses, with the calibration
//! wizards (the magnetometer's sphere or level turn, [`level`]; the accelerometer's poses,
//! [`poses`]; fits with `imu_cal::session`, uploads merged into the device's calibration,
//! [`merge`], after an explicit confirmation; the verification, [`verify`]).
//!
//! Safe by default ([`guard`]): it binds to 127.0.0.1, answers only requests whose `Host` is the
//! address it listens on (DNS rebinding), refuses writes from another origin (403) and writes
//! without the token the page obtains from `/api/info` (403), writes to the device without the
//! one-time code of the calibration confirmed (403), serves only its embedded assets (anything
//! else 404) and refuses malformed requests with 400 before changing anything.
use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::Arc;

use anyhow::{Context, Result};
use axum::extract::State;
use axum::http::{header, HeaderValue, StatusCode};
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post};
use axum::{Json, Router};
use serde_json::json;

pub mod assets;
pub mod guard;
pub mod level;
pub mod live;
pub mod merge;
pub mod noise;
pub mod poses;
#[cfg(test)]
mod tests;
pub mod verify;

/// What the server was given: a recording, or a device port.
pub enum Source {
    /// A CSV recording and `imu-lab fit`'s options to read it (the noise lab).
    File(crate::input::InputArgs),
    /// A device link (`/dev/ttyACM0`, `tcp:HOST:PORT`): the live page; recordings go into
    /// `record_dir`, each then open in the noise lab.
    Port { port: String, record_dir: PathBuf },
}

/// The server's shared state.
pub struct AppState {
    /// The address the server listens on (the only `Host` it answers).
    pub listen: SocketAddr,
    /// The write token the page obtains from `/api/info`.
    pub token: String,
    pub lab: noise::Lab,
    /// The device (live mode).
    pub live: Option<live::Live>,
}

pub type Shared = Arc<AppState>;

impl AppState {
    /// The state for `source` at `listen` (a port source starts the device reader).
    pub fn new(listen: SocketAddr, source: Source) -> Result<AppState> {
        let (lab, live) = match source {
            Source::File(file) => (noise::Lab::open(file)?, None),
            Source::Port { port, record_dir } => (
                noise::Lab::empty(),
                Some(live::Live::start(port, record_dir)?),
            ),
        };
        Ok(AppState {
            listen,
            token: guard::new_token(),
            lab,
            live,
        })
    }
}

/// Every route, behind the guard.
pub fn router(state: Shared) -> Router {
    Router::new()
        .route("/", get(assets::index))
        .route("/assets/{name}", get(assets::asset))
        .route("/favicon.ico", get(assets::no_icon))
        .route("/api/info", get(info))
        .route("/api/lab", get(noise::view))
        .route("/api/lab/select", post(noise::select))
        .route("/api/lab/edit", post(noise::edit))
        .route("/api/lab/auto", post(noise::auto))
        .route("/api/lab/reset", post(noise::reset))
        .route("/api/lab/export.json", get(noise::export_json))
        .route("/api/lab/report.html", get(noise::export_report))
        .route("/api/live/events", get(live::events))
        .route("/api/live/record", post(live::record))
        .route("/api/live/stop", post(live::stop))
        .route("/api/live/open", post(live::open_recording))
        .route("/api/live/mag/start", post(live::mag_start))
        .route("/api/live/mag/stop", post(live::mag_stop))
        .route("/api/live/mag/fit", post(live::mag_fit))
        .route("/api/live/accel/capture", post(poses::capture))
        .route("/api/live/accel/cancel", post(poses::cancel))
        .route("/api/live/accel/merge", post(poses::merge))
        .route("/api/live/accel/remove", post(poses::remove))
        .route("/api/live/accel/clear", post(poses::clear))
        .route("/api/live/accel/fit", post(poses::fit))
        .route("/api/live/upload", post(live::upload))
        .route("/api/live/calibration", get(live::get_calibration))
        .route("/api/live/verify/start", post(verify::start))
        .route("/api/live/verify/stop", post(verify::stop))
        .fallback(not_found)
        .layer(axum::middleware::from_fn_with_state(
            state.clone(),
            guard::check,
        ))
        .with_state(state)
}

/// What the page needs first: the mode, the write token, the recording and its columns, the
/// vocabulary of effects a click may add or remove.
async fn info(State(s): State<Shared>) -> Response {
    let lab = s.lab.describe().await;
    Json(json!({
        "mode": if s.live.is_some() { "live" } else { "file" },
        "port": s.live.as_ref().map(|l| l.port.clone()),
        "token": s.token,
        "listen": s.listen.to_string(),
        "version": env!("CARGO_PKG_VERSION"),
        "lab": lab,
        "vocabulary": noise::vocabulary(),
    }))
    .into_response()
}

async fn not_found() -> Response {
    error(StatusCode::NOT_FOUND, "no such page or file")
}

/// An error answer: the status and a JSON object `{"error": message}`.
pub fn error(status: StatusCode, message: &str) -> Response {
    let mut r = (status, Json(json!({ "error": message }))).into_response();
    r.headers_mut()
        .insert(header::CACHE_CONTROL, HeaderValue::from_static("no-store"));
    r
}

/// Serve until Ctrl-C: bind `listen`, print the URL, answer; on a device left on raw values by
/// a wizard, switch it back to calibrated ones before exiting.
pub fn serve(listen: SocketAddr, source: Source) -> Result<()> {
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .context("starting the server's runtime")?;
    let r = rt.block_on(async move {
        let listener = tokio::net::TcpListener::bind(listen)
            .await
            .with_context(|| format!("--listen {listen}: cannot bind"))?;
        let bound = listener.local_addr()?;
        let state = Arc::new(AppState::new(bound, source)?);
        if !bound.ip().is_loopback() {
            eprintln!(
                "warning: listening on {bound}, not a loopback address: anyone who can reach it \
                 can read the page (writes still need the page's token)"
            );
        }
        // the URL on stdout, alone on its line, for people and for scripts that start the server
        println!("imu-lab serve: http://{bound}/");
        use std::io::Write;
        let _ = std::io::stdout().flush();
        let server = axum::serve(listener, router(state.clone()));
        let Some(live) = state.live.as_ref() else {
            return server.await.context("serving");
        };
        // Ctrl-C with the device on raw values for a wizard: calibrated values again first
        let (tx, mut rx) = tokio::sync::mpsc::unbounded_channel();
        ctrlc::set_handler(move || {
            let _ = tx.send(());
        })
        .context("setting the Ctrl-C handler")?;
        tokio::select! {
            r = async { server.await } => r.context("serving"),
            _ = rx.recv() => {
                live.calibrated_on_exit().await;
                Ok(())
            }
        }
    });
    // a fit still running on a blocking thread is not waited for
    rt.shutdown_timeout(std::time::Duration::from_secs(1));
    r
}
