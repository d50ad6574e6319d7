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

use eframe::egui_wgpu::RenderState;

use glam::DVec3;

use super::measure::{self, MeasureKind, Measurement, Tool};
use crate::gpu::GpuContext;
use crate::gpu::volume_texture::{FeatureTexture, RenderVolume};
use crate::render::slice::{Overlay, SliceImage, SlicePlane, SliceRenderer, SliceRequest};
use crate::volume::{Volume, orientation_label};

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SliceKind {
    Axial,
    Coronal,
    Sagittal,
}

impl SliceKind {
    pub const ALL: [Self; 3] = [Self::Axial, Self::Coronal, Self::Sagittal];

    pub fn name(self) -> &'static str {
        match self {
            Self::Axial => "axial",
            Self::Coronal => "coronal",
            Self::Sagittal => "sagittal",
        }
    }

    pub fn title(self) -> &'static str {
        match self {
            Self::Axial => "Axial",
            Self::Coronal => "Coronal",
            Self::Sagittal => "Sagittal",
        }
    }
}

/// How a pane maps voxel axes to the screen.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PaneAxes {
    /// The voxel axis held fixed (the slice index runs along it).
    pub fixed: usize,
    /// The voxel axis across the screen, and whether its index grows to the right.
    pub across: usize,
    pub right_positive: bool,
    /// The voxel axis up the screen, and whether its index grows upwards.
    pub vertical: usize,
    pub up_positive: bool,
    /// Whether the slice index grows towards superior (axial), anterior (coronal) or the
    /// patient's left (sagittal): the way wheel-up and arrow-up go.
    pub forward_positive: bool,
}

/// For each patient axis (x = L, y = P, z = S in LPS), the voxel axis closest to it.
fn voxel_axis_of_patient_axes(volume: &Volume) -> [usize; 3] {
    // Greedy on the largest direction-cosine component: an oblique volume still gets a
    // permutation.
    let d = volume.direction;
    let mut pairs: Vec<(f64, usize, usize)> = Vec::with_capacity(9);
    for voxel_axis in 0..3 {
        let col = d.col(voxel_axis);
        for (patient_axis, c) in [col.x, col.y, col.z].into_iter().enumerate() {
            pairs.push((c.abs(), voxel_axis, patient_axis));
        }
    }
    pairs.sort_by(|a, b| b.0.total_cmp(&a.0));
    let mut of_patient = [usize::MAX; 3];
    let mut used = [false; 3];
    for (_, v, p) in pairs {
        if of_patient[p] == usize::MAX && !used[v] {
            of_patient[p] = v;
            used[v] = true;
        }
    }
    // Degenerate directions (all zero): fall back to i, j, k.
    if of_patient.contains(&usize::MAX) {
        return [0, 1, 2];
    }
    of_patient
}

/// The axes of a pane for a volume.
pub fn pane_axes(volume: &Volume, kind: SliceKind) -> PaneAxes {
    let of_patient = voxel_axis_of_patient_axes(volume);
    let comp = |voxel_axis: usize, patient_axis: usize| -> f64 {
        volume.direction.col(voxel_axis)[patient_axis]
    };
    let (fixed, across, vertical, up_is_plus) = kind.patient_axes();
    let up = comp(of_patient[vertical], vertical);
    // Forward: +z (superior), -y (anterior), +x (left).
    let forward = comp(of_patient[fixed], fixed)
        * if kind == SliceKind::Coronal {
            -1.0
        } else {
            1.0
        };
    PaneAxes {
        fixed: of_patient[fixed],
        across: of_patient[across],
        right_positive: comp(of_patient[across], across) >= 0.0,
        vertical: of_patient[vertical],
        up_positive: if up_is_plus { up >= 0.0 } else { up < 0.0 },
        forward_positive: forward >= 0.0,
    }
}

