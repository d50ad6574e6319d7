// Browser benchmark of a full-size scan (issue 11): a real 512 x 512 chest CT (../shared/data's
// lung2, 61 slices) repeated back and forth along z to DEPTH slices at 0.8 mm (a whole-body
// PET/CT's spacing), written as a raw NRRD, served on 127.0.0.1 and opened by link
// (`?url=/gen/wholebody.nrrd`) in Debian's headless Chromium with WebGPU on SwiftShader. It
// reports what a user waits for and what the tab holds:
//   download + read, time to the first MIP frame, the feature job (method, time), the frames
//   after it, and the memory of the browser's processes together (PSS, so shared pages count
//   once; also the largest process), sampled every 250 ms, peak and at the end.
// It is a benchmark, not a test: it fails only when the page errors or never becomes ready.
//
//   node tests/browser/bench.mjs [DEPTH] [--method li|hessian|rst|...] [--via link|file|folder|zip|multiframe]
//                                [--load-only] [--timeout-s N] [--json out.json]
//
// --via file opens the volume through the page's file input instead of a link, --via folder
// writes it as a DICOM series (one explicit-VR file per slice, the same voxels) and opens the
// folder through the page's folder input, --via zip opens that folder zipped (deflated) by link,
// --via multiframe writes it as one multi-frame DICOM file opened by the file input; --load-only stops
// 5 s after the first MIP frame (what reading costs, before any feature). The wasm memory's size
// (it never shrinks: its high-water mark) is reported beside the processes' memory.
//
// Default DEPTH 256, method li (the Hessian family: the RST of a 512-wide volume takes hours on
// SwiftShader). Results: target/browser/bench-DEPTH.json and a screenshot beside it.
import { chromium } from 'playwright-core';
import fs from 'node:fs';
import http from 'node:http';
import os from 'node:os';
import path from 'node:path';
import zlib from 'node:zlib';
import { fileURLToPath } from 'node:url';
import { zipFolder } from './zip.mjs';

const here = path.dirname(fileURLToPath(import.meta.url));
const root = path.resolve(here, '..', '..');
const dist = path.join(root, 'dist');
const data = path.resolve(root, '..', 'shared', 'data');
const outDir = path.join(root, 'target', 'browser');
const chromiumPath = process.env.CHROMIUM ?? '/usr/bin/chromium';

const args = process.argv.slice(2);
let depth = 256;
let timeoutS = 3600;
let jsonOut = null;
let method = 'li';
let via = 'link';
let loadOnly = false;
let settleS = 5;
for (let i = 0; i < args.length; i += 1) {
  if (args[i] === '--timeout-s') timeoutS = Number(args[++i]);
  else if (args[i] === '--method') method = args[++i];
  else if (args[i] === '--json') jsonOut = args[++i];
  else if (args[i] === '--via') via = args[++i];
  else if (args[i] === '--load-only') loadOnly = true;
  else if (args[i] === '--settle-s') settleS = Number(args[++i]);
  else depth = Number(args[i]);
}
if (!Number.isInteger(depth) || depth < 1 || depth > 4000) {
  console.error(`bench: DEPTH must be a whole number of slices (1..4000), not ${depth}`);
  process.exit(2);
}
for (const [what, p, hint] of [
  ['the built site', path.join(dist, 'index.html'), 'run `cargo xtask build` (or trunk build --release) first'],
  ['the browser', chromiumPath, 'apt-get install chromium'],
  ['the chest CT', path.join(data, 'ct', 'lung2_image.nrrd'), 'this benchmark needs ../shared/data'],
]) {
  if (!fs.existsSync(p)) {
    console.error(`bench: ${what} is missing at ${p}: ${hint}`);
    process.exit(1);
  }
}
fs.mkdirSync(outDir, { recursive: true });

// ---- The volume -----------------------------------------------------------------------------

function readNrrd(file) {
  const bytes = fs.readFileSync(file);
  const end = bytes.indexOf('\n\n');
  const header = bytes.subarray(0, end).toString('latin1');
  const field = (name) => header.match(new RegExp(`^${name}:\\s*(.*)$`, 'm'))?.[1];
  const sizes = field('sizes').split(/\s+/).map(Number);
  if (field('type') !== 'short' || field('encoding') !== 'gzip') throw new Error(`${file}: expected gzip shorts`);
  const voxels = zlib.gunzipSync(bytes.subarray(end + 2));
  return { sizes, voxels, origin: field('space origin') };
}

