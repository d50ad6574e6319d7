//! Linked slice panes (axial, coronal, sagittal), rendered on the GPU (`render::slice`) from the
//! intensity texture and, optionally, the displayed method's features. Patient orientation: the
//! voxel axis closest to each patient axis is chosen per pane, and flipped so that the patient's
//! left is on the right of the axial and coronal panes, anterior up in the axial pane, superior
//! up in the coronal and sagittal panes, and posterior on the right of the sagittal pane
//! (radiological convention); the four edges are labelled from the direction cosines. Voxels are
//! drawn at their true aspect in mm.
//!
//! Interaction: a click (or drag) moves the shared crosshair; the wheel (or the arrow and page
//! keys over the pane) moves through slices; a right-button drag, or ctrl + drag, sets the
//! window: horizontal is the width, vertical the level.

use eframe::egui_wgpu::RenderState;

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
    // The patient axes (x, y, z = 0, 1, 2) fixed, across (its + direction on the right) and
    // vertical, and whether up is the vertical axis's + direction.
    let (fixed, across, vertical, up_is_plus) = match kind {
        // Patient left (+x) on the right, anterior (-y) up.
        SliceKind::Axial => (2, 0, 1, false),
        // Patient left on the right, superior (+z) up.
        SliceKind::Coronal => (1, 0, 2, true),
        // Posterior (+y) on the right (the patient faces left), superior up.
        SliceKind::Sagittal => (0, 1, 2, true),
    };
    let up = comp(of_patient[vertical], vertical);
    PaneAxes {
        fixed: of_patient[fixed],
        across: of_patient[across],
        right_positive: comp(of_patient[across], across) >= 0.0,
        vertical: of_patient[vertical],
        up_positive: if up_is_plus { up >= 0.0 } else { up < 0.0 },
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
    pub error: Option<String>,
}

#[derive(Clone, Copy, Debug, PartialEq)]
struct DrawKey {
    request: SliceRequest,
    generation: u64,
    features: Option<u64>,
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
}

/// Wheel points per slice (a notch of a mouse wheel in a browser is about 100 points).
const POINTS_PER_SLICE: f32 = 50.0;

