//! One noise-lab session on a column of samples, without I/O: the lab built from the samples and
//! the options, the start model fitted, the walk from it (effects added one by one, or the
//! automatic walk diagnose → add → refit), every model diagnosed, and the object `imu-lab fit
//! --json` prints ([`Session::json`]). The CLI (`imu-lab fit`) and the Python package
//! (`pico_imu.fit`) are thin callers of [`run`]; they only read files and print.
use std::ops::Range;

use allan::{deviation_segments, Stat, TauSet};

use crate::diagnose::{diagnose, Diagnosis};
use crate::lab::{reading, Model, NoiseLab, Record, Timing};
use crate::practical::{recalibration, Recalibration};
use crate::{Assessment, Edit, Effect, Fit, Point, Step, Stop, TermSpec};

mod json;
pub use json::*;

/// The names the caller gives its options in messages (the CLI's flags, Python's keywords).
#[derive(Debug, Clone, Copy)]
pub struct Flags {
    pub terms: &'static str,
    pub add: &'static str,
    pub max_steps: &'static str,
    pub tolerance: &'static str,
}

impl Flags {
    /// The CLI's flags (`--terms`, …).
    pub const CLI: Flags = Flags {
        terms: "--terms",
        add: "--add",
        max_steps: "--max-steps",
        tolerance: "--tolerance",
    };
    /// Python's keyword arguments (`terms`, …).
    pub const PYTHON: Flags = Flags {
        terms: "terms",
        add: "add",
        max_steps: "max_steps",
        tolerance: "tolerance",
    };
}

/// What to fit and how to walk.
#[derive(Debug, Clone)]
pub struct Options {
    /// Start model's effects by name (empty: the lab's default, the five terms of Jaime et al.
    /// plus the data's resolution when its values sit on a lattice).
    pub terms: Vec<String>,
    /// Effects added one step each (ignored with `auto`).
    pub add: Vec<String>,
    /// Walk automatically until the model is adequate or nothing helps.
    pub auto: bool,
    /// Most steps of the automatic walk (1 to 20).
    pub max_steps: usize,
    /// User-described effects (candidates, and nameable in `terms` and `add`).
    pub user: Vec<Effect>,
    /// Bias tolerance in the column's unit: the recalibration period from B, K and R.
    pub tolerance: Option<f64>,
    /// The options' names in messages.
    pub flags: Flags,
}

impl Default for Options {
    fn default() -> Self {
        Options {
            terms: Vec::new(),
            add: Vec::new(),
            auto: false,
            max_steps: 6,
            user: Vec::new(),
            tolerance: None,
            flags: Flags::CLI,
        }
    }
}

/// The column to analyse.
#[derive(Debug, Clone)]
pub struct Input<'a> {
    /// Column name (`gx`, …), as reported.
    pub column: &'a str,
    /// Unit of the samples (e.g. deg/s).
    pub unit: &'a str,
    /// The samples, gaps removed (finite).
    pub y: &'a [f64],
    /// Sample rate [Hz].
    pub rate_hz: f64,
    /// Row ranges of `y` between gaps (at least one; no Allan difference spans a gap).
    pub segments: &'a [Range<usize>],
    /// Temperature [°C] beside each sample (NaN where missing), for the temperature effect.
    pub temp: Option<&'a [f64]>,
    /// What the time column says (gaps, irregular spacing), when there is one.
    pub timing: Option<&'a Timing>,
    /// Prefix of messages about the data (e.g. `rec.csv: column "gx"`).
    pub label: &'a str,
}

/// One analysed model.
#[derive(Debug, Clone)]
pub struct Stage {
    pub model: Model,
    pub diagnosis: Diagnosis,
    /// (τ [s], σ) of the record with the model's time-domain signals removed (empty without
    /// any).
    pub compensated: Vec<(f64, f64)>,
}

/// A finished session: the record's description, the models analysed (the start model first),
/// the steps between them, why an automatic walk stopped and the recalibration period.
#[derive(Debug, Clone)]
pub struct Session {
    pub column: String,
    pub unit: String,
    pub rate_hz: f64,
    pub samples: usize,
    pub timing: Option<Timing>,
    /// The overlapping Allan deviation at octave τ the models were fitted to.
    pub points: Vec<Point>,
    /// Allan rows left out for want of an EDF.
    pub skipped: usize,
    /// The data's lattice step (LSB) in the column's unit, when its values sit on one.
    pub lsb: Option<f64>,
    pub stages: Vec<Stage>,
    pub steps: Vec<Step<Effect>>,
    pub stop: Option<Stop>,
    pub recal: Option<Recalibration>,
}

impl Session {
    /// The last model analysed.
    pub fn last(&self) -> &Stage {
        self.stages
            .last()
            .expect("a session has one stage at least")
    }

    /// The verdict sentence on the last model.
    pub fn verdict(&self) -> String {
        let l = self.last();
        verdict(&l.model.fit, &l.model.assessment, l.diagnosis.adequate)
    }

    /// The unit of every parameter of the last model's terms, term by term: (parameter name,
    /// unit), the amplitude first (in the column's unit × s^k, e.g. N in deg/s·√s), then the
    /// shape parameters (Hz, s, …).
    pub fn param_units(&self) -> Vec<Vec<(String, String)>> {
        let f = &self.last().model.fit;
        let warm_up = f.ctx.temp_avar.is_none();
        f.terms
            .iter()
            .map(|t| {
                std::iter::once((
                    t.effect.amp_name().to_string(),
                    t.effect.amp_unit(&self.unit, warm_up),
                ))
                .chain(t.specs.iter().map(|s| (s.name.clone(), s.unit.clone())))
                .collect()
            })
            .collect()
    }

