//! The noise lab in the page: a column of a recording, the session `imu-lab fit` runs on it
//! ([`noise_model::session`]), and the edits a click makes — add the named effect, add or remove
//! any effect of the vocabulary, run the automatic walk — each one a new session from the
//! current model, so every view is what `imu-lab fit` prints for the command the page shows
//! beside it, and the exports are that command's `--json` and `--report`.
use std::path::PathBuf;
use std::sync::Arc;

use anyhow::{anyhow, Result};
use axum::body::Bytes;
use axum::extract::State;
use axum::http::{header, HeaderValue, StatusCode};
use axum::response::{IntoResponse, Response};
use axum::Json;
use imu_proto::csv::Timing;
use noise_model::session::{self, Session};
use noise_model::{Effect, ALL_EFFECTS};
use serde::{Deserialize, Serialize};
use serde_json::{json, Value};
use tokio::sync::Mutex;

use super::{error, Shared};
use crate::input::{self, InputArgs};
use crate::render::noise as report;
use crate::render::session_report::{report_html, report_title};

/// Samples the page's curves are drawn with (per decade of τ).
const CURVE_PER_DECADE: usize = 12;

/// The lab: the recording it works on (none yet in live mode), the current column's state
/// (held by a write for the whole of its fit, so that edits follow one another), and what the
/// last completed write published: reads take that, so a page asking for the view or an export
/// while a fit runs gets the current one at once instead of waiting for the fit.
pub struct Lab {
    file: Mutex<Option<InputArgs>>,
    state: Mutex<Option<Column>>,
    published: std::sync::Mutex<Option<Published>>,
}

/// The view and the session behind it, as the last completed write left them.
struct Published {
    view: Value,
    session: Arc<Session>,
    file: PathBuf,
    column: String,
}

/// One column's samples, as the session wants them.
struct Data {
    column: String,
    unit: String,
    y: Vec<f64>,
    rate_hz: f64,
    segments: Vec<std::ops::Range<usize>>,
    temp: Option<Vec<f64>>,
    timing: Option<Timing>,
    label: String,
}

/// The column under study: its data, the current model's terms (None: the lab's default start
/// model), the session that produced the view, and the step table so far.
struct Column {
    data: Arc<Data>,
    file: PathBuf,
    /// The reading options of `imu-lab fit` the recording was opened with (`--rate`,
    /// `--scale`, `--rename`, …), as flags.
    flags: Vec<String>,
    terms: Option<Vec<String>>,
    /// The `imu-lab fit` options after the file and column that give this session.
    command: Vec<String>,
    session: Arc<Session>,
    steps: Vec<StepRow>,
}

/// One row of the page's step table.
#[derive(Serialize, Clone)]
struct StepRow {
    edit: String,
    chi2_dof_before: f64,
    chi2_dof_after: f64,
    rms_log_residual_before: f64,
    rms_log_residual_after: f64,
    adequate_before: bool,
    adequate_after: bool,
    reading: String,
}

/// The effects a click may add or remove: the vocabulary but the steps and the drift, whose
/// shape comes from the time-domain tests of the automatic walk.
pub fn vocabulary() -> Vec<String> {
    ALL_EFFECTS
        .iter()
        .filter(|e| hand_editable(e.name()))
        .map(|e| e.name().to_string())
        .collect()
}

fn hand_editable(name: &str) -> bool {
    matches!(Effect::parse(name), Some(e) if !matches!(e, Effect::BiasStep | Effect::Drift { .. }))
}

/// The sensor columns of the contract, the ones the lab analyses.
const SENSOR_COLUMNS: [&str; 9] = ["ax", "ay", "az", "gx", "gy", "gz", "mx", "my", "mz"];

/// The sensor columns among the names a reader selected.
fn data_columns(names: &[String]) -> Vec<String> {
    names
        .iter()
        .filter(|n| SENSOR_COLUMNS.contains(&n.as_str()))
        .cloned()
        .collect()
}

/// The recording's header read: its sensor columns.
fn columns_of(args: &InputArgs) -> Result<Vec<String>> {
    let names = input::open_with(args, &[], &SENSOR_COLUMNS)?.names;
    Ok(data_columns(&names))
}

