//! The PET's MIP viewport beside the shape MIP (the paper's Fig. 21): its camera follows the
//! shape MIP's, its window is the PET's.

use super::*;

/// The PET's MIP viewport: its camera follows the shape MIP's.
#[derive(Default)]
pub struct PetMip {
    mip: MipView,
    /// The PET texture the viewport last framed (its first frame keeps the CT's camera).
    mip_for: Option<usize>,
}

/// Where the PET's MIP goes: the MIP pane, and where the shape MIP's image starts in it.
#[derive(Clone, Copy, Debug)]
pub struct MipArea {
    pub pane: egui::Rect,
    pub image_top: f32,
    /// The shared crosshair (LPS mm), marked in the PET's MIP as in the shape MIP.
    pub crosshair_mm: Option<DVec3>,
}

/// What the PET's MIP did this frame.
pub struct PetMipOutput {
    /// A click picked this point (LPS mm): the PET's maximum along that ray.
    pub pick: Option<DVec3>,
    /// What is left of the MIP pane for the shape MIP.
    pub rest: egui::Rect,
    /// The PET's window after this frame (a right drag in the viewport sets it).
    pub window: (f32, f32),
}

impl PetMip {
    /// Where the PET's MIP image was drawn last frame.
    pub fn image_area(&self) -> egui::Rect {
        self.mip.image_area()
    }

    /// Whether the PET's MIP was drawn with another camera than `camera` (the shape MIP's,
    /// moved after it this frame): it needs another frame.
    pub fn lags(&self, camera: &Camera) -> bool {
        self.mip_for.is_some() && self.mip.camera != *camera
    }

    /// The PET MIP's picture state ([`MipView::picture_state`]).
    pub fn picture_state(&self) -> &'static str {
        self.mip.picture_state()
    }

    /// The PET's MIP in the left half of the MIP pane's `area`, turned with `camera` (the shape
    /// MIP's: a drag in either turns both): inverted grey in the PET's window. `None` (the
    /// whole pane for the shape MIP) without a PET shown.
    pub fn ui(
        &mut self,
        ui: &mut egui::Ui,
        area: MipArea,
        gpu: &GpuContext,
        render_state: &eframe::egui_wgpu::RenderState,
        layer: Option<&PetLayer>,
        camera: &mut Camera,
    ) -> Option<PetMipOutput> {
        let MipArea {
            pane: area,
            image_top,
            crosshair_mm,
        } = area;
        let layer = layer.filter(|l| l.visible)?;
        let render = layer.render.as_ref()?;
        let (left, right) = area.split_left_right_at_fraction(0.5);
        let mut pick = None;
        let mut touched = false;
        let mut window = layer.window;
        let first = self.mip_for != Some(Arc::as_ptr(&layer.volume) as usize);
        let mip = &mut self.mip;
        ui.scope_builder(egui::UiBuilder::new().max_rect(left.shrink(2.0)), |ui| {
            ui.horizontal(|ui| {
                ui.label(egui::RichText::new("PET MIP").strong());
                ui.label(format!(
                    "{:.1} to {:.1} {}",
                    layer.window.0,
                    layer.window.1,
                    layer.volume.unit()
                ));
            });
            // The image starts where the shape MIP's does (below its toolbar), so that both
            // have one size and one scale.
            let gap = image_top - ui.cursor().top();
            if gap > 0.0 && gap < 200.0 {
                ui.add_space(gap);
            }
            mip.camera = *camera;
            mip.set_crosshair(crosshair_mm);
            mip.settings.window = layer.window;
            mip.settings.invert_grey = true;
            mip.settings.show_intensity = true;
            mip.mode = None;
            let scene = MipScene {
                volume: render,
                features: &[],
            };
            let out = mip.image_ui(ui, gpu, render_state, &scene);
            pick = out.pick.map(|p| p.world_mm);
            // Only the user's own moves here (drag, wheel, the view's keys) turn the shape MIP.
            touched = out.response.dragged() || out.response.hovered();
            // Its right drag sets the PET's window, as in the slice panes.
            if mip.settings.window.1 > mip.settings.window.0 {
                window = mip.settings.window;
            }
        });
        if first || !touched {
            // The viewport framed the PET on its first frame (or changed its camera by itself):
            // the shape MIP's view stays, and is the PET's from the next frame.
            self.mip_for = Some(Arc::as_ptr(&layer.volume) as usize);
            if self.mip.camera != *camera {
                self.mip.camera = *camera;
                ui.ctx().request_repaint();
            }
        } else if self.mip.camera != *camera {
            *camera = self.mip.camera;
            ui.ctx().request_repaint();
        }
        Some(PetMipOutput {
            pick,
            rest: right,
            window,
        })
    }
}
