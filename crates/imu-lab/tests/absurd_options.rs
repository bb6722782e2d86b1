//! Nothing hangs: `fit` and `calibrate` driven through the binary with absurd but finite
//! options (rates, scales, gravity, field, windows, thresholds, block counts, saturation from
//! 1e-320 to 1e308, either sign) each return — an answer or a clear refusal — within
//! [`BOUND`], and never panic. Bounded: 24 cases per subcommand (a few seconds in CI).
use std::io::Read;
use std::path::PathBuf;
use std::process::{Command, Stdio};
use std::sync::OnceLock;
use std::time::{Duration, Instant};

use proptest::prelude::*;

/// Longest a run may take (the slowest legitimate one here takes well under a second).
const BOUND: Duration = Duration::from_secs(20);

struct Files {
    _dir: tempfile::TempDir,
    clock: PathBuf,
    poses: PathBuf,
    rest: PathBuf,
    sphere: PathBuf,
}

/// Deterministic noise in [−0.5, 0.5).
fn noise(state: &mut u32) -> f64 {
    *state ^= *state << 13;
    *state ^= *state >> 17;
    *state ^= *state << 5;
    *state as f64 / 4_294_967_296.0 - 0.5
}

fn files() -> &'static Files {
    static F: OnceLock<Files> = OnceLock::new();
    F.get_or_init(|| {
        let dir = tempfile::tempdir().unwrap();
        let mut st = 0x9e37_79b9u32;
        let mut clock = String::from("t,gz\n");
        for i in 0..3000 {
            clock += &format!("{:.2},{:.5}\n", i as f64 / 100.0, noise(&mut st));
        }
        let mut poses = String::from("t,ax,ay,az,gx,gy,gz,temp\n");
        for i in 0..2400 {
            let k = (i / 300) as f64;
            let (th, ph) = (0.4 * k, 0.9 * k);
            poses += &format!(
                "{:.2},{:.5},{:.5},{:.5},{:.5},{:.5},{:.5},{:.2}\n",
                i as f64 / 100.0,
                9.80665 * th.sin() * ph.cos() + 0.02 * noise(&mut st),
                9.80665 * th.sin() * ph.sin() + 0.02 * noise(&mut st),
                9.80665 * th.cos() + 0.02 * noise(&mut st),
                0.1 + 0.05 * noise(&mut st),
                -0.2 + 0.05 * noise(&mut st),
                0.3 + 0.05 * noise(&mut st),
                25.0 + i as f64 * 0.001
            );
        }
        let mut sphere = String::from("mx,my,mz\n");
        for k in 0..600 {
            let z = 1.0 - 2.0 * (k as f64 + 0.5) / 600.0;
            let r = (1.0 - z * z).sqrt();
            let phi = 0.3 * k as f64;
            sphere += &format!(
                "{:.4},{:.4},{:.4}\n",
                45.0 * r * phi.cos() + 5.0 + 0.2 * noise(&mut st),
                45.0 * r * phi.sin() - 3.0 + 0.2 * noise(&mut st),
                45.0 * z + 12.0 + 0.2 * noise(&mut st)
            );
        }
        let write = |name: &str, text: &str| {
            let p = dir.path().join(name);
            std::fs::write(&p, text).unwrap();
            p
        };
        Files {
            clock: write("clock.csv", &clock),
            poses: write("poses.csv", &poses),
            rest: write("rest.csv", &poses),
            sphere: write("sphere.csv", &sphere),
            _dir: dir,
        }
    })
}

/// Run `imu-lab` with `args`; Err if it outlives [`BOUND`] (then killed) or panics.
fn run_bounded(args: &[String]) -> Result<(), String> {
    let mut child = Command::new(assert_cmd::cargo::cargo_bin("imu-lab"))
        .args(args)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .map_err(|e| e.to_string())?;
    let start = Instant::now();
    loop {
        if let Some(status) = child.try_wait().map_err(|e| e.to_string())? {
            let mut err = String::new();
            if let Some(mut e) = child.stderr.take() {
                let _ = e.read_to_string(&mut err);
            }
            if err.contains("panicked") || status.code().is_none_or(|c| c > 1) {
                return Err(format!("{args:?}: {status}: {err}"));
            }
            return Ok(());
        }
        if start.elapsed() > BOUND {
            let _ = child.kill();
            let _ = child.wait();
            return Err(format!("{args:?} did not return within {BOUND:?}"));
        }
        std::thread::sleep(Duration::from_millis(5));
    }
}

