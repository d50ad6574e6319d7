//! The web page's entry point (wasm only): checks for WebGPU, starts eframe on the canvas, and
//! replaces the canvas by a plain message when the browser cannot run the app: no WebGPU, a page
//! served over plain http (browsers offer WebGPU only to secure pages), or a panic.

use wasm_bindgen::JsCast as _;
use wasm_bindgen::JsValue;

use crate::status::{AppStatus, Phase};

const NO_WEBGPU: &str = "<h2>Shapecast needs WebGPU</h2>\
<p>This browser does not offer WebGPU, which Shapecast uses to compute and project the shape \
features on your graphics card. Nothing was sent anywhere.</p>\
<p>WebGPU works in current <b>Chrome</b> and <b>Edge</b> (version 113 or later) on Windows, macOS \
and ChromeOS, and on Linux with <code>chrome://flags/#enable-unsafe-webgpu</code> enabled; in \
<b>Safari</b> 26 or later; and in <b>Firefox</b> 141 or later on Windows (on other systems set \
<code>dom.webgpu.enabled</code> in <code>about:config</code>). Hospital browsers with hardware \
acceleration switched off in their policy cannot run it.</p>";

const NOT_SECURE: &str = "<h2>Shapecast needs an HTTPS address</h2>\
<p>This page was opened over plain <code>http</code> from another computer. Browsers offer WebGPU, \
which Shapecast uses to compute and project the shape features on your graphics card, only to \
pages served over <b>HTTPS</b> (or from this computer itself, <code>localhost</code>). Nothing was \
sent anywhere.</p>\
<p>Open the page by its <code>https://</code> address, or ask whoever hosts it to serve it over \
HTTPS (README, \"Deploy\").</p>";

/// Starts the app on the page's `<canvas id="shapecast_canvas">`.
pub fn start() {
    // A panic stops the app for good (the wasm instance is poisoned): say so on the page rather
    // than leave a frozen canvas. eframe's own hook (installed when its runner starts) logs it
    // to the console and then calls this one.
    std::panic::set_hook(Box::new(|info| {
        let message = info
            .payload()
            .downcast_ref::<&str>()
            .map(|s| (*s).to_owned())
            .or_else(|| info.payload().downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "unknown".to_owned());
        let place = info
            .location()
            .map(|l| format!(" at {}:{}", l.file(), l.line()))
            .unwrap_or_default();
        log::error!("panic: {message}{place}");
        show_message(&format!(
            "<h2>Shapecast stopped after an internal error</h2><p>{}</p>\
             <p>Reload the page to start again. Nothing was sent anywhere; please report the \
             message above with what you were doing.</p>",
            html_escape(&format!("{message}{place}"))
        ));
        publish_error(&format!("internal error (panic): {message}{place}"));
    }));
    eframe::WebLogger::init(log::LevelFilter::Info).ok();
    wasm_bindgen_futures::spawn_local(async {
        if let Err(message) = run().await {
            fail(&message);
        }
    });
}

