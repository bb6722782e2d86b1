//! One calibration-lab session on a recording's columns, without I/O: the physical constants
//! checked against the physics, the sensors' sentinels and the gaps excluded, the data prepared
//! (static poses, block means, moves or field samples), the model fitted and, with `auto`, the
//! walk diagnose → add → refit; the object `imu-lab calibrate --json` prints ([`json_out`]) and
//! the calibration file's section updated with the device's plausibility checks
//! ([`update_file`]). The CLI (`imu-lab calibrate`) and the Python package
//! (`pico_imu.calibrate`) are thin callers of [`prepare`] and [`run`].
use crate::device::plausible::{MagPart, Num};
use std::ops::Range;

use model_lab::{walk, Stop};
use nalgebra::Vector3;

use crate::accel::{detect_static_masked, AccelProblem, StaticDetect, G_STANDARD};
use crate::file::CalFile;
use crate::gyro::GyroProblem;
use crate::gyro_rot::GyroRotProblem;
use crate::lab::{CalLab, Effect, Model, Problem, Report, Step};
use crate::mag::MagProblem;
use crate::sentinel::{self, Part, Sentinels};

mod json;
pub use json::json_out;

/// The unit label of raw counts.
pub const COUNTS: &str = "LSB";

/// Which sensor to calibrate.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Sensor {
    /// Accelerometer from static poses (columns ax ay az, m/s²).
    Accel,
    /// Gyroscope at rest (columns gx gy gz, deg/s; temp °C used when present), or from
    /// rotations between static poses with scale/misalignment in the model.
    Gyro,
    /// Magnetometer rotated through many orientations (columns mx my mz, µT).
    Mag,
}

impl Sensor {
    /// `accel`, `gyro` or `mag`.
    pub fn parse(s: &str) -> Option<Sensor> {
        match s {
            "accel" => Some(Sensor::Accel),
            "gyro" => Some(Sensor::Gyro),
            "mag" => Some(Sensor::Mag),
            _ => None,
        }
    }

    /// The unit the calibration file holds for this sensor.
    pub fn contract_unit(self) -> &'static str {
        match self {
            Sensor::Accel => "m/s²",
            Sensor::Gyro => "deg/s",
            Sensor::Mag => "µT",
        }
    }

    /// The model a run starts from when none is given.
    pub fn default_model(self) -> Vec<Effect> {
        match self {
            Sensor::Accel => vec![Effect::Offset, Effect::Scale],
            Sensor::Gyro => vec![Effect::Bias],
            Sensor::Mag => vec![Effect::HardIron],
        }
    }
}

/// The options of a run, as the CLI's flags.
#[derive(Clone, Debug)]
pub struct Options {
    pub sensor: Sensor,
    /// The effects of the start model (empty: [`Sensor::default_model`]).
    pub model: Vec<Effect>,
    /// Gravity in the accelerometer columns' unit (default 9.80665 m/s²).
    pub g: Option<f64>,
    /// Field magnitude in the magnetometer columns' unit (fitted when absent).
    pub field: Option<f64>,
    /// Static detection window [s].
    pub window: f64,
    /// Static threshold: multiple of the at-rest window variance.
    pub threshold_k: f64,
    /// Shortest static pose kept [s].
    pub min_static: f64,
    /// Gyro saturation [deg/s]: moves reaching it are skipped by the rotation fit.
    pub saturation: Option<f64>,
    /// Blocks the gyro recording at rest is cut into.
    pub blocks: usize,
    /// Walk diagnose → add → refit.
    pub auto: bool,
    /// Most steps of the walk (1 to 20).
    pub max_steps: usize,
    /// Name the options as the CLI's flags (`--g`, `--threshold-k`) or as Python's keywords
    /// (`g`, `threshold_k`) in messages.
    pub cli: bool,
    /// The magnetometer part the recording was made with; `None`: the calibration file's, or
    /// the firmware's QMC5883L for a new file.
    pub mag_part: Option<MagPart>,
}

impl Options {
    /// The CLI's defaults for `sensor`.
    pub fn new(sensor: Sensor) -> Options {
        Options {
            sensor,
            model: Vec::new(),
            g: None,
            field: None,
            window: 1.0,
            threshold_k: 6.0,
            min_static: 1.5,
            saturation: None,
            blocks: 50,
            auto: false,
            max_steps: 4,
            mag_part: None,
            cli: true,
        }
    }