/// A finite number of any magnitude, either sign, subnormals included.
fn absurd() -> impl Strategy<Value = f64> {
    prop_oneof![
        (-320.0f64..308.0).prop_map(|e| 10f64.powf(e)),
        (-320.0f64..308.0).prop_map(|e| -(10f64.powf(e))),
        Just(f64::MIN_POSITIVE),
        Just(f64::MAX),
        Just(0.0),
        // The edges of what is accepted: these reach the fits.
        prop::sample::select(vec![1e-3, 1e7, 1e-12, 1e12, 0.0009, 1.1e7]),
        (-3.0f64..7.0).prop_map(|e| 10f64.powf(e)),
    ]
}

/// `--name=x` (the `=` form, so that negative numbers are values, not flags).
fn opt(name: &str, x: f64) -> String {
    format!("--{name}={x:e}")
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 24, failure_persistence: None, ..ProptestConfig::default() })]

    #[test]
    fn fit_returns(x in absurd(), which in 0..4u8,
                   terms in prop::sample::select(vec!["", "white", "white,rate_random_walk,markov", "sinusoid,white"])) {
        let f = &files().clock;
        let mut a: Vec<String> = vec!["fit".into(), f.display().to_string(), "--column".into(), "gz".into(),
            "--unit".into(), "deg/s".into()];
        // One absurd option at a time, so each reaches the code behind it.
        match which {
            0 => a.extend([opt("rate", x), "--ignore-time".into()]),
            1 => a.push(opt("scale", x)),
            2 => a.push(opt("tolerance", x)),
            _ => a.extend([opt("rate", x), opt("scale", x), "--ignore-time".into()]),
        }
        if !terms.is_empty() {
            a.extend(["--terms".into(), terms.to_string()]);
        }
        run_bounded(&a).map_err(TestCaseError::fail)?;
    }

    #[test]
    fn calibrate_returns(sensor in prop::sample::select(vec!["accel", "gyro", "mag"]),
                         model in prop::sample::select(vec!["", "scale,misalignment", "bias,temperature", "hard_iron,soft_iron", "offset,scale,misalignment"]),
                         g in absurd(), field in absurd(), window in absurd(), k in absurd(),
                         min_static in absurd(), saturation in absurd(), scale in absurd(),
                         blocks in prop_oneof![Just(0usize), Just(1), Just(4), Just(50), Just(100_000), Just(usize::MAX)],
                         which in 0..4u8) {
        let fs = files();
        let file = match sensor {
            "mag" => &fs.sphere,
            "gyro" => &fs.rest,
            _ => &fs.poses,
        };
        let mut a: Vec<String> = vec!["calibrate".into(), sensor.into(), file.display().to_string()];
        if sensor == "mag" {
            a.extend(["--rate".into(), "50".into()]);
        }
        if !model.is_empty() {
            a.extend(["--model".into(), model.into()]);
        }
        // One absurd option at a time, so each reaches the code behind it.
        match which {
            0 => a.extend([opt("g", g), opt("field", field)]),
            1 => a.extend([opt("window", window), opt("threshold-k", k), opt("min-static", min_static)]),
            2 => a.extend([opt("saturation", saturation), format!("--blocks={blocks}")]),
            _ => a.push(opt("scale", scale)),
        }
        run_bounded(&a).map_err(TestCaseError::fail)?;
    }
}