    /// (name, physical mechanism) of the last model's effects and of the effect the diagnosis
    /// names, each once.
    pub fn physics(&self) -> Vec<(String, String)> {
        let l = self.last();
        let mut out: Vec<(String, String)> = Vec::new();
        for e in l
            .model
            .fit
            .effects()
            .iter()
            .chain(l.diagnosis.missing.iter())
        {
            if !out.iter().any(|(n, _)| n == e.name()) {
                out.push((e.name().to_string(), e.physics().to_string()));
            }
        }
        out
    }
}

/// The segments as the noise lab counts them: (index of the first sample as if the gaps had been
/// recorded, length), the indices advanced by each gap's missing samples.
pub fn nominal_segments(segments: &[Range<usize>], timing: Option<&Timing>) -> Vec<(u64, u64)> {
    let gaps = timing.map(|t| t.gaps.as_slice()).unwrap_or(&[]);
    segments
        .iter()
        .map(|r| {
            let missing: u64 = gaps
                .iter()
                .filter(|g| g.row <= r.start)
                .fold(0u64, |a, g| a.saturating_add(g.missing_samples));
            (r.start as u64 + missing, (r.end - r.start) as u64)
        })
        .collect()
}

/// The options that no data is needed to refuse.
pub fn check_options(o: &Options) -> Result<(), String> {
    if let Some(tol) = o.tolerance {
        if !(tol > 0.0 && tol.is_finite()) {
            return Err(format!(
                "{} {tol}: must be a positive number in the column's unit",
                o.flags.tolerance
            ));
        }
    }
    if o.max_steps == 0 || o.max_steps > 20 {
        return Err(format!(
            "{} {}: give 1 to 20",
            o.flags.max_steps, o.max_steps
        ));
    }
    if o.auto && o.add.iter().any(|s| !s.trim().is_empty()) {
        return Err(format!(
            "{} with the automatic walk: give one or the other (the walk adds the effects it names)",
            o.flags.add
        ));
    }
    Ok(())
}

/// Effects by name (built-in or the user's), refusing an unknown one with the list of known.
pub fn parse_effects(list: &[String], flag: &str, user: &[Effect]) -> Result<Vec<Effect>, String> {
    list.iter()
        .filter(|s| !s.trim().is_empty())
        .map(|s| {
            Effect::parse(s)
                .or_else(|| user.iter().find(|u| u.name() == s.trim()).cloned())
                .ok_or_else(|| {
                    format!(
                        "{flag} {s:?}: unknown effect; expected one of {}{}",
                        crate::ALL_EFFECTS.map(|e| e.name().to_string()).join(", "),
                        if user.is_empty() {
                            String::new()
                        } else {
                            format!(
                                ", {}",
                                user.iter()
                                    .map(|u| u.name().to_string())
                                    .collect::<Vec<_>>()
                                    .join(", ")
                            )
                        }
                    )
                })
        })
        .collect()
}

/// The effects' names joined by " + ".
pub fn names(effects: &[Effect]) -> String {
    effects
        .iter()
        .map(|e| e.name().to_string())
        .collect::<Vec<_>>()
        .join(" + ")
}

/// Readings a temperature column may hold, °C: beyond them no IMU operates (and a value there
/// is a wrong unit or a corrupt field, which would outweigh every other reading).
pub const TEMP_RANGE_C: (f64, f64) = (-100.0, 200.0);

/// The temperature column `t` beside `n` samples, ready for the lab: missing readings (NaN)
/// filled by linear interpolation between the nearest readings on either side (the nearest one
/// at the ends), `None` when none is there; an infinite reading or one outside
/// [`TEMP_RANGE_C`] is refused naming its sample. (Passed with its NaN, one missing reading
/// made every temperature statistic NaN and the lab dropped the column.)
pub fn temperature(t: &[f64], n: usize, label: &str) -> Result<Option<Vec<f64>>, String> {
    if t.len() != n {
        return Err(format!(
            "{label}: {} temperature readings for {n} samples",
            t.len()
        ));
    }
    let (lo, hi) = TEMP_RANGE_C;
    if let Some((i, v)) = t
        .iter()
        .enumerate()
        .find(|(_, v)| !v.is_nan() && !(lo..=hi).contains(*v))
    {
        return Err(format!(
            "{label}: temperature sample {i} = {v} °C is outside {lo}…{hi} °C, where no IMU \
             operates (a wrong unit or a corrupt field)"
        ));
    }
    let known: Vec<usize> = (0..n).filter(|&i| !t[i].is_nan()).collect();
    let (Some(&first), Some(&last)) = (known.first(), known.last()) else {
        return Ok(None);
    };
    let mut out = t.to_vec();
    out[..first].fill(t[first]);
    out[last + 1..].fill(t[last]);
    for w in known.windows(2) {
        let (a, b) = (w[0], w[1]);
        for (i, o) in out.iter_mut().enumerate().take(b).skip(a + 1) {
            let f = (i - a) as f64 / (b - a) as f64;
            *o = t[a] + f * (t[b] - t[a]);
        }
    }
    Ok(Some(out))
}

