// The noise lab in a real headless Chromium, on a recording made by the simulator with an effect
// the five-term model lacks (a Gauss–Markov process, τ_c and σ drawn at random): the page names
// it, a click adds it, and the χ²/dof it shows falls to an adequate model. Then the security
// rules seen from a browser: another site can neither read the token nor write, and a rebound
// DNS name gets nothing.
import { test, before, after } from "node:test";
import assert from "node:assert/strict";
import { createServer, request } from "node:http";
import { join } from "node:path";
import { IMU_LAB, OUT, browser, imuLab, pick, scratch, serve } from "./lib.mjs";

let srv, ctx, file, drawn;
const T0 = Date.now();
const log = (m) => console.log(`[${((Date.now() - T0) / 1000).toFixed(1)} s] ${m}`);

before(async () => {
  const dir = scratch();
  file = join(dir, "hidden-markov.csv");
  const seed = pick(1, 1_000_000);
  const tauC = pick(20, 60) / 100; // s
  const sigma = pick(15, 30) / 1000; // deg/s
  drawn = `seed ${seed}, Gauss–Markov σ = ${sigma} deg/s, τ_c = ${tauC} s`;
  console.log(`recording: ${drawn} (${IMU_LAB})`);
  imuLab(["simulate", "--rate", "100", "--samples", "30000", "--seed", String(seed), "--columns", "gx,gy",
    "--white", "5e-3", "--markov", `${sigma},${tauC}`, "-o", file]);
  srv = await serve([file]);
  ctx = await browser(["--host-resolver-rules=MAP rebind.test 127.0.0.1, MAP other.test 127.0.0.1"]);
});

after(async () => {
  await ctx?.close();
  await srv?.stop();
});

test("the named effect is shown, a click adds it, χ²/dof falls to adequate", async () => {
  const page = await ctx.newPage();
  const foreign = [];
  page.on("request", (r) => { if (!r.url().startsWith(srv.url)) foreign.push(r.url()); });
  const t0 = Date.now();
  await page.goto(srv.url);
  await page.waitForSelector("body[data-ready=yes]");
  const load = await page.evaluate(() => {
    const n = performance.getEntriesByType("navigation")[0];
    return n.loadEventEnd - n.startTime;
  });
  console.log(`page load: ${load.toFixed(0)} ms (navigation timing), ${Date.now() - t0} ms to ready`);

  log("choosing gx");
  await page.selectOption("#column", "gx");
  await page.waitForSelector("#lab-body:not([hidden]) #verdict.bad", { timeout: 120_000 });
  log("first fit shown");
  const chi2Before = Number(await page.getAttribute("#chi2", "data-value"));
  const named = page.locator("#add-named");
  await named.waitFor({ state: "visible" });
  const effect = await named.getAttribute("data-effect");
  console.log(`${drawn}: χ²/dof ${chi2Before}, named: ${effect}`);
  assert.equal(effect, "markov", `the hidden Gauss–Markov process is named (${drawn})`);
  assert.match(await named.textContent(), /markov/);
  assert.match(await page.textContent("#diagnosis"), /markov/);
  // its physics paragraph and a failing τ range are on the page
  assert.match(await page.textContent("#physics"), /markov/);
  assert.ok((await page.locator("#params tbody tr").count()) >= 4);
  await page.screenshot({ path: join(OUT, "noise-lab-before.png"), fullPage: true });

  log("adding the named effect");
  await named.click();
  log("clicked");
  await page.waitForSelector("#steps tbody tr", { timeout: 120_000 });
  log("step row shown");
  await page.waitForSelector("#verdict.ok", { timeout: 120_000 });
  const chi2After = Number(await page.getAttribute("#chi2", "data-value"));
  const row = await page.textContent("#steps tbody tr");
  console.log(`after + ${effect}: χ²/dof ${chi2After}; step row: ${row}`);
  // Adequate by the lab's own criterion (global p at least 1e-3, noise_model::assess::P_GLOBAL):
  // with about ten degrees of freedom a right model's χ²/dof exceeds 2 in a few percent of draws.
  const verdict = await page.textContent("#verdict");
  assert.match(verdict, /^ADEQUATE/);
  const pGlobal = Number(verdict.match(/global p = ([0-9.e+-]+)/)?.[1]);
  assert.ok(pGlobal >= 1e-3, `global p ${pGlobal} (${verdict})`);
  assert.ok(chi2After * 5 < chi2Before, `χ²/dof ${chi2Before} → ${chi2After}: fell at least five-fold`);
  assert.match(row, /\+ markov/);
  assert.match(await page.textContent("#command"), /--add markov$/);
  // every parameter row carries a unit or is a shape parameter with its own
  const values = await page.locator("#params tbody td:nth-child(3)").allTextContents();
  assert.ok(values.every((v) => /±|—|\S+ \S+/.test(v)), values.join(" | "));
  await page.screenshot({ path: join(OUT, "noise-lab.png"), fullPage: true });

  log("exports");
  // the exports: the CLI's JSON and report for the command shown
  const [download] = await Promise.all([page.waitForEvent("download"), page.click("#export-json")]);
  const json = JSON.parse(await (await import("node:fs/promises")).readFile(await download.path(), "utf8"));
  assert.equal(json.column, "gx");
  assert.ok(json.terms.some((t) => t.effect === "markov"));
  const cli = JSON.parse(imuLab(["fit", file, "--column", "gx", "--add", "markov", "--json"]));
  assert.deepEqual(json, cli);

  log("remove, then the walk");
  // remove an effect by hand, then the walk: the table grows by a row each time
  await page.selectOption("#effect", "markov");
  await page.click("#remove-effect");
  await page.waitForFunction(() => document.querySelectorAll("#steps tbody tr").length === 2, null, { timeout: 120_000 });
  assert.match(await page.textContent("#steps tbody tr:nth-child(2)"), /− markov/);
  log("walk");
  await page.click("#auto");
  await page.waitForFunction(() => document.querySelectorAll("#steps tbody tr").length >= 3, null, { timeout: 180_000 });
  await page.waitForSelector("#verdict.ok");
  assert.deepEqual(foreign, [], "the page loads nothing from elsewhere");
  await page.close();
});

