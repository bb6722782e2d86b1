// The live page against the emulated Pico (xtask starts it, turned through the simulator's
// standard trajectory by a part with hard iron, and passes IMU_LIVE_PORT): the status arrives,
// the device's own Allan tables arrive and are replaced by the next round with more samples and
// narrower bounds, the decimated stream stays bounded, a recording made from the page opens in
// the noise lab; the magnetometer wizard collects the field with its coverage and fits it.
// The device holds a wrong calibration from the start (written to its flash, as a device
// calibrated before would): the wizards fit raw values, so their fits are the part's all the
// same.
import { test, before, after } from "node:test";
import assert from "node:assert/strict";
import { writeFileSync } from "node:fs";
import { join } from "node:path";
import { OUT, browser, imuLab, scratch, serve } from "./lib.mjs";

const PORT = process.env.IMU_LIVE_PORT;
let srv, ctx;

/// A uniform draw in ±[lo, hi].
function signed(lo, hi) {
  const x = lo + (hi - lo) * Math.random();
  return Math.random() < 0.5 ? -x : x;
}

/// A wrong calibration for the device (within the datasheet bounds it checks): a hard iron of
/// 10–40 µT an axis, a soft iron of 1 ± 3–10 % on its diagonal, an accelerometer offset of
/// 0.2–0.8 m/s² and scale of 1 ± 2–6 % an axis, drawn at random. A fit of the calibrated
/// values would be off by about that much.
function wrongCalibration() {
  const three = (f) => [f(), f(), f()];
  const hard = three(() => signed(10, 40));
  const soft = [0, 1, 2].map((i) => [0, 1, 2].map((j) => (i === j ? 1 + signed(0.03, 0.1) : 0)));
  const offset = three(() => signed(0.2, 0.8));
  const scale = three(() => 1 + signed(0.02, 0.06));
  const v = (a) => `[${a.map((x) => x.toFixed(6)).join(", ")}]`;
  return `# a deliberately wrong calibration (web/test/live.test.mjs)
version = 1

[accel]
part = "MPU-6050"
lsb_per_unit = ${8192 / 9.80665}
offset = ${v(offset)}
scale = ${v(scale)}
misalignment_deg = [0.0, 0.0, 0.0]

[gyro]
part = "MPU-6050"
lsb_per_unit = 131.0
bias = [0.0, 0.0, 0.0]
temp_coeff = [0.0, 0.0, 0.0]
temp_ref = 25.0
temp_lsb_per_c = 340.0
temp_offset_c = 36.53
scale = [1.0, 1.0, 1.0]
misalignment_deg = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0]

[mag]
part = "QMC5883L"
lsb_per_unit = 120.0
hard_iron = ${v(hard)}
soft_iron = [${soft.map(v).join(", ")}]
`;
}

before(async () => {
  if (!PORT) return;
  // the wrong calibration first, into the device's flash (the emulator serves one host at a
  // time: this upload, then the server)
  const dir = scratch();
  const toml = wrongCalibration();
  console.log(`the device's calibration before the wizards:\n${toml}`);
  writeFileSync(join(dir, "wrong.toml"), toml);
  const t0 = Date.now();
  imuLab(["device", "--port", PORT, "calibrate", "--upload", join(dir, "wrong.toml")]);
  console.log(`written to the device's flash in ${(Date.now() - t0) / 1000} s`);
  srv = await serve(["--port", PORT, "--record-dir", dir]);
  ctx = await browser();
});

after(async () => {
  await ctx?.close();
  await srv?.stop();
});

/// The gx table's rows on the page: [τ, σ, lo, hi] and its round.
async function gxTable(page) {
  return page.evaluate(() => {
    const el = document.querySelector('.table-plot[data-channel="gx"]');
    return el ? { round: Number(el.dataset.round), rows: JSON.parse(el.dataset.rows) } : null;
  });
}

