// Drives the dashboard in the system's headless Chromium (playwright-core, no downloaded
// browser): creates a small cohort through the form and watches it reach 100 % without a
// reload, opens a shape in the viewer and checks the WebGL canvas drew it, overlays a second
// shape, downloads a GLB and checks its header, validates the cohort against the model's
// training shapes and reads its verdict and report, shows a validation error beside its field,
// checks keyboard reach and a narrow window, and fails on any unexpected console error.
// Screenshots of the main pages go to SCREENSHOT_DIR.
//
// Environment: DASHBOARD_URL (required), CHROMIUM (default /usr/bin/chromium),
// SCREENSHOT_DIR (optional), USER_DATA_DIR (required: a fresh directory).

import assert from "node:assert/strict";
import { readFile } from "node:fs/promises";
import { join } from "node:path";
import { chromium } from "playwright-core";

const base = process.env.DASHBOARD_URL;
const shots = process.env.SCREENSHOT_DIR;
const userDataDir = process.env.USER_DATA_DIR;
assert.ok(base && userDataDir, "DASHBOARD_URL and USER_DATA_DIR must be set");

const FLAGS = [
  "--headless",
  "--no-sandbox",
  "--disable-gpu",
  "--disable-background-networking",
  "--disable-component-update",
  "--disable-sync",
  "--disable-quic",
  "--no-first-run",
  // WebGL on the CPU (SwiftShader): without a GPU, recent Chromium needs the opt-in.
  "--enable-unsafe-swiftshader",
];

const results = [];
const consoleErrors = [];
/** Console errors a step provokes on purpose (a 422 answer is logged by the browser). */
const expected = [];

async function step(name, fn) {
  const start = Date.now();
  try {
    await fn();
    results.push([name, true]);
    console.log(`ok   ${name} (${((Date.now() - start) / 1000).toFixed(1)} s)`);
  } catch (error) {
    results.push([name, false]);
    console.log(`FAIL ${name}: ${error.stack ?? error}`);
  }
}

async function screenshot(page, name) {
  if (shots) await page.screenshot({ path: join(shots, `dashboard-${name}.png`), fullPage: false });
}

/** Pixels in the middle fifth of the viewer canvas that differ from its background. */
async function shapePixels(page) {
  return page.evaluate(() => {
    const canvas = document.querySelector("#viewer-stage canvas");
    const bg = canvas.dataset.background.match(/[0-9a-f]{2}/gi).map((x) => parseInt(x, 16));
    const copy = document.createElement("canvas");
    copy.width = canvas.width;
    copy.height = canvas.height;
    const ctx = copy.getContext("2d");
    ctx.drawImage(canvas, 0, 0);
    const [w, h] = [Math.floor(copy.width / 5), Math.floor(copy.height / 5)];
    const data = ctx.getImageData(2 * w, 2 * h, w, h).data;
    let shape = 0;
    const colours = new Set();
    for (let i = 0; i < data.length; i += 4) {
      const d = Math.abs(data[i] - bg[0]) + Math.abs(data[i + 1] - bg[1]) + Math.abs(data[i + 2] - bg[2]);
      if (d > 24) shape++;
      colours.add(`${data[i] >> 4},${data[i + 1] >> 4},${data[i + 2] >> 4}`);
    }
    return { shape, total: data.length / 4, colours: colours.size };
  });
}

/** Pixels of the whole viewer canvas in the opening markers' colour (#1f7a4a). */
async function markerPixels(page) {
  return page.evaluate(() => {
    const canvas = document.querySelector("#viewer-stage canvas");
    const copy = document.createElement("canvas");
    copy.width = canvas.width;
    copy.height = canvas.height;
    const ctx = copy.getContext("2d");
    ctx.drawImage(canvas, 0, 0);
    const data = ctx.getImageData(0, 0, copy.width, copy.height).data;
    let marker = 0;
    for (let i = 0; i < data.length; i += 4) {
      if (Math.abs(data[i] - 0x1f) + Math.abs(data[i + 1] - 0x7a) + Math.abs(data[i + 2] - 0x4a) < 24) marker++;
    }
    return marker;
  });
}