impl SlicePane {
    pub fn new(kind: SliceKind) -> Self {
        Self {
            kind,
            image: None,
            texture_id: None,
            drawn: None,
            wheel_points: 0.0,
            image_rect: None,
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

        // Header: name, slice, position along the slice normal, maximise button.
        ui.horizontal(|ui| {
            ui.strong(self.kind.title());
            ui.label(format!("slice {} / {}", slice + 1, n_slices));
            ui.with_layout(egui::Layout::right_to_left(egui::Align::Center), |ui| {
                let (icon, tip) = if maximised {
                    ("restore", "back to all panes")
                } else {
                    ("maximise", "show this pane alone")
                };
                if ui.small_button(icon).on_hover_text(tip).clicked() {
                    out.toggle_maximise = true;
                }
            });
        });

        if let Err(e) = self.render_if_needed(inputs, axes, slice) {
            out.error = Some(e);
        }

        // The image at its true size in mm, centred in the space left.
        let area = ui.available_rect_before_wrap();
        let response = ui.allocate_rect(area, egui::Sense::click_and_drag());
        let size_mm = egui::vec2(
            (w as f64 * volume.spacing_mm[axes.across]) as f32,
            (h as f64 * volume.spacing_mm[axes.vertical]) as f32,
        );
        let scale = (area.width() / size_mm.x)
            .min(area.height() / size_mm.y)
            .max(0.01);
        let rect = egui::Rect::from_center_size(area.center(), size_mm * scale);
        self.image_rect = Some(rect);
        let painter = ui.painter_at(area);
        painter.rect_filled(area, 0.0, egui::Color32::BLACK);
        if let Some(id) = self.texture_id {
            painter.image(id, rect, axes.uv(), egui::Color32::WHITE);
        }

        // Mouse: hover, click to move the crosshair, right/ctrl drag for the window.
        let modifiers = ui.input(|i| i.modifiers);
        let primary = ui.input(|i| i.pointer.primary_down());
        if let Some(pos) = response.hover_pos()
            && let Some((u, v)) = axes.voxel_at(rect, pos, w, h)
        {
            let mut p = [0usize; 3];
            p[axes.fixed] = slice;
            p[axes.across] = u;
            p[axes.vertical] = v;
            out.hovered = Some(p);
        }
        let window_drag = response.dragged_by(egui::PointerButton::Secondary)
            || (response.dragged_by(egui::PointerButton::Primary)
                && (modifiers.ctrl || modifiers.command));
        if window_drag {
            out.window_drag = response.drag_delta();
        } else if primary
            && !(modifiers.ctrl || modifiers.command)
            && (response.is_pointer_button_down_on() || response.clicked())
            && let Some(pos) = response.interact_pointer_pos()
            && let Some((u, v)) = axes.voxel_at(rect, pos.clamp(rect.min, rect.max), w, h)
        {
            crosshair[axes.across] = u;
            crosshair[axes.vertical] = v;
            crosshair[axes.fixed] = slice;
        }

        // Wheel and keys: move through slices.
        if response.hovered() {
            let steps = self.wheel_steps(ui);
            if steps != 0 && n_slices > 0 {
                crosshair[axes.fixed] =
                    (slice as i64 + steps).clamp(0, n_slices as i64 - 1) as usize;
            }
        }

        self.draw_overlay(&painter, rect, axes, crosshair, w, h, volume);
        out
    }

    /// Slices to move by the wheel events and keys of this frame.
    fn wheel_steps(&mut self, ui: &egui::Ui) -> i64 {
        let mut steps = 0i64;
        ui.input(|i| {
            for e in &i.events {
                match e {
                    egui::Event::MouseWheel { unit, delta, .. } => match unit {
                        egui::MouseWheelUnit::Line => steps += delta.y.round() as i64,
                        egui::MouseWheelUnit::Page => steps += (delta.y * 10.0).round() as i64,
                        egui::MouseWheelUnit::Point => self.wheel_points += delta.y,
                    },
                    egui::Event::Key {
                        key, pressed: true, ..
                    } => match key {
                        egui::Key::ArrowUp => steps += 1,
                        egui::Key::ArrowDown => steps -= 1,
                        egui::Key::PageUp => steps += 10,
                        egui::Key::PageDown => steps -= 10,
                        _ => {}
                    },
                    _ => {}
                }
            }
        });
        let whole = (self.wheel_points / POINTS_PER_SLICE).trunc();
        self.wheel_points -= whole * POINTS_PER_SLICE;
        steps + whole as i64
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
        let mut renderer = inputs.render_state.renderer.write();
        match self.texture_id {
            Some(_) if reused_size == Some(image.size) => {}
            Some(id) => renderer.update_egui_texture_from_wgpu_texture(
                &inputs.gpu.device,
                &image.view,
                wgpu::FilterMode::Linear,
                id,
            ),
            None => {
                self.texture_id = Some(renderer.register_native_texture(
                    &inputs.gpu.device,
                    &image.view,
                    wgpu::FilterMode::Linear,
                ));
            }
        }
        self.image = Some(image);
        self.drawn = Some(key);
        Ok(())
    }

    #[allow(clippy::too_many_arguments)]
    fn draw_overlay(
        &self,
        painter: &egui::Painter,
        rect: egui::Rect,
        axes: PaneAxes,
        crosshair: &[usize; 3],
        w: usize,
        h: usize,
        volume: &Volume,
    ) {
        // Crosshair lines with a gap around the point, so they never hide what is there.
        let c = axes.screen_of(rect, crosshair[axes.across], crosshair[axes.vertical], w, h);
        let gap = 10.0;
        let stroke =
            egui::Stroke::new(1.0, egui::Color32::from_rgba_unmultiplied(90, 220, 90, 200));
        for seg in [
            [egui::pos2(c.x, rect.top()), egui::pos2(c.x, c.y - gap)],
            [egui::pos2(c.x, c.y + gap), egui::pos2(c.x, rect.bottom())],
            [egui::pos2(rect.left(), c.y), egui::pos2(c.x - gap, c.y)],
            [egui::pos2(c.x + gap, c.y), egui::pos2(rect.right(), c.y)],
        ] {
            painter.line_segment(seg, stroke);
        }

        // Patient-direction labels on the four edges.
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
                rect.right_center() - egui::vec2(4.0, 0.0),
                egui::Align2::RIGHT_CENTER,
                right,
            ),
            (
                rect.left_center() + egui::vec2(4.0, 0.0),
                egui::Align2::LEFT_CENTER,
                -right,
            ),
            (
                rect.center_top() + egui::vec2(0.0, 4.0),
                egui::Align2::CENTER_TOP,
                up,
            ),
            (
                rect.center_bottom() - egui::vec2(0.0, 4.0),
                egui::Align2::CENTER_BOTTOM,
                -up,
            ),
        ] {
            painter.text(pos, align, orientation_label(d), font.clone(), colour);
        }
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
                };
                for (u, v) in [(0, 0), (9, 4), (3, 2)] {
                    let p = axes.screen_of(rect, u, v, 10, 5);
                    assert_eq!(axes.voxel_at(rect, p, 10, 5), Some((u, v)));
                }
                assert_eq!(axes.voxel_at(rect, egui::pos2(0.0, 0.0), 10, 5), None);
            }
        }
    }
}