test("status, tables that update round by round, a bounded stream, a recording into the lab", { skip: !PORT && "IMU_LIVE_PORT not set (xtask starts the emulator and sets it)" }, async () => {
  const page = await ctx.newPage();
  const foreign = [];
  page.on("request", (r) => { if (!r.url().startsWith(srv.url)) foreign.push(r.url()); });
  await page.goto(srv.url);
  await page.waitForSelector("body[data-ready=yes]");
  assert.equal(await page.getAttribute("body", "data-mode"), "live");
  await page.waitForSelector("#live-status[data-uptime]", { timeout: 60_000 });
  assert.match(await page.textContent("#live-status"), /IMU\s*ok/);
  assert.match(await page.textContent("#source"), /device: tcp:/);

  // two rounds of the device's tables: the second has more samples and narrower bounds
  await page.waitForFunction(() => document.querySelector('.table-plot[data-channel="gx"]'), null, { timeout: 120_000 });
  const first = await gxTable(page);
  console.log(`gx table, round ${first.round}: ${first.rows.length} rows`);
  assert.equal(await page.locator(".table-plot").count(), 10, "a table per channel");
  await page.waitForFunction((r) => Number(document.querySelector('.table-plot[data-channel="gx"]').dataset.round) > r,
    first.round, { timeout: 120_000 });
  const second = await gxTable(page);
  console.log(`gx table, round ${second.round}: ${second.rows.length} rows`);
  assert.ok(second.rows.length >= first.rows.length);
  const width = (r) => (r[3] - r[2]) / r[1]; // relative width of the 68.3 % interval
  assert.ok(width(second.rows[0]) < width(first.rows[0]),
    `the interval at τ = ${second.rows[0][0]} s narrows: ${width(first.rows[0])} → ${width(second.rows[0])}`);

  // the stream: decimated on the server, at most 600 points on the page
  const points = Number(await page.getAttribute("#stream-plot", "data-points"));
  assert.ok(points > 0 && points <= 600, `${points} stream points`);
  // every channel (the ten calibrated columns and the device's roll, pitch and heading) with
  // its unit, each plotted on request with data
  const options = await page.$$eval("#stream-channel option", (o) => o.map((x) => [x.value, x.textContent]));
  assert.deepEqual(options.map((o) => o[1]), ["ax [m/s²]", "ay [m/s²]", "az [m/s²]", "gx [deg/s]", "gy [deg/s]",
    "gz [deg/s]", "mx [µT]", "my [µT]", "mz [µT]", "temp [°C]", "roll [deg]", "pitch [deg]", "heading [deg]"]);
  for (const [value, label] of options) {
    await page.selectOption("#stream-channel", value);
    const name = label.split(" ")[0];
    await page.waitForFunction((n) => document.querySelector("#stream-plot").dataset.channel === n &&
      Number(document.querySelector("#stream-plot").dataset.finite) > 0, name);
    const latest = await page.getAttribute(`#stream-latest tr[data-channel="${name}"]`, "data-mean");
    assert.ok(Number.isFinite(Number(latest)) && latest !== "", `${name}: latest mean ${latest}`);
  }
  // the magnitude of the mean specific force is gravity's (the board still or turning slowly)
  const g = await page.$$eval("#stream-latest tbody tr", (rows) => Math.hypot(...rows.slice(0, 3).map((r) => Number(r.dataset.mean))));
  assert.ok(g > 7 && g < 13, `|a| = ${g} m/s²`);
  await page.selectOption("#stream-channel", "3");
  await page.screenshot({ path: join(OUT, "live.png"), fullPage: true });

  // a recording made from the page, opened in the noise lab
  await page.click("#record-start");
  await page.waitForSelector("#record-state[data-recording=yes]");
  const t0 = Number(await page.getAttribute("#live-status", "data-uptime"));
  await page.waitForFunction((t) => Number(document.querySelector("#live-status").dataset.uptime) >= t + 4, t0, { timeout: 120_000 });
  await page.click("#record-stop");
  await page.waitForSelector("#record-open:not([hidden])");
  const summary = await page.textContent("#record-state");
  console.log(`recording: ${summary}`);
  assert.match(summary, /rows over/);
  await page.click("#record-open");
  await page.waitForSelector("#lab:not([hidden]) #column option[value=gx]", { state: "attached" });
  await page.selectOption("#column", "gx");
  await page.waitForSelector("#verdict.ok, #verdict.bad", { timeout: 120_000 });
  assert.match(await page.textContent("#verdict"), /ADEQUATE/);
  assert.deepEqual(foreign, []);
  await page.close();
});

