// Headless rendering of the viewer page in Chromium through playwright-core (called by
// btf-eval render-web and the browser tests; docs/viewer.md). Usage:
//   node render.mjs --export DIR --job DIR --mode shot|eval|bench --out FILE
//                   [--chromium /usr/bin/chromium] [--timeout SECONDS] [--frames N] [--ui JSON]
// shot: the frame as a PNG (the canvas's own pixels); page: a screenshot of the interactive page
// (mode=view, with its controls and ms per frame) as a PNG; canvas: the interactive page's frame
// (its canvas) as a PNG, after the controls in --ui ([[id, value], ...]: set like a user, with
// input and change events) were applied; eval: float32 [N][3] btf_eval values at
// JOB/queries.f32; bench: JSON with ms per frame. JOB/scene.json holds the scene (size, camera,
// light, exposure). Prints one JSON line (renderer, timings; in page and canvas modes the panel's
// texts by element id); exit 0 on success, 1 on failure.
import fs from 'node:fs';
import path from 'node:path';
import { chromium } from 'playwright-core';
import { startServer, parseArgs } from './server.mjs';

const a = parseArgs(process.argv.slice(2));
for (const k of ['export', 'job', 'mode', 'out']) if (!a[k]) { console.error(`render.mjs: --${k} is required`); process.exit(2); }
const timeoutMs = Number(a.timeout || 120) * 1000;
const scene = JSON.parse(fs.readFileSync(path.join(a.job, 'scene.json'), 'utf8'));

const { server, url } = await startServer({ exportDir: a.export, jobDir: a.job });
let browser;
let rc = 1;
try {
  browser = await chromium.launch({
    executablePath: a.chromium || '/usr/bin/chromium',
    headless: true,
    // Software WebGL2 (SwiftShader through ANGLE): the same pixels on any machine, no GPU needed.
    args: ['--use-angle=swiftshader', '--use-gl=angle', '--enable-unsafe-swiftshader', '--ignore-gpu-blocklist',
           '--no-sandbox', '--disable-dev-shm-usage'],
    timeout: timeoutMs,
  });
  const page = await browser.newPage({ viewport: { width: scene.width || 960, height: scene.height || 640 }, deviceScaleFactor: 1 });
  const logs = [];
  page.on('console', (m) => logs.push(`${m.type()}: ${m.text()}`));
  page.on('pageerror', (e) => logs.push(`pageerror: ${e.message}`));
  const t0 = Date.now();
  const interactive = a.mode === 'page' || a.mode === 'canvas';
  const pageMode = interactive ? 'view' : a.mode;
  await page.goto(`${url}index.html?mode=${pageMode}&job=1&frames=${a.frames || 10}`, { timeout: timeoutMs });
  await page.waitForFunction(() => window.btfStatus && window.btfStatus.done, null, { timeout: timeoutMs, polling: 100 });
  const st = await page.evaluate(() => window.btfStatus);
  if (st.error) throw new Error(`${st.error}\n${logs.join('\n')}`);
  const r = st.result;
  const tmp = `${a.out}.tmp-${process.pid}`;
  let summary = { mode: a.mode, seconds: (Date.now() - t0) / 1000, renderer: r.renderer };
  if (interactive) {
    // Set the controls as a user would, then wait for the frame they ask for.
    const ui = a.ui ? JSON.parse(a.ui) : [];
    await page.waitForFunction(() => window.btfStatus.frames >= 1, null, { timeout: timeoutMs, polling: 50 });
    const frames = await page.evaluate((ui) => {
      for (const [id, value] of ui) {
        const el = document.getElementById(id);
        if (!el) throw new Error(`no control '${id}'`);
        el.value = String(value);
        el.dispatchEvent(new Event('input'));
        el.dispatchEvent(new Event('change'));
      }
      return window.btfStatus.frames;
    }, ui);
    if (ui.length)
      await page.waitForFunction((f) => window.btfStatus.frames > f && !window.btfStatus.pending, frames, { timeout: timeoutMs, polling: 50 });
    const panel = await page.evaluate(() => Object.fromEntries(
      ['ms', 'exposure-value', 'tile-value', 'angles', 'info'].map((id) => [id, document.getElementById(id).textContent])));
    if (a.mode === 'page') {
      await page.waitForTimeout(500);  // the HUD's ms per frame is written after the first frame
      await page.screenshot({ path: tmp, type: 'png' });
    } else {
      const png = await page.evaluate(() => document.getElementById('view').toDataURL('image/png'));
      fs.writeFileSync(tmp, Buffer.from(png.replace(/^data:image\/png;base64,/, ''), 'base64'));
    }
    summary = { ...summary, width: scene.width, height: scene.height, panel };
  } else if (a.mode === 'shot') {
    fs.writeFileSync(tmp, Buffer.from(r.png.replace(/^data:image\/png;base64,/, ''), 'base64'));
    summary = { ...summary, width: r.width, height: r.height };
  } else if (a.mode === 'eval') {
    fs.writeFileSync(tmp, Buffer.from(new Float32Array(r.values).buffer));
    summary = { ...summary, count: r.count };
  } else if (a.mode === 'bench') {
    summary = { ...summary, ...r, width: scene.width, height: scene.height };
    fs.writeFileSync(tmp, JSON.stringify(summary) + '\n');
  } else {
    throw new Error(`unknown mode '${a.mode}' (shot, page, canvas, eval, bench)`);
  }
  fs.renameSync(tmp, a.out);
  console.log(JSON.stringify(summary));
  rc = 0;
} catch (e) {
  console.error(`render.mjs: ${e.message}`);
} finally {
  if (browser) await browser.close();
  server.close();
}
process.exit(rc);
