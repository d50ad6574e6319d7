// Browser test of opening scans by link and sharing the exact view (issue 15). It serves the
// trunk-built dist/ on 127.0.0.1 at / and under a sub-path (/some/path/), the test volumes of
// ../shared/data (at /data/, plus a zipped DICOM series made here, at /gen/), and a second origin
// (another port) with CORS headers (/cors/) and without (/nocors/); then drives Debian's headless
// Chromium (WebGPU on SwiftShader) with playwright-core and checks:
//  1. the build: every inline script's hash is in the page's Content-Security-Policy, and the
//     page names its files by relative URLs (it works under any sub-path);
//  2. ?url= (percent-encoded, relative) loads a NIfTI under the sub-path; a NRRD header + data
//     pair from the other origin (CORS), and a zipped DICOM series, by link; each has the
//     geometry a drop of the same files gives (a real drag and drop through the DevTools
//     protocol, Input.dispatchDragEvent, and the folder input);
//  3. failures name the URL, say what to do, and keep the volume: 404, 403, a CORS refusal,
//     an HTML page (by type and by content), a volume too large for the tab, a host the CSP
//     refuses; a download shows bytes of its total and can be cancelled;
//  4. a link round trip: the MIP turned by a mouse drag and zoomed by the wheel, windows
//     right-dragged, the mode and a gain clicked, "Copy link" clicked; the copied link opened in
//     a fresh browser gives an equal `view` and a screenshot within a small pixel difference;
//  5. a link to a dropped file says which file to drop and restores the view when it is dropped;
//  6. a page whose program cannot load says so, and plain http from another host says WebGPU
//     needs HTTPS.
// Every request the pages make is recorded: any to a host other than 127.0.0.1 fails the suite,
// and so does any Content-Security-Policy violation that a case did not ask for.
// ../shared/data missing: its cases are skipped with a message, except under CI=true, where that
// is a failure. Screenshots: target/browser/*.png.
import { chromium } from 'playwright-core';
import { PNG } from 'pngjs';
import crypto from 'node:crypto';
import fs from 'node:fs';
import http from 'node:http';
import os from 'node:os';
import path from 'node:path';
import { fileURLToPath } from 'node:url';
import { zipFolder } from './zip.mjs';

const here = path.dirname(fileURLToPath(import.meta.url));
const root = path.resolve(here, '..', '..');
const dist = path.join(root, 'dist');
const data = path.resolve(root, '..', 'shared', 'data');
const outDir = path.join(root, 'target', 'browser');
const chromiumPath = process.env.CHROMIUM ?? '/usr/bin/chromium';
const ci = process.env.CI === 'true';
const SUB = '/some/path/';
const t0 = Date.now();

let passed = 0;
let failed = 0;
let skipped = 0;
function check(name, ok, detail = '') {
  if (ok) passed += 1;
  else failed += 1;
  // [seconds since the start]: where a slow run spends its time.
  const t = ((Date.now() - STARTED) / 1000).toFixed(0).padStart(4);
  console.log(`${ok ? 'ok  ' : 'FAIL'} [${t} s] - ${name}${detail ? `: ${detail}` : ''}`);
  return ok;
}
const STARTED = Date.now();
function skip(name, why) {
  skipped += 1;
  console.log(`skip - ${name}: ${why}`);
}

if (!fs.existsSync(path.join(dist, 'index.html'))) {
  console.error(`links test: ${dist}/index.html is missing; run \`cargo xtask build\` (or trunk build --release) first`);
  process.exit(1);
}
if (!fs.existsSync(chromiumPath)) {
  console.error(`links test: no browser at ${chromiumPath}; apt-get install chromium`);
  process.exit(1);
}
const haveData = fs.existsSync(path.join(data, 'README.md'));
if (!haveData) {
  if (ci) {
    console.error(`links test: ${data} is missing, and under CI=true it must be there`);
    process.exit(1);
  }
  console.log(`note: ${data} is missing: the cases on its volumes are skipped (CI=true makes this a failure)`);
}
fs.mkdirSync(outDir, { recursive: true });

// ---- Test files ---------------------------------------------------------------------------

const NIFTI = 'ct/example_ct_sm.nii.gz';
const NIFTI_DIMS = [122, 101, 30];
const NRRD = ['formats/multishell-DWI-451dir.nhdr', 'formats/multishell-DWI-451dir.raw.gz'];
const SERIES = 'series/ct-head-64px';

