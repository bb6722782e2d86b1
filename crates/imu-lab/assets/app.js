// imu-lab serve: the page. It asks the server (same origin only) for its mode and write token,
// then drives the noise lab (and, on a device, the live view). Every number shown comes from
// the server with its unit; the page only draws and lays out.
"use strict";

const $ = (id) => document.getElementById(id);
let TOKEN = "";
let allanPlot = null;
let residualPlot = null;

function fmt(x, digits = 3) {
  if (x === null || x === undefined || !Number.isFinite(x)) return "—";
  if (x === 0) return "0";
  const e = Math.floor(Math.log10(Math.abs(x)));
  if (e >= -3 && e < 5) return x.toFixed(Math.max(0, digits - 1 - e));
  return x.toExponential(digits - 1);
}

function showError(msg) {
  const el = $("error");
  el.textContent = msg || "";
  el.hidden = !msg;
}

function busy(on) {
  $("busy").hidden = !on;
  document.querySelectorAll("#lab button, #live button").forEach((b) => {
    if (on) { b.dataset.wasDisabled = b.disabled ? "1" : ""; b.disabled = true; }
    else { b.disabled = b.dataset.wasDisabled === "1"; }
  });
}

async function api(path, body) {
  const opts = body === undefined ? {} : {
    method: "POST",
    headers: { "Content-Type": "application/json", "X-Imu-Lab-Token": TOKEN },
    body: JSON.stringify(body),
  };
  const r = await fetch(path, opts);
  const j = await r.json().catch(() => null);
  if (!r.ok) throw new Error((j && j.error) || `${path}: HTTP ${r.status}`);
  return j;
}

async function labCall(path, body) {
  showError("");
  busy(true);
  try {
    const v = await api(path, body);
    if (v) renderLab(v);
  } catch (e) {
    showError(e.message);
  } finally {
    busy(false);
  }
}

function cell(tr, text, cls) {
  const td = document.createElement("td");
  td.textContent = text;
  if (cls) td.className = cls;
  tr.appendChild(td);
  return td;
}

// ---------- noise lab ----------

const COLORS = ["#1f77b4", "#2ca02c", "#ff7f0e", "#8c564b", "#d62728", "#e377c2", "#7f7f7f",
  "#bcbd22", "#17becf", "#9467bd", "#1f3f9f", "#3f9f1f", "#ff1f8f", "#aa5500"];

function plotWidth() {
  return Math.min(1100, Math.max(480, document.querySelector("main").clientWidth - 20));
}

// A log axis spans whole decades: uPlot's log splits, given a range whose ends are not powers
// of ten (τ = 0.00999999999999801 s), search for seconds before drawing.
function decade(x, up) {
  return 10 ** (up ? Math.ceil(Math.log10(x) - 1e-9) : Math.floor(Math.log10(x) + 1e-9));
}
const logRange = (u, lo, hi) => [decade(lo, false), decade(hi, true)];
// tick labels: powers of ten as numbers, others left blank (minor grid lines)
const logValues = (u, splits) => splits.map((s) => {
  const e = Math.log10(s);
  return Math.abs(e - Math.round(e)) < 1e-9 ? fmt(s, 1) : "";
});
const numValues = (u, splits) => splits.map((s) => fmt(s, 2));

// Shade the failing τ ranges (red) on a plot's τ axis.
function shadeFailing(failing) {
  return (u) => {
    const ctx = u.ctx;
    ctx.save();
    ctx.fillStyle = "rgba(220, 0, 0, 0.12)";
    for (const r of failing) {
      const x0 = u.valToPos(r.lo / 1.2, "x", true);
      const x1 = u.valToPos(r.hi * 1.2, "x", true);
      ctx.fillRect(x0, u.bbox.top, x1 - x0, u.bbox.height);
    }
    ctx.restore();
  };
}

function drawAllan(v) {
  const f = v.fit;
  const unit = f.unit;
  // one τ axis for the measured points and the model curves (uPlot draws aligned series)
  const pts = new Map(f.adev.map((p) => [p.tau_s, p]));
  const curveAt = new Map(v.curves.tau.map((t, i) => [t, i]));
  const xs = [...new Set([...pts.keys(), ...curveAt.keys()])].sort((a, b) => a - b);
  const col = (fn) => xs.map(fn);
  // the σ axis spans the measurement (a decade beyond its bounds); curves below it are cut, as
  // a term of amplitude ~0 would otherwise stretch a log axis over hundreds of decades
  const yLo = decade(Math.min(...f.adev.map((p) => p.lo).filter((x) => x > 0)) / 3, false);
  const yHi = decade(Math.max(...f.adev.map((p) => p.hi)) * 1.5, true);
  const clip = (x) => (x !== null && x >= yLo ? x : null);
  const data = [
    xs,
    col((t) => (pts.has(t) ? pts.get(t).hi : null)),
    col((t) => (pts.has(t) ? pts.get(t).lo : null)),
    col((t) => (pts.has(t) ? pts.get(t).dev : null)),
    col((t) => (curveAt.has(t) ? clip(v.curves.total[curveAt.get(t)]) : null)),
    ...v.curves.terms.map((term) => col((t) => (curveAt.has(t) ? clip(term.dev[curveAt.get(t)]) : null))),
  ];
  const series = [
    { label: "τ [s]", value: (u, x) => fmt(x) },
    { label: "68.3 % upper", stroke: "rgba(0,0,0,0.25)", width: 1, spanGaps: true, points: { show: false }, value: (u, x) => fmt(x) },
    { label: "68.3 % lower", stroke: "rgba(0,0,0,0.25)", width: 1, spanGaps: true, points: { show: false }, value: (u, x) => fmt(x) },
    { label: `σ(τ) measured [${unit}]`, stroke: "#000", width: 0, points: { show: true, size: 7, fill: "#000" }, paths: () => null, value: (u, x) => fmt(x) },
    { label: "model", stroke: "#c00", width: 2, spanGaps: true, points: { show: false }, value: (u, x) => fmt(x) },
    ...v.curves.terms.map((term, i) => ({
      label: term.effect, stroke: COLORS[i % COLORS.length], width: 1.5, dash: [6, 4],
      spanGaps: true, points: { show: false }, value: (u, x) => fmt(x),
    })),
  ];
  const opts = {
    width: plotWidth(), height: 380,
    title: `Allan deviation of ${f.column} [${unit}] with 68.3 % bands, the model and its terms`,
    scales: { x: { time: false, distr: 3, range: logRange }, y: { distr: 3, range: () => [yLo, yHi] } },
    axes: [{ label: "τ [s]", values: logValues }, { label: `σ(τ) [${unit}]`, size: 70, values: logValues }],
    bands: [{ series: [1, 2], fill: "rgba(0, 90, 200, 0.15)" }],
    series,
    hooks: { drawClear: [shadeFailing(v.failing)] },
  };
  if (allanPlot) allanPlot.destroy();
  allanPlot = new uPlot(opts, data, $("allan-plot"));
}

