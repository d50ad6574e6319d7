//! The findings panel (the ranked list, a mark per row) and the markers drawn on the panes.

use super::*;

impl FindingsState {
    /// The panel: the ranked list, a click on a row goes there; a mark per row. Returns where
    /// to send the crosshair, and the controls drawn ("finding:i", "finding:i:confirm",
    /// "finding:i:dismiss").
    pub fn panel_ui(
        &mut self,
        ui: &mut egui::Ui,
        generation: u64,
        computing: bool,
    ) -> (Option<DVec3>, Vec<(String, egui::Rect)>) {
        let mut go = None;
        let mut controls = Vec::new();
        let mut ask = false;
        if let Some(m) = &self.message {
            ui.label(egui::RichText::new(m).weak());
        }
        let rows = self.rows(generation);
        let list = self.list(generation);
        match list {
            Some(l) => {
                ui.label(format!(
                    "{} finding(s) {} ({} blobness, {} preset); score 1 = its 99.9th percentile there",
                    l.findings.findings.len(),
                    l.findings.gate.describe(),
                    method_name(l.method),
                    crate::app::features::preset_label(l.preset),
                ))
                .on_hover_text(format!(
                    "dropped: {} outside, {} dense (mean above {} HU), {} cut by the volume's edge, {} smaller than {} mm; made in {:.2} s",
                    l.findings.outside,
                    l.findings.dense,
                    crate::cpu::findings::DENSE_ABOVE_HU,
                    l.findings.cut,
                    l.findings.small,
                    crate::cpu::findings::SMALLEST_MM,
                    l.seconds
                ));
            }
            None if self.busy() => {
                ui.label("reading the features…");
            }
            None if !self.asked && self.message.is_none() => {
                let r = ui
                    .button("List findings")
                    .on_hover_text("rank the round candidates of the features shown (N goes to the next); a large CT takes a few seconds");
                controls.push(("findings:list".to_owned(), r.rect));
                ask = r.clicked();
            }
            None if !rows.is_empty() => {
                ui.label("from the link; the list is made when the features are computed");
            }
            None if computing => {
                ui.label("made when the features are computed");
            }
            None if self.message.is_none() => {
                ui.label("show a feature (Hessian, Li or RST) to list its findings");
            }
            None => {}
        }
        let texts: Vec<String> = rows
            .iter()
            .enumerate()
            .map(
                |(i, (p, _, number))| match list.and_then(|l| l.findings.findings.get(i)) {
                    Some(f) => format!(
                        "{number}. score {:.1}, {:.0} mm{}, {:.0} HU",
                        f.score,
                        f.diameter_mm,
                        if f.bounded { "+" } else { "" },
                        f.mean_hu
                    ),
                    None => format!("{number}. {:.0}, {:.0}, {:.0} mm", p.x, p.y, p.z),
                },
            )
            .collect();
        let more = list.map_or(0, |l| l.findings.findings.len().saturating_sub(rows.len()));
        let pet_note = list.and_then(|l| l.pet_note.clone());
        // The PET's hot spots, as text (the list is borrowed no further).
        let pet_rows = list.and_then(|l| l.hot_spots.as_ref()).map(|spots| {
            let n = if self.show_all {
                spots.spots.len()
            } else {
                SHOWN
            };
            let rows: Vec<(String, String, DVec3)> = spots
                .spots
                .iter()
                .take(n)
                .map(|h| {
                    let shape = h.ct_shape();
                    (
                        format!(
                            "P{}. SUVpeak {:.1}, {:.0} ml, {shape}",
                            h.rank, h.suv_peak, h.volume_ml
                        ),
                        format!(
                            "SUVmax {:.1}; CT blobness score {}",
                            h.suv_max,
                            h.ct_score.map_or("-".to_owned(), |s| format!("{s:.2}"))
                        ),
                        h.lps_mm,
                    )
                })
                .collect();
            (
                format!(
                    "{} PET hot spot(s), SUVpeak above {:.2}{}",
                    spots.spots.len(),
                    spots.reference.threshold,
                    if spots.reference.liver.is_some() {
                        " (PERCIST, liver)"
                    } else {
                        " (no liver in the PET)"
                    }
                ),
                spots.reference.rule(),
                rows,
            )
        });
        let mut current = self.current;
        let mut marks = Vec::new();
        egui::Grid::new("findings")
            .num_columns(4)
            .striped(true)
            .show(ui, |ui| {
                for (i, ((p, mark, _), text)) in rows.iter().zip(texts).enumerate() {
                    let strike = *mark == Mark::Dismissed;
                    let mut rich = egui::RichText::new(text);
                    if strike {
                        rich = rich.strikethrough().weak();
                    }
                    let r = ui.selectable_label(current == Some(i), rich);
                    controls.push((format!("finding:{i}"), r.rect));
                    if r.clicked() {
                        current = Some(i);
                        go = Some(*p);
                    }
                    let c = ui
                        .selectable_label(*mark == Mark::Confirmed, "confirm")
                        .on_hover_text("confirm: a finding you agree with");
                    controls.push((format!("finding:{i}:confirm"), c.rect));
                    if c.clicked() {
                        marks.push((i, toggle(*mark, Mark::Confirmed)));
                    }
                    let d = ui
                        .selectable_label(*mark == Mark::Dismissed, "dismiss")
                        .on_hover_text("dismiss (N skips it)");
                    controls.push((format!("finding:{i}:dismiss"), d.rect));
                    if d.clicked() {
                        marks.push((i, toggle(*mark, Mark::Dismissed)));
                    }
                    ui.end_row();
                }
            });
        self.current = current;
        if more > 0 && ui.button(format!("{more} more")).clicked() {
            self.show_all = true;
        }
        for (i, m) in marks {
            self.set_mark(generation, i, m);
        }
        if !rows.is_empty() {
            ui.label(egui::RichText::new("N / Shift+N: next / previous finding").weak());
        }
        if let Some(note) = pet_note {
            ui.separator();
            ui.label(note);
        }
        if let Some((title, rule, pet_rows)) = pet_rows {
            ui.separator();
            ui.label(title).on_hover_text(rule);
            for (i, (text, hover, at)) in pet_rows.into_iter().enumerate() {
                let r = ui.selectable_label(false, text).on_hover_text(hover);
                controls.push((format!("hot-spot:{i}"), r.rect));
                if r.clicked() {
                    go = Some(at);
                }
            }
        }
        self.asked |= ask;
        (go, controls)
    }
}

