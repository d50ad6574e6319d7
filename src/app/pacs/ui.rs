//! The PACS bar above the panes ("Open from PACS…", Cancel, "Store to PACS" for a series from an
//! archive, the patient line) and the dialog: server, token, study search, studies, series.

use super::{PacsTarget, patient_line, study_summary};
use crate::app::ShapecastApp;
use crate::io::dicomweb::StudySearch;

impl ShapecastApp {
    /// The bar above the panes: "Open from PACS…", the retrieval's Cancel, "Store to PACS",
    /// the patient line.
    pub(in crate::app) fn pacs_bar_ui(&mut self, ui: &mut egui::Ui) {
        ui.horizontal(|ui| {
            let r = ui
                .button("Open from PACS…")
                .on_hover_text("find a study in an archive over DICOMweb (QIDO-RS) and open one of its series (WADO-RS)");
            self.control("open-pacs", r.rect);
            if r.clicked() {
                self.pacs.dialog = true;
            }
            if self.pacs.busy.is_some() {
                let r = ui
                    .small_button("Cancel")
                    .on_hover_text("stop the archive's requests; the volume shown stays");
                self.control("cancel-pacs", r.rect);
                if r.clicked() {
                    self.cancel_dicomweb();
                }
            }
            self.store_pacs_ui(ui);
            if let Some(line) = self.pacs.patient.as_ref().and_then(patient_line) {
                ui.separator();
                ui.label(egui::RichText::new(line).strong())
                    .on_hover_text("from the study's DICOM header; shown on this screen only, never put into a link or sent anywhere");
            }
        });
    }

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
        egui::Grid::new("pacs-server")
            .num_columns(2)
            .show(ui, |ui| {
                let l = ui.label("DICOMweb server");
                let r = ui
                    .add(
                        egui::TextEdit::singleline(&mut self.pacs.server)
                            .hint_text("/dicom-web, or https://pacs.example.org/dicom-web")
                            .desired_width(420.0),
                    )
                    .labelled_by(l.id);
                self.control("pacs-server", r.rect);
                ui.end_row();
                let l = ui.label("Bearer token");
                let r = ui
                    .add(
                        egui::TextEdit::singleline(&mut self.pacs.token)
                            .password(true)
                            .hint_text("optional; never put into a link")
                            .desired_width(420.0),
                    )
                    .labelled_by(l.id);
                self.control("pacs-token", r.rect);
                ui.end_row();
            });
        if let Some(m) = &self.pacs.message {
            let colour = if self.pacs.needs_token {
                egui::Color32::from_rgb(255, 190, 90)
            } else {
                egui::Color32::from_rgb(255, 140, 140)
            };
            ui.colored_label(colour, m);
        }
        if self.pacs.needs_token
            && let Some((target, auto_open)) = self.pacs.last.clone()
        {
            let enabled = !self.pacs.token.trim().is_empty() && self.pacs.busy.is_none();
            let r = ui.add_enabled(enabled, egui::Button::new("Open again with the token"));
            // Published only when it can be clicked (a token typed), for automation.
            if enabled {
                self.control("pacs-retry", r.rect);
            }
            if r.clicked() {
                self.pacs.needs_token = false;
                match target.series {
                    Some(_) if auto_open => self.pacs_retrieve(target),
                    _ => self.pacs_open_study(target, auto_open),
                }
            }
        }
        ui.separator();
        ui.label(egui::RichText::new("Find a study").strong());
        let mut go = false;
        egui::Grid::new("pacs-search")
            .num_columns(2)
            .show(ui, |ui| {
                for (label, value, hint, name) in [
                    (
                        "Patient ID",
                        &mut self.pacs.search.patient_id,
                        "e.g. 12345 or 123*",
                        "pacs-patient-id",
                    ),
                    (
                        "Patient name",
                        &mut self.pacs.search.patient_name,
                        "e.g. DOE^JANE or DOE*",
                        "pacs-patient-name",
                    ),
                    (
                        "Accession number",
                        &mut self.pacs.search.accession_number,
                        "",
                        "pacs-accession",
                    ),
                    (
                        "Modality",
                        &mut self.pacs.search.modality,
                        "e.g. CT, MR or PT",
                        "pacs-modality",
                    ),
                    (
                        "Study date",
                        &mut self.pacs.search.study_date,
                        "YYYYMMDD or YYYYMMDD-YYYYMMDD",
                        "pacs-date",
                    ),
                ] {
                    let l = ui.label(label);
                    let r = ui
                        .add(
                            egui::TextEdit::singleline(value)
                                .hint_text(hint)
                                .desired_width(260.0),
                        )
                        .labelled_by(l.id);
                    go |= r.lost_focus() && ui.input(|i| i.key_pressed(egui::Key::Enter));
                    self.controls.push((name.to_owned(), r.rect));
                    ui.end_row();
                }
            });
        if go {
            // Enter in a field: a new search, from its first page.
            self.pacs.search.offset = 0;
        }
        ui.horizontal(|ui| {
            let r = ui.button("Search");
            self.control("pacs-search", r.rect);
            if r.clicked() {
                // A new search starts on its first page.
                self.pacs.search.offset = 0;
                go = true;
            }
            let page = StudySearch::LIMIT;
            if self.pacs.search.offset > 0 {
                let r = ui.button("Previous");
                self.control("pacs-previous", r.rect);
                if r.clicked() {
                    self.pacs.search.offset = self.pacs.search.offset.saturating_sub(page);
                    go = true;
                }
            }
            if self.pacs.more {
                let r = ui.button(format!("Next {page}"));
                self.control("pacs-next", r.rect);
                if r.clicked() {
                    self.pacs.search.offset += page;
                    go = true;
                }
            }
            if let Some(b) = &self.pacs.busy {
                ui.spinner();
                ui.label(b.as_str());
                if ui.small_button("Cancel").clicked() {
                    self.cancel_dicomweb();
                }
            }
        });
        if go {
            self.pacs_search();
        }
        let mut open_study = None;
        if !self.pacs.studies.is_empty() {
            ui.separator();
            ui.label(egui::RichText::new("Studies").strong());
            egui::ScrollArea::vertical()
                .id_salt("pacs-studies")
                .max_height(160.0)
                .show(ui, |ui| {
                    for (i, s) in self.pacs.studies.iter().enumerate() {
                        let current = self
                            .pacs
                            .study
                            .as_ref()
                            .is_some_and(|(_, c)| c.study_uid == s.study_uid);
                        let r = ui.selectable_label(current, study_summary(s));
                        self.controls.push((format!("pacs-study:{i}"), r.rect));
                        if r.clicked() {
                            open_study = Some(s.study_uid.clone());
                        }
                    }
                });
        }
        if let Some(study) = open_study {
            let target = PacsTarget {
                base: self.pacs.server.clone(),
                study,
                series: None,
            };
            self.pacs_open_study(target, false);
        }
        let mut retrieve = None;
        if let Some((base, study)) = &self.pacs.study
            && !self.pacs.series.is_empty()
        {
            ui.separator();
            ui.label(egui::RichText::new(format!("Series of study {}", study.study_uid)).strong());
            egui::ScrollArea::vertical()
                .id_salt("pacs-series")
                .max_height(200.0)
                .show(ui, |ui| {
                    for (i, s) in self.pacs.series.iter().enumerate() {
                        let mut text = s.summary();
                        if self.pacs.preselected == Some(i) {
                            text.push_str("  (preselected)");
                        }
                        let r = ui.selectable_label(self.pacs.selected == Some(i), text);
                        self.controls.push((format!("pacs-series:{i}"), r.rect));
                        if r.clicked() {
                            self.pacs.selected = Some(i);
                        }
                        if r.double_clicked() {
                            retrieve = Some(i);
                        }
                    }
                });
            let r = ui.add_enabled(
                self.pacs.selected.is_some(),
                egui::Button::new("Open series"),
            );
            self.controls.push(("pacs-open-series".to_owned(), r.rect));
            if r.clicked() {
                retrieve = self.pacs.selected;
            }
            if let Some(i) = retrieve
                && let Some(s) = self.pacs.series.get(i)
            {
                let target = PacsTarget {
                    base: base.clone(),
                    study: study.study_uid.clone(),
                    series: Some(s.series_uid.clone()),
                };
                self.pacs_retrieve(target);
            }
        }
    }
}
