//! The PACS bar's widgets ("Open from PACS…", Cancel, the patient line; the app puts the
//! export's "Store to PACS" between them) and the dialog: server, token, study search, studies,
//! series.

use super::{Pacs, PacsTarget, study_summary};
use crate::app::ShapecastApp;
use crate::io::dicomweb::StudySearch;

/// The study search's fields, in the order of `StudySearch`'s: label, hint, control name.
const SEARCH_FIELDS: [(&str, &str, &str); 5] = [
    ("Patient ID", "e.g. 12345 or 123*", "pacs-patient-id"),
    ("Patient name", "e.g. DOE^JANE or DOE*", "pacs-patient-name"),
    ("Accession number", "", "pacs-accession"),
    ("Modality", "e.g. CT, MR or PT", "pacs-modality"),
    ("Study date", "YYYYMMDD or YYYYMMDD-YYYYMMDD", "pacs-date"),
];

/// What the user asked for in the PACS bar.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(in crate::app) enum BarEvent {
    /// Open the "Open from PACS" dialog.
    OpenDialog,
    /// Stop the archive's requests.
    Cancel,
}

/// The PACS bar's own buttons: "Open from PACS…", and Cancel while the archive is `busy`.
pub(in crate::app) fn bar_buttons(
    ui: &mut egui::Ui,
    busy: bool,
    controls: &mut Vec<(String, egui::Rect)>,
) -> Option<BarEvent> {
    let mut event = None;
    let r = ui.button("Open from PACS…").on_hover_text(
        "find a study in an archive over DICOMweb (QIDO-RS) and open one of its series (WADO-RS)",
    );
    controls.push(("open-pacs".to_owned(), r.rect));
    if r.clicked() {
        event = Some(BarEvent::OpenDialog);
    }
    if busy {
        let r = ui
            .small_button("Cancel")
            .on_hover_text("stop the archive's requests; the volume shown stays");
        controls.push(("cancel-pacs".to_owned(), r.rect));
        if r.clicked() {
            event = Some(BarEvent::Cancel);
        }
    }
    event
}

/// The patient line of the study shown (from its header), after a separator.
pub(in crate::app) fn patient_label(ui: &mut egui::Ui, line: Option<String>) {
    if let Some(line) = line {
        ui.separator();
        ui.label(egui::RichText::new(line).strong())
            .on_hover_text("from the study's DICOM header; shown on this screen only, never put into a link or sent anywhere");
    }
}

impl ShapecastApp {
    /// The "Open from PACS" dialog.
    pub(in crate::app) fn pacs_window_ui(&mut self, ctx: &egui::Context) {
        if !self.pacs.dialog {
            return;
        }
        let mut open = true;
        egui::Window::new("Open from PACS")
            .open(&mut open)
            .default_width(640.0)
            .show(ctx, |ui| self.pacs_dialog_ui(ui));
        if !open {
            self.pacs.dialog = false;
        }
    }

    fn pacs_dialog_ui(&mut self, ui: &mut egui::Ui) {
        let (events, controls) = dialog(ui, &mut self.pacs);
        self.controls.extend(controls);
        for e in events {
            match e {
                DialogEvent::Search => self.pacs_search(),
                DialogEvent::Cancel => self.cancel_dicomweb(),
                DialogEvent::OpenStudy { target, auto_open } => {
                    self.pacs_open_study(target, auto_open);
                }
                DialogEvent::Retrieve(target) => self.pacs_retrieve(target),
            }
        }
    }
}

/// What the user asked for in the "Open from PACS" dialog, applied after it is drawn.
#[derive(Clone, Debug, PartialEq)]
enum DialogEvent {
    /// Search with the fields (from the page its offset says).
    Search,
    Cancel,
    /// Open a study's series list (`auto_open`: and the chooser's series).
    OpenStudy {
        target: PacsTarget,
        auto_open: bool,
    },
    /// Retrieve a series.
    Retrieve(PacsTarget),
}