const src = readNrrd(path.join(data, 'ct', 'lung2_image.nrrd'));
const [nx, ny, nz] = src.sizes;
const slice = nx * ny * 2;
const tmp = fs.mkdtempSync(path.join(os.tmpdir(), 'shapecast-bench-'));
const volumeFile = path.join(tmp, 'wholebody.nrrd');
{
  const fd = fs.openSync(volumeFile, 'w');
  fs.writeSync(fd, [
    'NRRD0004',
    'type: short',
    'dimension: 3',
    'space: left-posterior-superior',
    `sizes: ${nx} ${ny} ${depth}`,
    'space directions: (0.626953,0,0) (0,0.626953,0) (0,0,0.8)',
    'kinds: domain domain domain',
    'endian: little',
    'encoding: raw',
    `space origin: ${src.origin}`,
    '',
    '',
  ].join('\n'));
  for (let k = 0; k < depth; k += 1) {
    // back and forth: 0..nz-1, nz-1..0, ... so that neighbouring slices stay neighbours
    const period = 2 * nz;
    const m = k % period;
    const s = m < nz ? m : period - 1 - m;
    fs.writeSync(fd, src.voxels, s * slice, slice);
  }
  fs.closeSync(fd);
}
const fileBytes = fs.statSync(volumeFile).size;