function drawResidual(v) {
  const f = v.fit;
  const xs = f.adev.map((p) => p.tau_s);
  const data = [xs, f.adev.map((p) => p.residual), xs.map(() => 1), xs.map(() => -1)];
  const opts = {
    width: plotWidth(), height: 190,
    title: "Residual r = (measured − model) / CI half-width; failing τ ranges shaded red",
    scales: { x: { time: false, distr: 3, range: logRange }, y: { range: (u, lo, hi) => [Math.min(-2, lo * 1.1), Math.max(2, hi * 1.1)] } },
    axes: [{ label: "τ [s]", values: logValues }, { label: "r", size: 70, values: numValues }],
    series: [
      { label: "τ [s]", value: (u, x) => fmt(x) },
      { label: "r", stroke: "#000", width: 1, points: { show: true, size: 6, fill: "#000" }, value: (u, x) => fmt(x) },
      { label: "+1", stroke: "#888", dash: [4, 4], width: 1, points: { show: false } },
      { label: "−1", stroke: "#888", dash: [4, 4], width: 1, points: { show: false } },
    ],
    hooks: { drawClear: [shadeFailing(v.failing)] },
  };
  if (residualPlot) residualPlot.destroy();
  residualPlot = new uPlot(opts, data, $("residual-plot"));
}

function renderLab(v) {
  $("lab-body").hidden = false;
  const f = v.fit;
  $("record-info").textContent =
    `${f.samples} samples at ${fmt(f.rate_hz, 6)} Hz (${fmt(f.samples / f.rate_hz, 4)} s), unit ${f.unit}`;
  const verdict = $("verdict");
  verdict.textContent = v.verdict;
  verdict.className = v.adequate ? "ok" : "bad";
  verdict.dataset.adequate = v.adequate ? "yes" : "no";
  $("chi2").textContent = fmt(v.chi2_dof);
  $("chi2").dataset.value = String(v.chi2_dof);
  $("rms").textContent = fmt(v.rms_log_residual);
  $("effects").textContent = v.effects.join(" + ");

  const named = $("add-named");
  named.hidden = !(v.missing && v.missing_addable && v.editable);
  named.textContent = v.missing ? `Add the named effect: ${v.missing}` : "";
  named.dataset.effect = v.missing || "";
  $("add-effect").disabled = !v.editable;
  $("remove-effect").disabled = !v.editable;

  const d = f.diagnosis;
  $("diagnosis").textContent =
    (d.missing ? `Missing effect: ${d.missing}. ` : "") + d.explanation +
    (d.tau_range_s ? ` (τ = ${fmt(d.tau_range_s[0])}–${fmt(d.tau_range_s[1])} s)` : "");
  const ev = $("evidence");
  ev.replaceChildren(...d.evidence.map((e) => { const li = document.createElement("li"); li.textContent = e; return li; }));
  $("physics").replaceChildren(...v.physics.map((p) => {
    const el = document.createElement("p");
    const b = document.createElement("b");
    b.textContent = p.effect;
    el.append(b, ` — ${p.text}`);
    if (p.effect === v.missing) el.className = "missing";
    return el;
  }));

  const pt = $("params").tBodies[0];
  pt.replaceChildren(...v.params.map((r) => {
    const tr = document.createElement("tr");
    cell(tr, r.effect); cell(tr, r.param); cell(tr, r.value); cell(tr, r.conventional); cell(tr, r.status);
    return tr;
  }));

  const st = $("steps").tBodies[0];
  st.replaceChildren(...v.steps.map((s, i) => {
    const tr = document.createElement("tr");
    const yn = (b) => (b ? "yes" : "no");
    cell(tr, String(i + 1));
    cell(tr, s.edit + (s.reading ? ` — ${s.reading}` : ""));
    const c = cell(tr, `${fmt(s.chi2_dof_before)} → ${fmt(s.chi2_dof_after)}`);
    c.dataset.after = String(s.chi2_dof_after);
    cell(tr, `${fmt(s.rms_log_residual_before)} → ${fmt(s.rms_log_residual_after)}`);
    cell(tr, `${yn(s.adequate_before)} → ${yn(s.adequate_after)}`, s.adequate_after ? "ok" : "bad");
    return tr;
  }));
  $("command").textContent = v.command;
  drawAllan(v);
  drawResidual(v);
}

