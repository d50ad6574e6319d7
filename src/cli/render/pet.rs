//! `render --pet`: the PET loaded, uploaded and drawn over the CT's MIP.

use super::*;

/// The PET of `render --pet`: loaded, uploaded, and the MIP settings it is drawn with.
pub(super) struct PetOverlay {
    pub volume: Volume,
    pub render: RenderVolume,
    pub settings: RenderSettings,
    pub opacity: f32,
}

impl PetOverlay {
    pub(super) fn load(
        ctx: &GpuContext,
        args: &RenderArgs,
        ct: &Volume,
    ) -> anyhow::Result<Option<Self>> {
        let Some(path) = &args.pet else {
            return Ok(None);
        };
        let files = crate::cli::features::read_input(path)?;
        let loaded = io::load(&files).with_context(|| format!("loading {}", path.display()))?;
        for w in &loaded.volume.warnings {
            eprintln!("warning: PET: {w}");
        }
        let volume = loaded.volume;
        if volume.modality != Modality::Pt {
            eprintln!(
                "warning: --pet {}: its modality is {}, not PT; fused as given",
                path.display(),
                volume.modality.as_str()
            );
        }
        if let Some(note) = crate::io::frame_of_reference_note(ct, &volume) {
            eprintln!("warning: {note}");
        }
        if !(0.0..=1.0).contains(&args.pet_opacity) {
            bail!("--pet-opacity {}: give 0..1", args.pet_opacity);
        }
        let window = match &args.pet_window {
            Some(w) => window_arg("--pet-window", w)?,
            None => default_window(&volume, Preset::default()),
        };
        let render = RenderVolume::upload(ctx, &volume)?;
        let settings = RenderSettings {
            window,
            ..Default::default()
        };
        Ok(Some(Self {
            volume,
            render,
            settings,
            opacity: args.pet_opacity,
        }))
    }

    /// The PET's MIP along the rays of `camera`, blended over `rgba` (the CT's picture).
    pub(super) fn fuse(
        &self,
        ctx: &GpuContext,
        caster: &Raycaster,
        camera: &Camera,
        size: [u32; 2],
        rgba: &mut [u8],
    ) -> anyhow::Result<()> {
        let scene = Scene {
            volume: &self.render,
            features: None,
            bricks: None,
            feature_bricks: None,
        };
        let mut target = RaycastTarget::new(ctx, size)?;
        caster.render(ctx, &scene, camera, &self.settings, &mut target, ..)?;
        let pet = target.read_image_blocking(ctx)?;
        crate::render::fusion::fuse_rgba(rgba, &pet, self.opacity);
        Ok(())
    }
}
