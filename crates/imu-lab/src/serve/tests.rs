//! The server's rules, request by request straight into the router (no socket): Host, Origin,
//! token, traversal, malformed bodies — and that a refused request changes nothing.
use std::io::Write;
use std::sync::Arc;

use axum::body::Body;
use axum::http::{Request, StatusCode};
use serde_json::Value;
use tower::ServiceExt;

use super::*;

const HOST: &str = "127.0.0.1:8750";
const TOKEN: &str = "0123456789abcdef0123456789abcdef";

/// A contract CSV of white noise (σ drawn at random) at 100 Hz in deg/s, `n` rows.
/// A uniform (0, 1) generator keyed by the clock, for the serve modules' randomized tests (the
/// key is printed on failure).
pub(super) fn rng() -> (u64, impl FnMut() -> f64) {
    let key = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .as_nanos() as u64;
    let mut s = key | 1;
    (key, move || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        ((s >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    })
}

fn recording(n: usize) -> (tempfile::NamedTempFile, u64) {
    let key = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .as_nanos() as u64;
    let mut state = key | 1;
    let mut next = || {
        // xorshift64*: uniform in (0, 1)
        state ^= state >> 12;
        state ^= state << 25;
        state ^= state >> 27;
        ((state.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    };
    let sigma = 0.01 + 0.05 * next();
    let mut f = tempfile::Builder::new().suffix(".csv").tempfile().unwrap();
    writeln!(f, "t,gx,gy").unwrap();
    for i in 0..n {
        // Box–Muller
        let (u, v) = (next(), next());
        let r = (-2.0 * u.ln()).sqrt();
        let a = 2.0 * std::f64::consts::PI * v;
        writeln!(
            f,
            "{:.4},{:.9},{:.9}",
            i as f64 / 100.0,
            sigma * r * a.cos(),
            sigma * r * a.sin()
        )
        .unwrap();
    }
    f.flush().unwrap();
    (f, key)
}

fn app(file: &std::path::Path) -> Router {
    router(Arc::new(AppState {
        listen: HOST.parse().unwrap(),
        token: TOKEN.into(),
        lab: noise::Lab::open(crate::input::InputArgs::for_file(file)).unwrap(),
        live: None,
    }))
}

fn get(path: &str) -> Request<Body> {
    Request::get(path)
        .header("host", HOST)
        .body(Body::empty())
        .unwrap()
}

fn post(path: &str) -> axum::http::request::Builder {
    Request::post(path)
        .header("host", HOST)
        .header("origin", format!("http://{HOST}"))
        .header("content-type", "application/json")
        .header(guard::TOKEN_HEADER, TOKEN)
}

async fn send(app: &Router, req: Request<Body>) -> (StatusCode, String) {
    let r = app.clone().oneshot(req).await.unwrap();
    let status = r.status();
    let bytes = axum::body::to_bytes(r.into_body(), 1 << 24).await.unwrap();
    (status, String::from_utf8_lossy(&bytes).into_owned())
}

async fn lab_view(app: &Router) -> String {
    let (st, body) = send(app, get("/api/lab")).await;
    assert_eq!(st, StatusCode::OK);
    body
}

#[tokio::test]
async fn host_must_be_the_listening_address() {
    let (f, _) = recording(500);
    let app = app(f.path());
    for (host, want) in [
        (Some(HOST), StatusCode::OK),
        (Some("localhost:8750"), StatusCode::OK),
        (Some("LOCALHOST:8750"), StatusCode::OK),
        (Some("evil.example:8750"), StatusCode::FORBIDDEN),
        (Some("evil.example"), StatusCode::FORBIDDEN),
        (Some("127.0.0.1:8751"), StatusCode::FORBIDDEN),
        (Some("127.0.0.1"), StatusCode::FORBIDDEN),
        (None, StatusCode::FORBIDDEN),
    ] {
        let mut b = Request::get("/api/info");
        if let Some(h) = host {
            b = b.header("host", h);
        }
        let (st, body) = send(&app, b.body(Body::empty()).unwrap()).await;
        assert_eq!(st, want, "Host {host:?}: {body}");
        // the token is only ever given to a request for the right Host
        assert_eq!(body.contains(TOKEN), want == StatusCode::OK, "{body}");
    }
}

#[tokio::test]
async fn writes_from_another_origin_or_without_the_token_are_refused_and_change_nothing() {
    let (f, _) = recording(500);
    let app = app(f.path());
    let body = r#"{"column":"gx"}"#;
    let cases: Vec<(Request<Body>, &str)> = vec![
        (
            post("/api/lab/select")
                .header("origin", "http://evil.example")
                .body(body.into())
                .unwrap(),
            "two Origins, one of them another site",
        ),
        (
            Request::post("/api/lab/select")
                .header("host", HOST)
                .header("origin", "http://evil.example")
                .header(guard::TOKEN_HEADER, TOKEN)
                .body(body.into())
                .unwrap(),
            "another origin only",
        ),
        (
            Request::post("/api/lab/select")
                .header("host", HOST)
                .header("origin", "null")
                .header(guard::TOKEN_HEADER, TOKEN)
                .body(body.into())
                .unwrap(),
            "an opaque origin",
        ),
        (
            Request::post("/api/lab/select")
                .header("host", HOST)
                .header("sec-fetch-site", "cross-site")
                .header(guard::TOKEN_HEADER, TOKEN)
                .body(body.into())
                .unwrap(),
            "cross-site fetch",
        ),
        (
            Request::post("/api/lab/select")
                .header("host", HOST)
                .header("origin", format!("http://{HOST}"))
                .body(body.into())
                .unwrap(),
            "no token",
        ),
        (
            Request::post("/api/lab/select")
                .header("host", HOST)
                .header(guard::TOKEN_HEADER, "0123456789abcdef0123456789abcdee")
                .body(body.into())
                .unwrap(),
            "a wrong token",
        ),
        (
            Request::post("/api/lab/select")
                .header("host", "evil.example:8750")
                .header(guard::TOKEN_HEADER, TOKEN)
                .body(body.into())
                .unwrap(),
            "another Host",
        ),
    ];
    for (req, what) in cases {
        let (st, resp) = send(&app, req).await;
        assert_eq!(st, StatusCode::FORBIDDEN, "{what}: {resp}");
        assert_eq!(lab_view(&app).await, "null", "{what} changed the lab");
    }
    // the page's own write goes through (with and without an Origin: curl sends none)
    let (st, resp) = send(&app, post("/api/lab/select").body(body.into()).unwrap()).await;
    assert_eq!(st, StatusCode::OK, "{resp}");
    assert_ne!(lab_view(&app).await, "null");
}

#[tokio::test]
async fn nothing_outside_the_embedded_files_is_served() {
    let (f, _) = recording(500);
    let app = app(f.path());
    for path in [
        "/assets/../Cargo.toml",
        "/assets/..%2f..%2fCargo.toml",
        "/assets/%2e%2e%2fsrc%2fmain.rs",
        "/assets/..%5c..%5cCargo.toml",
        "/../../../../etc/passwd",
        "/etc/passwd",
        "/assets/app.js/../../main.rs",
        "/assets/",
        "/assets/APP.JS",
        "/api/lab/../../../etc/passwd",
        "/index.html",
    ] {
        let (st, body) = send(&app, get(path)).await;
        assert_eq!(st, StatusCode::NOT_FOUND, "{path}: {body}");
        assert!(
            !body.contains("[package]") && !body.contains("root:"),
            "{path}"
        );
    }
    // the recording itself is not a page either
    let name = f.path().to_string_lossy().into_owned();
    let (st, _) = send(&app, get(&format!("/assets/{name}"))).await;
    assert_eq!(st, StatusCode::NOT_FOUND);
    for (name, ty) in [
        ("app.js", "text/javascript"),
        ("style.css", "text/css"),
        ("uPlot.iife.min.js", "text/javascript"),
        ("uPlot.min.css", "text/css"),
    ] {
        let r = app
            .clone()
            .oneshot(get(&format!("/assets/{name}")))
            .await
            .unwrap();
        assert_eq!(r.status(), StatusCode::OK, "{name}");
        assert!(r.headers()["content-type"]
            .to_str()
            .unwrap()
            .starts_with(ty));
    }
    let r = app.clone().oneshot(get("/")).await.unwrap();
    assert_eq!(r.status(), StatusCode::OK);
    let csp = r.headers()["content-security-policy"].to_str().unwrap();
    assert!(csp.contains("default-src 'self'"), "{csp}");
}

#[tokio::test]
async fn malformed_requests_get_400_and_change_nothing() {
    let (f, key) = recording(3000);
    let app = app(f.path());
    let ok = r#"{"column":"gx"}"#;
    let (st, resp) = send(&app, post("/api/lab/select").body(ok.into()).unwrap()).await;
    assert_eq!(st, StatusCode::OK, "key {key}: {resp}");
    let before = lab_view(&app).await;
    for (path, body) in [
        ("/api/lab/select", "{"),
        ("/api/lab/select", ""),
        ("/api/lab/select", "[]"),
        ("/api/lab/select", r#"{"column":5}"#),
        ("/api/lab/select", r#"{"column":"gx","extra":1}"#),
        ("/api/lab/select", r#"{"column":"nope"}"#),
        ("/api/lab/select", r#"{"column":"t"}"#),
        ("/api/lab/select", r#"{"column":"../../etc/passwd"}"#),
        ("/api/lab/edit", r#"{}"#),
        ("/api/lab/edit", r#"{"add":"nonsense"}"#),
        ("/api/lab/edit", r#"{"add":"bias_step"}"#),
        ("/api/lab/edit", r#"{"add":"markov","remove":"white"}"#),
        ("/api/lab/edit", r#"{"add":["markov"]}"#),
        ("/api/lab/edit", "\u{0}\u{1}"),
        ("/api/lab/auto", r#"{"steps":3}"#),
        ("/api/lab/auto", "nope"),
        ("/api/lab/reset", "{"),
        ("/api/live/upload", r#"{"confirm":"0123abcd"}"#),
        (
            "/api/live/upload",
            r#"{"confirm":"0123abcd","persist":"yes"}"#,
        ),
        ("/api/live/upload", r#"{"persist":false}"#),
        ("/api/live/accel/capture", r#"{"pose":3}"#),
        ("/api/live/accel/capture", r#"{}"#),
        ("/api/live/accel/merge", r#"{"a":0}"#),
        ("/api/live/accel/merge", r#"{"a":0,"b":-1}"#),
        ("/api/live/accel/remove", r#"{"index":"first"}"#),
        ("/api/live/accel/fit", r#"{"model":"offset"}"#),
        ("/api/live/verify/start", r#"{"seconds":30}"#),
        ("/api/live/verify/stop", "stop"),
        ("/api/live/record", r#"{"file":"/etc/passwd"}"#),
        ("/api/live/mag/start", "x"),
        ("/api/live/mag/fit", r#"{"method":"cube"}"#),
        ("/api/live/mag/fit", r#"{"method":"level","points":5}"#),
        ("/api/live/mag/fit", "level"),
    ] {
        let (st, resp) = send(&app, post(path).body(body.to_string().into()).unwrap()).await;
        assert_eq!(st, StatusCode::BAD_REQUEST, "{path} {body:?}: {resp}");
        let j: Value = serde_json::from_str(&resp).unwrap();
        assert!(!j["error"].as_str().unwrap().is_empty());
        assert_eq!(
            lab_view(&app).await,
            before,
            "{path} {body:?} changed the lab"
        );
    }
}

/// The page's edits: add, remove and the walk each add rows to the step table, the view says
/// the command that gives the same session, and the exports are that session's.
#[tokio::test]
async fn edits_grow_the_step_table_and_exports_follow_the_session() {
    let (f, key) = recording(4000);
    let app = app(f.path());
    let send_json = |path: &'static str, body: &'static str| {
        let app = app.clone();
        async move {
            let (st, resp) = send(&app, post(path).body(body.into()).unwrap()).await;
            assert_eq!(st, StatusCode::OK, "key {key}: {path} {body}: {resp}");
            serde_json::from_str::<Value>(&resp).unwrap()
        }
    };
    let v0 = send_json("/api/lab/select", r#"{"column":"gy"}"#).await;
    assert_eq!(v0["steps"].as_array().unwrap().len(), 0);
    assert_eq!(v0["fit"]["column"], "gy");
    assert!(v0["effects"]
        .as_array()
        .unwrap()
        .iter()
        .any(|e| e == "white"));
    let v1 = send_json("/api/lab/edit", r#"{"add":"markov"}"#).await;
    let steps = v1["steps"].as_array().unwrap();
    assert_eq!(steps.len(), 1);
    assert!(steps[0]["edit"].as_str().unwrap().contains("markov"));
    // the step's "before" is the model shown before it
    let c0 = v0["chi2_dof"].as_f64().unwrap();
    let b1 = steps[0]["chi2_dof_before"].as_f64().unwrap();
    assert!((b1 / c0 - 1.0).abs() < 1e-9, "{b1} vs {c0}");
    assert!(v1["effects"]
        .as_array()
        .unwrap()
        .iter()
        .any(|e| e == "markov"));
    assert!(v1["command"].as_str().unwrap().ends_with("--add markov"));
    // adding an effect the model has (and may hold once) is refused without a change
    let (st, _) = send(
        &app,
        post("/api/lab/edit")
            .body(r#"{"add":"white"}"#.into())
            .unwrap(),
    )
    .await;
    assert_eq!(st, StatusCode::CONFLICT);
    let now: Value = serde_json::from_str(&lab_view(&app).await).unwrap();
    assert!(now == v1, "a refused edit changed the lab");
    let v2 = send_json("/api/lab/edit", r#"{"remove":"markov"}"#).await;
    assert_eq!(v2["steps"].as_array().unwrap().len(), 2);
    assert!(!v2["effects"]
        .as_array()
        .unwrap()
        .iter()
        .any(|e| e == "markov"));
    assert_eq!(v2["steps"][1]["edit"], "− markov");
    // the JSON export is the session of the view
    let (st, exported) = send(&app, get("/api/lab/export.json")).await;
    assert_eq!(st, StatusCode::OK);
    let e: Value = serde_json::from_str(&exported).unwrap();
    assert!(e == v2["fit"], "the export is not the view's session");
    let (st, html) = send(&app, get("/api/lab/report.html")).await;
    assert_eq!(st, StatusCode::OK);
    assert!(html.starts_with("<!DOCTYPE html>") && html.contains("gy [deg/s]"));
    let v3 = send_json("/api/lab/reset", "{}").await;
    assert_eq!(v3["steps"].as_array().unwrap().len(), 0);
    assert!(
        v3["fit"] == v0["fit"],
        "reset does not give the start model back"
    );
}

/// A read while a write holds the lab (a fit of seconds) answers at once with the view the
/// last write published, and the exports with its session; the write's own result follows.
#[tokio::test]
async fn reads_do_not_wait_for_a_running_fit() {
    let (f, key) = recording(3000);
    let state = Arc::new(AppState {
        listen: HOST.parse().unwrap(),
        token: TOKEN.into(),
        lab: noise::Lab::open(crate::input::InputArgs::for_file(f.path())).unwrap(),
        live: None,
    });
    let app = router(state.clone());
    let (st, v0) = send(
        &app,
        post("/api/lab/select")
            .body(r#"{"column":"gx"}"#.into())
            .unwrap(),
    )
    .await;
    assert_eq!(st, StatusCode::OK, "key {key}: {v0}");
    let v0: Value = serde_json::from_str(&v0).unwrap();
    // What a running fit does to the lab: hold its state.
    let held = state.lab.hold().await;
    let within = |path: &'static str| {
        let app = app.clone();
        async move {
            tokio::time::timeout(std::time::Duration::from_secs(20), send(&app, get(path)))
                .await
                .unwrap_or_else(|_| panic!("key {key}: GET {path} waited for the fit"))
        }
    };
    let (st, view) = within("/api/lab").await;
    assert_eq!(st, StatusCode::OK);
    assert!(serde_json::from_str::<Value>(&view).unwrap() == v0);
    let (st, exported) = within("/api/lab/export.json").await;
    assert_eq!(st, StatusCode::OK);
    assert!(serde_json::from_str::<Value>(&exported).unwrap() == v0["fit"]);
    let (st, html) = within("/api/lab/report.html").await;
    assert_eq!(st, StatusCode::OK);
    assert!(html.contains("gx ["), "key {key}");
    // A write waits for the one before it, then answers with its own result.
    let edit = {
        let app = app.clone();
        tokio::spawn(async move {
            send(
                &app,
                post("/api/lab/edit")
                    .body(r#"{"add":"markov"}"#.into())
                    .unwrap(),
            )
            .await
        })
    };
    tokio::time::sleep(std::time::Duration::from_millis(50)).await;
    assert!(
        !edit.is_finished(),
        "an edit did not wait for the fit before it"
    );
    drop(held);
    let (st, v1) = edit.await.unwrap();
    assert_eq!(st, StatusCode::OK, "key {key}: {v1}");
    let v1: Value = serde_json::from_str(&v1).unwrap();
    assert!(serde_json::from_str::<Value>(&lab_view(&app).await).unwrap() == v1);
    assert_eq!(v1["steps"].as_array().unwrap().len(), 1);
}