const context = await chromium.launchPersistentContext(userDataDir, {
  executablePath: process.env.CHROMIUM ?? "/usr/bin/chromium",
  headless: true,
  args: FLAGS,
  viewport: { width: 1280, height: 800 },
  acceptDownloads: true,
});
const page = context.pages()[0] ?? (await context.newPage());
page.setDefaultTimeout(30000);
page.on("console", (message) => {
  if (message.type() !== "error") return;
  const text = `${message.text()} @ ${message.location().url}`;
  const hit = expected.find((e) => !e.seen && e.pattern.test(text));
  if (hit) hit.seen = true;
  else consoleErrors.push(text);
});
page.on("pageerror", (error) => consoleErrors.push(`uncaught: ${error.message}`));

let cohortId;
let shapeIds = [];

await step("the dashboard opens at / and its event stream goes live", async () => {
  await page.goto(base);
  await page.getByRole("heading", { name: "Cohorts" }).waitFor();
  await page.locator("#live.on").waitFor();
});

await step("a validation error is shown beside the field it names", async () => {
  await page.goto(`${base}/#/new`);
  await page.getByRole("heading", { name: "New cohort" }).waitFor();
  expected.push({ pattern: /status of 422/, seen: false });
  await page.fill("#f-resolution", "20");
  await page.click("button[type=submit]");
  const error = page.locator('[data-field="resolution"] .field-error');
  await error.filter({ hasText: /resolution/i }).waitFor();
  assert.equal(await page.getAttribute("#f-resolution", "aria-invalid"), "true");
  assert.equal(await page.locator('[data-field="count"] .field-error').textContent(), "");
  await screenshot(page, "form-error");
});

