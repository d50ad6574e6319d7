//! The side panel: the data, the features and their parameters, display gains, the window,
//! and the measurements with their readouts.

use super::*;

impl ShapecastApp {
    pub(in crate::app) fn side_panel_ui(&mut self, ui: &mut egui::Ui) {
        egui::CollapsingHeader::new("Data")
            .default_open(true)
            .show(ui, |ui| {
                match &self.scene {
                    Some(s) => {
                        let v = &s.volume;
                        ui.label(&v.source);
                        ui.label(format!(
                            "{} × {} × {} voxels, {:.3} × {:.3} × {:.3} mm, {}",
                            v.dims[0],
                            v.dims[1],
                            v.dims[2],
                            v.spacing_mm[0],
                            v.spacing_mm[1],
                            v.spacing_mm[2],
                            v.modality.as_str()
                        ));
                    }
                    None => {
                        ui.label("nothing loaded");
                    }
                }
                self.series_ui(ui);
                let controls = self.pet.panel_ui(ui);
                self.controls.extend(controls);
                if !self.notes.is_empty() {
                    let title = format!("Notes ({})", self.notes.len());
                    notes_ui(ui, title, "notes", &self.notes);
                }
            });

        egui::CollapsingHeader::new("Features")
            .default_open(true)
            .show(ui, |ui| {
                ui.horizontal_wrapped(|ui| {
                    for m in DisplayMode::ALL {
                        if ui.selectable_label(self.mode == m, m.label()).clicked()
                            && self.mode != m
                        {
                            self.set_mode(m);
                        }
                    }
                });
                let method = self.mode.method();
                if features::params_ui(ui, &mut self.params, method) {
                    self.recompute();
                }
                if let Some(m) = method
                    && self.params.request(m) != self.applied.request(m)
                {
                    ui.colored_label(
                        ui.visuals().warn_fg_color,
                        "parameters changed: Recompute to apply",
                    );
                }
                if let Some(bar) = self.feature_progress_bar(180.0) {
                    ui.horizontal(|ui| {
                        ui.add(bar);
                        if ui.button("Cancel").clicked() {
                            self.features.cancel();
                        }
                    });
                }
                let (used, budget) = self.features.memory();
                ui.label(
                    egui::RichText::new(format!(
                        "{} method(s) computed and kept ({} MB of GPU memory, budget {} MB: the least recently used goes first); switching to them is instant",
                        self.features.len(),
                        used >> 20,
                        budget >> 20
                    ))
                    .small(),
                );
                if let Some(e) = self.displayed_entry()
                    && !e.notes.is_empty()
                {
                    notes_ui(ui, "How they were computed", "feature notes", &e.notes);
                }
            });

        egui::CollapsingHeader::new("Display")
            .default_open(true)
            .show(ui, |ui| {
                let rgb = crate::render::slice::FEATURE_RGB;
                for c in 0..3 {
                    ui.horizontal(|ui| {
                        let col = egui::Color32::from_rgb(
                            (rgb[c][0] * 255.0) as u8,
                            (rgb[c][1] * 255.0) as u8,
                            (rgb[c][2] * 255.0) as u8,
                        );
                        let (r, _) =
                            ui.allocate_exact_size(egui::vec2(12.0, 12.0), egui::Sense::hover());
                        ui.painter().rect_filled(r, 2.0, col);
                        ui.checkbox(&mut self.display.enabled[c], FEATURE_NAMES[c]);
                        let r = ui.add(
                            egui::Slider::new(&mut self.display.gain[c], 0.1..=10.0)
                                .logarithmic(true)
                                .text("gain"),
                        );
                        self.control(&format!("gain:{c}"), r.rect);
                    });
                }
                // Gain 1 shows the 99.9th percentile of a feature's positive values as full
                // colour (not its maximum: one metal voxel would dim every other structure).
                if let Some(entry) = self.displayed_entry() {
                    let r = entry.texture.reference();
                    ui.label(format!(
                        "gain 1 = full colour at p99.9: V {:.3}, A {:.3}, B {:.3} (max {:.3}, {:.3}, {:.3})",
                        r[0], r[1], r[2], entry.texture.max[0], entry.texture.max[1], entry.texture.max[2]
                    ))
                    .on_hover_text("the 99.9th percentile of each feature's positive values over the volume");
                }
                ui.checkbox(&mut self.display.overlay_on_slices, "overlay on the slices");
                ui.add_enabled(
                    self.display.overlay_on_slices,
                    egui::Slider::new(&mut self.display.opacity, 0.0..=1.0).text("opacity"),
                );
            });

        egui::CollapsingHeader::new("Window")
            .default_open(true)
            .show(ui, |ui| {
                ui.horizontal_wrapped(|ui| {
                    for p in WindowPreset::ALL {
                        let w = p.window();
                        if ui
                            .selectable_label(self.reading.window == w, p.name())
                            .on_hover_text(format!("W {} L {}", w.width, w.level))
                            .clicked()
                        {
                            // The CT presets set the MIP's grey window too.
                            self.reading.window = w;
                            self.mip_view.settings.window = w.bounds();
                        }
                    }
                    if ui
                        .button("auto")
                        .on_hover_text("the volume's default")
                        .clicked()
                        && let Some(s) = &self.scene
                    {
                        self.reading.window = crate::app::window_level::default_window(&s.volume);
                    }
                });
                ui.horizontal(|ui| {
                    let l = ui.label("W");
                    ui.add(
                        egui::DragValue::new(&mut self.reading.window.width)
                            .range(1.0..=100_000.0)
                            .speed(2.0),
                    )
                    .labelled_by(l.id);
                    let l = ui.label("L");
                    ui.add(egui::DragValue::new(&mut self.reading.window.level).speed(2.0))
                        .labelled_by(l.id);
                });
                ui.label(
                    egui::RichText::new(
                        "right-drag (or ctrl-drag) on a slice: sideways = width, up/down = level",
                    )
                    .small(),
                );
            });

        egui::CollapsingHeader::new("Measure")
            .default_open(true)
            .show(ui, |ui| self.measure_ui(ui));

        // Last: a list of up to 30 rows (and "more") pushes no control down.
        egui::CollapsingHeader::new("Findings")
            .default_open(true)
            .show(ui, |ui| {
                let computing = self.computing();
                let (go, controls) = self.findings.panel_ui(ui, self.generation, computing);
                self.controls.extend(controls);
                if let Some(p) = go {
                    self.go_to_lps(p);
                }
            });
    }

