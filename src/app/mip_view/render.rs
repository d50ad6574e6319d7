//! Drawing a frame: the ray caster prepared for the textures shown, a frame (or a band of its
//! rows) rendered into the pane's target or an off-screen one.

use super::*;

impl MipView {
    /// Renders the rows `rows` of a frame of `volume` and `features` seen by `camera` into the
    /// caller's `target` (an off-screen frame: "Save movie"), with the pane's ray caster and
    /// brick tables; `samples` (its [`FrameCost`]) counts towards the pane's measured GPU rate.
    #[allow(clippy::too_many_arguments)]
    pub fn render_offscreen(
        &mut self,
        gpu: &GpuContext,
        volume: &RenderVolume,
        features: Option<&FeatureTexture>,
        camera: &Camera,
        settings: &RenderSettings,
        target: &mut RaycastTarget,
        rows: std::ops::Range<u32>,
        samples: f64,
    ) -> Result<(), String> {
        self.prepare(gpu, volume, features)?;
        let Some(caster) = &self.caster else {
            return Err("the ray caster is not ready".to_owned());
        };
        let scene = Scene {
            volume,
            features,
            bricks: self.bricks.as_ref(),
            feature_bricks: self.feature_bricks.as_ref(),
        };
        let span = self.pacer.open(gpu);
        caster
            .render(gpu, &scene, camera, settings, target, rows)
            .map_err(|e| e.to_string())?;
        self.pacer.submitted(gpu, samples, span);
        Ok(())
    }

    /// The ray caster, and brick tables started for the textures shown.
    pub(super) fn prepare(
        &mut self,
        gpu: &GpuContext,
        volume: &RenderVolume,
        features: Option<&FeatureTexture>,
    ) -> Result<(), String> {
        if self.caster.is_none() {
            self.caster = Some(Raycaster::new(gpu).map_err(|e| e.to_string())?);
        }
        let Some(caster) = &self.caster else {
            return Err("the ray caster is not ready".to_owned());
        };
        if !self
            .bricks
            .as_ref()
            .is_some_and(|b| b.of(&volume.intensity))
        {
            self.bricks = Some(caster.start_bricks(gpu, BrickSource::Intensity(volume)));
        }
        if let Some(f) = features
            && !self
                .feature_bricks
                .as_ref()
                .is_some_and(|b| b.of(&f.texture))
        {
            self.feature_bricks = Some(caster.start_bricks(gpu, BrickSource::Features(f)));
        }
        Ok(())
    }

    /// Renders `rows` of the frame into target `slot` (of `size`), timing the caster's
    /// submission of their `samples` for the pacer.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn render(
        &mut self,
        gpu: &GpuContext,
        render_state: &eframe::egui_wgpu::RenderState,
        volume: &RenderVolume,
        features: Option<&FeatureTexture>,
        settings: &RenderSettings,
        slot: usize,
        size: [u32; 2],
        (rows, samples): (std::ops::Range<u32>, f64),
    ) -> Result<(), String> {
        self.prepare(gpu, volume, features)?;
        let resized = self.targets[slot].as_ref().is_none_or(|t| t.size != size);
        if resized {
            self.targets[slot] = Some(RaycastTarget::new(gpu, size).map_err(|e| e.to_string())?);
        }
        let (Some(caster), Some(target)) = (&self.caster, &mut self.targets[slot]) else {
            return Err("the ray caster is not ready".to_owned());
        };
        let scene = Scene {
            volume,
            features,
            bricks: self.bricks.as_ref(),
            feature_bricks: self.feature_bricks.as_ref(),
        };
        let span = self.pacer.open(gpu);
        caster
            .render(gpu, &scene, &self.camera, settings, target, rows)
            .map_err(|e| e.to_string())?;
        self.pacer.submitted(gpu, samples, span);
        if resized {
            show_texture(render_state, gpu, &target.view, &mut self.texture_ids[slot]);
        }
        Ok(())
    }
}