/// The inputs that hung before the rate checks, kept as fixed cases.
#[test]
fn rates_that_once_hung() {
    let f = files().clock.display().to_string();
    for r in ["1e300", "1e200", "1e-100", "1e-300"] {
        let a: Vec<String> = ["fit", &f, "--column", "gz", "--rate", r]
            .iter()
            .map(|s| s.to_string())
            .collect();
        run_bounded(&a).unwrap();
    }
}

/// `imu-lab` with `args`: its exit code and standard error (within [`BOUND`]).
fn refusal(args: &[&str]) -> (Option<i32>, String) {
    let out = Command::new(assert_cmd::cargo::cargo_bin("imu-lab"))
        .args(args)
        .stdout(Stdio::null())
        .output()
        .unwrap();
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stderr).into(),
    )
}

/// What the lab cannot do honestly is refused with exit code 1 and a message naming the option
/// or key and the value: a negative rate (was "unexpected argument '-1'"), a record too long to
/// build in memory (was an allocation failure and an abort), fewer blocks than an uncertainty
/// needs (was silently raised to 4), a heading evaluated with a calibration the device would
/// refuse (was evaluated), and a theory file that cannot be written (was found only after the
/// record was written).
#[test]
fn the_refusals_name_what_and_where() {
    let dir = tempfile::tempdir().unwrap();
    let rest = files().rest.display().to_string();
    let bad = dir.path().join("scale19.toml");
    let mut f = imu_cal::file::CalFile::default();
    f.accel.scale[1] = 1.9;
    std::fs::write(&bad, f.to_toml()).unwrap();
    let out = dir.path().join("o.csv").display().to_string();
    let bad = bad.display().to_string();
    let stuck = dir.path().join("stuck.csv");
    let rows: String = (0..3000)
        .map(|i| format!("{:.2},12.5,-3.25,40.5\n", f64::from(i) / 100.0))
        .collect();
    std::fs::write(&stuck, format!("t,mx,my,mz\n{rows}")).unwrap();
    let stuck = stuck.display().to_string();
    // Arguments split at spaces, with REST, BAD, STUCK and OUT standing for the files' paths.
    let cases = [
        // A negative number after a space is the option's value (clap took it for a flag).
        (
            "simulate --samples 100 --white 1 --rate -100",
            "--rate -100 Hz: a sample rate must be between",
        ),
        (
            "simulate --samples 100000000000000 --white 1 -o OUT",
            "--samples 100000000000000: at most 268435456",
        ),
        (
            "calibrate gyro REST --blocks 2",
            "--blocks 2: at least 4 blocks",
        ),
        (
            "heading REST --cal BAD",
            "refused: accel.scale[1] = 1.9 is outside 0.91–1.09",
        ),
        (
            "simulate --samples 100 --white 1 -o OUT --theory /",
            "creating /",
        ),
        // A stuck part: named as such (was "1 magnetometer samples", "0 usable τ points").
        (
            "calibrate mag STUCK",
            "2999 of 3000 rows hold the same reading as the row before them, 1 distinct",
        ),
        // An absurd value in short form (was 301 digits).
        (
            "calibrate accel REST --g 1e300",
            "--g 1e300 m/s²: gravity must be between 9.7 and 9.9 m/s²",
        ),
        (
            "calibrate mag STUCK --model hard_iron,soft_iron,hard_iron",
            "--model hard_iron,soft_iron,hard_iron: hard_iron is given twice (entry 2)",
        ),
        (
            "fit STUCK --column mx",
            "all 3000 samples are 12.5: a constant column has no noise to fit",
        ),
    ];
    for (line, want) in cases {
        let args: Vec<&str> = line
            .split_whitespace()
            .map(|a| match a {
                "REST" => rest.as_str(),
                "BAD" => bad.as_str(),
                "STUCK" => stuck.as_str(),
                "OUT" => out.as_str(),
                a => a,
            })
            .collect();
        let (code, err) = refusal(&args);
        assert_eq!(code, Some(1), "{args:?}: {err}");
        assert!(err.contains(want), "{args:?}: {err}");
    }
    // The theory's failure came before the record: nothing written.
    assert!(!std::path::Path::new(&out).exists());
}
