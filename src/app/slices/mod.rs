//! Linked slice panes (axial, coronal, sagittal), rendered on the GPU (`render::slice`) from the
//! intensity texture and, optionally, the displayed method's features. Patient orientation: the
//! voxel axis closest to each patient axis is chosen per pane, and flipped so that the patient's
//! left is on the right of the axial and coronal panes, anterior up in the axial pane, superior
//! up in the coronal and sagittal panes, and posterior on the right of the sagittal pane
//! (radiological convention); the four edges are labelled from the direction cosines. Voxels are
//! drawn at their true aspect in mm. The header gives the slice's position along the pane's
//! normal in mm ("S 12.5 mm": patient coordinates, whatever the file's voxel order).
//!
//! Interaction (the MIP's gestures where they mean the same): a click (or drag) moves the shared
//! crosshair, or draws a measurement when a measuring tool is chosen; the wheel, the arrow and
//! the page keys over the pane move through slices, always towards superior (axial), anterior
//! (coronal) or the patient's left (sagittal) for wheel-up / arrow-up; ctrl + wheel (or a pinch)
//! zooms at the pointer; middle drag or shift + drag pans; a double click or "fit" shows the whole
//! slice again, "1:1" one voxel per screen pixel; a right-button drag, or ctrl + drag, sets the
//! window: horizontal is the width, vertical the level (down = darker); "cine" plays through the
//! slices at the chosen rate, wrapping around, until stopped.

mod draw;

use eframe::egui_wgpu::RenderState;

use glam::DVec3;

use super::error::AppError;
use super::measure::{self, MeasureKind, Measurement, Tool};
use crate::gpu::GpuContext;
use crate::gpu::volume_texture::{FeatureTexture, RenderVolume};
use crate::render::slice::{
    Overlay, SliceError, SliceImage, SlicePlane, SliceRenderer, SliceRequest,
};
use crate::volume::{Volume, orientation_label};

pub use super::model::axes::{PaneAxes, PaneView, SliceKind, pane_axes};
pub use draw::slice_position;

/// Everything a pane needs to draw, shared by the three panes in a frame.
pub struct PaneInputs<'a> {
    pub gpu: &'a GpuContext,
    pub render_state: &'a RenderState,
    pub renderer: &'a SliceRenderer,
    pub volume: &'a Volume,
    pub render_volume: &'a RenderVolume,
    /// Changes with every loaded volume.
    pub generation: u64,
    /// The displayed method's features and their cache id.
    pub features: Option<(&'a FeatureTexture, u64)>,
    pub overlay: Option<Overlay>,
    /// (lo, hi) in physical units.
    pub window: (f32, f32),
    /// What a left drag does.
    pub tool: Tool,
    /// The measurements to draw (those of this pane on the slice shown).
    pub measurements: &'a [measure::Entry],
    /// The values' unit ("HU", or "" when unknown).
    pub unit: &'a str,
    /// The PET fused over the CT, when one is shown.
    pub pet: Option<&'a super::pet::PetLayer>,
    /// The findings' markers (drawn where the slice crosses them).
    pub findings: &'a [super::findings::Marker],
}

/// What happened in a pane this frame.
#[derive(Debug, Default)]
pub struct PaneResponse {
    /// The voxel under the mouse.
    pub hovered: Option<[usize; 3]>,
    /// Window/level drag this frame, screen points.
    pub window_drag: egui::Vec2,
    /// The maximise/restore button was clicked.
    pub toggle_maximise: bool,
    /// A measurement drawn this frame.
    pub measured: Option<Measurement>,
    /// The pane's slice could not be drawn.
    pub error: Option<AppError>,
}

#[derive(Clone, Copy, Debug, PartialEq)]
struct DrawKey {
    request: SliceRequest,
    generation: u64,
    features: Option<u64>,
}

/// Cine: playing through the slices since `started_s` (egui time), `steps` taken so far.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Cine {
    started_s: f64,
    steps: i64,
}

