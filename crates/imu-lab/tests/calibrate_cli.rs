//! `imu-lab calibrate` on real recordings and on what real recordings hold: overflow
//! sentinels, wild samples, too few poses, a stuck gyro, raw counts, abutting poses, and
//! options no physics allows. Real data: the HMC5883L tilt sphere and the MPU-6050 multi-pose
//! run of crates/imu-cal/tests/data (provenance there).
use std::path::{Path, PathBuf};

use imu_cal::device::plausible::Num;
use serde_json::Value;

mod common;
use common::{run_err, run_ok, stdout_json, stdout_text};

fn data(rel: &str) -> String {
    format!("{}/../imu-cal/tests/data/{rel}", env!("CARGO_MANIFEST_DIR"))
}

fn tilt_sphere() -> String {
    data("mpu6050-hmc5883l-tilt-sphere/hmc5883l.csv")
}

fn multipose() -> String {
    data("mpu6050-static/multipose_calibration.csv")
}

/// The tilt sphere in µT: its gauss columns renamed onto the contract and scaled by 100.
const SPHERE: [&str; 4] = [
    "--rename",
    "t_s=t,mx_gauss=mx,my_gauss=my,mz_gauss=mz",
    "--scale",
    "100",
];

/// The multi-pose run in m/s² (±2 g: 9.80665/16384 m/s² per LSB).
const POSES: [&str; 6] = [
    "--skip-lines",
    "4",
    "--rate",
    "100",
    "--scale",
    "0.000598550",
];

/// A copy of the tilt sphere with row `row` (0-based data row) changed by `edit`.
fn edited_sphere(dir: &Path, row: usize, edit: impl Fn(&mut [String])) -> PathBuf {
    let text = std::fs::read_to_string(tilt_sphere()).unwrap();
    let mut out = String::new();
    for (i, l) in text.lines().enumerate() {
        if i == row + 1 {
            let mut f: Vec<String> = l.split(',').map(str::to_string).collect();
            edit(&mut f);
            out += &f.join(",");
        } else {
            out += l;
        }
        out.push('\n');
    }
    let p = dir.join(format!("sphere_{row}.csv"));
    std::fs::write(&p, out).unwrap();
    p
}

/// The arguments of `calibrate SENSOR FILE`: the file's reading flags, then `more`.
fn calibrate<'a>(
    sensor: &'a str,
    file: &'a str,
    reading: &[&'a str],
    more: &[&'a str],
) -> Vec<&'a str> {
    [&["calibrate", sensor, file][..], reading, more].concat()
}

/// `calibrate mag` of a copy of the tilt sphere: hard and soft iron, JSON.
fn iron_fit(file: &str) -> Vec<&str> {
    calibrate(
        "mag",
        file,
        &SPHERE,
        &["--model", "hard_iron,soft_iron", "--json"],
    )
}

fn fails_with(args: &[&str], needles: &[&str]) {
    let err = run_err(args);
    for n in needles {
        assert!(err.contains(n), "{args:?}: {n:?} not in {err}");
    }
    // (the file's path aside: a temporary directory's random name may hold "inf")
    let words = args.iter().fold(err.clone(), |e, a| e.replace(a, ""));
    assert!(!words.contains("NaN") && !words.contains("inf"), "{err}");
}

/// Hard iron of the reference set's quick fit: (−0.4, 5.6, −20.6) µT.
fn hard_iron_is_the_spheres(v: &Value) {
    let h = &v["params"]["hard_iron"];
    for (k, t) in [-0.4, 5.6, -20.6].iter().enumerate() {
        let x = h[k].as_f64().unwrap();
        assert!((x - t).abs() < 0.5, "hard iron {h}");
    }
}