async function startLab(lab, vocabulary) {
  $("lab").hidden = false;
  const colSel = $("column");
  colSel.replaceChildren(new Option("— choose —", ""), ...lab.columns.map((c) => new Option(c, c)));
  $("effect").replaceChildren(...vocabulary.map((e) => new Option(e, e)));
  colSel.onchange = () => { if (colSel.value) labCall("/api/lab/select", { column: colSel.value }); };
  $("add-named").onclick = () => labCall("/api/lab/edit", { add: $("add-named").dataset.effect });
  $("add-effect").onclick = () => labCall("/api/lab/edit", { add: $("effect").value });
  $("remove-effect").onclick = () => labCall("/api/lab/edit", { remove: $("effect").value });
  $("auto").onclick = () => labCall("/api/lab/auto", {});
  $("reset").onclick = () => labCall("/api/lab/reset", {});
  const v = await api("/api/lab");
  if (v) { colSel.value = v.fit.column; renderLab(v); }
}

async function main() {
  try {
    const info = await api("/api/info");
    TOKEN = info.token;
    document.body.dataset.mode = info.mode;
    $("source").textContent = info.lab && info.lab.file
      ? `recording: ${info.lab.file}` : (info.port ? `device: ${info.port}` : "");
    if (info.mode === "live" && window.startLive) window.startLive(info);
    if (info.lab && info.lab.columns) await startLab(info.lab, info.vocabulary);
    else if (info.lab && info.lab.error) showError(info.lab.error);
    window.LAB_VOCABULARY = info.vocabulary;
    document.body.dataset.ready = "yes";
  } catch (e) {
    showError(e.message);
  }
}

window.labApi = { api, startLab, showError, fmt, busy };
document.addEventListener("DOMContentLoaded", main);

// ---------- live device ----------

const STREAM_KEEP = 600; // points kept by the page: the server's history, never more
// the stream's channels with their units (the server's list, sent with the device's identity)
let CHANNELS = [];
const tablePlots = new Map();
let streamPlot = null;
let streamPoints = []; // the last STREAM_KEEP points as the server sent them
let streamChannel = 3; // gx until the user picks another

function renderStatus(s) {
  const t = document.createElement("table");
  t.className = "status";
  const row = (k, v, fault) => {
    const tr = t.insertRow();
    cell(tr, k);
    cell(tr, v, fault ? "fault" : "");
  };
  const losses = (m) => {
    const e = Object.entries(m || {});
    return e.length ? e.map(([c, n]) => `${n} ${c}`).join(", ") : "none";
  };
  row("uptime", `${fmt(s.uptime_s, 6)} s`);
  row("IMU", `${s.imu.state}; ${s.imu.taken} samples taken, ${s.imu.lost} lost (${losses(s.imu.losses)}), ` +
    `${s.imu.fifo_overflows} FIFO overflows; period ${fmt(s.imu.period_us, 6)} µs`, s.imu.state !== "ok");
  row("magnetometer", `${s.mag.state}; ${s.mag.taken} samples taken, ${s.mag.lost} lost (${losses(s.mag.losses)}); ` +
    `period ${fmt(s.mag.period_us, 6)} µs`, s.mag.state !== "ok");
  row("I2C", `${s.i2c_errors} errors, ${s.bus_faults} bus faults, ${s.bus_recoveries} bus recoveries`, s.bus_faults > 0);
  row("frames", `${s.frames_rejected} host frames rejected, ${s.frames_unsent} device frames not sent`);
  row("CPU load", `${fmt(s.cpu_percent, 3)} %`);
  row("temperature", s.temp_c === null ? "n/a" : `${fmt(s.temp_c, 4)} °C`);
  row("stream", s.mode);
  row("calibration", s.calibration);
  $("live-status").replaceChildren(t);
  $("live-status").dataset.uptime = String(s.uptime_s);
}

function renderTables(v) {
  $("tables-state").textContent = `round ${v.round}: ${v.tables.length} channels`;
  $("tables").dataset.round = String(v.round);
  for (const t of v.tables) {
    const rows = t.rows.filter((r) => r.dev > 0);
    const data = [rows.map((r) => r.tau_s), rows.map((r) => r.hi), rows.map((r) => r.lo), rows.map((r) => r.dev)];
    const title = `${t.channel} [${t.unit}] — round ${t.round}, ${t.samples} samples` +
      (rows.length ? "" : " — σ = 0 at every τ (a constant signal)");
    let p = tablePlots.get(t.channel);
    if (!p) {
      const div = document.createElement("div");
      div.className = "table-plot";
      div.dataset.channel = t.channel;
      $("tables").appendChild(div);
      p = new uPlot({
        width: 360, height: 220, title,
        scales: { x: { time: false, distr: 3, range: logRange }, y: { distr: 3, range: logRange } },
        axes: [{ label: "τ [s]", values: logValues }, { label: `σ(τ) [${t.unit}]`, size: 60, values: logValues }],
        bands: [{ series: [1, 2], fill: "rgba(0, 90, 200, 0.18)" }],
        legend: { show: false },
        series: [{}, { stroke: "rgba(0,0,0,0.2)" }, { stroke: "rgba(0,0,0,0.2)" },
          { stroke: "#000", points: { show: true, size: 5 } }],
      }, data, div);
      tablePlots.set(t.channel, p);
    } else {
      p.setData(data);
      const h = p.root.querySelector(".u-title");
      if (h) h.textContent = title;
    }
    p.root.parentElement.dataset.round = String(t.round);
    p.root.parentElement.dataset.rows = JSON.stringify(rows.map((r) => [r.tau_s, r.dev, r.lo, r.hi]));
  }
}

