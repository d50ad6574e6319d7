//! The shape-encoding MIP ray caster (shaders/raycast.wgsl): the picture of the MIP viewport and
//! of `shapecast render`, and the depth per pixel that click-to-navigate reads back.
//!
//! - Input: the intensity texture of a [`RenderVolume`] and, optionally, one method's
//!   [`FeatureTexture`] `(V, A, B, 0)`. Nothing is recomputed: a frame only projects.
//! - Geometry: an orthographic [`Camera`] in world LPS mm. The world rays are turned into voxel
//!   space through the volume's `world_from_voxel`, so anisotropic and oblique volumes render at
//!   their true shape. Samples lie at `t = k * step` (k integer, `t` the depth in mm from the
//!   plane through the camera's centre), `step = step_fraction * smallest spacing` (half a voxel
//!   by default), inside the box of the voxels (`[-0.5, n - 0.5]` in voxel coordinates) and the
//!   slab, if any. Aligning the samples to a grid in `t` keeps the picture still when the slab
//!   moves.
//! - Sampling: trilinear, computed in the shader from `textureLoad` of the 8 neighbours
//!   (positions clamped to `[0, n - 1]`, i.e. borders replicated), not by the sampler: the CPU
//!   twin ([`cpu_twin`]) does the same arithmetic in f32 on the same half-float values, so images
//!   agree to a level of 8 bits and picks to the sample.
//! - Colour (paper section 5.2: every feature projected on its own, then composited): grey =
//!   windowed intensity MIP (or MinIP); over it, in this order, red = vesselness, blue =
//!   airwayness, yellow = blobness, each with opacity `clamp(F_max * gain / feature maximum, 0,
//!   1)`. Blobness comes last, so a blob (which by eq. 1 has vesselness too) is yellow to orange,
//!   a vessel red.
//! - Pick rule: each pixel stores the depth of the extreme of its *dominant channel*, the channel
//!   with the largest share of the final colour: yellow `a_B`, blue `a_A (1 - a_B)`, red
//!   `a_V (1 - a_A)(1 - a_B)`, grey `vis (1 - a_V)(1 - a_A)(1 - a_B)` with `vis` the grey level
//!   (MIP) or its complement (MinIP); ties to the earlier channel (intensity first). On ties
//!   along the ray the sample nearest the viewer wins. [`RaycastTarget::pick`] turns that depth
//!   back into a world point and a voxel.
//! - Empty-space skipping: with [`Bricks`] (extrema of 8^3-voxel bricks, one compute pass per
//!   texture) in the [`Scene`], a ray jumps over a brick when neither its intensity nor any shown
//!   feature can exceed the running extremes, and skips the loads of one kind when only that kind
//!   cannot. Updates need a strictly larger value, so the picture and the picks are unchanged
//!   (tested against the unskipped GPU frame and the twin, which skips the same way).
//! - Progressive frames: [`Raycaster::render`] draws a band of rows; a frame drawn band by
//!   band is the same, pixel for pixel, as one drawn whole. [`FrameCost`] counts a frame's sample
//!   slots and [`FramePacer`] measures how many the device projects per second, so the viewer
//!   keeps every frame's GPU work within a budget (a coarse frame first, then bands).
//!
//! One file per concern: `settings` (the frame's settings and the uniforms mirroring
//! raycast.wgsl), `bricks` (the brick tables of the skipping), `target` (the render target, its
//! readbacks and the picks), `twin` (the CPU twin of the pass), `pace` (the progressive
//! renderer's clock); here, the pass itself.

mod bricks;
mod pace;
mod settings;
mod target;
mod twin;

pub use bricks::{BRICK, BrickSource, Bricks, brick_dims, cpu_bricks};
pub use pace::{FramePacer, FramePlan, MIN_COARSE_SCALE, scale_within};
pub use settings::{
    CHANNEL_COLOURS, ChannelDisplay, Params, Projection, RenderSettings, Slab, VolumeGeometry,
    params,
};
#[cfg(not(target_arch = "wasm32"))]
pub use target::read_feature_texel_blocking;
pub use target::{
    Channel, PendingPick, Pick, RaycastTarget, RenderedView, pixel_of_uv, read_feature_texel,
};
pub use twin::{TwinImage, TwinScene, cpu_twin};

use crate::gpu::kernel::bind_group;
use crate::gpu::readback::ReadbackError;
use crate::gpu::volume_texture::{FeatureTexture, RenderVolume};
use crate::gpu::{GpuContext, checks, shaders};
use crate::render::camera::Camera;
use crate::render::{no_features_view, submit_dispatch};

