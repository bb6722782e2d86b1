//! Reading a calibration run: the sensor's columns, the physical constants checked against the
//! physics, the samples excluded (sentinels, gaps) and the prepared data.
use super::*;

pub(super) fn default_model(s: SensorArg) -> Vec<Effect> {
    match s {
        SensorArg::Accel => vec![Effect::Offset, Effect::Scale],
        SensorArg::Gyro => vec![Effect::Bias],
        SensorArg::Mag => vec![Effect::HardIron],
    }
}

/// Three columns of one sensor, their common unit, and the recording.
fn columns(
    in_: &InputArgs,
    names: [&str; 3],
    optional: &[&str],
) -> Result<(input::Recording, [Vec<f64>; 3], String)> {
    let rec = input::load_with(in_, &names, optional)?;
    let col = |n: &str| rec.column(n).with_context(|| format!("column {n} missing"));
    let units: Vec<&str> = names
        .iter()
        .map(|n| col(n).map(|c| c.unit.as_str()))
        .collect::<Result<_>>()?;
    if units.iter().any(|u| *u != units[0]) {
        bail!(
            "{}: columns {} are in different units ({}): one sensor's axes must share one",
            in_.file.display(),
            names.join(", "),
            units.join(", ")
        );
    }
    let unit = units[0].to_string();
    let cols = [
        col(names[0])?.values.clone(),
        col(names[1])?.values.clone(),
        col(names[2])?.values.clone(),
    ];
    Ok((rec, cols, unit))
}

/// Gravity in the accelerometer's unit: Earth's surface gravity is 9.76–9.84 m/s²; in raw
/// counts it must be given (the sensitivity is the user's to state).
fn gravity(g: Option<f64>, unit: &str) -> Result<f64> {
    let (lo, hi, default) = match unit {
        "m/s²" | "m/s^2" => (9.7, 9.9, Some(G_STANDARD)),
        "g" => (0.99, 1.01, Some(1.0)),
        COUNTS => (1.0, 1e6, None),
        _ => (f64::MIN_POSITIVE, 1e12, None),
    };
    let g = match (g, default) {
        (Some(g), _) => g,
        (None, Some(d)) => d,
        (None, None) if unit == COUNTS => bail!(
            "the accelerometer columns are raw counts (LSB): give gravity in counts with --g \
             (e.g. --g 16384 for a ±2 g MPU-6050), or convert them to m/s² with --scale"
        ),
        (None, None) => {
            bail!("the accelerometer columns are in {unit}: give gravity in {unit} with --g")
        }
    };
    if !(g.is_finite() && (lo..=hi).contains(&g)) {
        bail!(
            "--g {g} {unit}: gravity must be between {lo} and {hi} {unit}{}",
            if unit == "m/s²" {
                " (Earth's surface gravity is 9.76–9.84 m/s²)"
            } else {
                ""
            }
        );
    }
    Ok(g)
}

/// The field magnitude, if given, checked against the physics (Earth's field is 22–67 µT;
/// indoors near steel a few hundred).
fn field(f: Option<f64>, unit: &str) -> Result<Option<f64>> {
    let Some(f) = f else { return Ok(None) };
    let (lo, hi) = match unit {
        "µT" | "uT" => (1.0, 1000.0),
        "G" | "gauss" => (0.01, 10.0),
        "nT" => (1e3, 1e6),
        COUNTS => (1.0, 1e6),
        _ => (f64::MIN_POSITIVE, 1e12),
    };
    if !(f.is_finite() && (lo..=hi).contains(&f)) {
        bail!(
            "--field {f} {unit}: the field magnitude must be between {lo} and {hi} {unit} \
             (Earth's field is 22–67 µT)"
        );
    }
    Ok(Some(f))
}

fn static_detect(a: &Args) -> Result<StaticDetect> {
    for (v, name, lo, hi) in [
        (a.window, "--window", 1e-3, 3600.0),
        (a.threshold_k, "--threshold-k", 1.0, 1e6),
        (a.min_static, "--min-static", 0.0, 86400.0),
    ] {
        if !(v.is_finite() && (lo..=hi).contains(&v)) {
            bail!("{name} {v}: must be between {lo} and {hi}");
        }
    }
    Ok(StaticDetect {
        window_s: a.window,
        k: a.threshold_k,
        min_static_s: a.min_static,
    })
}

/// Samples to exclude: the sentinels, plus the first sample after each gap (a pose or a move
/// must not span a gap).
fn flags(s: &Sentinels, rec: &input::Recording) -> Vec<bool> {
    let mut f = s.flagged.clone();
    for seg in rec.segments.iter().skip(1) {
        if let Some(x) = f.get_mut(seg.start) {
            *x = true;
        }
    }
    f
}

fn gap_note(rec: &input::Recording) -> Option<String> {
    (rec.segments.len() > 1).then(|| {
        format!(
            "the record has {} gaps: no pose or move spans one",
            rec.segments.len() - 1
        )
    })
}

/// The rows that repeat the row before them exactly, when the record is a zero-order hold of a
/// slower sensor (at least half of the rows repeat: a 200 Hz magnetometer in a 1 kHz record
/// repeats each value five times); none otherwise, since a quiet quantized part can repeat a
/// value by chance and those repeats are samples. Counting a held value five times would make
/// the residuals' scatter, the noise floor the verdict is judged by, look five times too
/// precise.
fn held_rows(c: &[Vec<f64>; 3]) -> Vec<bool> {
    let n = c[0].len();
    let repeat: Vec<bool> = (0..n)
        .map(|i| i > 0 && (0..3).all(|a| c[a][i] == c[a][i - 1]))
        .collect();
    if 2 * repeat.iter().filter(|&&r| r).count() >= n && n > 0 {
        repeat
    } else {
        vec![false; n]
    }
}