function setChannels(list) {
  CHANNELS = list;
  const sel = $("stream-channel");
  sel.replaceChildren(...list.map((c, i) => new Option(`${c.name} [${c.unit}]`, String(i))));
  sel.value = String(streamChannel);
  sel.onchange = () => {
    streamChannel = Number(sel.value);
    if (streamPlot) { streamPlot.destroy(); streamPlot = null; }
    drawStream();
  };
  $("stream-latest").tBodies[0].replaceChildren(...list.map((c) => {
    const tr = document.createElement("tr");
    tr.dataset.channel = c.name;
    cell(tr, c.name); cell(tr, "—"); cell(tr, "—"); cell(tr, c.unit);
    return tr;
  }));
}

function streamPush(points) {
  for (const p of points) streamPoints.push(p);
  // how many points the page has received (read by the soak benchmark, web/bench)
  window.imuLabStreamReceived = (window.imuLabStreamReceived || 0) + points.length;
  if (streamPoints.length > STREAM_KEEP) streamPoints.splice(0, streamPoints.length - STREAM_KEEP);
  const last = streamPoints[streamPoints.length - 1];
  if (last) {
    $("stream-kind").textContent = last.raw
      ? "Raw stream (nominal sensitivities, no corrections; decimated on the server)"
      : "Calibrated stream (decimated on the server)";
    $("stream-kind").dataset.raw = last.raw ? "yes" : "no";
    const rows = $("stream-latest").tBodies[0].rows;
    for (let k = 0; k < rows.length; k++) {
      const m = last.mean[k];
      rows[k].cells[1].textContent = m === null ? "—" : `${fmt(m, 5)} ± ${fmt(last.sd[k], 2)}`;
      rows[k].cells[2].textContent = m === null ? "—" : `${fmt(last.min[k], 5)} … ${fmt(last.max[k], 5)}`;
      rows[k].dataset.mean = m === null ? "" : String(m);
    }
  }
  drawStream();
}

function drawStream() {
  const k = streamChannel;
  const c = CHANNELS[k] || { name: `channel ${k}`, unit: "" };
  const data = [streamPoints.map((p) => p.t), streamPoints.map((p) => p.min[k]),
    streamPoints.map((p) => p.max[k]), streamPoints.map((p) => p.mean[k])];
  if (!streamPlot) {
    streamPlot = new uPlot({
      width: plotWidth(), height: 220,
      title: `${c.name} [${c.unit}]: mean, min and max per 0.1 s of device time`,
      axes: [{ label: "device time [s]", values: numValues }, { label: c.unit, size: 70, values: numValues }],
      scales: { x: { time: false } },
      bands: [{ series: [2, 1], fill: "rgba(0, 90, 200, 0.15)" }],
      series: [{ label: "t [s]" }, { label: "min", stroke: "rgba(0,0,0,0.2)" },
        { label: "max", stroke: "rgba(0,0,0,0.2)" }, { label: "mean", stroke: "#1f77b4" }],
    }, data, $("stream-plot"));
  } else {
    streamPlot.setData(data);
  }
  const el = $("stream-plot");
  el.dataset.points = String(streamPoints.length);
  el.dataset.channel = c.name;
  el.dataset.finite = String(data[3].filter((x) => x !== null && Number.isFinite(x)).length);
}

function renderRecord(r) {
  $("record-start").disabled = r.recording;
  $("record-stop").disabled = !r.recording;
  $("record-open").hidden = r.recording || !r.summary;
  $("record-state").textContent = r.recording
    ? `recording to ${r.file}`
    : (r.summary ? `${r.file}: ${r.summary}` : "");
  $("record-state").dataset.recording = r.recording ? "yes" : "no";
}

// The device streams raw values while a wizard collects (the server says which).
function renderMode(m) {
  const el = $("raw-banner");
  el.hidden = !m.raw;
  el.textContent = m.raw
    ? `Raw values: the device's corrections are off while the wizard collects (${m.for.join(", ")}); ` +
      "calibrated values return when it stops."
    : "";
  el.dataset.raw = m.raw ? "yes" : "no";
}

// ---------- magnetometer wizard ----------

const magPoints = []; // at most the server's MAG_POINTS (5000): [x, y, z, level (1/0)]
let magLast = null; // the last state the server sent

// The wizard's method: "sphere" (3-D) or "level" (the level turn, 2-D).
function magMethod() {
  return $("mag-method-level").checked ? "level" : "sphere";
}

// Points in three projections (or, for the level turn, the x–y plane of the level points),
// each panel scaled to its largest value; `circle`: a circle of that radius around the origin.
function drawProjections(cv, points, panels, circle) {
  const ctx = cv.getContext("2d");
  ctx.clearRect(0, 0, cv.width, cv.height);
  if (!points.length) return;
  const w = cv.width / panels.length;
  panels.forEach(([a, b, la, lb, pick], i) => {
    // each panel scaled to the points it picks (the level turn's: the level ones), the others
    // drawn as far as the panel reaches
    let r = circle ? circle * 1.2 : 1;
    for (const p of points) if (!pick || pick(p)) r = Math.max(r, Math.abs(p[a]), Math.abs(p[b]));
    const x0 = i * w + w / 2, y0 = cv.height / 2, k = (cv.height / 2 - 20) / r;
    ctx.save();
    ctx.beginPath();
    ctx.rect(i * w + 10, 10, w - 20, cv.height - 20);
    ctx.clip();
    ctx.strokeStyle = "#bbb";
    ctx.strokeRect(i * w + 10, 10, w - 20, cv.height - 20);
    ctx.fillStyle = "#222";
    ctx.fillText(`${la} → / ${lb} ↑ [µT], ±${fmt(r, 3)} µT`, i * w + 16, 24);
    if (circle) {
      ctx.strokeStyle = "#c00";
      ctx.beginPath();
      ctx.arc(x0, y0, circle * k, 0, 2 * Math.PI);
      ctx.stroke();
    }
    for (const p of points) {
      const on = pick ? pick(p) : true;
      ctx.fillStyle = on ? "rgba(31, 119, 180, 0.6)" : "rgba(150, 150, 150, 0.25)";
      ctx.fillRect(x0 + p[a] * k - 1, y0 - p[b] * k - 1, 2, 2);
    }
    ctx.restore();
  });
}