/// Why a frame or a pick failed.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum RaycastError {
    #[error(transparent)]
    Shader(#[from] shaders::ShaderSourceError),
    #[error(transparent)]
    Readback(#[from] ReadbackError),
    #[error("image size {0}x{1} is empty or larger than this GPU's 2D textures ({2} per side)")]
    Size(u32, u32, u32),
    #[error("the feature texture is {got:?} voxels, the volume {want:?}")]
    FeatureDims { got: [u32; 3], want: [u32; 3] },
}

/// The ray caster's pipeline and the stand-in for "no features".
pub struct Raycaster {
    pipeline: wgpu::ComputePipeline,
    no_features: wgpu::TextureView,
    linear_clamp: wgpu::Sampler,
    bricks_intensity: wgpu::ComputePipeline,
    bricks_features: wgpu::ComputePipeline,
}

/// What a frame projects: the volume, optionally one method's features, and optionally their
/// bricks (skipping is on when the bricks of every texture used are given).
#[derive(Clone, Copy)]
pub struct Scene<'a> {
    pub volume: &'a RenderVolume,
    pub features: Option<&'a FeatureTexture>,
    pub bricks: Option<&'a Bricks>,
    pub feature_bricks: Option<&'a Bricks>,
}

impl<'a> Scene<'a> {
    /// A scene without bricks (no skipping).
    pub fn new(volume: &'a RenderVolume, features: Option<&'a FeatureTexture>) -> Self {
        Self {
            volume,
            features,
            bricks: None,
            feature_bricks: None,
        }
    }

    /// Whether the bricks given belong to the textures used, so that skipping is exact.
    pub fn skipping(&self) -> bool {
        let volume_ok = self
            .bricks
            .is_some_and(|b| b.of(&self.volume.intensity) && b.complete());
        let features_ok = match self.features {
            None => true,
            Some(f) => self
                .feature_bricks
                .is_some_and(|b| b.of(&f.texture) && b.complete()),
        };
        volume_ok && features_ok
    }
}

impl Raycaster {
    pub fn new(ctx: &GpuContext) -> Result<Self, RaycastError> {
        let module = shaders::create_module(&ctx.device, "raycast.wgsl")?;
        let linear_clamp = ctx.device.create_sampler(&wgpu::SamplerDescriptor {
            label: Some("raycast linear clamp"),
            address_mode_u: wgpu::AddressMode::ClampToEdge,
            address_mode_v: wgpu::AddressMode::ClampToEdge,
            address_mode_w: wgpu::AddressMode::ClampToEdge,
            mag_filter: wgpu::FilterMode::Linear,
            min_filter: wgpu::FilterMode::Linear,
            mipmap_filter: wgpu::MipmapFilterMode::Nearest,
            ..Default::default()
        });
        let bricks_module = shaders::create_module(&ctx.device, "raycast_bricks.wgsl")?;
        Ok(Self {
            pipeline: checks::labelled_pipeline(ctx, "raycast", &module, "main"),
            no_features: no_features_view(ctx, "raycast no features"),
            linear_clamp,
            bricks_intensity: checks::pipeline(ctx, &bricks_module, "bricks_intensity"),
            bricks_features: checks::pipeline(ctx, &bricks_module, "bricks_features"),
        })
    }

    /// Renders the image rows `rows` (`..` for the whole frame) into `target` (submitted; not
    /// waited for), the other rows untouched: a frame drawn band by band over several
    /// submissions (progressive rendering, [`FrameCost`]) is the same, pixel for pixel, as one
    /// drawn whole. Bricks in the scene turn on empty-space skipping, which does not change the
    /// picture or the picks.
    pub fn render(
        &self,
        ctx: &GpuContext,
        scene: &Scene<'_>,
        camera: &Camera,
        settings: &RenderSettings,
        target: &mut RaycastTarget,
        rows: impl std::ops::RangeBounds<u32>,
    ) -> Result<(), RaycastError> {
        use std::ops::Bound;
        let h = target.size[1];
        let start = match rows.start_bound() {
            Bound::Included(&r) => r,
            Bound::Excluded(&r) => r.saturating_add(1),
            Bound::Unbounded => 0,
        };
        let end = match rows.end_bound() {
            Bound::Included(&r) => r.saturating_add(1),
            Bound::Excluded(&r) => r,
            Bound::Unbounded => h,
        };
        let rows = start.min(h)..end.min(h);
        if rows.is_empty() {
            return Ok(());
        }
        let (volume, features) = (scene.volume, scene.features);
        if let Some(f) = features
            && f.dims != volume.dims
        {
            return Err(RaycastError::FeatureDims {
                got: f.dims,
                want: volume.dims,
            });
        }
        let geometry = VolumeGeometry::of(volume);
        let p = params(
            &geometry,
            camera,
            settings,
            target.size,
            features.map(|f| f.reference()),
        );
        let skipping = scene.skipping();
        let mut p = if skipping { p.with_skipping() } else { p };
        (p.row0, p.row_end) = (rows.start, rows.end);
        p.feature_level = features.map_or(0, |f| f.level);
        ctx.queue
            .write_buffer(&target.params, 0, bytemuck::bytes_of(&p));
        let feature_view = features.map_or(&self.no_features, |f| &f.view);
        let (brick_view, feature_brick_view) = match (skipping, scene.bricks) {
            (true, Some(b)) => (
                &b.view,
                scene.feature_bricks.map_or(&self.no_features, |f| &f.view),
            ),
            _ => (&self.no_features, &self.no_features),
        };
        let bind_group = bind_group(
            &ctx.device,
            "raycast",
            &self.pipeline,
            [
                target.params.as_entire_binding(),
                wgpu::BindingResource::TextureView(&volume.intensity_view),
                wgpu::BindingResource::TextureView(feature_view),
                wgpu::BindingResource::TextureView(&target.view),
                target.pick.as_entire_binding(),
                wgpu::BindingResource::Sampler(&self.linear_clamp),
                wgpu::BindingResource::TextureView(brick_view),
                wgpu::BindingResource::TextureView(feature_brick_view),
            ],
        );
        let groups = [
            target.size[0].div_ceil(8),
            (rows.end - rows.start).div_ceil(8),
            1,
        ];
        submit_dispatch(ctx, "raycast", &self.pipeline, &bind_group, groups);
        target.rendered = Some(RenderedView {
            camera: *camera,
            size: target.size,
            geometry,
        });
        Ok(())
    }
}