/// One slice pane and its GPU image.
pub struct SlicePane {
    pub kind: SliceKind,
    image: Option<SliceImage>,
    texture_id: Option<egui::TextureId>,
    drawn: Option<DrawKey>,
    /// Wheel points not yet turned into slices.
    wheel_points: f32,
    /// Where the image was drawn last frame (tests and automation click there).
    pub image_rect: Option<egui::Rect>,
    /// The image's part of the pane (below the header) last frame: what "Save picture" keeps.
    pub area_rect: Option<egui::Rect>,
    /// Zoom and pan.
    pub view: PaneView,
    /// Cine rate, slices per second.
    pub cine_fps: f32,
    cine: Option<Cine>,
    /// The measurement being drawn: its kind and first point (pane coordinates).
    drawing: Option<(MeasureKind, [f64; 2])>,
    /// The fused PET's image of the slice shown.
    pet_overlay: super::pet::PaneOverlay,
}

/// Wheel points per slice (a notch of a mouse wheel in a browser is about 100 points).
const POINTS_PER_SLICE: f32 = 50.0;

/// What the wheel and the keys did this frame.
#[derive(Default)]
struct WheelInput {
    /// Slices towards superior / anterior / left.
    steps: i64,
    /// Zoom factor (ctrl + wheel, pinch).
    zoom: f32,
}

impl SlicePane {
    pub fn new(kind: SliceKind) -> Self {
        Self {
            kind,
            image: None,
            texture_id: None,
            drawn: None,
            wheel_points: 0.0,
            image_rect: None,
            area_rect: None,
            view: PaneView::default(),
            cine_fps: 10.0,
            cine: None,
            drawing: None,
            pet_overlay: super::pet::PaneOverlay::default(),
        }
    }

    /// Whether cine is playing.
    pub fn playing(&self) -> bool {
        self.cine.is_some()
    }

    /// Starts cine at `fps` slices per second from now (egui time `now_s`), or stops it.
    pub fn set_cine(&mut self, fps: Option<f32>, now_s: f64) {
        match fps {
            Some(f) if f.is_finite() && f > 0.0 => {
                self.cine_fps = f.clamp(0.5, 60.0);
                self.cine = Some(Cine {
                    started_s: now_s,
                    steps: 0,
                });
            }
            _ => self.cine = None,
        }
    }