/// The reading options as `imu-lab fit`'s flags (none for a file in the contract).
fn input_flags(a: &InputArgs) -> Vec<String> {
    let mut v = Vec::new();
    if let Some(r) = a.rate {
        v.extend(["--rate".into(), r.to_string()]);
    }
    if a.ignore_time {
        v.push("--ignore-time".into());
    }
    if a.skip_lines > 0 {
        v.extend(["--skip-lines".into(), a.skip_lines.to_string()]);
    }
    if let Some(x) = a.scale {
        v.extend(["--scale".into(), x.to_string()]);
    }
    if let Some(u) = &a.unit {
        v.extend(["--unit".into(), u.clone()]);
    }
    if !a.rename.is_empty() {
        v.extend(["--rename".into(), a.rename.join(",")]);
    }
    v
}

impl Lab {
    /// The lab on a recording: its header is read now, so a missing or malformed file is
    /// refused before the server starts.
    /// `args` are `imu-lab fit`'s reading options (any CSV `fit` takes: columns renamed,
    /// scaled, a unit, a rate, metadata lines skipped), and the same errors for bad input.
    pub fn open(args: InputArgs) -> Result<Lab> {
        if columns_of(&args)?.is_empty() {
            return Err(anyhow!(
                "{}: no sensor column (ax … mz) to analyse",
                args.file.display()
            ));
        }
        Ok(Lab {
            file: Mutex::new(Some(args)),
            state: Mutex::new(None),
            published: std::sync::Mutex::new(None),
        })
    }

    /// The lab without a recording yet (live mode: it opens the recordings made).
    pub fn empty() -> Lab {
        Lab {
            file: Mutex::new(None),
            state: Mutex::new(None),
            published: std::sync::Mutex::new(None),
        }
    }

    /// Study `file` from now on (a recording just made).
    pub async fn set_file(&self, file: PathBuf) -> Result<()> {
        let args = InputArgs::for_file(file);
        if columns_of(&args)?.is_empty() {
            return Err(anyhow!(
                "{}: no sensor column (ax … mz) to analyse",
                args.file.display()
            ));
        }
        *self.file.lock().await = Some(args);
        let mut state = self.state.lock().await;
        *state = None;
        *self.published() = None;
        Ok(())
    }

    /// The state's lock, as a write holds it while its fit runs (for the tests).
    #[cfg(test)]
    pub(super) async fn hold(&self) -> impl Sized + '_ {
        self.state.lock().await
    }

    fn published(&self) -> std::sync::MutexGuard<'_, Option<Published>> {
        // Only ever replaced whole: a panic elsewhere cannot leave it half-written.
        self.published
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    /// `c` is the lab's state now: its view is what reads get from here on.
    fn publish(&self, c: &Column) -> Response {
        let view = view_of(c);
        *self.published() = Some(Published {
            view: view.clone(),
            session: c.session.clone(),
            file: c.file.clone(),
            column: c.data.column.clone(),
        });
        Json(view).into_response()
    }

    /// The recording's name and columns (null without one).
    pub async fn describe(&self) -> Value {
        let file = self.file.lock().await.clone();
        match file {
            None => Value::Null,
            Some(f) => match columns_of(&f) {
                Ok(columns) => json!({
                    "file": f.file.display().to_string(),
                    "columns": columns,
                }),
                Err(e) => {
                    json!({ "file": f.file.display().to_string(), "error": format!("{e:#}") })
                }
            },
        }
    }
}

/// The body of a write, parsed strictly: unknown fields, wrong types and bad JSON are refused
/// (the message says what, for a 400).
pub fn body<T: for<'de> Deserialize<'de>>(bytes: &Bytes) -> Result<T, String> {
    serde_json::from_slice(bytes).map_err(|e| format!("request body: {e}"))
}

