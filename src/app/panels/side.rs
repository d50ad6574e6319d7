//! The side panel: the data, the features and their parameters, display gains, the window,
//! and the measurements with their readouts. Its sections are widgets: each takes its own state
//! (`&mut`) and what it shows, and returns what the user asked of the rest of the app as
//! [`SideEvent`]s, which [`ShapecastApp::side_panel_ui`] applies once the panel is drawn.

use super::*;
use crate::app::features::{FeatureDisplay, FeatureParams};
use crate::app::measure::{self, Tool};
use crate::app::window_level::Window;

/// What the user asked for in the side panel, applied after it is drawn.
#[derive(Clone, Debug, PartialEq)]
pub(in crate::app) enum SideEvent {
    /// Show another display mode.
    Mode(DisplayMode),
    /// Compute the edited parameters now.
    Recompute,
    /// Stop the running feature computation.
    CancelFeatures,
    /// A window preset: the slices' window and the MIP's grey window.
    WindowPreset(Window),
    /// The volume's default window.
    AutoWindow,
    /// Show measurement `n`'s slice (a 3D ruler: its far end).
    ShowMeasurement(usize),
    /// Delete measurement `n`; `None`: all of them.
    DeleteMeasurement(Option<usize>),
    /// Go to a point, LPS mm (a finding).
    GoTo(glam::DVec3),
}

/// What the features section shows besides the parameters it edits.
pub(in crate::app) struct FeaturesShown<'a> {
    pub mode: DisplayMode,
    /// The parameters of the features shown (edits differ until recomputed).
    pub applied: &'a FeatureParams,
    pub progress: Option<egui::ProgressBar>,
    /// Methods kept, their GPU bytes and the budget.
    pub kept: (usize, u64, u64),
    /// How the features shown were computed.
    pub notes: &'a [String],
}

/// The display mode, the parameters (edited in place), the running job and what is kept.
pub(in crate::app) fn features_section(
    ui: &mut egui::Ui,
    params: &mut FeatureParams,
    shown: FeaturesShown<'_>,
) -> Vec<SideEvent> {
    let mut events = Vec::new();
    ui.horizontal_wrapped(|ui| {
        for m in DisplayMode::ALL {
            if ui.selectable_label(shown.mode == m, m.label()).clicked() && shown.mode != m {
                events.push(SideEvent::Mode(m));
            }
        }
    });
    let method = shown.mode.method();
    if features::params_ui(ui, params, method) {
        events.push(SideEvent::Recompute);
    }
    if let Some(m) = method
        && params.request(m) != shown.applied.request(m)
    {
        ui.colored_label(
            ui.visuals().warn_fg_color,
            "parameters changed: Recompute to apply",
        );
    }
    if let Some(bar) = shown.progress {
        ui.horizontal(|ui| {
            ui.add(bar);
            if ui.button("Cancel").clicked() {
                events.push(SideEvent::CancelFeatures);
            }
        });
    }
    let (count, used, budget) = shown.kept;
    ui.label(
        egui::RichText::new(format!(
            "{count} method(s) computed and kept ({} MB of GPU memory, budget {} MB: the least recently used goes first); switching to them is instant",
            used >> 20,
            budget >> 20
        ))
        .small(),
    );
    if !shown.notes.is_empty() {
        notes_ui(ui, "How they were computed", "feature notes", shown.notes);
    }
    events
}

