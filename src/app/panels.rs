//! The app's bars and panels: the top bar (open, demo and phantom menu, mode, layout, about),
//! the side panel (features and their parameters, display gains, window), the status bar
//! (mouse and crosshair readouts, progress), the error messages, the about window and the drop
//! overlay.

use super::features::{self, DisplayMode};
use super::{Layout, LoadSource, PaneId, ShapecastApp, SliceKind, WindowPreset, demo};

const FEATURE_NAMES: [&str; 3] = ["vesselness", "airwayness", "blobness"];

impl ShapecastApp {
    pub(super) fn top_bar_ui(&mut self, ui: &mut egui::Ui) {
        egui::MenuBar::new().ui(ui, |ui| {
            ui.heading("Shapecast");
            ui.separator();
            self.open_menu_ui(ui);
            ui.menu_button("Demo", |ui| {
                if ui.button("Demo CT (chest CTA, 1.5 mm)").clicked() {
                    self.open_demo_ct();
                    ui.close();
                }
                ui.separator();
                ui.label("Phantoms of the paper (0.5 mm, HU):");
                for name in crate::phantom::NAMES
                    .iter()
                    .chain(crate::phantom::EXTRA_NAMES.iter())
                {
                    if ui.button(*name).clicked() {
                        self.open(LoadSource::Phantom((*name).to_owned()));
                        ui.close();
                    }
                }
            });
            ui.separator();
            ui.label("Mode:");
            for m in DisplayMode::ALL {
                let r = ui.selectable_label(self.mode == m, m.label());
                let r = match m.method() {
                    Some(method) => {
                        let cached = self.features.find(&self.applied.request(method)).is_some();
                        r.on_hover_text(if cached {
                            "computed: switches at once"
                        } else if method == crate::cpu::pipeline::Method::Rst {
                            "computes the RST features with the current parameters: rays from every voxel, several times the Hessian's time (the status says how long)"
                        } else {
                            "computes the features with the current parameters"
                        })
                    }
                    None => r.on_hover_text("grey values only"),
                };
                self.control(&format!("mode:{}", m.name()), r.rect);
                if r.clicked() && self.mode != m {
                    self.set_mode(m);
                }
            }
            ui.separator();
            ui.label("Layout:");
            let before = self.reading.layout;
            for (layout, label) in [
                (Layout::MipAndSlices, "MIP + slices"),
                (Layout::Grid, "2×2"),
                (Layout::Single(PaneId::Mip), "MIP"),
                (Layout::Single(PaneId::Slice(SliceKind::Axial)), "Axial"),
                (Layout::Single(PaneId::Slice(SliceKind::Coronal)), "Coronal"),
                (
                    Layout::Single(PaneId::Slice(SliceKind::Sagittal)),
                    "Sagittal",
                ),
            ] {
                let r = ui.selectable_label(self.reading.layout == layout, label);
                self.control(&format!("layout:{}", layout.name()), r.rect);
                if r.clicked() {
                    self.reading.layout = layout;
                }
            }
            if self.reading.layout != before && !matches!(self.reading.layout, Layout::Single(_)) {
                self.reading.multi_layout = self.reading.layout;
            }
            ui.separator();
            self.copy_link_ui(ui);
            self.save_picture_ui(ui);
            self.save_movie_ui(ui);
            ui.separator();
            if ui.button("About & data").clicked() {
                self.windows.show_about = !self.windows.show_about;
            }
        });
    }

    pub(super) fn open_demo_ct(&mut self) {
        #[cfg(target_arch = "wasm32")]
        {
            self.load_progress = Some((0.0, "fetching the demo CT".to_owned()));
            super::web_files::fetch_demo();
        }
        #[cfg(not(target_arch = "wasm32"))]
        self.open_from(demo::demo_source(), Some(super::ViewSource::Demo));
    }

    #[cfg(target_arch = "wasm32")]
    fn open_menu_ui(&mut self, ui: &mut egui::Ui) {
        if ui
            .button("Open files…")
            .on_hover_text("a volume file, a header with its data file, or DICOM slices")
            .clicked()
        {
            super::web_files::open_dialog(false);
        }
        if ui
            .button("Open folder…")
            .on_hover_text("a folder holding a DICOM series")
            .clicked()
        {
            super::web_files::open_dialog(true);
        }
    }