test("another site can neither read the token nor write; a rebound name gets nothing", async () => {
  // the lab's state before: what must not change
  const before = await (await fetch(srv.url + "api/lab")).text();
  // a page on another origin (its own server, another port)
  const evil = createServer((req, res) => {
    res.writeHead(200, { "content-type": "text/html" });
    res.end("<!DOCTYPE html><title>elsewhere</title><p>elsewhere</p>");
  });
  await new Promise((r) => evil.listen(0, "127.0.0.1", r));
  const evilUrl = `http://other.test:${evil.address().port}/`;
  const page = await ctx.newPage();
  await page.goto(evilUrl);
  const target = srv.url;
  const results = await page.evaluate(async (target) => {
    const out = {};
    // reading the token: blocked by the browser (no CORS headers)
    try { await (await fetch(target + "api/info")).json(); out.read = "read"; } catch (e) { out.read = "blocked"; }
    // a JSON write with the header: the preflight is refused
    try {
      const r = await fetch(target + "api/lab/edit", { method: "POST", headers: { "content-type": "application/json", "x-imu-lab-token": "guess" }, body: '{"add":"markov"}' });
      out.preflighted = r.status;
    } catch (e) { out.preflighted = "blocked"; }
    // a "simple" write (no preflight): sent, refused by the server for its Origin
    try {
      await fetch(target + "api/lab/select", { method: "POST", mode: "no-cors", headers: { "content-type": "text/plain" }, body: '{"column":"gy"}' });
      out.simple = "sent";
    } catch (e) { out.simple = "blocked"; }
    return out;
  }, target);
  assert.equal(results.read, "blocked");
  assert.equal(results.preflighted, "blocked");
  assert.equal(await (await fetch(srv.url + "api/lab")).text(), before, "the lab is unchanged");
  // the status the server gave that simple write, seen from outside the browser
  const status = await new Promise((resolve, reject) => {
    const req = request(srv.url + "api/lab/select", { method: "POST", headers: { origin: evilUrl.slice(0, -1), "content-type": "text/plain" } },
      (res) => { res.resume(); resolve(res.statusCode); });
    req.on("error", reject);
    req.end('{"column":"gy"}');
  });
  assert.equal(status, 403);
  // DNS rebinding: a name that resolves to 127.0.0.1 gets a 403, not the page
  const port = new URL(srv.url).port;
  const resp = await page.goto(`http://rebind.test:${port}/api/info`);
  assert.equal(resp.status(), 403);
  assert.doesNotMatch(await page.content(), /token/);
  // a path outside the embedded files
  const trav = await page.goto(srv.url + "assets/..%2F..%2FCargo.toml");
  assert.equal(trav.status(), 404);
  await page.close();
  evil.close();
});