    /// An option's name in messages.
    fn flag(&self, cli: &'static str, py: &'static str) -> &'static str {
        if self.cli {
            cli
        } else {
            py
        }
    }

    /// The model to fit: the given one or the sensor's default.
    pub fn start_model(&self) -> Vec<Effect> {
        if self.model.is_empty() {
            self.sensor.default_model()
        } else {
            self.model.clone()
        }
    }

    /// Whether the gyro is calibrated from rotations (scale or misalignment in the model).
    pub fn rotation(&self) -> bool {
        let m = self.start_model();
        self.sensor == Sensor::Gyro
            && (m.contains(&Effect::Scale) || m.contains(&Effect::Misalignment))
    }

    /// The columns a run reads: (required, optional).
    pub fn columns(&self) -> (Vec<&'static str>, Vec<&'static str>) {
        match self.sensor {
            Sensor::Gyro if self.rotation() => {
                (vec!["ax", "ay", "az", "gx", "gy", "gz"], Vec::new())
            }
            Sensor::Accel => (vec!["ax", "ay", "az"], Vec::new()),
            Sensor::Gyro => (vec!["gx", "gy", "gz"], vec!["temp"]),
            Sensor::Mag => (vec!["mx", "my", "mz"], Vec::new()),
        }
    }
}

/// One column of the recording.
#[derive(Clone, Debug)]
pub struct Column<'a> {
    pub name: &'a str,
    pub unit: &'a str,
    pub values: &'a [f64],
}

/// The recording's columns with its rate and segments.
#[derive(Clone, Debug)]
pub struct Input<'a> {
    pub columns: Vec<Column<'a>>,
    /// Sample rate [Hz].
    pub rate_hz: f64,
    /// Row ranges between gaps (at least one).
    pub segments: &'a [Range<usize>],
    /// The recording as named in messages.
    pub shown: &'a str,
}

impl Input<'_> {
    fn column(&self, n: &str) -> Result<&Column<'_>, String> {
        self.columns
            .iter()
            .find(|c| c.name == n)
            .ok_or_else(|| format!("column {n} missing"))
    }
}

/// The prepared data of one run (kept for the report and the figures).
pub enum Data {
    /// Static poses.
    Accel(AccelProblem),
    /// Block means at rest.
    Gyro(GyroProblem),
    /// Moves between static poses.
    GyroRot(GyroRotProblem),
    /// Samples of the field.
    Mag(MagProblem),
}

impl Data {
    /// The problem behind it.
    pub fn problem(&self) -> &dyn Problem {
        match self {
            Data::Accel(p) => p,
            Data::Gyro(p) => p,
            Data::GyroRot(p) => p,
            Data::Mag(p) => p,
        }
    }

    /// The calibration file's section this run writes (`accel`, `gyro`, `gyro-rot`, `mag`).
    pub fn section(&self) -> &'static str {
        match self {
            Data::GyroRot(_) => "gyro-rot",
            _ => self.problem().sensor(),
        }
    }

    /// The unit of the fitted parameters (the rotation fit's are dimensionless; its bias is in
    /// deg/s).
    pub fn unit(&self) -> &str {
        match self {
            Data::GyroRot(_) => "deg/s",
            _ => self.problem().unit(),
        }
    }
}

/// A loaded run: the data, the sentinels excluded, and notes about the input for the report.
pub struct Loaded {
    /// The problem's data.
    pub data: Data,
    /// Sentinels found (and excluded) in the sensor's columns.
    pub sentinels: Sentinels,
    /// Other notes on the input (gaps, missing temperature, …).
    pub notes: Vec<String>,
    /// The magnetometer part the recording was made with, when stated ([`Options::mag_part`]).
    pub mag_part: Option<MagPart>,
}

/// What a run produced: the report on the last model, and for `auto` the walk that led to it.
pub struct Outcome {
    /// The model the run started from.
    pub start: Model,
    /// The steps of the walk (`auto`), in order.
    pub steps: Vec<Step>,
    /// Why the walk ended (`None` without `auto`).
    pub stop: Option<Stop>,
    /// The last model's report: verdict, candidates, diagnosis, the next step.
    pub report: Report,
}