/// Each feature's colour, switch and gain (edited in place), and the overlay on the slices;
/// `reference`: the p99.9 and the maximum of each feature shown. Returns the gains' sliders as
/// named controls.
pub(in crate::app) fn display_section(
    ui: &mut egui::Ui,
    display: &mut FeatureDisplay,
    reference: Option<([f32; 3], [f32; 3])>,
) -> Vec<(String, egui::Rect)> {
    let mut controls = Vec::new();
    let rgb = crate::render::slice::FEATURE_RGB;
    for c in 0..3 {
        ui.horizontal(|ui| {
            let col = egui::Color32::from_rgb(
                (rgb[c][0] * 255.0) as u8,
                (rgb[c][1] * 255.0) as u8,
                (rgb[c][2] * 255.0) as u8,
            );
            let (r, _) = ui.allocate_exact_size(egui::vec2(12.0, 12.0), egui::Sense::hover());
            ui.painter().rect_filled(r, 2.0, col);
            ui.checkbox(&mut display.enabled[c], FEATURE_NAMES[c]);
            let r = ui.add(
                egui::Slider::new(&mut display.gain[c], 0.1..=10.0)
                    .logarithmic(true)
                    .text("gain"),
            );
            controls.push((format!("gain:{c}"), r.rect));
        });
    }
    // Gain 1 shows the 99.9th percentile of a feature's positive values as full colour (not
    // its maximum: one metal voxel would dim every other structure).
    if let Some((r, max)) = reference {
        ui.label(format!(
            "gain 1 = full colour at p99.9: V {:.3}, A {:.3}, B {:.3} (max {:.3}, {:.3}, {:.3})",
            r[0], r[1], r[2], max[0], max[1], max[2]
        ))
        .on_hover_text("the 99.9th percentile of each feature's positive values over the volume");
    }
    ui.checkbox(&mut display.overlay_on_slices, "overlay on the slices");
    ui.add_enabled(
        display.overlay_on_slices,
        egui::Slider::new(&mut display.opacity, 0.0..=1.0).text("opacity"),
    );
    controls
}

/// The window presets, "auto" (with a volume) and width and level (edited in place).
pub(in crate::app) fn window_section(
    ui: &mut egui::Ui,
    window: &mut Window,
    has_volume: bool,
) -> Option<SideEvent> {
    let mut event = None;
    ui.horizontal_wrapped(|ui| {
        for p in WindowPreset::ALL {
            let w = p.window();
            if ui
                .selectable_label(*window == w, p.name())
                .on_hover_text(format!("W {} L {}", w.width, w.level))
                .clicked()
            {
                // The CT presets set the MIP's grey window too.
                event = Some(SideEvent::WindowPreset(w));
            }
        }
        if ui
            .button("auto")
            .on_hover_text("the volume's default")
            .clicked()
            && has_volume
        {
            event = Some(SideEvent::AutoWindow);
        }
    });
    ui.horizontal(|ui| {
        let l = ui.label("W");
        ui.add(
            egui::DragValue::new(&mut window.width)
                .range(1.0..=100_000.0)
                .speed(2.0),
        )
        .labelled_by(l.id);
        let l = ui.label("L");
        ui.add(egui::DragValue::new(&mut window.level).speed(2.0))
            .labelled_by(l.id);
    });
    ui.label(
        egui::RichText::new(
            "right-drag (or ctrl-drag) on a slice: sideways = width, up/down = level",
        )
        .small(),
    );
    event
}

