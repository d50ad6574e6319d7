//! What leaves the app: "Save picture" (a PNG of one pane, `picture`), "Save movie" (a
//! turntable APNG of the MIP drawn off-screen, `movie`) and "Store to PACS" (the same turn as a
//! Secondary Capture series in the archive, `movie` then `app::pacs`), and their state in
//! [`Export`].

pub mod apng;
pub mod movie;
pub mod picture;

pub use super::error::ExportError;

/// The picture and the movie being made, and the last of each.
#[derive(Default)]
pub(super) struct Export {
    pub(super) picture: picture::PictureState,
    pub(super) movie: movie::MovieState,
}