/// The session: the lab of `input` (its overlapping Allan deviation at octave τ as the fit's
/// points), the start model fitted and the walk from it, each model diagnosed, and the
/// recalibration period when a tolerance is given. Errors name the option or the data.
pub fn run(input: &Input, o: &Options) -> Result<Session, String> {
    check_options(o)?;
    if !(input.rate_hz > 0.0 && input.rate_hz.is_finite()) {
        return Err(format!(
            "{}: rate {} Hz: must be a positive number",
            input.label, input.rate_hz
        ));
    }
    let tau0 = 1.0 / input.rate_hz;
    if let Some(&v) = input.y.first() {
        if input.y.iter().all(|&x| x == v) {
            return Err(format!(
                "{}: all {} samples are {v}: a constant column has no noise to fit (a stuck \
                 sensor, or the wrong column)",
                input.label,
                input.y.len()
            ));
        }
    }
    let segs: Vec<&[f64]> = slices(input.y, input.segments, input.label)?;
    let rows = deviation_segments(&segs, tau0, Stat::Oadev, &TauSet::Octave)
        .map_err(|e| format!("{}: {e}", input.label))?;
    let (points, skipped) = Point::from_rows(&rows);
    let temp = input
        .temp
        .map(|t| temperature(t, input.y.len(), input.label))
        .transpose()?
        .flatten();
    let lab = NoiseLab::new(Record {
        y: input.y,
        unit: input.unit,
        tau0,
        segments: nominal_segments(input.segments, input.timing),
        temp: temp.as_deref(),
        timing: input.timing.cloned(),
        points: points.clone(),
        user_effects: o.user.clone(),
    })
    .map_err(|e| format!("{}: {e}", input.label))?;
    let (models, mut steps, stop) = fit_and_walk(o, &lab, input.label)?;
    let stages = analyse(&lab, input, models)?;
    // the step records say what the diagnosis says of each model
    for (i, s) in steps.iter_mut().enumerate() {
        s.before.adequate = stages[i].diagnosis.adequate;
        s.after.adequate = stages[i + 1].diagnosis.adequate;
    }
    let last = stages.last().expect("one stage");
    let recal = o.tolerance.map(|tol| {
        let (b, k, r, kc, rc) = drift_terms(&last.model.fit);
        recalibration(b, k, r, kc, rc, tol)
    });
    Ok(Session {
        column: input.column.to_string(),
        unit: input.unit.to_string(),
        rate_hz: input.rate_hz,
        samples: input.y.len(),
        timing: input.timing.cloned(),
        points,
        skipped,
        lsb: lab.lsb,
        stages,
        steps,
        stop,
        recal,
    })
}

/// The segments of `y`, refusing ranges outside it or out of order.
fn slices<'a>(
    y: &'a [f64],
    segments: &[Range<usize>],
    label: &str,
) -> Result<Vec<&'a [f64]>, String> {
    let mut end = 0;
    segments
        .iter()
        .enumerate()
        .map(|(i, r)| {
            if r.start < end || r.start > r.end || r.end > y.len() {
                return Err(format!(
                    "{label}: segment {i} ({}..{}): must lie in the {} samples, in order, without overlap",
                    r.start,
                    r.end,
                    y.len()
                ));
            }
            end = r.end;
            Ok(&y[r.clone()])
        })
        .collect()
}

/// The start model (`terms`, or the lab's default) fitted, then the walk from it: automatic
/// with `auto`, else one step per `add`. Returns the models, the steps between them and, for
/// `auto`, why the walk stopped.
#[allow(clippy::type_complexity)]
/// The start model fitted and, with `auto`, the walk from it; a fit that fails names the
/// record (`label`) and the model.
fn fit_and_walk(
    o: &Options,
    lab: &NoiseLab,
    label: &str,
) -> Result<(Vec<Model>, Vec<Step<Effect>>, Option<Stop>), String> {
    let f = o.flags;
    let base: Vec<TermSpec> = if o.terms.is_empty() {
        lab.default_specs()
    } else {
        parse_effects(&o.terms, f.terms, &o.user)?
            .into_iter()
            .map(TermSpec::new)
            .collect()
    };
    let adds = parse_effects(&o.add, f.add, &o.user)?;
    for e in &adds {
        if !e.repeatable() && base.iter().any(|s| s.effect == *e) {
            return Err(format!("{} {e}: the model already has it", f.add));
        }
        if matches!(e, Effect::BiasStep) {
            return Err(format!("{} bias_step: a step's instant comes from the change-point test; use --auto, which adds the steps it finds", f.add));
        }
        if matches!(e, Effect::Drift { .. }) {
            return Err(format!("{} drift: a drift's shape comes from the time-domain test; use --auto, which adds the drift it finds", f.add));
        }
    }
    let start = lab.fit(&base).map_err(|e| {
        format!(
            "{label}: fit of {}: {e}",
            names(&base.iter().map(|s| s.effect.clone()).collect::<Vec<_>>())
        )
    })?;
    if o.auto {
        let w = crate::walk(lab, start, o.max_steps).map_err(|e| format!("{label}: {e}"))?;
        return Ok((w.models, w.steps, Some(w.stop)));
    }
    let mut models: Vec<Model> = vec![start];
    let mut steps: Vec<Step<Effect>> = Vec::new();
    for e in &adds {
        let prev = models.last().expect("one model");
        let mut specs = prev.specs.clone();
        if e.replaces_white() {
            specs.retain(|s| s.effect != Effect::White);
        }
        specs.push(TermSpec::new(e.clone()));
        let next = lab
            .fit(&specs)
            .map_err(|err| format!("{label}: fit with {e}: {err}"))?;
        let before = summary(lab, prev);
        steps.push(Step {
            edit: Edit {
                add: vec![e.clone()],
                remove: if e.replaces_white()
                    && prev.specs.iter().any(|s| s.effect == Effect::White)
                {
                    vec![Effect::White]
                } else {
                    vec![]
                },
            },
            before,
            after: summary(lab, &next),
            p_value: f64::NAN,
            reading: reading(&next.fit, e, lab.record.unit),
            reason: String::new(),
        });
        models.push(next);
    }
    Ok((models, steps, None))
}