// The same voxels as a DICOM series: one file per slice, explicit VR little endian, HU stored
// as signed 16-bit pixels (the writer of src/io/dicom/synth.rs, in JavaScript).
function dicomElement(tag, vr, value) {
  let v = Buffer.from(value);
  if (v.length % 2 === 1) v = Buffer.concat([v, Buffer.from([vr === 'UI' || vr === 'OB' ? 0 : 0x20])]);
  const long = ['OB', 'OW', 'SQ', 'UN', 'UT'].includes(vr);
  const head = Buffer.alloc(long ? 12 : 8);
  head.writeUInt16LE(tag[0], 0);
  head.writeUInt16LE(tag[1], 2);
  head.write(vr, 4, 'latin1');
  if (long) head.writeUInt32LE(v.length, 8);
  else head.writeUInt16LE(v.length, 6);
  return Buffer.concat([head, v]);
}
// Everything of one file up to PixelData's value: slice k of the series (its position 0.8 mm
// apart), or with `frames` one multi-frame file of that many frames at the first position
// with SpacingBetweenSlices 0.8 mm. PixelData's header says `pixelBytes`.
function dicomHead(k, origin, pixelBytes, frames = 0) {
  const us = (n) => { const b = Buffer.alloc(2); b.writeUInt16LE(n); return b; };
  const ct = '1.2.840.10008.5.1.4.1.1.2';
  const series = frames ? '2.25.1234567890124' : '2.25.1234567890123';
  const sop = `${series}.${k + 1}`;
  const multi = frames ? [
    dicomElement([0x0018, 0x0050], 'DS', '0.8'),
    dicomElement([0x0018, 0x0088], 'DS', '0.8'),
  ] : [];
  const pixelHead = Buffer.alloc(12);
  pixelHead.writeUInt16LE(0x7fe0, 0);
  pixelHead.writeUInt16LE(0x0010, 2);
  pixelHead.write('OW', 4, 'latin1');
  pixelHead.writeUInt32LE(pixelBytes, 8);
  const data = Buffer.concat([
    dicomElement([0x0008, 0x0016], 'UI', ct),
    dicomElement([0x0008, 0x0018], 'UI', sop),
    dicomElement([0x0008, 0x0060], 'CS', 'CT'),
    dicomElement([0x0010, 0x0010], 'PN', 'Bench^Wholebody'),
    ...multi,
    dicomElement([0x0020, 0x000D], 'UI', '2.25.1234567890'),
    dicomElement([0x0020, 0x000E], 'UI', series),
    dicomElement([0x0020, 0x0013], 'IS', String(k + 1)),
    dicomElement([0x0020, 0x0032], 'DS', `${origin[0]}\\${origin[1]}\\${(origin[2] + 0.8 * k).toFixed(2)}`),
    dicomElement([0x0020, 0x0037], 'DS', '1\\0\\0\\0\\1\\0'),
    dicomElement([0x0028, 0x0002], 'US', us(1)),
    dicomElement([0x0028, 0x0004], 'CS', 'MONOCHROME2'),
    ...(frames ? [dicomElement([0x0028, 0x0008], 'IS', String(frames))] : []),
    dicomElement([0x0028, 0x0010], 'US', us(ny)),
    dicomElement([0x0028, 0x0011], 'US', us(nx)),
    dicomElement([0x0028, 0x0030], 'DS', '0.626953\\0.626953'),
    dicomElement([0x0028, 0x0100], 'US', us(16)),
    dicomElement([0x0028, 0x0101], 'US', us(16)),
    dicomElement([0x0028, 0x0102], 'US', us(15)),
    dicomElement([0x0028, 0x0103], 'US', us(1)),
    dicomElement([0x0028, 0x1052], 'DS', '0'),
    dicomElement([0x0028, 0x1053], 'DS', '1'),
    pixelHead,
  ]);
  const group = Buffer.concat([
    dicomElement([0x0002, 0x0001], 'OB', Buffer.from([0, 1])),
    dicomElement([0x0002, 0x0002], 'UI', ct),
    dicomElement([0x0002, 0x0003], 'UI', sop),
    dicomElement([0x0002, 0x0010], 'UI', '1.2.840.10008.1.2.1'),
  ]);
  const len = Buffer.alloc(4);
  len.writeUInt32LE(group.length);
  return Buffer.concat([Buffer.alloc(128), Buffer.from('DICM'), dicomElement([0x0002, 0x0000], 'UL', len), group, data]);
}
function dicomSlice(k, pixels, origin) {
  return Buffer.concat([dicomHead(k, origin, pixels.length), pixels]);
}
const folder = path.join(tmp, 'wholebody');
if (via === 'folder' || via === 'zip') {
  fs.mkdirSync(folder);
  const origin = (src.origin ?? '(0,0,0)').replace(/[()]/g, '').split(',').map(Number);
  for (let k = 0; k < depth; k += 1) {
    const period = 2 * nz;
    const m = k % period;
    const s = m < nz ? m : period - 1 - m;
    const pixels = src.voxels.subarray(s * slice, (s + 1) * slice);
    fs.writeFileSync(path.join(folder, `IM${String(k + 1).padStart(5, '0')}.dcm`), dicomSlice(k, pixels, origin));
  }
  console.log(`  the same as ${depth} DICOM files in ${folder}`);
}
// The same voxels as one multi-frame DICOM file (frames in z order at 0.8 mm, positions from the
// first frame and the spacing between slices), opened through the file input: the loader reads
// its frames where they lie in the page's bytes and lets each go once decoded.
const multiFrameFile = path.join(tmp, 'wholebody-frames.dcm');
if (via === 'multiframe') {
  const origin = (src.origin ?? '(0,0,0)').replace(/[()]/g, '').split(',').map(Number);
  const fd = fs.openSync(multiFrameFile, 'w');
  fs.writeSync(fd, dicomHead(0, origin, depth * slice, depth));
  for (let k = 0; k < depth; k += 1) {
    const period = 2 * nz;
    const m = k % period;
    const s = m < nz ? m : period - 1 - m;
    fs.writeSync(fd, src.voxels.subarray(s * slice, (s + 1) * slice));
  }
  fs.closeSync(fd);
  console.log(`  the same as one multi-frame DICOM file of ${depth} frames: ${multiFrameFile}`);
}
let zipBytes = null;
if (via === 'zip') {
  zipBytes = zipFolder(folder, 'wholebody');
  console.log(`  zipped: ${(zipBytes.length / 2 ** 20).toFixed(0)} MiB`);
}
console.log(`volume: ${nx} x ${ny} x ${depth} (lung2's ${nz} slices back and forth, 0.8 mm), ${(fileBytes / 2 ** 20).toFixed(0)} MiB raw NRRD`);

// ---- Server ---------------------------------------------------------------------------------