/// Keep the samples not flagged.
fn keep(v: &[f64], flagged: &[bool]) -> Vec<f64> {
    v.iter()
        .zip(flagged)
        .filter(|(_, f)| !**f)
        .map(|(x, _)| *x)
        .collect()
}

pub(super) fn load_data(a: &Args, model: &[Effect]) -> Result<Loaded> {
    let rotation = model.contains(&Effect::Scale) || model.contains(&Effect::Misalignment);
    if let Some(s) = a.saturation {
        if !(s.is_finite() && s > 0.0) {
            bail!("--saturation {s}: must be a positive rate");
        }
    }
    let mut notes = Vec::new();
    Ok(match a.sensor {
        SensorArg::Gyro if rotation => {
            // Gyro scale/misalignment: rotations between static poses, gravity as reference.
            // Only the direction of the accelerometer is used, so its unit does not matter.
            let (rec, c, au) = columns(&a.input, ["ax", "ay", "az"], &[])?;
            let (_, w, gu) = columns(&a.input, ["gx", "gy", "gz"], &[])?;
            if gu != "deg/s" {
                bail!(
                    "the gyro columns are in {gu}: the rotation fit integrates rates, so convert \
                     them to deg/s with --scale (e.g. 0.0076336 for ±250 °/s counts)"
                );
            }
            let sa = sentinel::find([&c[0], &c[1], &c[2]], &au, Part::for_sensor("accel"));
            let sg = sentinel::find([&w[0], &w[1], &w[2]], &gu, Part::for_sensor("gyro"));
            let mut fl = flags(&sa, &rec);
            for (f, g) in fl.iter_mut().zip(&sg.flagged) {
                *f |= *g;
            }
            notes.extend(gap_note(&rec));
            let poses =
                detect_static_masked([&c[0], &c[1], &c[2]], rec.rate_hz, static_detect(a)?, &fl)?;
            let both: Vec<bool> = sa
                .flagged
                .iter()
                .zip(&sg.flagged)
                .map(|(a, g)| *a || *g)
                .collect();
            let sentinels = Sentinels {
                samples: both.iter().filter(|f| **f).count(),
                found: sa.found.into_iter().chain(sg.found).collect(),
                flagged: both,
            };
            Loaded {
                data: Data::GyroRot(GyroRotProblem::new_flagged(
                    [&c[0], &c[1], &c[2]],
                    [&w[0], &w[1], &w[2]],
                    rec.rate_hz,
                    &poses,
                    a.saturation,
                    &fl,
                )?),
                sentinels,
                notes,
            }
        }
        SensorArg::Accel => {
            let (rec, c, unit) = columns(&a.input, ["ax", "ay", "az"], &[])?;
            let g = gravity(a.g, &unit)?;
            let s = sentinel::find([&c[0], &c[1], &c[2]], &unit, Part::for_sensor("accel"));
            notes.extend(gap_note(&rec));
            let poses = detect_static_masked(
                [&c[0], &c[1], &c[2]],
                rec.rate_hz,
                static_detect(a)?,
                &flags(&s, &rec),
            )?;
            Loaded {
                data: Data::Accel(AccelProblem::with_unit(poses, g, &unit)),
                sentinels: s,
                notes,
            }
        }
        SensorArg::Gyro => {
            let (rec, c, unit) = columns(&a.input, ["gx", "gy", "gz"], &["temp"])?;
            let s = sentinel::find([&c[0], &c[1], &c[2]], &unit, Part::for_sensor("gyro"));
            let t = rec.column("temp").map(|c| keep(&c.values, &s.flagged));
            if let Some(t) = &t {
                let missing = t.iter().filter(|v| v.is_nan()).count();
                if missing > 0 {
                    notes.push(format!("{missing} temperature readings are missing"));
                }
            }
            let g = [0, 1, 2].map(|k| keep(&c[k], &s.flagged));
            Loaded {
                data: Data::Gyro(GyroProblem::with_unit(
                    [&g[0], &g[1], &g[2]],
                    t.as_deref(),
                    a.blocks,
                    &unit,
                )?),
                sentinels: s,
                notes,
            }
        }
        SensorArg::Mag => {
            let (_, c, unit) = columns(&a.input, ["mx", "my", "mz"], &[])?;
            let f = field(a.field, &unit)?;
            let s = sentinel::find([&c[0], &c[1], &c[2]], &unit, Part::for_sensor("mag"));
            let held = held_rows(&c);
            if held.iter().filter(|&&h| h).count() > 0 {
                notes.push(format!(
                    "{} of {} rows repeat the row before them exactly: the record holds a slower \
                     magnetometer between its samples (zero-order hold), so each held value is \
                     counted once",
                    held.iter().filter(|&&h| h).count(),
                    held.len()
                ));
            }
            let m = (0..c[0].len())
                .filter(|&i| !s.flagged[i] && !held[i])
                .map(|i| Vector3::new(c[0][i], c[1][i], c[2][i]))
                .collect();
            Loaded {
                data: Data::Mag(MagProblem::with_unit(m, f, &unit)?),
                sentinels: s,
                notes,
            }
        }
    })
}
