//! Drawing a frame: the ray caster prepared for the textures shown, a frame (or a band of its
//! rows) rendered into the pane's target or an off-screen one.

use super::*;
use crate::render::raycast::RaycastError;

/// What a frame shows: the volume, and the features over it.
#[derive(Clone, Copy)]
pub struct Shown<'a> {
    pub volume: &'a RenderVolume,
    pub features: Option<&'a FeatureTexture>,
}

/// Rows of a frame to render, and their cost ([`FrameCost`]: the samples the pacer counts).
#[derive(Clone, Debug, PartialEq)]
pub struct Band {
    pub rows: std::ops::Range<u32>,
    pub samples: f64,
}

impl MipView {
    /// Renders the band `band` of a frame of `shown` seen by `camera` into the caller's
    /// `target` (an off-screen frame: "Save movie"), with the pane's ray caster and brick
    /// tables; its samples count towards the pane's measured GPU rate.
    pub fn render_offscreen(
        &mut self,
        gpu: &GpuContext,
        shown: Shown<'_>,
        camera: &Camera,
        settings: &RenderSettings,
        target: &mut RaycastTarget,
        band: Band,
    ) -> Result<(), RaycastError> {
        let caster = self.prepare(gpu, shown)?;
        let scene = Scene {
            volume: shown.volume,
            features: shown.features,
            bricks: self.bricks.as_ref(),
            feature_bricks: self.feature_bricks.as_ref(),
        };
        let span = self.pacer.open(gpu);
        let rendered = caster.render(gpu, &scene, camera, settings, target, band.rows);
        // Kept whether or not the frame went well (remade only when it cannot be made).
        self.caster = Some(caster);
        rendered?;
        self.pacer.submitted(gpu, band.samples, span);
        Ok(())
    }

    /// The ray caster (made the first time), with brick tables started for the textures
    /// shown; the caller puts it back in `self.caster`.
    fn prepare(&mut self, gpu: &GpuContext, shown: Shown<'_>) -> Result<Raycaster, RaycastError> {
        let caster = match self.caster.take() {
            Some(c) => c,
            None => Raycaster::new(gpu)?,
        };
        if !self
            .bricks
            .as_ref()
            .is_some_and(|b| b.of(&shown.volume.intensity))
        {
            self.bricks = Some(caster.start_bricks(gpu, BrickSource::Intensity(shown.volume)));
        }
        if let Some(f) = shown.features
            && !self
                .feature_bricks
                .as_ref()
                .is_some_and(|b| b.of(&f.texture))
        {
            self.feature_bricks = Some(caster.start_bricks(gpu, BrickSource::Features(f)));
        }
        Ok(caster)
    }

    /// Renders `band` of the pane's frame into its target `slot` (made or remade at `size`),
    /// as [`MipView::render_offscreen`] does with the pane's camera.
    pub(super) fn render(
        &mut self,
        gpu: &GpuContext,
        render_state: &eframe::egui_wgpu::RenderState,
        shown: Shown<'_>,
        settings: &RenderSettings,
        (slot, size): (usize, [u32; 2]),
        band: Band,
    ) -> Result<(), RaycastError> {
        // A new target is made before the old one goes: if it cannot be, the old one stays.
        let (mut target, resized) = match self.targets[slot].take() {
            Some(t) if t.size == size => (t, false),
            old => match RaycastTarget::new(gpu, size) {
                Ok(t) => (t, true),
                Err(e) => {
                    self.targets[slot] = old;
                    return Err(e);
                }
            },
        };
        let camera = self.camera;
        let result = self.render_offscreen(gpu, shown, &camera, settings, &mut target, band);
        if resized {
            show_texture(render_state, gpu, &target.view, &mut self.texture_ids[slot]);
        }
        self.targets[slot] = Some(target);
        result
    }
}