await step("a cohort created through the form reaches 100 % without a reload", async () => {
  await page.evaluate(() => (window.__sameDocument = true));
  await page.fill("#f-count", "3");
  await page.fill("#f-arity", "2");
  await page.fill("#f-resolution", "40");
  await page.fill("#f-seed", "7");
  await page.click("button[type=submit]");
  await page.waitForURL(/#\/cohorts\/\d+$/);
  cohortId = Number(page.url().match(/cohorts\/(\d+)$/)[1]);
  const seen = new Set();
  const pct = page.locator("#cohort-progress .pct");
  const deadline = Date.now() + 240000;
  while (Date.now() < deadline) {
    const text = await pct.textContent();
    seen.add(text);
    if (text === "100 %") break;
    await page.waitForTimeout(200);
  }
  assert.ok(seen.has("100 %"), `progress seen: ${[...seen].join(", ")}`);
  assert.ok(seen.size > 1, `the progress never changed on the page: ${[...seen].join(", ")}`);
  assert.equal(await page.evaluate(() => window.__sameDocument), true, "the page was reloaded");
  await page.locator("h1 .badge.succeeded").waitFor({ timeout: 60000 });
  await page.locator("ul.thumbs img").nth(2).waitFor();
  await page.waitForFunction(() => [...document.querySelectorAll("ul.thumbs img")].every((i) => i.complete && i.naturalWidth === 256));
  await page.locator(".plots img").first().waitFor();
  await page.waitForFunction(() => [...document.querySelectorAll(".plots img")].every((i) => i.complete && i.naturalWidth > 0));
  shapeIds = await page.$$eval("#measurements td.links a[href^='#/viewer']", (as) => as.map((a) => Number(a.href.match(/shape=(\d+)/)[1])));
  assert.equal(shapeIds.length, 3);
  await screenshot(page, "cohort");
});

await step("the measurements table sorts by a column", async () => {
  const volumes = () => page.$$eval("#measurements tbody tr", (rows) => rows.map((r) => Number(r.children[2].textContent)));
  await page.getByRole("button", { name: "Volume mm³" }).click();
  const up = await volumes();
  assert.deepEqual(up, [...up].sort((a, b) => a - b));
  await page.getByRole("button", { name: "Volume mm³" }).click();
  const down = await volumes();
  assert.deepEqual(down, [...up].reverse());
});

await step("a GLB download is binary glTF version 2", async () => {
  const download = page.waitForEvent("download");
  await page.locator("#measurements td.links a", { hasText: /^glb$/ }).first().click();
  const file = await (await download).path();
  const bytes = await readFile(file);
  assert.equal(bytes.subarray(0, 4).toString("latin1"), "glTF");
  assert.equal(bytes.readUInt32LE(4), 2);
  assert.equal(bytes.readUInt32LE(8), bytes.length, "header length = file length");
});

await step("a validation against the model's training shapes reaches its verdict on the cohort page", async () => {
  const form = page.locator("#validation-form");
  await form.waitFor();
  const options = await page.$$eval("#validation-reference option", (os) => os.map((o) => o.value));
  assert.ok(options.includes("training"), `references offered: ${options}`);
  await page.selectOption("#validation-reference", "training");
  expected.push({ pattern: /status of 422/, seen: false });
  await page.fill("#validation-points", "200000");
  await form.getByRole("button", { name: "Validate" }).click();
  await page.locator("#validations .error", { hasText: /^points: / }).waitFor();
  assert.equal(await page.getAttribute("#validation-points", "aria-invalid"), "true");
  assert.equal(await page.locator("#validation-list").count(), 0, "a rejected request made a validation");
  await page.fill("#validation-points", "300");
  await page.fill("#validation-criteria", '{"nna_max": 1.0}');
  await form.getByRole("button", { name: "Validate" }).click();
  const row = page.locator("#validation-list tbody tr").first();
  await row.locator(".badge.pass").waitFor({ timeout: 180000 });
  assert.match(await row.locator("td").first().textContent(), /training \(16 shapes\)/);
  await row.locator("td").first().click();
  await page.locator("#validation-checks li", { hasText: /nna_max/ }).waitFor();
  const report = row.getByRole("link", { name: "report" });
  assert.match(await report.getAttribute("href"), /^\/v1\/validations\/\d+\/report\.html$/);
  const html = await (await page.request.get(`${base}${await report.getAttribute("href")}`)).text();
  assert.match(html, /1-NNA/);
  await page.locator("#validation-checks").scrollIntoViewIfNeeded();
  await screenshot(page, "validation");
});

await step("the viewer draws the shape in the middle of its canvas", async () => {
  await page.goto(`${base}/#/viewer?shape=${shapeIds[0]}`);
  await page.locator("#viewer-stage[data-state=ready]").waitFor();
  const pixels = await shapePixels(page);
  assert.ok(pixels.shape > pixels.total / 4, `only ${pixels.shape} of ${pixels.total} pixels differ from the background`);
  await screenshot(page, "viewer");
});

await step("orbit and zoom respond to the mouse and keyboard", async () => {
  const before = await page.evaluate(() => document.querySelector("#viewer-stage canvas").toDataURL());
  const box = await page.locator("#viewer-stage canvas").boundingBox();
  await page.mouse.move(box.x + box.width / 2, box.y + box.height / 2);
  await page.mouse.down();
  await page.mouse.move(box.x + box.width / 2 + 120, box.y + box.height / 2 + 30, { steps: 8 });
  await page.mouse.up();
  const orbited = await page.evaluate(() => document.querySelector("#viewer-stage canvas").toDataURL());
  assert.notEqual(orbited, before, "dragging did not change the view");
  await page.getByRole("button", { name: "Zoom in" }).focus();
  await page.keyboard.press("Enter");
  const zoomed = await page.evaluate(() => document.querySelector("#viewer-stage canvas").toDataURL());
  assert.notEqual(zoomed, orbited, "the zoom button did not change the view");
  await page.getByRole("button", { name: "Reset view" }).click();
});

await step("a second shape overlays the first with a distance colour map", async () => {
  await page.selectOption("#v-overlay", String(shapeIds[1]));
  await page.locator("#viewer-stage[data-overlay=ready]").waitFor();
  await page.locator(".legend:not([hidden])").waitFor();
  assert.match(await page.locator(".legend").textContent(), new RegExp(`shape ${shapeIds[1]}`));
  const pixels = await shapePixels(page);
  assert.ok(pixels.shape > pixels.total / 4, `overlay: ${pixels.shape} of ${pixels.total}`);
  assert.ok(pixels.colours > 8, `a colour map shows several colours, got ${pixels.colours}`);
  assert.match(page.url(), new RegExp(`overlay=${shapeIds[1]}`));
  await screenshot(page, "overlay");
});

await step("the viewer finds a shape's openings and labels them", async () => {
  await page.click("#find-openings");
  await page.locator("#openings li, #openings-error").first().waitFor({ timeout: 120000 });
  const error = await page.locator("#openings-error").count();
  assert.equal(error, 0, error ? await page.locator("#openings-error").textContent() : "");
  const names = await page.$$eval("#openings li", (items) => items.map((li) => li.textContent));
  assert.ok(names.some((n) => n.startsWith("inlet:")), `no inlet among ${names}`);
  assert.ok(names.some((n) => n.startsWith("outlet")), `no outlet among ${names}`);
  assert.ok(names.every((n) => /⌀ \d/.test(n)), `every opening shows its diameter: ${names}`);
  assert.equal(await page.getAttribute("#viewer-stage", "data-markers"), String(names.length));
  const marked = await markerPixels(page);
  assert.ok(marked > 20, `the openings' markers show in the scene (${marked} pixels of their colour)`);
  await screenshot(page, "viewer-openings");
});

await step("the cohorts list shows the cohort as succeeded", async () => {
  await page.goto(`${base}/#/cohorts`);
  const row = page.locator(`tr[data-cohort="${cohortId}"]`);
  await row.locator(".badge.succeeded").waitFor();
  assert.equal(await row.locator(".pct").textContent(), "100 %");
  await screenshot(page, "cohorts");
});

await step("the models page shows the bundled model with its plot", async () => {
  await page.goto(`${base}/#/models`);
  await page.getByRole("heading", { name: /default/ }).waitFor();
  await page.waitForFunction(() => [...document.querySelectorAll(".card figure img")].some((i) => i.complete && i.naturalWidth > 0));
  await screenshot(page, "models");
});

await step("every control is reachable with the keyboard", async () => {
  await page.goto("about:blank");
  await page.goto(`${base}/#/new`);
  await page.getByRole("heading", { name: "New cohort" }).waitFor();
  const unreachable = await page.$$eval("a, button, input, select", (els) =>
    els.filter((e) => e.tabIndex < 0 && !e.closest("dialog")).map((e) => e.outerHTML.slice(0, 80)));
  assert.deepEqual(unreachable, []);
  await page.keyboard.press("Tab");
  assert.equal(await page.evaluate(() => document.activeElement.className), "skip");
  const reached = new Set();
  for (let i = 0; i < 60; i++) {
    await page.keyboard.press("Tab");
    reached.add(await page.evaluate(() => document.activeElement.id || document.activeElement.textContent.trim()));
  }
  for (const id of ["f-model_id", "f-count", "f-resolution", "f-targets-annulus_mm-min", "Create cohort"]) {
    assert.ok(reached.has(id), `Tab never reached ${id}`);
  }
});

await step("a narrow window shows the pages without sideways scrolling", async () => {
  await page.setViewportSize({ width: 390, height: 844 });
  for (const hash of ["#/cohorts", `#/cohorts/${cohortId}`, "#/new", "#/models", `#/viewer?shape=${shapeIds[0]}`]) {
    await page.goto(`${base}/${hash}`);
    await page.locator("main h1").waitFor();
    await page.waitForTimeout(300);
    const overflow = await page.evaluate(() => document.documentElement.scrollWidth - window.innerWidth);
    assert.ok(overflow <= 1, `${hash} is ${overflow} px wider than the window`);
  }
  await page.locator("#viewer-stage[data-state=ready]").waitFor();
  await screenshot(page, "narrow-viewer");
  await page.setViewportSize({ width: 1280, height: 800 });
});

await step("no unexpected console error", async () => {
  const missing = expected.filter((e) => !e.seen).map((e) => String(e.pattern));
  assert.deepEqual(consoleErrors, []);
  assert.deepEqual(missing, [], "an expected console error did not happen");
});

await context.close();
const failed = results.filter(([, ok]) => !ok).length;
console.log(`${results.length - failed} passed, ${failed} failed`);
process.exit(failed ? 1 : 0);
