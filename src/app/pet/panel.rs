//! The panel's PET section: what is shown, its window (SUV presets), the opacity, on/off.

use super::*;

impl PetState {
    /// The panel's PET section: what is shown, its window (SUV), the opacity, on/off.
    pub fn panel_ui(&mut self, ui: &mut egui::Ui) -> Vec<(String, egui::Rect)> {
        let mut controls = Vec::new();
        if self.loading() {
            ui.label("PET: loading…");
        }
        let Some(layer) = &mut self.layer else {
            return controls;
        };
        ui.separator();
        ui.strong("PET (fused over the CT)");
        let v = &layer.volume;
        ui.label(format!(
            "{}, {}",
            v.grid_text(),
            match v.pet.as_ref().and_then(|p| p.suv_factor) {
                Some(1.0) => "stored as SUVbw".to_owned(),
                Some(f) => format!("SUVbw (factor {f:.4e})"),
                None => format!("in {} (no SUV)", layer.unit()),
            }
        ));
        let r = ui.checkbox(&mut layer.visible, "show the PET");
        controls.push(("pet-visible".to_owned(), r.rect));
        let r = ui
            .checkbox(&mut layer.alone, "PET alone on the slices")
            .on_hover_text(
                "The slice panes show the PET in inverted grey instead of fused over the CT",
            );
        controls.push(("pet-alone".to_owned(), r.rect));
        let unit = layer.unit().to_owned();
        let (mut lo, mut hi) = layer.window;
        // The sliders' ranges hold the window set (a link's, a PET's own values below 0 or
        // above its maximum), and never clamp it just by being drawn.
        let range = v.value_range().unwrap_or((0.0, 10.0));
        let top = range.1.max(hi).max(lo + 1.0);
        let bottom = range.0.min(lo).min(0.0);
        let r = ui.add(
            egui::Slider::new(&mut hi, bottom..=top)
                .text(format!("window top ({unit})"))
                .clamping(egui::SliderClamping::Never),
        );
        controls.push(("pet-window-hi".to_owned(), r.rect));
        let r = ui.add(
            egui::Slider::new(&mut lo, bottom..=top)
                .text("window bottom")
                .clamping(egui::SliderClamping::Never),
        );
        controls.push(("pet-window-lo".to_owned(), r.rect));
        if hi > lo {
            layer.window = (lo, hi);
        }
        ui.horizontal_wrapped(|ui| {
            for (label, window) in window_presets(&unit, range) {
                let r = ui.selectable_label(layer.window == window, label);
                if r.clicked() {
                    layer.window = window;
                }
                controls.push((format!("pet-preset:{label}"), r.rect));
            }
        });
        let r = ui.add(egui::Slider::new(&mut layer.opacity, 0.0..=1.0).text("opacity"));
        controls.push(("pet-opacity".to_owned(), r.rect));
        for n in &layer.notes {
            ui.label(egui::RichText::new(n).small().weak());
        }
        controls
    }
}

/// The PET window presets a nuclear-medicine reader expects: SUV 0-5 (lymph nodes, lesions
/// beside the mediastinal blood pool), 0-10 (the default), 0-20 (the hot organs: brain,
/// bladder) and the volume's whole range; a PET without SUV gets its whole range only.
pub(super) fn window_presets(unit: &str, range: (f32, f32)) -> Vec<(&'static str, (f32, f32))> {
    let full = (range.0.min(0.0), range.1.max(range.0.min(0.0) + 1.0));
    let mut presets = Vec::new();
    if unit == "SUV" {
        presets.extend([
            ("0-5", (0.0, 5.0)),
            ("0-10", (0.0, 10.0)),
            ("0-20", (0.0, 20.0)),
        ]);
    }
    presets.push(("full", full));
    presets
}
