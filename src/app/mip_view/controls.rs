//! The MIP's toolbar: mode, preset views, projection, channels and gains, window, slab.

use super::*;

impl MipView {
    /// The toolbar: mode, preset views, projection, channels and gains, window, slab.
    pub fn controls_ui(&mut self, ui: &mut egui::Ui, scene: &MipScene<'_>) {
        // The first feature set the scene offers is shown unless somebody chose a mode.
        if !self.mode_chosen
            && self.mode.is_none()
            && let Some((name, _)) = scene.features.first()
        {
            self.mode = Some((*name).to_owned());
            self.mode_chosen = true;
        }
        ui.horizontal_wrapped(|ui| {
            let selected = self.mode.clone().unwrap_or_else(|| "Intensity".to_owned());
            egui::ComboBox::from_id_salt("mip mode")
                .selected_text(selected)
                .show_ui(ui, |ui| {
                    if ui
                        .selectable_label(self.mode.is_none(), "Intensity")
                        .clicked()
                    {
                        self.mode = None;
                        self.mode_chosen = true;
                    }
                    for (name, _) in scene.features {
                        let on = self.mode.as_deref() == Some(*name);
                        if ui.selectable_label(on, *name).clicked() {
                            self.mode = Some((*name).to_owned());
                            self.mode_chosen = true;
                        }
                    }
                })
                .response
                .on_hover_text("what the colours show: intensity only, or a feature set");
            ui.separator();
            for (label, preset) in [
                ("A", ViewPreset::Anterior),
                ("P", ViewPreset::Posterior),
                ("L", ViewPreset::Left),
                ("R", ViewPreset::Right),
                ("S", ViewPreset::Superior),
                ("I", ViewPreset::Inferior),
            ] {
                if ui
                    .small_button(label)
                    .on_hover_text(format!("{} view", preset.name()))
                    .clicked()
                {
                    self.camera.set_preset(preset);
                }
            }
            if ui
                .small_button("Reset")
                .on_hover_text("frame the volume, anterior view")
                .clicked()
            {
                self.reset_view(scene.volume);
            }
            ui.separator();
            let mut minip = self.settings.projection == Projection::MinIp;
            if ui
                .checkbox(&mut minip, "MinIP")
                .on_hover_text("minimum intensity projection of the grey (airways)")
                .changed()
            {
                self.settings.projection = if minip {
                    Projection::MinIp
                } else {
                    Projection::Mip
                };
            }
            ui.checkbox(&mut self.settings.show_intensity, "Grey");
            if self.features(scene).is_some() {
                ui.separator();
                for (c, name) in ["Vessels", "Airways", "Blobs"].iter().enumerate() {
                    let [r, g, b] = CHANNEL_COLOURS[c].map(|x| (x * 255.0) as u8);
                    let ch = &mut self.settings.channels[c];
                    ui.checkbox(
                        &mut ch.on,
                        egui::RichText::new(*name).color(egui::Color32::from_rgb(r, g, b)),
                    );
                    ui.add(
                        egui::DragValue::new(&mut ch.gain)
                            .range(0.05..=50.0)
                            .speed(0.02)
                            .prefix("x"),
                    )
                    .on_hover_text("gain: 1 shows the feature's maximum at full colour");
                }
            }
            ui.separator();
            ui.label("W");
            let (mut lo, mut hi) = self.settings.window;
            ui.add(egui::DragValue::new(&mut lo).speed(5.0))
                .on_hover_text("grey window: lowest value (black)");
            ui.add(egui::DragValue::new(&mut hi).speed(5.0))
                .on_hover_text("grey window: highest value (white)");
            if hi > lo {
                self.settings.window = (lo, hi);
            }
            ui.separator();
            let mut slab = self.slab_mm.is_some();
            ui.checkbox(&mut slab, "Slab")
                .on_hover_text("only what lies within the slab around the crosshair");
            if slab {
                let mut t = self.slab_mm.unwrap_or(10.0);
                ui.add(
                    egui::DragValue::new(&mut t)
                        .range(0.5..=2000.0)
                        .speed(0.5)
                        .suffix(" mm"),
                )
                .on_hover_text("slab thickness");
                self.slab_mm = Some(t);
            } else {
                self.slab_mm = None;
            }
        });
    }
}
