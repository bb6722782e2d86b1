// The plotting library the page embeds is exactly the npm package web/package.json pins: the
// files in crates/imu-lab/assets/vendor equal those of node_modules/uplot, licence included.
import { test } from "node:test";
import assert from "node:assert/strict";
import { readFileSync } from "node:fs";
import { dirname, join } from "node:path";
import { fileURLToPath } from "node:url";

const web = join(dirname(fileURLToPath(import.meta.url)), "..");
const vendor = join(web, "..", "crates", "imu-lab", "assets", "vendor");

test("the vendored uPlot is the pinned npm release", () => {
  const pinned = JSON.parse(readFileSync(join(web, "package.json"), "utf8")).dependencies.uplot;
  const installed = JSON.parse(readFileSync(join(web, "node_modules", "uplot", "package.json"), "utf8")).version;
  assert.equal(installed, pinned, "npm ci installed the version package.json pins");
  for (const [mine, theirs] of [
    ["uPlot.iife.min.js", "dist/uPlot.iife.min.js"],
    ["uPlot.min.css", "dist/uPlot.min.css"],
    ["LICENSE-uPlot", "LICENSE"],
  ]) {
    assert.ok(readFileSync(join(vendor, mine)).equals(readFileSync(join(web, "node_modules", "uplot", theirs))), `${mine} differs from uplot ${pinned}'s ${theirs}`);
  }
});