/// What a frame costs the GPU, in samples: each ray's sample count inside the box of the voxels
/// and the slab, exactly as the shader finds it ([`twin`]'s `ray_span`), plus a few for the
/// ray's setup; counted on every `stride`-th pixel of each row. Empty-space skipping makes the
/// real cost lower in air; [`FramePacer`] measures the rate on the device's own frames.
#[derive(Clone, Debug, PartialEq)]
pub struct FrameCost {
    size: [u32; 2],
    /// `prefix[r]`: samples of rows `[0, r)`.
    prefix: Vec<f64>,
}

/// Samples a ray costs beyond its own (setup, the miss test).
const RAY_SETUP_SAMPLES: f64 = 4.0;

impl FrameCost {
    /// The cost of each row of a `size` frame of `volume` from `camera`.
    pub fn of(
        volume: &RenderVolume,
        camera: &Camera,
        settings: &RenderSettings,
        size: [u32; 2],
    ) -> Self {
        let p = params(&VolumeGeometry::of(volume), camera, settings, size, None);
        let [w, h] = size;
        let stride = (w / 128).max(1);
        let per = f64::from(w) / f64::from(w.div_ceil(stride).max(1));
        let mut prefix = Vec::with_capacity(h as usize + 1);
        let mut total = 0.0;
        prefix.push(total);
        for y in 0..h {
            let mut row = 0.0;
            for x in (0..w).step_by(stride as usize) {
                let o: [f32; 3] = std::array::from_fn(|a| {
                    p.origin_v[a] + p.du_v[a] * x as f32 + p.dv_v[a] * y as f32
                });
                let (t0, t1, _, count) = twin::ray_span(&p, o);
                if t0 <= t1 && count > 0 {
                    row += f64::from(count);
                }
                row += RAY_SETUP_SAMPLES;
            }
            total += row * per;
            prefix.push(total);
        }
        Self { size, prefix }
    }

    /// The frame's size.
    pub fn size(&self) -> [u32; 2] {
        self.size
    }

    /// Samples of the whole frame.
    pub fn total(&self) -> f64 {
        self.prefix.last().copied().unwrap_or(0.0)
    }

    /// Samples of the rows `rows`.
    pub fn rows(&self, rows: std::ops::Range<u32>) -> f64 {
        let at = |r: u32| self.prefix[(r as usize).min(self.prefix.len() - 1)];
        (at(rows.end) - at(rows.start)).max(0.0)
    }

    /// The band from row `start` that costs at most `budget` samples: its end (at least one
    /// row, at most the frame's height). Bands of whole workgroups (8 rows) where the budget
    /// allows.
    pub fn band_within(&self, start: u32, budget: f64) -> u32 {
        let h = self.size[1];
        if start >= h {
            return h;
        }
        let base = self.prefix[start as usize];
        // The last end whose cost fits (the prefix is non-decreasing).
        let fits =
            self.prefix[start as usize + 1..].partition_point(|&c| c - base <= budget) as u32;
        let rows = fits.max(1);
        let rows = if rows >= 8 { rows / 8 * 8 } else { rows };
        (start + rows).min(h)
    }
}