/// Each model diagnosed, with the Allan deviation of the record with its time-domain signals
/// removed.
fn analyse(lab: &NoiseLab, input: &Input, models: Vec<Model>) -> Result<Vec<Stage>, String> {
    let tau0 = 1.0 / input.rate_hz;
    models
        .into_iter()
        .map(|m| {
            let d = diagnose(lab, &m).map_err(|e| format!("{e}"))?;
            let compensated = match lab.compensated(&m) {
                Some(yc) => {
                    let segs: Vec<&[f64]> = input.segments.iter().map(|r| &yc[r.clone()]).collect();
                    deviation_segments(&segs, tau0, Stat::Oadev, &TauSet::Octave)
                        .map_err(|e| format!("{e}"))?
                        .iter()
                        .map(|r| (r.tau, r.dev))
                        .collect()
                }
                None => Vec::new(),
            };
            Ok(Stage {
                model: m,
                diagnosis: d,
                compensated,
            })
        })
        .collect()
}

fn summary(lab: &NoiseLab, m: &Model) -> crate::Summary {
    <NoiseLab as model_lab::Lab>::summary(lab, m)
}

/// B, K, R with their conservative values (+1σ, or the 95 % upper end when not detected).
pub fn drift_terms(f: &Fit) -> (f64, f64, f64, f64, f64) {
    let get = |e: Effect| -> (f64, f64) {
        match f.term(&e) {
            Some(t) if t.detected => (t.amplitude(), t.amplitude() + t.amplitude_sigma()),
            Some(t) => (0.0, t.amplitude_interval().1),
            None => (0.0, 0.0),
        }
    };
    let (b, _) = get(Effect::Flicker);
    let (k, kc) = get(Effect::RateRandomWalk);
    let (r, rc) = get(Effect::RateRamp);
    (b, k, r, kc, rc)
}

/// `x` with `sig` significant digits, fixed notation for 1e-3 ≤ |x| < 1e5, else scientific.
pub fn sig(x: f64, sig: usize) -> String {
    if !x.is_finite() {
        return "—".into();
    }
    if x == 0.0 {
        return "0".into();
    }
    let e = x.abs().log10().floor() as i32;
    if (-3..5).contains(&e) {
        let dec = (sig as i32 - 1 - e).max(0) as usize;
        format!("{:.*}", dec, x)
    } else {
        format!("{:.*e}", sig.saturating_sub(1), x)
    }
}

