// Memory of the live page and of the server over a long run against a device (or the emulated
// Pico): every INTERVAL s the page's JS heap and DOM size (Chromium's performance metrics over
// CDP, after a forced garbage collection) and the server's resident memory (/proc). Neither
// should grow once the stream history (60 s of device time) is full. The run lasts until
// MINUTES of wall time and DEVICE_MINUTES (default MINUTES) of the device's time have passed
// (an emulated board runs faster or slower than real time with the machine's load). The plotted channel changes at
// every row (each of the stream's channels in turn), as a user's clicks would.
//
//   IMU_LAB_BIN=… node web/bench/live_soak.mjs tcp:127.0.0.1:PORT MINUTES [INTERVAL_S [DEVICE_MINUTES]]
// (`cargo xtask bench-serve --minutes 60` starts the emulated board and runs this.)
import { readFileSync } from "node:fs";
import { browser, scratch, serve } from "../test/lib.mjs";

const [port, minutes = "10", every = "30", deviceMinutes = minutes] = process.argv.slice(2);
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
const uptime = () => page.evaluate(() => Number(document.querySelector("#live-status").dataset.uptime));
const channels = await page.evaluate(() => [...document.querySelectorAll("#stream-channel option")].map((o) => o.value));
console.log("| wall [min] | device uptime [min] | stream points received | table round | channel plotted | points on the page | page JS heap [MiB] | page DOM nodes | server RSS [MiB] |");
console.log("|---:|---:|---:|---:|---|---:|---:|---:|---:|");
const t0 = Date.now();
const u0 = await uptime();
const rows = [];
for (let k = 0; ; k++) {
  const wall = (Date.now() - t0) / 60_000;
  await cdp.send("HeapProfiler.collectGarbage").catch(() => {});
  const { metrics } = await cdp.send("Performance.getMetrics");
  const m = Object.fromEntries(metrics.map((x) => [x.name, x.value]));
  const s = await page.evaluate(() => ({
    uptime: Number(document.querySelector("#live-status").dataset.uptime),
    round: document.querySelector("#tables").dataset.round || "—",
    points: Number(document.querySelector("#stream-plot").dataset.points || 0),
    channel: document.querySelector("#stream-plot").dataset.channel || "—",
    received: window.imuLabStreamReceived || 0,
  }));
  const row = { wall, device: (s.uptime - u0) / 60, heap: m.JSHeapUsedSize / 2 ** 20, nodes: m.Nodes, rss: rss(srv.pid) };
  rows.push(row);
  console.log(`| ${wall.toFixed(1)} | ${row.device.toFixed(1)} | ${s.received} | ${s.round} | ${s.channel} | ${s.points} | ` +
    `${row.heap.toFixed(2)} | ${m.Nodes} | ${row.rss.toFixed(1)} |`);
  if (wall >= Number(minutes) && row.device >= Number(deviceMinutes)) break;
  // the next channel, as a user's click would pick it
  if (channels.length) await page.selectOption("#stream-channel", channels[(k + 1) % channels.length]);
  await new Promise((r) => setTimeout(r, Number(every) * 1000));
}
// after the first row past 2 minutes (the history full): the range of each measure
const full = rows.filter((r) => r.wall >= 2);
const range = (f, d = 2) => `${Math.min(...full.map(f)).toFixed(d)}–${Math.max(...full.map(f)).toFixed(d)}`;
if (full.length) {
  console.log();
  console.log(`From ${full[0].wall.toFixed(1)} to ${full[full.length - 1].wall.toFixed(1)} min of wall time ` +
    `(${full[0].device.toFixed(1)} to ${full[full.length - 1].device.toFixed(1)} min of device time): ` +
    `page JS heap ${range((r) => r.heap)} MiB, DOM ${range((r) => r.nodes, 0)} nodes, server RSS ${range((r) => r.rss)} MiB.`);
}
await ctx.close();
await srv.stop();
