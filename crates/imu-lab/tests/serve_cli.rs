//! `imu-lab serve` over a real socket: it prints its URL, answers its own Host only, refuses a
//! malformed request line, serves nothing outside its files, and its exports are exactly what
//! `imu-lab fit … --json` and `--report` give for the command the page shows.
mod common;
use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::process::{Child, Command, Stdio};

use common::{run_ok, stdout_json};
use serde_json::Value;

/// The server, stopped when dropped.
struct Server {
    child: Child,
    addr: String,
}

impl Drop for Server {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn serve(file: &str) -> Server {
    serve_with(file, &[])
}

/// `imu-lab serve FILE OPTIONS… --listen 127.0.0.1:0`.
fn serve_with(file: &str, options: &[&str]) -> Server {
    let mut child = Command::new(assert_cmd::cargo::cargo_bin("imu-lab"))
        .args(["serve", file])
        .args(options)
        .args(["--listen", "127.0.0.1:0"])
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn()
        .unwrap();
    let mut line = String::new();
    BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    let addr = line
        .trim()
        .strip_prefix("imu-lab serve: http://")
        .and_then(|s| s.strip_suffix('/'))
        .unwrap_or_else(|| panic!("no URL in {line:?}"))
        .to_string();
    Server { child, addr }
}

/// One raw HTTP/1.1 exchange: the status code and the body (the server closes the connection).
fn exchange(addr: &str, request: &str) -> (u16, String) {
    let mut s = TcpStream::connect(addr).unwrap();
    s.write_all(request.as_bytes()).unwrap();
    let mut out = Vec::new();
    s.read_to_end(&mut out).unwrap();
    let text = String::from_utf8_lossy(&out).into_owned();
    let status = text
        .split(' ')
        .nth(1)
        .and_then(|c| c.parse().ok())
        .unwrap_or_else(|| panic!("no status in {text:?}"));
    let body = text.split_once("\r\n\r\n").map_or("", |(_, b)| b);
    (status, dechunk(body))
}

/// A chunked body joined (hyper chunks the bodies it does not know the length of).
fn dechunk(body: &str) -> String {
    let mut out = String::new();
    let mut rest = body;
    loop {
        let Some((len, tail)) = rest.split_once("\r\n") else {
            return body.to_string();
        };
        let Ok(n) = usize::from_str_radix(len.trim(), 16) else {
            return body.to_string();
        };
        if n == 0 {
            return out;
        }
        out.push_str(&tail[..n]);
        rest = &tail[n + 2..];
    }
}

fn get(addr: &str, path: &str) -> (u16, String) {
    exchange(
        addr,
        &format!("GET {path} HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\n\r\n"),
    )
}

fn post(addr: &str, token: &str, path: &str, body: &str) -> (u16, String) {
    exchange(
        addr,
        &format!(
            "POST {path} HTTP/1.1\r\nHost: {addr}\r\nOrigin: http://{addr}\r\nX-Imu-Lab-Token: {token}\r\n\
             Content-Type: application/json\r\nContent-Length: {}\r\nConnection: close\r\n\r\n{body}",
            body.len()
        ),
    )
}

fn key() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .as_nanos() as u64
        % 1_000_000
}

/// A simulated gyro record with a Gauss–Markov process hidden in it (τ_c between 0.2 and 0.6 s).
fn recording(dir: &std::path::Path, key: u64) -> String {
    let path = dir.join("rec.csv").to_string_lossy().into_owned();
    let tau_c = 0.2 + 0.4 * ((key % 97) as f64 / 96.0);
    run_ok([
        "simulate",
        "--rate",
        "100",
        "--samples",
        "30000",
        "--seed",
        &key.to_string(),
        "--columns",
        "gx",
        "--white",
        "5e-3",
        "--markov",
        &format!("0.02,{tau_c}"),
        "-o",
        &path,
    ]);
    path
}