    #[cfg(not(target_arch = "wasm32"))]
    fn open_menu_ui(&mut self, ui: &mut egui::Ui) {
        ui.menu_button("Open", |ui| {
            ui.label("A file or a folder (DICOM series), or drop them on the window:");
            let r = ui.add(
                egui::TextEdit::singleline(&mut self.windows.open_path)
                    .hint_text("/path/to/volume.nii.gz or /path/to/dicom-folder")
                    .desired_width(360.0),
            );
            let enter = r.lost_focus() && ui.input(|i| i.key_pressed(egui::Key::Enter));
            if (ui.button("Open").clicked() || enter) && !self.windows.open_path.trim().is_empty() {
                let path = std::path::PathBuf::from(self.windows.open_path.trim());
                self.open(LoadSource::Paths(vec![path]));
                ui.close();
            }
        });
    }

    pub(super) fn side_panel_ui(&mut self, ui: &mut egui::Ui) {
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
                        self.reading.window = super::window_level::default_window(&s.volume);
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
    fn measure_ui(&mut self, ui: &mut egui::Ui) {
        ui.horizontal(|ui| {
            for tool in super::measure::Tool::ALL {
                let r = ui
                    .selectable_label(self.measure.tool == tool, tool.label())
                    .on_hover_text(match tool {
                        super::measure::Tool::Navigate => "a left drag on a slice moves the crosshair (Esc)",
                        super::measure::Tool::Ruler => "a left drag on a slice draws a distance ruler; a click in the MIP measures in 3D from the crosshair to the clicked point (D)",
                        super::measure::Tool::Ellipse => "a left drag on a slice draws an ellipse, corner to corner: mean, SD, min, max and area (E)",
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
                    let axes = super::slices::pane_axes(&scene.volume, pane);
                    self.reading.crosshair[axes.fixed] = p.slice;
                }
                // A ruler in 3D: its far end (the point picked in the MIP).
                (None, _) => {
                    if let Some(v) = super::measure::nearest_voxel(&scene.volume, m.b_mm) {
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
    fn readout(&self, voxel: [usize; 3]) -> String {
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

    pub(super) fn status_bar_ui(&mut self, ui: &mut egui::Ui) {
        ui.horizontal(|ui| {
            ui.label(self.status.phase.as_str());
            if let Some((f, what)) = &self.load_progress {
                ui.add(
                    egui::ProgressBar::new(*f)
                        .desired_width(260.0)
                        .text(what.as_str()),
                );
                #[cfg(target_arch = "wasm32")]
                if super::web_fetch::active() {
                    let r = ui
                        .small_button("Cancel")
                        .on_hover_text("stop the download; the volume shown stays");
                    self.control("cancel-download", r.rect);
                    if r.clicked() {
                        super::web_fetch::cancel();
                    }
                }
            } else if let Some(bar) = self.feature_progress_bar(260.0) {
                ui.add(bar);
                if ui.small_button("Cancel").clicked() {
                    self.features.cancel();
                }
            }
            self.movie_progress_ui(ui);
            if let Some(a) = &self.status.adapter {
                ui.separator();
                ui.label(egui::RichText::new(format!("GPU: {} ({})", a.name, a.backend)).small());
            }
            ui.separator();
            ui.label(format!(
                "W {:.0} L {:.0}",
                self.reading.window.width, self.reading.window.level
            ));
        });
        let mono = egui::TextStyle::Monospace;
        ui.horizontal(|ui| {
            ui.label(egui::RichText::new("mouse     ").text_style(mono.clone()));
            if let Some(h) = self.reading.hover {
                ui.label(egui::RichText::new(self.readout(h)).text_style(mono.clone()));
            }
        });
        ui.horizontal(|ui| {
            ui.label(egui::RichText::new("crosshair ").text_style(mono.clone()));
            if self.scene.is_some() {
                ui.label(
                    egui::RichText::new(self.readout(self.reading.crosshair)).text_style(mono),
                );
            }
        });
    }

    pub(super) fn errors_ui(&mut self, ui: &mut egui::Ui) {
        let mut dismiss = None;
        for (n, e) in self.errors.iter().enumerate() {
            let fill = egui::Color32::from_rgb(70, 25, 25);
            let title = ("Error:", egui::Color32::from_rgb(255, 170, 160));
            if notice_ui(ui, fill, title, e) {
                dismiss = Some(n);
            }
        }
        if let Some(n) = dismiss {
            self.errors.remove(n);
        }
    }

    pub(super) fn about_ui(&mut self, ctx: &egui::Context) {
        let mut open = self.windows.show_about;
        egui::Window::new("About & data")
            .open(&mut open)
            .default_width(520.0)
            .show(ctx, |ui| {
                ui.label(
                    "Shapecast shows shape features of CT and MR volumes (Hessian and radial \
                     structure tensor, after Wiemker et al. 2013) as colour-coded maximum \
                     intensity projections beside linked slice panes. Everything runs on this \
                     machine's GPU; no data leaves it.",
                );
                ui.separator();
                ui.heading("Demo data");
                ui.label(demo::ATTRIBUTION);
                ui.hyperlink_to("Apache License 2.0", demo::LICENCE_URL);
                ui.hyperlink_to(
                    "TotalSegmentator on GitHub",
                    "https://github.com/wasserth/TotalSegmentator",
                );
                ui.separator();
                ui.label(demo::PHANTOM_NOTE);
                ui.separator();
                ui.label(
                    "Use: click a slice to move the crosshair; wheel to change slice; \
                     right-drag (or ctrl-drag) for window/level; 'maximise' shows one pane alone.",
                );
            });
        self.windows.show_about = open;
    }

    pub(super) fn drop_overlay(&self, ctx: &egui::Context) {
        if !self.windows.drop_hover {
            return;
        }
        let screen = ctx.content_rect();
        let painter = ctx.layer_painter(egui::LayerId::new(
            egui::Order::Foreground,
            egui::Id::unique("drop overlay"),
        ));
        painter.rect_filled(screen, 0.0, egui::Color32::from_black_alpha(170));
        painter.text(
            screen.center(),
            egui::Align2::CENTER_CENTER,
            "Drop files or a folder to open them",
            egui::FontId::proportional(24.0),
            egui::Color32::WHITE,
        );
    }

    /// The running feature computation's progress, `width` points wide: "method: stage".
    fn feature_progress_bar(&self, width: f32) -> Option<egui::ProgressBar> {
        let (fraction, stage) = self.features.progress()?;
        let name = self
            .features
            .running_request()
            .map_or("", |r| features::method_name(r.method));
        Some(
            egui::ProgressBar::new(fraction)
                .desired_width(width)
                .text(format!(
                    "{name}: {stage}{}",
                    time_left(self.features.timing())
                )),
        )
    }

    /// Keeps the status bar's feature readback going.
    pub(super) fn update_probe(&mut self) {
        let Some(gpu) = &self.gpu else { return };
        let entry = self
            .displayed_request()
            .and_then(|r| self.features.find(&r));
        let mut voxels = vec![self.reading.crosshair];
        if let Some(h) = self.reading.hover
            && h != self.reading.crosshair
        {
            voxels.push(h);
        }
        self.probe
            .update(gpu, entry.map(|e| (&e.texture, e.id)), voxels);
    }
}

/// ", about 12 s left" from a job's (elapsed, left) seconds; ", estimating the time" before it
/// has progress to go by.
pub(super) fn time_left(timing: Option<(f64, Option<f64>)>) -> String {
    match timing {
        None => String::new(),
        Some((_, None)) => ", estimating the time".to_owned(),
        Some((_, Some(left))) if left < 60.0 => format!(", about {:.0} s left", left.ceil()),
        Some((_, Some(left))) => format!(", about {:.0} min left", (left / 60.0).ceil()),
    }
}

/// A notice in a `fill` frame: a Dismiss button on the right, the title (text, colour), then
/// `text`, wrapped. True when Dismiss was clicked.
pub(super) fn notice_ui(
    ui: &mut egui::Ui,
    fill: egui::Color32,
    title: (&str, egui::Color32),
    text: impl Into<egui::WidgetText>,
) -> bool {
    let mut dismiss = false;
    egui::Frame::new()
        .fill(fill)
        .inner_margin(6.0)
        .corner_radius(4.0)
        .show(ui, |ui| {
            ui.with_layout(egui::Layout::right_to_left(egui::Align::TOP), |ui| {
                dismiss = ui.button("Dismiss").clicked();
                ui.with_layout(egui::Layout::left_to_right(egui::Align::TOP), |ui| {
                    ui.colored_label(title.1, title.0);
                    ui.add(egui::Label::new(text).wrap());
                });
            });
        });
    dismiss
}

/// A closed header `title` over `notes`, one small line each.
fn notes_ui(
    ui: &mut egui::Ui,
    title: impl Into<egui::WidgetText>,
    id_salt: &str,
    notes: &[String],
) {
    egui::CollapsingHeader::new(title)
        .id_salt(id_salt)
        .show(ui, |ui| {
            for n in notes {
                ui.label(egui::RichText::new(n).small());
            }
        });
}