async fn run() -> Result<(), String> {
    let window = web_sys::window().ok_or("no window object")?;
    let document = window.document().ok_or("no document object")?;
    let gpu = js_sys::Reflect::get(&window.navigator(), &JsValue::from_str("gpu"))
        .unwrap_or(JsValue::UNDEFINED);
    if (gpu.is_undefined() || gpu.is_null()) && !window.is_secure_context() {
        show_message(NOT_SECURE);
        publish_error(
            "WebGPU needs a secure page: this one was served over plain http (use https://)",
        );
        return Ok(());
    }
    if gpu.is_undefined() || gpu.is_null() {
        show_message(NO_WEBGPU);
        publish_error("this browser has no WebGPU (navigator.gpu is missing)");
        return Ok(());
    }
    match browser_adapter(&gpu).await {
        Some(name) => crate::gpu::context::set_browser_adapter_name(name),
        None => {
            show_message(&format!(
                "{NO_WEBGPU}<p>Details: this browser has WebGPU but gave no graphics adapter \
                 (hardware acceleration may be switched off).</p>"
            ));
            publish_error("WebGPU is present but navigator.gpu.requestAdapter() gave no adapter");
            return Ok(());
        }
    }
    let canvas = document
        .get_element_by_id("shapecast_canvas")
        .ok_or("the page has no element with id shapecast_canvas")?
        .dyn_into::<web_sys::HtmlCanvasElement>()
        .map_err(|_| "shapecast_canvas is not a canvas")?;
    let options = eframe::WebOptions {
        wgpu_options: crate::app::wgpu_options(),
        ..Default::default()
    };
    let started = eframe::WebRunner::new()
        .start(
            canvas,
            options,
            Box::new(|cc| Ok(Box::new(crate::app::ShapecastApp::new(cc)))),
        )
        .await;
    match started {
        Ok(()) => hide("loading"),
        Err(e) => {
            let detail = e.as_string().unwrap_or_else(|| format!("{e:?}"));
            show_message(&format!(
                "{NO_WEBGPU}<p>Details: the graphics adapter could not be started: {}</p>",
                html_escape(&detail)
            ));
            publish_error(&format!("WebGPU could not be started: {detail}"));
        }
    }
    Ok(())
}

/// Asks `navigator.gpu` for an adapter and describes it, or `None` when it gives none.
async fn browser_adapter(gpu: &JsValue) -> Option<String> {
    let get = |obj: &JsValue, key: &str| {
        js_sys::Reflect::get(obj, &JsValue::from_str(key)).unwrap_or(JsValue::UNDEFINED)
    };
    let request = get(gpu, "requestAdapter")
        .dyn_into::<js_sys::Function>()
        .ok()?;
    let promise = request
        .call0(gpu)
        .ok()?
        .dyn_into::<js_sys::Promise>()
        .ok()?;
    let adapter = wasm_bindgen_futures::JsFuture::from(promise).await.ok()?;
    if adapter.is_null() || adapter.is_undefined() {
        return None;
    }
    let info = get(&adapter, "info");
    let parts: Vec<String> = ["vendor", "architecture", "description"]
        .iter()
        .filter_map(|k| get(&info, k).as_string())
        .filter(|s| !s.is_empty())
        .collect();
    let fallback = get(&info, "isFallbackAdapter").as_bool() == Some(true);
    let mut name = if parts.is_empty() {
        "WebGPU adapter".to_owned()
    } else {
        parts.join(" ")
    };
    if fallback {
        name.push_str(" (software fallback)");
    }
    Some(name)
}

fn fail(message: &str) {
    show_message(&format!(
        "<h2>Shapecast could not start</h2><p>{}</p>",
        html_escape(message)
    ));
    publish_error(message);
}

fn publish_error(message: &str) {
    let status = AppStatus {
        phase: Phase::Error,
        error: Some(message.to_owned()),
        ..Default::default()
    };
    status.publish();
}

fn hide(id: &str) {
    if let Some(e) = web_sys::window()
        .and_then(|w| w.document())
        .and_then(|d| d.get_element_by_id(id))
    {
        let _ = e.set_attribute("hidden", "");
    }
}

/// Hides the canvas and shows `html` in the page's message box.
fn show_message(html: &str) {
    let Some(document) = web_sys::window().and_then(|w| w.document()) else {
        return;
    };
    if let Some(canvas) = document.get_element_by_id("shapecast_canvas") {
        let _ = canvas.set_attribute("hidden", "");
    }
    if let Some(loading) = document.get_element_by_id("loading") {
        let _ = loading.set_attribute("hidden", "");
    }
    if let Some(message) = document.get_element_by_id("message") {
        message.set_inner_html(html);
        let _ = message.remove_attribute("hidden");
    }
}

fn html_escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}