#[test]
fn one_hmc5883l_overflow_sample_is_excluded_and_counted() {
    let dir = tempfile::tempdir().unwrap();
    // −4096 counts at the file's gain of 1090 LSB/G.
    let p = edited_sphere(dir.path(), 1234, |f| f[3] = "-3.757798".into());
    let p = p.to_str().unwrap();
    let a = iron_fit(p);
    let v = stdout_json(&run_ok(&a));
    assert_eq!(v["excluded"]["sentinels"], 1);
    assert!(
        v["excluded"]["sentinel_kinds"][0]
            .as_str()
            .unwrap()
            .contains("HMC5883L overflow"),
        "{v}"
    );
    hard_iron_is_the_spheres(&v);
    assert!(v["params"]["field"].as_f64().unwrap() < 60.0);
    let text = stdout_text(&run_ok(&a[..a.len() - 1]));
    assert!(
        text.contains("excluded before fitting: 1 sample(s) excluded as sensor sentinels"),
        "{text}"
    );
}

#[test]
fn one_wild_sample_is_named_as_an_outlier() {
    let dir = tempfile::tempdir().unwrap();
    // 1.5 G added to mx (a bumped sensor or a corrupted read).
    let p = edited_sphere(dir.path(), 2000, |f| {
        f[1] = format!("{}", f[1].parse::<f64>().unwrap() + 1.5)
    });
    let p = p.to_str().unwrap();
    let a = iron_fit(p);
    let v = stdout_json(&run_ok(&a));
    assert_eq!(v["excluded"]["outliers"], 1, "{v}");
    hard_iron_is_the_spheres(&v);
    // The residual is the clean file's 0.44 µT, not 2–5 µT.
    let rms = v["residual_rms"].as_f64().unwrap();
    assert!((0.40..0.48).contains(&rms), "rms {rms}");
    let d = v["diagnosis"]["explanation"].as_str().unwrap();
    assert!(
        d.contains("1 samples beyond 6σ excluded as outliers"),
        "{d}"
    );
}

#[test]
fn ten_poses_cannot_judge_nine_parameters() {
    let f = multipose();
    let mut a = calibrate(
        "accel",
        &f,
        &POSES,
        &["--model", "offset,scale,misalignment"],
    );
    let text = stdout_text(&run_ok(&a));
    assert!(text.contains("verdict: UNDERDETERMINED"), "{text}");
    assert!(!text.contains("ADEQUATE\n"), "{text}");
    assert!(
        text.contains("misalignment     = [") && text.contains(" ± "),
        "{text}"
    );
    a.push("--json");
    let v = stdout_json(&run_ok(&a));
    assert_eq!(v["diagnosis"]["underdetermined"], true);
    assert_eq!(v["diagnosis"]["adequate"], false);
    // the parameters the ten poses cannot identify are named in the JSON, not only in the text
    let free: Vec<&str> = v["diagnosis"]["unidentified"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p.as_str().unwrap())
        .collect();
    assert!(
        free.iter().any(|p| p.starts_with("misalignment_deg")),
        "{free:?}"
    );
    assert!(v["diagnosis"]["not_converged"].is_null());
    for k in 0..3 {
        let s = v["sigma"]["misalignment_deg"][k].as_f64().unwrap();
        assert!(s > 0.0, "{v}");
    }
}

#[test]
fn a_constant_gyro_column_gets_a_clear_answer() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("stuck.csv");
    let mut s = String::from("gx,gy,gz\n");
    for i in 0..5000 {
        s += &format!("{},0.5,{}\n", (i % 7) as f64 * 0.01, (i % 3) as f64 * 0.02);
    }
    std::fs::write(&p, s).unwrap();
    fails_with(
        &["calibrate", "gyro", p.to_str().unwrap(), "--rate", "100"],
        &["gyro axis y is constant", "stuck sensor"],
    );
}

#[test]
fn absurd_gravity_and_field_are_refused() {
    let f = multipose();
    let a = calibrate("accel", &f, &POSES, &["--g", "1e300"]);
    fails_with(&a, &["--g", "9.76–9.84 m/s²"]);
    let s = tilt_sphere();
    let a = calibrate("mag", &s, &SPHERE, &["--field", "1e300"]);
    fails_with(&a, &["--field", "22–67 µT"]);
}