function drawCloud() {
  const cv = $("mag-cloud");
  if (magMethod() === "level") {
    // the level points in x–y (the tilted ones grey: the level turn leaves them out)
    drawProjections(cv, magPoints, [[0, 1, "mx", "my", (p) => p[3] === 1]]);
  } else {
    drawProjections(cv, magPoints, [[0, 1, "mx", "my"], [1, 2, "my", "mz"], [0, 2, "mx", "mz"]]);
  }
}

function renderMagState(m) {
  magLast = m;
  const level = magMethod() === "level";
  const el = $("mag-state");
  el.textContent = (level
    ? `${m.level_points} level points of ${m.points}, heading coverage ${fmt(100 * m.heading_coverage, 3)} % ` +
      `of the ${m.heading_bins} bins of 10°`
    : `${m.points} points, coverage ${fmt(100 * m.coverage, 3)} % of the directions`) +
    (m.collecting ? " — collecting" : "");
  el.dataset.points = String(m.points);
  el.dataset.coverage = String(m.coverage);
  el.dataset.levelPoints = String(m.level_points);
  el.dataset.headingCoverage = String(m.heading_coverage);
  el.dataset.tilt = m.tilt_deg === null || m.tilt_deg === undefined ? "" : String(m.tilt_deg);
  const tilt = $("mag-tilt");
  const tilted = level && m.collecting && m.tilt_deg !== null && m.tilt_deg !== undefined &&
    m.tilt_deg > m.level_tilt_deg;
  tilt.hidden = !tilted;
  tilt.textContent = tilted
    ? `Not level: the board is tilted ${fmt(m.tilt_deg, 3)}° (the bound is ${m.level_tilt_deg}°): ` +
      "these points are left out of the level turn; lay it flat."
    : "";
  tilt.dataset.tilted = tilted ? "yes" : "no";
  $("mag-method-help").hidden = !level;
  $("mag-start").disabled = m.collecting;
  $("mag-stop").disabled = !m.collecting;
}

function renderMagFit(r) {
  const f = r.fit;
  const div = $("mag-result");
  const p = (text, cls) => { const el = document.createElement("p"); el.textContent = text; if (cls) el.className = cls; return el; };
  const t = document.createElement("table");
  const head = t.insertRow();
  for (const h of ["parameter", "value", "1σ", "unit"]) { const th = document.createElement("th"); th.textContent = h; head.appendChild(th); }
  const row = (name, values, sig, unit) => {
    const tr = t.insertRow();
    tr.dataset.param = name;
    cell(tr, name);
    cell(tr, values.map((x) => fmt(x, 4)).join(", "));
    cell(tr, sig.map((x) => fmt(x, 2)).join(", "));
    cell(tr, unit);
  };
  // soft_iron_2d (Jaime et al., eqs. 4–5): the ellipse's semi-axes r and q, its tilt θ and σ = q/r
  const units2d = { r: f.unit, q: f.unit, theta_deg: "deg", sigma: "1 (σ = q/r)" };
  for (const [name, v] of Object.entries(f.params || {})) {
    const s = f.sigma ? f.sigma[name] : undefined;
    if (name === "soft_iron_2d" && v && typeof v === "object") {
      for (const k of ["r", "q", "theta_deg", "sigma"]) {
        row(`soft_iron_2d.${k}`, [v[k]], s && s[k] !== undefined ? [s[k]] : [], units2d[k]);
      }
      continue;
    }
    const values = Array.isArray(v) ? v.flat() : [v];
    const sig = s !== undefined && s !== null ? (Array.isArray(s) ? s.flat() : [s]) : [];
    row(name, values, sig, name.includes("soft") ? "1 (a matrix)" : f.unit);
  }
  const d = f.diagnosis || {};
  const cover = r.method === "level"
    ? `level turn: the ${f.n_residuals} magnetometer samples of ${r.level_windows} windows taken level (tilt within ` +
      `${r.level_tilt_deg}°, under ${r.level_rate_dps} deg/s about x and y), heading coverage ` +
      `${fmt(100 * r.heading_coverage, 3)} %`
    : `full sphere: coverage ${fmt(100 * r.coverage, 3)} %`;
  div.replaceChildren(
    p(`Model: ${f.model.join(" + ")}; residual RMS ${fmt(f.residual_rms, 3)} ${f.unit} ` +
      `(noise floor ${fmt(f.noise_floor, 3)} ${f.unit}, ${f.n_residuals} residuals); ${cover}`),
    p(`${d.adequate ? "ADEQUATE" : "NOT ADEQUATE"} — ${d.explanation || ""}`, d.adequate ? "ok" : "bad"),
    t,
    ...(f.steps || []).map((s) => p(`step: + ${s.added.join(", ")}${s.removed && s.removed.length ? ", − " + s.removed.join(", ") : ""}: ` +
      `residual RMS ${fmt(s.rms_residual_before, 3)} → ${fmt(s.rms_residual_after, 3)} ${s.rms_unit}`)),
  );
  div.dataset.method = r.method;
  div.dataset.model = f.model.join(",");
  div.dataset.adequate = d.adequate ? "yes" : "no";
  div.dataset.params = JSON.stringify(f.params);
  div.dataset.sigma = JSON.stringify(f.sigma);
  div.appendChild(renderUpload(r.upload, "mag"));
}

