//! What differs between the page and the native window, behind one small trait ([`Platform`]),
//! so that the rest of the app does not ask which it runs in: the "Open" menu, handing a saved
//! file to the user, the demo CT, the page's downloads and the page's address. The page's
//! files, downloads and events live in `web/`; the native window's side in `native/`. This is
//! where the app's `cfg(target_arch = "wasm32")` lives: each platform module names the same
//! types and functions, re-exported here.

use super::error::{PlatformError, SaveError};
use super::load::{LoadSource, SeriesSet};

#[cfg(not(target_arch = "wasm32"))]
pub(crate) mod native;
#[cfg(target_arch = "wasm32")]
pub(crate) mod web;

#[cfg(not(target_arch = "wasm32"))]
use native as current;
#[cfg(target_arch = "wasm32")]
use web as current;

/// The platform the app runs on.
pub type Current = current::This;

/// The page address's query parameters and its fragment (`#...`; natively none).
pub use current::page_query_and_fragment;

/// A URL resolved against the page's address (natively as given).
pub use current::absolute_url;

/// `#token=...` of the page's address, removed from the address bar (natively none).
pub use current::take_fragment_token;

/// Whether the page's query names a token (refused: a query is sent to servers and logged).
pub use current::query_has_token;

/// True in the page (WebAssembly in a browser), false in the native window.
pub const IN_PAGE: bool = cfg!(target_arch = "wasm32");

/// What happened outside the app's frame loop: files dropped or read, downloads, a link pasted
/// into the page ([`Platform::take_events`]). The native window has only drops.
// Each platform makes some of them: natively `Hover`, `Open` and `Failed`; the page all but
// `Open`.
#[allow(dead_code)]
pub enum Event {
    /// Files are dragged over the window (true) or not any more (false).
    Hover(bool),
    /// Paths or files dropped on the native window, to open.
    Open(LoadSource),
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
        files: Vec<crate::io::InputFile>,
        origin: crate::app::view_link::ViewSource,
    },
    /// A DICOM set decoded as it was read (`FolderReader`): the volume, and the series list
    /// when the files held several. `origin` is how a link names the files (`None` for another
    /// series of the set shown: its origin stays).
    Loaded {
        loaded: Box<crate::io::Loaded>,
        series: Option<crate::app::load::SeriesSet>,
        origin: Option<crate::app::view_link::ViewSource>,
    },
    /// The PET series of a PET/CT study's files, read for the CT of `generation`.
    PetLoaded {
        loaded: Box<crate::io::Loaded>,
        generation: u64,
    },
    /// Reading the PET series failed; the CT shown stays, without it.
    PetFailed {
        error: crate::app::error::AppError,
        generation: u64,
    },
    /// The files of a PET/CT link's PET (`&pet=URL`), downloaded for the CT of `generation`.
    PetFiles {
        label: String,
        files: Vec<crate::io::InputFile>,
        generation: u64,
    },
    /// Reading failed; the error names the file.
    Failed { error: crate::app::error::AppError },
    /// The user cancelled a download.
    Cancelled { label: String },
    /// A link was pasted into the address bar of the open page (only its fragment changed).
    Link { fragment: String },
}

/// What the app asks of the platform it runs on.
pub trait Platform {
    /// What happened since the last frame (drops, the page's reads and downloads).
    fn take_events(&mut self, ctx: &egui::Context) -> Vec<Event>;

    /// The "Open" menu's entries. Returns a load to start when the user chose one now (the
    /// page's file dialogs answer later, through its events).
    fn open_menu_ui(&mut self, ui: &mut egui::Ui) -> Option<LoadSource>;

    /// Hands a saved file (a picture, a movie) to the user: a download in the page, a file in
    /// the pictures' folder natively. Says where it went.
    fn deliver(&self, name: &str, bytes: &[u8]) -> Result<String, SaveError>;

    /// Where [`Self::deliver`] writes files natively; the page hands them to the browser's
    /// downloads, which choose the folder, so it keeps none.
    fn set_save_dir(&mut self, dir: std::path::PathBuf);

    /// Sets up what reaches the app from outside its frames (the page's drops and inputs);
    /// called once, at the first frame.
    fn install(&self, ctx: &egui::Context) -> Result<(), PlatformError>;

    /// Starts getting the demo CT: its source when it is at hand (natively it is embedded in
    /// the binary), `None` while it is fetched (the page: it arrives with the page's events).
    fn demo(&self) -> Option<LoadSource>;

    /// Starts downloading volumes by URL (the page's `?url=`, a link); the error says why this
    /// platform cannot.
    fn fetch(&self, urls: Vec<String>) -> Result<(), PlatformError>;

    /// Whether one of the page's downloads (`?url=`) is running ([`Self::cancel_download`]).
    fn downloading(&self) -> bool;

    /// Stops the page's download; the volume shown stays.
    fn cancel_download(&self);

    /// Starts downloading a PET/CT link's PET (`&pet=URL`) for the CT of `generation`; the
    /// error says why this platform cannot.
    fn fetch_pet(&self, urls: Vec<String>, generation: u64) -> Result<(), PlatformError>;

    /// The address of the page, which a link to the view starts with (empty natively).
    fn page_address(&self) -> String;

    /// Names the window `title` (natively; a page's title is the tab's name in the browser's
    /// history, so it never names the patient).
    fn set_title(&mut self, ctx: &egui::Context, title: String);

    /// Reads another series of the page's files (`set`'s chosen one) as the page reads files,
    /// to be shown (`pet_for` `None`) or as the PET of the CT of generation `pet_for`; its
    /// events bring the volume. Hands `set` back when its files are not the page's: a
    /// [`super::load::LoadJob`] reads those.
    fn read_page_series(&self, set: SeriesSet, pet_for: Option<u64>) -> Option<SeriesSet>;

    /// Whether a large volume's CPU copy is kept packed (`Voxels::packed`). Packing holds the
    /// dense and the packed copy at once; natively the dense one then goes back to the system,
    /// but a page's WebAssembly memory never shrinks, so there it would only add the packed
    /// copy to the tab's peak.
    fn packs_voxels(&self) -> bool;
}