const mime = { '.html': 'text/html; charset=utf-8', '.js': 'text/javascript', '.wasm': 'application/wasm', '.css': 'text/css' };
const server = http.createServer((req, res) => {
  const p = decodeURIComponent(new URL(req.url, 'http://127.0.0.1').pathname);
  if (p === '/gen/wholebody.zip' && zipBytes) {
    res.writeHead(200, { 'content-type': 'application/zip', 'content-length': zipBytes.length });
    res.end(zipBytes);
    return;
  }
  if (p === '/gen/wholebody.nrrd') {
    res.writeHead(200, { 'content-type': 'application/octet-stream', 'content-length': fileBytes });
    fs.createReadStream(volumeFile).pipe(res);
    return;
  }
  const rel = p === '/' ? 'index.html' : p.slice(1);
  const file = path.normalize(path.join(dist, rel));
  if (!file.startsWith(dist) || !fs.existsSync(file) || !fs.statSync(file).isFile()) {
    res.writeHead(404).end('not found');
    return;
  }
  const bytes = fs.readFileSync(file);
  res.writeHead(200, { 'content-type': mime[path.extname(file)] ?? 'application/octet-stream', 'content-length': bytes.length });
  res.end(bytes);
});
await new Promise((r) => server.listen(0, '127.0.0.1', r));
const origin = `http://127.0.0.1:${server.address().port}`;

// ---- Memory of the browser's processes --------------------------------------------------------

function children() {
  const kids = new Map();
  for (const name of fs.readdirSync('/proc')) {
    if (!/^\d+$/.test(name)) continue;
    try {
      const stat = fs.readFileSync(`/proc/${name}/stat`, 'latin1');
      const ppid = Number(stat.slice(stat.lastIndexOf(')') + 2).split(' ')[1]);
      if (!kids.has(ppid)) kids.set(ppid, []);
      kids.get(ppid).push(Number(name));
    } catch { /* gone */ }
  }
  return kids;
}
function kbField(text, name) {
  const m = text.match(new RegExp(`^${name}:\\s+(\\d+) kB`, 'm'));
  return m ? Number(m[1]) * 1024 : 0;
}
function memoryOf(rootPid) {
  const kids = children();
  const todo = [rootPid];
  let pss = 0;
  let largest = { pss: 0, type: '' };
  const byType = {};
  while (todo.length) {
    const pid = todo.pop();
    todo.push(...(kids.get(pid) ?? []));
    try {
      const p = kbField(fs.readFileSync(`/proc/${pid}/smaps_rollup`, 'latin1'), 'Pss');
      pss += p;
      const cmd = fs.readFileSync(`/proc/${pid}/cmdline`, 'latin1');
      const type = cmd.match(/--type=([a-z-]+)/)?.[1] ?? 'browser';
      byType[type] = (byType[type] ?? 0) + p;
      if (p > largest.pss) largest = { pss: p, type };
    } catch { /* gone */ }
  }
  return { pss, largest, byType };
}

// ---- The run -------------------------------------------------------------------------------

// A non-persistent launch: playwright gives the browser a fresh temporary profile.
const server2 = await chromium.launchServer({
  executablePath: chromiumPath,
  headless: true,
  args: [
    '--no-sandbox', '--disable-background-networking', '--disable-component-update', '--disable-sync',
    '--no-first-run', '--disable-quic',
    '--enable-unsafe-webgpu', '--enable-features=Vulkan', '--use-vulkan=swiftshader', '--use-angle=swiftshader',
  ],
});
const browserPid = server2.process().pid;
const browser = await chromium.connect(server2.wsEndpoint());
const page = await browser.newPage({ viewport: { width: 1280, height: 800 } });
page.on('console', (msg) => {
  if (msg.type() === 'error') console.log(`  [page error] ${msg.text().slice(0, 300)}`);
  else if (process.env.BENCH_LOG && msg.text().includes(process.env.BENCH_LOG)) console.log(`  [page] ${msg.text().slice(0, 400)}`);
});
page.on('pageerror', (err) => console.log(`  [page exception] ${err}`));
// The wasm memory, caught as the module is instantiated (any build, no app support needed).
await page.addInitScript(() => {
  for (const name of ['instantiateStreaming', 'instantiate']) {
    const orig = WebAssembly[name];
    WebAssembly[name] = async (...a) => {
      const r = await orig.apply(WebAssembly, a);
      const exports = (r.instance ?? r).exports;
      if (exports?.memory) window.__wasmMemory = exports.memory;
      return r;
    };
  }
});
// The viewer's frame intervals, seen from the page: a 10 ms timer notes when the status's
// frame count moves (the main thread is free while the GPU works), with the features' state.
await page.addInitScript(() => {
  const log = [];
  window.__frameLog = log;
  let last = -1;
  setInterval(() => {
    const s = window.shapecastStatus;
    if (s && s.frames !== last) {
      last = s.frames;
      log.push([performance.now(), s.frames, s.features?.state ?? null, s.features?.fraction ?? 0]);
    }
  }, 10);
});

