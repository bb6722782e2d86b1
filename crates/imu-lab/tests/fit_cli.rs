//! `imu-lab fit` end to end on the real MPU-6050 recording: the JSON contract, the verdict, and
//! the pictures in both formats.
mod common;
use common::{run_err, run_ok, simulate_gyro, static_449s, stdout_json, GZ_RAW};
use serde_json::Value;

/// The term of `effect` in a fit's JSON.
#[track_caller]
fn term<'a>(v: &'a Value, effect: &str) -> &'a Value {
    v["terms"]
        .as_array()
        .unwrap()
        .iter()
        .find(|t| t["effect"] == effect)
        .unwrap_or_else(|| panic!("no {effect} term in {v}"))
}

#[test]
fn json_contract_and_white_noise_of_the_real_gyro() {
    let f = static_449s();
    let out = run_ok(["fit", &f].into_iter().chain(GZ_RAW).chain(["--json"]));
    let v = stdout_json(&out);
    assert_eq!(v["unit"], "deg/s");
    assert_eq!(v["diagnosis"]["adequate"], true);
    assert!(v["diagnosis"]["missing"].is_null());
    let white = term(&v, "white");
    // AllanTools: OADEV(1 s) of gz = 1.2093 LSB → N ≈ 1.2093 × 0.0076336 deg/s·√s = 0.00923.
    let n = white["params"]["N"].as_f64().unwrap();
    assert!((n / 0.00923 - 1.0).abs() < 0.03, "N = {n}");
    assert_eq!(v["adev"].as_array().unwrap().len(), 15);
}

#[test]
fn plots_in_svg_and_png_and_refuses_other_names() {
    let dir = tempfile::tempdir().unwrap();
    let f = static_449s();
    for name in ["fit.svg", "fit.png"] {
        let p = dir.path().join(name);
        let p = p.to_str().unwrap();
        run_ok(["fit", &f].into_iter().chain(GZ_RAW).chain(["--plot", p]));
        let bytes = std::fs::read(p).unwrap();
        if name.ends_with("png") {
            assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n");
            let (w, h) = (
                u32::from_be_bytes(bytes[16..20].try_into().unwrap()),
                u32::from_be_bytes(bytes[20..24].try_into().unwrap()),
            );
            assert!(w >= 400 && h >= 300, "{w}×{h}");
        } else {
            assert!(String::from_utf8_lossy(&bytes).contains("<svg"));
        }
    }
    let jpg = dir.path().join("fit.jpg");
    let err = run_err(
        ["fit", &f]
            .into_iter()
            .chain(GZ_RAW)
            .chain(["--plot", jpg.to_str().unwrap()]),
    );
    assert!(err.contains(".svg or .png"), "{err}");
}

/// Simulated gyro data through a one-pole 5 Hz low-pass (the MPU-6050's DLPF), 30 min at 100 Hz.
fn dlpf_file(dir: &std::path::Path) -> String {
    let p = dir.join("dlpf.csv");
    let p = p.to_str().unwrap().to_string();
    simulate_gyro(&p, 5, &["--dlpf", "5"]);
    p
}