#[test]
fn real_socket_rules_and_exports_equal_the_cli() {
    let key = key();
    let dir = tempfile::tempdir().unwrap();
    let file = recording(dir.path(), key);
    let srv = serve(&file);
    let a = srv.addr.as_str();
    assert!(a.starts_with("127.0.0.1:"), "{a}");

    let (st, page) = get(a, "/");
    assert_eq!(st, 200);
    assert!(
        page.contains("/assets/app.js") && !page.contains("http://") && !page.contains("https://")
    );
    // DNS rebinding: the same socket, another name
    let (st, _) = exchange(
        a,
        "GET /api/info HTTP/1.1\r\nHost: attacker.example\r\nConnection: close\r\n\r\n",
    );
    assert_eq!(st, 403);
    // traversal, raw on the wire
    for p in [
        "/assets/../../Cargo.toml",
        "/assets/..%2F..%2FCargo.toml",
        "/rec.csv",
    ] {
        assert_eq!(get(a, p).0, 404, "{p}");
    }
    // a request line that is not HTTP
    let (st, _) = exchange(a, "HELLO\r\n\r\n");
    assert_eq!(st, 400);

    let (st, info) = get(a, "/api/info");
    assert_eq!(st, 200);
    let info: Value = serde_json::from_str(&info).unwrap();
    let token = info["token"].as_str().unwrap().to_string();
    assert_eq!(token.len(), 32);
    assert_eq!(info["lab"]["columns"], serde_json::json!(["gx"]));

    // a write without the token: 403; with it twice, whatever the other: 403
    let (st, _) = post(a, "", "/api/lab/select", r#"{"column":"gx"}"#);
    assert_eq!(st, 403);
    for second in ["wrong", token.as_str()] {
        let (st, _) = post(
            a,
            &format!("{token}\r\nX-Imu-Lab-Token: {second}"),
            "/api/lab/select",
            r#"{"column":"gx"}"#,
        );
        assert_eq!(st, 403, "a second token {second:?}");
    }
    let (st, v0) = post(a, &token, "/api/lab/select", r#"{"column":"gx"}"#);
    assert_eq!(st, 200, "key {key}: {v0}");
    let v0: Value = serde_json::from_str(&v0).unwrap();
    assert_eq!(v0["command"], format!("imu-lab fit {file} --column gx"));
    let cli = stdout_json(&run_ok(["fit", &file, "--column", "gx", "--json"]));
    let (_, exported) = get(a, "/api/lab/export.json");
    assert_eq!(serde_json::from_str::<Value>(&exported).unwrap(), cli);
    // the named effect added by the page = `--add` on the command line
    let missing = v0["missing"].as_str().unwrap_or("markov").to_string();
    let (st, v1) = post(
        a,
        &token,
        "/api/lab/edit",
        &format!(r#"{{"add":"{missing}"}}"#),
    );
    assert_eq!(st, 200, "key {key}: {v1}");
    let v1: Value = serde_json::from_str(&v1).unwrap();
    assert_eq!(
        v1["command"],
        format!("imu-lab fit {file} --column gx --add {missing}")
    );
    let report = dir.path().join("cli.html");
    let cli = stdout_json(&run_ok([
        "fit",
        &file,
        "--column",
        "gx",
        "--add",
        &missing,
        "--json",
        "--report",
        report.to_str().unwrap(),
    ]));
    let (_, exported) = get(a, "/api/lab/export.json");
    assert_eq!(serde_json::from_str::<Value>(&exported).unwrap(), cli);
    let (_, html) = get(a, "/api/lab/report.html");
    assert_eq!(html, std::fs::read_to_string(&report).unwrap());
}

#[test]
fn a_missing_file_or_a_busy_port_is_refused_by_name() {
    let out = Command::new(assert_cmd::cargo::cargo_bin("imu-lab"))
        .args(["serve", "/nonexistent/rec.csv", "--listen", "127.0.0.1:0"])
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("/nonexistent/rec.csv"), "{err}");
    let taken = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let port = taken.local_addr().unwrap().to_string();
    let dir = tempfile::tempdir().unwrap();
    let file = recording(dir.path(), key());
    let out = Command::new(assert_cmd::cargo::cargo_bin("imu-lab"))
        .args(["serve", &file, "--listen", &port])
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains(&format!("--listen {port}")), "{err}");
}

/// A CSV that is not in the contract — a logger's line before the header, its own column names,
/// raw gyro counts — served with `imu-lab fit`'s options to read it: the page offers the
/// renamed column, fits it in deg/s and shows the command with those options, whose `--json`
/// equals the page's export; a field that is not a number is refused (400) naming the file, the
/// line and the column, as `imu-lab fit` names it.
#[test]
fn any_csv_fit_reads_is_served_with_its_options_and_a_bad_field_is_named() {
    let key = key();
    let dir = tempfile::tempdir().unwrap();
    let write = |name: &str, bad_line: Option<usize>| {
        let path = dir.path().join(name);
        let mut text = String::from("# logger v2, serial 0042\ntime_s,gyro_z_counts\n");
        let mut s = key | 1;
        for i in 0..4000 {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            // counts of a ±250 deg/s gyro: white noise of about 40 counts
            let v = (s % 161) as i64 - 80;
            if bad_line == Some(i + 3) {
                text.push_str(&format!("{:.2},abc\n", i as f64 / 100.0));
            } else {
                text.push_str(&format!("{:.2},{v}\n", i as f64 / 100.0));
            }
        }
        std::fs::write(&path, text).unwrap();
        path.to_string_lossy().into_owned()
    };
    let options = [
        "--skip-lines",
        "1",
        "--rename",
        "time_s=t,gyro_z_counts=gz",
        "--scale",
        "0.0076336",
    ];
    let file = write("logger.csv", None);
    let srv = serve_with(&file, &options);
    let a = srv.addr.as_str();
    let (st, info) = get(a, "/api/info");
    assert_eq!(st, 200, "{info}");
    let info: Value = serde_json::from_str(&info).unwrap();
    assert_eq!(info["lab"]["columns"], serde_json::json!(["gz"]), "{info}");
    let token = info["token"].as_str().unwrap();
    let (st, view) = post(a, token, "/api/lab/select", r#"{"column":"gz"}"#);
    assert_eq!(st, 200, "key {key}: {view}");
    let view: Value = serde_json::from_str(&view).unwrap();
    let command = view["command"].as_str().unwrap();
    for flag in [
        "--skip-lines 1",
        "--rename time_s=t,gyro_z_counts=gz",
        "--scale 0.0076336",
    ] {
        assert!(command.contains(flag), "{flag}: {command}");
    }
    assert_eq!(view["fit"]["unit"], "deg/s", "{}", view["fit"]);
    let mut args: Vec<&str> = vec!["fit", &file];
    args.extend(options);
    args.extend(["--column", "gz", "--json"]);
    let cli = stdout_json(&run_ok(&args));
    let (_, exported) = get(a, "/api/lab/export.json");
    assert_eq!(serde_json::from_str::<Value>(&exported).unwrap(), cli);
    drop(srv);

    let line = 3 + (key % 3000) as usize;
    let bad = write("bad.csv", Some(line));
    let srv = serve_with(&bad, &options);
    let a = srv.addr.as_str();
    let (_, info) = get(a, "/api/info");
    let info: Value = serde_json::from_str(&info).unwrap();
    let (st, resp) = post(
        a,
        info["token"].as_str().unwrap(),
        "/api/lab/select",
        r#"{"column":"gz"}"#,
    );
    assert_eq!(st, 400, "{resp}");
    let err: Value = serde_json::from_str(&resp).unwrap();
    let err = err["error"].as_str().unwrap();
    assert!(
        err.contains("bad.csv")
            && err.contains(&format!("line {line}"))
            && err.contains("\"gz\" (column 2)"),
        "line {line}: {err}"
    );
}