/// The measuring tool (chosen in place) and the list of measurements with their readings in
/// `unit` (`None`: no volume, no list). Returns the tools' buttons as named controls.
pub(in crate::app) fn measure_section(
    ui: &mut egui::Ui,
    tool: &mut Tool,
    list: &[measure::Entry],
    unit: Option<&str>,
) -> (Vec<SideEvent>, Vec<(String, egui::Rect)>) {
    let mut events = Vec::new();
    let mut controls = Vec::new();
    ui.horizontal(|ui| {
        for t in Tool::ALL {
            let r = ui
                .selectable_label(*tool == t, t.label())
                .on_hover_text(match t {
                    Tool::Navigate => "a left drag on a slice moves the crosshair (Esc)",
                    Tool::Ruler => "a left drag on a slice draws a distance ruler; a click in the MIP measures in 3D from the crosshair to the clicked point (D)",
                    Tool::Ellipse => "a left drag on a slice draws an ellipse, corner to corner: mean, SD, min, max and area (E)",
                });
            controls.push((format!("tool:{}", t.label()), r.rect));
            if r.clicked() {
                *tool = t;
            }
        }
    });
    let Some(unit) = unit else {
        return (events, controls);
    };
    for (n, e) in list.iter().enumerate() {
        let m = &e.measurement;
        let centre = 0.5 * (m.a_mm + m.b_mm);
        ui.horizontal_wrapped(|ui| {
            if ui.small_button("×").on_hover_text("delete").clicked() {
                events.push(SideEvent::DeleteMeasurement(Some(n)));
            }
            let r = ui
                .link(format!("{} {}", n + 1, m.kind.name()))
                .on_hover_text("show its slice");
            if r.clicked() {
                events.push(SideEvent::ShowMeasurement(n));
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
    if !list.is_empty() && ui.small_button("delete all").clicked() {
        events.push(SideEvent::DeleteMeasurement(None));
    }
    (events, controls)
}

impl ShapecastApp {
    /// Draws the side panel's sections, then applies what the user asked for in them.
    pub(in crate::app) fn side_panel_ui(&mut self, ui: &mut egui::Ui) {
        let mut events = Vec::new();
        egui::CollapsingHeader::new("Data")
            .default_open(true)
            .show(ui, |ui| {
                match &self.scene {
                    Some(s) => {
                        let v = &s.volume;
                        ui.label(&v.source);
                        ui.label(format!("{}, {}", v.grid_text(), v.modality.as_str()));
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

        let entry = self.displayed_entry();
        let notes = entry.map(|e| e.notes.clone()).unwrap_or_default();
        let reference = entry.map(|e| (e.texture.reference(), e.texture.max));
        let shown = FeaturesShown {
            mode: self.mode,
            applied: &self.applied,
            progress: self.feature_progress_bar(180.0),
            kept: {
                let (used, budget) = self.features.memory();
                (self.features.len(), used, budget)
            },
            notes: &notes,
        };
        egui::CollapsingHeader::new("Features")
            .default_open(true)
            .show(ui, |ui| {
                events.extend(features_section(ui, &mut self.params, shown));
            });

        egui::CollapsingHeader::new("Display")
            .default_open(true)
            .show(ui, |ui| {
                let controls = display_section(ui, &mut self.display, reference);
                self.controls.extend(controls);
            });

        egui::CollapsingHeader::new("Window")
            .default_open(true)
            .show(ui, |ui| {
                let has_volume = self.scene.is_some();
                events.extend(window_section(ui, &mut self.reading.window, has_volume));
            });

        egui::CollapsingHeader::new("Measure")
            .default_open(true)
            .show(ui, |ui| {
                let unit = self.scene.as_ref().map(|s| s.unit().to_owned());
                let (measured, controls) = measure_section(
                    ui,
                    &mut self.measure.tool,
                    &self.measure.list,
                    unit.as_deref(),
                );
                events.extend(measured);
                self.controls.extend(controls);
            });

        // Last: a list of up to 30 rows (and "more") pushes no control down.
        egui::CollapsingHeader::new("Findings")
            .default_open(true)
            .show(ui, |ui| {
                let computing = self.computing();
                let (go, controls) = self.findings.panel_ui(ui, self.generation, computing);
                self.controls.extend(controls);
                events.extend(go.map(SideEvent::GoTo));
            });

        for e in events {
            self.apply_side_event(e);
        }
    }

    fn apply_side_event(&mut self, event: SideEvent) {
        match event {
            SideEvent::Mode(m) => {
                if self.mode != m {
                    self.set_mode(m);
                }
            }
            SideEvent::Recompute => self.recompute(),
            SideEvent::CancelFeatures => self.features.cancel(),
            SideEvent::WindowPreset(w) => {
                self.reading.window = w;
                self.mip_view.settings.window = w.bounds();
            }
            SideEvent::AutoWindow => {
                if let Some(s) = &self.scene {
                    self.reading.window = crate::app::window_level::default_window(&s.volume);
                }
            }
            SideEvent::ShowMeasurement(n) => self.show_measurement(n),
            SideEvent::DeleteMeasurement(Some(n)) => {
                if n < self.measure.list.len() {
                    self.measure.list.remove(n);
                }
            }
            SideEvent::DeleteMeasurement(None) => self.measure.list.clear(),
            SideEvent::GoTo(p) => self.go_to_lps(p),
        }
    }

    /// Moves the crosshair to measurement `n`'s slice (a ruler in 3D: to its far end, the
    /// point picked in the MIP).
    fn show_measurement(&mut self, n: usize) {
        let (Some(scene), Some(e)) = (&self.scene, self.measure.list.get(n)) else {
            return;
        };
        let m = e.measurement;
        match (m.pane, m.in_pane(&scene.volume)) {
            (Some(pane), Some(p)) => {
                let axes = crate::app::model::axes::pane_axes(&scene.volume, pane);
                self.reading.crosshair[axes.fixed] = p.slice;
            }
            (None, _) => {
                if let Some(v) = measure::nearest_voxel(&scene.volume, m.b_mm) {
                    self.reading.crosshair = v;
                }
            }
            _ => {}
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
                    "   {}: V {a:.1}  A {b:.1}  B {c:.1}{}",
                    self.mode.label(),
                    entry.texture.value_note()
                )),
                None => s.push_str(&format!("   {}: …", self.mode.label())),
            }
        }
        s
    }
}

#[cfg(test)]
mod tests {
    use egui_kittest::Harness;
    use egui_kittest::kittest::Queryable as _;

    use super::*;
    use crate::app::measure::{Entry, MeasureKind, Measurement};

    /// The window section: a preset is asked for (not set here: the app sets the MIP's window
    /// too), width and level are the section's own state, "auto" needs a volume.
    #[test]
    fn the_window_section_asks_for_presets_and_auto_only_with_a_volume() {
        let state = (Window::from_bounds((-1000.0, 200.0)), Vec::new(), true);
        let mut h = Harness::new_ui_state(
            |ui, (window, events, has_volume): &mut (Window, Vec<SideEvent>, bool)| {
                events.extend(window_section(ui, window, *has_volume));
            },
            state,
        );
        h.get_by_label("bone").click();
        h.run();
        let bone = WindowPreset::Bone.window();
        assert_eq!(h.state().1, vec![SideEvent::WindowPreset(bone)]);
        assert_ne!(
            h.state().0,
            bone,
            "the app applies the preset, not the section"
        );
        h.get_by_label("auto").click();
        h.run();
        assert_eq!(h.state().1.last(), Some(&SideEvent::AutoWindow));
        h.state_mut().1.clear();
        h.state_mut().2 = false;
        h.run();
        h.get_by_label("auto").click();
        h.run();
        assert!(h.state().1.is_empty(), "{:?}", h.state().1);
    }

    /// The measure section: the tool is its own state; deleting and showing are asked for.
    #[test]
    fn the_measure_section_chooses_the_tool_and_asks_to_show_and_delete() {
        let ruler = Entry {
            measurement: Measurement {
                kind: MeasureKind::Ruler,
                pane: Some(SliceKind::Axial),
                a_mm: glam::DVec3::ZERO,
                b_mm: glam::DVec3::new(30.0, 40.0, 0.0),
            },
            stats: None,
            pet: None,
        };
        let list = vec![ruler.clone(), ruler];
        let mut h = Harness::new_ui_state(
            move |ui, (tool, events): &mut (Tool, Vec<SideEvent>)| {
                let (asked, controls) = measure_section(ui, tool, &list, Some("HU"));
                assert_eq!(controls.len(), Tool::ALL.len());
                events.extend(asked);
            },
            (Tool::Navigate, Vec::new()),
        );
        h.get_by_label(Tool::Ellipse.label()).click();
        h.run();
        assert_eq!(h.state().0, Tool::Ellipse);
        h.get_by_label("2 ruler").click();
        h.run();
        h.get_by_label("delete all").click();
        h.run();
        assert_eq!(
            h.state().1,
            vec![
                SideEvent::ShowMeasurement(1),
                SideEvent::DeleteMeasurement(None)
            ]
        );
    }
}
