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

const PART = JSON.parse(process.env.IMU_LIVE_MAG_TRUTH || "null");

/// A wrong calibration for the device (within the datasheet bounds it checks): a hard iron of
/// 10–40 µT an axis, a soft iron of 1 ± 3–10 % on its diagonal, an accelerometer offset of
/// 0.2–0.8 m/s² and scale of 1 ± 2–6 % an axis, drawn at random. A fit of the calibrated
/// values would be off by about that much. Its gyro bias is a right one (the part's within
/// 0.05 deg/s an axis, or 0.1–0.5 deg/s without the part): a gyro calibrated before, which
/// the wizards' uploads must keep.
let WRONG = null;
function wrongCalibration() {
  const three = (f) => [f(), f(), f()];
  const hard = three(() => signed(10, 40));
  const soft = [0, 1, 2].map((i) => [0, 1, 2].map((j) => (i === j ? 1 + signed(0.03, 0.1) : 0)));
  const offset = three(() => signed(0.2, 0.8));
  const scale = three(() => 1 + signed(0.02, 0.06));
  const bias = [0, 1, 2].map((k) => (PART ? PART.gyro_bias[k] + signed(0, 0.05) : signed(0.1, 0.5)));
  const r6 = (a) => a.map((x) => Number(x.toFixed(6)));
  WRONG = { hard: r6(hard), soft: soft.map(r6), offset: r6(offset), scale: r6(scale), bias: r6(bias) };
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
bias = ${v(bias)}
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
  // the level turn's view while collecting: its heading coverage and tilt warning, sampled
  // every 50 ms by the test (the calibration run's level start and level turn, then its tilts)
  await page.check("#mag-method-level");
  await page.evaluate(() => {
    window.seenLevel = [];
    window.seenTimer = setInterval(() => {
      const m = document.querySelector("#mag-state").dataset;
      const t = document.querySelector("#mag-tilt");
      window.seenLevel.push({ cover: Number(m.headingCoverage || 0), tilted: t.dataset.tilted === "yes" && !t.hidden,
        text: t.textContent });
    }, 50);
  });
  await page.click("#mag-start");
  // the device streams raw values while the wizard collects, and the page says so
  await page.waitForSelector("#raw-banner[data-raw=yes]");
  assert.match(await page.textContent("#raw-banner"), /corrections are off while the wizard collects/);
  await page.waitForFunction(() => /stream\s*Raw/.test(document.querySelector("#live-status").textContent),
    null, { timeout: 30_000 });
  await page.waitForSelector("#stream-kind[data-raw=yes]");
  // the accelerometer's poses while the magnetometer's points are collected (the same turns)
  await accelPoses(page);
  // the emulated board turns through the simulator's calibration run: wait for half of the
  // directions and the level turn's full circle (or 90 s of device time: the run is 80.5 s)
  const t0 = Number(await page.getAttribute("#live-status", "data-uptime"));
  const waited = Date.now();
  await page.waitForFunction((t) => {
    const m = document.querySelector("#mag-state").dataset;
    return (Number(m.coverage || 0) >= 0.5 && Number(m.headingCoverage || 0) >= 0.9) ||
      Number(document.querySelector("#live-status").dataset.uptime) >= t + 90;
  }, t0, { timeout: 240_000 });
  await shotInView(page, "#mag-method", join(OUT, "mag-level-collecting.png"));
  await page.click("#mag-stop");
  const seen = await page.evaluate(() => { clearInterval(window.seenTimer); return window.seenLevel; });
  console.log(`collecting after the poses: ${(Date.now() - waited) / 1000} s until the coverage and the level circle`);
  // every wizard done collecting: calibrated values again
  await page.waitForSelector("#raw-banner[data-raw=no]", { state: "attached" });
  await page.waitForFunction(() => /stream\s*Calibrated/.test(document.querySelector("#live-status").textContent),
    null, { timeout: 30_000 });
  const points = Number(await page.getAttribute("#mag-state", "data-points"));
  const coverage = Number(await page.getAttribute("#mag-state", "data-coverage"));
  console.log(`magnetometer: ${points} points, coverage ${(100 * coverage).toFixed(1)} %`);
  assert.ok(points >= 20 && points <= 5000, `${points} points`);
  assert.ok(coverage > 0.2, `coverage ${coverage}`);
  await levelTurn(page, seen);
  // the full sphere
  await page.check("#mag-method-sphere");
  await page.click("#mag-fit");
  await page.waitForSelector("#mag-result[data-method=sphere]", { timeout: 120_000 });
  await page.waitForSelector("#mag-result[data-model]", { timeout: 120_000 });
  const model = await page.getAttribute("#mag-result", "data-model");
  const text = await page.textContent("#mag-result");
  console.log(`fit: ${model}; ${text.slice(0, 300)}`);
  assert.match(model, /hard_iron/);
  assert.match(text, /residual RMS [\d.e-]+ µT/);
  const magTruth = PART;
  if (magTruth) {
    // the part's hard iron, not the one left over by the device's wrong calibration: 0.5 µT is
    // 25 times the σ of the fits here (0.02 µT), far inside the 10–40 µT of the wrong one
    const hard = JSON.parse(await page.getAttribute("#mag-result", "data-params")).hard_iron;
    console.log(`hard iron: fitted ${hard} µT, the part's ${magTruth.hard_iron} µT`);
    for (let k = 0; k < 3; k++) {
      assert.ok(Math.abs(hard[k] - magTruth.hard_iron[k]) < 0.5, `hard iron ${k}: ${hard[k]} vs ${magTruth.hard_iron[k]} µT`);
    }
  }
  // the upload says what it changes and what it keeps (the device's accelerometer and gyro)
  assert.match(await page.textContent("#mag-upload-replaces"), /magnetometer's hard iron/);
  const keeps = await page.textContent("#mag-upload-keeps");
  assert.match(keeps, /accelerometer's offset/);
  assert.match(keeps, /gyro's bias/);
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
  // read back: the magnetometer's is the fit's, the accelerometer's and the gyro's the device's
  const fitted = JSON.parse(await page.getAttribute("#mag-result", "data-params"));
  const back = await readBack(page);
  close(back.mag.hard_iron, fitted.hard_iron, 1e-3, "magnetometer hard iron (the fit's)");
  close(back.mag.soft_iron.flat(), fitted.soft_iron.flat(), 1e-6, "soft iron (the fit's)");
  keptAccelAndGyro(back, "after the magnetometer's upload");
  await accelFit(page);
  // the accelerometer's upload keeps the magnetometer's uploaded before and the gyro's
  const after = await readBack(page);
  close(after.mag.hard_iron, fitted.hard_iron, 1e-3, "magnetometer hard iron kept by the accelerometer's upload");
  close(after.gyro.bias, WRONG.bias, 1e-5, "gyro bias kept by the accelerometer's upload");
  const accel = JSON.parse(await page.getAttribute("#accel-result", "data-params"));
  close(after.accel.offset, accel.offset, 1e-5, "accelerometer offset (the fit's)");
  await verification(page);
  await page.close();
});

/// A screenshot of the viewport with `selector` scrolled to its top: the raw-values banner,
/// sticky at the top of the page, shows above a wizard while it collects.
async function shotInView(page, selector, path) {
  await page.evaluate((sel) => {
    const el = document.querySelector(sel);
    window.scrollTo(0, el.getBoundingClientRect().top + window.scrollY - 60);
  }, selector);
  await page.screenshot({ path });
}

/// `got` within `tol` of `want`, element by element.
function close(got, want, tol, what) {
  assert.equal(got.length, want.length, what);
  for (let k = 0; k < want.length; k++) {
    assert.ok(Math.abs(got[k] - want[k]) <= tol, `${what} [${k}]: ${got[k]}, expected ${want[k]} (±${tol})`);
  }
}

/// The device's calibration, read from it by the server (GetCalibration).
async function readBack(page) {
  const v = await page.evaluate(async () => (await fetch("/api/live/calibration")).json());
  console.log(`read back (${v.source}): accel offset ${v.accel.offset} m/s², scale ${v.accel.scale}; ` +
    `gyro bias ${v.gyro.bias} deg/s; mag hard iron ${v.mag.hard_iron} µT, soft iron ${JSON.stringify(v.mag.soft_iron)}`);
  return v;
}

/// The accelerometer's and gyro's terms are the wrong calibration's, written before the
/// wizards (the fixed point keeps them within 1e-5 m/s², 1e-6 and 1e-5 deg/s).
function keptAccelAndGyro(back, when) {
  close(back.accel.offset, WRONG.offset, 1e-5, `accelerometer offset kept ${when}`);
  close(back.accel.scale, WRONG.scale, 1e-6, `accelerometer scale kept ${when}`);
  close(back.gyro.bias, WRONG.bias, 1e-5, `gyro bias kept ${when}`);
}

/// The level turn (2-D, Jaime et al.) on the points collected: its heading coverage rose while
/// collecting and the tilt warning showed on the run's tilts; the planar fit recovers the
/// part's in-plane centre; its upload replaces x and y and keeps the device's z terms, its
/// accelerometer and gyro.
async function levelTurn(page, seen) {
  const started = Date.now();
  const covers = seen.map((s) => s.cover);
  const last = covers[covers.length - 1];
  const warned = seen.filter((s) => s.tilted);
  console.log(`level turn: heading coverage sampled ${covers.length} times, ${covers[0]} → ${last}; ` +
    `tilt warning in ${warned.length} samples${warned.length ? `: ${warned[0].text}` : ""}`);
  assert.ok(covers[0] < 0.5 && last >= 0.9, `heading coverage ${covers[0]} → ${last}`);
  assert.ok(covers.some((c) => c > covers[0] && c < last), "the coverage rises through values between");
  assert.ok(warned.length > 0 && /tilted [\d.]+° \(the bound is 5°\)/.test(warned[0].text), "the tilt warning");
  await page.click("#mag-fit");
  await page.waitForSelector("#mag-result[data-method=level]", { timeout: 120_000 });
  const text = await page.textContent("#mag-result");
  const model = await page.getAttribute("#mag-result", "data-model");
  const params = JSON.parse(await page.getAttribute("#mag-result", "data-params"));
  const sigma = JSON.parse(await page.getAttribute("#mag-result", "data-sigma"));
  console.log(`level-turn fit: ${model}; ${text.slice(0, 400)}`);
  console.log(`level-turn fit: hard iron ${params.hard_iron} ± ${sigma.hard_iron} µT, soft_iron_2d ${JSON.stringify(params.soft_iron_2d)}`);
  assert.match(model, /hard_iron/);
  assert.doesNotMatch(model, /(^|,)soft_iron(,|$)/, "the planar problem, not the sphere's");
  assert.equal(await page.getAttribute("#mag-result", "data-adequate"), "yes", text);
  assert.match(text, /heading coverage [\d.]+ %/);
  if (model.includes("soft_iron_2d")) {
    for (const k of ["r", "q", "theta_deg", "sigma"]) {
      assert.ok(await page.locator(`#mag-result tr[data-param="soft_iron_2d.${k}"]`).count() === 1, k);
    }
  }
  if (PART) {
    // the in-plane centre: the hard iron plus the soft iron's coupling of the constant vertical
    // field (sensor z is up: B_z = −F·sin(dip)); 0.5 µT, as for the sphere
    const bz = -PART.field_ut * Math.sin(PART.dip_deg * Math.PI / 180);
    const want = [0, 1].map((k) => PART.hard_iron[k] + PART.soft_iron[k][2] * bz);
    console.log(`level-turn fit: in-plane centre ${params.hard_iron.slice(0, 2)} µT, the part's ${want} µT`);
    close(params.hard_iron.slice(0, 2), want, 0.5, "the level turn's in-plane hard iron");
  }
  assert.match(await page.textContent("#mag-upload-replaces"), /in-plane terms/);
  assert.match(await page.textContent("#mag-upload-keeps"), /out-of-plane terms.*hard iron z/);
  await page.check("#mag-confirm");
  await page.click("#mag-upload-button");
  await page.waitForSelector("#mag-upload-state[data-applied=yes]", { timeout: 60_000 });
  const back = await readBack(page);
  close(back.mag.hard_iron.slice(0, 2), params.hard_iron.slice(0, 2), 1e-3, "in-plane hard iron (the fit's)");
  close(back.mag.hard_iron.slice(2), WRONG.hard.slice(2), 1e-3, "z hard iron (the device's, kept)");
  close(back.mag.soft_iron[2], WRONG.soft[2], 1e-6, "the soft iron's z row (the device's, kept)");
  close([back.mag.soft_iron[0][2], back.mag.soft_iron[1][2]], [0, 0], 0, "no coupling from z in x and y");
  keptAccelAndGyro(back, "after the level turn's upload");
  console.log(`level turn: fit, upload and read-back in ${(Date.now() - started) / 1000} s`);
  await page.locator("#mag-result").screenshot({ path: join(OUT, "mag-level.png") });
}

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
  const turned = Number(await page.getAttribute("#verify-result", "data-turned"));
  console.log(`verification: ${await page.textContent("#verify-turn")}`);
  assert.match(text, /before \(raw\) [\d.]+ ± [\d.e-]+° rms .* → after \(the uploaded calibration\) [\d.]+ ± [\d.e-]+° rms/);
  // the emulated part's hard iron (25 µT, half the field) turns the heading by tens of degrees
  // as the board turns, and the check sees that as far as the board turned in its windows
  // (the calibration run holds poses still for seconds: 30 s may fall mostly on them; 26° rms
  // a window gave 12° before); the fitted calibration leaves the gyro's noise and the 0.1 s
  // windows
  assert.ok(windows >= 5, `${windows} windows`);
  assert.ok(turned > 0 && before > 0.15 * turned, `before ${before}° on a turn of ${turned}° rms a window`);
  assert.equal(/says little/.test(await page.textContent("#verify-turn")), turned < 10, `turned ${turned}°`);
  if (turned >= 10) assert.ok(before > 2, `before ${before}° on a turn of ${turned}° rms a window`);
  assert.ok(after < before / 3, `before ${before}°, after ${after}°`);
  // on the sphere: the part's 25 µT of hard iron spread the raw |B| by about 15 µT rms; the
  // calibration leaves the noise of 0.1 s means and the fit's error (well under 1 µT): a fall
  // by ten at least; the accelerometer's drawn offset (0.05–0.3 m/s² an axis) and scale
  // spread the raw |a|, the fit leaves millimetres per second squared: by three at least
  const d = await page.evaluate(() => ({ ...document.querySelector("#verify-result").dataset }));
  const magnitudes = await page.textContent("#verify-magnitudes");
  console.log(`verification on the sphere: ${magnitudes}`);
  const [mb, ma, ab, aa] = [d.magBefore, d.magAfter, d.accelBefore, d.accelAfter].map(Number);
  assert.ok(mb > 3 && ma < mb / 10, `|B| spread ${mb} → ${ma} µT`);
  assert.ok(Number(d.magAfterSigma) > 0, `its uncertainty ${d.magAfterSigma}`);
  assert.ok(ab > 0 && aa < ab / 3, `|a| spread ${ab} → ${aa} m/s²`);
  if (PART) assert.ok(Math.abs(Number(d.field) - PART.field_ut) < 2.5, `field ${d.field} µT (the part's soft iron scales it by 1 ± 5 %)`);
  assert.ok(Number(await page.getAttribute("#verify-cloud", "data-points")) > 100);
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
  // one pose, asked for while the board moves: the progress bar, then the pose; the page asks
  // for the same pose again as soon as the first is taken (the emulated board runs five times
  // faster than real time here: its 5 s holds last a second, too short for a round trip of
  // the test's own)
  await page.waitForSelector("#accel-still[data-still=no]", { timeout: 180_000 });
  await page.evaluate(() => {
    const body = document.querySelector("#accel-poses tbody");
    const again = new MutationObserver(() => {
      if (Number(body.dataset.poses) >= 1) { again.disconnect(); document.querySelector("#accel-capture").click(); }
    });
    again.observe(body, { attributes: true, attributeFilter: ["data-poses"] });
  });
  await page.click("#accel-capture");
  // the pending row with its bar, or the pose already (the emulated board runs faster than
  // real time: it may have come to rest for the hold's second before the click arrived)
  await page.waitForFunction(() => document.querySelector("#accel-progress") ||
    Number(document.querySelector("#accel-poses tbody").dataset.poses) > 0, null, { timeout: 60_000 });
  console.log(`first capture: ${await page.$("#accel-progress") ? "pending, its progress bar shown" : "taken at once"}`);
  await captured(0);
  // the same pose again at once (the board still held): the same orientation twice
  await captured(1);
  await page.waitForSelector(".merge-warning");
  const warning = await page.textContent(".merge-warning");
  console.log(`merge warning: ${warning}`);
  assert.match(warning, /Poses 1 and 2 are the same orientation \([\d.e-]+° apart/);
  assert.match(await page.textContent("#accel-warnings"), /Missing: no pose yet with .* up/);
  await shotInView(page, "#accel-wizard", join(OUT, "accel-merge-warning.png"));
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
