//! Files in the browser (wasm only): drag and drop of files and folders, the page's two file
//! inputs (files, and a folder with `webkitdirectory`), fetching the demo CT, and the page's
//! address (query parameters, the link fragment). Downloads by URL are `web_fetch`. Everything is
//! asynchronous (promises awaited with `spawn_local`); results are queued as [`WebEvent`]s that
//! the app takes once per frame, so nothing ever blocks the page.
//!
//! eframe's own drop handling is bypassed: it does not walk folders. Our listeners sit on the
//! window in the capture phase and stop the drag events there, walk dropped folders with
//! `webkitGetAsEntry` and `FileSystemDirectoryReader`, and read every file through its stream
//! (`Blob.stream()`, gathered into buffers of up to 16 MiB) or, a DICOM image, whole. A file's
//! bytes stay JavaScript's (`JsBytes`) and the loader reads them on demand, letting each buffer
//! go once read; a DICOM set is decoded file by file as it is read.

mod read;

use std::cell::RefCell;

use wasm_bindgen::JsCast as _;
use wasm_bindgen::JsValue;
use wasm_bindgen::closure::Closure;
use wasm_bindgen_futures::JsFuture;

use crate::app::error::{PageError, PlatformError};
use crate::app::platform::web::js_bytes::{self, JsBytes};
use crate::app::view_link::ViewSource;
use crate::io::InputFile;
use crate::io::js::error_text as js_error;

use crate::app::platform::web::events::{WebEvent, push};
use read::{SeriesFor, read_all, read_series};

/// The page's hidden file inputs (web/index.html).
pub const OPEN_FILES_INPUT: &str = "shapecast_open_files";
pub const OPEN_FOLDER_INPUT: &str = "shapecast_open_folder";

thread_local! {
    static HOVERING: RefCell<bool> = const { RefCell::new(false) };
}

fn set_hover(on: bool) {
    let changed = HOVERING.with(|h| std::mem::replace(&mut *h.borrow_mut(), on) != on);
    if changed {
        push(WebEvent::Hover(on));
    }
}

/// Installs the drag-and-drop listeners and the file inputs' change listeners (once).
pub fn install(ctx: &egui::Context) -> Result<(), PlatformError> {
    crate::app::platform::web::events::set_context(ctx);
    let unavailable = |words: &str| PlatformError::DropUnavailable(words.to_owned());
    let window = web_sys::window().ok_or_else(|| unavailable("no window object"))?;
    let document = window
        .document()
        .ok_or_else(|| unavailable("no document object"))?;

    let over = Closure::<dyn FnMut(web_sys::DragEvent)>::new(|event: web_sys::DragEvent| {
        event.prevent_default();
        event.stop_propagation();
        if let Some(dt) = event.data_transfer() {
            dt.set_drop_effect("copy");
        }
        set_hover(true);
    });
    for name in ["dragenter", "dragover"] {
        window
            .add_event_listener_with_callback_and_bool(name, over.as_ref().unchecked_ref(), true)
            .map_err(|e| unavailable(&js_error(&e)))?;
    }
    over.forget();

    let leave = Closure::<dyn FnMut(web_sys::DragEvent)>::new(|event: web_sys::DragEvent| {
        event.prevent_default();
        event.stop_propagation();
        // Leaving one element for another inside the page has a related target.
        if event.related_target().is_none() {
            set_hover(false);
        }
    });
    window
        .add_event_listener_with_callback_and_bool(
            "dragleave",
            leave.as_ref().unchecked_ref(),
            true,
        )
        .map_err(|e| unavailable(&js_error(&e)))?;
    leave.forget();

    let drop = Closure::<dyn FnMut(web_sys::DragEvent)>::new(|event: web_sys::DragEvent| {
        event.prevent_default();
        event.stop_propagation();
        set_hover(false);
        if let Some(dt) = event.data_transfer() {
            on_drop(&dt);
        }
    });
    window
        .add_event_listener_with_callback_and_bool("drop", drop.as_ref().unchecked_ref(), true)
        .map_err(|e| unavailable(&js_error(&e)))?;
    drop.forget();

    // A link pasted into the address bar of an open page changes only the fragment, which does
    // not reload the page: the app opens the link's volume (keeping the one shown until it
    // arrives) or, for the volume shown, changes the view in place.
    let link = Closure::<dyn FnMut(web_sys::Event)>::new(|_event: web_sys::Event| {
        push(WebEvent::Link {
            fragment: fragment(),
        });
    });
    window
        .add_event_listener_with_callback("hashchange", link.as_ref().unchecked_ref())
        .map_err(|e| unavailable(&js_error(&e)))?;
    link.forget();

    crate::app::platform::web::fetch::install();

    for id in [OPEN_FILES_INPUT, OPEN_FOLDER_INPUT] {
        let Some(input) = document
            .get_element_by_id(id)
            .and_then(|e| e.dyn_into::<web_sys::HtmlInputElement>().ok())
        else {
            log::warn!("the page has no <input id={id}>: its Open button will do nothing");
            continue;
        };
        let target = input.clone();
        let change = Closure::<dyn FnMut(web_sys::Event)>::new(move |_event: web_sys::Event| {
            let files = file_list(target.files());
            // Clear it so that choosing the same file again fires `change` again.
            target.set_value("");
            if !files.is_empty() {
                crate::app::platform::web::fetch::cancel();
                wasm_bindgen_futures::spawn_local(read_all(files));
            }
        });
        input
            .add_event_listener_with_callback("change", change.as_ref().unchecked_ref())
            .map_err(|e| unavailable(&js_error(&e)))?;
        change.forget();
    }
    Ok(())
}

