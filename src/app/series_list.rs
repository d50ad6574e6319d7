//! The series list: when the files given (a folder, a drop, an archive) hold more than one
//! DICOM series, the side panel lists them (modality, description, images, slice thickness,
//! orientation) and one click loads another, from the files kept in the [`SeriesSet`]. The
//! list carries no patient data, so it is also published in `window.shapecastStatus`.

use super::ShapecastApp;
use super::load::{LoadSource, SeriesSet};
use super::platform::Platform as _;
use crate::io::SeriesEntry;
use crate::status::SeriesStatus;

/// The app's series list and the entry being loaded, if one is.
#[derive(Default)]
pub(super) struct SeriesState {
    pub set: Option<SeriesSet>,
    /// The entry whose load is running (cleared when that load ends either way).
    pub loading: Option<usize>,
}

/// One row of the list: "CT  93 images  1.5 mm  axial".
pub(super) fn row_text(e: &SeriesEntry) -> String {
    let mut s = format!(
        "{}  {} image{}",
        if e.modality.is_empty() {
            "?"
        } else {
            e.modality.as_str()
        },
        e.images,
        if e.images == 1 { "" } else { "s" }
    );
    if let Some(t) = e.thickness_mm() {
        s.push_str(&format!("  {} mm", short_mm(t)));
    }
    s.push_str(&format!("  {}", e.orientation.name()));
    if e.part.1 > 1 {
        s.push_str(&format!(" (part {} of {})", e.part.0 + 1, e.part.1));
    }
    s
}

/// A thickness to the micrometre, without trailing zeros: 3.2700000000000005 -> "3.27",
/// 0.625 -> "0.625", 5.0 -> "5".
fn short_mm(t: f64) -> String {
    let s = format!("{t:.3}");
    s.trim_end_matches('0').trim_end_matches('.').to_owned()
}

/// The series' number and description on a second line: "#3 HEAD STD".
pub(super) fn row_description(e: &SeriesEntry) -> String {
    let number = e.number.map(|n| format!("#{n}"));
    let description = (!e.description.is_empty()).then(|| e.description.clone());
    match (number, description) {
        (Some(n), Some(d)) => format!("{n} {d}"),
        (Some(n), None) => n,
        (None, Some(d)) => d,
        (None, None) => "(no description)".to_owned(),
    }
}

/// How a link names an entry of a list: its SeriesInstanceUID, with `:k` for stack k of a
/// series split in several.
pub(super) fn entry_key(e: &SeriesEntry) -> String {
    if e.part.1 > 1 {
        format!("{}:{}", e.series_uid, e.part.0)
    } else {
        e.series_uid.clone()
    }
}

/// The entry of `set` a link's `key` names.
pub(super) fn find_entry(set: &SeriesSet, key: &str) -> Option<usize> {
    set.list.entries().iter().position(|e| entry_key(e) == key)
}

/// What `window.shapecastStatus.series` shows of a list.
pub(super) fn status_of(state: &SeriesState) -> Vec<SeriesStatus> {
    let Some(set) = &state.set else {
        return Vec::new();
    };
    set.list
        .entries()
        .iter()
        .enumerate()
        .map(|(i, e)| SeriesStatus {
            modality: e.modality.clone(),
            description: e.description.clone(),
            number: e.number,
            images: e.images,
            rows: e.rows,
            cols: e.cols,
            thickness_mm: e.thickness_mm(),
            orientation: e.orientation.name().to_owned(),
            chosen: i == set.chosen,
            loading: state.loading == Some(i),
        })
        .collect()
}

/// The list of `set`'s series (`loading`: the entry being loaded). Returns the entry clicked
/// (not the one shown or loading) and each row as a named control.
pub(super) fn series_section(
    ui: &mut egui::Ui,
    set: &SeriesSet,
    loading: Option<usize>,
) -> (Option<usize>, Vec<(String, egui::Rect)>) {
    let mut controls = Vec::new();
    ui.separator();
    ui.label(egui::RichText::new(format!("Series ({})", set.list.entries().len())).strong())
        .on_hover_text("the files given hold several series; click one to load it");
    let mut pick = None;
    for (i, e) in set.list.entries().iter().enumerate() {
        let mut text = row_text(e);
        if loading == Some(i) {
            text.push_str("  (loading…)");
        }
        let r = ui
            .selectable_label(
                i == set.chosen,
                format!("{text}\n    {}", row_description(e)),
            )
            .on_hover_text(format!(
                "{} × {} pixels, {} file{}",
                e.cols,
                e.rows,
                e.files,
                if e.files == 1 { "" } else { "s" }
            ));
        controls.push((format!("series:{i}"), r.rect));
        if r.clicked() && i != set.chosen && loading != Some(i) {
            pick = Some(i);
        }
    }
    (pick, controls)
}

impl ShapecastApp {
    /// The series of the files loaded, when they hold several; a click loads one.
    pub(super) fn series_ui(&mut self, ui: &mut egui::Ui) {
        let Some(set) = self.series.set.clone() else {
            return;
        };
        let (pick, controls) = series_section(ui, &set, self.series.loading);
        self.controls.extend(controls);
        if let Some(i) = pick {
            self.open_series(&set, i);
        }
    }

    /// Loads entry `index` of `set`; the volume shown and the list stay until it is loaded.
    pub(super) fn open_series(&mut self, set: &SeriesSet, index: usize) {
        if index >= set.list.entries().len() {
            return;
        }
        let set = set.with_chosen(index);
        let label = set.label();
        let Some(set) = self.platform.read_page_series(set, None) else {
            // The page's files: read again by the page, one at a time.
            self.cancel_upload();
            self.load_progress = Some((0.0, format!("opening {label}")));
            self.series.loading = Some(index);
            return;
        };
        let origin = self.scene.as_ref().and_then(|s| s.origin.clone());
        self.open_from(LoadSource::Series(set), origin);
        self.series.loading = Some(index);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn thicknesses_are_short_and_keep_what_a_reader_reads() {
        assert_eq!(short_mm(1.09 * 3.0), "3.27"); // 3.2700000000000005
        assert_eq!(short_mm(0.625), "0.625");
        assert_eq!(short_mm(5.0), "5");
        assert_eq!(short_mm(1.5), "1.5");
        assert_eq!(short_mm(0.1 * 6.0), "0.6"); // 0.6000000000000001
    }
}