// The upload: only a plausible calibration, only after the user ticks the confirmation, which
// says what the upload changes and what it keeps of the device's calibration (read from it);
// RAM only unless "write to flash" is ticked too (the CLI's --no-persist is the default here).
function renderUpload(u, prefix) {
  const box = document.createElement("div");
  box.id = `${prefix}-upload`;
  if (!u.plausible) {
    const p = document.createElement("p");
    p.className = "bad";
    p.textContent = `Not uploadable: ${u.problem}`;
    box.appendChild(p);
    return box;
  }
  const label = (id, text) => {
    const l = document.createElement("label");
    const c = document.createElement("input");
    c.type = "checkbox";
    c.id = id;
    l.append(c, " ", text);
    return l;
  };
  const list = (title, items, id) => {
    const d = document.createElement("div");
    d.id = id;
    const h = document.createElement("p");
    h.textContent = title;
    const ul = document.createElement("ul");
    ul.replaceChildren(...items.map((x) => { const li = document.createElement("li"); li.textContent = x; return li; }));
    d.append(h, ul);
    return d;
  };
  box.append(
    list("The upload changes:", u.replaces, `${prefix}-upload-replaces`),
    list(`It keeps, from the device's current calibration (${u.device}, read from the device):`, u.keeps,
      `${prefix}-upload-keeps`),
  );
  const btn = document.createElement("button");
  btn.type = "button";
  btn.id = `${prefix}-upload-button`;
  btn.textContent = "Upload to the device";
  const state = document.createElement("span");
  state.id = `${prefix}-upload-state`;
  btn.onclick = async () => {
    if (!$(`${prefix}-confirm`).checked) { showError("Tick the confirmation first: nothing was uploaded."); return; }
    showError("");
    try {
      const r = await api("/api/live/upload", { confirm: u.code, persist: $(`${prefix}-persist`).checked });
      state.textContent = r.persisted ? "applied and written to flash" : "applied in RAM only (not persisted; a reset forgets it)";
      state.dataset.applied = "yes";
      btn.disabled = true;
    } catch (e) { showError(e.message); }
  };
  const row = document.createElement("div");
  row.className = "row";
  row.append(label(`${prefix}-confirm`, `I confirm: change the device's calibration as listed above, keeping the rest (code ${u.code})`),
    label(`${prefix}-persist`, "also write it to flash"), btn, state);
  box.appendChild(row);
  return box;
}

// ---------- accelerometer wizard ----------

function renderAccel(a) {
  const still = $("accel-still");
  still.dataset.still = a.still === null ? "" : (a.still ? "yes" : "no");
  const r = (x) => (x === null || x === undefined ? "—" : fmt(x, 2));
  still.textContent = a.still === null
    ? "stillness: waiting for the device's Allan tables (its noise)"
    : `${a.still ? "still" : "moving"}: accelerometer variance ${r(a.accel_ratio)}×, gyro variance ` +
      `${r(a.gyro_ratio)}× the noise's (limit ${a.rules.noise_k}×), gyro rate ${r(a.gyro_rate_dps)} deg/s ` +
      `(limit ${a.rules.turn_dps})` + (a.noise ? `; noise σ ${fmt(a.noise.accel_sigma, 2)} ${a.noise.accel_unit}, ` +
      `${fmt(a.noise.gyro_sigma, 2)} ${a.noise.gyro_unit}` : "");
  $("accel-capture").disabled = a.armed;
  $("accel-continuous").disabled = a.armed;
  // capturing (or holding raw values between captures) ends with Stop capturing
  $("accel-cancel").disabled = !a.armed && !a.raw;
  // the rows and warnings are rebuilt only when the poses change (the state comes ten times
  // a second while capturing: the buttons stay put under the pointer)
  const key = JSON.stringify([a.poses, a.same, a.missing, a.armed]);
  const body = $("accel-poses").tBodies[0];
  if (body.dataset.key !== key) {
    body.dataset.key = key;
    renderPoses(a, body);
  }
  const bar = $("accel-progress");
  if (bar) {
    bar.value = a.progress;
    $("accel-pending-state").textContent = a.waiting_for_motion ? "turn the board to the next pose…"
      : (a.still ? "hold it still…" : "waiting for the board to be still…");
    $("accel-pending-progress").textContent = ` ${fmt(100 * a.progress, 3)} % of ${a.rules.hold_s} s`;
  }
}

