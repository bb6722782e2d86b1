use super::*;
use imu_cal::file::CalFile;
use nalgebra::{Matrix3, Vector3};
use std::io::Write;

fn args(file: &std::path::Path, sensor: SensorArg, model: &[&str]) -> Args {
    Args {
        sensor,
        input: InputArgs {
            file: file.to_path_buf(),
            rate: Some(50.0),
            ignore_time: false,
            skip_lines: 0,
            scale: None,
            unit: None,
            rename: vec![],
        },
        model: model.iter().map(|s| s.to_string()).collect(),
        g: None,
        field: None,
        window: 1.0,
        threshold_k: 6.0,
        min_static: 1.5,
        blocks: 50,
        saturation: None,
        auto: false,
        max_steps: 4,
        json: true,
        plot: None,
        report: None,
        out: None,
        part: None,
    }
}

/// A magnetometer turned over the whole sphere through a symmetric soft-iron distortion.
fn mag_csv() -> tempfile::NamedTempFile {
    let mut f = tempfile::NamedTempFile::new().unwrap();
    writeln!(f, "mx,my,mz").unwrap();
    let d = Matrix3::new(1.1, 0.05, 0.0, 0.05, 0.9, 0.02, 0.0, 0.02, 1.0);
    let n = 3000;
    for k in 0..n {
        let z = 1.0 - 2.0 * (k as f64 + 0.5) / n as f64;
        let r = (1.0 - z * z).sqrt();
        let phi = 0.05 * k as f64;
        // Deterministic ±0.1 µT dither in place of noise.
        let e = 0.1 * ((k * 7919 % 13) as f64 / 6.0 - 1.0);
        let m = d * Vector3::new(r * phi.cos(), r * phi.sin(), z) * 45.0
            + Vector3::new(5.0, -3.0, 12.0);
        writeln!(f, "{},{},{}", m.x + e, m.y - e, m.z + 0.5 * e).unwrap();
    }
    f
}

#[test]
fn mag_run_writes_toml_svg_and_html() {
    let csv = mag_csv();
    let dir = tempfile::tempdir().unwrap();
    let mut a = args(csv.path(), SensorArg::Mag, &["hard_iron", "soft_iron"]);
    a.plot = Some(dir.path().join("m.svg"));
    a.report = Some(dir.path().join("m.html"));
    a.out = Some(dir.path().join("cal.toml"));
    run(a).unwrap();
    let svg = std::fs::read_to_string(dir.path().join("m.svg")).unwrap();
    assert!(svg.starts_with("<svg") && svg.contains("circle F ="));
    assert!(std::fs::read_to_string(dir.path().join("m.html"))
        .unwrap()
        .contains("<svg"));
    let cal =
        CalFile::from_toml(&std::fs::read_to_string(dir.path().join("cal.toml")).unwrap()).unwrap();
    for (k, t) in [5.0, -3.0, 12.0].iter().enumerate() {
        assert!(
            (cal.mag.hard_iron[k] - t).abs() < 0.05,
            "{:?}",
            cal.mag.hard_iron
        );
    }
    // A second run for another sensor keeps the mag section.
    let mut a = args(csv.path(), SensorArg::Mag, &["hard_iron"]);
    a.out = Some(dir.path().join("cal.toml"));
    run(a).unwrap();
    let cal2 =
        CalFile::from_toml(&std::fs::read_to_string(dir.path().join("cal.toml")).unwrap()).unwrap();
    assert_eq!(
        cal2.mag.soft_iron,
        [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
    );
    assert_eq!(cal2.accel, cal.accel);
}

#[test]
fn bad_inputs_give_clear_errors() {
    let csv = mag_csv();
    let e = run(args(csv.path(), SensorArg::Mag, &["offset"]))
        .unwrap_err()
        .to_string();
    assert!(e.contains("does not apply to the mag"), "{e}");
    let e = run(args(csv.path(), SensorArg::Mag, &["hardiron"]))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("unknown effect") && e.contains("hard_iron"),
        "{e}"
    );
    let mut f = tempfile::NamedTempFile::new().unwrap();
    writeln!(f, "mx,my,mz\n1,2,3\n4,x,6").unwrap();
    let e = format!(
        "{:#}",
        run(args(f.path(), SensorArg::Mag, &[])).unwrap_err()
    );
    assert!(e.contains("line 3"), "{e}");
    // Accelerometer columns absent from a magnetometer file.
    let e = format!(
        "{:#}",
        run(args(csv.path(), SensorArg::Accel, &[])).unwrap_err()
    );
    assert!(e.contains("ax"), "{e}");
}
