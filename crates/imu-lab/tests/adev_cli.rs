//! `imu-lab adev` end to end: both real recordings read through the documented flags, the JSON
//! contract, the bounded-memory mode, and refusals that name the line and the field.
use serde_json::Value;

mod common;
use common::{run, run_err, run_ok, static_449s, stdout_json, GZ_RAW};

fn unmoved() -> String {
    format!(
        "{}/tests/data/mpu6050-hmc5883l-unmoved-x/mpu6050.csv",
        env!("CARGO_MANIFEST_DIR")
    )
}

/// The flags that read its gx: the file's `t_s` and `gx_dps` under the contract's names.
const UNMOVED_GX: [&str; 4] = ["--column", "gx", "--rename", "t_s=t,gx_dps=gx"];

fn json(args: &[&str]) -> Value {
    stdout_json(&run_ok(args))
}

#[test]
fn raw_counts_with_metadata_lines_json_contract() {
    let f = static_449s();
    let args: Vec<&str> = ["adev", &f]
        .into_iter()
        .chain(GZ_RAW)
        .chain(["--json"])
        .collect();
    let v = json(&args);
    assert_eq!(v["column"], "gz");
    assert_eq!(v["unit"], "deg/s");
    assert_eq!(v["stat"], "oadev");
    assert_eq!(v["rate_hz"], 100.0);
    let rows = v["adev"].as_array().unwrap();
    assert_eq!(rows.len(), 15, "octave τ from 0.01 s to 163.84 s");
    // AllanTools 2024.06: 12.2424 LSB at τ = 0.01 s (shared/reference README), × 0.0076336 deg/s/LSB.
    let first = &rows[0];
    assert_eq!(first["m"], 1);
    assert_eq!(first["n"], 44_929);
    assert!((first["dev"].as_f64().unwrap() / (12.2424 * 0.0076336) - 1.0).abs() < 1e-5);
    for r in rows {
        let (lo, dev, hi) = (
            r["lo"].as_f64().unwrap(),
            r["dev"].as_f64().unwrap(),
            r["hi"].as_f64().unwrap(),
        );
        assert!(lo < dev && dev < hi, "{r}");
        assert!(r["edf"].as_f64().unwrap() > 0.0);
        assert!(r["tau_s"].as_f64().unwrap() > 0.0);
    }
}

#[test]
fn timestamped_recording_with_renamed_columns_derives_the_rate() {
    let f = unmoved();
    let more = ["--unit", "deg/s", "--json", "--stat", "ohdev"];
    let v = json(&[&["adev", &f][..], &UNMOVED_GX, &more].concat());
    let rate = v["rate_hz"].as_f64().unwrap();
    // (N − 1)/duration of this file, computed independently here.
    let text = std::fs::read_to_string(&f).unwrap();
    let t: Vec<f64> = text
        .lines()
        .skip(1)
        .map(|l| l.split(',').next().unwrap().parse().unwrap())
        .collect();
    let expect = (t.len() - 1) as f64 / (t[t.len() - 1] - t[0]);
    assert!((rate - expect).abs() < 1e-9, "{rate} vs {expect}");
    assert!((90.0..110.0).contains(&rate));
    assert_eq!(v["unit"], "deg/s");
    // Host read times of buffered samples: named as such, with the spacings that show it.
    let tm = &v["timing"];
    assert_eq!(tm["regularity"], "bursty");
    assert!(
        (tm["median_dt_s"].as_f64().unwrap() - 0.000889).abs() < 2e-6,
        "{tm}"
    );
    assert!(
        (tm["p95_dt_s"].as_f64().unwrap() - 0.0439).abs() < 2e-4,
        "{tm}"
    );
    assert_eq!(tm["gaps"], 0);
    assert!(v["adev"].as_array().unwrap().len() >= 8);
}

#[test]
fn bounded_mode_equals_exact_on_unit_stride_levels() {
    let f = static_449s();
    let base = [
        "adev",
        f.as_str(),
        "--column",
        "gx",
        "--skip-lines",
        "4",
        "--rate",
        "100",
        "--json",
    ];
    let exact = json(&base);
    let mut b = base.to_vec();
    b.push("--bounded");
    let bounded = json(&b);
    let (e, s) = (
        exact["adev"].as_array().unwrap(),
        bounded["adev"].as_array().unwrap(),
    );
    for k in 0..4 {
        assert_eq!(e[k]["n"], s[k]["n"]);
        let (a, b) = (e[k]["dev"].as_f64().unwrap(), s[k]["dev"].as_f64().unwrap());
        assert!((a / b - 1.0).abs() < 1e-12, "m = {}: {a} vs {b}", e[k]["m"]);
        assert_eq!(s[k]["estimator"], "exact");
    }
    assert_eq!(s[4]["estimator"], "stride-2");
}

#[test]
fn malformed_file_is_refused_naming_line_and_field() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("bad.csv");
    std::fs::write(&p, "t,gz\n0,1\n0.01,2\n0.02,oops\n").unwrap();
    let out = run(["adev", p.to_str().unwrap(), "--column", "gz"]);
    assert!(!out.status.success());
    assert!(out.stdout.is_empty());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("line 4") && err.contains("\"gz\"") && err.contains("oops"),
        "{err}"
    );
}

#[test]
fn bounded_mode_refuses_non_integer_counts() {
    let f = unmoved();
    let err = run_err([&["adev", &f][..], &UNMOVED_GX, &["--bounded"]].concat());
    assert!(
        err.contains("line 2") && err.contains("not an integer count"),
        "{err}"
    );
}

/// `imu-lab adev … | head`: the reader closes the pipe after two lines of a table of every τ;
/// the tool stops quietly with success instead of panicking on the closed stdout.
#[test]
fn a_reader_that_closes_the_pipe_early_is_no_panic() {
    use std::io::{BufRead, BufReader};
    use std::process::Stdio;
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("long.csv");
    let p = p.to_str().unwrap().to_string();
    common::simulate_gyro(&p, 7, &[] as &[&str]);
    let mut child = std::process::Command::new(assert_cmd::cargo::cargo_bin("imu-lab"))
        .args(["adev", &p, "--column", "gz", "--taus", "all"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut lines = BufReader::new(child.stdout.take().unwrap()).lines();
    for _ in 0..2 {
        lines.next().unwrap().unwrap();
    }
    drop(lines);
    let out = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!err.contains("panicked"), "{err}");
    assert!(out.status.success(), "{:?}: {err}", out.status);
}