/// Opens the browser's file chooser (files, or a folder). Browsers allow it only shortly after a
/// user gesture, which a click on the app's button is.
pub fn open_dialog(folder: bool) {
    let id = if folder {
        OPEN_FOLDER_INPUT
    } else {
        OPEN_FILES_INPUT
    };
    if let Some(input) = web_sys::window()
        .and_then(|w| w.document())
        .and_then(|d| d.get_element_by_id(id))
        .and_then(|e| e.dyn_into::<web_sys::HtmlElement>().ok())
    {
        input.click();
    }
}

/// A file with the path the user sees (relative path inside a dropped or chosen folder).
struct Named {
    name: String,
    file: web_sys::File,
}

fn file_list(list: Option<web_sys::FileList>) -> Vec<Named> {
    let Some(list) = list else {
        return Vec::new();
    };
    (0..list.length())
        .filter_map(|i| list.get(i))
        .map(|file| {
            let relative = js_sys::Reflect::get(&file, &JsValue::from_str("webkitRelativePath"))
                .ok()
                .and_then(|v| v.as_string())
                .filter(|s| !s.is_empty());
            Named {
                name: relative.unwrap_or_else(|| file.name()),
                file,
            }
        })
        .collect()
}

/// Takes what was dropped. Entries must be taken while the event is being handled; reading
/// them happens afterwards.
fn on_drop(dt: &web_sys::DataTransfer) {
    let items = dt.items();
    let mut entries = Vec::new();
    let mut plain = Vec::new();
    for i in 0..items.length() {
        let Some(item) = items.get(i) else { continue };
        if item.kind() != "file" {
            continue;
        }
        match item.webkit_get_as_entry() {
            Ok(Some(entry)) => entries.push(entry),
            _ => {
                if let Ok(Some(file)) = item.get_as_file() {
                    plain.push(Named {
                        name: file.name(),
                        file,
                    });
                }
            }
        }
    }
    if entries.is_empty() && plain.is_empty() {
        plain = file_list(dt.files());
    }
    if entries.is_empty() && plain.is_empty() {
        return;
    }
    // A new drop replaces a download in progress.
    crate::app::platform::web::fetch::cancel();
    wasm_bindgen_futures::spawn_local(async move {
        let label = drop_label(&entries, &plain);
        push(WebEvent::Progress {
            verb: "reading",
            label: label.clone(),
            done: 0.0,
            total: 0.0,
        });
        match walk(entries).await {
            Ok(mut files) => {
                files.extend(plain);
                if files.is_empty() {
                    push(WebEvent::Failed {
                        error: PageError::EmptyDrop { label }.into(),
                    });
                } else {
                    read_all(files).await;
                }
            }
            Err(e) => push(WebEvent::Failed { error: e.into() }),
        }
    });
}

fn drop_label(entries: &[web_sys::FileSystemEntry], plain: &[Named]) -> String {
    match (entries, plain) {
        ([one], []) => one.name(),
        ([], [one]) => one.name.clone(),
        _ => format!("{} dropped items", entries.len() + plain.len()),
    }
}