test("calibration wizards: the magnetometer's point cloud and coverage, the accelerometer's poses with a merge warning; both fits within tolerance, both uploaded in RAM", { skip: !PORT && "IMU_LIVE_PORT not set" }, async () => {
  const page = await ctx.newPage();
  await page.goto(srv.url);
  await page.waitForSelector("#live-status[data-uptime]", { timeout: 60_000 });
  assert.match(await page.textContent("#live-status"), /from flash/);
  await page.click("#mag-start");
  // the device streams raw values while the wizard collects, and the page says so
  await page.waitForSelector("#raw-banner[data-raw=yes]");
  assert.match(await page.textContent("#raw-banner"), /corrections are off while the wizard collects/);
  await page.waitForFunction(() => /stream\s*Raw/.test(document.querySelector("#live-status").textContent),
    null, { timeout: 30_000 });
  await page.waitForSelector("#stream-kind[data-raw=yes]");
  // the accelerometer's poses while the magnetometer's points are collected (the same turns)
  await accelPoses(page);
  // the emulated board turns through the simulator's standard trajectory: wait for half of the
  // directions (or 60 s of device time)
  const t0 = Number(await page.getAttribute("#live-status", "data-uptime"));
  await page.waitForFunction((t) => Number(document.querySelector("#mag-state").dataset.coverage || 0) >= 0.5 ||
    Number(document.querySelector("#live-status").dataset.uptime) >= t + 60, t0, { timeout: 240_000 });
  await page.click("#mag-stop");
  // every wizard done collecting: calibrated values again
  await page.waitForSelector("#raw-banner[data-raw=no]", { state: "attached" });
  await page.waitForFunction(() => /stream\s*Calibrated/.test(document.querySelector("#live-status").textContent),
    null, { timeout: 30_000 });
  const points = Number(await page.getAttribute("#mag-state", "data-points"));
  const coverage = Number(await page.getAttribute("#mag-state", "data-coverage"));
  console.log(`magnetometer: ${points} points, coverage ${(100 * coverage).toFixed(1)} %`);
  assert.ok(points >= 20 && points <= 5000, `${points} points`);
  assert.ok(coverage > 0.2, `coverage ${coverage}`);
  await page.click("#mag-fit");
  await page.waitForSelector("#mag-result[data-model]", { timeout: 120_000 });
  const model = await page.getAttribute("#mag-result", "data-model");
  const text = await page.textContent("#mag-result");
  console.log(`fit: ${model}; ${text.slice(0, 300)}`);
  assert.match(model, /hard_iron/);
  assert.match(text, /residual RMS [\d.e-]+ µT/);
  const magTruth = JSON.parse(process.env.IMU_LIVE_MAG_TRUTH || "null");
  if (magTruth) {
    // the part's hard iron, not the one left over by the device's wrong calibration: 0.5 µT is
    // 25 times the σ of the fits here (0.02 µT), far inside the 10–40 µT of the wrong one
    const hard = JSON.parse(await page.getAttribute("#mag-result", "data-params")).hard_iron;
    console.log(`hard iron: fitted ${hard} µT, the part's ${magTruth.hard_iron} µT`);
    for (let k = 0; k < 3; k++) {
      assert.ok(Math.abs(hard[k] - magTruth.hard_iron[k]) < 0.5, `hard iron ${k}: ${hard[k]} vs ${magTruth.hard_iron[k]} µT`);
    }
  }
  // the upload: refused without the confirmation, then sent to RAM only
  await page.click("#mag-upload-button");
  assert.match(await page.textContent("#error"), /confirmation/);
  assert.equal(await page.getAttribute("#mag-upload-state", "data-applied"), null);
  // a wrong code is refused by the server, whatever the page does
  const wrong = await page.evaluate(async () => {
    const info = await (await fetch("/api/info")).json();
    const r = await fetch("/api/live/upload", { method: "POST", headers: { "x-imu-lab-token": info.token },
      body: JSON.stringify({ confirm: "00000000", persist: false }) });
    return r.status;
  });
  assert.equal(wrong, 403);
  await page.check("#mag-confirm");
  await page.click("#mag-upload-button");
  await page.waitForSelector("#mag-upload-state[data-applied=yes]", { timeout: 60_000 });
  assert.match(await page.textContent("#mag-upload-state"), /RAM only/);
  // the device says so in its next status frames
  await page.waitForFunction(() => /set by the host, not persisted/.test(document.querySelector("#live-status").textContent),
    null, { timeout: 60_000 });
  await page.screenshot({ path: join(OUT, "mag-wizard.png"), fullPage: true });
  await accelFit(page);
  await verification(page);
  await page.close();
});