/// Raw counts are fitted in counts and said to be counts; g must then be given in counts.
#[test]
fn raw_accelerometer_counts_stay_counts() {
    let f = multipose();
    let raw = ["--skip-lines", "4", "--rate", "100"];
    let mut a = calibrate("accel", &f, &raw, &[]);
    fails_with(&a, &["raw counts (LSB)", "--g 16384"]);
    a.extend(["--g", "16384"]);
    let text = stdout_text(&run_ok(&a));
    assert!(
        text.contains("offset           = [") && text.contains("] LSB"),
        "{text}"
    );
    assert!(!text.contains("m/s²"), "{text}");
    // The calibration file holds m/s²: counts cannot go there.
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("cal.toml");
    a.extend(["--out", out.to_str().unwrap()]);
    fails_with(&a, &["holds m/s²", "LSB"]);
}

/// 24 poses recorded back to back (concatenated pose files, no motion between them) are 24
/// poses, not one.
#[test]
fn abutting_poses_are_separate_poses() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("poses.csv");
    let mut s = String::from("t,ax,ay,az\n");
    let mut state = 0x1234_5678u32;
    let mut noise = || {
        state ^= state << 13;
        state ^= state >> 17;
        state ^= state << 5;
        (state as f64 / 4_294_967_296.0 - 0.5) * 0.05
    };
    let mut i = 0;
    for k in 0..24 {
        let (th, ph) = (0.3 + 0.11 * k as f64, 0.7 * k as f64);
        let g = [
            9.80665 * th.sin() * ph.cos(),
            9.80665 * th.sin() * ph.sin(),
            9.80665 * th.cos(),
        ];
        for _ in 0..300 {
            s += &format!(
                "{:.2},{:.5},{:.5},{:.5}\n",
                i as f64 * 0.01,
                g[0] + noise(),
                g[1] + noise(),
                g[2] + noise()
            );
            i += 1;
        }
    }
    std::fs::write(&p, s).unwrap();
    let v = stdout_json(&run_ok([
        "calibrate",
        "accel",
        p.to_str().unwrap(),
        "--json",
    ]));
    assert_eq!(v["n_residuals"], 24, "{v}");
}

/// A magnetometer turned slowly over the sphere through soft iron (a stretched, sheared ellipsoid) and
/// hard iron, with 0.2 µT of white noise per axis, at 100 Hz: the contract's CSV.
fn soft_iron_sphere(dir: &Path) -> PathBuf {
    let mut s: u64 = 0x9E37_79B9_7F4A_7C15;
    let mut uniform = move || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 11) as f64 / (1u64 << 53) as f64
    };
    let mut gauss = || {
        let (u, v) = (uniform().max(1e-300), uniform());
        (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
    };
    let a = [[1.12, 0.06, 0.0], [0.06, 0.91, 0.03], [0.0, 0.03, 1.02]];
    let h = [12.0, -7.0, 25.0];
    let mut text = String::from("t,mx,my,mz\n");
    for k in 0..3000 {
        // A slow spiral from pole to pole, 24 turns: consecutive samples a few µT apart, as
        // when the board is turned by hand.
        let z: f64 = 2.0 * (k as f64 + 0.5) / 3000.0 - 1.0;
        let phi = k as f64 * 0.05;
        let r = (1.0 - z * z).sqrt();
        let b = [50.0 * r * phi.cos(), 50.0 * r * phi.sin(), 50.0 * z];
        let m: Vec<f64> = (0..3)
            .map(|i| (0..3).map(|j| a[i][j] * b[j]).sum::<f64>() + h[i] + 0.2 * gauss())
            .collect();
        text += &format!(
            "{:.3},{:.4},{:.4},{:.4}\n",
            k as f64 * 0.01,
            m[0],
            m[1],
            m[2]
        );
    }
    let p = dir.join("soft_iron_sphere.csv");
    std::fs::write(&p, text).unwrap();
    p
}

