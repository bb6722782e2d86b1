// Memory of the live page and of the server over a long run against a device (or the emulated
// Pico): every INTERVAL s the page's JS heap and DOM size (Chromium's performance metrics) and the
// server's resident memory (/proc). Neither should grow once the stream history (60 s of device
// time) is full.
//
//   IMU_LAB_BIN=… node web/bench/live_soak.mjs tcp:127.0.0.1:PORT MINUTES [INTERVAL_S]
import { readFileSync } from "node:fs";
import { browser, scratch, serve } from "../test/lib.mjs";

const [port, minutes = "10", every = "30"] = process.argv.slice(2);
if (!port) {
  console.error("usage: node web/bench/live_soak.mjs PORT MINUTES [INTERVAL_S]");
  process.exit(2);
}
const rss = (pid) => Number(/VmRSS:\s+(\d+) kB/.exec(readFileSync(`/proc/${pid}/status`, "utf8"))[1]) / 1024;
const srv = await serve(["--port", port, "--record-dir", scratch()]);
const ctx = await browser();
const page = await ctx.newPage();
const cdp = await ctx.newCDPSession(page);
await cdp.send("Performance.enable");
await page.goto(srv.url);
await page.waitForSelector("#live-status[data-uptime]", { timeout: 120_000 });
console.log("| wall [s] | device uptime [s] | table round | stream points on the page | page JS heap [MiB] | page DOM nodes | server RSS [MiB] |");
console.log("|---:|---:|---:|---:|---:|---:|---:|");
const t0 = Date.now();
while (Date.now() - t0 < Number(minutes) * 60_000) {
  await cdp.send("HeapProfiler.collectGarbage").catch(() => {});
  const { metrics } = await cdp.send("Performance.getMetrics");
  const m = Object.fromEntries(metrics.map((x) => [x.name, x.value]));
  const s = await page.evaluate(() => ({
    uptime: Number(document.querySelector("#live-status").dataset.uptime),
    round: document.querySelector("#tables").dataset.round || "—",
    points: Number(document.querySelector("#stream-plot").dataset.points || 0),
  }));
  console.log(`| ${((Date.now() - t0) / 1000).toFixed(0)} | ${s.uptime.toFixed(1)} | ${s.round} | ${s.points} | ` +
    `${(m.JSHeapUsedSize / 2 ** 20).toFixed(2)} | ${m.Nodes} | ${rss(srv.pid).toFixed(1)} |`);
  await new Promise((r) => setTimeout(r, Number(every) * 1000));
}
await ctx.close();
await srv.stop();
