//! The export's controls as widgets: "Copy link", "Save picture", "Save movie", "Store to
//! PACS" and the movie's progress with its Cancel. Each takes what it shows and returns what the
//! user asked for as an [`ExportEvent`] (and where it drew, for automation); the app applies the
//! events after drawing.

use super::movie::{Destination, MOVIE_FRAMES};
use crate::app::{Layout, PaneId, SliceKind};

/// What the user asked of the export.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(in crate::app) enum ExportEvent {
    CopyLink,
    SavePicture(PaneId),
    SaveMovie,
    StoreToPacs,
    CancelMovie,
}

/// Named controls drawn (published as `window.shapecastStatus.controls`).
pub(in crate::app) type Controls = Vec<(String, egui::Rect)>;

/// "copied", "stored": a word in green for `seconds` after `at` (the app's time); `at` is
/// cleared after.
fn flash(
    ui: &mut egui::Ui,
    at: &mut Option<f64>,
    seconds: f64,
    word: &str,
) -> Option<egui::Response> {
    let t = (*at)?;
    if ui.ctx().input(|i| i.time) - t < seconds {
        ui.ctx()
            .request_repaint_after(std::time::Duration::from_millis(500));
        let done = egui::Color32::from_rgb(140, 220, 140);
        Some(ui.label(egui::RichText::new(word).color(done)))
    } else {
        *at = None;
        None
    }
}

/// The "Copy link" button, "copied" beside it for 2 s after `copied_at`.
pub(in crate::app) fn copy_link_button(
    ui: &mut egui::Ui,
    copied_at: &mut Option<f64>,
    controls: &mut Controls,
) -> Option<ExportEvent> {
    let r = ui.button("Copy link").on_hover_text(
        "copies a link to exactly this view (volume, mode, parameters, camera, windows, layout); the view is in the link's #fragment, which browsers never send to a server",
    );
    controls.push(("copy-link".to_owned(), r.rect));
    flash(ui, copied_at, 2.0, "copied");
    r.clicked().then_some(ExportEvent::CopyLink)
}

/// The "Save picture" menu: one entry per pane, enabled when `layout` shows it and there is a
/// volume.
pub(in crate::app) fn save_picture_menu(
    ui: &mut egui::Ui,
    layout: Layout,
    has_volume: bool,
) -> Option<ExportEvent> {
    let mut event = None;
    ui.menu_button("Save picture", |ui| {
        ui.label("A PNG of a pane as shown, with its letters and scale bar:");
        for (label, pane) in [
            ("MIP pane", PaneId::Mip),
            ("Axial pane", PaneId::Slice(SliceKind::Axial)),
            ("Coronal pane", PaneId::Slice(SliceKind::Coronal)),
            ("Sagittal pane", PaneId::Slice(SliceKind::Sagittal)),
        ] {
            let shown = match layout {
                Layout::Single(p) => p == pane,
                _ => true,
            };
            if ui
                .add_enabled(shown && has_volume, egui::Button::new(label))
                .clicked()
            {
                event = Some(ExportEvent::SavePicture(pane));
                ui.close();
            }
        }
    });
    event
}

/// The "Save movie" button, enabled when there is a volume and no movie is being made.
pub(in crate::app) fn save_movie_button(
    ui: &mut egui::Ui,
    enabled: bool,
    controls: &mut Controls,
) -> Option<ExportEvent> {
    let r = ui
        .add_enabled(enabled, egui::Button::new("Save movie"))
        .on_hover_text(format!(
            "a full turn of the MIP as an animated PNG, {MOVIE_FRAMES} frames (M)"
        ));
    controls.push(("save-movie".to_owned(), r.rect));
    r.clicked().then_some(ExportEvent::SaveMovie)
}

/// What the "Store to PACS" button shows.
pub(in crate::app) struct StoreShown<'a> {
    /// No movie is being made and nothing is being sent.
    pub enabled: bool,
    /// A series is being sent to the archive.
    pub storing: bool,
    /// When the last series was stored ("stored" is shown for 4 s after).
    pub stored_at: &'a mut Option<f64>,
}