/// The dialog: server, token, search fields (edited in place), studies and series. Returns what
/// was asked for and the named controls.
fn dialog(ui: &mut egui::Ui, pacs: &mut Pacs) -> (Vec<DialogEvent>, Vec<(String, egui::Rect)>) {
    let mut events = Vec::new();
    let mut controls: Vec<(String, egui::Rect)> = Vec::new();
    egui::Grid::new("pacs-server")
        .num_columns(2)
        .show(ui, |ui| {
            let l = ui.label("DICOMweb server");
            let r = ui
                .add(
                    egui::TextEdit::singleline(&mut pacs.server)
                        .hint_text("/dicom-web, or https://pacs.example.org/dicom-web")
                        .desired_width(420.0),
                )
                .labelled_by(l.id);
            controls.push(("pacs-server".to_owned(), r.rect));
            ui.end_row();
            let l = ui.label("Bearer token");
            let r = ui
                .add(
                    egui::TextEdit::singleline(&mut pacs.token)
                        .password(true)
                        .hint_text("optional; never put into a link")
                        .desired_width(420.0),
                )
                .labelled_by(l.id);
            controls.push(("pacs-token".to_owned(), r.rect));
            ui.end_row();
        });
    if let Some(m) = &pacs.message {
        let colour = if pacs.needs_token {
            egui::Color32::from_rgb(255, 190, 90)
        } else {
            egui::Color32::from_rgb(255, 140, 140)
        };
        ui.colored_label(colour, m);
    }
    if pacs.needs_token
        && let Some((target, auto_open)) = pacs.last.clone()
    {
        let enabled = !pacs.token.trim().is_empty() && pacs.busy.is_none();
        let r = ui.add_enabled(enabled, egui::Button::new("Open again with the token"));
        // Published only when it can be clicked (a token typed), for automation.
        if enabled {
            controls.push(("pacs-retry".to_owned(), r.rect));
        }
        if r.clicked() {
            pacs.needs_token = false;
            events.push(match target.series {
                Some(_) if auto_open => DialogEvent::Retrieve(target),
                _ => DialogEvent::OpenStudy { target, auto_open },
            });
        }
    }
    ui.separator();
    ui.label(egui::RichText::new("Find a study").strong());
    let mut go = false;
    egui::Grid::new("pacs-search")
        .num_columns(2)
        .show(ui, |ui| {
            let f = &mut pacs.search;
            let values = [
                &mut f.patient_id,
                &mut f.patient_name,
                &mut f.accession_number,
                &mut f.modality,
                &mut f.study_date,
            ];
            for ((label, hint, name), value) in SEARCH_FIELDS.into_iter().zip(values) {
                let l = ui.label(label);
                let r = ui
                    .add(
                        egui::TextEdit::singleline(value)
                            .hint_text(hint)
                            .desired_width(260.0),
                    )
                    .labelled_by(l.id);
                go |= r.lost_focus() && ui.input(|i| i.key_pressed(egui::Key::Enter));
                controls.push((name.to_owned(), r.rect));
                ui.end_row();
            }
        });
    if go {
        // Enter in a field: a new search, from its first page.
        pacs.search.offset = 0;
    }
    ui.horizontal(|ui| {
        let r = ui.button("Search");
        controls.push(("pacs-search".to_owned(), r.rect));
        if r.clicked() {
            // A new search starts on its first page.
            pacs.search.offset = 0;
            go = true;
        }
        let page = StudySearch::LIMIT;
        if pacs.search.offset > 0 {
            let r = ui.button("Previous");
            controls.push(("pacs-previous".to_owned(), r.rect));
            if r.clicked() {
                pacs.search.offset = pacs.search.offset.saturating_sub(page);
                go = true;
            }
        }
        if pacs.more {
            let r = ui.button(format!("Next {page}"));
            controls.push(("pacs-next".to_owned(), r.rect));
            if r.clicked() {
                pacs.search.offset += page;
                go = true;
            }
        }
        if let Some(b) = &pacs.busy {
            ui.spinner();
            ui.label(b.as_str());
            if ui.small_button("Cancel").clicked() {
                events.push(DialogEvent::Cancel);
            }
        }
    });
    if go {
        events.push(DialogEvent::Search);
    }
    let mut open_study = None;
    if !pacs.studies.is_empty() {
        ui.separator();
        ui.label(egui::RichText::new("Studies").strong());
        egui::ScrollArea::vertical()
            .id_salt("pacs-studies")
            .max_height(160.0)
            .show(ui, |ui| {
                for (i, s) in pacs.studies.iter().enumerate() {
                    let current = pacs
                        .study
                        .as_ref()
                        .is_some_and(|(_, c)| c.study_uid == s.study_uid);
                    let r = ui.selectable_label(current, study_summary(s));
                    controls.push((format!("pacs-study:{i}"), r.rect));
                    if r.clicked() {
                        open_study = Some(s.study_uid.clone());
                    }
                }
            });
    }
    if let Some(study) = open_study {
        let target = PacsTarget {
            base: pacs.server.clone(),
            study,
            series: None,
        };
        events.push(DialogEvent::OpenStudy {
            target,
            auto_open: false,
        });
    }
    let mut retrieve = None;
    if let Some((base, study)) = &pacs.study
        && !pacs.series.is_empty()
    {
        ui.separator();
        ui.label(egui::RichText::new(format!("Series of study {}", study.study_uid)).strong());
        egui::ScrollArea::vertical()
            .id_salt("pacs-series")
            .max_height(200.0)
            .show(ui, |ui| {
                for (i, s) in pacs.series.iter().enumerate() {
                    let mut text = s.summary();
                    if pacs.preselected == Some(i) {
                        text.push_str("  (preselected)");
                    }
                    let r = ui.selectable_label(pacs.selected == Some(i), text);
                    controls.push((format!("pacs-series:{i}"), r.rect));
                    if r.clicked() {
                        pacs.selected = Some(i);
                    }
                    if r.double_clicked() {
                        retrieve = Some(i);
                    }
                }
            });
        let r = ui.add_enabled(pacs.selected.is_some(), egui::Button::new("Open series"));
        controls.push(("pacs-open-series".to_owned(), r.rect));
        if r.clicked() {
            retrieve = pacs.selected;
        }
        if let Some(i) = retrieve
            && let Some(s) = pacs.series.get(i)
        {
            let target = PacsTarget {
                base: base.clone(),
                study: study.study_uid.clone(),
                series: Some(s.series_uid.clone()),
            };
            events.push(DialogEvent::Retrieve(target));
        }
    }
    (events, controls)
}