/// Files under the dropped entries (folders walked depth first, hidden entries skipped).
async fn walk(entries: Vec<web_sys::FileSystemEntry>) -> Result<Vec<Named>, PageError> {
    let mut out = Vec::new();
    let mut stack: Vec<web_sys::FileSystemEntry> = entries.into_iter().rev().collect();
    while let Some(entry) = stack.pop() {
        if entry.name().starts_with('.') {
            continue;
        }
        let path = entry.full_path();
        let name = path.trim_start_matches('/').to_owned();
        if entry.is_file() {
            let fe: web_sys::FileSystemFileEntry = entry.unchecked_into();
            let promise = js_sys::Promise::new(&mut |resolve, reject| {
                fe.file_with_callback_and_callback(&resolve, &reject);
            });
            let file = JsFuture::from(promise)
                .await
                .map_err(|e| PageError::CannotOpen {
                    file: name.clone(),
                    words: js_error(&e),
                })?;
            out.push(Named {
                name,
                file: file.unchecked_into(),
            });
        } else if entry.is_directory() {
            let dir: web_sys::FileSystemDirectoryEntry = entry.unchecked_into();
            let reader = dir.create_reader();
            let mut children = Vec::new();
            // readEntries returns the entries in batches until an empty one.
            loop {
                let promise = js_sys::Promise::new(&mut |resolve, reject| {
                    if let Err(e) =
                        reader.read_entries_with_callback_and_callback(&resolve, &reject)
                    {
                        let _ = reject.call1(&JsValue::NULL, &e);
                    }
                });
                let batch = JsFuture::from(promise)
                    .await
                    .map_err(|e| PageError::CannotList {
                        folder: name.clone(),
                        words: js_error(&e),
                    })?;
                let batch: js_sys::Array = batch.unchecked_into();
                if batch.length() == 0 {
                    break;
                }
                children.extend(
                    batch
                        .iter()
                        .map(|e| e.unchecked_into::<web_sys::FileSystemEntry>()),
                );
            }
            children.sort_by_key(|e| e.name());
            stack.extend(children.into_iter().rev());
        }
    }
    Ok(out)
}

/// Loads the chosen series of a set of the page's files (a click in the series list): its
/// files read again one at a time and decoded as they come.
pub fn load_series(set: crate::app::load::SeriesSet) {
    wasm_bindgen_futures::spawn_local(read_series(set, SeriesFor::Shown(None)));
}

/// Loads the PET series of a set of the page's files, for the CT of `generation`.
pub fn load_pet_series(set: crate::app::load::SeriesSet, generation: u64) {
    wasm_bindgen_futures::spawn_local(read_series(set, SeriesFor::Pet(generation)));
}

/// Fetches the demo CT (a static file next to the page).
pub fn fetch_demo() {
    wasm_bindgen_futures::spawn_local(async {
        let label = "demo CT".to_owned();
        push(WebEvent::Progress {
            verb: "reading",
            label: label.clone(),
            done: 0.0,
            total: 0.0,
        });
        match fetch_bytes(crate::app::demo::DEMO_URL).await {
            Ok(bytes) => push(WebEvent::Files {
                label,
                files: vec![InputFile::new(crate::app::demo::DEMO_FILE, bytes)],
                origin: ViewSource::Demo,
            }),
            Err(e) => push(WebEvent::Failed { error: e.into() }),
        }
    });
}

/// The demo's bytes.
async fn fetch_bytes(url: &str) -> Result<Vec<u8>, PageError> {
    let fail = |words: String| PageError::Demo {
        url: url.to_owned(),
        words,
    };
    let window = web_sys::window().ok_or_else(|| fail("no window object".to_owned()))?;
    let response = JsFuture::from(window.fetch_with_str(url))
        .await
        .map_err(|e| fail(js_error(&e)))?;
    let response: web_sys::Response = response.unchecked_into();
    if !response.ok() {
        return Err(fail(format!("HTTP {}", response.status())));
    }
    let buffer = JsFuture::from(response.array_buffer().map_err(|e| fail(js_error(&e)))?)
        .await
        .map_err(|e| fail(js_error(&e)))?;
    Ok(js_sys::Uint8Array::new(&buffer).to_vec())
}

/// The parameters of the page's URL (`?phantom=sphere&method=li&url=a%20b.nii`), decoded, in
/// order (repeated ones kept).
pub fn query_params() -> Vec<(String, String)> {
    let search = web_sys::window()
        .and_then(|w| w.location().search().ok())
        .unwrap_or_default();
    crate::io::url::parse_params(&search)
}

/// The page's fragment (a shared view), with its `#`.
pub fn fragment() -> String {
    web_sys::window()
        .and_then(|w| w.location().hash().ok())
        .unwrap_or_default()
}

/// A URL as the page resolves it (relative ones against the page's address).
pub fn absolute_url(url: &str) -> String {
    let base = web_sys::window()
        .and_then(|w| w.location().href().ok())
        .unwrap_or_default();
    web_sys::Url::new_with_base(url, &base)
        .map(|u| u.href())
        .unwrap_or_else(|_| url.to_owned())
}