/// The verification recording after the uploads: 30 s of device time in raw values, the
/// heading's consistency with the gyro before (raw) and after (the calibration uploaded).
async function verification(page) {
  await page.click("#verify-start");
  await page.waitForSelector("#verify-stop:not([disabled])");
  await page.waitForFunction(() => Number(document.querySelector("#verify-state").dataset.seconds) >= 30,
    null, { timeout: 120_000 });
  await page.click("#verify-stop");
  await page.waitForSelector("#verify-result[data-windows]", { timeout: 60_000 });
  const text = await page.textContent("#verify-result");
  console.log(`verification: ${text}`);
  const before = Number(await page.getAttribute("#verify-result", "data-before"));
  const after = Number(await page.getAttribute("#verify-result", "data-after"));
  const windows = Number(await page.getAttribute("#verify-result", "data-windows"));
  assert.match(text, /before \(raw\) [\d.]+ ± [\d.e-]+° rms .* → after \(the uploaded calibration\) [\d.]+ ± [\d.e-]+° rms/);
  // the emulated part's hard iron (25 µT, half the field) turns the heading by tens of degrees
  // as the board turns; the fitted calibration leaves the gyro's noise and the 0.1 s windows
  assert.ok(windows >= 5, `${windows} windows`);
  assert.ok(before > 2 && after < before / 3, `before ${before}°, after ${after}°`);
  // back to calibrated values
  await page.waitForFunction(() => /Calibrated/.test(document.querySelector("#live-status").textContent), null, { timeout: 30_000 });
  await page.locator("#verify-wizard").screenshot({ path: join(OUT, "verify.png") });
}