const t0 = Date.now();
const at = () => (Date.now() - t0) / 1000;
let peak = { pss: 0, at: 0, largest: null };
const samples = [];
const typePeaks = {};
const sampler = setInterval(() => {
  const m = memoryOf(browserPid);
  samples.push([at(), m.pss]);
  // BENCH_TRACE=1: each second's memory by process type (where a peak comes from).
  if (process.env.BENCH_TRACE && samples.length % 4 === 0) {
    console.log(`  [memory ${at().toFixed(1)} s] ${Object.entries(m.byType).map(([k, v]) => `${k} ${(v / 1e9).toFixed(2)}`).join(', ')}`);
  }
  for (const [k, v] of Object.entries(m.byType)) typePeaks[k] = Math.max(typePeaks[k] ?? 0, v);
  if (m.pss > peak.pss) peak = { pss: m.pss, at: at(), largest: m.largest, byType: m.byType };
}, 250);

if (via === 'link' || via === 'zip') {
  const file = via === 'zip' ? '/gen/wholebody.zip' : '/gen/wholebody.nrrd';
  await page.goto(`${origin}/?url=${encodeURIComponent(file)}&method=${encodeURIComponent(method)}`, { waitUntil: 'commit' });
  console.log(`  ${at().toFixed(1)} s: page requested`);
} else {
  // A small phantom first (not the demo CT and its features); the file replaces it.
  await page.goto(`${origin}/?phantom=sphere&method=${encodeURIComponent(method)}`);
  await page.waitForFunction(() => window.shapecastStatus?.volume, null, { timeout: 120000 });
  if (via === 'folder') await page.setInputFiles('#shapecast_open_folder', folder);
  else if (via === 'multiframe') await page.setInputFiles('#shapecast_open_files', multiFrameFile);
  else await page.setInputFiles('#shapecast_open_files', volumeFile);
  console.log(`  ${at().toFixed(1)} s: file chosen`);
}
let wasmPeak = 0;
let wasmAtLoad = null;
let memoryAtLoad = null;
const events = {};
let last = null;
let error = null;
let lastPrint = 0;
const deadline = t0 + timeoutS * 1000;
for (;;) {
  const s = await page.evaluate(() => {
    const st = window.shapecastStatus;
    return st ? { ...st, wasm_bytes: window.__wasmMemory?.buffer.byteLength ?? 0 } : null;
  }).catch(() => null);
  if (s) wasmPeak = Math.max(wasmPeak, s.wasm_bytes);
  if (Date.now() - lastPrint > 10000) {
    lastPrint = Date.now();
    const f = s?.features;
    console.log(`  ${at().toFixed(0)} s: ${s?.phase ?? 'no status'}${s?.task ? ` (${s.task})` : ''}, frames ${s?.frames ?? 0}`
      + `${f ? `, features ${f.method} ${f.state} ${(f.fraction * 100).toFixed(0)}%` : ''}, PSS ${(memoryOf(browserPid).pss / 1e9).toFixed(2)} GB`);
  }
  if (s) {
    last = s;
    const ours = s.volume && s.volume.dims[2] === depth;
    if (ours && events.loaded === undefined) {
      events.loaded = at();
      wasmAtLoad = s.wasm_bytes;
      memoryAtLoad = memoryOf(browserPid);
    }
    if (ours && s.frames > 0 && events.first_frame === undefined) events.first_frame = at();
    if (loadOnly && events.first_frame !== undefined && at() > events.first_frame + settleS) break;
    const f = s.features;
    if (f && f.state === 'running' && events.features_started === undefined) events.features_started = at();
    if (f && f.state === 'done' && events.features_done === undefined) {
      events.features_done = at();
      events.frames_at_features_done = s.frames;
    }
    if (s.phase === 'error') {
      error = s.error;
      break;
    }
    if (events.features_done !== undefined && s.frames >= events.frames_at_features_done + 30) break;
    if (!loadOnly && f && (f.state === 'failed' || f.state === 'none') && events.first_frame !== undefined && at() > events.first_frame + 20) {
      error = `features ${f.state}: ${s.error ?? s.notice ?? ''}`;
      break;
    }
  }
  if (Date.now() > deadline) {
    error = `timed out after ${timeoutS} s (features ${last?.features?.state} ${((last?.features?.fraction ?? 0) * 100).toFixed(1)}%)`;
    break;
  }
  await new Promise((r) => setTimeout(r, 200));
}
const end = memoryOf(browserPid);
clearInterval(sampler);
// Frame intervals while the feature job ran (an interval spanning k frames counts as k equal ones).
const frameLog = await page.evaluate(() => window.__frameLog).catch(() => []);
const jobIntervals = [];
for (let i = 1; i < frameLog.length; i += 1) {
  const [t0f, f0, state0] = frameLog[i - 1];
  const [t1f, f1] = frameLog[i];
  if (state0 !== 'running' || f1 <= f0) continue;
  for (let k = 0; k < f1 - f0; k += 1) jobIntervals.push((t1f - t0f) / (f1 - f0) / 1000);
}
jobIntervals.sort((a, b) => a - b);
const q = (p) => (jobIntervals.length ? jobIntervals[Math.min(jobIntervals.length - 1, Math.floor(p * jobIntervals.length))] : null);
const frameStats = {
  frames: jobIntervals.length,
  median_s: q(0.5),
  p95_s: q(0.95),
  max_s: jobIntervals.length ? jobIntervals[jobIntervals.length - 1] : null,
  over_1s: jobIntervals.filter((x) => x > 1).length,
};
const shot = path.join(outDir, `bench-${depth}.png`);
await page.screenshot({ path: shot }).catch(() => {});
await browser.close();
await server2.close();
server.close();
fs.rmSync(tmp, { recursive: true, force: true });

