//! `imu-lab fit` end to end on the real MPU-6050 recording: the JSON contract, the verdict, and
//! the pictures in both formats.
mod common;
use common::{run, run_ok, static_449s, GZ_RAW};

#[test]
fn json_contract_and_white_noise_of_the_real_gyro() {
    let f = static_449s();
    let out = run_ok(["fit", &f].into_iter().chain(GZ_RAW).chain(["--json"]));
    let v: serde_json::Value =
        serde_json::from_slice(&out.stdout).expect("exactly one JSON object");
    assert_eq!(v["unit"], "deg/s");
    assert_eq!(v["diagnosis"]["adequate"], true);
    assert!(v["diagnosis"]["missing"].is_null());
    let white = v["terms"]
        .as_array()
        .unwrap()
        .iter()
        .find(|t| t["effect"] == "white")
        .expect("white term");
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
    let out = run(["fit", &f]
        .into_iter()
        .chain(GZ_RAW)
        .chain(["--plot", jpg.to_str().unwrap()]));
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains(".svg or .png"));
}