impl SliceKind {
    /// The patient axes (x, y, z = 0, 1, 2) fixed, across (its + direction on the right) and
    /// vertical, and whether up is the vertical axis's + direction.
    fn patient_axes(self) -> (usize, usize, usize, bool) {
        match self {
            // Patient left (+x) on the right, anterior (-y) up.
            SliceKind::Axial => (2, 0, 1, false),
            // Patient left on the right, superior (+z) up.
            SliceKind::Coronal => (1, 0, 2, true),
            // Posterior (+y) on the right (the patient faces left), superior up.
            SliceKind::Sagittal => (0, 1, 2, true),
        }
    }
}

impl PaneAxes {
    /// The voxel (across, vertical) indices under a point of `rect` (the image), if inside.
    pub fn voxel_at(
        &self,
        rect: egui::Rect,
        pos: egui::Pos2,
        w: usize,
        h: usize,
    ) -> Option<(usize, usize)> {
        if !rect.contains(pos) || w == 0 || h == 0 {
            return None;
        }
        let fx = ((pos.x - rect.left()) / rect.width()).clamp(0.0, 0.999_999);
        let fy = ((pos.y - rect.top()) / rect.height()).clamp(0.0, 0.999_999);
        let col = (fx * w as f32) as usize;
        let row = (fy * h as f32) as usize;
        let u = if self.right_positive {
            col
        } else {
            w - 1 - col
        };
        let v = if self.up_positive { h - 1 - row } else { row };
        Some((u, v))
    }

    /// The continuous voxel coordinates (across, vertical; a voxel's centre at its integer
    /// index) of a screen point, for an image of `w` x `h` voxels drawn in `rect`.
    pub fn coord_at(&self, rect: egui::Rect, pos: egui::Pos2, w: usize, h: usize) -> [f64; 2] {
        let fx = f64::from((pos.x - rect.left()) / rect.width().max(1e-6)) * w as f64;
        let fy = f64::from((pos.y - rect.top()) / rect.height().max(1e-6)) * h as f64;
        let u = if self.right_positive {
            fx - 0.5
        } else {
            w as f64 - 0.5 - fx
        };
        let v = if self.up_positive {
            h as f64 - 0.5 - fy
        } else {
            fy - 0.5
        };
        [u, v]
    }

    /// The screen point of continuous voxel coordinates (the inverse of [`Self::coord_at`]).
    pub fn screen_of_coord(&self, rect: egui::Rect, c: [f64; 2], w: usize, h: usize) -> egui::Pos2 {
        let col = if self.right_positive {
            c[0] + 0.5
        } else {
            w as f64 - 0.5 - c[0]
        };
        let row = if self.up_positive {
            h as f64 - 0.5 - c[1]
        } else {
            c[1] + 0.5
        };
        egui::pos2(
            rect.left() + (col / w.max(1) as f64) as f32 * rect.width(),
            rect.top() + (row / h.max(1) as f64) as f32 * rect.height(),
        )
    }

    /// The world point (LPS mm) of continuous pane coordinates on slice `slice`.
    pub fn world_of(&self, volume: &Volume, slice: usize, c: [f64; 2]) -> DVec3 {
        let mut ijk = DVec3::ZERO;
        ijk[self.fixed] = slice as f64;
        ijk[self.across] = c[0];
        ijk[self.vertical] = c[1];
        volume.world_from_voxel().transform_point3(ijk)
    }

    /// The screen point of the centre of voxel (u, v) in `rect`.
    pub fn screen_of(
        &self,
        rect: egui::Rect,
        u: usize,
        v: usize,
        w: usize,
        h: usize,
    ) -> egui::Pos2 {
        let col = if self.right_positive {
            u
        } else {
            w.saturating_sub(1 + u)
        };
        let row = if self.up_positive {
            h.saturating_sub(1 + v)
        } else {
            v
        };
        egui::pos2(
            rect.left() + (col as f32 + 0.5) / w.max(1) as f32 * rect.width(),
            rect.top() + (row as f32 + 0.5) / h.max(1) as f32 * rect.height(),
        )
    }

