//! Bad and real-world input through `adev`, `fit` and `export`, as a user meets it: absurd
//! options are refused (quickly), time is read from `t` (gaps, duplicates, a wrong `--rate`),
//! and raw counts are never labelled in physical units.
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

mod common;
use common::{run, run_ok, static_449s, stdout_json, stdout_text};

/// A 100 Hz gz recording with `t`, written by `shift(row)` added to each stamp.
fn clock_file(dir: &Path, name: &str, rows: usize, shift: impl Fn(usize) -> f64) -> PathBuf {
    let mut s = String::from("t,gz\n");
    let mut state = 0x2545_f491u32;
    for i in 0..rows {
        state ^= state << 13;
        state ^= state >> 17;
        state ^= state << 5;
        let v = state as f64 / 4_294_967_296.0 - 0.5;
        s += &format!("{:.6},{v:.6}\n", i as f64 / 100.0 + shift(i));
    }
    let p = dir.join(name);
    std::fs::write(&p, s).unwrap();
    p
}

/// A `shift` for [`clock_file`]: the stamps from row `row` on moved `by` seconds later.
fn shifted_from(row: usize, by: f64) -> impl Fn(usize) -> f64 {
    move |i| if i >= row { by } else { 0.0 }
}

fn fails_with(args: &[&str], needles: &[&str]) -> String {
    let start = Instant::now();
    let out = run(args);
    let err = String::from_utf8_lossy(&out.stderr).to_string();
    assert!(!out.status.success(), "{args:?} succeeded: {err}");
    assert!(out.stdout.is_empty(), "{args:?}: no output on failure");
    for n in needles {
        assert!(err.contains(n), "{args:?}: {n:?} not in {err}");
    }
    assert!(!err.contains("NaN") && !err.contains("panicked"), "{err}");
    assert!(
        start.elapsed() < Duration::from_secs(30),
        "{args:?} took too long"
    );
    err
}

#[test]
fn absurd_rates_are_refused_before_any_fit() {
    let dir = tempfile::tempdir().unwrap();
    let f = clock_file(dir.path(), "c.csv", 3000, |_| 0.0);
    let f = f.to_str().unwrap();
    for r in ["1e300", "1e200", "1e-100", "1e-300"] {
        fails_with(
            &["fit", f, "--column", "gz", "--rate", r],
            &["--rate", "between 1e-3 Hz and 1e7 Hz"],
        );
    }
}

#[test]
fn a_rate_that_disagrees_with_t_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let f = clock_file(dir.path(), "c.csv", 3000, |_| 0.0);
    let f = f.to_str().unwrap();
    for r in ["102", "50"] {
        fails_with(
            &["adev", f, "--column", "gz", "--rate", r],
            &["disagrees with the time column", "100 Hz", "--ignore-time"],
        );
    }
    // Within 1 % it is the user's nominal rate; with --ignore-time any rate is taken as said.
    let v = stdout_json(&run_ok([
        "adev", f, "--column", "gz", "--rate", "100.4", "--json",
    ]));
    assert_eq!(v["rate_hz"], 100.4);
    let v = stdout_json(&run_ok([
        "adev",
        f,
        "--column",
        "gz",
        "--rate",
        "50",
        "--ignore-time",
        "--json",
    ]));
    assert_eq!(v["rate_hz"], 50.0);
}

#[test]
fn a_long_gap_splits_the_record_and_the_rate_stays() {
    let dir = tempfile::tempdir().unwrap();
    // 50 s of data at 100 Hz with a 1000 s hole in the middle.
    let f = clock_file(dir.path(), "gap.csv", 5000, shifted_from(2500, 1000.0));
    let f = f.to_str().unwrap();
    let out = run_ok(["adev", f, "--column", "gz", "--unit", "deg/s", "--json"]);
    let v = stdout_json(&out);
    assert!((v["rate_hz"].as_f64().unwrap() - 100.0).abs() < 1e-6, "{v}");
    assert_eq!(v["timing"]["gaps"], 1);
    assert!((v["timing"]["largest_gap_s"].as_f64().unwrap() - 1000.0).abs() < 1e-3);
    assert!((v["adev"][0]["tau_s"].as_f64().unwrap() - 0.01).abs() < 1e-12);
    // No difference spans the gap: 2 × (2500 − 1) terms at m = 1 (one record of 5000 would
    // have 4999).
    assert_eq!(v["adev"][0]["n"], 4998);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("1 gap(s)") && err.contains("2 segments"),
        "{err}"
    );
    // fit names the data's own length, 50 s, not the 1050 s span.
    let out = run_ok(["fit", f, "--column", "gz", "--unit", "deg/s"]);
    let text = stdout_text(&out);
    assert!(
        text.contains("5000 samples at 100.000 Hz (50.0 s)"),
        "{text}"
    );
}

#[test]
fn a_short_gap_leaves_every_tau_exact() {
    let dir = tempfile::tempdir().unwrap();
    let f = clock_file(dir.path(), "g.csv", 4000, shifted_from(1000, 0.49));
    let v = stdout_json(&run_ok([
        "adev",
        f.to_str().unwrap(),
        "--column",
        "gz",
        "--unit",
        "deg/s",
        "--json",
    ]));
    assert!((v["rate_hz"].as_f64().unwrap() - 100.0).abs() < 1e-6, "{v}");
    assert_eq!(v["timing"]["missing_samples"], 49);
    for r in v["adev"].as_array().unwrap() {
        let (tau, m) = (r["tau_s"].as_f64().unwrap(), r["m"].as_f64().unwrap());
        assert!((tau / (m * 0.01) - 1.0).abs() < 1e-9, "{r}");
    }
}

