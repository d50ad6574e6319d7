// Starts the app: imports the wasm-bindgen module trunk built and runs it. Trunk writes the
// (content-hashed) file names into this script tag's data attributes (Trunk.toml's
// `pattern_script`), so no inline script is needed and the page's Content-Security-Policy holds
// no hash that changes with every build. A program that cannot be loaded or started is reported
// in plain words (window.shapecastFail, web/index.html) instead of leaving "Loading…" on screen.
const tag = document.getElementById('shapecast_start');
try {
  const js = new URL(tag.dataset.js, document.baseURI).href;
  const wasm = new URL(tag.dataset.wasm, document.baseURI).href;
  const { default: init } = await import(js);
  await init({ module_or_path: wasm });
} catch (e) {
  const detail = e && e.message ? e.message : String(e);
  window.shapecastFail?.('Shapecast could not start',
    `Its program did not load or stopped while starting: ${detail}`, true);
}
