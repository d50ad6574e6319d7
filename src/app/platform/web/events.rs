//! What happened outside the app's frame loop in the page (wasm only): the file reading and
//! the downloads queue [`WebEvent`]s here, and the app takes them once per frame.

use std::cell::RefCell;
use std::collections::VecDeque;

use crate::app::view_link::ViewSource;
use crate::io::InputFile;

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
        series: Option<crate::app::load::SeriesSet>,
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
}

/// The context a new event asks for a frame from (set once, when the page's listeners are
/// installed).
pub(super) fn set_context(ctx: &egui::Context) {
    CONTEXT.with(|c| *c.borrow_mut() = Some(ctx.clone()));
}

pub(super) fn push(event: WebEvent) {
    INBOX.with(|q| q.borrow_mut().push_back(event));
    CONTEXT.with(|c| {
        if let Some(ctx) = c.borrow().as_ref() {
            ctx.request_repaint();
        }
    });
}

/// The events since the last call.
pub fn take_events() -> Vec<WebEvent> {
    INBOX.with(|q| q.borrow_mut().drain(..).collect())
}
