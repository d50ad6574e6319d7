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

use std::cell::RefCell;
use std::collections::VecDeque;

use wasm_bindgen::JsCast as _;
use wasm_bindgen::JsValue;
use wasm_bindgen::closure::Closure;
use wasm_bindgen_futures::JsFuture;

use super::js_bytes::{self, JsBytes};
use super::view_link::ViewSource;
use crate::io::InputFile;

/// The page's hidden file inputs (web/index.html).
pub const OPEN_FILES_INPUT: &str = "shapecast_open_files";
pub const OPEN_FOLDER_INPUT: &str = "shapecast_open_folder";

/// What happened outside the app's frame loop.
pub enum WebEvent {
    /// Files are dragged over the page (true) or not any more (false).
    Hover(bool),
    /// `verb` ("reading", "downloading") `label`: `done` of `total` bytes (`total` 0 while
    /// unknown).
    Progress {
        verb: &'static str,
        label: String,
        done: f64,
        total: f64,
    },
    /// All files of one drop, one input selection, one download or the demo, read; `origin` is
    /// how a link names them.
    Files {
        label: String,
        files: Vec<InputFile>,
        origin: ViewSource,
    },
    /// A DICOM set decoded as it was read (`FolderReader`): the volume, and the series list
    /// when the files held several. `origin` is how a link names the files (`None` for another
    /// series of the set shown: its origin stays).
    Loaded {
        loaded: Box<crate::io::Loaded>,
        series: Option<super::load::SeriesSet>,
        origin: Option<ViewSource>,
    },
    /// The PET series of a PET/CT study's files, read for the CT of `generation`.
    PetLoaded {
        loaded: Box<crate::io::Loaded>,
        generation: u64,
    },
    /// Reading the PET series failed; the CT shown stays, without it.
    PetFailed { message: String, generation: u64 },
    /// The files of a PET/CT link's PET (`&pet=URL`), downloaded for the CT of `generation`.
    PetFiles {
        label: String,
        files: Vec<InputFile>,
        generation: u64,
    },
    /// Reading failed; the message names the file.
    Failed { message: String },
    /// The user cancelled a download.
    Cancelled { label: String },
    /// A link was pasted into the address bar of the open page (only its fragment changed).
    Link { fragment: String },
}

thread_local! {
    static INBOX: RefCell<VecDeque<WebEvent>> = const { RefCell::new(VecDeque::new()) };
    static CONTEXT: RefCell<Option<egui::Context>> = const { RefCell::new(None) };
    static HOVERING: RefCell<bool> = const { RefCell::new(false) };
}

pub(super) fn push(event: WebEvent) {
    INBOX.with(|q| q.borrow_mut().push_back(event));
    CONTEXT.with(|c| {
        if let Some(ctx) = c.borrow().as_ref() {
            ctx.request_repaint();
        }
    });
}

fn set_hover(on: bool) {
    let changed = HOVERING.with(|h| std::mem::replace(&mut *h.borrow_mut(), on) != on);
    if changed {
        push(WebEvent::Hover(on));
    }
}

/// The events since the last call.
pub fn take_events() -> Vec<WebEvent> {
    INBOX.with(|q| q.borrow_mut().drain(..).collect())
}

pub(super) fn js_error(e: &JsValue) -> String {
    e.as_string()
        .or_else(|| {
            js_sys::Reflect::get(e, &JsValue::from_str("message"))
                .ok()
                .and_then(|m| m.as_string())
        })
        .unwrap_or_else(|| format!("{e:?}"))
}