    /// Texture coordinates that show the raw slice image (x = across, y = vertical) oriented.
    fn uv(&self) -> egui::Rect {
        let (x0, x1) = if self.right_positive {
            (0.0, 1.0)
        } else {
            (1.0, 0.0)
        };
        let (y0, y1) = if self.up_positive {
            (1.0, 0.0)
        } else {
            (0.0, 1.0)
        };
        egui::Rect::from_min_max(egui::pos2(x0, y0), egui::pos2(x1, y1))
    }
}

/// Zoom and pan of a pane. Zoom 1 fits the whole slice in the pane; the pan is the offset of the
/// image's centre from the pane's centre, in mm of the image (so it survives a resize).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PaneView {
    pub zoom: f32,
    pub pan_mm: egui::Vec2,
}

impl Default for PaneView {
    fn default() -> Self {
        Self {
            zoom: 1.0,
            pan_mm: egui::Vec2::ZERO,
        }
    }
}

impl PaneView {
    pub const MIN_ZOOM: f32 = 0.25;
    pub const MAX_ZOOM: f32 = 64.0;

    /// Screen points per mm at zoom 1: the whole image fits `area`.
    fn fit_scale(area: egui::Rect, size_mm: egui::Vec2) -> f32 {
        (area.width() / size_mm.x.max(1e-6))
            .min(area.height() / size_mm.y.max(1e-6))
            .max(1e-3)
    }

    /// Where an image of `size_mm` is drawn in `area`.
    pub fn image_rect(&self, area: egui::Rect, size_mm: egui::Vec2) -> egui::Rect {
        let scale = Self::fit_scale(area, size_mm) * self.zoom;
        egui::Rect::from_center_size(area.center() + self.pan_mm * scale, size_mm * scale)
    }

    /// Zooms by `factor` keeping the image point under `pos` where it is.
    pub fn zoom_at(&mut self, area: egui::Rect, size_mm: egui::Vec2, pos: egui::Pos2, factor: f32) {
        if !factor.is_finite() || factor <= 0.0 {
            return;
        }
        let fit = Self::fit_scale(area, size_mm);
        let rect = self.image_rect(area, size_mm);
        let from_centre_mm = (pos - rect.center()) / (fit * self.zoom);
        self.zoom = (self.zoom * factor).clamp(Self::MIN_ZOOM, Self::MAX_ZOOM);
        let scale = fit * self.zoom;
        let centre = pos - from_centre_mm * scale;
        self.pan_mm = (centre - area.center()) / scale;
    }

    /// Moves the image by `delta` screen points.
    pub fn pan_by(&mut self, area: egui::Rect, size_mm: egui::Vec2, delta: egui::Vec2) {
        self.pan_mm += delta / (Self::fit_scale(area, size_mm) * self.zoom);
    }