#[test]
fn auto_walk_names_the_filter_and_the_json_reproduces_the_model() {
    let dir = tempfile::tempdir().unwrap();
    let f = dlpf_file(dir.path());
    let out = run_ok(["fit", &f, "--column", "gz", "--auto", "--json"]);
    let v = stdout_json(&out);
    let steps = v["steps"].as_array().unwrap();
    assert_eq!(
        steps[0]["added"],
        serde_json::json!(["lowpass"]),
        "{steps:?}"
    );
    assert_eq!(steps[0]["removed"], serde_json::json!(["white"]));
    assert_eq!(steps[0]["adequate_before"], false);
    let last = steps.last().unwrap();
    assert_eq!(last["adequate_after"], true);
    assert!(
        steps[0]["chi2_dof_after"].as_f64().unwrap()
            < steps[0]["chi2_dof_before"].as_f64().unwrap() / 10.0
    );
    assert!(
        steps[0]["rms_log_residual_after"].as_f64().unwrap()
            < steps[0]["rms_log_residual_before"].as_f64().unwrap()
    );
    assert_eq!(v["stop"], "the model is adequate");
    assert_eq!(v["diagnosis"]["adequate"], true);
    // The reported parameters give back the model column, by the textbook formulas (IEEE 952
    // Annex C for the power laws; the sampled AR(1) for the filtered white noise).
    let tau0 = 1.0 / v["rate_hz"].as_f64().unwrap();
    let terms = v["terms"].as_array().unwrap();
    let param = |e: &str, p: &str| {
        terms
            .iter()
            .find(|t| t["effect"] == e)
            .map(|t| t["params"][p].as_f64().unwrap())
    };
    let fc = param("lowpass", "cutoff_hz").expect("lowpass term");
    assert!((fc / 5.0 - 1.0).abs() < 0.1, "f_c = {fc}");
    for pt in v["adev"].as_array().unwrap() {
        let tau = pt["tau_s"].as_f64().unwrap();
        let m = tau / tau0;
        let mut var = 0.0;
        if let Some(q) = param("quantization", "Q") {
            var += 3.0 * q * q / (tau * tau);
        }
        if let Some(b) = param("flicker", "B") {
            var += 2.0 * std::f64::consts::LN_2 / std::f64::consts::PI * b * b;
        }
        if let Some(k) = param("rate_random_walk", "K") {
            var += k * k * (tau / 3.0 + tau0 * tau0 / (6.0 * tau));
        }
        if let Some(r) = param("rate_ramp", "R") {
            var += r * r * tau * tau / 2.0;
        }
        let n = param("lowpass", "N").unwrap();
        let phi: f64 = (-2.0 * std::f64::consts::PI * fc * tau0).exp();
        // AR(1) of variance s2: σ²(m) = s2·[2m(1−φ²)... ] from S(n) = Σ(n−|k|)φ^|k|
        let s2 = n * n / tau0 * (1.0 - phi) / (1.0 + phi);
        let s = |k: f64| {
            k * (1.0 + phi) / (1.0 - phi) - 2.0 * phi * (1.0 - phi.powf(k)) / (1.0 - phi).powi(2)
        };
        var += s2 * (4.0 * s(m) - s(2.0 * m)) / (2.0 * m * m);
        let model = pt["model"].as_f64().unwrap();
        assert!(
            (var.sqrt() / model - 1.0).abs() < 1e-6,
            "τ {tau}: params give {} but model {model}",
            var.sqrt()
        );
    }
}

#[test]
fn simulate_resonance_and_the_auto_walk_names_it() {
    // `simulate --resonance SIGMA,F0,ZETA` on the gyro background; `fit --auto` names the
    // resonance with f0 and ζ from the spectrum's band; an overdamped ζ is refused
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("res.csv");
    let p = p.to_str().unwrap().to_string();
    simulate_gyro(&p, 3, &["--resonance", "0.03,12,0.1"]);
    let out = run_ok(["fit", &p, "--column", "gz", "--auto", "--json"]);
    let v = stdout_json(&out);
    let steps = v["steps"].as_array().unwrap();
    assert_eq!(
        steps[0]["added"],
        serde_json::json!(["resonance"]),
        "{steps:?}"
    );
    assert_eq!(v["diagnosis"]["adequate"], true);
    let t = term(&v, "resonance");
    let (f0, zeta) = (
        t["params"]["f0_hz"].as_f64().unwrap(),
        t["params"]["zeta"].as_f64().unwrap(),
    );
    assert!((f0 / 12.0 - 1.0).abs() < 0.05, "f0 {f0}");
    assert!((zeta / 0.1 - 1.0).abs() < 0.4, "ζ {zeta}");
    let err = run_err([
        "simulate",
        "--resonance",
        "0.03,12,1.5",
        "-o",
        dir.path().join("x.csv").to_str().unwrap(),
    ]);
    assert!(err.contains("ζ ≥ 1 has no resonant peak"), "{err}");
}