/// The accelerometer's wizard on the emulated board turned through the calibration run (eight
/// poses held 5 s): one pose captured twice at once (the merge warning, then the merge), then
/// every hold captured until each face is up once and eight poses are held.
async function accelPoses(page) {
  // stillness is judged once the device's noise is known (its first Allan tables)
  await page.waitForSelector("#accel-still[data-still=yes], #accel-still[data-still=no]", { timeout: 120_000 });
  const state = () => page.evaluate(() => ({
    n: Number(document.querySelector("#accel-poses tbody").dataset.poses || 0),
    same: Number(document.querySelector("#accel-warnings").dataset.same || 0),
    missing: document.querySelector("#accel-warnings").dataset.missing || "",
  }));
  const captured = (n) => page.waitForFunction((n) => Number(document.querySelector("#accel-poses tbody").dataset.poses) > n,
    n, { timeout: 180_000 });
  // one pose, asked for while the board moves: the progress bar, then the pose
  await page.waitForSelector("#accel-still[data-still=no]", { timeout: 180_000 });
  await page.click("#accel-capture");
  await page.waitForSelector("#accel-progress", { state: "attached" });
  await captured(0);
  // the same pose again at once (the board still held: its last second): the same orientation
  // twice
  await page.click("#accel-capture");
  await captured(1);
  await page.waitForSelector(".merge-warning");
  const warning = await page.textContent(".merge-warning");
  console.log(`merge warning: ${warning}`);
  assert.match(warning, /Poses 1 and 2 are the same orientation \([\d.]+° apart/);
  assert.match(await page.textContent("#accel-warnings"), /Missing: no pose yet with .* up/);
  await page.locator("#accel-wizard").screenshot({ path: join(OUT, "accel-merge-warning.png") });
  await page.click(".accel-merge");
  await page.waitForFunction(() => document.querySelector("#accel-poses tbody").dataset.poses === "1" &&
    document.querySelector("#accel-warnings").dataset.same === "0");
  // every hold from now on, until each face is up once and eight poses are held; a hold taken
  // again when the run loops is merged
  await page.click("#accel-continuous");
  for (;;) {
    await page.waitForFunction(() => {
      const n = Number(document.querySelector("#accel-poses tbody").dataset.poses);
      const w = document.querySelector("#accel-warnings").dataset;
      return w.same !== "0" || (n >= 8 && w.missing === "");
    }, null, { timeout: 240_000 });
    const s = await state();
    if (!s.same) break;
    await page.click(".accel-merge");
    // merged (a new pose may come at the same time: the warnings count, not the poses)
    await page.waitForFunction((k) => Number(document.querySelector("#accel-warnings").dataset.same) < k, s.same);
  }
  await page.click("#accel-cancel");
  const faces = await page.$$eval("#accel-poses tbody tr", (rows) => rows.map((r) => r.dataset.face));
  console.log(`poses: ${faces.join(" ")}`);
  assert.ok(faces.length >= 8 && ["+x", "-x", "+y", "-y", "+z", "-z"].every((f) => faces.includes(f)), faces.join(" "));
}

/// The accelerometer's fit against the emulated part's errors (drawn by xtask), and its
/// upload through the magnetometer's path.
async function accelFit(page) {
  const truth = JSON.parse(process.env.IMU_LIVE_ACCEL_TRUTH || "null");
  await page.click("#accel-fit");
  await page.waitForSelector("#accel-result[data-model]", { timeout: 120_000 });
  const params = JSON.parse(await page.getAttribute("#accel-result", "data-params"));
  const sigma = JSON.parse(await page.getAttribute("#accel-result", "data-sigma"));
  console.log(`emulated accelerometer: ${JSON.stringify(truth)}`);
  console.log(`fit: ${await page.getAttribute("#accel-result", "data-model")}; offset ${params.offset} ± ${sigma.offset} m/s², ` +
    `scale ${params.scale} ± ${sigma.scale}`);
  assert.match(await page.getAttribute("#accel-result", "data-model"), /offset.*scale|scale.*offset/);
  assert.match(await page.textContent("#accel-result"), /residual RMS [\d.e-]+ m\/s²/);
  if (truth) {
    // each pose mean holds ≥ 1000 samples of 0.04 m/s² noise (σ ≈ 1.3 mm/s²) read in 16-bit
    // counts (0.6 mm/s²): the fit recovers the part within 0.02 m/s² and 0.2 % (ten times
    // that), far inside the errors drawn (0.05–0.3 m/s², 0.5–3 %)
    for (let k = 0; k < 3; k++) {
      assert.ok(Math.abs(params.offset[k] - truth.offset[k]) < 0.02, `offset ${k}: ${params.offset[k]} vs ${truth.offset[k]}`);
      assert.ok(Math.abs(params.scale[k] - truth.scale[k]) < 0.002, `scale ${k}: ${params.scale[k]} vs ${truth.scale[k]}`);
    }
  }
  // the upload shares the magnetometer's path: refused without the confirmation, then in RAM
  await page.click("#accel-upload-button");
  assert.match(await page.textContent("#error"), /confirmation/);
  await page.check("#accel-confirm");
  await page.click("#accel-upload-button");
  await page.waitForSelector("#accel-upload-state[data-applied=yes]", { timeout: 60_000 });
  assert.match(await page.textContent("#accel-upload-state"), /RAM only/);
  await page.locator("#accel-wizard").screenshot({ path: join(OUT, "accel-wizard.png") });
}
