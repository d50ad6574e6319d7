//! The shape-encoding MIP viewport: an egui widget that owns the camera and the render settings,
//! draws the GPU ray caster's image ([`crate::render::raycast`]) and turns mouse input into camera
//! moves and picks. It re-renders only when something that changes the picture changed (camera,
//! settings, size, the textures), so an idle viewer costs nothing.
//!
//! No frame waits on more than [`MipView::FRAME_BUDGET_S`] of GPU work (0.06 s, below ~100 ms on
//! any device, lavapipe included): a frame that would cost more is drawn first at a coarse
//! resolution that fits, then at full resolution in bands of rows over the following frames, shown
//! when complete; while the mouse moves the view only the reduced preview is drawn, small enough to
//! fit. The cost is counted in samples along the rays ([`FrameCost`]) and the device's rate
//! measured on its own frames ([`FramePacer`]).
//!
//! Mouse: left drag turns the volume (arcball), middle drag or shift + left drag pans, the
//! wheel zooms towards the pointer, right drag sets the grey window as in the slice panes
//! (right = wider, down = darker). A left click (press and release without moving: egui's click, not a drag)
//! asks where that pixel's maximum came from; the answer arrives a frame or two later in
//! [`MipViewOutput::pick`] (GPU readback with `map_async`, never blocking).
//!
//! Use (the app owns the GPU textures, the crosshair and the slice panes):
//! ```ignore
//! // once
//! let mut mip = MipView::new();
//! // every frame
//! let scene = MipScene { volume: &render_volume, features: &[("RST", &rst), ("Hessian", &hes)] };
//! mip.controls_ui(ui, &scene);
//! let out = mip.image_ui(ui, &gpu, render_state, &scene);
//! if let Some(pick) = out.pick {
//!     crosshair = pick.voxel;                 // move the slice panes
//!     mip.set_crosshair(Some(pick.world_mm)); // marker, and the slab's centre
//! }
//! ```

mod controls;
mod overlay;
mod render;
pub use render::{Band, Shown};

use super::paint::show_texture;

use glam::{DVec2, DVec3};

use crate::gpu::GpuContext;
use crate::gpu::volume_texture::{FeatureTexture, RenderVolume};
use crate::render::camera::{Camera, ViewPreset};
use crate::render::raycast::{
    BrickSource, Bricks, CHANNEL_COLOURS, FrameCost, FramePacer, FramePlan, PendingPick, Pick,
    Projection, RaycastTarget, Raycaster, RenderSettings, Scene, Slab, scale_within,
};
use crate::volume::orientation_label;

/// What the viewport shows: the intensity and the feature sets computed so far, by name
/// (e.g. "RST", "Hessian"). Switching between them never recomputes anything.
pub struct MipScene<'a> {
    pub volume: &'a RenderVolume,
    pub features: &'a [(&'a str, &'a FeatureTexture)],
}

/// What happened in the viewport this frame.
pub struct MipViewOutput {
    /// The image's response (hover, clicks, drags).
    pub response: egui::Response,
    /// A pick that finished this frame: move the crosshair there.
    pub pick: Option<Pick>,
    /// The image pixel under the pointer.
    pub hover_pixel: Option<[u32; 2]>,
    /// Where the maximum of the pixel under the pointer lies (as a click's pick, read back
    /// without blocking a frame or two after the pointer stops; `None` off the volume).
    pub hover: Option<Pick>,
    /// Whether a new frame was rendered this frame.
    pub rendered: bool,
}

/// Everything that changes the picture: a new frame is rendered only when it differs.
#[derive(Clone, PartialEq)]
struct FrameKey {
    camera: Camera,
    settings: RenderSettings,
    /// Full resolution.
    size: [u32; 2],
    /// The mouse is moving the view (a reduced preview is drawn).
    interacting: bool,
    volume: wgpu::Texture,
    features: Option<(wgpu::Texture, [f32; 3])>,
}

/// A full-resolution frame in progress: rows `[0, next_row)` of target 0 are drawn.
struct Refining {
    next_row: u32,
    /// What each row of the full frame costs.
    cost: FrameCost,
}