    /// The measuring tool and the list of measurements with their positions.
    pub(super) fn measure_ui(&mut self, ui: &mut egui::Ui) {
        ui.horizontal(|ui| {
            for tool in crate::app::measure::Tool::ALL {
                let r = ui
                    .selectable_label(self.measure.tool == tool, tool.label())
                    .on_hover_text(match tool {
                        crate::app::measure::Tool::Navigate => "a left drag on a slice moves the crosshair (Esc)",
                        crate::app::measure::Tool::Ruler => "a left drag on a slice draws a distance ruler; a click in the MIP measures in 3D from the crosshair to the clicked point (D)",
                        crate::app::measure::Tool::Ellipse => "a left drag on a slice draws an ellipse, corner to corner: mean, SD, min, max and area (E)",
                    });
                self.control(&format!("tool:{}", tool.label()), r.rect);
                if r.clicked() {
                    self.measure.tool = tool;
                }
            }
        });
        let Some(scene) = &self.scene else { return };
        let unit = scene.unit();
        let mut remove = None;
        let mut go_to = None;
        for (n, e) in self.measure.list.iter().enumerate() {
            let m = &e.measurement;
            let centre = 0.5 * (m.a_mm + m.b_mm);
            ui.horizontal_wrapped(|ui| {
                if ui.small_button("×").on_hover_text("delete").clicked() {
                    remove = Some(n);
                }
                let r = ui
                    .link(format!("{} {}", n + 1, m.kind.name()))
                    .on_hover_text("show its slice");
                if r.clicked() {
                    go_to = Some(n);
                }
                ui.label(egui::RichText::new(e.reading(unit)).small());
                ui.label(
                    egui::RichText::new(format!(
                        "{} at LPS ({:.1}, {:.1}, {:.1}) mm",
                        m.pane.map_or("3D", SliceKind::name),
                        centre.x,
                        centre.y,
                        centre.z
                    ))
                    .small()
                    .weak(),
                );
            });
        }
        if let Some(n) = go_to {
            let m = self.measure.list[n].measurement;
            match (m.pane, m.in_pane(&scene.volume)) {
                (Some(pane), Some(p)) => {
                    let axes = crate::app::model::axes::pane_axes(&scene.volume, pane);
                    self.reading.crosshair[axes.fixed] = p.slice;
                }
                // A ruler in 3D: its far end (the point picked in the MIP).
                (None, _) => {
                    if let Some(v) = crate::app::measure::nearest_voxel(&scene.volume, m.b_mm) {
                        self.reading.crosshair = v;
                    }
                }
                _ => {}
            }
        }
        if let Some(n) = remove {
            self.measure.list.remove(n);
        }
        if !self.measure.list.is_empty() && ui.small_button("delete all").clicked() {
            self.measure.list.clear();
        }
    }

    /// One line of the status bar: voxel, LPS position, value, features.
    pub(super) fn readout(&self, voxel: [usize; 3]) -> String {
        let Some(scene) = &self.scene else {
            return String::new();
        };
        let v = &scene.volume;
        if (0..3).any(|a| voxel[a] >= v.dims[a]) {
            return String::new();
        }
        let [i, j, k] = voxel;
        let p = v
            .world_from_voxel()
            .transform_point3(glam::DVec3::new(i as f64, j as f64, k as f64));
        let value = crate::volume::format_value(v.value_at(i, j, k), scene.unit());
        let mut s = format!(
            "voxel ({i}, {j}, {k})   LPS ({:.1}, {:.1}, {:.1}) mm   {value}",
            p.x, p.y, p.z
        );
        if let Some(pet) = &self.pet.layer {
            match pet.volume.value_at_world(p) {
                Some(x) => s.push_str(&format!(
                    "   PET {}",
                    crate::volume::format_value(x, pet.unit())
                )),
                None => s.push_str("   PET: outside"),
            }
        }
        if let Some(entry) = self.displayed_entry() {
            match self.probe.value_at(entry.id, voxel) {
                Some([a, b, c]) => s.push_str(&format!(
                    "   {}: V {a:.1}  A {b:.1}  B {c:.1}",
                    self.mode.label()
                )),
                None => s.push_str(&format!("   {}: …", self.mode.label())),
            }
        }
        s
    }
}
