//! What leaves the app: "Copy link" (the view as a link, `app::share`), "Save picture" (a PNG of one pane, `picture`), "Save movie" (a
//! turntable APNG of the MIP drawn off-screen, `movie`) and "Store to PACS" (the same turn as a
//! Secondary Capture series in the archive, `movie` then `app::pacs`), and their state in
//! [`Export`]; their controls are widgets that return [`buttons::ExportEvent`]s.

pub mod apng;
pub(super) mod buttons;
pub mod movie;
pub mod picture;

use super::ShapecastApp;
pub use super::error::ExportError;
use buttons::ExportEvent;

/// The picture and the movie being made, and the last of each.
#[derive(Default)]
pub(super) struct Export {
    pub(super) picture: picture::PictureState,
    pub(super) movie: movie::MovieState,
}

impl ShapecastApp {
    /// Does what the user asked of the export (the buttons' [`ExportEvent`]s).
    pub(super) fn apply_export(&mut self, ctx: &egui::Context, event: ExportEvent) {
        match event {
            ExportEvent::CopyLink => {
                ctx.copy_text(self.link());
                self.windows.link_copied_at = Some(ctx.input(|i| i.time));
            }
            ExportEvent::SavePicture(pane) => self.save_picture(ctx, pane),
            ExportEvent::SaveMovie => self.save_movie(ctx, movie::MOVIE_FRAMES),
            ExportEvent::StoreToPacs => self.store_to_pacs(ctx, movie::MOVIE_FRAMES),
            ExportEvent::CancelMovie => self.cancel_movie(),
        }
    }
}