/// The "Store to PACS" button (in the PACS bar, for a volume that came from an archive), with
/// "sending to the archive" or "stored" beside it.
pub(in crate::app) fn store_button(
    ui: &mut egui::Ui,
    shown: StoreShown<'_>,
    controls: &mut Controls,
) -> Option<ExportEvent> {
    let r = ui
        .add_enabled(shown.enabled, egui::Button::new("Store to PACS"))
        .on_hover_text(format!(
            "the MIP's full turn ({MOVIE_FRAMES} frames) as a Secondary Capture series in this study of the archive, beside the source series"
        ));
    controls.push(("store-pacs".to_owned(), r.rect));
    if shown.storing {
        ui.spinner();
        ui.label(egui::RichText::new("sending to the archive").small());
    } else if let Some(stored) = flash(ui, shown.stored_at, 4.0, "stored") {
        stored.on_hover_text("the series is in the study (see Notes)");
    }
    r.clicked().then_some(ExportEvent::StoreToPacs)
}

/// The status bar's progress of the movie being made, `(frames done, frames, where they go)`,
/// with its Cancel.
pub(in crate::app) fn movie_progress(
    ui: &mut egui::Ui,
    progress: Option<(u32, u32, Destination)>,
    controls: &mut Controls,
) -> Option<ExportEvent> {
    let (done, frames, destination) = progress?;
    ui.add(
        egui::ProgressBar::new(done as f32 / frames.max(1) as f32)
            .desired_width(200.0)
            .text(format!(
                "{}: frame {done} of {frames}",
                match destination {
                    Destination::Pacs => "storing to PACS",
                    Destination::File => "saving the movie",
                }
            )),
    );
    let r = ui
        .small_button("Cancel")
        .on_hover_text("stop making the movie");
    controls.push(("cancel-movie".to_owned(), r.rect));
    r.clicked().then_some(ExportEvent::CancelMovie)
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::expect_used)] // a failed expect is a failed test
mod tests {
    use egui_kittest::Harness;
    use egui_kittest::kittest::{NodeT as _, Queryable as _};

    use super::*;

    /// The top bar's three export controls, as the app draws them, with no app around them.
    fn bar(layout: Layout, has_volume: bool) -> Harness<'static, (Vec<ExportEvent>, Option<f64>)> {
        Harness::new_ui_state(
            move |ui, (events, copied_at): &mut (Vec<ExportEvent>, Option<f64>)| {
                let mut controls = Controls::new();
                ui.horizontal(|ui| {
                    events.extend(copy_link_button(ui, copied_at, &mut controls));
                    events.extend(save_picture_menu(ui, layout, has_volume));
                    events.extend(save_movie_button(ui, has_volume, &mut controls));
                });
                let names: Vec<&str> = controls.iter().map(|(n, _)| n.as_str()).collect();
                assert_eq!(names, ["copy-link", "save-movie"]);
            },
            (Vec::new(), None),
        )
    }

    #[test]
    fn the_export_buttons_ask_for_a_link_a_pane_s_picture_and_a_movie() {
        let mut h = bar(Layout::Single(PaneId::Slice(SliceKind::Coronal)), true);
        h.get_by_label("Copy link").click();
        h.run();
        h.get_by_label("Save movie").click();
        h.run();
        h.get_by_label("Save picture").click();
        h.run();
        // One pane shown alone: only its entry can be saved.
        assert!(h.get_by_label("MIP pane").accesskit_node().is_disabled());
        h.get_by_label("Coronal pane").click();
        h.run();
        assert_eq!(
            h.state().0,
            vec![
                ExportEvent::CopyLink,
                ExportEvent::SaveMovie,
                ExportEvent::SavePicture(PaneId::Slice(SliceKind::Coronal)),
            ]
        );
    }

    #[test]
    fn without_a_volume_nothing_can_be_saved_but_the_link_copied() {
        let mut h = bar(Layout::Grid, false);
        assert!(h.get_by_label("Save movie").accesskit_node().is_disabled());
        h.get_by_label("Save picture").click();
        h.run();
        assert!(h.get_by_label("Axial pane").accesskit_node().is_disabled());
        h.get_by_label("Copy link").click();
        h.run();
        assert_eq!(h.state().0, vec![ExportEvent::CopyLink]);
    }

    #[test]
    fn the_movie_s_progress_says_where_it_goes_and_asks_to_cancel() {
        let mut h = Harness::new_ui_state(
            |ui, events: &mut Vec<ExportEvent>| {
                let mut controls = Controls::new();
                events.extend(movie_progress(
                    ui,
                    Some((3, 36, Destination::Pacs)),
                    &mut controls,
                ));
                assert_eq!(controls.len(), 1);
            },
            Vec::new(),
        );
        h.get_by_label_contains("storing to PACS: frame 3 of 36");
        h.get_by_label("Cancel").click();
        h.run();
        assert_eq!(h.state(), &vec![ExportEvent::CancelMovie]);
    }
}