const gb = (b) => (b / 1e9).toFixed(2);
const result = {
  dims: [nx, ny, depth],
  voxel_bytes: nx * ny * depth * 2,
  adapter: last?.adapter?.name ?? null,
  method: last?.features?.method ?? null,
  preset: last?.features?.preset ?? null,
  events_s: events,
  peak_pss_bytes: peak.pss,
  peak_at_s: peak.at,
  peak_largest_process: peak.largest,
  peak_by_process_type: peak.byType,
  peak_of_each_process_type: typePeaks,
  pss_at_load_by_process_type: memoryAtLoad?.byType ?? null,
  end_pss_bytes: end.pss,
  via,
  wasm_memory_bytes_at_load: wasmAtLoad,
  wasm_memory_bytes_peak: wasmPeak,
  notice: last?.notice ?? null,
  features_fraction_at_end: last?.features?.fraction ?? null,
  frames_while_job_ran: frameStats,
  error,
  memory_samples: samples.filter((_, i) => i % 4 === 0),
};
fs.writeFileSync(jsonOut ?? path.join(outDir, `bench-${depth}.json`), JSON.stringify(result, null, 1));
console.log(`adapter: ${result.adapter}`);
console.log(`loaded (download + read): ${events.loaded?.toFixed(1)} s`);
console.log(`first MIP frame: ${events.first_frame?.toFixed(1)} s`);
console.log(`features (${result.method}, ${result.preset}): started ${events.features_started?.toFixed(1)} s, done ${events.features_done?.toFixed(1)} s`);
console.log(`memory of the browser's processes (PSS): peak ${gb(peak.pss)} GB at ${peak.at.toFixed(0)} s (largest: ${peak.largest?.type} ${gb(peak.largest?.pss ?? 0)} GB), at the end ${gb(end.pss)} GB; voxels ${gb(result.voxel_bytes)} GB`);
const types = (m) => Object.entries(m ?? {}).map(([t, b]) => `${t} ${gb(b)}`).join(', ');
console.log(`each process type's own peak: ${types(typePeaks)}`);
console.log(`by process: when loaded ${types(memoryAtLoad?.byType)}; at the peak ${types(peak.byType)}; at the end ${types(end.byType)}`);
console.log(`wasm memory (its high-water mark): ${gb(wasmAtLoad ?? 0)} GB when loaded, ${gb(wasmPeak)} GB at most; opened by ${via}`);
console.log(`frames while the job ran: ${frameStats.frames}, interval median ${frameStats.median_s?.toFixed(2)} s, 95th percentile ${frameStats.p95_s?.toFixed(2)} s, max ${frameStats.max_s?.toFixed(2)} s, ${frameStats.over_1s} over 1 s; features at the end ${((last?.features?.fraction ?? 0) * 100).toFixed(1)}%`);
if (result.notice) console.log(`notice: ${result.notice}`);
console.log(`screenshot: ${shot}`);
if (error) {
  console.log(`FAIL: ${error}`);
  process.exit(1);
}