/// Three columns of one sensor and their common unit.
fn columns(input: &Input, names: [&str; 3]) -> Result<([Vec<f64>; 3], String), String> {
    let cols = [
        input.column(names[0])?,
        input.column(names[1])?,
        input.column(names[2])?,
    ];
    let units: Vec<&str> = cols.iter().map(|c| c.unit).collect();
    if units.iter().any(|u| *u != units[0]) {
        return Err(format!(
            "{}: columns {} are in different units ({}): one sensor's axes must share one",
            input.shown,
            names.join(", "),
            units.join(", ")
        ));
    }
    for c in &cols {
        if let Some(i) = c.values.iter().position(|v| !v.is_finite()) {
            return Err(format!(
                "{}: column {} row {i}: {} is not a finite number",
                input.shown, c.name, c.values[i]
            ));
        }
    }
    Ok((cols.map(|c| c.values.to_vec()), units[0].to_string()))
}

/// Gravity in the accelerometer's unit: Earth's surface gravity is 9.76–9.84 m/s²; in raw
/// counts it must be given (the sensitivity is the user's to state).
fn gravity(o: &Options, unit: &str) -> Result<f64, String> {
    let flag = o.flag("--g", "g");
    let (lo, hi, default) = match unit {
        "m/s²" | "m/s^2" => (9.7, 9.9, Some(G_STANDARD)),
        "g" => (0.99, 1.01, Some(1.0)),
        COUNTS => (1.0, 1e6, None),
        _ => (f64::MIN_POSITIVE, 1e12, None),
    };
    let g = match (o.g, default) {
        (Some(g), _) => g,
        (None, Some(d)) => d,
        (None, None) if unit == COUNTS => {
            return Err(format!(
            "the accelerometer columns are raw counts (LSB): give gravity in counts with {flag} \
                 (e.g. {flag} 16384 for a ±2 g MPU-6050), or convert them to m/s² with --scale"
        ))
        }
        (None, None) => {
            return Err(format!(
                "the accelerometer columns are in {unit}: give gravity in {unit} with {flag}"
            ))
        }
    };
    if !(g.is_finite() && (lo..=hi).contains(&g)) {
        return Err(format!(
            "{flag} {} {unit}: gravity must be between {} and {} {unit}{}",
            Num(g),
            Num(lo),
            Num(hi),
            if unit == "m/s²" {
                " (Earth's surface gravity is 9.76–9.84 m/s²)"
            } else {
                ""
            }
        ));
    }
    Ok(g)
}

/// The field magnitude, if given, checked against the physics (Earth's field is 22–67 µT;
/// indoors near steel a few hundred).
fn field(o: &Options, unit: &str) -> Result<Option<f64>, String> {
    let Some(f) = o.field else { return Ok(None) };
    let (lo, hi) = match unit {
        "µT" | "uT" => (1.0, 1000.0),
        "G" | "gauss" => (0.01, 10.0),
        "nT" => (1e3, 1e6),
        COUNTS => (1.0, 1e6),
        _ => (f64::MIN_POSITIVE, 1e12),
    };
    if !(f.is_finite() && (lo..=hi).contains(&f)) {
        return Err(format!(
            "{} {} {unit}: the field magnitude must be between {} and {} {unit} \
             (Earth's field is 22–67 µT)",
            o.flag("--field", "field"),
            Num(f),
            Num(lo),
            Num(hi)
        ));
    }
    Ok(Some(f))
}

fn static_detect(o: &Options) -> Result<StaticDetect, String> {
    for (v, name, lo, hi) in [
        (o.window, o.flag("--window", "window"), 1e-3, 3600.0),
        (
            o.threshold_k,
            o.flag("--threshold-k", "threshold_k"),
            1.0,
            1e6,
        ),
        (
            o.min_static,
            o.flag("--min-static", "min_static"),
            0.0,
            86400.0,
        ),
    ] {
        if !(v.is_finite() && (lo..=hi).contains(&v)) {
            return Err(format!(
                "{name} {}: must be between {} and {}",
                Num(v),
                Num(lo),
                Num(hi)
            ));
        }
    }
    Ok(StaticDetect {
        window_s: o.window,
        k: o.threshold_k,
        min_static_s: o.min_static,
    })
}