pub(super) fn toggle(now: Mark, to: Mark) -> Mark {
    if now == to { Mark::Open } else { to }
}

/// Draws the findings' markers on a slice pane: a ring (the finding's size) with its number
/// where the slice crosses the finding. `screen_of` maps LPS mm to the pane (with the distance
/// from the slice plane, mm); `px_per_mm` the pane's scale.
pub fn draw_markers(
    painter: &egui::Painter,
    markers: &[Marker],
    px_per_mm: f32,
    screen_of: impl Fn(DVec3) -> Option<(egui::Pos2, f64)>,
) {
    for m in markers {
        let Some((p, off)) = screen_of(m.lps_mm) else {
            continue;
        };
        if off.abs() > m.radius_mm {
            continue;
        }
        // The ring is the finding's section in this slice.
        let r = (m.radius_mm * m.radius_mm - off * off).sqrt() as f32 * px_per_mm;
        draw_one(painter, m, p, r.max(6.0));
    }
}

/// One marker: a ring of radius `r` px at `p`, its number beside it, coloured by its mark (a
/// PET hot spot: magenta, dashed, numbered "P1", "P2", ... as in the panel).
pub fn draw_one(painter: &egui::Painter, m: &Marker, p: egui::Pos2, r: f32) {
    let colour = match m.mark {
        _ if m.hot_spot => egui::Color32::from_rgb(240, 80, 230),
        Mark::Open => egui::Color32::from_rgb(255, 170, 40),
        Mark::Confirmed => egui::Color32::from_rgb(90, 230, 90),
        Mark::Dismissed => egui::Color32::from_gray(130),
    };
    let width = if m.current { 2.5 } else { 1.5 };
    if m.hot_spot {
        // Dashed: 16 arcs, so that a hot spot on a finding stays visible beside its ring.
        let n = 16;
        for k in 0..n {
            let a0 = std::f32::consts::TAU * k as f32 / n as f32;
            let a1 = a0 + 0.6 * std::f32::consts::TAU / n as f32;
            let at = |a: f32| p + r * egui::vec2(a.cos(), a.sin());
            painter.line_segment([at(a0), at(a1)], egui::Stroke::new(width, colour));
        }
    } else {
        painter.circle_stroke(p, r, egui::Stroke::new(width, colour));
    }
    let label = if m.hot_spot {
        format!("P{}", m.number)
    } else {
        m.number.to_string()
    };
    painter.text(
        p + egui::vec2(r * 0.75 + 2.0, -r * 0.75 - 2.0),
        egui::Align2::LEFT_BOTTOM,
        label,
        egui::FontId::proportional(if m.current { 15.0 } else { 13.0 }),
        colour,
    );
}