    /// The zoom at which one voxel across spans one screen pixel, centred where it was.
    pub fn one_to_one(
        &mut self,
        area: egui::Rect,
        size_mm: egui::Vec2,
        voxels_across: usize,
        pixels_per_point: f32,
    ) {
        let points_per_voxel = 1.0 / pixels_per_point.max(1e-3);
        let points_per_mm = points_per_voxel * voxels_across.max(1) as f32 / size_mm.x.max(1e-6);
        let zoom = points_per_mm / Self::fit_scale(area, size_mm);
        self.zoom_at(area, size_mm, area.center(), zoom / self.zoom);
    }
}

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
    pub error: Option<String>,
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

        if let Err(e) = self.render_if_needed(inputs, axes, slice) {
            out.error = Some(e);
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
        self.draw_overlay(&painter, area, rect, axes, crosshair, w, h, volume);
        super::export::picture::draw_scale_bar(&painter, area, rect.width() / size_mm.x.max(1e-6));
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
        self.draw_measurements(&painter, inputs, rect, axes, slice, w, h);
        let to_voxel = volume.voxel_from_world();
        super::findings::draw_markers(
            &painter,
            inputs.findings,
            rect.width() / size_mm.x.max(1e-6),
            |p| {
                let v = to_voxel.transform_point3(p);
                v.is_finite().then(|| {
                    (
                        axes.screen_of_coord(rect, [v[axes.across], v[axes.vertical]], w, h),
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
            draw_measurement(&painter, &entry, inputs.unit, rect, axes, a, b, w, h, true);
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
    ) -> Result<(), String> {
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
        let image = inputs
            .renderer
            .render(
                inputs.gpu,
                inputs.render_volume,
                inputs.features.map(|(t, _)| t),
                &request,
                reuse,
            )
            .map_err(|e| format!("{} pane: {e}", self.kind.name()))?;
        if self.texture_id.is_none() || reused_size != Some(image.size) {
            super::mip_view::show_texture(
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

    #[allow(clippy::too_many_arguments)]
    fn draw_overlay(
        &self,
        painter: &egui::Painter,
        area: egui::Rect,
        rect: egui::Rect,
        axes: PaneAxes,
        crosshair: &[usize; 3],
        w: usize,
        h: usize,
        volume: &Volume,
    ) {
        // What of the image is on screen (zoomed in, the image is larger than the pane).
        let shown = rect.intersect(area);
        // Crosshair lines with a gap around the point, so they never hide what is there.
        let c = axes.screen_of(rect, crosshair[axes.across], crosshair[axes.vertical], w, h);
        let gap = 10.0;
        let stroke =
            egui::Stroke::new(1.0, egui::Color32::from_rgba_unmultiplied(90, 220, 90, 200));
        for seg in [
            [egui::pos2(c.x, shown.top()), egui::pos2(c.x, c.y - gap)],
            [egui::pos2(c.x, c.y + gap), egui::pos2(c.x, shown.bottom())],
            [egui::pos2(shown.left(), c.y), egui::pos2(c.x - gap, c.y)],
            [egui::pos2(c.x + gap, c.y), egui::pos2(shown.right(), c.y)],
        ] {
            if seg[0].x <= seg[1].x && seg[0].y <= seg[1].y {
                painter.line_segment(seg, stroke);
            }
        }

        // Patient-direction labels on the four edges of what is shown.
        let dir = |a: usize, positive: bool| {
            let d = volume.direction.col(a);
            if positive { d } else { -d }
        };
        let right = dir(axes.across, axes.right_positive);
        let up = dir(axes.vertical, axes.up_positive);
        let colour = egui::Color32::from_rgb(240, 200, 80);
        let font = egui::FontId::proportional(14.0);
        for (pos, align, d) in [
            (
                shown.right_center() - egui::vec2(4.0, 0.0),
                egui::Align2::RIGHT_CENTER,
                right,
            ),
            (
                shown.left_center() + egui::vec2(4.0, 0.0),
                egui::Align2::LEFT_CENTER,
                -right,
            ),
            (
                shown.center_top() + egui::vec2(0.0, 4.0),
                egui::Align2::CENTER_TOP,
                up,
            ),
            (
                shown.center_bottom() - egui::vec2(0.0, 4.0),
                egui::Align2::CENTER_BOTTOM,
                -up,
            ),
        ] {
            painter.text(pos, align, orientation_label(d), font.clone(), colour);
        }
    }

    /// The measurements of this pane made on the slice shown.
    #[allow(clippy::too_many_arguments)]
    fn draw_measurements(
        &self,
        painter: &egui::Painter,
        inputs: &PaneInputs<'_>,
        rect: egui::Rect,
        axes: PaneAxes,
        slice: usize,
        w: usize,
        h: usize,
    ) {
        for (n, entry) in inputs.measurements.iter().enumerate() {
            let m = &entry.measurement;
            if m.pane.is_none() {
                draw_ends_3d(painter, inputs, n, rect, axes, slice, w, h);
                continue;
            }
            if m.pane != Some(self.kind) {
                continue;
            }
            let Some(p) = m.in_pane(inputs.volume) else {
                continue;
            };
            if p.slice == slice {
                draw_measurement(
                    painter,
                    entry,
                    inputs.unit,
                    rect,
                    axes,
                    p.a,
                    p.b,
                    w,
                    h,
                    false,
                );
            }
        }
    }
}

/// The slice's position along the pane's normal through the crosshair, e.g. "S 12.5 mm": the
/// patient coordinate (LPS mm) along the normal of the slice plane, signed towards the pane's
/// forward direction (superior, anterior, left), written with the letter of the side it is on.
pub fn slice_position(volume: &Volume, axes: PaneAxes, crosshair: [usize; 3]) -> String {
    let d = volume.direction;
    let forward = d.col(axes.fixed) * if axes.forward_positive { 1.0 } else { -1.0 };
    let mut normal = d.col(axes.across).cross(d.col(axes.vertical));
    if normal.length_squared() < 1e-12 {
        normal = forward;
    }
    let mut normal = normal.normalize_or_zero();
    if normal.dot(forward) < 0.0 {
        normal = -normal;
    }
    let p = volume.world_from_voxel().transform_point3(DVec3::new(
        crosshair[0] as f64,
        crosshair[1] as f64,
        crosshair[2] as f64,
    ));
    let along = p.dot(normal);
    let side = if along >= 0.0 { normal } else { -normal };
    format!("{} {:.1} mm", orientation_label(side), along.abs())
}

/// The ends of ruler `n` in 3D that lie on the slice shown: a ring each, with its number and
/// length.
#[allow(clippy::too_many_arguments)]
fn draw_ends_3d(
    painter: &egui::Painter,
    inputs: &PaneInputs<'_>,
    n: usize,
    rect: egui::Rect,
    axes: PaneAxes,
    slice: usize,
    w: usize,
    h: usize,
) {
    let Some(entry) = inputs.measurements.get(n) else {
        return;
    };
    let m = &entry.measurement;
    let volume = inputs.volume;
    let to_voxel = volume.voxel_from_world();
    let top = volume.dims[axes.fixed].saturating_sub(1) as f64;
    let colour = egui::Color32::from_rgb(90, 200, 255);
    for end in [m.a_mm, m.b_mm] {
        let v = to_voxel.transform_point3(end);
        // An end is on the slice whose voxels hold it (none outside the volume).
        let k = v[axes.fixed];
        if !v.is_finite()
            || !(-0.5..=top + 0.5).contains(&k)
            || k.round().max(0.0) as usize != slice
        {
            continue;
        }
        let p = axes.screen_of_coord(rect, [v[axes.across], v[axes.vertical]], w, h);
        painter.circle_stroke(p, 5.0, egui::Stroke::new(1.5, colour));
        painter.text(
            p + egui::vec2(7.0, -7.0),
            egui::Align2::LEFT_BOTTOM,
            format!("{} 3D {}", n + 1, entry.reading(inputs.unit)),
            egui::FontId::proportional(13.0),
            colour,
        );
    }
}

/// A ruler (line, end ticks, length) or an ellipse (outline and statistics) between pane
/// coordinates `a` and `b`.
#[allow(clippy::too_many_arguments)]
fn draw_measurement(
    painter: &egui::Painter,
    entry: &measure::Entry,
    unit: &str,
    rect: egui::Rect,
    axes: PaneAxes,
    a: [f64; 2],
    b: [f64; 2],
    w: usize,
    h: usize,
    drawing: bool,
) {
    let colour = if drawing {
        egui::Color32::from_rgb(255, 230, 120)
    } else {
        egui::Color32::from_rgb(90, 200, 255)
    };
    let stroke = egui::Stroke::new(1.5, colour);
    let (pa, pb) = (
        axes.screen_of_coord(rect, a, w, h),
        axes.screen_of_coord(rect, b, w, h),
    );
    let font = egui::FontId::proportional(13.0);
    match entry.measurement.kind {
        MeasureKind::Ruler => {
            painter.line_segment([pa, pb], stroke);
            let along = (pb - pa).normalized();
            let tick = egui::vec2(-along.y, along.x) * 5.0;
            for p in [pa, pb] {
                painter.line_segment([p - tick, p + tick], stroke);
            }
            painter.text(
                pb + egui::vec2(6.0, -6.0),
                egui::Align2::LEFT_BOTTOM,
                entry.reading(unit),
                font,
                colour,
            );
        }
        MeasureKind::Ellipse => {
            let centre = pa + (pb - pa) * 0.5;
            let radius = ((pb - pa) * 0.5).abs();
            let points: Vec<egui::Pos2> = (0..64)
                .map(|n| {
                    let t = n as f32 / 64.0 * std::f32::consts::TAU;
                    centre + egui::vec2(radius.x * t.cos(), radius.y * t.sin())
                })
                .collect();
            painter.add(egui::Shape::closed_line(points, stroke));
            painter.text(
                egui::pos2(centre.x, centre.y + radius.y + 4.0),
                egui::Align2::CENTER_TOP,
                entry.reading(unit),
                font,
                colour,
            );
        }
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

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{DMat3, DVec3};

    fn vol(direction: DMat3) -> Volume {
        let mut v = Volume::from_f32([4, 5, 6], [1.0; 3], vec![0.0; 120]);
        v.direction = direction;
        v
    }

    #[test]
    fn lps_volume_follows_the_radiological_convention() {
        let v = vol(DMat3::IDENTITY);
        let a = pane_axes(&v, SliceKind::Axial);
        // i runs to patient left: on the right; j runs posterior: index grows downwards.
        assert_eq!((a.fixed, a.across, a.vertical), (2, 0, 1));
        assert!(a.right_positive && !a.up_positive);
        let c = pane_axes(&v, SliceKind::Coronal);
        assert_eq!((c.fixed, c.across, c.vertical), (1, 0, 2));
        assert!(c.right_positive && c.up_positive);
        let s = pane_axes(&v, SliceKind::Sagittal);
        assert_eq!((s.fixed, s.across, s.vertical), (0, 1, 2));
        assert!(s.right_positive && s.up_positive);
    }

    #[test]
    fn flipped_and_permuted_volumes_show_the_same_way() {
        // A sagittally stored MR: i along -y (anterior), j along -z (inferior), k along +x (left).
        let d = DMat3::from_cols(DVec3::NEG_Y, DVec3::NEG_Z, DVec3::X);
        let v = vol(d);
        let a = pane_axes(&v, SliceKind::Axial);
        assert_eq!((a.fixed, a.across, a.vertical), (1, 2, 0));
        // i runs anterior, so its index grows upwards in the axial pane.
        assert!(a.right_positive && a.up_positive);
        let c = pane_axes(&v, SliceKind::Coronal);
        assert_eq!((c.fixed, c.across, c.vertical), (0, 2, 1));
        assert!(c.right_positive && !c.up_positive);
    }

    #[test]
    fn screen_and_voxel_round_trip() {
        let rect = egui::Rect::from_min_size(egui::pos2(10.0, 20.0), egui::vec2(100.0, 50.0));
        for right_positive in [true, false] {
            for up_positive in [true, false] {
                let axes = PaneAxes {
                    fixed: 2,
                    across: 0,
                    right_positive,
                    vertical: 1,
                    up_positive,
                    forward_positive: true,
                };
                for (u, v) in [(0, 0), (9, 4), (3, 2)] {
                    let p = axes.screen_of(rect, u, v, 10, 5);
                    assert_eq!(axes.voxel_at(rect, p, 10, 5), Some((u, v)));
                    let c = axes.coord_at(rect, p, 10, 5);
                    assert!((c[0] - u as f64).abs() < 1e-4 && (c[1] - v as f64).abs() < 1e-4);
                    let q = axes.screen_of_coord(rect, [u as f64 + 0.3, v as f64 - 0.2], 10, 5);
                    let c = axes.coord_at(rect, q, 10, 5);
                    assert!((c[0] - u as f64 - 0.3).abs() < 1e-4, "{c:?}");
                    assert!((c[1] - v as f64 + 0.2).abs() < 1e-4, "{c:?}");
                }
                assert_eq!(axes.voxel_at(rect, egui::pos2(0.0, 0.0), 10, 5), None);
            }
        }
    }

    #[test]
    fn forward_is_superior_anterior_left_whatever_the_voxel_order() {
        let lps = vol(DMat3::IDENTITY);
        let flipped = vol(DMat3::from_cols(DVec3::NEG_X, DVec3::NEG_Y, DVec3::NEG_Z));
        for kind in SliceKind::ALL {
            let (a, b) = (pane_axes(&lps, kind), pane_axes(&flipped, kind));
            assert_eq!(a.fixed, b.fixed);
            assert_ne!(a.forward_positive, b.forward_positive, "{kind:?}");
        }
        // LPS: k runs superior, j posterior (so anterior is -j), i left.
        assert!(pane_axes(&lps, SliceKind::Axial).forward_positive);
        assert!(!pane_axes(&lps, SliceKind::Coronal).forward_positive);
        assert!(pane_axes(&lps, SliceKind::Sagittal).forward_positive);
        // The position reads the same patient coordinate in both orders.
        let mut v = Volume::from_f32([4, 5, 6], [1.0, 1.0, 2.5], vec![0.0; 120]);
        v.origin_mm = [0.0, 0.0, -5.0];
        assert_eq!(
            slice_position(&v, pane_axes(&v, SliceKind::Axial), [0, 0, 1]),
            "I 2.5 mm"
        );
        assert_eq!(
            slice_position(&v, pane_axes(&v, SliceKind::Axial), [0, 0, 5]),
            "S 7.5 mm"
        );
        assert_eq!(
            slice_position(&v, pane_axes(&v, SliceKind::Coronal), [0, 3, 0]),
            "P 3.0 mm"
        );
    }

    #[test]
    fn zoom_keeps_the_point_under_the_pointer_and_pan_moves_the_image() {
        let area = egui::Rect::from_min_size(egui::pos2(100.0, 50.0), egui::vec2(300.0, 200.0));
        let size_mm = egui::vec2(180.0, 240.0);
        let mut view = PaneView::default();
        let fitted = view.image_rect(area, size_mm);
        assert!((fitted.height() - 200.0).abs() < 1e-3 && area.contains_rect(fitted.shrink(0.01)));
        for (pos, factor) in [
            (egui::pos2(180.0, 90.0), 2.0),
            (egui::pos2(300.0, 220.0), 3.5),
            (egui::pos2(150.0, 60.0), 0.4),
        ] {
            let before = view.image_rect(area, size_mm);
            let f = (pos - before.min) / before.size();
            view.zoom_at(area, size_mm, pos, factor);
            let after = view.image_rect(area, size_mm);
            let g = (pos - after.min) / after.size();
            assert!((f - g).length() < 1e-4, "{f:?} vs {g:?}");
        }
        let before = view.image_rect(area, size_mm);
        view.pan_by(area, size_mm, egui::vec2(13.0, -7.0));
        let after = view.image_rect(area, size_mm);
        assert!((after.min - before.min - egui::vec2(13.0, -7.0)).length() < 1e-3);
        view.zoom_at(area, size_mm, area.center(), 1e9);
        assert_eq!(view.zoom, PaneView::MAX_ZOOM);
        view.zoom_at(area, size_mm, area.center(), f32::NAN);
        assert_eq!(view.zoom, PaneView::MAX_ZOOM);
        // 1:1: one voxel (here 180 across) per pixel at 2 pixels per point.
        view.one_to_one(area, size_mm, 180, 2.0);
        let r = view.image_rect(area, size_mm);
        assert!((r.width() - 90.0).abs() < 1e-3, "{r:?}");
    }
}
