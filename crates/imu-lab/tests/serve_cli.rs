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
    let mut child = Command::new(assert_cmd::cargo::cargo_bin("imu-lab"))
        .args(["serve", file, "--listen", "127.0.0.1:0"])
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

    // a write without the token: 403
    let (st, _) = post(a, "", "/api/lab/select", r#"{"column":"gx"}"#);
    assert_eq!(st, 403);
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