fn bad_request(message: &str) -> Response {
    error(StatusCode::BAD_REQUEST, message)
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SelectBody {
    column: String,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct EditBody {
    #[serde(default)]
    add: Option<String>,
    #[serde(default)]
    remove: Option<String>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Empty {}

/// Run a session off the async threads (a fit takes seconds).
async fn run_session(
    data: Arc<Data>,
    opts: session::Options,
) -> Result<Session, (StatusCode, String)> {
    tokio::task::spawn_blocking(move || {
        session::run(
            &session::Input {
                column: &data.column,
                unit: &data.unit,
                y: &data.y,
                rate_hz: data.rate_hz,
                segments: &data.segments,
                temp: data.temp.as_deref(),
                timing: data.timing.as_ref(),
                label: &data.label,
            },
            &opts,
        )
    })
    .await
    .map_err(|e| {
        (
            StatusCode::INTERNAL_SERVER_ERROR,
            format!("the fit stopped: {e}"),
        )
    })?
    .map_err(|e| (StatusCode::UNPROCESSABLE_ENTITY, e))
}

fn options(terms: &Option<Vec<String>>) -> session::Options {
    session::Options {
        terms: terms.clone().unwrap_or_default(),
        ..session::Options::default()
    }
}

/// `--terms a,b` when the terms are not the default.
fn terms_args(terms: &Option<Vec<String>>) -> Vec<String> {
    match terms {
        Some(t) => vec!["--terms".into(), t.join(",")],
        None => vec![],
    }
}

fn names_of(s: &Session) -> Vec<String> {
    s.last()
        .model
        .fit
        .effects()
        .iter()
        .map(|e| e.name().to_string())
        .collect()
}

fn row_of(step: &noise_model::Step<Effect>) -> StepRow {
    StepRow {
        edit: step.edit.to_string(),
        chi2_dof_before: step.before.chi2_dof,
        chi2_dof_after: step.after.chi2_dof,
        rms_log_residual_before: step.before.rms_residual,
        rms_log_residual_after: step.after.rms_residual,
        adequate_before: step.before.adequate,
        adequate_after: step.after.adequate,
        reading: step.reading.clone(),
    }
}

/// GET /api/lab: the current view (null before a column is chosen).
pub async fn view(State(s): State<Shared>) -> Response {
    match s.lab.published().as_ref() {
        Some(p) => Json(p.view.clone()).into_response(),
        None => Json(Value::Null).into_response(),
    }
}

/// POST /api/lab/select {"column": "gx"}: load the column and fit the start model.
pub async fn select(State(s): State<Shared>, bytes: Bytes) -> Response {
    let b: SelectBody = match body(&bytes) {
        Ok(b) => b,
        Err(e) => return bad_request(&e),
    };
    let Some(file) = s.lab.file.lock().await.clone() else {
        return error(StatusCode::CONFLICT, "no recording to study yet");
    };
    let mut g = s.lab.state.lock().await;
    let load = {
        let file = file.clone();
        let column = b.column.clone();
        tokio::task::spawn_blocking(move || load(&file, &column)).await
    };
    let data = match load {
        Ok(Ok(d)) => Arc::new(d),
        Ok(Err(e)) => return error(StatusCode::BAD_REQUEST, &format!("{e:#}")),
        Err(e) => return error(StatusCode::INTERNAL_SERVER_ERROR, &e.to_string()),
    };
    match run_session(data.clone(), options(&None)).await {
        Ok(session) => {
            let c = Column {
                data,
                flags: input_flags(&file),
                file: file.file,
                terms: None,
                command: vec![],
                session: Arc::new(session),
                steps: vec![],
            };
            let r = s.lab.publish(&c);
            *g = Some(c);
            r
        }
        Err((st, e)) => error(st, &e),
    }
}

/// The column `column` of `file`, with its temperature when the file has one.
fn load(args: &InputArgs, column: &str) -> Result<Data> {
    let file = &args.file;
    let columns = columns_of(args)?;
    if !columns.iter().any(|c| c == column) {
        return Err(anyhow!(
            "column {column:?}: not a sensor column of {} (it has {})",
            file.display(),
            columns.join(", ")
        ));
    }
    let rec = input::load_with(args, &[column], &["temp"])?;
    let series = rec
        .column(column)
        .ok_or_else(|| anyhow!("column {column:?} missing"))?;
    let shown = file.display().to_string();
    Ok(Data {
        column: column.to_string(),
        unit: series.unit.clone(),
        y: series.values.clone(),
        rate_hz: rec.rate_hz,
        segments: rec.segments.clone(),
        temp: rec.column("temp").map(|c| c.values.clone()),
        timing: rec.timing.clone(),
        label: format!("{shown}: column {column:?}"),
    })
}

/// POST /api/lab/edit {"add": "markov"} or {"remove": "flicker"}: one step from the current
/// model.
pub async fn edit(State(s): State<Shared>, bytes: Bytes) -> Response {
    let b: EditBody = match body(&bytes) {
        Ok(b) => b,
        Err(e) => return bad_request(&e),
    };
    let (name, adding) = match (&b.add, &b.remove) {
        (Some(a), None) => (a.clone(), true),
        (None, Some(r)) => (r.clone(), false),
        _ => {
            return error(
                StatusCode::BAD_REQUEST,
                "give one of \"add\" or \"remove\", with an effect's name",
            )
        }
    };
    if !hand_editable(&name) {
        return error(
            StatusCode::BAD_REQUEST,
            &format!(
                "{name:?}: not an effect a click can add or remove; expected one of {}",
                vocabulary().join(", ")
            ),
        );
    }
    let name = Effect::parse(&name).expect("checked").name().to_string();
    let mut g = s.lab.state.lock().await;
    let Some(c) = g.as_mut() else {
        return error(StatusCode::CONFLICT, "choose a column first");
    };
    let current = names_of(&c.session);
    if let Some(n) = current.iter().find(|n| !hand_editable(n)) {
        return error(
            StatusCode::CONFLICT,
            &format!(
                "the model holds {n}, found by the automatic walk in the time series; start \
                 again from the default model to edit it by hand"
            ),
        );
    }
    let has = current.contains(&name);
    let (terms, opts, command) = if adding {
        if has && Effect::parse(&name).is_some_and(|e| !e.repeatable()) {
            return error(
                StatusCode::CONFLICT,
                &format!("the model already has {name}"),
            );
        }
        let mut command = terms_args(&c.terms);
        command.extend(["--add".into(), name.clone()]);
        let opts = session::Options {
            add: vec![name.clone()],
            ..options(&c.terms)
        };
        (c.terms.clone(), opts, command)
    } else {
        if !has {
            return error(
                StatusCode::CONFLICT,
                &format!("the model has no {name} to remove"),
            );
        }
        let rest: Vec<String> = current.iter().filter(|n| **n != name).cloned().collect();
        if rest.is_empty() {
            return error(StatusCode::CONFLICT, "a model needs one effect at least");
        }
        let terms = Some(rest);
        (terms.clone(), options(&terms), terms_args(&terms))
    };
    let session = match run_session(c.data.clone(), opts).await {
        Ok(s) => s,
        Err((st, e)) => return error(st, &e),
    };
    let before = c.session.last();
    let row = if adding {
        row_of(session.steps.last().expect("one step per add"))
    } else {
        let after = session.last();
        StepRow {
            edit: format!("− {name}"),
            chi2_dof_before: before.model.fit.chi2_dof(),
            chi2_dof_after: after.model.fit.chi2_dof(),
            rms_log_residual_before: before.model.assessment.rms_log_residual,
            rms_log_residual_after: after.model.assessment.rms_log_residual,
            adequate_before: before.diagnosis.adequate,
            adequate_after: after.diagnosis.adequate,
            reading: String::new(),
        }
    };
    // the next edit starts from this session's last model, by name
    c.terms = match terms {
        Some(t) if !adding => Some(t),
        _ => Some(names_of(&session)),
    };
    c.steps.push(row);
    c.command = command;
    c.session = Arc::new(session);
    s.lab.publish(c)
}

/// POST /api/lab/auto {}: the automatic walk from the current model.
pub async fn auto(State(s): State<Shared>, bytes: Bytes) -> Response {
    if let Err(e) = body::<Empty>(&bytes) {
        return bad_request(&e);
    }
    let mut g = s.lab.state.lock().await;
    let Some(c) = g.as_mut() else {
        return error(StatusCode::CONFLICT, "choose a column first");
    };
    let opts = session::Options {
        auto: true,
        ..options(&c.terms)
    };
    let session = match run_session(c.data.clone(), opts).await {
        Ok(s) => s,
        Err((st, e)) => return error(st, &e),
    };
    let mut command = terms_args(&c.terms);
    command.push("--auto".into());
    c.steps.extend(session.steps.iter().map(row_of));
    c.terms = Some(names_of(&session));
    c.command = command;
    c.session = Arc::new(session);
    s.lab.publish(c)
}

/// POST /api/lab/reset {}: back to the default start model, the step table emptied.
pub async fn reset(State(s): State<Shared>, bytes: Bytes) -> Response {
    if let Err(e) = body::<Empty>(&bytes) {
        return bad_request(&e);
    }
    let mut g = s.lab.state.lock().await;
    let Some(c) = g.as_mut() else {
        return error(StatusCode::CONFLICT, "choose a column first");
    };
    match run_session(c.data.clone(), options(&None)).await {
        Ok(session) => {
            c.terms = None;
            c.command = vec![];
            c.steps.clear();
            c.session = Arc::new(session);
            s.lab.publish(c)
        }
        Err((st, e)) => error(st, &e),
    }
}

fn download(body: String, ty: &'static str, name: &str) -> Response {
    let mut r = body.into_response();
    let h = r.headers_mut();
    h.insert(header::CONTENT_TYPE, HeaderValue::from_static(ty));
    if let Ok(v) = HeaderValue::from_str(&format!("attachment; filename=\"{name}\"")) {
        h.insert(header::CONTENT_DISPOSITION, v);
    }
    r
}

/// GET /api/lab/export.json: the session's JSON, as `imu-lab fit … --json` prints it.
pub async fn export_json(State(s): State<Shared>) -> Response {
    let p = s
        .lab
        .published()
        .as_ref()
        .map(|p| (p.session.clone(), p.column.clone()));
    match p {
        Some((session, column)) => download(
            session.json_string() + "\n",
            "application/json",
            &format!("fit-{column}.json"),
        ),
        None => error(StatusCode::CONFLICT, "choose a column first"),
    }
}

/// GET /api/lab/report.html: the session's report, as `imu-lab fit … --report` writes it.
pub async fn export_report(State(s): State<Shared>) -> Response {
    // The session is shared: the report is rendered without holding the lock.
    let p = s
        .lab
        .published()
        .as_ref()
        .map(|p| (p.session.clone(), p.file.clone(), p.column.clone()));
    match p {
        Some((session, file, column)) => {
            let title = report_title(&session, &file);
            download(
                report_html(&session, &title, &file.display().to_string()),
                "text/html; charset=utf-8",
                &format!("report-{column}.html"),
            )
        }
        None => error(StatusCode::CONFLICT, "choose a column first"),
    }
}

/// Log-spaced τ from `lo` to `hi`.
fn grid(lo: f64, hi: f64) -> Vec<f64> {
    let decades = (hi / lo).log10().max(0.0);
    let n = ((decades * CURVE_PER_DECADE as f64).ceil() as usize).max(2);
    (0..=n)
        .map(|i| lo * (hi / lo).powf(i as f64 / n as f64))
        .collect()
}

/// What the page draws and prints for a column.
fn view_of(c: &Column) -> Value {
    let s = &c.session;
    let last = s.last();
    let fit = &last.model.fit;
    let a = &last.model.assessment;
    let (lo, hi) = (
        fit.points.first().map_or(1e-3, |p| p.tau),
        fit.points.last().map_or(1.0, |p| p.tau),
    );
    let taus = grid(lo, hi);
    let terms: Vec<Value> = fit
        .terms
        .iter()
        .map(|t| {
            json!({
                "effect": t.effect.name(),
                "dev": taus.iter().map(|&x| session::num(t.avar(x, &fit.ctx).max(0.0).sqrt())).collect::<Vec<_>>(),
            })
        })
        .collect();
    let total: Vec<Value> = taus
        .iter()
        .map(|&x| {
            session::num(
                fit.terms
                    .iter()
                    .map(|t| t.avar(x, &fit.ctx))
                    .sum::<f64>()
                    .max(0.0)
                    .sqrt(),
            )
        })
        .collect();
    let params: Vec<Value> = report::param_rows(fit, &s.unit)
        .into_iter()
        .map(|r| {
            json!({
                "effect": r.effect, "param": r.param, "value": r.canonical,
                "conventional": r.conventional, "status": r.status,
            })
        })
        .collect();
    let failing: Vec<Value> = a
        .failing
        .iter()
        .map(|r| json!({ "lo": r.lo, "hi": r.hi, "sign": r.sign, "worst_z": session::num(r.worst_z) }))
        .collect();
    let missing = last.diagnosis.missing.as_ref();
    let mut command = vec![
        "imu-lab".to_string(),
        "fit".into(),
        c.file.display().to_string(),
    ];
    command.extend(c.flags.iter().cloned());
    command.extend(["--column".into(), c.data.column.clone()]);
    command.extend(c.command.iter().cloned());
    let current = names_of(s);
    json!({
        "fit": s.json(),
        "verdict": s.verdict(),
        "chi2_dof": session::num(fit.chi2_dof()),
        "rms_log_residual": session::num(a.rms_log_residual),
        "adequate": last.diagnosis.adequate,
        "effects": current,
        "editable": current.iter().all(|n| hand_editable(n)),
        "missing": missing.map(|e| e.name().to_string()),
        "missing_addable": missing.is_some_and(|e| hand_editable(e.name())),
        "physics": s.physics().into_iter().map(|(n, t)| json!({"effect": n, "text": t})).collect::<Vec<_>>(),
        "params": params,
        "failing": failing,
        "curves": { "tau": taus, "total": total, "terms": terms },
        "steps": c.steps,
        "command": command.join(" "),
    })
}