function renderPoses(a, body) {
  const rows = a.poses.map((p, i) => {
    const tr = document.createElement("tr");
    tr.dataset.face = p.face;
    tr.dataset.t = String(p.t);
    cell(tr, String(i + 1));
    cell(tr, p.face);
    cell(tr, p.mean.map((m, k) => `${fmt(m, 5)} ± ${fmt(p.sigma[k], 2)}`).join(", "));
    cell(tr, fmt(p.norm, 6));
    const td = cell(tr, "");
    const bar = document.createElement("progress");
    bar.max = 1; bar.value = 1;
    td.append(bar, ` ${fmt(p.seconds, 3)} s, ${p.samples} samples`);
    const rm = document.createElement("button");
    rm.type = "button"; rm.textContent = "Remove"; rm.className = "accel-remove";
    rm.onclick = () => accelAct("/api/live/accel/remove", { index: i });
    cell(tr, "").appendChild(rm);
    return tr;
  });
  if (a.armed) {
    const tr = document.createElement("tr");
    tr.id = "accel-pending";
    cell(tr, String(a.poses.length + 1));
    cell(tr, "—");
    cell(tr, "").id = "accel-pending-state";
    cell(tr, "");
    const td = cell(tr, "");
    const bar = document.createElement("progress");
    bar.id = "accel-progress";
    bar.max = 1; bar.value = 0;
    const label = document.createElement("span");
    label.id = "accel-pending-progress";
    td.append(bar, label);
    cell(tr, "");
    rows.push(tr);
  }
  body.replaceChildren(...rows);
  body.dataset.poses = String(a.poses.length);
  const w = $("accel-warnings");
  const items = a.same.map((m) => {
    const p = document.createElement("p");
    p.className = "bad merge-warning";
    p.textContent = `Poses ${m.a + 1} and ${m.b + 1} are the same orientation (${fmt(m.angle_deg, 2)}° apart, ` +
      `under ${a.rules.merge_deg}°): a second capture of a pose adds no new direction. `;
    const b = document.createElement("button");
    b.type = "button"; b.textContent = `Merge ${m.a + 1} and ${m.b + 1}`; b.className = "accel-merge";
    b.onclick = () => accelAct("/api/live/accel/merge", { a: m.a, b: m.b });
    p.appendChild(b);
    return p;
  });
  if (a.poses.length && a.missing.length) {
    const p = document.createElement("p");
    p.className = "missing-faces";
    p.textContent = `Missing: no pose yet with ${a.missing.join(", ")} up.`;
    items.push(p);
  }
  w.replaceChildren(...items);
  w.dataset.same = String(a.same.length);
  w.dataset.missing = a.missing.join(",");
}

async function accelAct(path, body = {}) {
  showError("");
  try {
    const v = await api(path, body);
    if (v && v.poses) renderAccel(v);
    return v;
  } catch (e) { showError(e.message); return null; }
}

function renderAccelFit(r) {
  const f = r.fit;
  const div = $("accel-result");
  const p = (text, cls) => { const el = document.createElement("p"); el.textContent = text; if (cls) el.className = cls; return el; };
  const t = document.createElement("table");
  const head = t.insertRow();
  for (const h of ["parameter", "x", "y", "z", "unit"]) { const th = document.createElement("th"); th.textContent = h; head.appendChild(th); }
  const units = { offset: "m/s²", scale: "1", misalignment_deg: "deg" };
  for (const name of ["offset", "scale", "misalignment_deg"]) {
    const v = f.params[name];
    if (!v) continue;
    const sig = (f.sigma && f.sigma[name]) || [];
    const tr = t.insertRow();
    tr.dataset.param = name;
    cell(tr, name);
    v.forEach((x, k) => cell(tr, `${fmt(x, 6)} ± ${sig[k] === undefined ? "—" : fmt(sig[k], 2)}`));
    cell(tr, units[name]);
  }
  const d = f.diagnosis || {};
  const res = r.residuals.map((x, i) => `${i + 1}: ${fmt(x, 2)}`).join(", ");
  div.replaceChildren(
    p(`Model: ${f.model.join(" + ")}; residual RMS ${fmt(f.residual_rms, 3)} ${f.unit} ` +
      `(noise floor ${fmt(f.noise_floor, 3)} ${f.unit}, ${f.n_residuals} poses)`),
    p(`${d.adequate ? "ADEQUATE" : "NOT ADEQUATE"} — ${d.explanation || ""}`, d.adequate ? "ok" : "bad"),
    t,
    p(`Residual per pose, |corrected mean| − g [${r.residual_unit}]: ${res}`),
    ...(r.warnings.same.length ? [p(`Warning: ${r.warnings.same.length} pair(s) of poses are the same orientation.`, "bad")] : []),
    ...(r.warnings.missing.length ? [p(`Warning: no pose with ${r.warnings.missing.join(", ")} up.`, "bad")] : []),
  );
  div.dataset.model = f.model.join(",");
  div.dataset.adequate = d.adequate ? "yes" : "no";
  div.dataset.params = JSON.stringify(f.params);
  div.dataset.sigma = JSON.stringify(f.sigma);
  div.appendChild(renderUpload(r.upload, "accel"));
}

// ---------- verification: heading before → after ----------

