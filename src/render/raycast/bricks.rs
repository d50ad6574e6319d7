//! Empty-space skipping: brick extrema tables, the host side of raycast_bricks.wgsl (one
//! compute pass per texture) and its CPU twin [`cpu_bricks`].

use crate::gpu::GpuContext;
use crate::gpu::kernel::{bind_group, params_buffer};
use crate::gpu::volume_texture::{FeatureTexture, RenderVolume};
use crate::render::{output_texture, submit_dispatch};

#[cfg(not(target_arch = "wasm32"))]
use super::RaycastError;
use super::Raycaster;
use super::settings::BIG;

/// Edge of the bricks of the empty-space skipping, voxels (raycast_bricks.wgsl).
pub const BRICK: u32 = 8;

/// Brick counts per axis for a volume of `dims` (brick b covers positions `[8b, 8b + 8]`).
pub fn brick_dims(dims: [u32; 3]) -> [u32; 3] {
    dims.map(|n| n.saturating_sub(1).div_ceil(BRICK).max(1))
}

/// Brick extrema of one texture (the volume's intensity, or one method's features), for
/// empty-space skipping: made once per texture with [`Raycaster::intensity_bricks`] or
/// [`Raycaster::feature_bricks`] (whole), or started with [`Raycaster::start_bricks`] and made
/// a few brick slices at a time with [`Bricks::advance`] (the viewer keeps each frame's GPU work
/// small); used every frame once [`Bricks::complete`]. Holds a handle of its source, so it is
/// only ever used with that texture.
pub struct Bricks {
    pub dims: [u32; 3],
    pub texture: wgpu::Texture,
    pub view: wgpu::TextureView,
    source: wgpu::Texture,
    source_view: wgpu::TextureView,
    features: bool,
    /// The source's level (a feature texture may be max-pooled) and the volume's voxels.
    level: u32,
    volume_dims: [u32; 3],
    /// Brick slices made so far.
    done_z: u32,
}