#[cfg(test)]
mod tests {
    use egui_kittest::Harness;
    use egui_kittest::kittest::Queryable as _;

    use super::*;
    use crate::io::dicomweb::StudyInfo;

    /// The bar asks for the dialog, and offers Cancel only while the archive is busy.
    #[test]
    fn the_bar_opens_the_dialog_and_cancels_only_while_busy() {
        let mut h = Harness::new_ui_state(
            |ui, (busy, events): &mut (bool, Vec<BarEvent>)| {
                let mut controls = Vec::new();
                events.extend(bar_buttons(ui, *busy, &mut controls));
                assert_eq!(controls.len(), 1 + usize::from(*busy));
            },
            (false, Vec::new()),
        );
        assert!(h.query_by_label("Cancel").is_none());
        h.get_by_label("Open from PACS…").click();
        h.run();
        h.state_mut().0 = true;
        h.run();
        h.get_by_label("Cancel").click();
        h.run();
        assert_eq!(h.state().1, vec![BarEvent::OpenDialog, BarEvent::Cancel]);
    }

    /// The dialog asks; it does not search or open itself. "Search" starts again from the first
    /// page, and a study clicked is opened on the server typed.
    #[test]
    fn the_dialog_asks_for_a_search_from_the_first_page_and_for_the_study_clicked() {
        let mut pacs = Pacs {
            server: "https://pacs.example.org/dicom-web".to_owned(),
            ..Pacs::default()
        };
        pacs.search.offset = 40;
        pacs.studies = vec![StudyInfo {
            study_uid: "1.2.3".to_owned(),
            description: Some("CT CHEST".to_owned()),
            ..StudyInfo::default()
        }];
        let mut h = Harness::new_ui_state(
            |ui, (pacs, events): &mut (Pacs, Vec<DialogEvent>)| {
                let (asked, _) = dialog(ui, pacs);
                events.extend(asked);
            },
            (pacs, Vec::new()),
        );
        h.get_by_label("Search").click();
        h.run();
        assert_eq!(h.state().0.search.offset, 0);
        assert_eq!(h.state().1, vec![DialogEvent::Search]);
        h.get_by_label_contains("CT CHEST").click();
        h.run();
        assert_eq!(
            h.state().1,
            vec![
                DialogEvent::Search,
                DialogEvent::OpenStudy {
                    target: PacsTarget {
                        base: "https://pacs.example.org/dicom-web".to_owned(),
                        study: "1.2.3".to_owned(),
                        series: None,
                    },
                    auto_open: false,
                }
            ]
        );
    }
}
