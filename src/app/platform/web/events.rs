//! The page's inbox: its file reading and downloads queue [`crate::app::platform::Event`]s
//! here (outside the app's frame loop), and the app takes them once per frame.

use std::cell::RefCell;
use std::collections::VecDeque;

pub use crate::app::platform::Event as WebEvent;

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
