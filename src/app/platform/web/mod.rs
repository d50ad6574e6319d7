//! The page's side of [`Platform`], and the page's own parts: files read by its inputs and
//! drops (`files/`), downloads of `?url=` links (`fetch.rs`), file bytes kept by JavaScript
//! (`js_bytes.rs`), and the events they queue for the app's next frame (`events.rs`).

pub mod events;
pub mod fetch;
pub mod files;
pub mod js_bytes;

use super::{LoadSource, Platform, PlatformError, SaveError, SeriesSet};

/// The page.
pub type This = Web;

pub use files::absolute_url;

/// The page address's query parameters and its fragment.
pub fn page_query_and_fragment() -> (Vec<(String, String)>, String) {
    (files::query_params(), files::fragment())
}

/// `#token=...` of the page's address, removed from the address bar (the rest of the
/// fragment stays).
pub fn take_fragment_token() -> Option<String> {
    let window = web_sys::window()?;
    let hash = files::fragment();
    let fragment = hash.trim_start_matches('#');
    let params = crate::io::url::parse_params(fragment);
    let token = params
        .iter()
        .rev()
        .find(|(k, _)| k == "token")
        .map(|(_, v)| v.clone())?;
    let rest: Vec<&str> = fragment
        .split('&')
        .filter(|kv| kv.split('=').next() != Some("token"))
        .collect();
    let location = window.location();
    let url = format!(
        "{}{}{}",
        location.pathname().unwrap_or_default(),
        location.search().unwrap_or_default(),
        if rest.is_empty() {
            String::new()
        } else {
            format!("#{}", rest.join("&"))
        }
    );
    if let Ok(history) = window.history() {
        let _ = history.replace_state_with_url(&wasm_bindgen::JsValue::NULL, "", Some(&url));
    }
    Some(token)
}

/// Whether the page's query names a token (refused).
pub fn query_has_token() -> bool {
    files::query_params().iter().any(|(k, _)| k == "token")
}

/// The page.
#[derive(Default)]
pub struct Web;

impl Platform for Web {
    fn take_events(&mut self, _ctx: &egui::Context) -> Vec<super::Event> {
        events::take_events()
    }

    fn open_menu_ui(&mut self, ui: &mut egui::Ui) -> Option<LoadSource> {
        if ui
            .button("Open files…")
            .on_hover_text("a volume file, a header with its data file, or DICOM slices")
            .clicked()
        {
            files::open_dialog(false);
        }
        if ui
            .button("Open folder…")
            .on_hover_text("a folder holding a DICOM series")
            .clicked()
        {
            files::open_dialog(true);
        }
        None
    }

    fn deliver(&self, name: &str, bytes: &[u8]) -> Result<String, SaveError> {
        download(name, bytes).map_err(|e| SaveError::Download(crate::io::js::error_text(&e)))?;
        Ok(format!("{name} (your downloads)"))
    }

    fn set_save_dir(&mut self, _dir: std::path::PathBuf) {}

    fn install(&self, ctx: &egui::Context) -> Result<(), PlatformError> {
        files::install(ctx)
    }

    fn demo(&self) -> Option<LoadSource> {
        files::fetch_demo();
        None
    }

    fn fetch(&self, urls: Vec<String>) -> Result<(), PlatformError> {
        fetch::fetch_urls(urls);
        Ok(())
    }

    fn downloading(&self) -> bool {
        fetch::active()
    }

    fn cancel_download(&self) {
        fetch::cancel();
    }

    fn fetch_pet(&self, urls: Vec<String>, generation: u64) -> Result<(), PlatformError> {
        fetch::fetch_pet_urls(urls, generation);
        Ok(())
    }

    fn page_address(&self) -> String {
        web_sys::window()
            .and_then(|w| {
                let l = w.location();
                Some(format!("{}{}", l.origin().ok()?, l.pathname().ok()?))
            })
            .unwrap_or_default()
    }

    fn set_title(&mut self, _ctx: &egui::Context, _title: String) {}

    fn read_page_series(&self, set: SeriesSet, pet_for: Option<u64>) -> Option<SeriesSet> {
        if set.page_files().is_none() {
            return Some(set);
        }
        match pet_for {
            None => files::load_series(set),
            Some(generation) => files::load_pet_series(set, generation),
        }
        None
    }

    fn packs_voxels(&self) -> bool {
        false
    }
}

/// Offers `png` to the user as a download named `name`.
fn download(name: &str, png: &[u8]) -> Result<(), wasm_bindgen::JsValue> {
    use wasm_bindgen::JsCast as _;
    let window = web_sys::window().ok_or("no window")?;
    let document = window.document().ok_or("no document")?;
    let bytes = js_sys::Uint8Array::from(png);
    let parts = js_sys::Array::of1(&bytes);
    let options = web_sys::BlobPropertyBag::new();
    options.set_type("image/png");
    let blob = web_sys::Blob::new_with_u8_array_sequence_and_options(&parts, &options)?;
    let url = web_sys::Url::create_object_url_with_blob(&blob)?;
    let a: web_sys::HtmlAnchorElement = document.create_element("a")?.dyn_into()?;
    a.set_href(&url);
    a.set_download(name);
    a.click();
    // The URL is kept until the next picture: revoked at once, a browser may not have started
    // reading it yet.
    LAST_URL.with(|last| {
        if let Some(old) = last.replace(Some(url)) {
            let _ = web_sys::Url::revoke_object_url(&old);
        }
    });
    Ok(())
}

thread_local! {
    static LAST_URL: std::cell::RefCell<Option<String>> = const { std::cell::RefCell::new(None) };
}