    /// Draws the pane into the whole of `ui`'s available space.
    pub fn ui(
        &mut self,
        ui: &mut egui::Ui,
        inputs: &PaneInputs<'_>,
        crosshair: &mut [usize; 3],
        maximised: bool,
    ) -> PaneResponse {
        let mut out = PaneResponse::default();
        let volume = inputs.volume;
        let axes = pane_axes(volume, self.kind);
        let n_slices = volume.dims[axes.fixed];
        let slice = crosshair[axes.fixed].min(n_slices.saturating_sub(1));
        let (w, h) = (volume.dims[axes.across], volume.dims[axes.vertical]);
        let size_mm = egui::vec2(
            (w as f64 * volume.spacing_mm[axes.across]) as f32,
            (h as f64 * volume.spacing_mm[axes.vertical]) as f32,
        );
        let now = ui.input(|i| i.time);

        // Header: name, position along the normal in mm, slice, view buttons, cine, maximise.
        let mut fit = false;
        let mut one_to_one = false;
        ui.horizontal(|ui| {
            ui.strong(self.kind.title());
            let position = slice_position(volume, axes, *crosshair);
            ui.label(egui::RichText::new(&position).monospace())
                .on_hover_text("the slice's position along the pane's normal, patient coordinates (LPS), mm");
            ui.with_layout(egui::Layout::right_to_left(egui::Align::Center), |ui| {
                let (icon, tip) = if maximised {
                    ("restore", "back to all panes")
                } else {
                    ("maximise", "show this pane alone")
                };
                if ui.small_button(icon).on_hover_text(tip).clicked() {
                    out.toggle_maximise = true;
                }
                let playing = self.cine.is_some();
                // The rate while playing (the header has no room for it otherwise).
                if playing {
                    ui.add(
                        egui::DragValue::new(&mut self.cine_fps)
                            .range(0.5..=60.0)
                            .speed(0.2)
                            .max_decimals(1)
                            .suffix("/s"),
                    )
                    .on_hover_text("cine rate, slices per second");
                }
                if ui
                    .selectable_label(playing, "cine")
                    .on_hover_text("play through the slices (towards superior / anterior / left, wrapping around); click again to stop")
                    .clicked()
                {
                    self.set_cine((!playing).then_some(self.cine_fps), now);
                }
                one_to_one = ui
                    .small_button("1:1")
                    .on_hover_text("one voxel per screen pixel")
                    .clicked();
                fit = ui
                    .small_button("fit")
                    .on_hover_text("the whole slice in the pane (or double-click the image)")
                    .clicked();
            });
        });

        // The image at its true size in mm, zoomed and panned in the space left.
        let area = ui.available_rect_before_wrap();
        let response = ui.allocate_rect(area, egui::Sense::click_and_drag());
        self.area_rect = Some(area);
        if fit || response.double_clicked() {
            self.view = PaneView::default();
        }
        if one_to_one {
            let ppp = ui.ctx().pixels_per_point();
            self.view.one_to_one(area, size_mm, w, ppp);
        }

        // Wheel and keys: slices, or zoom with ctrl (a pinch too).
        let mut slice_now = slice;
        if response.hovered() {
            let input = self.wheel_input(ui);
            if input.zoom != 1.0
                && let Some(pos) = response.hover_pos()
            {
                self.view.zoom_at(area, size_mm, pos, input.zoom);
            }
            let steps = if axes.forward_positive {
                input.steps
            } else {
                -input.steps
            };
            if steps != 0 && n_slices > 0 {
                slice_now = (slice as i64 + steps).clamp(0, n_slices as i64 - 1) as usize;
            }
        }
        // Cine: the slices due since it started, wrapping around.
        if let Some(cine) = &mut self.cine
            && n_slices > 0
        {
            let due = ((now - cine.started_s).max(0.0) * f64::from(self.cine_fps)).floor() as i64;
            let n = due - cine.steps;
            cine.steps = due;
            let forward = if axes.forward_positive { n } else { -n };
            slice_now = (slice_now as i64 + forward).rem_euclid(n_slices as i64) as usize;
            ui.ctx()
                .request_repaint_after(std::time::Duration::from_secs_f32(
                    0.5 / self.cine_fps.max(0.5),
                ));
        }
        crosshair[axes.fixed] = slice_now;
        let slice = slice_now;

        if let Err(source) = self.render_if_needed(inputs, axes, slice) {
            out.error = Some(AppError::Pane {
                pane: self.kind.name(),
                source,
            });
        }

        // Mouse: pan, window, measure or move the crosshair.
        let modifiers = ui.input(|i| i.modifiers);
        let ctrl = modifiers.ctrl || modifiers.command;
        let pan = response.dragged_by(egui::PointerButton::Middle)
            || (modifiers.shift && response.dragged_by(egui::PointerButton::Primary));
        if pan {
            self.view.pan_by(area, size_mm, response.drag_delta());
        }
        let rect = self.view.image_rect(area, size_mm);
        self.image_rect = Some(rect);
        let window_drag = response.dragged_by(egui::PointerButton::Secondary)
            || (response.dragged_by(egui::PointerButton::Primary) && ctrl);
        let measuring = inputs.tool.kind().filter(|_| !ctrl && !modifiers.shift);
        let primary = ui.input(|i| i.pointer.primary_down());
        if let Some(pos) = response.hover_pos()
            && area.contains(pos)
            && let Some((u, v)) = axes.voxel_at(rect, pos, w, h)
        {
            let mut p = [0usize; 3];
            p[axes.fixed] = slice;
            p[axes.across] = u;
            p[axes.vertical] = v;
            out.hovered = Some(p);
        }
        if window_drag {
            out.window_drag = response.drag_delta();
        } else if let Some(kind) = measuring.filter(|_| !pan) {
            if response.drag_started_by(egui::PointerButton::Primary)
                && let Some(origin) = ui.input(|i| i.pointer.press_origin())
            {
                self.drawing = Some((kind, axes.coord_at(rect, origin, w, h)));
            }
            if response.drag_stopped()
                && let Some((kind, a)) = self.drawing.take()
                && let Some(pos) = response.interact_pointer_pos()
            {
                let b = axes.coord_at(rect, pos, w, h);
                // A click is not a measurement.
                if (a[0] - b[0]).abs() + (a[1] - b[1]).abs() > 0.25 {
                    out.measured = Some(Measurement {
                        kind,
                        pane: Some(self.kind),
                        a_mm: axes.world_of(volume, slice, a),
                        b_mm: axes.world_of(volume, slice, b),
                    });
                }
            }
        } else if primary
            && !pan
            && !ctrl
            && !modifiers.shift
            && (response.is_pointer_button_down_on() || response.clicked())
            && let Some(pos) = response.interact_pointer_pos()
            && let Some((u, v)) = axes.voxel_at(
                rect,
                pos.clamp(rect.min.max(area.min), rect.max.min(area.max)),
                w,
                h,
            )
        {
            crosshair[axes.across] = u;
            crosshair[axes.vertical] = v;
            crosshair[axes.fixed] = slice;
        }
        if measuring.is_none() || !response.dragged() {
            self.drawing = self.drawing.filter(|_| response.dragged());
        }

        let painter = ui.painter_at(area);
        painter.rect_filled(area, 0.0, egui::Color32::BLACK);
        if let Some(id) = self.texture_id {
            painter.image(id, rect, axes.uv(), egui::Color32::WHITE);
        }
        if let Some(pet) = inputs.pet.filter(|p| p.visible) {
            let id =
                self.pet_overlay
                    .texture(ui.ctx(), pet, volume, axes, slice, inputs.generation);
            painter.image(id, rect, axes.uv(), egui::Color32::WHITE);
        }
        let at = draw::Placed { rect, axes, w, h };
        self.draw_overlay(&painter, area, at, crosshair, volume);
        super::paint::draw_scale_bar(&painter, area, rect.width() / size_mm.x.max(1e-6));
        // Corner annotation: the slice index in the file, and the zoom when not fitted.
        let mut corner = format!("{} / {}", slice + 1, n_slices);
        if (self.view.zoom - 1.0).abs() > 1e-3 {
            corner.push_str(&format!("   zoom {:.1}x", self.view.zoom));
        }
        painter.text(
            area.left_bottom() + egui::vec2(4.0, -3.0),
            egui::Align2::LEFT_BOTTOM,
            corner,
            egui::FontId::proportional(12.0),
            egui::Color32::from_gray(190),
        );
        self.draw_measurements(&painter, inputs, at, slice);
        let to_voxel = volume.voxel_from_world();
        super::findings::draw_markers(
            &painter,
            inputs.findings,
            rect.width() / size_mm.x.max(1e-6),
            |p| {
                let v = to_voxel.transform_point3(p);
                v.is_finite().then(|| {
                    (
                        at.screen_of_coord([v[axes.across], v[axes.vertical]]),
                        (v[axes.fixed] - slice as f64) * volume.spacing_mm[axes.fixed],
                    )
                })
            },
        );
        if let (Some((kind, a)), Some(pos)) = (self.drawing, response.interact_pointer_pos()) {
            let b = axes.coord_at(rect, pos, w, h);
            let m = Measurement {
                kind,
                pane: Some(self.kind),
                a_mm: axes.world_of(volume, slice, a),
                b_mm: axes.world_of(volume, slice, b),
            };
            let entry = measure::Entry::new(volume, m);
            draw::draw_measurement(&painter, &entry, inputs.unit, at, [a, b], true);
        }
        out
    }