/// The MIP viewport widget (see the module documentation).
pub struct MipView {
    pub camera: Camera,
    /// Projection, window, grey and channel toggles and gains, step. Its `slab` is derived from
    /// [`Self::slab_mm`] and the crosshair each frame.
    pub settings: RenderSettings,
    /// Slab thickness around the crosshair (or the view's centre), mm; `None`: whole volume.
    pub slab_mm: Option<f64>,
    /// The feature set shown, by name; `None`: intensity only.
    pub mode: Option<String>,
    /// The shared crosshair in LPS mm, drawn as a marker; the slab's centre.
    pub crosshair_mm: Option<DVec3>,
    /// The findings' numbered markers, set by the app each frame.
    pub markers: Vec<super::findings::Marker>,
    /// Resolution (fraction of the full one) of the frames drawn while a drag or the wheel
    /// moves the view; the full resolution follows when the mouse stops. 1 turns it off.
    pub interactive_scale: f32,
    /// The GPU's measured speed and the budget of GPU seconds per frame (`budget_s: None`
    /// draws every frame whole).
    pub pacer: FramePacer,
    /// The full-resolution frame being drawn band by band (the coarse one shown meanwhile).
    refining: Option<Refining>,
    last_samples: f64,
    mode_chosen: bool,
    caster: Option<Raycaster>,
    /// Brick extrema of the textures last shown (empty-space skipping), remade when they change.
    bricks: Option<Bricks>,
    feature_bricks: Option<Bricks>,
    /// Full resolution (0) and the preview drawn while the mouse moves the view (1).
    targets: [Option<RaycastTarget>; 2],
    texture_ids: [Option<egui::TextureId>; 2],
    /// Which target the user sees.
    shown: usize,
    last: Option<FrameKey>,
    pending: Option<PendingPick>,
    /// The hover pick in flight, and for which pixel of which frame.
    hover_pending: Option<PendingPick>,
    /// The pixel (and frame count) the hover pick is or was for, and its result.
    hover_for: Option<([u32; 2], u64)>,
    hover: Option<Pick>,
    /// A line the app shows in the image's corner (the value under the pointer).
    pub hover_text: Option<String>,
    error: Option<String>,
    frames: u64,
    image_rect: egui::Rect,
}

impl Default for MipView {
    fn default() -> Self {
        Self::new()
    }
}

impl MipView {
    /// GPU seconds of work one frame may wait on (leaves headroom below ~100 ms, since the
    /// measured rate lags).
    pub const FRAME_BUDGET_S: f64 = 0.06;

    pub fn new() -> Self {
        Self {
            camera: Camera::default(),
            settings: RenderSettings {
                // One trilinear fetch by the texture unit per sample: the interactive path.
                hardware_filtering: true,
                ..RenderSettings::default()
            },
            slab_mm: None,
            mode: None,
            crosshair_mm: None,
            markers: Vec::new(),
            interactive_scale: 0.5,
            pacer: FramePacer::new(Some(Self::FRAME_BUDGET_S)),
            refining: None,
            last_samples: 0.0,
            mode_chosen: false,
            caster: None,
            bricks: None,
            feature_bricks: None,
            targets: [None, None],
            texture_ids: [None, None],
            shown: 0,
            last: None,
            pending: None,
            hover_pending: None,
            hover_for: None,
            hover: None,
            hover_text: None,
            error: None,
            frames: 0,
            image_rect: egui::Rect::NOTHING,
        }
    }

    /// Moves the crosshair marker (and with it a slab's centre).
    pub fn set_crosshair(&mut self, world_mm: Option<DVec3>) {
        self.crosshair_mm = world_mm;
    }

    /// Frames the volume again (anterior view, zoom 1).
    pub fn reset_view(&mut self, volume: &RenderVolume) {
        self.camera =
            Camera::for_volume(&volume.world_from_voxel, volume.dims, ViewPreset::Anterior);
    }

    /// Where the image was drawn last frame (screen points).
    pub fn image_area(&self) -> egui::Rect {
        self.image_rect
    }

    /// How many frames the ray caster has rendered (tests: nothing re-renders when idle).
    pub fn frames_rendered(&self) -> u64 {
        self.frames
    }

    /// The last error (shader, readback, size), shown in the viewport too.
    pub fn error(&self) -> Option<&str> {
        self.error.as_deref()
    }