#[test]
fn a_magnetometer_held_in_a_faster_record_counts_each_value_once() {
    // the same sphere written as `imu-lab record` writes a 200 Hz magnetometer in a 1 kHz
    // record: each value held for five rows
    let dir = tempfile::tempdir().unwrap();
    let f = soft_iron_sphere(dir.path());
    let text = std::fs::read_to_string(&f).unwrap();
    let mut held = String::from("t,mx,my,mz\n");
    for (k, line) in text.lines().skip(1).enumerate() {
        let v = line.split_once(',').unwrap().1;
        for j in 0..5 {
            held += &format!("{:.3},{v}\n", (5 * k + j) as f64 * 0.002);
        }
    }
    let h = dir.path().join("held.csv");
    std::fs::write(&h, held).unwrap();
    let json = |p: &Path| {
        stdout_json(&run_ok([
            "calibrate",
            "mag",
            p.to_str().unwrap(),
            "--auto",
            "--json",
        ]))
    };
    let (a, b) = (json(&f), json(&h));
    assert_eq!(b["stop"], "the model is adequate", "{b}");
    assert_eq!(b["model"], a["model"], "{b}");
    for i in 0..3 {
        let (x, y) = (
            a["params"]["hard_iron"][i].as_f64().unwrap(),
            b["params"]["hard_iron"][i].as_f64().unwrap(),
        );
        assert!(
            (x - y).abs() < 1e-9 * (1.0 + x.abs()),
            "hard iron {i}: {x} vs {y}"
        );
    }
    let notes = b["notes"].as_array().unwrap();
    assert!(
        notes.iter().any(|n| n
            .as_str()
            .unwrap()
            .starts_with("12000 of 15000 rows repeat")),
        "{notes:?}"
    );
}

#[test]
fn auto_walks_from_hard_iron_to_soft_iron_and_stops_adequate() {
    let dir = tempfile::tempdir().unwrap();
    let f = soft_iron_sphere(dir.path());
    let out = run_ok(["calibrate", "mag", f.to_str().unwrap(), "--auto", "--json"]);
    let v = stdout_json(&out);
    let steps = v["steps"].as_array().expect("steps with --auto");
    assert_eq!(steps.len(), 1, "{v}");
    let s = &steps[0];
    assert_eq!(s["added"], serde_json::json!(["soft_iron"]));
    let (before, after) = (
        s["chi2_dof_before"].as_f64().unwrap(),
        s["chi2_dof_after"].as_f64().unwrap(),
    );
    assert!(before > 50.0 && after < 1.5, "s²/σ² {before} → {after}");
    assert!(
        s["rms_residual_after"].as_f64().unwrap()
            < 0.3 * s["rms_residual_before"].as_f64().unwrap()
    );
    assert_eq!(
        (
            s["adequate_before"].as_bool(),
            s["adequate_after"].as_bool()
        ),
        (Some(false), Some(true))
    );
    assert_eq!(s["rms_unit"], "µT");
    assert_eq!(v["stop"], "the model is adequate");
    assert_eq!(v["model"], serde_json::json!(["hard_iron", "soft_iron"]));
    assert_eq!(v["diagnosis"]["adequate"], true);
    // The final model's hard iron is the truth within 4σ.
    for (i, truth) in [12.0, -7.0, 25.0].into_iter().enumerate() {
        let (x, sx) = (
            v["params"]["hard_iron"][i].as_f64().unwrap(),
            v["sigma"]["hard_iron"][i].as_f64().unwrap(),
        );
        assert!(
            (x - truth).abs() < 4.0 * sx + 1e-9,
            "hard iron {i}: {x} ± {sx}, truth {truth}"
        );
    }
    // Without --auto the same file reports the model it was given and no walk.
    let v = stdout_json(&run_ok(["calibrate", "mag", f.to_str().unwrap(), "--json"]));
    assert!(v.get("steps").is_none() && v.get("stop").is_none());
    assert_eq!(v["model"], serde_json::json!(["hard_iron"]));
    assert_eq!(v["step"]["added"], serde_json::json!(["soft_iron"]));
}

#[test]
fn auto_on_the_real_tilt_sphere_names_soft_iron_and_says_what_is_left() {
    let f = tilt_sphere();
    let a = calibrate("mag", &f, &SPHERE, &["--auto", "--json"]);
    let v = stdout_json(&run_ok(a));
    let steps = v["steps"].as_array().unwrap();
    assert_eq!(steps[0]["added"], serde_json::json!(["soft_iron"]));
    assert!(
        steps[0]["chi2_dof_after"].as_f64().unwrap()
            < 0.1 * steps[0]["chi2_dof_before"].as_f64().unwrap()
    );
    assert_eq!(v["stop"], "no effect of the vocabulary helps further");
    assert_eq!(v["diagnosis"]["adequate"], false);
}