const generated = {};
if (haveData) generated['ct-head-64px.zip'] = zipFolder(path.join(data, SERIES), 'ct-head-64px');
// A PET/CT study's CT and PET, each a zipped series, for `?url=CT&pet=PET`.
const PETCT = 'petct/sts-cropped/STS_001';
if (haveData) {
  generated['sts001-ct.zip'] = zipFolder(path.join(data, PETCT, 'CT'), 'CT');
  generated['sts001-pet.zip'] = zipFolder(path.join(data, PETCT, 'PET'), 'PET');
}

// ---- Servers ------------------------------------------------------------------------------

const mime = {
  '.html': 'text/html; charset=utf-8',
  '.js': 'text/javascript',
  '.wasm': 'application/wasm',
  '.css': 'text/css',
  '.gz': 'application/gzip',
  '.zip': 'application/zip',
};
function sendFile(res, file, extra = {}) {
  fs.readFile(file, (err, bytes) => {
    if (err) {
      res.writeHead(404, { 'content-type': 'text/plain', ...extra }).end('not found');
      return;
    }
    res.writeHead(200, {
      'content-type': mime[path.extname(file)] ?? 'application/octet-stream',
      'content-length': bytes.length,
      ...extra,
    });
    res.end(bytes);
  });
}
function under(base, rel) {
  const file = path.normalize(path.join(base, rel));
  return file.startsWith(base) ? file : null;
}
// A page's request for a build file, optionally with one kind of file missing (a broken deploy).
function serveDist(res, rel, missing) {
  if (rel === '' || rel.endsWith('/')) rel += 'index.html';
  if (missing && rel.endsWith(missing)) {
    res.writeHead(404, { 'content-type': 'text/plain' }).end('not found');
    return;
  }
  const file = under(dist, rel);
  if (!file) {
    res.writeHead(403).end();
    return;
  }
  sendFile(res, file);
}

const LOGIN = '<!DOCTYPE html><html><head><title>Sign in</title></head><body><form>Password <input type=password></form></body></html>';
let slowCancelled = false;
const serverA = http.createServer((req, res) => {
  const url = new URL(req.url, 'http://127.0.0.1');
  const p = decodeURIComponent(url.pathname);
  if (p === SUB.slice(0, -1)) {
    res.writeHead(301, { location: SUB }).end();
  } else if (p.startsWith(SUB)) {
    serveDist(res, p.slice(SUB.length));
  } else if (p.startsWith('/broken-js/')) {
    serveDist(res, p.slice('/broken-js/'.length), '.js');
  } else if (p.startsWith('/broken-wasm/')) {
    serveDist(res, p.slice('/broken-wasm/'.length), '_bg.wasm');
  } else if (p.startsWith('/data/')) {
    const file = under(data, p.slice('/data/'.length));
    if (file) sendFile(res, file);
    else res.writeHead(403).end();
  } else if (p.startsWith('/gen/')) {
    const bytes = generated[p.slice('/gen/'.length)];
    if (!bytes) res.writeHead(404).end('not found');
    else res.writeHead(200, { 'content-type': 'application/zip', 'content-length': bytes.length }).end(bytes);
  } else if (p === '/login') {
    res.writeHead(200, { 'content-type': 'text/html; charset=utf-8' }).end(LOGIN);
  } else if (p === '/sneaky.nii.gz') {
    // A login page sent as if it were a file.
    res.writeHead(200, { 'content-type': 'application/octet-stream' }).end(`\n  ${LOGIN}`);
  } else if (p === '/private.nii.gz') {
    res.writeHead(403, { 'content-type': 'text/plain' }).end('forbidden');
  } else if (p === '/huge.nii.gz') {
    // Declares 3 GB; the app must refuse it from the header, before reading the body.
    res.writeHead(200, { 'content-type': 'application/gzip', 'content-length': 3_000_000_000 });
    res.write(Buffer.alloc(1024));
    setTimeout(() => res.destroy(), 2000);
  } else if (p === '/slow.nii.gz') {
    // 4 MB at 64 KB every 100 ms: long enough to see progress and cancel.
    const total = 4 << 20;
    res.writeHead(200, { 'content-type': 'application/gzip', 'content-length': total });
    let sent = 0;
    const timer = setInterval(() => {
      if (res.destroyed || sent >= total) {
        clearInterval(timer);
        if (!res.destroyed) res.end();
        return;
      }
      res.write(Buffer.alloc(64 << 10));
      sent += 64 << 10;
    }, 100);
    res.on('close', () => {
      if (sent < total) slowCancelled = true;
      clearInterval(timer);
    });
  } else if (p === '/' || p.startsWith('/')) {
    serveDist(res, p.slice(1));
  }
});
const serverB = http.createServer((req, res) => {
  const url = new URL(req.url, 'http://127.0.0.1');
  const p = decodeURIComponent(url.pathname);
  const cors = { 'access-control-allow-origin': '*' };
  if (req.method === 'OPTIONS') {
    res.writeHead(204, cors).end();
  } else if (p.startsWith('/cors/')) {
    const file = under(data, p.slice('/cors/'.length));
    if (file) sendFile(res, file, cors);
    else res.writeHead(403).end();
  } else if (p.startsWith('/nocors/')) {
    const file = under(data, p.slice('/nocors/'.length));
    if (file) sendFile(res, file);
    else res.writeHead(403).end();
  } else {
    res.writeHead(404).end();
  }
});
await new Promise((r) => serverA.listen(0, '127.0.0.1', r));
await new Promise((r) => serverB.listen(0, '127.0.0.1', r));
const A = `http://127.0.0.1:${serverA.address().port}`;
const B = `http://127.0.0.1:${serverB.address().port}`;
console.log(`serving ${dist} at ${A}/ and ${A}${SUB}, data at ${A}/data/ and ${B}/cors/, /nocors/`);