    /// Slices to move by the wheel events and keys of this frame (wheel-up and arrow-up
    /// positive), and the zoom of ctrl + wheel and pinches.
    fn wheel_input(&mut self, ui: &egui::Ui) -> WheelInput {
        let mut input = WheelInput {
            steps: 0,
            zoom: 1.0,
        };
        ui.input(|i| {
            for e in &i.events {
                match e {
                    egui::Event::MouseWheel {
                        unit,
                        delta,
                        modifiers,
                        ..
                    } if modifiers.ctrl || modifiers.command => {
                        // The MIP's wheel zoom.
                        let points = match unit {
                            egui::MouseWheelUnit::Point => delta.y,
                            egui::MouseWheelUnit::Line => delta.y * 40.0,
                            egui::MouseWheelUnit::Page => delta.y * 400.0,
                        };
                        input.zoom *= (points * 0.002).exp();
                    }
                    egui::Event::Zoom(f) => input.zoom *= f,
                    egui::Event::MouseWheel { unit, delta, .. } => match unit {
                        egui::MouseWheelUnit::Line => input.steps += delta.y.round() as i64,
                        egui::MouseWheelUnit::Page => {
                            input.steps += (delta.y * 10.0).round() as i64;
                        }
                        egui::MouseWheelUnit::Point => self.wheel_points += delta.y,
                    },
                    egui::Event::Key {
                        key,
                        pressed: true,
                        modifiers,
                        ..
                    } if !modifiers.ctrl && !modifiers.command => match key {
                        egui::Key::ArrowUp => input.steps += 1,
                        egui::Key::ArrowDown => input.steps -= 1,
                        egui::Key::PageUp => input.steps += 10,
                        egui::Key::PageDown => input.steps -= 10,
                        _ => {}
                    },
                    _ => {}
                }
            }
        });
        let whole = (self.wheel_points / POINTS_PER_SLICE).trunc();
        self.wheel_points -= whole * POINTS_PER_SLICE;
        input.steps += whole as i64;
        input
    }

