// Browser test: serves the trunk-built dist/ on 127.0.0.1, drives Debian's headless Chromium
// (WebGPU on SwiftShader) with playwright-core, and checks that
//  1. the app reports WebGPU up, the demo volume loaded and frames drawn (window.shapecastStatus),
//  2. the screenshot is not blank,
//  3. a browser without WebGPU gets a plain-words message instead of a blank canvas.
// It never downloads a browser. Under CI=true a missing browser or dist/ is a failure (it always
// is here: there is no skip path).
import { chromium } from 'playwright-core';
import { PNG } from 'pngjs';
import http from 'node:http';
import fs from 'node:fs';
import os from 'node:os';
import path from 'node:path';
import { fileURLToPath } from 'node:url';

const here = path.dirname(fileURLToPath(import.meta.url));
const root = path.resolve(here, '..', '..');
const dist = path.join(root, 'dist');
const outDir = path.join(here, 'out');
const chromiumPath = process.env.CHROMIUM ?? '/usr/bin/chromium';
const timeoutMs = Number(process.env.SHAPECAST_BROWSER_TIMEOUT_MS ?? 300000);

let passed = 0;
let failed = 0;
function check(name, ok, detail = '') {
  if (ok) {
    passed += 1;
    console.log(`ok   - ${name}${detail ? `: ${detail}` : ''}`);
  } else {
    failed += 1;
    console.log(`FAIL - ${name}${detail ? `: ${detail}` : ''}`);
  }
}

if (!fs.existsSync(path.join(dist, 'index.html'))) {
  console.error(`browser test: ${dist}/index.html is missing; run \`trunk build --release\` first`);
  process.exit(1);
}
if (!fs.existsSync(chromiumPath)) {
  console.error(`browser test: no browser at ${chromiumPath}; apt-get install chromium`);
  process.exit(1);
}

const mime = {
  '.html': 'text/html; charset=utf-8',
  '.js': 'text/javascript',
  '.wasm': 'application/wasm',
  '.css': 'text/css',
  '.png': 'image/png',
  '.gz': 'application/gzip',
  '.json': 'application/json',
};
const server = http.createServer((req, res) => {
  const url = new URL(req.url, 'http://127.0.0.1');
  let file = path.normalize(path.join(dist, decodeURIComponent(url.pathname)));
  if (!file.startsWith(dist)) {
    res.writeHead(403).end();
    return;
  }
  if (fs.existsSync(file) && fs.statSync(file).isDirectory()) file = path.join(file, 'index.html');
  fs.readFile(file, (err, data) => {
    if (err) {
      res.writeHead(404).end('not found');
      return;
    }
    res.writeHead(200, { 'content-type': mime[path.extname(file)] ?? 'application/octet-stream' });
    res.end(data);
  });
});
await new Promise((resolve) => server.listen(0, '127.0.0.1', resolve));
const url = `http://127.0.0.1:${server.address().port}/`;
console.log(`serving ${dist} at ${url}`);

const baseArgs = [
  '--no-sandbox',
  '--disable-background-networking',
  '--disable-component-update',
  '--disable-sync',
  '--no-first-run',
  '--disable-quic',
];
const webgpuArgs = [
  '--enable-unsafe-webgpu',
  '--enable-features=Vulkan',
  '--use-vulkan=swiftshader',
  '--use-angle=swiftshader',
];

async function withBrowser(args, fn) {
  const userDataDir = fs.mkdtempSync(path.join(os.tmpdir(), 'shapecast-chromium-'));
  const context = await chromium.launchPersistentContext(userDataDir, {
    executablePath: chromiumPath,
    headless: true,
    args,
    viewport: { width: 1280, height: 800 },
  });
  try {
    const page = context.pages()[0] ?? (await context.newPage());
    page.on('console', (msg) => {
      if (msg.type() === 'error' || msg.type() === 'warning') console.log(`  [page ${msg.type()}] ${msg.text()}`);
    });
    page.on('pageerror', (err) => console.log(`  [page error] ${err}`));
    return await fn(page);
  } finally {
    await context.close();
    fs.rmSync(userDataDir, { recursive: true, force: true });
  }
}

