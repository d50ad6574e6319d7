//! The archive's work outside the frame: `fetch` tasks in the page (`web.rs`, over
//! `io::dicomweb::web`), a thread per task over the blocking client natively (`native.rs`, over
//! `io::dicomweb::client`). Each reports the dialog's `Event`s into its inbox, tagged with its
//! task. Besides `src/app/platform/`, the one place in the app that asks which target it is
//! built for: the transports speak the dialog's own events, so they live beside it.
//!
//! The tasks are written once here: each side gives the work (blocking or async) and runs it,
//! and the answer becomes the same event on both.

#[cfg(not(target_arch = "wasm32"))]
mod native;
#[cfg(target_arch = "wasm32")]
mod web;

#[cfg(not(target_arch = "wasm32"))]
use native as side;
#[cfg(target_arch = "wasm32")]
use web as side;

pub(in crate::app) use side::Task;

use super::{Event, Inbox, PacsTarget, StoreJob};
use crate::io::dicomweb::{Auth, Base, StudySearch};

/// Searches the archive's studies.
pub(in crate::app) fn search(
    base: Base,
    auth: Auth,
    search: StudySearch,
    task: u64,
    inbox: Inbox,
) -> Task {
    side::run(
        (base, auth),
        task,
        inbox,
        side::search(search),
        Event::Studies,
    )
}

/// Finds a study and lists its series.
pub(in crate::app) fn study(
    base: Base,
    auth: Auth,
    target: PacsTarget,
    task: u64,
    inbox: Inbox,
) -> Task {
    let work = side::study(target.study.clone());
    let event = move |result| Event::Study { target, result };
    side::run((base, auth), task, inbox, work, event)
}

/// Retrieves a series (its progress told as it goes).
pub(in crate::app) fn retrieve(
    base: Base,
    auth: Auth,
    target: PacsTarget,
    task: u64,
    inbox: Inbox,
) -> Task {
    let series = target.series.clone().unwrap_or_default();
    let work = side::retrieve(target.study.clone(), series, task);
    let event = move |result| Event::Retrieved {
        target,
        result: Box::new(result),
    };
    side::run((base, auth), task, inbox, work, event)
}

/// Stores a rotation into its study (the source series' metadata, then STOW-RS).
pub(in crate::app) fn store(
    base: Base,
    auth: Auth,
    job: StoreJob,
    task: u64,
    inbox: Inbox,
) -> Task {
    side::run((base, auth), task, inbox, side::store(job), Event::Stored)
}