/// A recording as `imu-lab record` writes it: device stamps in µs, 1 kHz, with 32 samples lost
/// (a FIFO overflow) — once as today's stamps show it, once with the `gap_before` column of the
/// contract. Both read back at 1000 Hz with exactly that gap.
#[test]
fn a_recorded_gap_round_trips() {
    let dir = tempfile::tempdir().unwrap();
    for with_column in [false, true] {
        let mut s = String::from(if with_column {
            "t,gap_before,ax,ay,az,gx,gy,gz,mx,my,mz,temp\n"
        } else {
            "t,ax,ay,az,gx,gy,gz,mx,my,mz,temp\n"
        });
        let mut t_us = 1_000_000u64;
        for i in 0..3000u64 {
            let lost = if i == 1700 { 32 } else { 0 };
            t_us += 1000 * (1 + lost);
            let gap = if with_column {
                format!("{lost},")
            } else {
                String::new()
            };
            s += &format!(
                "{:.6},{gap}0.1,0.2,9.8,{},0.01,-0.02,20,-3,40,{}\n",
                t_us as f64 * 1e-6,
                (i % 5) as f64 * 0.01,
                if i % 10 == 0 {
                    String::new()
                } else {
                    "25.5".into()
                }
            );
        }
        let p = dir.path().join(format!("rec{with_column}.csv"));
        std::fs::write(&p, s).unwrap();
        let v = stdout_json(&run_ok([
            "adev",
            p.to_str().unwrap(),
            "--column",
            "gx",
            "--json",
        ]));
        assert!(
            (v["rate_hz"].as_f64().unwrap() - 1000.0).abs() < 1e-6,
            "{v}"
        );
        assert_eq!(v["unit"], "deg/s");
        let tm = &v["timing"];
        assert_eq!(
            (tm["gaps"].as_u64(), tm["missing_samples"].as_u64()),
            (Some(1), Some(32))
        );
        assert_eq!(tm["gap_list"][0]["row"], 1700);
        assert_eq!(tm["gap_list"][0]["reported"], with_column);
        assert_eq!(tm["regularity"], "regular");
    }
}

#[test]
fn duplicated_stamps_are_reported_and_duplicated_names_refused() {
    let dir = tempfile::tempdir().unwrap();
    let mut s = String::from("t,gz\n");
    for i in 0..2000 {
        s += &format!("{:.2},{}\n", i as f64 / 100.0, (i % 3) as f64 * 0.1);
        if i == 700 || i == 1200 {
            s += &format!("{:.2},{}\n", i as f64 / 100.0, (i % 3) as f64 * 0.1);
        }
    }
    let p = dir.path().join("dup.csv");
    std::fs::write(&p, s).unwrap();
    let out = run_ok(["adev", p.to_str().unwrap(), "--column", "gz", "--json"]);
    assert_eq!(stdout_json(&out)["timing"]["duplicates"], 2);
    assert!(String::from_utf8_lossy(&out.stderr).contains("2 duplicated stamps"));
    let p = dir.path().join("names.csv");
    std::fs::write(&p, "t,gx,gx\n0,1,2\n0.01,2,3\n0.02,1,1\n").unwrap();
    fails_with(
        &["adev", p.to_str().unwrap(), "--column", "gx"],
        &["line 1", "\"gx\" appears twice", "columns 2 and 3"],
    );
}

#[test]
fn empty_tau_tables_and_absurd_scales_are_errors() {
    let f = static_449s();
    let raw = ["--skip-lines", "4", "--rate", "100"];
    let mut a = vec!["adev", f.as_str(), "--column", "gz", "--taus", "999999"];
    a.extend(raw);
    fails_with(&a, &["no averaging time of --taus fits", "44930 samples"]);
    let mut a = vec!["adev", f.as_str(), "--column", "gz", "--scale", "1e308"];
    a.extend(raw);
    fails_with(&a, &["--scale 1e308"]);
}

/// The raw MPU-6050 file (counts, metadata lines above a contract-named header) read without
/// --scale: every output says LSB, none says deg/s.
#[test]
fn raw_counts_are_labelled_in_counts() {
    let f = static_449s();
    let raw = ["--column", "gz", "--skip-lines", "4", "--rate", "100"];
    let adev = |extra: &[&str]| {
        let mut a = vec!["adev", f.as_str()];
        a.extend(raw);
        a.extend(extra);
        run_ok(a)
    };
    assert_eq!(stdout_json(&adev(&["--json"]))["unit"], "LSB");
    let text = stdout_text(&adev(&[]));
    assert!(text.contains("[LSB]") && !text.contains("deg/s"), "{text}");
    let mut a = vec!["fit", f.as_str()];
    a.extend(raw);
    let v = stdout_json(&run_ok(a.iter().chain(&["--json"])));
    assert_eq!(v["unit"], "LSB");
    let text = stdout_text(&run_ok(a));
    assert!(
        text.contains("gz [LSB]") && !text.contains("deg/s"),
        "{text}"
    );
    // The same file with --scale: deg/s (the contract's unit for gz).
    let v = stdout_json(&run_ok(["adev", f.as_str()].iter().chain(&raw).chain(&[
        "--scale",
        "0.0076336",
        "--json",
    ])));
    assert_eq!(v["unit"], "deg/s");
}