/// Which texture a brick table is made of.
#[derive(Clone, Copy)]
pub enum BrickSource<'a> {
    Intensity(&'a RenderVolume),
    Features(&'a FeatureTexture),
}

/// Mirrors `Slices` in raycast_bricks.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
struct Slices {
    z0: u32,
    nz: u32,
    level: u32,
    _pad0: u32,
    dims: [u32; 3],
    _pad1: u32,
}
const _: () = assert!(std::mem::size_of::<Slices>() == 32);

impl Bricks {
    /// Native only: the brick values (tests), brick x fastest.
    #[cfg(not(target_arch = "wasm32"))]
    pub fn read_blocking(&self, ctx: &GpuContext) -> Result<Vec<[f32; 4]>, RaycastError> {
        let bytes = crate::gpu::readback::read_texture_blocking(ctx, &self.texture, self.dims, 8)?;
        let halves: Vec<half::f16> = bytemuck::pod_collect_to_vec(&bytes);
        Ok(halves
            .chunks_exact(4)
            .map(|t| [t[0].to_f32(), t[1].to_f32(), t[2].to_f32(), t[3].to_f32()])
            .collect())
    }

    /// Whether these are the bricks of `texture`.
    pub fn of(&self, texture: &wgpu::Texture) -> bool {
        self.source == *texture
    }

    /// Whether every brick is made (skipping uses only complete tables).
    pub fn complete(&self) -> bool {
        self.done_z >= self.dims[2]
    }

    /// Source voxels one brick slice reads (the unit of [`Self::advance`]'s cost).
    pub fn voxels_per_slice(&self) -> u64 {
        u64::from(self.dims[0]) * u64::from(self.dims[1]) * u64::from(BRICK + 1).pow(3)
    }

    /// Makes the next `slices` brick slices (at least one; submitted, not waited for). Returns
    /// the source voxels read.
    pub fn advance(&mut self, caster: &Raycaster, ctx: &GpuContext, slices: u32) -> u64 {
        if self.complete() {
            return 0;
        }
        let nz = slices.max(1).min(self.dims[2] - self.done_z);
        let pipeline = if self.features {
            &caster.bricks_features
        } else {
            &caster.bricks_intensity
        };
        let range = params_buffer(
            &ctx.device,
            "raycast brick slices",
            &Slices {
                z0: self.done_z,
                nz,
                level: self.level,
                _pad0: 0,
                dims: self.volume_dims,
                _pad1: 0,
            },
        );
        let bind_group = bind_group(
            &ctx.device,
            "raycast bricks",
            pipeline,
            [
                wgpu::BindingResource::TextureView(&self.source_view),
                wgpu::BindingResource::TextureView(&self.view),
                range.as_entire_binding(),
            ],
        );
        let groups = [
            self.dims[0].div_ceil(4),
            self.dims[1].div_ceil(4),
            nz.div_ceil(4),
        ];
        submit_dispatch(ctx, "raycast bricks", pipeline, &bind_group, groups);
        self.done_z += nz;
        u64::from(nz) * self.voxels_per_slice()
    }
}

impl Raycaster {
    /// The brick extrema of the volume's intensity, made whole (one pass).
    pub fn intensity_bricks(&self, ctx: &GpuContext, volume: &RenderVolume) -> Bricks {
        self.whole_bricks(ctx, BrickSource::Intensity(volume))
    }

    /// The brick extrema of one method's features, made whole (one pass).
    pub fn feature_bricks(&self, ctx: &GpuContext, features: &FeatureTexture) -> Bricks {
        self.whole_bricks(ctx, BrickSource::Features(features))
    }

    fn whole_bricks(&self, ctx: &GpuContext, source: BrickSource<'_>) -> Bricks {
        let mut bricks = self.start_bricks(ctx, source);
        bricks.advance(self, ctx, u32::MAX);
        bricks
    }

    /// An empty brick table of `source`, to be made with [`Bricks::advance`].
    pub fn start_bricks(&self, ctx: &GpuContext, source: BrickSource<'_>) -> Bricks {
        let (texture, view, dims, features, level) = match source {
            BrickSource::Intensity(v) => (&v.intensity, &v.intensity_view, v.dims, false, 0),
            BrickSource::Features(f) => (&f.texture, &f.view, f.dims, true, f.level),
        };
        let nb = brick_dims(dims);
        let (out, out_view) = output_texture(
            ctx,
            "raycast bricks",
            wgpu::TextureDimension::D3,
            nb,
            wgpu::TextureFormat::Rgba16Float,
        );
        Bricks {
            dims: nb,
            texture: out,
            view: out_view,
            source: texture.clone(),
            source_view: view.clone(),
            features,
            level,
            volume_dims: dims,
            done_z: 0,
        }
    }
}

/// The CPU twin of raycast_bricks.wgsl. For each brick: `[max c0, min c0, max c1, max c2]` of
/// the three values `get` gives per voxel (intensity: all three the same).
pub fn cpu_bricks<T>(dims: [u32; 3], values: &[T], get: impl Fn(&T) -> [f32; 3]) -> Vec<[f32; 4]> {
    cpu_bricks_of_level(dims, 0, dims, values, get)
}

/// [`cpu_bricks`] of a max-pooled level `level` (`values` a texture of `texture_dims`): each
/// brick of the volume's `dims` over the texels of the blocks that hold its voxels, as the
/// kernel reads a pooled feature texture.
pub fn cpu_bricks_of_level<T>(
    dims: [u32; 3],
    level: u32,
    texture_dims: [u32; 3],
    values: &[T],
    get: impl Fn(&T) -> [f32; 3],
) -> Vec<[f32; 4]> {
    let nb = brick_dims(dims);
    let t = texture_dims.map(|x| x as usize);
    let mut out = Vec::with_capacity(nb.iter().map(|&x| x as usize).product());
    for bz in 0..nb[2] {
        for by in 0..nb[1] {
            for bx in 0..nb[0] {
                let b = [bx, by, bz];
                let lo: [usize; 3] = std::array::from_fn(|a| ((b[a] * BRICK) >> level) as usize);
                let hi: [usize; 3] = std::array::from_fn(|a| {
                    ((b[a] * BRICK + BRICK).min(dims[a].saturating_sub(1)) >> level) as usize
                });
                let mut e = [-BIG, BIG, -BIG, -BIG];
                for k in lo[2]..=hi[2] {
                    for j in lo[1]..=hi[1] {
                        for i in lo[0]..=hi[0] {
                            let v = get(&values[i + t[0] * (j + t[1] * k)]);
                            e[0] = e[0].max(v[0]);
                            e[1] = e[1].min(v[0]);
                            e[2] = e[2].max(v[1]);
                            e[3] = e[3].max(v[2]);
                        }
                    }
                }
                out.push(e);
            }
        }
    }
    out
}