function renderVerify(v) {
  $("verify-start").disabled = v.recording;
  $("verify-stop").disabled = !v.recording;
  $("verify-state").textContent = v.recording
    ? `recording raw values: ${fmt(v.seconds, 3)} s` : "";
  $("verify-state").dataset.seconds = String(v.seconds);
  if (v.recording) return;
  const one = (r) => (r ? `${fmt(r.rms_deg, 3)} ± ${fmt(r.sigma_deg, 2)}° rms (max ${fmt(r.max_deg, 3)}°, ${r.windows} windows)`
    : "no window counted (no turn within ±70° of pitch)");
  const div = $("verify-result");
  const p = document.createElement("p");
  p.textContent = `Heading inconsistency with the gyro over ${fmt(v.seconds, 3)} s of device time ` +
    `(${v.check_window_s} s windows): before (raw) ${one(v.before)} → after (the uploaded calibration) ${one(v.after)}` +
    (v.calibrated_again ? ` — the stream did not return to calibrated values: ${v.calibrated_again}` : "");
  p.className = v.before && v.after && v.after.rms_deg < v.before.rms_deg ? "ok" : "bad";
  // how far the board turned in the windows judged: the check sees a heading error only where
  // the heading changes
  const turn = document.createElement("p");
  turn.id = "verify-turn";
  turn.textContent = v.turned
    ? `The board turned ${fmt(v.turned.rms_deg, 3)} ± ${fmt(v.turned.sigma_deg, 2)}° rms a window (the gyro's heading change)` +
      (v.little_turn ? `: under ${v.little_turn_deg}°, the check says little — turn the board through all headings and record again.` : ".")
    : "";
  turn.className = v.little_turn ? "bad" : "";
  // the magnitudes on the sphere: |B| around the field, |a| around g, raw and corrected
  const m = v.magnitudes;
  const spread = (r, unit) => (r ? `${fmt(r.rms, 3)} ± ${fmt(r.sigma, 2)} ${unit} rms (max ${fmt(r.max, 3)} ${unit})` : "—");
  const q = document.createElement("p");
  q.id = "verify-magnitudes";
  q.textContent = `On the sphere: |B| around ${fmt(m.field_ut, 4)} µT (${m.field_from}): before (raw) ` +
    `${spread(m.mag_before, m.mag_unit)} → after ${spread(m.mag_after, m.mag_unit)}; |a| around g = ` +
    `${fmt(m.g, 6)} m/s²: before ${spread(m.accel_before, m.accel_unit)} → after ${spread(m.accel_after, m.accel_unit)} ` +
    `(uncertainties from blocks of ${m.block_windows} windows). The corrected points below, with the circle of ` +
    `${fmt(m.field_ut, 4)} µT.`;
  q.className = m.mag_before && m.mag_after && m.mag_after.rms < m.mag_before.rms ? "ok" : "bad";
  div.replaceChildren(p, turn, q);
  div.dataset.before = v.before ? String(v.before.rms_deg) : "";
  div.dataset.turned = v.turned ? String(v.turned.rms_deg) : "";
  div.dataset.after = v.after ? String(v.after.rms_deg) : "";
  div.dataset.windows = v.after ? String(v.after.windows) : "0";
  const num = (r) => (r ? String(r.rms) : "");
  div.dataset.magBefore = num(m.mag_before);
  div.dataset.magAfter = num(m.mag_after);
  div.dataset.magAfterSigma = m.mag_after ? String(m.mag_after.sigma) : "";
  div.dataset.accelBefore = num(m.accel_before);
  div.dataset.accelAfter = num(m.accel_after);
  div.dataset.field = String(m.field_ut);
  const cv = $("verify-cloud");
  cv.hidden = false;
  cv.dataset.points = String(m.cloud.length);
  drawProjections(cv, m.cloud, [[0, 1, "mx", "my"], [1, 2, "my", "mz"], [0, 2, "mx", "mz"]], m.field_ut);
}

window.startLive = (info) => {
  $("live").hidden = false;
  const es = new EventSource("/api/live/events");
  es.addEventListener("identity", (e) => {
    const id = JSON.parse(e.data);
    $("source").textContent = `device: ${info.port} — ${id.firmware} on ${id.board}, IMU ${id.imu_rate_hz} Hz, magnetometer ${id.mag_rate_hz} Hz`;
    if (id.channels) setChannels(id.channels);
  });
  es.addEventListener("status", (e) => renderStatus(JSON.parse(e.data)));
  es.addEventListener("tables", (e) => renderTables(JSON.parse(e.data)));
  es.addEventListener("history", (e) => streamPush(JSON.parse(e.data)));
  es.addEventListener("stream", (e) => streamPush([JSON.parse(e.data)]));
  es.addEventListener("record", (e) => renderRecord(JSON.parse(e.data)));
  es.addEventListener("link", (e) => showError(JSON.parse(e.data).error));
  es.addEventListener("accel", (e) => renderAccel(JSON.parse(e.data)));
  es.addEventListener("verify", (e) => renderVerify(JSON.parse(e.data)));
  es.addEventListener("mode", (e) => renderMode(JSON.parse(e.data)));
  $("verify-start").onclick = async () => { const v = await act("/api/live/verify/start"); if (v) renderVerify(v); };
  $("verify-stop").onclick = async () => { const v = await act("/api/live/verify/stop"); if (v) renderVerify(v); };
  $("accel-capture").onclick = () => accelAct("/api/live/accel/capture", { continuous: false });
  $("accel-continuous").onclick = () => accelAct("/api/live/accel/capture", { continuous: true });
  $("accel-cancel").onclick = () => accelAct("/api/live/accel/cancel");
  $("accel-clear").onclick = () => accelAct("/api/live/accel/clear");
  $("accel-fit").onclick = async () => { const r = await accelAct("/api/live/accel/fit"); if (r) renderAccelFit(r); };
  es.addEventListener("mag", (e) => {
    const m = JSON.parse(e.data);
    // the state alone when the page connects; then one point a window
    if (m.point) magPoints.push([...m.point, m.level ? 1 : 0]);
    if (magPoints.length > 5000) magPoints.splice(0, magPoints.length - 5000);
    renderMagState(m);
    drawCloud();
  });
  $("mag-start").onclick = async () => {
    const m = await act("/api/live/mag/start");
    if (m) { magPoints.length = 0; drawCloud(); renderMagState(m); }
  };
  $("mag-stop").onclick = async () => { const m = await act("/api/live/mag/stop"); if (m) renderMagState(m); };
  $("mag-fit").onclick = async () => {
    showError("");
    try { renderMagFit(await api("/api/live/mag/fit", { method: magMethod() })); } catch (err) { showError(err.message); }
  };
  for (const id of ["mag-method-sphere", "mag-method-level"]) {
    $(id).onchange = () => { if (magLast) renderMagState(magLast); drawCloud(); };
  }
  const act = async (path) => {
    showError("");
    try { return await api(path, {}); } catch (err) { showError(err.message); return null; }
  };
  $("record-start").onclick = async () => { const r = await act("/api/live/record"); if (r) renderRecord(r); };
  $("record-stop").onclick = async () => { const r = await act("/api/live/stop"); if (r) renderRecord(r); };
  $("record-open").onclick = async () => {
    const lab = await act("/api/live/open");
    if (lab && lab.columns) await startLab(lab, info.vocabulary);
  };
};