/// Samples to exclude: the sentinels, plus the first sample after each gap (a pose or a move
/// must not span a gap).
fn flags(s: &Sentinels, segments: &[Range<usize>]) -> Vec<bool> {
    let mut f = s.flagged.clone();
    for seg in segments.iter().skip(1) {
        if let Some(x) = f.get_mut(seg.start) {
            *x = true;
        }
    }
    f
}

fn gap_note(segments: &[Range<usize>]) -> Option<String> {
    (segments.len() > 1).then(|| {
        format!(
            "the record has {} gaps: no pose or move spans one",
            segments.len() - 1
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

/// Rows repeating one reading at least this many times in a row, and [`STUCK_HOLDS`] times the
/// record's median run, are a stuck magnetometer, not a slower one held between its samples (a
/// hold repeats each reading about as often: the QMC5883L's 200 Hz read at 1 kHz five times,
/// the HMC5883L's 15 Hz at 1 kHz 67).
const STUCK_ROWS: usize = 64;
/// How many median runs a stuck run is at least.
const STUCK_HOLDS: usize = 8;

/// The stuck runs of identical rows: (first row, length).
fn stuck_runs(c: &[Vec<f64>; 3]) -> Vec<(usize, usize)> {
    let n = c[0].len();
    let mut runs = Vec::new();
    let mut i = 0;
    while i < n {
        let mut j = i + 1;
        while j < n && (0..3).all(|a| c[a][j] == c[a][i]) {
            j += 1;
        }
        runs.push((i, j - i));
        i = j;
    }
    let mut lengths: Vec<usize> = runs.iter().map(|r| r.1).collect();
    lengths.sort_unstable();
    let Some(&median) = lengths.get(lengths.len() / 2) else {
        return Vec::new();
    };
    let least = STUCK_ROWS.max(STUCK_HOLDS * median);
    runs.retain(|r| r.1 >= least);
    runs
}

/// Keep the samples not flagged.
fn keep(v: &[f64], flagged: &[bool]) -> Vec<f64> {
    v.iter()
        .zip(flagged)
        .filter(|(_, f)| !**f)
        .map(|(x, _)| *x)
        .collect()
}

/// The options checked and the data prepared for the fit: constants against the physics,
/// sentinels and gaps excluded, static poses detected, blocks or moves formed.
pub fn prepare(input: &Input, o: &Options) -> Result<Loaded, String> {
    if let Some((i, e)) = o
        .model
        .iter()
        .enumerate()
        .find(|(i, e)| o.model[..*i].contains(e))
    {
        return Err(format!(
            "{} {}: {} is given twice (entry {i})",
            o.flag("--model", "model"),
            o.model
                .iter()
                .map(|e| e.name())
                .collect::<Vec<_>>()
                .join(","),
            e.name()
        ));
    }
    if !(1..=20).contains(&o.max_steps) {
        return Err(format!(
            "{} {}: give 1 to 20",
            o.flag("--max-steps", "max_steps"),
            o.max_steps
        ));
    }
    if !(input.rate_hz > 0.0 && input.rate_hz.is_finite()) {
        return Err(format!(
            "{}: rate {} Hz: must be a positive number",
            input.shown, input.rate_hz
        ));
    }
    let rotation = o.rotation();
    if let Some(s) = o.saturation {
        if !(s.is_finite() && s > 0.0) {
            return Err(format!(
                "{} {s}: must be a positive rate",
                o.flag("--saturation", "saturation")
            ));
        }
    }
    let segments = input.segments;
    // The data's own errors name the recording.
    let e = |e: crate::error::CalError| format!("{}: {e}", input.shown);
    let mut notes = Vec::new();
    Ok(match o.sensor {
        Sensor::Gyro if rotation => {
            // Gyro scale/misalignment: rotations between static poses, gravity as reference.
            // Only the direction of the accelerometer is used, so its unit does not matter.
            let (c, au) = columns(input, ["ax", "ay", "az"])?;
            let (w, gu) = columns(input, ["gx", "gy", "gz"])?;
            if gu != "deg/s" {
                return Err(format!(
                    "the gyro columns are in {gu}: the rotation fit integrates rates, so convert \
                     them to deg/s with --scale (e.g. 0.0076336 for ±250 °/s counts)"
                ));
            }
            let sa = sentinel::find([&c[0], &c[1], &c[2]], &au, Part::for_sensor("accel"));
            let sg = sentinel::find([&w[0], &w[1], &w[2]], &gu, Part::for_sensor("gyro"));
            let mut fl = flags(&sa, segments);
            for (f, g) in fl.iter_mut().zip(&sg.flagged) {
                *f |= *g;
            }
            notes.extend(gap_note(segments));
            let poses =
                detect_static_masked([&c[0], &c[1], &c[2]], input.rate_hz, static_detect(o)?, &fl)
                    .map_err(e)?;
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
                data: Data::GyroRot(
                    GyroRotProblem::new_flagged(
                        [&c[0], &c[1], &c[2]],
                        [&w[0], &w[1], &w[2]],
                        input.rate_hz,
                        &poses,
                        o.saturation,
                        &fl,
                    )
                    .map_err(e)?,
                ),
                sentinels,
                notes,
                mag_part: o.mag_part,
            }
        }
        Sensor::Accel => {
            let (c, unit) = columns(input, ["ax", "ay", "az"])?;
            let g = gravity(o, &unit)?;
            let s = sentinel::find([&c[0], &c[1], &c[2]], &unit, Part::for_sensor("accel"));
            notes.extend(gap_note(segments));
            let poses = detect_static_masked(
                [&c[0], &c[1], &c[2]],
                input.rate_hz,
                static_detect(o)?,
                &flags(&s, segments),
            )
            .map_err(e)?;
            Loaded {
                data: Data::Accel(AccelProblem::with_unit(poses, g, &unit)),
                sentinels: s,
                notes,
                mag_part: o.mag_part,
            }
        }
        Sensor::Gyro => {
            let (c, unit) = columns(input, ["gx", "gy", "gz"])?;
            let s = sentinel::find([&c[0], &c[1], &c[2]], &unit, Part::for_sensor("gyro"));
            let t = input
                .columns
                .iter()
                .find(|c| c.name == "temp")
                .map(|c| keep(c.values, &s.flagged));
            if let Some(t) = &t {
                let missing = t.iter().filter(|v| v.is_nan()).count();
                if missing > 0 {
                    notes.push(format!("{missing} temperature readings are missing"));
                }
            }
            if o.blocks < 4 {
                // The blocks' scatter is the bias's uncertainty: fewer than 4 cannot give one.
                return Err(format!(
                    "{} {}: at least 4 blocks",
                    o.flag("--blocks", "blocks"),
                    o.blocks
                ));
            }
            let g = [0, 1, 2].map(|k| keep(&c[k], &s.flagged));
            Loaded {
                data: Data::Gyro(
                    GyroProblem::with_unit([&g[0], &g[1], &g[2]], t.as_deref(), o.blocks, &unit)
                        .map_err(e)?,
                ),
                sentinels: s,
                notes,
                mag_part: o.mag_part,
            }
        }
        Sensor::Mag => {
            let (c, unit) = columns(input, ["mx", "my", "mz"])?;
            let f = field(o, &unit)?;
            let s = sentinel::find([&c[0], &c[1], &c[2]], &unit, Part::for_sensor("mag"));
            let held = held_rows(&c);
            let mut out = vec![false; c[0].len()];
            let stuck = stuck_runs(&c);
            if !stuck.is_empty() && stuck.iter().map(|r| r.1).sum::<usize>() < c[0].len() {
                // Left out whole: one held value kept would weigh like any other reading, and
                // a part stuck for a third of the record had its noise floor read as 0.
                for &(from, len) in &stuck {
                    out[from..from + len].fill(true);
                }
                notes.push(format!(
                    "left out as a stuck magnetometer (one reading repeated {STUCK_ROWS} rows or \
                     more, and {STUCK_HOLDS} times the record's median run): {}",
                    stuck
                        .iter()
                        .map(|&(from, len)| format!(
                            "rows {}–{} ({len} rows)",
                            from + 1,
                            from + len
                        ))
                        .collect::<Vec<_>>()
                        .join(", ")
                ));
            }
            let held: Vec<bool> = held.iter().zip(&out).map(|(h, o)| *h && !o).collect();
            if held.iter().filter(|&&h| h).count() > 0 {
                notes.push(format!(
                    "{} of {} rows repeat the row before them exactly: the record holds a slower \
                     magnetometer between its samples (zero-order hold), so each held value is \
                     counted once",
                    held.iter().filter(|&&h| h).count(),
                    held.len()
                ));
            }
            let m: Vec<_> = (0..c[0].len())
                .filter(|&i| !s.flagged[i] && !held[i] && !out[i])
                .map(|i| Vector3::new(c[0][i], c[1][i], c[2][i]))
                .collect();
            if m.len() < 20 && held.len() >= 20 && m.len() * 10 < held.len() {
                // Counted once per held value, a stuck part leaves a handful: say why.
                return Err(format!(
                    "{}: {} of {} rows hold the same reading as the row before them, {} distinct \
                     readings are left (at least 20 are needed): a stuck magnetometer, or the \
                     wrong columns",
                    input.shown,
                    held.iter().filter(|&&h| h).count(),
                    held.len(),
                    m.len()
                ));
            }
            Loaded {
                data: Data::Mag(MagProblem::with_unit(m, f, &unit).map_err(e)?),
                sentinels: s,
                notes,
                mag_part: o.mag_part,
            }
        }
    })
}

/// Fit `model`, and with `auto` walk from it; the report is on the last model.
pub fn outcome(
    p: &dyn Problem,
    model: &[Effect],
    auto: bool,
    max_steps: usize,
) -> Result<Outcome, String> {
    let e = |e: crate::error::CalError| e.to_string();
    let lab = CalLab::new(p);
    let start = lab.fit(model).map_err(e)?;
    if !auto {
        return Ok(Outcome {
            start: start.clone(),
            steps: Vec::new(),
            stop: None,
            report: lab.report(start).map_err(e)?,
        });
    }
    let w = walk(&lab, start.clone(), max_steps).map_err(e)?;
    let last = w.last().clone();
    Ok(Outcome {
        start,
        steps: w.steps,
        stop: Some(w.stop),
        report: lab.report(last).map_err(e)?,
    })
}

/// The run on prepared data: the rotation fit's model without the bias (removed at rest first),
/// the fit and, with `auto`, the walk.
pub fn run(loaded: &Loaded, o: &Options) -> Result<Outcome, String> {
    let mut model = o.start_model();
    if let Data::GyroRot(_) = loaded.data {
        // The rotation fit always removes the bias at rest first; temperature is a block fit.
        if model.contains(&Effect::Temperature) {
            return Err(
                "fit temperature with --model bias,temperature and scale/misalignment separately"
                    .into(),
            );
        }
        model.retain(|e| *e != Effect::Bias);
    }
    outcome(loaded.data.problem(), &model, o.auto, o.max_steps)
}

/// The fitted parameters the data do not determine at all (no finite σ; given ones such as
/// the reference temperature aside): a calibration file must not carry their values, which
/// are the solver's starting point, not a measurement.
fn undetermined(loaded: &Loaded, run: &Outcome) -> Vec<String> {
    let p = loaded.data.problem();
    let f = &run.report.model.fitted;
    f.params
        .named_values()
        .into_iter()
        .zip(f.sigma.values())
        .filter(|((name, _), s)| !s.is_finite() && p.plausible_range(name, &f.params).is_some())
        .map(|((name, _), _)| name)
        .collect()
}

/// The unit the calibration file holds this fit's sensor in, and the fit's own.
fn file_units(loaded: &Loaded) -> (&'static str, &str) {
    let sensor = match loaded.data {
        Data::Accel(_) => Sensor::Accel,
        Data::Gyro(_) | Data::GyroRot(_) => Sensor::Gyro,
        Data::Mag(_) => Sensor::Mag,
    };
    (sensor.contract_unit(), loaded.data.unit())
}

/// The fitted model against the parts' datasheet bounds (docs/calibration.md,
/// "Plausibility"): `Ok(None)` within them, `Ok(Some(why))` outside (what `--out` and an
/// upload would refuse, in the file's words), `Err` when this fit's unit is not the
/// calibration file's (nothing to judge it by).
pub fn plausibility(loaded: &Loaded, run: &Outcome) -> Result<Option<String>, String> {
    let (contract, unit) = file_units(loaded);
    if unit != contract {
        return Err(format!(
            "not judged in {unit}: the bounds are in the calibration file's unit (convert with \
             --scale)"
        ));
    }
    let undetermined = undetermined(loaded, run);
    if !undetermined.is_empty() {
        return Err(format!(
            "not judged: the data do not determine {}",
            undetermined.join(", ")
        ));
    }
    let mut file = CalFile::default();
    if let Some(part) = loaded.mag_part {
        file.set_mag_part(part);
    }
    file.set(loaded.data.section(), &run.report.model.fitted.params)
        .map_err(|e| e.to_string())?;
    Ok(file.to_device().err().map(|e| e.to_string()))
}

/// The part a recording was made with, as stated by the user (`flag`: the option's name in
/// messages): a magnetometer this lab has the datasheet of, or the MPU-6050 for the
/// accelerometer and gyroscope (the only one: `None`, nothing to record).
pub fn stated_part(sensor: Sensor, name: &str, flag: &str) -> Result<Option<MagPart>, String> {
    let imu = crate::device::ImuPart::Mpu6050.name();
    match sensor {
        Sensor::Mag => MagPart::from_name(name).map(Some).ok_or_else(|| {
            let known: Vec<&str> = MagPart::ALL.iter().map(|p| p.name()).collect();
            format!(
                "{flag} {name}: not a magnetometer this lab knows the datasheet of ({})",
                known.join(", ")
            )
        }),
        _ if name.trim().eq_ignore_ascii_case(imu) => Ok(None),
        _ => Err(format!(
            "{flag} {name}: not an accelerometer/gyroscope this lab knows the datasheet of ({imu})"
        )),
    }
}

/// The part a fit is judged for, in words: the MPU-6050 for the accelerometer and gyroscope;
/// for the magnetometer the part stated for the recording, or else the firmware's (said to be
/// assumed).
pub fn judged_part(loaded: &Loaded) -> String {
    let (imu, mag) = CalFile::default().parts();
    match (&loaded.data, loaded.mag_part) {
        (Data::Mag(_), Some(part)) => part.name().to_string(),
        (Data::Mag(_), None) => format!(
            "{} (assumed, the firmware's part: state the recording's part to judge another)",
            mag.name()
        ),
        _ => imu.name().to_string(),
    }
}

/// The calibration file `existing` (TOML text, or a new file) with this run's section set to
/// the last model's parameters, refused — naming the key, axis, value and bound — unless the
/// device can hold it within the parts' datasheet bounds and its unit is the file's. Returns
/// the new TOML text.
/// A magnetometer part stated for the recording ([`Loaded::mag_part`]) is written as the
/// file's `mag.part`.
pub fn update_file(
    existing: Option<&str>,
    loaded: &Loaded,
    run: &Outcome,
) -> Result<String, String> {
    let (contract, unit) = file_units(loaded);
    if unit != contract {
        return Err(format!(
            "the calibration file holds {contract}, but this fit is in {unit}; convert the \
             columns with --scale"
        ));
    }
    let undetermined = undetermined(loaded, run);
    if !undetermined.is_empty() {
        return Err(format!(
            "refused, not written: the data do not determine {} (no finite σ); record the \
             poses or turns that excite them, or fit fewer parameters",
            undetermined.join(", ")
        ));
    }
    let mut file = match existing {
        Some(text) => CalFile::from_toml(text).map_err(|e| e.to_string())?,
        None => CalFile::default(),
    };
    if let Some(part) = loaded.mag_part {
        file.set_mag_part(part);
    }
    file.set(loaded.data.section(), &run.report.model.fitted.params)
        .map_err(|e| e.to_string())?;
    // The device must be able to hold it, within the parts' datasheet bounds.
    file.to_device()
        .map_err(|e| format!("refused, not written: {e}"))?;
    Ok(file.to_toml())
}