// ---- Browser ------------------------------------------------------------------------------

const baseArgs = [
  '--no-sandbox',
  '--disable-background-networking',
  '--disable-component-update',
  '--disable-sync',
  '--no-first-run',
  '--disable-quic',
  // The one name that is not 127.0.0.1, for the plain-http case: it resolves to 127.0.0.1.
  '--host-resolver-rules=MAP insecure.test 127.0.0.1',
];
const webgpuArgs = [
  '--enable-unsafe-webgpu',
  '--enable-features=Vulkan',
  '--use-vulkan=swiftshader',
  '--use-angle=swiftshader',
];
const requests = [];
const offending = [];
const cspViolations = [];
let expectCsp = null;

async function withBrowser(args, fn) {
  const userDataDir = fs.mkdtempSync(path.join(os.tmpdir(), 'shapecast-links-'));
  const context = await chromium.launchPersistentContext(userDataDir, {
    executablePath: chromiumPath,
    headless: true,
    args,
    viewport: { width: 1280, height: 800 },
  });
  await context.grantPermissions(['clipboard-read', 'clipboard-write'], { origin: A });
  context.on('request', (r) => {
    const u = new URL(r.url());
    if (u.protocol === 'data:' || u.protocol === 'blob:') return;
    requests.push(r.url());
    if (u.hostname !== '127.0.0.1' && u.hostname !== 'insecure.test') offending.push(r.url());
  });
  context.on('response', async (r) => {
    const addr = await r.serverAddr().catch(() => null);
    if (addr && addr.ipAddress !== '127.0.0.1') offending.push(`${r.url()} (server ${addr.ipAddress})`);
  });
  await context.addInitScript(() => {
    window.__csp = [];
    window.addEventListener('securitypolicyviolation', (e) => window.__csp.push(`${e.violatedDirective} ${e.blockedURI}`));
  });
  try {
    const page = context.pages()[0] ?? (await context.newPage());
    page.on('console', (msg) => {
      const text = msg.text();
      if (/Content.Security.Policy/i.test(text)) {
        if (expectCsp && expectCsp.test(text)) return;
        cspViolations.push(text);
      }
      if (msg.type() === 'error') console.log(`  [page error] ${text.slice(0, 300)}`);
    });
    page.on('pageerror', (err) => console.log(`  [page exception] ${err}`));
    return await fn(page, context);
  } finally {
    await context.close();
    fs.rmSync(userDataDir, { recursive: true, force: true });
  }
}

const status = (page) => page.evaluate(() => window.shapecastStatus);
async function waitStatus(page, pred, what, arg = null, timeout = 180000) {
  try {
    await page.waitForFunction(pred, arg, { timeout, polling: 200 });
  } catch {
    console.log(`  timed out waiting for ${what}`);
  }
  return status(page);
}
// The status once its view has stayed the same for half a second (at most ~10 s).
async function stableView(page) {
  let s = await status(page);
  for (let i = 0; i < 20; i += 1) {
    await page.waitForTimeout(500);
    const t = await status(page);
    if (JSON.stringify(t?.view) === JSON.stringify(s?.view)) return t;
    s = t;
  }
  return s;
}
// The MIP drawn in full (not the coarse frame nor the bands that refine it) and the features
// done: a picture a screenshot can compare, instead of a sleep that a slow machine outruns.
async function waitPicture(page, what) {
  return waitStatus(page, () => {
    const s = window.shapecastStatus;
    return s?.mip === 'done' && ['done', 'none', 'failed'].includes(s?.features?.state ?? 'none');
  }, `${what}: the finished picture`);
}
const idle = (s) => s && (s.phase === 'ready' || s.phase === 'error') && s.volume;
async function waitReady(page, what) {
  return waitStatus(page, () => {
    const s = window.shapecastStatus;
    const f = s?.features?.state;
    return s && s.phase === 'error'
      || (s?.phase === 'ready' && s.volume && s.frames > 3 && (f === 'done' || f === 'none' || f === 'failed'));
  }, what);
}
const geometry = (s) => JSON.stringify(s?.volume
  ? { dims: s.volume.dims, spacing: s.volume.spacing_mm, origin: s.volume.origin_mm, direction: s.volume.direction }
  : null);