#[test]
fn a_user_effect_file_is_fitted_and_reported_by_its_name() {
    let dir = tempfile::tempdir().unwrap();
    let f = dlpf_file(dir.path());
    let effect = format!(
        "{}/../../docs/effects/bartlett_decimation.toml",
        env!("CARGO_MANIFEST_DIR")
    );
    let out = run_ok([
        "fit",
        &f,
        "--column",
        "gz",
        "--effect",
        &effect,
        "--terms",
        "quantization,bartlett_decimation,flicker,rate_random_walk",
        "--json",
    ]);
    let v = stdout_json(&out);
    let t = term(&v, "bartlett_decimation");
    assert!(
        t["params"]["N"].as_f64().unwrap() > 0.0 && t["params"]["L"].as_f64().unwrap() >= 1.0,
        "{t}"
    );
    // a broken file is refused with its name and the reason
    let bad = dir.path().join("bad.toml");
    std::fs::write(
        &bad,
        "name = \"x\"\nphysics = \"p\"\namplitude = \"a\"\nautocovariance = \"a * exp(-k)\"\n",
    )
    .unwrap();
    let err = run_err([
        "fit",
        &f,
        "--column",
        "gz",
        "--effect",
        bad.to_str().unwrap(),
    ]);
    assert!(
        err.contains("bad.toml") && err.contains("proportional to a²"),
        "{err}"
    );
}

#[test]
fn the_temperature_coefficient_is_the_calibration_labs() {
    // a gyro whose bias follows a warming temperature (0.02 °/s/°C over 15 °C): the noise lab
    // names `temperature` and its coefficient is the one `calibrate gyro` fits on the same file
    let dir = tempfile::tempdir().unwrap();
    let f = dir.path().join("warm.csv");
    let f = f.to_str().unwrap();
    simulate_gyro(
        f,
        9,
        &["--columns", "gx,gy,gz", "--temperature", "0.02,25,15,900"],
    );
    let out = run_ok(["fit", f, "--column", "gz", "--auto", "--json"]);
    let v = stdout_json(&out);
    let t = term(&v, "temperature");
    let (c, s) = (
        t["params"]["coefficient"].as_f64().unwrap(),
        t["sigma"]["coefficient"].as_f64().unwrap(),
    );
    assert!((c - 0.02).abs() < 4.0 * s, "noise lab: {c} ± {s}");
    let out = run_ok([
        "calibrate",
        "gyro",
        f,
        "--model",
        "bias,temperature",
        "--json",
    ]);
    let cal = stdout_json(&out);
    let k = cal["params"]["temp_coeff"][2].as_f64().unwrap();
    assert!(
        (k - c).abs() < 3.0 * s,
        "calibration lab {k} vs noise lab {c} ± {s}"
    );
}

/// `export kalibr` on simulated white noise of a drawn density: every axis's N carries its 1σ
/// and lies within 4σ of the truth, each density line is the noisiest axis's N in Kalibr's
/// units, and the rate reads back as the record's (not 100.0000000000199).
#[test]
fn kalibr_export_gives_each_density_with_its_uncertainty() {
    let key = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(1, |d| d.subsec_nanos());
    let n_true = 0.005 + f64::from(key % 1000) * 1e-5;
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("six.csv");
    let csv = csv.to_str().unwrap();
    let white = format!("{n_true}");
    let seed = format!("{key}");
    run_ok([
        "simulate",
        "--samples",
        "30000",
        "--rate",
        "100",
        "--white",
        &white,
        "--seed",
        &seed,
        "--columns",
        "gx,gy,gz,ax,ay,az",
        "-o",
        csv,
    ]);
    let out = run_ok(["export", "kalibr", csv]);
    let text = String::from_utf8_lossy(&out.stdout).to_string();
    let mut n_max: [f64; 2] = [0.0, 0.0];
    for (i, axis) in ["gx", "gy", "gz", "ax", "ay", "az"].iter().enumerate() {
        let line = text
            .lines()
            .find(|l| l.starts_with(&format!("#   {axis}: N = ")))
            .unwrap_or_else(|| panic!("no line for {axis} in\n{text}"));
        let rest = &line[format!("#   {axis}: N = ").len()..];
        let mut it = rest.split_whitespace();
        let n: f64 = it.next().unwrap().parse().unwrap();
        assert_eq!(it.next(), Some("±"), "{line}");
        let s: f64 = it.next().unwrap().parse().unwrap();
        assert!(s > 0.0 && s < 0.1 * n, "{line}");
        assert!(
            (n - n_true).abs() < 4.0 * s,
            "key {key}: {line} against N = {n_true}"
        );
        n_max[i / 3] = n_max[i / 3].max(n);
    }
    let value = |k: &str| -> f64 {
        let l = text.lines().find(|l| l.starts_with(k)).unwrap();
        l[k.len()..]
            .split_whitespace()
            .next()
            .unwrap()
            .parse()
            .unwrap()
    };
    // The per-axis lines have four significant digits.
    let g = value("gyroscope_noise_density:") / n_max[0].to_radians();
    let a = value("accelerometer_noise_density:") / n_max[1];
    assert!(
        (g - 1.0).abs() < 1e-3 && (a - 1.0).abs() < 1e-3,
        "{g} {a}\n{text}"
    );
    assert_eq!(value("update_rate:"), 100.0, "{text}");
}

