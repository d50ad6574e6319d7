//! The panes of the current layout (the slice panes and the MIP), each in its rectangle, with
//! their input (`ShapecastApp::panes_ui`).

use super::*;

/// The panes a layout can show.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PaneId {
    Mip,
    Slice(SliceKind),
}

impl PaneId {
    pub fn name(self) -> &'static str {
        match self {
            Self::Mip => "mip",
            Self::Slice(k) => k.name(),
        }
    }
}

/// How the panes are arranged.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Layout {
    /// The MIP large on the left, the three slice panes stacked on the right (the arrangement
    /// the paper's clinicians preferred: a separate viewport beside the linked slices).
    MipAndSlices,
    /// MIP, axial / coronal, sagittal in a 2x2 grid.
    Grid,
    /// One pane, maximised.
    Single(PaneId),
}

impl Layout {
    pub fn name(self) -> &'static str {
        match self {
            Self::MipAndSlices => "mip+slices",
            Self::Grid => "grid",
            Self::Single(p) => p.name(),
        }
    }
}

impl ShapecastApp {
    /// The panes of the current layout, each in its rectangle.
    pub(super) fn panes_ui(&mut self, ui: &mut egui::Ui, frame: &eframe::Frame) {
        let area = ui.available_rect_before_wrap();
        let Some(scene) = &self.scene else {
            ui.centered_and_justified(|ui| {
                if self.load_progress.is_some() {
                    ui.spinner();
                } else {
                    ui.label("Drop a CT or MR volume here (NIfTI, NRRD, MetaImage, a DICOM folder), or open one from the menu.");
                }
            });
            return;
        };
        let (Some(gpu), Some(render_state), Some(renderer)) =
            (&self.gpu, frame.wgpu_render_state(), &self.slice_renderer)
        else {
            ui.label("no GPU renderer");
            return;
        };
        let gap = 4.0;
        let rects: Vec<(PaneId, egui::Rect)> = match self.reading.layout {
            Layout::MipAndSlices => {
                let split = area.left() + area.width() * 0.58;
                let mip = egui::Rect::from_min_max(
                    area.min,
                    egui::pos2(split - gap * 0.5, area.bottom()),
                );
                let col =
                    egui::Rect::from_min_max(egui::pos2(split + gap * 0.5, area.top()), area.max);
                let h = (col.height() - 2.0 * gap) / 3.0;
                let mut v = vec![(PaneId::Mip, mip)];
                for (n, kind) in SliceKind::ALL.into_iter().enumerate() {
                    let top = col.top() + n as f32 * (h + gap);
                    v.push((
                        PaneId::Slice(kind),
                        egui::Rect::from_min_size(
                            egui::pos2(col.left(), top),
                            egui::vec2(col.width(), h),
                        ),
                    ));
                }
                v
            }
            Layout::Grid => {
                let w = (area.width() - gap) / 2.0;
                let h = (area.height() - gap) / 2.0;
                let cell = |c: f32, r: f32| {
                    egui::Rect::from_min_size(
                        egui::pos2(area.left() + c * (w + gap), area.top() + r * (h + gap)),
                        egui::vec2(w, h),
                    )
                };
                vec![
                    (PaneId::Mip, cell(0.0, 0.0)),
                    (PaneId::Slice(SliceKind::Axial), cell(1.0, 0.0)),
                    (PaneId::Slice(SliceKind::Coronal), cell(0.0, 1.0)),
                    (PaneId::Slice(SliceKind::Sagittal), cell(1.0, 1.0)),
                ]
            }
            Layout::Single(p) => vec![(p, area)],
        };
        // Panes not shown keep no stale rectangle.
        for pane in &mut self.panes {
            pane.image_rect = None;
            pane.area_rect = None;
        }
        let maximised = matches!(self.reading.layout, Layout::Single(_));
        let entry = self
            .displayed_request()
            .and_then(|r| self.features.find(&r));
        let overlay = self.overlay();
        let markers = self.findings.markers(scene.generation);
        let inputs = PaneInputs {
            gpu,
            render_state,
            renderer,
            volume: &scene.volume,
            render_volume: &scene.render,
            generation: scene.generation,
            features: entry.map(|e| (&e.texture, e.id)),
            overlay,
            window: self.reading.window.range(),
            tool: self.measure.tool,
            measurements: &self.measure.list,
            unit: scene.unit(),
            pet: self.pet.layer.as_ref(),
            findings: &markers,
        };
        let mut hover = None;
        let mut toggle = None;
        let mut window_drag = egui::Vec2::ZERO;
        let mut errors = Vec::new();
        let mut measured = Vec::new();
        let mut mip_drawn = false;
        let mut pet_window = None;
        // The crosshair before a click in the MIP, and what the click picked.
        let mut mip_click = None;
        for (id, rect) in &rects {
            let kind = match id {
                PaneId::Mip => None,
                PaneId::Slice(k) => Some(*k),
            };
            self.controls.push((share::pane_control(kind), *rect));
        }
        for (id, rect) in rects {
            let frame_rect = rect.shrink(1.0);
            ui.scope_builder(egui::UiBuilder::new().max_rect(frame_rect), |ui| {
                ui.set_clip_rect(frame_rect);
                egui::Frame::new()
                    .stroke(egui::Stroke::new(1.0, egui::Color32::from_gray(60)))
                    .inner_margin(2.0)
                    .show(ui, |ui| {
                        ui.set_min_size(frame_rect.size() - egui::vec2(6.0, 6.0));
                        match id {
                            PaneId::Slice(kind) => {
                                if let Some(pane) = self.panes.iter_mut().find(|p| p.kind == kind) {
                                    let r = pane.ui(
                                        ui,
                                        &inputs,
                                        &mut self.reading.crosshair,
                                        maximised,
                                    );
                                    hover = hover.or(r.hovered);
                                    window_drag += r.window_drag;
                                    if r.toggle_maximise {
                                        toggle = Some(id);
                                    }
                                    errors.extend(r.error);
                                    measured.extend(r.measured);
                                }
                            }
                            PaneId::Mip => {
                                // With a PET, its MIP (inverted grey, as nuclear-medicine
                                // readers see it) on the left, turning with the shape MIP
                                // (the paper's Fig. 21); a click in it goes to the PET's
                                // hottest point along that ray.
                                let whole = ui.available_rect_before_wrap();
                                let image_top = self.mip_view.image_area().top();
                                let [ci, cj, ck] = self.reading.crosshair;
                                let area = pet::MipArea {
                                    pane: whole,
                                    image_top,
                                    crosshair_mm: Some(
                                        scene.volume.world_from_voxel().transform_point3(
                                            glam::DVec3::new(ci as f64, cj as f64, ck as f64),
                                        ),
                                    ),
                                };
                                let ct_rect = match self.pet_mip.ui(
                                    ui,
                                    area,
                                    gpu,
                                    render_state,
                                    inputs.pet,
                                    &mut self.mip_view.camera,
                                ) {
                                    Some(out) => {
                                        pet_window = Some(out.window);
                                        self.controls.push((
                                            "pane:pet-mip".to_owned(),
                                            self.pet_mip.image_area(),
                                        ));
                                        if let Some(p) = out.pick {
                                            let q =
                                                scene.volume.voxel_from_world().transform_point3(p);
                                            let v = scene.volume.dims;
                                            let voxel: [usize; 3] = std::array::from_fn(|a| {
                                                let c =
                                                    [q.x, q.y, q.z][a].round().max(0.0) as usize;
                                                c.min(v[a].saturating_sub(1))
                                            });
                                            self.reading.crosshair = voxel;
                                        }
                                        out.rest
                                    }
                                    None => whole,
                                };
                                ui.scope_builder(egui::UiBuilder::new().max_rect(ct_rect), |ui| {
                                    // The shape MIP (paper section 5): the displayed method's
                                    // features over the windowed intensity; a click moves the
                                    // crosshair to the 3D point the pixel's maximum came from.
                                    let clicked = ui
                                        .horizontal(|ui| {
                                            ui.label(egui::RichText::new("MIP").strong());
                                            let (icon, tip) = if maximised {
                                                ("restore", "back to all panes")
                                            } else {
                                                ("maximise", "show this pane alone")
                                            };
                                            ui.small_button(icon).on_hover_text(tip).clicked()
                                        })
                                        .inner;
                                    let label = self.mode.label();
                                    let feats: Vec<(&str, &FeatureTexture)> =
                                        entry.map(|e| (label, &e.texture)).into_iter().collect();
                                    self.mip_view.mode = entry.map(|_| label.to_owned());
                                    // The MIP has its own window (set per volume; its W fields
                                    // change it): a soft-tissue window saturates a CT's MIP, where
                                    // contrast, vessels and bone are what should stay apart.
                                    if self.reading.mip_window_for != Some(scene.generation) {
                                        self.reading.mip_window_for = Some(scene.generation);
                                        self.mip_view.settings.window =
                                            default_mip_window(scene, self.reading.window);
                                    }
                                    for c in 0..3 {
                                        self.mip_view.settings.channels[c].on =
                                            self.display.enabled[c];
                                        self.mip_view.settings.channels[c].gain =
                                            self.display.gain[c];
                                    }
                                    let [i, j, k] = self.reading.crosshair;
                                    let centre = scene.volume.world_from_voxel().transform_point3(
                                        glam::DVec3::new(i as f64, j as f64, k as f64),
                                    );
                                    self.mip_view.set_crosshair(Some(centre));
                                    self.mip_view.markers.clone_from(&markers);
                                    // Toolbar above, image below.
                                    let mip_scene = MipScene {
                                        volume: &scene.render,
                                        features: &feats,
                                    };
                                    self.mip_view.controls_ui(ui, &mip_scene);
                                    let out =
                                        self.mip_view.image_ui(ui, gpu, render_state, &mip_scene);
                                    // The toolbar's channel toggles and gains are the display's.
                                    for c in 0..3 {
                                        self.display.enabled[c] =
                                            self.mip_view.settings.channels[c].on;
                                        self.display.gain[c] =
                                            self.mip_view.settings.channels[c].gain;
                                    }
                                    mip_drawn = true;
                                    // The value where the pointer's pixel has its maximum, in the
                                    // image's corner and the status bar's mouse line.
                                    hover = hover.or(out.hover.map(|p| p.voxel));
                                    self.mip_view.hover_text = out.hover.map(|p| {
                                        let [i, j, k] = p.voxel;
                                        let value = scene.volume.value_at(i, j, k);
                                        let mut t = format!(
                                            "{} at voxel ({i}, {j}, {k})",
                                            crate::volume::format_value(value, scene.unit())
                                        );
                                        if let Some(e) = entry
                                            && let Some([a, b, c]) =
                                                self.probe.value_at(e.id, p.voxel)
                                        {
                                            t.push_str(&format!(
                                                "   V {a:.1}  A {b:.1}  B {c:.1}{}",
                                                e.texture.value_note()
                                            ));
                                        }
                                        t
                                    });
                                    if let Some(pick) = out.pick {
                                        mip_click = Some((self.reading.crosshair, pick));
                                        self.reading.crosshair = pick.voxel;
                                    }
                                    measure::draw_rulers_3d(
                                        &ui.painter_at(self.mip_view.image_area()),
                                        inputs.measurements,
                                        |p| self.mip_view.screen_pos_of(p),
                                    );
                                    if clicked {
                                        toggle = Some(id);
                                    }
                                });
                            }
                        }
                    });
            });
        }
        self.reading.hover = hover;
        if let (Some(w), Some(layer)) = (pet_window, &mut self.pet.layer) {
            layer.window = w;
        }
        // The shape MIP turned after the PET's was drawn: one more frame brings the PET along.
        if self.pet.layer.is_some() && self.pet_mip.lags(&self.mip_view.camera) {
            ui.ctx().request_repaint();
        }
        if let Some(s) = &self.scene {
            // With the ruler, a click in the MIP measures in 3D from the crosshair to the point
            // it picked.
            if let Some((before, pick)) = mip_click {
                measured.extend(self.measure.mip_pick(
                    &s.volume,
                    before,
                    pick.voxel,
                    pick.world_mm,
                ));
            }
            for m in measured {
                let pet = self.pet.layer.as_ref().map(|p| p.volume.as_ref());
                self.measure.add(&s.volume, pet, m);
            }
        }
        if mip_drawn {
            self.restore_camera(ui.ctx());
        }
        if window_drag != egui::Vec2::ZERO {
            // The slices show the PET alone: the drag sets the PET's window (in SUV), as on
            // its MIP; otherwise the CT's.
            match &mut self.pet.layer {
                Some(pet) if pet.visible && pet.alone => {
                    pet.window = Window::from_bounds(pet.window)
                        .dragged(window_drag)
                        .bounds();
                }
                _ => self.reading.window = self.reading.window.dragged(window_drag),
            }
        }
        for e in errors {
            self.error(e);
        }
        if let Some(id) = toggle {
            if maximised {
                self.reading.layout = self.reading.multi_layout;
            } else {
                self.reading.multi_layout = self.reading.layout;
                self.reading.layout = Layout::Single(id);
            }
        }
    }
}
