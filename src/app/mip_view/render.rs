//! Drawing a frame: the ray caster prepared for the textures shown, a frame (or a band of its
//! rows) rendered into the pane's target or an off-screen one.

use super::*;

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
    ) -> Result<(), String> {
        self.prepare(gpu, shown)?;
        let Some(caster) = &self.caster else {
            return Err("the ray caster is not ready".to_owned());
        };
        let scene = Scene {
            volume: shown.volume,
            features: shown.features,
            bricks: self.bricks.as_ref(),
            feature_bricks: self.feature_bricks.as_ref(),
        };
        let span = self.pacer.open(gpu);
        caster
            .render(gpu, &scene, camera, settings, target, band.rows)
            .map_err(|e| e.to_string())?;
        self.pacer.submitted(gpu, band.samples, span);
        Ok(())
    }

    /// The ray caster, and brick tables started for the textures shown.
    pub(super) fn prepare(&mut self, gpu: &GpuContext, shown: Shown<'_>) -> Result<(), String> {
        if self.caster.is_none() {
            self.caster = Some(Raycaster::new(gpu).map_err(|e| e.to_string())?);
        }
        let Some(caster) = &self.caster else {
            return Err("the ray caster is not ready".to_owned());
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
        Ok(())
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
    ) -> Result<(), String> {
        let resized = self.targets[slot].as_ref().is_none_or(|t| t.size != size);
        // A new target is made before the old one goes: if it cannot be, the old one stays.
        let made = if resized {
            Some(RaycastTarget::new(gpu, size).map_err(|e| e.to_string())?)
        } else {
            None
        };
        let Some(mut target) = made.or_else(|| self.targets[slot].take()) else {
            return Err("the ray caster is not ready".to_owned());
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