    /// Whether the reduced-resolution frame of a drag or wheel move is shown.
    pub fn showing_preview(&self) -> bool {
        self.shown == 1
    }

    /// Samples ([`FrameCost`]) of the last dispatch: what the frame budget bounds.
    pub fn last_dispatch_samples(&self) -> f64 {
        self.last_samples
    }

    /// Whether the full-resolution frame is still being drawn in bands (a coarse one shown).
    pub fn refining(&self) -> bool {
        self.refining.is_some()
    }

    /// The picture's state for automation: "none", "coarse", "refining" or "done"
    /// ([`crate::status::AppStatus::mip`]).
    pub fn picture_state(&self) -> &'static str {
        if self.frames == 0 {
            "none"
        } else if self.refining() {
            "refining"
        } else if self.showing_preview() {
            "coarse"
        } else {
            "done"
        }
    }

    /// Whether a pick is being read back.
    pub fn pick_pending(&self) -> bool {
        self.pending.is_some()
    }

    /// The screen position of a world point in the last frame (e.g. to click it in a test).
    pub fn screen_pos_of(&self, world_mm: DVec3) -> Option<egui::Pos2> {
        let view = self.shown_target()?.rendered()?;
        let (p, _) = view.camera.project(world_mm, view.size);
        let rect = self.image_rect;
        let x = rect.left() + (p.x as f32 / view.size[0] as f32) * rect.width();
        let y = rect.top() + (p.y as f32 / view.size[1] as f32) * rect.height();
        let pos = egui::pos2(x, y);
        rect.contains(pos).then_some(pos)
    }

    fn shown_target(&self) -> Option<&RaycastTarget> {
        self.targets[self.shown].as_ref()
    }

    /// The image pixel under a screen position.
    pub fn pixel_at(&self, pos: egui::Pos2) -> Option<[u32; 2]> {
        let target = self.shown_target()?;
        let rect = self.image_rect;
        if !rect.contains(pos) || rect.width() <= 0.0 || rect.height() <= 0.0 {
            return None;
        }
        let u = f64::from((pos.x - rect.left()) / rect.width());
        let v = f64::from((pos.y - rect.top()) / rect.height());
        crate::render::raycast::pixel_of_uv(DVec2::new(u, v), target.size)
    }

    /// The settings the pane's frames are drawn with: [`Self::settings`] with the slab around
    /// the crosshair (or the view's centre).
    pub fn frame_settings(&self) -> RenderSettings {
        let mut settings = self.settings;
        settings.slab = self.slab_mm.map(|t| Slab {
            centre_mm: self.crosshair_mm.unwrap_or(self.camera.centre_mm),
            thickness_mm: t,
        });
        settings
    }

    /// The size of the pane's full-resolution frame, in pixels (`None` before the first).
    pub fn full_size(&self) -> Option<[u32; 2]> {
        self.last.as_ref().map(|k| k.size)
    }

    /// The feature texture of the current mode, if the scene has it.
    pub fn features<'a>(&self, scene: &MipScene<'a>) -> Option<&'a FeatureTexture> {
        let name = self.mode.as_deref()?;
        scene
            .features
            .iter()
            .find(|(n, _)| *n == name)
            .map(|(_, f)| *f)
    }

    /// The image: fills the available space, handles the mouse, renders if needed.
    pub fn image_ui(
        &mut self,
        ui: &mut egui::Ui,
        gpu: &GpuContext,
        render_state: &eframe::egui_wgpu::RenderState,
        scene: &MipScene<'_>,
    ) -> MipViewOutput {
        let (rect, response) =
            ui.allocate_exact_size(ui.available_size(), egui::Sense::click_and_drag());
        self.image_rect = rect;
        let ppp = ui.ctx().pixels_per_point();
        let max = gpu.limits.max_texture_dimension_2d.max(1);
        // Input works in full-resolution pixels, whatever resolution is drawn.
        let full = [
            ((rect.width() * ppp).round() as u32).clamp(1, max),
            ((rect.height() * ppp).round() as u32).clamp(1, max),
        ];
        let new_volume = self
            .last
            .as_ref()
            .is_none_or(|k| k.volume != scene.volume.intensity);
        if new_volume {
            self.reset_view(scene.volume);
        }

        // Input, against the frame the user is looking at.
        let mut pick = None;
        let to_px = |p: egui::Pos2| {
            DVec2::new(
                f64::from((p.x - rect.left()) * ppp),
                f64::from((p.y - rect.top()) * ppp),
            )
        };
        let shift = ui.input(|i| i.modifiers.shift);
        if let Some(pos) = response.interact_pointer_pos() {
            let delta = response.drag_delta();
            if delta != egui::Vec2::ZERO {
                let (from, to) = (to_px(pos - delta), to_px(pos));
                if response.dragged_by(egui::PointerButton::Middle)
                    || (shift && response.dragged_by(egui::PointerButton::Primary))
                {
                    self.camera.pan(to.x - from.x, to.y - from.y, full);
                } else if response.dragged_by(egui::PointerButton::Primary) {
                    self.camera.arcball(from, to, full);
                } else if response.dragged_by(egui::PointerButton::Secondary) {
                    // The slice panes' convention (down = darker, right = wider).
                    self.settings.window =
                        super::window_level::Window::from_bounds(self.settings.window)
                            .dragged(delta)
                            .bounds();
                }
            }
        }
        if response.clicked()
            && let (Some(pos), Some(gpu_target)) =
                (response.interact_pointer_pos(), self.shown_target())
            && let Some(px) = self.pixel_at(pos)
        {
            self.pending = gpu_target.start_pick(gpu, px);
        }
        let mut wheeled = false;
        if response.hovered() {
            let wheel: f32 = ui.input(|i| {
                i.events
                    .iter()
                    .map(|e| match e {
                        egui::Event::MouseWheel { unit, delta, .. } => match unit {
                            egui::MouseWheelUnit::Point => delta.y,
                            egui::MouseWheelUnit::Line => delta.y * 40.0,
                            egui::MouseWheelUnit::Page => delta.y * 400.0,
                        },
                        _ => 0.0,
                    })
                    .sum()
            });
            if wheel != 0.0
                && let Some(pos) = response.hover_pos()
            {
                self.camera
                    .zoom_at((f64::from(wheel) * 0.002).exp(), to_px(pos), full);
                wheeled = true;
            }
        }
        if let Some(pending) = &mut self.pending {
            match pending.poll() {
                None => ui.ctx().request_repaint(),
                Some(Ok(p)) => {
                    pick = p;
                    self.pending = None;
                }
                Some(Err(e)) => {
                    self.error = Some(format!("pick: {}", crate::error::chain(&e)));
                    self.pending = None;
                }
            }
        }

        // Render if anything changed: while the mouse moves the view a reduced preview that fits
        // the frame budget; otherwise the full frame, whole if it fits, else a coarse frame first
        // and the full one in bands over the following frames.
        let interacting = response.dragged() || wheeled;
        if interacting {
            // The full frame follows when the mouse stops.
            ui.ctx().request_repaint();
        }
        if self.pacer.poll(gpu) {
            ui.ctx().request_repaint();
        }
        let features = self.features(scene);
        let settings = self.frame_settings();
        let key = FrameKey {
            camera: self.camera,
            settings,
            size: full,
            interacting,
            volume: scene.volume.intensity.clone(),
            features: features.map(|f| (f.texture.clone(), f.reference())),
        };
        let mut rendered = false;
        let mut step = None;
        self.pacer.set_scene(features.is_some());
        if self.last.as_ref() != Some(&key) {
            self.refining = None;
            let cost = FrameCost::of(scene.volume, &self.camera, &settings, full);
            let full_samples = cost.total();
            let budget = self.pacer.budget_samples();
            let cap = if self.interactive_scale.is_finite() {
                self.interactive_scale.clamp(0.1, 1.0)
            } else {
                1.0
            };
            let scale = if interacting {
                scale_within(full_samples, budget, cap)
            } else {
                match FramePlan::of(full_samples, budget) {
                    FramePlan::Whole => 1.0,
                    FramePlan::Progressive { coarse_scale } => coarse_scale,
                }
            };
            let slot = usize::from(scale < 1.0);
            let size = if slot == 1 {
                full.map(|s| ((s as f32 * scale).round() as u32).max(1))
            } else {
                full
            };
            let samples = full_samples * f64::from(scale) * f64::from(scale);
            if slot == 1 && !interacting {
                self.refining = Some(Refining { next_row: 0, cost });
            }
            step = Some((slot, size, 0..size[1], samples));
            self.last = Some(key);
        } else if let Some(r) = &self.refining {
            let end = r.cost.band_within(r.next_row, self.pacer.budget_samples());
            let rows = r.next_row..end;
            step = Some((0, full, rows.clone(), r.cost.rows(rows)));
        }
        if let Some((slot, size, rows, samples)) = step {
            let shown = Shown {
                volume: scene.volume,
                features,
            };
            let band = Band {
                rows: rows.clone(),
                samples,
            };
            match self.render(gpu, render_state, shown, &settings, (slot, size), band) {
                Ok(()) => {
                    self.last_samples = samples;
                    rendered = true;
                    self.frames += 1;
                    self.error = None;
                    let refining_band = slot == 0 && self.refining.is_some();
                    if refining_band {
                        if rows.end >= full[1] {
                            self.refining = None;
                            self.shown = 0;
                        } else if let Some(r) = &mut self.refining {
                            r.next_row = rows.end;
                        }
                    } else {
                        self.shown = slot;
                    }
                }
                Err(e) => {
                    self.error = Some(crate::error::chain(&e));
                    self.refining = None;
                }
            }
            if self.refining.is_some() {
                ui.ctx().request_repaint();
            }
        }
        // Brick tables of a new texture, a few slices a frame (half the budget when a frame was
        // drawn too); skipping starts when a table is complete (the picture is the same).
        if let Some(caster) = &self.caster {
            let budget = self.pacer.budget_samples() * if rendered { 0.5 } else { 1.0 };
            let tables = [self.bricks.as_mut(), self.feature_bricks.as_mut()];
            if let Some(b) = tables.into_iter().flatten().find(|b| !b.complete()) {
                let slices = (budget / b.voxels_per_slice() as f64).clamp(1.0, f64::from(u32::MAX));
                b.advance(caster, gpu, slices as u32);
                ui.ctx().request_repaint();
            }
        }

        // Draw.
        let painter = ui.painter_at(rect);
        painter.rect_filled(rect, 0.0, egui::Color32::BLACK);
        if let Some(id) = self.texture_ids[self.shown] {
            painter.image(
                id,
                rect,
                egui::Rect::from_min_max(egui::pos2(0.0, 0.0), egui::pos2(1.0, 1.0)),
                egui::Color32::WHITE,
            );
        }
        self.draw_overlay(&painter, rect);
        // Orthographic: one scale for the whole image (mm per full-resolution pixel).
        let mm_per_point = self.camera.mm_per_pixel(full) * f64::from(ppp);
        super::paint::draw_scale_bar(&painter, rect, (1.0 / mm_per_point) as f32);

        let hover_pixel = response.hover_pos().and_then(|p| self.pixel_at(p));
        self.update_hover(gpu, ui.ctx(), hover_pixel, response.dragged() || wheeled);
        MipViewOutput {
            response,
            pick,
            hover_pixel,
            hover: self.hover.filter(|_| hover_pixel.is_some()),
            rendered,
        }
    }

    /// Keeps a pick of the pixel under the pointer (one readback in flight; a new one when the
    /// pointer reaches another pixel or a new frame is shown).
    fn update_hover(
        &mut self,
        gpu: &GpuContext,
        ctx: &egui::Context,
        pixel: Option<[u32; 2]>,
        moving_view: bool,
    ) {
        if let Some(pending) = &mut self.hover_pending {
            match pending.poll() {
                None => ctx.request_repaint(),
                Some(Ok(p)) => {
                    self.hover = p;
                    self.hover_pending = None;
                }
                Some(Err(_)) => {
                    // A failed hover readback only loses the hover value; a click reports.
                    self.hover = None;
                    self.hover_pending = None;
                }
            }
        }
        let Some(px) = pixel.filter(|_| !moving_view) else {
            self.hover = None;
            self.hover_for = None;
            return;
        };
        let wanted = (px, self.frames);
        if self.hover_for != Some(wanted)
            && self.hover_pending.is_none()
            && self.refining.is_none()
            && let Some(target) = self.shown_target()
        {
            self.hover_pending = target.start_pick(gpu, px);
            self.hover_for = Some(wanted);
            ctx.request_repaint();
        }
    }
}
