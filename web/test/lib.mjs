// Shared by the browser tests: the imu-lab binary, the server it starts, and Debian's Chromium
// driven by playwright-core (never a downloaded browser).
import { spawn, execFileSync } from "node:child_process";
import { mkdtempSync, mkdirSync, existsSync } from "node:fs";
import { tmpdir } from "node:os";
import { join } from "node:path";
import { createInterface } from "node:readline";
import { chromium } from "playwright-core";

/// The imu-lab binary (xtask passes the one it built).
export const IMU_LAB = process.env.IMU_LAB_BIN || "imu-lab";
/// The browser: Debian's chromium package.
export const CHROMIUM = process.env.CHROMIUM || "/usr/bin/chromium";
/// Where screenshots go (xtask: out/serve).
export const OUT = process.env.SERVE_TEST_OUT || mkdtempSync(join(tmpdir(), "serve-out-"));
mkdirSync(OUT, { recursive: true });

export function scratch() {
  return mkdtempSync(join(tmpdir(), "serve-test-"));
}

/// A random integer in [lo, hi]; the tests print the values they drew.
export function pick(lo, hi) {
  return lo + Math.floor(Math.random() * (hi - lo + 1));
}

export function imuLab(args) {
  return execFileSync(IMU_LAB, args, { encoding: "utf8", stdio: ["ignore", "pipe", "inherit"] });
}

/// `imu-lab serve ARGS --listen 127.0.0.1:0`: resolves to { url, stop } once it prints its URL.
export function serve(args, { timeoutMs = 120_000 } = {}) {
  const child = spawn(IMU_LAB, ["serve", ...args, "--listen", "127.0.0.1:0"], {
    stdio: ["ignore", "pipe", "inherit"],
  });
  return new Promise((resolve, reject) => {
    const timer = setTimeout(() => { child.kill(); reject(new Error("imu-lab serve printed no URL")); }, timeoutMs);
    child.on("exit", (code) => reject(new Error(`imu-lab serve exited (${code}) before printing its URL`)));
    const lines = createInterface({ input: child.stdout });
    lines.on("line", (line) => {
      const m = /^imu-lab serve: (http:\/\/127\.0\.0\.1:\d+\/)$/.exec(line);
      if (m) {
        clearTimeout(timer);
        resolve({
          url: m[1],
          host: new URL(m[1]).host,
          pid: child.pid,
          stop: () => new Promise((r) => { child.once("exit", r); child.kill(); }),
        });
      }
    });
  });
}

/// Headless Chromium with the flags that keep it off the network, on an empty profile
/// (playwright-core passes it as --user-data-dir): a browser context; close it when done.
export async function browser(extraArgs = []) {
  return chromium.launchPersistentContext(scratch(), {
    executablePath: CHROMIUM,
    headless: true,
    viewport: { width: 1280, height: 900 },
    args: [
      "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
      "--disable-background-networking", "--disable-component-update", "--disable-sync",
      ...extraArgs,
    ],
  });
}

export function chromiumAvailable() {
  return existsSync(CHROMIUM);
}