/// A random value from the clock (printed with the failure): the refusals below are not tuned
/// to one number.
fn random_below(n: u64) -> u64 {
    let t = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .as_nanos() as u64;
    let mut x = t | 1;
    x ^= x << 13;
    x ^= x >> 7;
    x ^= x << 17;
    x % n
}

/// A calibration file beyond a datasheet bound is refused before anything is sent: the error
/// names the file key, index, value and bound, the exit code is non-zero, and the device port
/// (a listening socket here) is never connected to.
#[test]
fn device_upload_of_an_implausible_file_is_refused_before_connecting() {
    let dir = tempfile::tempdir().unwrap();
    let k = 110 + random_below(90); // accel scale 1.10–1.99
    let scale = k as f64 / 100.0;
    let mut f = imu_cal::file::CalFile::default();
    f.accel.scale[0] = scale;
    let path = dir.path().join("bad.toml");
    std::fs::write(&path, f.to_toml()).unwrap();
    let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    listener.set_nonblocking(true).unwrap();
    let port = format!("tcp:{}", listener.local_addr().unwrap());
    let err = run_err([
        "device",
        "--port",
        &port,
        "calibrate",
        "--upload",
        path.to_str().unwrap(),
    ]);
    let want = format!("accel.scale[0] = {scale} is outside 0.91–1.09");
    assert!(
        err.contains(&want) && err.contains("nothing uploaded"),
        "{want:?} not in {err}"
    );
    assert_eq!(
        listener.accept().map(|_| ()).unwrap_err().kind(),
        std::io::ErrorKind::WouldBlock,
        "the port was opened"
    );
}

/// `calibrate … --out cal.toml` refuses to write a file that would hold a parameter beyond its
/// datasheet bound (here the gyro bias already in it): the key, index, value and bound are
/// named, the exit code is non-zero and the file is left as it was.
#[test]
fn calibrate_out_refuses_an_implausible_file_and_leaves_it_unchanged() {
    let dir = tempfile::tempdir().unwrap();
    let bias = 61 + random_below(100); // deg/s, beyond ±60
    let mut f = imu_cal::file::CalFile::default();
    f.gyro.bias[1] = -(bias as f64);
    let out = dir.path().join("cal.toml");
    let before = f.to_toml();
    std::fs::write(&out, &before).unwrap();
    let sphere = tilt_sphere();
    let a = calibrate(
        "mag",
        &sphere,
        &SPHERE,
        &["--model", "hard_iron", "--out", out.to_str().unwrap()],
    );
    fails_with(
        &a,
        &[
            &format!("gyro.bias[1] = −{bias} deg/s is outside ±60 deg/s"),
            "not written",
        ],
    );
    assert_eq!(std::fs::read_to_string(&out).unwrap(), before);
}

