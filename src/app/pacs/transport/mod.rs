//! The archive's work outside the frame: `fetch` tasks in the page (`web.rs`, over
//! `io::dicomweb::web`), a thread per task over the blocking client natively (`native.rs`, over
//! `io::dicomweb::client`). Each reports the dialog's `Event`s into its inbox, tagged with its
//! task. Besides `src/app/platform/`, the one place in the app that asks which target it is
//! built for: the transports speak the dialog's own events, so they live beside it.

#[cfg(not(target_arch = "wasm32"))]
mod native;
#[cfg(target_arch = "wasm32")]
mod web;

#[cfg(not(target_arch = "wasm32"))]
pub(in crate::app) use native::*;
#[cfg(target_arch = "wasm32")]
pub(in crate::app) use web::*;