    fn render_if_needed(
        &mut self,
        inputs: &PaneInputs<'_>,
        axes: PaneAxes,
        slice: usize,
    ) -> Result<(), SliceError> {
        let request = SliceRequest {
            plane: SlicePlane {
                fixed: axes.fixed,
                across: axes.across,
                vertical: axes.vertical,
                index: u32::try_from(slice).unwrap_or(u32::MAX),
            },
            window: inputs.window,
            overlay: inputs.overlay.filter(|_| inputs.features.is_some()),
        };
        let key = DrawKey {
            request,
            generation: inputs.generation,
            features: inputs.features.map(|(_, id)| id),
        };
        if self.drawn == Some(key) && self.texture_id.is_some() {
            return Ok(());
        }
        let reuse = self.image.take();
        let reused_size = reuse.as_ref().map(|i| i.size);
        let image = inputs.renderer.render(
            inputs.gpu,
            inputs.render_volume,
            inputs.features.map(|(t, _)| t),
            &request,
            reuse,
        )?;
        if self.texture_id.is_none() || reused_size != Some(image.size) {
            super::paint::show_texture(
                inputs.render_state,
                inputs.gpu,
                &image.view,
                &mut self.texture_id,
            );
        }
        self.image = Some(image);
        self.drawn = Some(key);
        Ok(())
    }
}

impl super::ShapecastApp {
    /// The voxel under the pointer: in a slice pane, or where the MIP pixel under it has its
    /// maximum.
    pub fn hovered_voxel(&self) -> Option<[usize; 3]> {
        self.reading.hover
    }

    /// What the MIP shows in its corner about the pixel under the pointer.
    pub fn mip_hover_text(&self) -> Option<&str> {
        self.mip_view.hover_text.as_deref()
    }

    /// A pane's zoom and pan.
    pub fn pane_view(&self, kind: SliceKind) -> Option<PaneView> {
        Some(self.panes.iter().find(|p| p.kind == kind)?.view)
    }

    /// Whether a pane's cine is playing.
    pub fn pane_playing(&self, kind: SliceKind) -> bool {
        self.panes.iter().any(|p| p.kind == kind && p.playing())
    }

    /// The continuous voxel coordinates (i, j, k) under a screen point of a pane's image as
    /// drawn in the last frame (on the pane's slice).
    pub fn pane_coord_at(&self, kind: SliceKind, pos: egui::Pos2) -> Option<DVec3> {
        let v = self.volume()?;
        let rect = self.pane_rect(kind)?;
        let axes = pane_axes(v, kind);
        let c = axes.coord_at(rect, pos, v.dims[axes.across], v.dims[axes.vertical]);
        let mut p = DVec3::ZERO;
        p[axes.fixed] = self.reading.crosshair[axes.fixed] as f64;
        p[axes.across] = c[0];
        p[axes.vertical] = c[1];
        Some(p)
    }

    /// The screen point of continuous voxel coordinates in a pane's image (last frame).
    pub fn pane_screen_of(&self, kind: SliceKind, voxel: DVec3) -> Option<egui::Pos2> {
        let v = self.volume()?;
        let rect = self.pane_rect(kind)?;
        let axes = pane_axes(v, kind);
        Some(axes.screen_of_coord(
            rect,
            [voxel[axes.across], voxel[axes.vertical]],
            v.dims[axes.across],
            v.dims[axes.vertical],
        ))
    }
}