/// Installs the drag-and-drop listeners and the file inputs' change listeners (once).
pub fn install(ctx: &egui::Context) -> Result<(), String> {
    CONTEXT.with(|c| *c.borrow_mut() = Some(ctx.clone()));
    let window = web_sys::window().ok_or("no window object")?;
    let document = window.document().ok_or("no document object")?;

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
            .map_err(|e| js_error(&e))?;
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
        .map_err(|e| js_error(&e))?;
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
        .map_err(|e| js_error(&e))?;
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
        .map_err(|e| js_error(&e))?;
    link.forget();

    super::web_fetch::install();

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
                super::web_fetch::cancel();
                wasm_bindgen_futures::spawn_local(read_all(files));
            }
        });
        input
            .add_event_listener_with_callback("change", change.as_ref().unchecked_ref())
            .map_err(|e| js_error(&e))?;
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
    super::web_fetch::cancel();
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
                        message: format!("{label}: the dropped folder holds no files"),
                    });
                } else {
                    read_all(files).await;
                }
            }
            Err(message) => push(WebEvent::Failed { message }),
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
async fn walk(entries: Vec<web_sys::FileSystemEntry>) -> Result<Vec<Named>, String> {
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
                .map_err(|e| format!("{name}: cannot open: {}", js_error(&e)))?;
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
                    .map_err(|e| format!("{name}: cannot list the folder: {}", js_error(&e)))?;
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

/// Why a file could not be read, naming it.
fn cannot_read(f: &Named, e: &JsValue) -> String {
    format!("{}: cannot read: {}", f.name, js_error(e))
}

/// A blob's bytes as JavaScript holds them (not copied into the wasm memory). A blob of 4 GiB
/// or more is refused: a `Uint8Array`'s length is 32-bit here, and the page's limits (1.5 GiB
/// of voxels, 2 GiB per decompression) hold less anyway.
async fn read_js(f: &Named, blob: &web_sys::Blob) -> Result<js_sys::Uint8Array, String> {
    too_large(f, blob.size())?;
    match JsFuture::from(blob.array_buffer()).await {
        Ok(buffer) => Ok(js_sys::Uint8Array::new(&buffer)),
        Err(e) => Err(cannot_read(f, &e)),
    }
}

/// Refuses a file or blob of 4 GiB or more ([`read_js`]).
fn too_large(f: &Named, size: f64) -> Result<(), String> {
    if size > f64::from(u32::MAX) {
        return Err(format!(
            "{}: {:.1} GB is more than a browser tab can read as one file (4 GiB at most)",
            f.name,
            size / 1e9
        ));
    }
    Ok(())
}

/// A file's bytes as JavaScript chunks, read through its stream (`Blob.stream()`) and gathered
/// into 16 MiB buffers (`js_bytes::Gathered`, as a download is), which the loader lets go one
/// by one as it reads them into the voxels (`io::FileSource::release_before`); progress is
/// reported as `done` (bytes of the files before this one) + this file's of `total`.
async fn read_chunked(f: &Named, label: &str, done: f64, total: f64) -> Result<JsBytes, String> {
    too_large(f, f.file.size())?;
    let reader: web_sys::ReadableStreamDefaultReader =
        f.file.stream().get_reader().unchecked_into();
    let mut bytes = js_bytes::Gathered::default();
    let mut reported = 0u64;
    while let Some(chunk) = js_bytes::next_chunk(&reader)
        .await
        .map_err(|e| cannot_read(f, &e))?
    {
        bytes.push(&chunk);
        if bytes.len() - reported >= 16 << 20 {
            reported = bytes.len();
            push(WebEvent::Progress {
                verb: "reading",
                label: label.to_owned(),
                done: done + reported as f64,
                total,
            });
        }
    }
    Ok(bytes.finish())
}

/// A file's bytes, read whole into the wasm memory (one DICOM image at a time).
async fn read_file(f: &Named) -> Result<Vec<u8>, String> {
    Ok(read_js(f, &f.file).await?.to_vec())
}

/// The first bytes of a file (enough to tell its format: `io::sniff`).
async fn read_head(f: &Named) -> Result<Vec<u8>, String> {
    let end = f.file.size().min(crate::io::HEAD_BYTES as f64);
    let blob = f
        .file
        .slice_with_f64_and_f64(0.0, end)
        .map_err(|e| cannot_read(f, &e))?;
    Ok(read_js(f, &blob).await?.to_vec())
}

/// Whether several files are a DICOM set to decode as it is read: the first file is DICOM
/// and no archive is among them (an archive is unpacked by the loader first).
async fn is_dicom_set(files: &[Named]) -> bool {
    if files.len() < 2
        || files
            .iter()
            .any(|f| f.name.to_ascii_lowercase().ends_with(".zip"))
    {
        return false;
    }
    match read_head(&files[0]).await {
        Ok(head) => crate::io::sniff(&files[0].name, &head) == crate::io::Format::Dicom,
        Err(_) => false,
    }
}

/// Reads every file (in order), reporting progress, then queues them as one load; a DICOM
/// set is decoded as it is read instead ([`read_dicom_set`]).
async fn read_all(files: Vec<Named>) {
    let label = match files.as_slice() {
        [one] => one.name.clone(),
        many => {
            // A chosen or dropped folder: name it by its top-level folder.
            let top = many
                .first()
                .and_then(|f| f.name.split('/').next().map(str::to_owned))
                .filter(|t| many.iter().all(|f| f.name.starts_with(&format!("{t}/"))));
            match top {
                Some(t) => format!("{t} ({} files)", many.len()),
                None => format!("{} files", many.len()),
            }
        }
    };
    let total: f64 = files.iter().map(|f| f.file.size()).sum();
    if is_dicom_set(&files).await && read_dicom_set(&files, &label, total).await {
        return;
    }
    let mut done = 0.0;
    let mut out = Vec::with_capacity(files.len());
    for f in files {
        push(WebEvent::Progress {
            verb: "reading",
            label: label.clone(),
            done,
            total,
        });
        // The bytes stay JavaScript's, in chunks that the loader lets go as it reads them
        // into the voxels.
        let read = match read_chunked(&f, &label, done, total).await {
            Ok(bytes) => js_bytes::into_input(bytes, f.name),
            Err(e) => Err(e),
        };
        match read {
            Ok(file) => {
                done += f.file.size();
                out.push(file);
            }
            Err(message) => {
                push(WebEvent::Failed { message });
                return;
            }
        }
    }
    let origin = ViewSource::Dropped {
        name: label.clone(),
        bytes: total as u64,
    };
    push(WebEvent::Files {
        label,
        files: out,
        origin,
    });
}

/// Decodes a DICOM set as it is read (`io::FolderReader`): each file read whole, decoded and
/// dropped, so the page holds one file and the voxels, not every file and the voxels. Files of
/// an unrecognised format are ignored (noted), as the loader does in a DICOM set. Returns
/// false, having queued nothing, when another format is among the files (the caller reads the
/// set the usual way); every other outcome is queued as an event.
async fn read_dicom_set(files: &[Named], label: &str, total: f64) -> bool {
    use crate::io::{FolderRead, FolderReader, Format, InputFile, Limits};
    let limits = Limits::default();
    let mut reader = FolderReader::new(limits);
    reader.expect_files(files.len());
    let mut done = 0.0;
    for f in files {
        push(WebEvent::Progress {
            verb: "reading",
            label: label.to_owned(),
            done,
            total,
        });
        let bytes = match read_file(f).await {
            Ok(b) => b,
            Err(message) => {
                push(WebEvent::Failed { message });
                return true;
            }
        };
        done += f.file.size();
        match crate::io::sniff(&f.name, &bytes) {
            Format::Dicom => {
                if let Err(e) = reader.push(InputFile::new(f.name.clone(), bytes)) {
                    push(WebEvent::Failed {
                        message: e.to_string(),
                    });
                    return true;
                }
            }
            Format::Unknown => reader.ignore(f.name.clone()),
            _ => return false,
        }
    }
    let origin = ViewSource::Dropped {
        name: label.to_owned(),
        bytes: total as u64,
    };
    match reader.finish() {
        Ok(FolderRead::Loaded(loaded)) => push(WebEvent::Loaded {
            loaded,
            series: None,
            origin: Some(origin),
        }),
        Ok(FolderRead::List(list)) => {
            let chosen = list.default_choice();
            let handles = files.iter().map(|f| f.file.clone()).collect();
            let set = super::load::SeriesSet::of_web_files(list, handles, chosen);
            read_series(set, SeriesFor::Shown(Some(origin))).await;
        }
        Err(e) => push(WebEvent::Failed {
            message: e.to_string(),
        }),
    }
    true
}

/// Loads the chosen series of a set of the page's files (a click in the series list): its
/// files read again one at a time and decoded as they come.
pub fn load_series(set: super::load::SeriesSet) {
    wasm_bindgen_futures::spawn_local(read_series(set, SeriesFor::Shown(None)));
}

/// Loads the PET series of a set of the page's files, for the CT of `generation`.
pub fn load_pet_series(set: super::load::SeriesSet, generation: u64) {
    wasm_bindgen_futures::spawn_local(read_series(set, SeriesFor::Pet(generation)));
}

/// What a series read from the page's files is for.
enum SeriesFor {
    /// To be shown (`origin`: how a link names the files; `None`: another series of the set
    /// shown).
    Shown(Option<ViewSource>),
    /// The PET over the CT of this generation.
    Pet(u64),
}

async fn read_series(set: super::load::SeriesSet, purpose: SeriesFor) {
    let fail = |message: String| match purpose {
        SeriesFor::Shown(_) => WebEvent::Failed { message },
        SeriesFor::Pet(generation) => WebEvent::PetFailed {
            message,
            generation,
        },
    };
    let Some(files) = set.web_files() else {
        return;
    };
    let limits = crate::io::Limits::default();
    let members = set.list.members(set.chosen);
    let label = set.label();
    let total: f64 = members
        .iter()
        .filter_map(|&i| files.get(i))
        .map(|f| f.size())
        .sum();
    let mut builder = crate::io::entry_builder(members.len(), &limits);
    let mut done = 0.0;
    for &i in &members {
        let Some(file) = files.get(i) else { continue };
        // A PET read beside the volume shown does not take the progress bar of another load
        // (the panel says it is loading).
        if matches!(purpose, SeriesFor::Shown(_)) {
            push(WebEvent::Progress {
                verb: "reading",
                label: label.clone(),
                done,
                total,
            });
        }
        let named = Named {
            name: set.list.file_name(i).to_owned(),
            file: file.clone(),
        };
        let pushed = match read_file(&named).await {
            Ok(bytes) => builder
                .push(crate::io::InputFile::new(named.name, bytes))
                .map_err(|e| e.to_string()),
            Err(message) => Err(message),
        };
        if let Err(message) = pushed {
            push(fail(message));
            return;
        }
        done += file.size();
    }
    match (crate::io::finish_entry(&set.list, builder), purpose) {
        (Ok(loaded), SeriesFor::Shown(origin)) => push(WebEvent::Loaded {
            loaded: Box::new(loaded),
            series: Some(set),
            origin,
        }),
        (Ok(loaded), SeriesFor::Pet(generation)) => push(WebEvent::PetLoaded {
            loaded: Box::new(loaded),
            generation,
        }),
        (Err(e), purpose) => push(match purpose {
            SeriesFor::Shown(_) => WebEvent::Failed {
                message: e.to_string(),
            },
            SeriesFor::Pet(generation) => WebEvent::PetFailed {
                message: e.to_string(),
                generation,
            },
        }),
    }
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
        match fetch_bytes(super::demo::DEMO_URL).await {
            Ok(bytes) => push(WebEvent::Files {
                label,
                files: vec![InputFile::new(super::demo::DEMO_FILE, bytes)],
                origin: ViewSource::Demo,
            }),
            Err(e) => push(WebEvent::Failed {
                message: format!(
                    "{}: could not fetch the demo CT: {e}",
                    super::demo::DEMO_URL
                ),
            }),
        }
    });
}

async fn fetch_bytes(url: &str) -> Result<Vec<u8>, String> {
    let window = web_sys::window().ok_or("no window object")?;
    let response = JsFuture::from(window.fetch_with_str(url))
        .await
        .map_err(|e| js_error(&e))?;
    let response: web_sys::Response = response.unchecked_into();
    if !response.ok() {
        return Err(format!("HTTP {}", response.status()));
    }
    let buffer = JsFuture::from(response.array_buffer().map_err(|e| js_error(&e))?)
        .await
        .map_err(|e| js_error(&e))?;
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