/// The verdict sentence. `adequate` is the lab's whole verdict (the Allan test, the time-domain
/// checks and the candidates' nested tests).
pub fn verdict(fit: &Fit, a: &Assessment, adequate: bool) -> String {
    if a.adequate && !adequate {
        return format!(
            "NOT ADEQUATE — the Allan curve alone passes (χ²/dof = {}, global p = {}), but the \
             record shows an effect the model lacks (see the diagnosis).",
            sig(fit.chi2_dof(), 3),
            sig(a.p_value, 2)
        );
    }
    if a.adequate {
        format!(
            "ADEQUATE — χ²/dof = {}, global p = {}, and no τ where the model leaves the 68.3 % interval significantly (largest |z| = {:.1}, below the threshold {:.1}).",
            sig(fit.chi2_dof(), 3),
            sig(a.p_value, 2),
            a.largest_z(),
            a.threshold
        )
    } else {
        let ranges: Vec<String> = if a.failing.is_empty() {
            vec!["(no single range: the misfit is spread over all τ)".into()]
        } else {
            a.failing
                .iter()
                .map(|r| {
                    format!(
                        "τ = {}–{} s (measured {} model, up to |z| = {:.1})",
                        sig(r.lo, 3),
                        sig(r.hi, 3),
                        if r.sign > 0 { "above" } else { "below" },
                        r.worst_z
                    )
                })
                .collect()
        };
        format!(
            "NOT ADEQUATE — χ²/dof = {}, global p = {}; failing: {}.",
            sig(fit.chi2_dof(), 3),
            sig(a.p_value, 2),
            ranges.join("; ")
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn white(n: usize, key: u64, sigma: f64) -> Vec<f64> {
        let mut g = crate::test_noise(key);
        (0..n).map(|_| sigma * g()).collect()
    }

    /// `--auto`'s walk on one gap-free segment of `y` (100 Hz, deg/s).
    fn walk(y: &[f64]) -> Session {
        let segs = [Range {
            start: 0,
            end: y.len(),
        }];
        let o = Options {
            auto: true,
            ..Options::default()
        };
        run(&input(y, &segs), &o).unwrap()
    }

    fn input<'a>(y: &'a [f64], segments: &'a [Range<usize>]) -> Input<'a> {
        Input {
            column: "gx",
            unit: "deg/s",
            y,
            rate_hz: 100.0,
            segments,
            temp: None,
            timing: None,
            label: "test",
        }
    }

    /// White noise of a known size: the session's white term finds it within its σ-based
    /// interval, the JSON says what the session holds, and the walk's first model is the start.
    #[test]
    fn white_noise_session_and_its_json() {
        for key in [3u64, 17, 91] {
            let sigma = 0.01 + 0.01 * (key % 5) as f64;
            let y = white(20_000, key, sigma);
            let segs = [Range {
                start: 0,
                end: y.len(),
            }];
            let s = run(&input(&y, &segs), &Options::default()).unwrap();
            assert_eq!(s.stages.len(), 1);
            assert!(s.steps.is_empty() && s.stop.is_none());
            // N = σ·√τ0 for white rate noise sampled at 100 Hz
            let n_true = sigma * (0.01f64).sqrt();
            let t = s.last().model.fit.term(&Effect::White).unwrap();
            assert!(
                (t.amplitude() - n_true).abs() < 4.0 * t.amplitude_sigma() + 0.03 * n_true,
                "N = {} ± {} against {n_true}",
                t.amplitude(),
                t.amplitude_sigma()
            );
            let j: serde_json::Value = serde_json::from_str(&s.json_string()).unwrap();
            assert_eq!(j["samples"], 20_000);
            assert_eq!(j["column"], "gx");
            assert_eq!(j["adev"].as_array().unwrap().len(), s.points.len());
            assert!(j["timing"].is_null());
            let units = s.param_units();
            assert_eq!(units.len(), s.last().model.fit.terms.len());
            assert!(units.iter().all(|u| !u[0].1.is_empty()));
            // the verdict gives the largest |z|, not the threshold as if it were one
            let a = &s.last().model.assessment;
            let largest = a.z.iter().map(|z| z.abs()).fold(0.0, f64::max);
            assert!(largest > 0.0 && largest < a.threshold);
            assert!(
                s.verdict().contains(&format!(
                    "largest |z| = {largest:.1}, below the threshold {:.1}",
                    a.threshold
                )),
                "{}",
                s.verdict()
            );
            let mut nan = a.clone();
            nan.z[1] = f64::NAN;
            assert!(nan.largest_z().is_nan());
        }
    }

    /// Missing temperature readings are filled between their neighbours (the nearest at the
    /// ends); none at all is no column; an infinite or impossible one is refused by sample.
    #[test]
    fn missing_temperatures_are_interpolated_and_impossible_ones_refused() {
        let nan = f64::NAN;
        let t = [nan, 20.0, nan, nan, 23.0, nan];
        assert_eq!(
            temperature(&t, 6, "x").unwrap().unwrap(),
            [20.0, 20.0, 21.0, 22.0, 23.0, 23.0]
        );
        assert_eq!(temperature(&[nan; 4], 4, "x").unwrap(), None);
        for (v, want) in [
            (f64::INFINITY, "x: temperature sample 2 = inf °C is outside"),
            (
                1e6,
                "x: temperature sample 2 = 1000000 °C is outside -100…200 °C",
            ),
        ] {
            let e = temperature(&[20.0, 21.0, v], 3, "x").unwrap_err();
            assert!(e.starts_with(want), "{e}");
        }
        assert!(temperature(&[20.0], 2, "x").is_err());
    }

    /// A temperature coefficient is found the same with readings missing at random (a CSV's
    /// empty fields): one missing reading used to drop the column.
    #[test]
    fn a_temperature_coefficient_survives_missing_readings() {
        let key = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(7, |d| d.subsec_nanos() as u64);
        let n = 30_000;
        let coef = 0.005 + (key % 10) as f64 * 1e-3;
        let temp: Vec<f64> = (0..n)
            .map(|i| 20.0 + 15.0 * (1.0 - (-(i as f64) / 8_000.0).exp()))
            .collect();
        let noise = white(n, key, 0.02);
        let y: Vec<f64> = (0..n).map(|i| noise[i] + coef * (temp[i] - 20.0)).collect();
        let segs = [Range { start: 0, end: n }];
        let o = Options {
            terms: vec!["white".into(), "temperature".into()],
            ..Options::default()
        };
        let coef_of = |t: &[f64]| {
            let s = run(
                &Input {
                    temp: Some(t),
                    ..input(&y, &segs)
                },
                &o,
            )
            .unwrap();
            let t = s
                .last()
                .model
                .fit
                .term(&Effect::Temperature)
                .cloned()
                .unwrap();
            (t.amplitude(), t.amplitude_sigma(), t.detected)
        };
        let full = coef_of(&temp);
        let mut holed = temp.clone();
        let mut g = crate::test_noise(key ^ 0x55);
        for _ in 0..(1 + key % 300) {
            let i = ((g().abs() * 1e6) as usize) % n;
            holed[i] = f64::NAN;
        }
        holed[0] = f64::NAN;
        let with_holes = coef_of(&holed);
        assert!(full.2 && with_holes.2, "key {key}: {full:?} {with_holes:?}");
        assert!(
            (full.0 - coef).abs() < 4.0 * full.1 && (with_holes.0 - full.0).abs() < 0.5 * full.1,
            "key {key}: {coef} against {full:?} and, with holes, {with_holes:?}"
        );
    }

    /// The temperature column analysed beside itself (or a copy in other units) is no
    /// regressor: the session is the one without a temperature column. (Passed, the walk
    /// regressed the column on itself, coefficient 1.000 per °C, and χ²/dof rose 70-fold.)
    #[test]
    fn the_temperature_column_is_no_regressor_for_itself() {
        let key = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(11, |d| d.subsec_nanos() as u64);
        let n = 20_000 + (key % 10_000) as usize;
        let tc = 2_000.0 + (key % 7_000) as f64;
        let noise = white(n, key, 0.01 + (key % 5) as f64 * 0.01);
        // A warming board read by a quantising sensor: a transient, the noise, 1/340 °C steps.
        let y: Vec<f64> = (0..n)
            .map(|i| {
                let v = 25.0 + 8.0 * (1.0 - (-(i as f64) / tc).exp()) + noise[i];
                (v * 340.0).round() / 340.0
            })
            .collect();
        let fahrenheit: Vec<f64> = y.iter().map(|c| c * 1.8 + 32.0).collect();
        let segs = [Range { start: 0, end: n }];
        let o = Options {
            auto: true,
            ..Options::default()
        };
        let alone = run(&input(&y, &segs), &o).unwrap().json_string();
        for t in [&y, &fahrenheit] {
            let beside = run(
                &Input {
                    temp: Some(t),
                    ..input(&y, &segs)
                },
                &o,
            )
            .unwrap()
            .json_string();
            assert!(
                beside == alone,
                "key {key}: with itself as the temperature the session differs"
            );
        }
    }

    /// A glitch or a stuck stretch in white noise: the Allan fit alone passes them (a spike
    /// reads as white noise), the session does not: not adequate, the defect named with its
    /// sample; the same noise without it is adequate.
    #[test]
    fn a_glitch_or_a_stuck_stretch_is_not_adequate() {
        let key = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(13, |d| d.subsec_nanos() as u64);
        let n = 10_000 + (key % 20_000) as usize;
        let sigma = 0.01 + (key % 7) as f64 * 0.01;
        let clean = white(n, key, sigma);
        let verdict = |y: &[f64]| {
            let s = walk(y);
            let d = &s.last().diagnosis;
            (d.adequate, d.evidence.join("\n"))
        };
        assert!(
            verdict(&clean).0,
            "key {key}: clean white noise not adequate"
        );
        let mut spiked = clean.clone();
        let at = 1 + (key as usize / 3) % (n - 2);
        spiked[at] += sigma * 10f64.powf(1.5 + (key % 50) as f64 / 10.0);
        let (ok, why) = verdict(&spiked);
        assert!(
            !ok && why.contains(&format!("sample {at} (t = ")),
            "key {key}: a spike at {at}: {why}"
        );
        let mut stuck = clean.clone();
        let len = 200 + (key as usize / 7) % 2_000;
        let from = (key as usize / 11) % (n - len);
        let v = stuck[from];
        stuck[from..from + len].fill(v);
        let (ok, why) = verdict(&stuck);
        assert!(
            !ok && why.contains(&format!("samples {from}–{}", from + len - 1)),
            "key {key}: stuck {from}+{len}: {why}"
        );
    }

    /// A glitch beside a real bias step (0.7–1.1 σ, where the Allan curve alone often passes):
    /// the diagnosis that names the step says so in its explanation, with the defect beside it
    /// (it explained the defect alone while naming the step); the walk adds the step once
    /// named and ends not adequate, the glitch named.
    #[test]
    fn a_defect_beside_a_missing_effect_names_both() {
        let key = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(29, |d| d.subsec_nanos() as u64);
        let (n, sigma) = (20_000, 0.02);
        let mut y = white(n, key, sigma);
        let at = 2_000 + (key as usize / 5) % 16_000;
        y[at..]
            .iter_mut()
            .for_each(|v| *v += sigma * (0.7 + (key % 41) as f64 / 100.0));
        let g = (at + 1_000 + (key as usize / 13) % 10_000) % (n - 2) + 1;
        y[g] += sigma * (30.0 + (key % 200) as f64);
        let s = walk(&y);
        for st in &s.stages {
            let d = &st.diagnosis;
            match &d.missing {
                Some(e) => assert!(
                    d.explanation.starts_with("The model misses")
                        || d.explanation
                            .contains("fits significantly better. The model misses"),
                    "key {key}: names {e} but explains: {}",
                    d.explanation
                ),
                None => assert!(
                    d.explanation.starts_with("The record holds a defect"),
                    "key {key}: {}",
                    d.explanation
                ),
            }
            assert!(
                d.explanation.contains(&format!("sample {g} (t = ")),
                "key {key}: the glitch at {g} unnamed: {}",
                d.explanation
            );
        }
        let last = &s.last().diagnosis;
        assert!(!last.adequate, "key {key}");
        // a step as small as 0.7 σ is not always found; once named, it is added
        let named = s.stages.iter().any(|st| {
            st.diagnosis
                .missing
                .as_ref()
                .is_some_and(|e| e.to_string().starts_with("bias_step"))
        });
        assert!(
            !named
                || s.last()
                    .model
                    .specs
                    .iter()
                    .any(|t| t.effect.to_string().starts_with("bias_step")),
            "key {key}: the step at {at} named but not in the final model"
        );
    }

    /// White noise with one bias step (1.5–3.9 σ, anywhere) at the key's realisation: the walks
    /// that named a step and then an effect after it, by key.
    fn step_walks(keys: impl Iterator<Item = u64>) -> Vec<(u64, Vec<String>)> {
        keys.map(|key| {
            let (n, sigma) = (30_000, 0.02);
            let mut y = white(n, key, sigma);
            let at = 3_000 + (key as usize * 7919) % 24_000;
            y[at..]
                .iter_mut()
                .for_each(|v| *v += sigma * (1.5 + (key % 25) as f64 / 10.0));
            let s = walk(&y);
            let added = s.steps.iter().map(|st| st.edit.to_string()).collect();
            (key, added)
        })
        .filter(|(_, added): &(u64, Vec<String>)| added.len() > 1)
        .collect()
    }

    /// After the right step no filter is named in place of white noise for what its refit
    /// moved elsewhere: the swap's time-domain ratio was taken on the whole change from the
    /// current model (a random walk and the step's estimate moved with the refit), 12.4 where
    /// the Allan points gave 2.1, and a low-pass or a moving average was named at keys 98 and
    /// 103. Those keys and two at random.
    #[test]
    fn no_filter_is_named_for_what_the_refit_moved() {
        let key = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(31, |d| d.subsec_nanos() as u64);
        let keys = [98, 103, 200 + key % 1000, 1200 + key % 997];
        let swaps: Vec<_> = step_walks(keys.into_iter())
            .into_iter()
            .filter(|(_, added)| added.iter().any(|a| a.contains("− white")))
            .collect();
        assert!(swaps.is_empty(), "{swaps:?}");
    }

    /// After the right step nothing more is named for white noise, where the old time-domain
    /// test credited a Markov candidate with what the refit's other terms gained (a random walk
    /// the current model carried dropped to zero beside it): the three realisations of the
    /// sweep below where it named one (keys 23, 24 and 28), each of which it did.
    #[test]
    fn after_the_right_step_white_noise_needs_nothing_more() {
        let extra = step_walks([23, 24, 28].into_iter());
        assert!(extra.is_empty(), "{extra:?}");
    }

    /// The sweep: 40 realisations, at most 2 walks name anything after the step (the old rule
    /// named a Markov process or a filter in 4: keys 23, 24, 28 and 39; now only 39). About three
    /// minutes in release: `cargo test --release -p noise-model --lib -- --ignored step_sweep`.
    #[test]
    #[ignore]
    fn step_sweep() {
        let extra = step_walks(0..40);
        assert!(extra.len() <= 2, "{} of 40: {extra:?}", extra.len());
    }

    /// A step in white noise, estimated in the time domain, and the Allan fit after it: the
    /// step's 1σ relative to white noise's bound σ_w·√(1/n₁ + 1/n₂), its error in its own σ,
    /// and χ²/dof without and with it.
    fn step_precision(key: u64) -> (f64, f64, f64, f64) {
        let (n, sigma) = (30_000, 0.02);
        let mut y = white(n, key, sigma);
        let at = 3_000 + (key as usize * 7919) % 24_000;
        let size = sigma * (1.5 + (key % 25) as f64 / 10.0);
        y[at..].iter_mut().for_each(|v| *v += size);
        let s = walk(&y);
        let Some((k, st)) = s
            .stages
            .iter()
            .enumerate()
            .find_map(|(k, g)| Some((k, g.model.fit.term(&Effect::BiasStep)?)))
        else {
            return (f64::NAN, f64::NAN, f64::NAN, f64::NAN);
        };
        let bound = sigma * (1.0 / at as f64 + 1.0 / (n - at) as f64).sqrt();
        (
            st.amplitude_sigma() / bound,
            (st.amplitude() - size) / st.amplitude_sigma(),
            s.stages[k - 1].model.fit.chi2_dof(),
            s.stages[k].model.fit.chi2_dof(),
        )
    }

    /// Adding the right step to white noise does not make the fit worse (χ²/dof rises by less
    /// than 1), and the step is where it is. The time-domain estimate and the Allan fit take
    /// turns; they alternated between a random walk the data did not support (K² ≈ 2e-7, under
    /// which the step is estimated from the samples near it, with 3–8 times white noise's σ)
    /// and none, and ended on the former in most realisations: χ²/dof then rose, 0.65 → 6.75
    /// at key 39, 2.45 → 5.17 at key 3, 0.26 → 2.27 at key 26, and an effect was named for it.
    /// Those keys and two at random.
    #[test]
    fn the_right_step_does_not_make_the_fit_worse() {
        let key = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(29, |d| d.subsec_nanos() as u64);
        for k in [39, 3, 26, 40 + key % 1000, 1040 + key % 997] {
            let (rel, z, before, after) = step_precision(k);
            assert!(
                after < before + 1.0,
                "key {k}: χ²/dof {before:.2} → {after:.2} with the step (σ {rel:.2}× white noise's bound)"
            );
            assert!(z.abs() < 4.0, "key {k}: the step is off by {z:.2} σ");
        }
    }

    /// The sweep of [`step_precision`] over 40 keys: χ²/dof rises by less than 1 with the step
    /// in every one (it rose by more in 5 when the last round was kept, and in 6 with the
    /// estimate's share taken out of the points' covariance in full), and the step's σ is
    /// within 3.2 times white noise's bound at the median (2.7; 3.6 with the last round kept).
    /// About two minutes in release: `cargo test --release -p noise-model --lib -- --ignored
    /// step_precision_sweep --nocapture`.
    #[test]
    #[ignore]
    fn step_precision_sweep() {
        let mut rel = Vec::new();
        let mut worse = Vec::new();
        for k in 0..40 {
            let (r, z, before, after) = step_precision(k);
            eprintln!("key {k}: σ/bound {r:.2}, z {z:+.2}, χ²/dof {before:.2} → {after:.2}");
            rel.push(r);
            if !(after < before + 1.0) {
                worse.push(k);
            }
        }
        rel.sort_by(f64::total_cmp);
        let median = 0.5 * (rel[19] + rel[20]);
        assert!(worse.is_empty(), "worse with the step: {worse:?}");
        assert!(median < 3.2, "median σ/bound {median:.2}");
    }

    /// A reading carries its amplitude's unit and 1σ, in the walk's steps, the findings and
    /// the JSON terms (they printed "a bias step of -1.1489e-1 at t = 100 s").
    #[test]
    fn readings_carry_their_unit_and_uncertainty() {
        let key = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(17, |d| d.subsec_nanos() as u64);
        let n = 20_000;
        let at = 5_000 + (key % 10_000) as usize;
        let mut y = white(n, key, 0.02);
        y[at..].iter_mut().for_each(|v| *v += 0.05);
        let segs = [Range { start: 0, end: n }];
        let s = run(
            &Input {
                unit: "m/s²",
                ..input(&y, &segs)
            },
            &Options {
                auto: true,
                ..Options::default()
            },
        )
        .unwrap();
        let reading = &s.steps[0].reading;
        assert!(
            reading.starts_with("a bias step of +")
                && reading.contains(" ± ")
                && reading.contains(" m/s² at t = "),
            "key {key}: {reading}"
        );
        let j = s.json_string();
        assert!(j.contains(" m/s² at t = "), "key {key}: {j}");
        let first = &s.stages[0].diagnosis.evidence.join("\n");
        assert!(first.contains(" m/s² at t ≈ "), "key {key}: {first}");
    }

    /// A warm-up's time constant comes with its 1σ, from the likelihood profile over the
    /// scanned time constants (it had none), and covers the truth. (The walk names some
    /// exponentials a drift instead: six draws, at least one warm-up.)
    #[test]
    fn a_warm_up_time_constant_has_its_uncertainty() {
        let key = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(19, |d| d.subsec_nanos() as u64);
        let mut named = 0;
        for draw in 0..6u64 {
            let k = key.wrapping_add(draw * 7_919);
            let n = 30_000;
            let tw = 10.0 + (k % 50) as f64;
            let a = 0.5 + (k / 50 % 15) as f64 * 0.1;
            let noise = white(n, k, 0.01);
            let y: Vec<f64> = (0..n)
                .map(|i| noise[i] + a * (-(i as f64) / 100.0 / tw).exp())
                .collect();
            let s = walk(&y);
            let Some(t) = s.last().model.fit.term(&Effect::Temperature).cloned() else {
                continue;
            };
            named += 1;
            let (got, sigma) = (t.theta[0], t.theta_sigma[0]);
            assert!(
                sigma > 0.0 && sigma < 0.5 * tw && (got - tw).abs() < 4.0 * sigma,
                "key {k}: {tw} s against {got} ± {sigma} s"
            );
        }
        assert!(named > 0, "key {key}: no warm-up named in six");
    }

    /// White noise rounded to an LSB of 3–6 σ (most samples on one level) is described by the
    /// white term, adequate, with the evidence saying the noise is below the LSB (a known
    /// LSB²/12 floor put every point below the model, χ²/dof 332) and no lone excursion called
    /// a glitch; rounded to an LSB of 0.6–1 σ the lattice is the known resolution term as before.
    #[test]
    fn noise_below_the_lsb_is_white_and_said() {
        let key = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(23, |d| d.subsec_nanos() as u64);
        let sigma = 0.05;
        let clean = white(20_000, key, sigma);
        for (k, coarse) in [
            (3.0 + (key % 30) as f64 / 10.0, true),
            (0.6 + (key % 5) as f64 / 10.0, false),
        ] {
            let lsb = k * sigma;
            let y: Vec<f64> = clean.iter().map(|v| (v / lsb).round() * lsb).collect();
            let s = walk(&y);
            let d = &s.last().diagnosis;
            let said = d
                .evidence
                .iter()
                .any(|e| e.contains("below the data's LSB"));
            let has_res = s.last().model.fit.term(&Effect::Resolution).is_some();
            assert_eq!(said, coarse, "key {key}: LSB {k} σ: {:?}", d.evidence);
            assert_eq!(has_res, !coarse, "key {key}: LSB {k} σ");
            if coarse {
                assert!(d.adequate, "key {key}: LSB {k} σ: {}", d.explanation);
            }
        }
    }

    #[test]
    fn options_and_segments_are_refused_by_name() {
        let flat = vec![0.25; 4000];
        let whole = [Range {
            start: 0,
            end: flat.len(),
        }];
        let e = run(&input(&flat, &whole), &Options::default()).unwrap_err();
        assert_eq!(
            e,
            "test: all 4000 samples are 0.25: a constant column has no noise to fit (a stuck \
             sensor, or the wrong column)"
        );
        let y = white(3000, 5, 0.01);
        let segs = [Range {
            start: 0,
            end: y.len(),
        }];
        let tol = Options {
            tolerance: Some(-1.0),
            ..Options::default()
        };
        assert!(run(&input(&y, &segs), &tol)
            .unwrap_err()
            .starts_with("--tolerance -1"));
        let py = Options {
            max_steps: 0,
            flags: Flags::PYTHON,
            ..Options::default()
        };
        assert!(run(&input(&y, &segs), &py)
            .unwrap_err()
            .starts_with("max_steps 0"));
        let unknown = Options {
            terms: vec!["whit".into()],
            ..Options::default()
        };
        assert!(run(&input(&y, &segs), &unknown)
            .unwrap_err()
            .starts_with("--terms \"whit\": unknown effect"));
        let bad = [0..10, 5..20];
        let e = run(&input(&y, &bad), &Options::default()).unwrap_err();
        assert!(e.contains("segment 1 (5..20)"), "{e}");
        let beyond = [Range {
            start: 0,
            end: y.len() + 1,
        }];
        assert!(run(&input(&y, &beyond), &Options::default()).is_err());
    }
}