const rectCentre = (r, fx = 0.5, fy = 0.5) => [r[0] + r[2] * fx, r[1] + r[3] * fy];
async function control(page, name) {
  const s = await status(page);
  const r = s?.controls?.[name];
  if (!r) throw new Error(`no control ${name} in ${JSON.stringify(Object.keys(s?.controls ?? {}))}`);
  return r;
}
async function click(page, name, fx = 0.5, fy = 0.5) {
  const [x, y] = rectCentre(await control(page, name), fx, fy);
  await page.mouse.click(x, y);
}
// A real drag and drop of files on disk, through the DevTools protocol.
async function cdpDrop(page, context, files) {
  const cdp = await context.newCDPSession(page);
  const [x, y] = [640, 400];
  const dragData = { items: [], files, dragOperationsMask: 1 };
  for (const type of ['dragEnter', 'dragOver', 'drop']) {
    await cdp.send('Input.dispatchDragEvent', { type, x, y, data: dragData });
  }
  await cdp.detach();
}
async function openLink(page, fragment) {
  await page.evaluate((f) => { window.location.hash = f; }, fragment);
}
function pngDiff(a, b) {
  const pa = PNG.sync.read(a);
  const pb = PNG.sync.read(b);
  if (pa.width !== pb.width || pa.height !== pb.height) return { fraction: 1, mean: 255 };
  let differing = 0;
  let sum = 0;
  const n = pa.width * pa.height;
  for (let p = 0; p < n; p += 1) {
    let d = 0;
    for (let c = 0; c < 3; c += 1) d = Math.max(d, Math.abs(pa.data[4 * p + c] - pb.data[4 * p + c]));
    sum += d;
    if (d > 24) differing += 1;
  }
  return { fraction: differing / n, mean: sum / n };
}