function screenshotStats(buffer) {
  const png = PNG.sync.read(buffer);
  const colours = new Set();
  let sum = 0;
  let sum2 = 0;
  const n = png.width * png.height;
  for (let p = 0; p < n; p += 1) {
    const r = png.data[4 * p];
    const g = png.data[4 * p + 1];
    const b = png.data[4 * p + 2];
    colours.add((r << 16) | (g << 8) | b);
    const l = 0.299 * r + 0.587 * g + 0.114 * b;
    sum += l;
    sum2 += l * l;
  }
  const mean = sum / n;
  return { colours: colours.size, mean, std: Math.sqrt(Math.max(0, sum2 / n - mean * mean)) };
}

fs.mkdirSync(outDir, { recursive: true });
try {
  // 1 and 2: the app on WebGPU.
  await withBrowser([...baseArgs, ...webgpuArgs], async (page) => {
    const t0 = Date.now();
    await page.goto(url);
    let status;
    try {
      // The wasm must start within two minutes even on SwiftShader; a page that never leaves
      // "starting" (a load error) fails fast instead of waiting for the full timeout.
      await page.waitForFunction(() => window.shapecastStatus?.phase !== 'starting', null,
        { timeout: 120000, polling: 250 });
      await page.waitForFunction(
        () => {
          const s = window.shapecastStatus;
          return s && (s.phase === 'error' || (s.phase === 'ready' && s.frames >= 3));
        },
        null,
        { timeout: timeoutMs, polling: 250 },
      );
    } catch (e) {
      console.log(`  timed out waiting for the app: ${e.message.split('\n')[0]}`);
    }
    status = await page.evaluate(() => window.shapecastStatus);
    const seconds = ((Date.now() - t0) / 1000).toFixed(1);
    console.log(`  window.shapecastStatus after ${seconds} s: ${JSON.stringify(status)}`);
    check('app reports ready', status?.phase === 'ready', `phase ${status?.phase}, error ${status?.error}`);
    check('WebGPU adapter reported', !!status?.adapter?.name, `${status?.adapter?.name} (${status?.adapter?.backend})`);
    check('demo volume loaded', Array.isArray(status?.volume?.dims) && status.volume.dims.every((d) => d > 1),
      `${JSON.stringify(status?.volume?.dims)} at ${JSON.stringify(status?.volume?.spacing_mm)} mm`);
    check('frames drawn', (status?.frames ?? 0) >= 3, `${status?.frames} frames`);
    // Give the compositor a moment to present the last frame before the screenshot.
    await page.waitForTimeout(500);
    const shot = await page.screenshot({ path: path.join(outDir, 'app.png') });
    const stats = screenshotStats(shot);
    check('screenshot is not blank', stats.colours >= 64 && stats.std >= 8,
      `${stats.colours} colours, luminance mean ${stats.mean.toFixed(1)} std ${stats.std.toFixed(1)} (${path.join(outDir, 'app.png')})`);
  });

  // 3: a browser without WebGPU.
  await withBrowser(baseArgs, async (page) => {
    await page.addInitScript(() => {
      Object.defineProperty(Navigator.prototype, 'gpu', { get: () => undefined, configurable: true });
    });
    await page.goto(url);
    await page.waitForFunction(() => window.shapecastStatus?.phase === 'error', null, { timeout: 60000 })
      .catch(() => {});
    const status = await page.evaluate(() => window.shapecastStatus);
    const message = await page.evaluate(() => {
      const m = document.getElementById('message');
      return m && !m.hidden ? m.innerText : '';
    });
    await page.screenshot({ path: path.join(outDir, 'no-webgpu.png') });
    check('no WebGPU: status says error', status?.phase === 'error', `${status?.error}`);
    check('no WebGPU: page explains in plain words', /needs WebGPU/.test(message) && /Chrome/.test(message),
      message.split('\n')[0]);
  });
} finally {
  server.close();
}

console.log(`browser: ${passed} passed, ${failed} failed`);
process.exit(failed === 0 ? 0 : 1);