/// The report judges the fitted model against the datasheet bounds before anything is written:
/// an adequate fit of an accelerometer whose scale no MPU-6050 has (a drawn 1.15–1.90 or
/// 0.50–0.85 on a drawn axis: a wrong range or unit) is called NOT PLAUSIBLE with the key,
/// axis, value and bound, in the text and in the JSON; a scale within ±3 % is within them.
#[test]
fn the_report_judges_the_model_against_the_datasheet_bounds() {
    let dir = tempfile::tempdir().unwrap();
    let axis = random_below(3) as usize;
    let k = random_below(115);
    let bad = if k < 75 {
        1.15 + k as f64 / 100.0
    } else {
        0.5 + (k - 75) as f64 / 100.0
    };
    for (scale, plausible) in [(bad, false), (1.0 + (k % 5) as f64 / 100.0 - 0.02, true)] {
        let mut s = [1.0; 3];
        s[axis] = scale;
        let arg = format!("{},{},{}", s[0], s[1], s[2]);
        let csv = dir.path().join("poses.csv");
        let csv = csv.to_str().unwrap();
        run_ok([
            "simulate",
            "--trajectory",
            "calibration",
            "--rate",
            "100",
            "--samples",
            "20000",
            "--accel-scale",
            &arg,
            "-o",
            csv,
        ]);
        let text = String::from_utf8(run_ok(["calibrate", "accel", csv]).stdout).unwrap();
        let v = stdout_json(&run_ok(["calibrate", "accel", csv, "--json"]));
        let fitted = v["params"]["scale"][axis].as_f64().unwrap();
        assert!(
            (fitted - scale).abs() < 0.01,
            "scale {scale}: fitted {fitted}"
        );
        if plausible {
            assert!(
                text.contains("plausibility: within the datasheet bounds of the MPU-6050"),
                "{text}"
            );
            assert!(v["implausible"].is_null(), "{v}");
        } else {
            let want = format!("accel.scale[{axis}] = {} is outside 0.91–1.09", Num(fitted));
            assert!(
                text.contains(&format!(
                    "plausibility: NOT PLAUSIBLE for the MPU-6050, {want}"
                )),
                "{text}"
            );
            assert_eq!(v["implausible"], want.as_str());
        }
    }
}

/// The tilt sphere is an HMC5883L's: with `--part HMC5883L` the fit is judged for it and
/// `--out` names it, at its power-on sensitivity or at the file's when that is one of its
/// ranges (a drawn gain); without `--part` the report says the firmware's QMC5883L was
/// assumed; a part the lab has no datasheet for, or a magnetometer for the accelerometer, is
/// refused naming the known ones.
#[test]
fn calibrate_mag_names_the_part_it_was_told() {
    let dir = tempfile::tempdir().unwrap();
    let sphere = tilt_sphere();
    let out = dir.path().join("cal.toml");
    let out = out.to_str().unwrap();
    let text = stdout_text(&run_ok(calibrate("mag", &sphere, &SPHERE, &["--out", out])));
    assert!(
        text.contains("within the datasheet bounds of the QMC5883L (assumed"),
        "{text}"
    );
    let file = std::fs::read_to_string(out).unwrap();
    assert!(file.contains("part = \"QMC5883L\"") && file.contains("lsb_per_unit = 120.0"));

    std::fs::remove_file(out).unwrap();
    let args = ["--part", "hmc5883l", "--out", out];
    let text = stdout_text(&run_ok(calibrate("mag", &sphere, &SPHERE, &args)));
    assert!(
        text.contains("plausibility: within the datasheet bounds of the HMC5883L ("),
        "{text}"
    );
    let file = std::fs::read_to_string(out).unwrap();
    assert!(
        file.contains("part = \"HMC5883L\"") && file.contains("lsb_per_unit = 10.9"),
        "{file}"
    );
    let v = stdout_json(&run_ok(calibrate(
        "mag",
        &sphere,
        &SPHERE,
        &["--part", "HMC5883L", "--json"],
    )));
    assert_eq!(v["judged_part"], "HMC5883L");

    // A file at another of its gains keeps that gain.
    let gains = [13.7, 10.9, 8.2, 6.6, 4.4, 3.9, 3.3, 2.3];
    let lsb = gains[random_below(8) as usize];
    let edited = file.replace("lsb_per_unit = 10.9", &format!("lsb_per_unit = {lsb}"));
    std::fs::write(out, edited).unwrap();
    run_ok(calibrate("mag", &sphere, &SPHERE, &args));
    let file = std::fs::read_to_string(out).unwrap();
    assert!(
        file.contains(&format!("lsb_per_unit = {lsb}\n")),
        "{lsb}: {file}"
    );

    fails_with(
        &calibrate("mag", &sphere, &SPHERE, &["--part", "BMI160"]),
        &["--part BMI160", "QMC5883L, HMC5883L"],
    );
    fails_with(
        &["calibrate", "accel", &multipose(), "--part", "HMC5883L"],
        &["--part HMC5883L", "MPU-6050"],
    );
}