/// The real gyro with its gz stuck for 30 s (rows 10000–12999 one value) and one stamp
/// duplicated (two segments): the stretch is named as a stuck reading, the verdict is not
/// adequate, and no two bias steps share an instant. (Before, the change-point search put three
/// steps at 99.48 s, each the same column, χ²/dof 1.09 → 11.7 → 2.5, and ended adequate.)
#[test]
fn a_stuck_stretch_is_named_and_makes_no_staircase() {
    let text = std::fs::read_to_string(static_449s()).unwrap();
    let rows: Vec<&str> = text.lines().skip(5).collect();
    let gz: Vec<i64> = rows
        .iter()
        .map(|r| r.rsplit(',').next().unwrap().trim().parse().unwrap())
        .collect();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("stuck.csv");
    let mut out = String::from("t,gz\n");
    for (i, v) in gz.iter().enumerate() {
        let v = if (10_000..13_000).contains(&i) {
            gz[10_000]
        } else {
            *v
        };
        // the stamp of row 2000 repeats row 1999's
        let t = if i == 2_000 { 1_999 } else { i } as f64 * 0.01;
        out.push_str(&format!("{t:.2},{v}\n"));
    }
    std::fs::write(&path, out).unwrap();
    let p = path.to_str().unwrap();
    let o = run_ok([
        "fit",
        p,
        "--column",
        "gz",
        "--scale",
        "0.0076336",
        "--unit",
        "deg/s",
        "--auto",
        "--json",
    ]);
    let v = stdout_json(&o);
    assert_eq!(v["diagnosis"]["adequate"], false, "{}", v["diagnosis"]);
    let evidence = v["diagnosis"].to_string();
    assert!(
        evidence.contains("samples 10000–12999") && evidence.contains("stuck reading"),
        "{evidence}"
    );
    let mut at: Vec<f64> = v["terms"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|t| t["effect"] == "bias_step")
        .map(|t| t["params"]["time_s"].as_f64().unwrap())
        .collect();
    at.sort_by(f64::total_cmp);
    assert!(
        at.windows(2).all(|w| w[1] - w[0] > 0.02),
        "steps at one instant: {at:?}"
    );
}

/// A recording too short for the lab is refused naming the file (the calibration said "input:
/// 8 magnetometer samples", the noise fit "fit of quantization + …: 4 usable τ points").
#[test]
fn a_record_too_short_is_named() {
    let dir = tempfile::tempdir().unwrap();
    let short = dir.path().join("short.csv");
    let rows: String = (0..8)
        .map(|i| {
            let a = f64::from(i);
            format!("{:.2},{},{},{}\n", a / 100.0, 20.0 + a, -3.0 * a, 40.0 - a)
        })
        .collect();
    std::fs::write(&short, format!("t,mx,my,mz\n{rows}")).unwrap();
    let tiny = dir.path().join("tiny.csv");
    let rows: String = (0..20)
        .map(|i| format!("{:.2},{}\n", f64::from(i) / 100.0, (i * 7919) % 13))
        .collect();
    std::fs::write(&tiny, format!("t,gz\n{rows}")).unwrap();
    let (short, tiny) = (short.display().to_string(), tiny.display().to_string());
    let e = run_err(["calibrate", "mag", &short]);
    assert!(
        e.contains(&format!("{short}: input: 8 magnetometer samples")),
        "{e}"
    );
    let e = run_err(["fit", &tiny, "--column", "gz"]);
    assert!(
        e.contains(&format!("{tiny}: column \"gz\": fit of ")) && e.contains("usable τ points"),
        "{e}"
    );
}