try {
  // ---- 1. The build -----------------------------------------------------------------------
  {
    const html = fs.readFileSync(path.join(dist, 'index.html'), 'utf8');
    const csp = /<meta http-equiv="Content-Security-Policy" content="([^"]*)"/.exec(html)?.[1] ?? '';
    check('CSP: a policy meta is in the built page', csp.includes("default-src 'self'") && csp.includes("'wasm-unsafe-eval'"), csp);
    const inline = [...html.matchAll(/<script(?![^>]*\bsrc=)[^>]*>([\s\S]*?)<\/script>/g)].map((m) => m[1]);
    const hashes = inline.map((s) => `'sha256-${crypto.createHash('sha256').update(s, 'utf8').digest('base64')}'`);
    check('CSP: every inline script is allowed by its hash', inline.length > 0 && hashes.every((h) => csp.includes(h)),
      `${inline.length} inline script(s), hashes ${hashes.join(' ')}`);
    const absolute = [...html.matchAll(/\b(?:src|href|data-js|data-wasm)="(\/[^"]*)"/g)].map((m) => m[1]);
    check('the page names its files by relative URLs', absolute.length === 0, absolute.join(' ') || 'none absolute');
  }

  // ---- 2 and 3: loading by URL, failures, geometry against drops --------------------------
  await withBrowser([...baseArgs, ...webgpuArgs], async (page, context) => {
    if (!haveData) {
      skip('?url= and link loading', `${data} is missing`);
      return;
    }
    // Percent-encoded and relative (to the sub-path's page).
    const encoded = encodeURIComponent(`../../data/${NIFTI}`);
    await page.goto(`${A}${SUB}?url=${encoded}&method=intensity`);
    let s = await waitReady(page, 'the NIfTI by ?url=');
    check('sub-path: the page loads and starts under /some/path/', s?.adapter?.name && s?.phase === 'ready',
      `phase ${s?.phase}, adapter ${s?.adapter?.name}, error ${s?.error}`);
    check('?url= (percent-encoded, relative): NIfTI loaded', JSON.stringify(s?.volume?.dims) === JSON.stringify(NIFTI_DIMS)
      && /example_ct_sm/.test(s?.volume?.source ?? ''), `${JSON.stringify(s?.volume?.dims)} from ${s?.volume?.source}`);
    check('?url=: the link names the absolute URL', s?.view?.url?.[0] === `${A}/data/${NIFTI}`, JSON.stringify(s?.view?.url));
    const niftiByUrl = geometry(s);
    await page.screenshot({ path: path.join(outDir, 'url-nifti.png') });

    // The same file dropped for real (DevTools protocol): the same geometry.
    await cdpDrop(page, context, [path.join(data, NIFTI)]);
    s = await waitStatus(page, () => window.shapecastStatus?.view?.file === 'example_ct_sm.nii.gz' && window.shapecastStatus.phase === 'ready',
      'the dropped NIfTI');
    check('drag and drop (Input.dispatchDragEvent): the NIfTI loads', s?.view?.file === 'example_ct_sm.nii.gz'
      && s?.view?.bytes === fs.statSync(path.join(data, NIFTI)).size, `${JSON.stringify(s?.view?.file)} ${s?.view?.bytes} bytes; error ${s?.error}`);
    check('NIfTI: ?url= gives the geometry a drop gives', geometry(s) === niftiByUrl, `${geometry(s)} vs ${niftiByUrl}`);
    const kept = geometry(s);

    // Failures: each names the URL, says what to do, and keeps the volume.
    const failures = [
      ['404', `${A}/data/missing.nii.gz`, /not found on the server \(HTTP 404\); check the address/],
      ['403', `${A}/private.nii.gz`, /refused access \(HTTP 403\).*download the file and drop it here/],
      ['CORS refusal', `${B}/nocors/${NIFTI}`, new RegExp(`server at 127\\.0\\.0\\.1:${serverB.address().port} must allow this site \\(${A.replace(/[.]/g, '\\.')}\\)`)],
      ['HTML page (by type)', `${A}/login`, /sent a web page, not a volume/],
      ['HTML page (by content)', `${A}/sneaky.nii.gz`, /sent a web page, not a volume/],
      ['too large for the tab', `${A}/huge.nii.gz`, /3000 MB is more than this browser tab can hold/],
      ['host outside the CSP', 'http://blocked.invalid/scan.nii.gz', /Content-Security-Policy does not allow downloads from blocked\.invalid/],
    ];
    for (const [what, url, expected] of failures) {
      expectCsp = what === 'host outside the CSP' ? /blocked\.invalid/ : null;
      await openLink(page, `v=1&url=${encodeURIComponent(url)}`);
      s = await waitStatus(page, (u) => (window.shapecastStatus?.error ?? '').includes(u), `the ${what} message`, url, 60000);
      check(`${what}: the message names the URL and says what to do`, (s?.error ?? '').startsWith(url) && expected.test(s?.error ?? ''), s?.error);
      check(`${what}: the volume stays`, geometry(s) === kept && s?.phase === 'ready', `phase ${s?.phase}, ${geometry(s)}`);
    }
    expectCsp = null;
    const csp = await page.evaluate(() => window.__csp);
    check('CSP: the blocked host was reported as a violation, not requested', csp.some((c) => c.includes('blocked.invalid'))
      && !requests.some((r) => r.includes('blocked.invalid')), JSON.stringify(csp));
    await page.screenshot({ path: path.join(outDir, 'url-error.png') });

    // Errors stay on screen until dismissed: from here on, a case fails on a new one.
    const shown = (await status(page)).error;
    // A slow download: bytes of the total, then cancelled; the volume stays.
    await openLink(page, `v=1&url=${encodeURIComponent(`${A}/slow.nii.gz`)}`);
    s = await waitStatus(page, () => /downloading slow\.nii\.gz \([0-9.]+ of 4\.2 MB\)/.test(window.shapecastStatus?.task ?? '')
      && window.shapecastStatus.progress > 0 && window.shapecastStatus.controls?.['cancel-download'], 'download progress', null, 60000);
    check('download: progress in bytes of the total', /downloading slow\.nii\.gz \([0-9.]+ of 4\.2 MB\)/.test(s?.task ?? '') && s.progress > 0 && s.progress < 0.5,
      `${s?.task}, progress ${s?.progress}`);
    await page.screenshot({ path: path.join(outDir, 'url-progress.png') });
    await click(page, 'cancel-download');
    s = await waitStatus(page, () => window.shapecastStatus?.phase === 'ready' && !window.shapecastStatus.task, 'the cancel', null, 30000);
    await new Promise((r) => setTimeout(r, 300));
    check('download: cancel stops it and keeps the volume', s?.phase === 'ready' && s?.error === shown && geometry(s) === kept && slowCancelled,
      `phase ${s?.phase}, error ${s?.error}, server saw the abort: ${slowCancelled}`);

    // A NRRD header + data pair from the other origin, which allows it (CORS).
    const pair = NRRD.map((f) => `url=${encodeURIComponent(`${B}/cors/${f}`)}`).join('&');
    await openLink(page, `v=1&${pair}`);
    s = await waitStatus(page, (e) => JSON.stringify(window.shapecastStatus?.volume?.dims) === '[7,7,2]' || window.shapecastStatus?.error !== e,
      'the NRRD pair by link', shown);
    check('link: NRRD header + data pair from a CORS origin', JSON.stringify(s?.volume?.dims) === '[7,7,2]' && s?.error === shown,
      `${JSON.stringify(s?.volume?.dims)} from ${s?.volume?.source}; error ${s?.error}`);
    const nrrdByUrl = geometry(s);
    await cdpDrop(page, context, NRRD.map((f) => path.join(data, f)));
    s = await waitStatus(page, () => /2 files/.test(window.shapecastStatus?.view?.file ?? ''), 'the dropped NRRD pair');
    check('NRRD pair: ?url= gives the geometry a drop gives', geometry(s) === nrrdByUrl && JSON.parse(nrrdByUrl)?.direction?.[2] !== 0,
      `${geometry(s)} vs ${nrrdByUrl}`);

    // A zipped DICOM series, against the same series through the folder input.
    await openLink(page, `v=1&url=${encodeURIComponent(`${A}/gen/ct-head-64px.zip`)}`);
    s = await waitStatus(page, (e) => JSON.stringify(window.shapecastStatus?.volume?.dims) === '[64,64,93]' || window.shapecastStatus?.error !== e,
      'the zipped DICOM series', shown);
    check('link: zipped DICOM series unpacked in the page', JSON.stringify(s?.volume?.dims) === '[64,64,93]' && s?.error === shown,
      `${JSON.stringify(s?.volume?.dims)} from ${s?.volume?.source}; error ${s?.error}`);
    const zipByUrl = geometry(s);
    await page.screenshot({ path: path.join(outDir, 'url-zip-dicom.png') });
    await page.setInputFiles('#shapecast_open_folder', path.join(data, SERIES));
    s = await waitStatus(page, () => /ct-head-64px/.test(window.shapecastStatus?.view?.file ?? ''), 'the DICOM folder');
    check('zipped DICOM: ?url= gives the geometry the folder gives', geometry(s) === zipByUrl, `${geometry(s)} vs ${zipByUrl}`);
  });

  // ---- 4. The link round trip -------------------------------------------------------------
  if (haveData) {
    let link = null;
    let viewA = null;
    let shotA = null;
    await withBrowser([...baseArgs, ...webgpuArgs], async (page) => {
      await page.goto(`${A}${SUB}?url=${encodeURIComponent(`${A}/data/${NIFTI}`)}&method=intensity`);
      let s = await waitReady(page, 'the NIfTI');
      check('round trip: the volume loads', JSON.stringify(s?.volume?.dims) === JSON.stringify(NIFTI_DIMS), s?.error ?? '');
      const before = s.view;
      // Turn the MIP by a mouse drag, zoom it with the wheel, right-drag its window.
      const mip = await control(page, 'pane:mip');
      const [cx, cy] = rectCentre(mip, 0.5, 0.6);
      await page.mouse.move(cx, cy);
      await page.mouse.down();
      for (let i = 1; i <= 10; i += 1) await page.mouse.move(cx + 9 * i, cy - 4 * i);
      await page.mouse.up();
      await page.mouse.wheel(0, -240);
      await page.mouse.move(cx, cy);
      await page.mouse.down({ button: 'right' });
      for (let i = 1; i <= 5; i += 1) await page.mouse.move(cx + 8 * i, cy + 6 * i);
      await page.mouse.up({ button: 'right' });
      // The slice window by a right-drag on the axial pane, the crosshair by a click there.
      const axial = await control(page, 'pane:axial');
      const [ax, ay] = rectCentre(axial, 0.55, 0.55);
      await page.mouse.click(ax, ay);
      await page.mouse.move(ax, ay);
      await page.mouse.down({ button: 'right' });
      for (let i = 1; i <= 5; i += 1) await page.mouse.move(ax - 10 * i, ay + 4 * i);
      await page.mouse.up({ button: 'right' });
      // The mode and a gain, clicked.
      await click(page, 'mode:li');
      s = await waitReady(page, 'the Li features');
      // On the slider's rail (the rest of the control is its value and label).
      await click(page, 'gain:0', 0.4, 0.5);
      await page.waitForTimeout(500);
      // The view once it has settled (a zoom or a window drag can still be moving it).
      s = await stableView(page);
      const v = s.view;
      check('round trip: the drag turned the MIP', JSON.stringify(v.rot) !== JSON.stringify(before.rot), `${JSON.stringify(before.rot)} -> ${JSON.stringify(v.rot)}`);
      check('round trip: the wheel zoomed it', v.zoom > before.zoom, `${before.zoom} -> ${v.zoom}`);
      check('round trip: the right-drags changed both windows', JSON.stringify(v.mipwin) !== JSON.stringify(before.mipwin)
        && JSON.stringify(v.wl) !== JSON.stringify(before.wl), `${JSON.stringify(before.mipwin)} -> ${JSON.stringify(v.mipwin)}, ${JSON.stringify(before.wl)} -> ${JSON.stringify(v.wl)}`);
      check('round trip: the mode and the gain changed', v.mode === 'li' && s.features?.state === 'done' && v.gain[0] !== 1,
        `mode ${v.mode} (${s.features?.state}), gain ${JSON.stringify(v.gain)}`);
      check('round trip: the crosshair moved', JSON.stringify(v.cross) !== JSON.stringify(before.cross), JSON.stringify(v.cross));
      await click(page, 'copy-link');
      await page.waitForTimeout(300);
      const copied = await page.evaluate(() => navigator.clipboard.readText()).catch((e) => `clipboard: ${e}`);
      s = await status(page);
      check('"Copy link" copies the link to this view', copied === s.link && copied.includes(`${SUB}#v=1&url=`), copied.slice(0, 160));
      const changed = Object.keys({ ...v, ...s.view }).filter((k) => JSON.stringify(v[k]) !== JSON.stringify(s.view?.[k]));
      check('window.shapecastStatus.view is the link\'s state', changed.length === 0,
        changed.map((k) => `${k}: ${JSON.stringify(v[k])} -> ${JSON.stringify(s.view?.[k])}`).join('; '));
      link = copied;
      viewA = s.view;
      // Away from every control, and past the "copied" note, before the screenshot.
      await page.mouse.move(5, 795);
      await page.waitForTimeout(2500);
      await waitPicture(page, 'the original view');
      shotA = await page.screenshot({ path: path.join(outDir, 'link-original.png') });
    });
    await withBrowser([...baseArgs, ...webgpuArgs], async (page) => {
      await page.goto(link);
      let s = await waitReady(page, 'the linked view');
      // The link's mode starts its features after the volume is ready: wait for both.
      s = await waitStatus(page, (want) => JSON.stringify(window.shapecastStatus?.view) === want
        && window.shapecastStatus?.features?.state === 'done', 'the same view, its features done', JSON.stringify(viewA));
      check('round trip: the link opens an equal view', JSON.stringify(s?.view) === JSON.stringify(viewA),
        `${JSON.stringify(s?.view)}\n    vs ${JSON.stringify(viewA)}`);
      check('round trip: features computed in the opened view', s?.features?.method === 'li' && s?.features?.state === 'done', JSON.stringify(s?.features));
      await page.mouse.move(5, 795);
      await page.waitForTimeout(1500);
      await waitPicture(page, 'the opened view');
      const shotB = await page.screenshot({ path: path.join(outDir, 'link-opened.png') });
      const d = pngDiff(shotA, shotB);
      check('round trip: the screenshots match', d.fraction < 0.005,
        `${(100 * d.fraction).toFixed(3)}% of pixels differ by more than 24 levels, mean difference ${d.mean.toFixed(2)} (target/browser/link-original.png, link-opened.png)`);
    });

    // ---- 5. A link to a dropped file ------------------------------------------------------
    await withBrowser([...baseArgs, ...webgpuArgs], async (page, context) => {
      const bytes = fs.statSync(path.join(data, NIFTI)).size;
      const fragment = link.split('#')[1].replace(/url=[^&]*/, `file=example_ct_sm.nii.gz&bytes=${bytes}`);
      await page.goto(`${A}${SUB}#${fragment}`);
      let s = await waitStatus(page, () => window.shapecastStatus?.notice, 'the notice');
      check('dropped-file link: it says which file to drop', /example_ct_sm\.nii\.gz/.test(s?.notice ?? '') && /[Dd]rop/.test(s?.notice ?? '') && !s?.volume,
        s?.notice);
      await page.screenshot({ path: path.join(outDir, 'link-drop-notice.png') });
      await cdpDrop(page, context, [path.join(data, NIFTI)]);
      s = await waitReady(page, 'the dropped file');
      const want = { ...viewA };
      delete want.url;
      s = await waitStatus(page, (w) => {
        const v = { ...window.shapecastStatus?.view };
        delete v.file;
        delete v.bytes;
        return JSON.stringify(v) === w;
      }, 'the restored view', JSON.stringify(want), 30000);
      const got = { ...s?.view };
      check('dropped-file link: the drop restores the view', got.file === 'example_ct_sm.nii.gz' && got.bytes === bytes
        && (delete got.file, delete got.bytes, JSON.stringify(got) === JSON.stringify(want)) && !s?.notice,
      `${JSON.stringify(s?.view)}`);
    });
  } else {
    skip('link round trip and dropped-file link', `${data} is missing`);
  }

  // ---- 5b. PET/CT by link: ?url=CT&pet=PET, and the fusion carried by the copied link -----
  if (haveData) {
    await withBrowser([...baseArgs, ...webgpuArgs], async (page) => {
      const ct = `${A}/gen/sts001-ct.zip`;
      const pet = `${A}/gen/sts001-pet.zip`;
      await page.goto(`${A}${SUB}?url=${encodeURIComponent(ct)}&pet=${encodeURIComponent(pet)}&method=intensity`);
      let s = await waitStatus(page, () => window.shapecastStatus?.pet?.unit === 'SUV'
        || window.shapecastStatus?.phase === 'error', 'the CT and its PET by link');
      check('PET/CT link: the CT opens with its PET by URL, in SUV', s?.volume?.modality === 'CT'
        && s?.pet?.unit === 'SUV' && JSON.stringify(s?.pet?.dims) === '[41,43,59]',
        `volume ${s?.volume?.modality}, pet ${JSON.stringify(s?.pet)}; error ${s?.error}`);
      const link = s?.link ?? '';
      const plain = decodeURIComponent(link);
      check('PET/CT link: the copied link names the PET and its fusion', plain.includes(`pet=${pet}`)
        && /[#&]petwin=0,10(&|$)/.test(plain) && /[#&]petop=0.5(&|$)/.test(plain), link);
      // The link with another opacity and window reopens both volumes with them.
      const edited = link.replace(/petop=[^&]*/, 'petop=0.25').replace(/petwin=[^&]*/, 'petwin=1,6');
      await page.goto('about:blank');
      await page.goto(edited);
      s = await waitStatus(page, () => window.shapecastStatus?.pet?.unit === 'SUV'
        || window.shapecastStatus?.phase === 'error', 'the PET/CT link reopened');
      check('PET/CT link: reopened with its PET, window and opacity', s?.volume?.modality === 'CT'
        && s?.pet?.opacity === 0.25 && JSON.stringify(s?.pet?.window) === '[1,6]',
        `pet ${JSON.stringify(s?.pet)}; error ${s?.error}`);
      await page.screenshot({ path: path.join(outDir, 'url-pet-ct.png') });
    });
  } else {
    skip('PET/CT by link', `${data} is missing`);
  }

  // ---- 6. Pages that cannot run ------------------------------------------------------------
  await withBrowser([...baseArgs, ...webgpuArgs], async (page) => {
    for (const [what, where] of [['program (JS module) missing', '/broken-js/'], ['wasm missing', '/broken-wasm/']]) {
      await page.goto(`${A}${where}`);
      await page.waitForFunction(() => window.shapecastStatus?.phase === 'error', null, { timeout: 60000 }).catch(() => {});
      const s = await status(page);
      const message = await page.evaluate(() => {
        const m = document.getElementById('message');
        return m && !m.hidden ? m.innerText : '';
      });
      const loadingHidden = await page.evaluate(() => document.getElementById('loading').hidden);
      check(`${what}: the page says so instead of "Loading…"`, s?.phase === 'error' && /could not (start|load)/.test(message) && loadingHidden,
        `${message.split('\n').slice(0, 2).join(' / ')}`);
    }
    await page.screenshot({ path: path.join(outDir, 'broken-deploy.png') });
    await page.goto(`http://insecure.test:${serverA.address().port}/`);
    await page.waitForFunction(() => window.shapecastStatus?.phase === 'error', null, { timeout: 60000 }).catch(() => {});
    const s = await status(page);
    const message = await page.evaluate(() => document.getElementById('message')?.innerText ?? '');
    check('plain http from another host: WebGPU needs HTTPS, said in plain words',
      s?.phase === 'error' && /needs an HTTPS address/.test(message) && !/Chrome/.test(message), message.split('\n')[0]);
    await page.screenshot({ path: path.join(outDir, 'not-https.png') });
  });

  check('every request went to 127.0.0.1', offending.length === 0 && requests.length > 0,
    `${requests.length} requests${offending.length ? `; elsewhere: ${offending.join(', ')}` : ''}`);
  check('no Content-Security-Policy violation', cspViolations.length === 0, cspViolations.join(' | '));
} catch (e) {
  check('the suite ran to the end', false, e.stack ?? String(e));
} finally {
  serverA.close();
  serverB.close();
}

console.log(`links: ${passed} passed, ${failed} failed, ${skipped} skipped in ${((Date.now() - t0) / 1000).toFixed(0)} s`);
process.exit(failed === 0 ? 0 : 1);
