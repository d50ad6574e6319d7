//! What the MIP ray caster and the slice panes read every frame: the intensity and the feature
//! volumes as 3D textures, kept on the GPU after they are computed (features computed once,
//! projected many times).
//!
//! - Intensity: `R16Float`, physical values (HU, SUV, ...) times the volume's
//!   [`texture_value_scale`], uploaded once from the CPU volume. Half floats hold integers
//!   exactly up to 2048 and in steps of 2 up to 4096: enough for display; values shown to the
//!   user come from the CPU volume. The scale is a power of two, 1 for every volume whose values
//!   lie within 1..32768 in magnitude (CT, most MR): a PET in Bq/ml or counts (up to 10^6) would
//!   otherwise be clipped at the half float's 65504, and tiny float values would lose their
//!   precision among the subnormals. Scaling by a power of two commutes with rounding, so the
//!   texture keeps 11 significant bits of every value whatever its range.
//! - Features: `Rgb9e5Ufloat` per method, `(V, A, B)` in their physical units (no scale to
//!   keep): three 9-bit mantissas with a shared 5-bit exponent, 4 bytes per voxel (half of
//!   `Rgba16Float`), filterable everywhere, the features' range (0 to 65408) without a
//!   per-volume scale. Each channel is exact to half a step of the texel's largest channel
//!   (1/512 to 1/1024 of it): on the MIP a fraction of a grey level where that channel is the
//!   one shown. Written brick by brick by the GPU pipeline (the pack kernel encodes into a
//!   buffer, copied into the texture: the format cannot be a storage texture) or uploaded from
//!   CPU components with the same encoding ([`encode_rgb9e5`], bit for bit the kernel's).
//!   Features are non-negative (negative values are stored as 0). `max` is the largest value of
//!   each feature, for default gains.
//!
//! Both are on the volume's own voxel grid (the input grid), whatever grid features used. A
//! feature texture may be a max-pooled level of it ([`FeatureTexture::level`] L > 0: texel m
//! holds, per channel, the maximum over the 2^L x 2^L x 2^L voxels `m * 2^L ..`): what the GPU
//! budget ([`super::budget`]) allows when the full resolution does not fit. For a MIP a
//! max-pooled level is exact at its own resolution (the maximum over a pixel's footprint is the
//! maximum of the blocks' maxima), so no blob disappears from the projection.

mod histogram;
mod pool;
mod rgb9e5;

pub use histogram::{
    HISTOGRAM_BINS, feature_statistics, histogram_bin, histogram_bin_upper, histogram_quantile,
    reference_of,
};
pub use pool::pool_texels;
use rgb9e5::pow2;
pub use rgb9e5::{RGB9E5_MAX, decode_rgb9e5, encode_rgb9e5, encode_rgb9e5_up, feature_texel};

use super::alloc::{AllocCheck, Allocation};
use std::sync::Arc;
use std::sync::atomic::{AtomicU32, Ordering};

use crate::cpu::Components3;
use crate::gpu::GpuContext;
use crate::volume::Volume;

pub const INTENSITY_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::R16Float;
pub const FEATURE_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgb9e5Ufloat;
/// Bytes of one feature texel.
pub const FEATURE_TEXEL_BYTES: u32 = 4;

/// The power of two by which physical values are multiplied into the intensity texture (and the
/// display window with them): 1 when the largest magnitude of `range` lies within 1..=32768,
/// else the power of two that brings it into 16384..=32768 (finite, non-zero ranges only).
pub fn texture_value_scale(range: (f32, f32)) -> f32 {
    let m = range.0.abs().max(range.1.abs());
    if !m.is_finite() || m == 0.0 || (1.0..=32768.0).contains(&m) {
        return 1.0;
    }
    // floor(log2(m)) from the exponent bits (m is a normal f32 or a subnormal; both fine here).
    let e = ((m.to_bits() >> 23) & 0xff) as i32 - 127;
    // m * 2^(14 - e) lies in [2^14, 2^15).
    pow2((14 - e).clamp(-126, 127))
}

/// Why a volume cannot be shown on this device.
#[derive(Debug, thiserror::Error, Clone, PartialEq)]
#[non_exhaustive]
pub enum RenderVolumeError {
    #[error(
        "the volume ({0}x{1}x{2} voxels) exceeds this GPU's largest 3D texture ({3} voxels per side)"
    )]
    TooLarge(u32, u32, u32, u32),
    #[error("the volume is empty")]
    Empty,
    #[error("feature components have {got} values, the volume has {want} voxels")]
    Length { got: usize, want: usize },
    /// The device has no memory for the texture (`what`: "intensity", "features").
    #[error("the GPU has no memory for the {what} ({:.0} MB): {detail}", *.bytes as f64 / 1e6)]
    OutOfMemory {
        what: String,
        bytes: u64,
        detail: String,
    },
}

/// The bytes of a 3D texture of `dims` at `bytes_per_texel`.
pub fn texture_bytes(dims: [u32; 3], bytes_per_texel: u64) -> u64 {
    dims.iter().map(|&d| u64::from(d)).product::<u64>() * bytes_per_texel
}

/// `texture_3d` in an out-of-memory error scope: the texture, and the device's answer
/// ([`AllocCheck`]); refused at once (natively) is an error.
fn texture_3d_checked(
    ctx: &GpuContext,
    label: &str,
    dims: [u32; 3],
    format: wgpu::TextureFormat,
    usage: wgpu::TextureUsages,
) -> Result<(wgpu::Texture, AllocCheck), RenderVolumeError> {
    let (texture, mut check) =
        AllocCheck::around(ctx, || texture_3d(ctx, label, dims, format, usage));
    match check.poll() {
        Allocation::Refused(detail) => Err(out_of_memory(label, dims, format, detail)),
        Allocation::Waiting | Allocation::Granted => Ok((texture, check)),
    }
}

/// The error of a refused texture of `dims` in `format`.
fn out_of_memory(
    label: &str,
    dims: [u32; 3],
    format: wgpu::TextureFormat,
    detail: String,
) -> RenderVolumeError {
    RenderVolumeError::OutOfMemory {
        what: label.to_owned(),
        bytes: texture_bytes(dims, u64::from(format.block_copy_size(None).unwrap_or(4))),
        detail,
    }
}

/// Checks that `dims` fit a 3D texture on this device.
pub fn check_dims(ctx: &GpuContext, dims: [u32; 3]) -> Result<(), RenderVolumeError> {
    let max = ctx.limits.max_texture_dimension_3d;
    if dims.contains(&0) {
        return Err(RenderVolumeError::Empty);
    }
    if dims.iter().any(|&d| d > max) {
        return Err(RenderVolumeError::TooLarge(dims[0], dims[1], dims[2], max));
    }
    Ok(())
}

fn texture_3d(
    ctx: &GpuContext,
    label: &str,
    dims: [u32; 3],
    format: wgpu::TextureFormat,
    usage: wgpu::TextureUsages,
) -> wgpu::Texture {
    ctx.device.create_texture(&wgpu::TextureDescriptor {
        label: Some(label),
        size: wgpu::Extent3d {
            width: dims[0],
            height: dims[1],
            depth_or_array_layers: dims[2],
        },
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D3,
        format,
        usage,
        view_formats: &[],
    })
}

/// Writes z-slices `[z0, z0 + nz)` of a 3D texture from texel bytes (whole slices).
fn write_slices(
    ctx: &GpuContext,
    texture: &wgpu::Texture,
    dims: [u32; 3],
    bpt: u32,
    z0: u32,
    nz: u32,
    bytes: &[u8],
) {
    ctx.queue.write_texture(
        wgpu::TexelCopyTextureInfo {
            texture,
            mip_level: 0,
            origin: wgpu::Origin3d { x: 0, y: 0, z: z0 },
            aspect: wgpu::TextureAspect::All,
        },
        bytes,
        wgpu::TexelCopyBufferLayout {
            offset: 0,
            bytes_per_row: Some(dims[0] * bpt),
            rows_per_image: Some(dims[1]),
        },
        wgpu::Extent3d {
            width: dims[0],
            height: dims[1],
            depth_or_array_layers: nz,
        },
    );
}

/// Slices per CPU->GPU upload step of at most `bytes` (bounds the temporary CPU copy).
fn slices_per_chunk(dims: [u32; 3], bytes_per_texel: u32, bytes: u64) -> u32 {
    let slice = u64::from(dims[0]) * u64::from(dims[1]) * u64::from(bytes_per_texel);
    (bytes / slice.max(1)).clamp(1, u64::from(dims[2])) as u32
}

/// The intensity texture's usages. In the browser also RENDER_ATTACHMENT, though nothing renders
/// into it: the first slab written initialises the whole texture, and Dawn clears a renderable
/// texture with render passes where it otherwise fills a staging buffer as large as the texture
/// with zeros (1 GB more in the GPU process at 2000 slices, measured). Browsers older than the
/// WebGPU revision that allowed 3D render attachments refuse it, so the first volume is
/// uploaded without it while a 1-voxel probe finds out ([`probe_render_attachment_3d`]).
/// Natively wgpu clears a 3D texture by small buffer copies, so it is not asked for.
fn intensity_usage(ctx: &GpuContext) -> wgpu::TextureUsages {
    let usage = wgpu::TextureUsages::TEXTURE_BINDING
        | wgpu::TextureUsages::COPY_DST
        | wgpu::TextureUsages::COPY_SRC;
    #[cfg(target_arch = "wasm32")]
    match RENDER_ATTACHMENT_3D.load(Ordering::Acquire) {
        PROBE_YES => return usage | wgpu::TextureUsages::RENDER_ATTACHMENT,
        PROBE_UNKNOWN => probe_render_attachment_3d(ctx),
        _ => {}
    }
    #[cfg(not(target_arch = "wasm32"))]
    let _ = ctx;
    usage
}

/// What the browser said to a 3D render attachment: not asked yet, being asked, yes, no.
#[cfg(target_arch = "wasm32")]
static RENDER_ATTACHMENT_3D: std::sync::atomic::AtomicU8 = std::sync::atomic::AtomicU8::new(0);
#[cfg(target_arch = "wasm32")]
const PROBE_UNKNOWN: u8 = 0;
#[cfg(target_arch = "wasm32")]
const PROBE_ASKING: u8 = 1;
#[cfg(target_arch = "wasm32")]
const PROBE_YES: u8 = 2;
#[cfg(target_arch = "wasm32")]
const PROBE_NO: u8 = 3;

/// Asks the browser, once, whether a 3D texture may be a render attachment (the viewer asks at
/// start, so that the answer is in before its first volume; [`intensity_usage`]). Natively
/// there is nothing to ask: the device's features answer.
pub fn ask_render_attachment_3d(ctx: &GpuContext) {
    #[cfg(target_arch = "wasm32")]
    if RENDER_ATTACHMENT_3D.load(Ordering::Acquire) == PROBE_UNKNOWN {
        probe_render_attachment_3d(ctx);
    }
    #[cfg(not(target_arch = "wasm32"))]
    let _ = ctx;
}

/// Creates a 1-voxel 3D texture with RENDER_ATTACHMENT in an error scope and records, when the
/// browser answers, whether it was accepted.
#[cfg(target_arch = "wasm32")]
fn probe_render_attachment_3d(ctx: &GpuContext) {
    RENDER_ATTACHMENT_3D.store(PROBE_ASKING, Ordering::Release);
    let scope = ctx.device.push_error_scope(wgpu::ErrorFilter::Validation);
    let texture = texture_3d(
        ctx,
        "3D render attachment probe",
        [1, 1, 1],
        INTENSITY_FORMAT,
        wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::RENDER_ATTACHMENT,
    );
    let answer = scope.pop();
    wasm_bindgen_futures::spawn_local(async move {
        let refused = answer.await.is_some();
        drop(texture);
        RENDER_ATTACHMENT_3D.store(
            if refused { PROBE_NO } else { PROBE_YES },
            Ordering::Release,
        );
    });
}

/// Texture bytes per step of an intensity upload: 16 MiB, about 90 ms on lavapipe (the viewer
/// writes one or more per frame: one there).
const UPLOAD_SLAB_BYTES: u64 = 16 << 20;

/// The intensity of a volume as a 3D texture, with the geometry the ray caster needs.
pub struct RenderVolume {
    pub dims: [u32; 3],
    pub spacing_mm: [f32; 3],
    /// World (LPS, mm) from continuous voxel index.
    pub world_from_voxel: glam::DAffine3,
    pub intensity: wgpu::Texture,
    pub intensity_view: wgpu::TextureView,
    /// Smallest and largest physical value.
    pub value_range: (f32, f32),
    /// Texel value = physical value * `value_scale` ([`texture_value_scale`]).
    pub value_scale: f32,
}

impl RenderVolume {
    /// Uploads `volume` slab by slab (the CPU never holds a second full-size copy). Natively a
    /// texture the device has no memory for is the error; a browser answers a frame or more
    /// later, which [`Self::upload_checked`] lets the caller poll.
    pub fn upload(ctx: &GpuContext, volume: &Volume) -> Result<Self, RenderVolumeError> {
        Self::upload_checked(ctx, volume).map(|(render, _)| render)
    }

    /// The error of this texture refused by the device: `what` it held ("intensity", "PET"),
    /// `detail` the device's words.
    pub fn out_of_memory(&self, what: &str, detail: String) -> RenderVolumeError {
        out_of_memory(what, self.dims, INTENSITY_FORMAT, detail)
    }

    /// [`Self::upload`], and the device's answer to the texture (in a browser still to come:
    /// the texture is written at once, and is not to be drawn if the answer is a refusal).
    pub fn upload_checked(
        ctx: &GpuContext,
        volume: &Volume,
    ) -> Result<(Self, AllocCheck), RenderVolumeError> {
        let (render, mut upload) = Self::create(ctx, volume)?;
        // A browser answers the allocation between frames, never inside this loop.
        upload.wait_for_answer = false;
        while !upload.step(ctx, volume, &render)? {}
        Ok((render, upload.alloc))
    }

    /// The texture for `volume`, not yet written, and the upload that writes it a slab per
    /// [`IntensityUpload::step`] (the viewer spreads a large volume's upload over frames).
    pub fn create(
        ctx: &GpuContext,
        volume: &Volume,
    ) -> Result<(Self, IntensityUpload), RenderVolumeError> {
        let dims = volume.dims.map(|d| u32::try_from(d).unwrap_or(u32::MAX));
        check_dims(ctx, dims)?;
        let (intensity, alloc) = texture_3d_checked(
            ctx,
            "intensity",
            dims,
            INTENSITY_FORMAT,
            intensity_usage(ctx),
        )?;
        let intensity_view = intensity.create_view(&wgpu::TextureViewDescriptor::default());
        let value_range = volume.value_range().unwrap_or((0.0, 1.0));
        let render = Self {
            dims,
            spacing_mm: volume.spacing_mm.map(|s| s as f32),
            world_from_voxel: volume.world_from_voxel(),
            intensity,
            intensity_view,
            value_range,
            value_scale: texture_value_scale(value_range),
        };
        let upload = IntensityUpload {
            alloc,
            wait_for_answer: true,
            next_z: 0,
            per: slices_per_chunk(dims, 2, UPLOAD_SLAB_BYTES),
            in_flight: Arc::new(AtomicU32::new(0)),
        };
        Ok((render, upload))
    }
}

/// Writing a [`RenderVolume`]'s intensity, one slab of at most 16 MiB per step.
#[derive(Debug)]
pub struct IntensityUpload {
    /// The device's answer to the texture: nothing is written before it is in (in a
    /// browser a refused texture would fail every write).
    alloc: AllocCheck,
    /// Whether [`IntensityUpload::step`] waits for that answer (a blocking upload cannot).
    wait_for_answer: bool,
    next_z: u32,
    per: u32,
    /// Slabs submitted that the GPU has not finished (counted down by the queue's callback).
    in_flight: Arc<AtomicU32>,
}

/// Slabs an upload paced by [`IntensityUpload::ready`] keeps in flight at most (64 MiB): in the
/// browser a write returns before the GPU process has taken it, so without this bound the
/// page's and the GPU process's shared memory both queue up to the whole volume while a slow
/// device catches up.
pub const UPLOAD_SLABS_IN_FLIGHT: u32 = 4;

impl IntensityUpload {
    /// Whether the GPU has finished all but fewer than [`UPLOAD_SLABS_IN_FLIGHT`] slabs, so that
    /// the next may be written (the viewer stops writing for the frame when it has not).
    pub fn ready(&self) -> bool {
        self.in_flight.load(Ordering::Acquire) < UPLOAD_SLABS_IN_FLIGHT
    }

    /// Whether the device has not yet said whether it granted the texture (a browser answers
    /// a frame or more after it was made): [`Self::step`] writes nothing until it has.
    pub fn waiting(&mut self) -> bool {
        self.wait_for_answer && self.alloc.poll() == Allocation::Waiting
    }

    /// The fraction written so far.
    pub fn fraction(&self, render: &RenderVolume) -> f32 {
        self.next_z as f32 / render.dims[2].max(1) as f32
    }

    /// Writes the next slab of `volume` (the volume `render` was created for); true once the
    /// last one is written. Writes nothing while the device has not said whether it granted
    /// the texture; an error when it refused it.
    pub fn step(
        &mut self,
        ctx: &GpuContext,
        volume: &Volume,
        render: &RenderVolume,
    ) -> Result<bool, RenderVolumeError> {
        let dims = render.dims;
        match self.alloc.poll() {
            Allocation::Waiting if self.wait_for_answer => return Ok(false),
            Allocation::Refused(detail) => {
                return Err(out_of_memory("intensity", dims, INTENSITY_FORMAT, detail));
            }
            Allocation::Waiting | Allocation::Granted => {}
        }
        if self.next_z >= dims[2] {
            return Ok(true);
        }
        let z0 = self.next_z;
        let nz = self.per.min(dims[2] - z0);
        let n = dims[0] as usize * dims[1] as usize * nz as usize;
        let mut values = vec![0f32; n];
        volume.values_into(
            z0 as usize * dims[0] as usize * dims[1] as usize,
            &mut values,
        );
        let scale = render.value_scale;
        let halves: Vec<half::f16> = values
            .iter()
            .map(|&v| half::f16::from_f32(v * scale))
            .collect();
        drop(values);
        write_slices(
            ctx,
            &render.intensity,
            dims,
            2,
            z0,
            nz,
            bytemuck::cast_slice(&halves),
        );
        // Each slab goes now: the queue's staging for writes not yet submitted would
        // otherwise hold a second copy of the whole volume until the next submit (in the
        // browser in the page's and the GPU process's shared memory both).
        ctx.queue.submit(std::iter::empty());
        self.in_flight.fetch_add(1, Ordering::AcqRel);
        let in_flight = Arc::clone(&self.in_flight);
        ctx.queue.on_submitted_work_done(move || {
            in_flight.fetch_sub(1, Ordering::AcqRel);
        });
        self.next_z += nz;
        Ok(self.next_z >= dims[2])
    }
}

/// The dims of max-pooled level `level` of a volume of `dims`: `ceil(n / 2^level)` per axis.
pub fn level_dims(dims: [u32; 3], level: u32) -> [u32; 3] {
    dims.map(|n| n.div_ceil(1u32 << level.min(31)).max(1))
}

/// One method's features `(V, A, B, 0)` on the volume's grid, as a 3D texture: at full
/// resolution (level 0) or as a max-pooled level of it.
pub struct FeatureTexture {
    /// The volume's grid the features describe (voxels).
    pub dims: [u32; 3],
    /// 0: a texel per voxel; L > 0: each texel the per-channel maximum of a block of 2^L voxels
    /// per axis ([`level_dims`]).
    pub level: u32,
    /// The texture's own size: `level_dims(dims, level)`.
    pub texture_dims: [u32; 3],
    pub texture: wgpu::Texture,
    pub view: wgpu::TextureView,
    /// The largest value of each feature; `[0; 3]` until known.
    pub max: [f32; 3],
    /// The 99.9th percentile of each feature's positive values (docs/science.md, "Rendering"):
    /// what a gain of 1 shows as full colour, so that one metal voxel or a contrast bolus does
    /// not dim every other structure; `[0; 3]` until known (then `max` serves).
    pub p999: [f32; 3],
}

impl FeatureTexture {
    /// What a gain of 1 shows as full colour, per feature: [`Self::p999`] where known, else the
    /// maximum.
    pub fn reference(&self) -> [f32; 3] {
        reference_of(self.max, self.p999)
    }

    /// The texel that holds voxel `voxel` (clamped into the texture).
    pub fn texel_of(&self, voxel: [u32; 3]) -> [u32; 3] {
        std::array::from_fn(|a| {
            (voxel[a] >> self.level.min(31)).min(self.texture_dims[a].saturating_sub(1))
        })
    }

    /// Voxels per texel along each axis (1 at full resolution).
    pub fn block(&self) -> u32 {
        1u32 << self.level.min(31)
    }

    /// What a value read from this texture is, for a readout beside it: "" at full
    /// resolution, " (max of 2x2x2)" at level 1 (a block's maximum, not the voxel's value).
    pub fn value_note(&self) -> String {
        if self.level == 0 {
            return String::new();
        }
        let f = self.block();
        format!(" (max of {f}x{f}x{f})")
    }
}

impl FeatureTexture {
    /// An empty feature texture the GPU pipeline copies into and renderers sample.
    pub fn new(ctx: &GpuContext, dims: [u32; 3], label: &str) -> Result<Self, RenderVolumeError> {
        Self::new_checked(ctx, dims, label).map(|(t, _)| t)
    }

    /// [`Self::new`] and the device's answer to the texture ([`AllocCheck`]: natively a
    /// refusal is already the error; in a browser the owner polls it before using it).
    pub fn new_checked(
        ctx: &GpuContext,
        dims: [u32; 3],
        label: &str,
    ) -> Result<(Self, AllocCheck), RenderVolumeError> {
        Self::new_level_checked(ctx, dims, 0, label)
    }

    /// [`Self::new_checked`] for max-pooled level `level` of a volume of `dims`.
    pub fn new_level_checked(
        ctx: &GpuContext,
        dims: [u32; 3],
        level: u32,
        label: &str,
    ) -> Result<(Self, AllocCheck), RenderVolumeError> {
        if dims.contains(&0) {
            return Err(RenderVolumeError::Empty);
        }
        let texture_dims = level_dims(dims, level);
        check_dims(ctx, texture_dims)?;
        let (texture, alloc) = texture_3d_checked(
            ctx,
            label,
            texture_dims,
            FEATURE_FORMAT,
            wgpu::TextureUsages::TEXTURE_BINDING
                | wgpu::TextureUsages::COPY_DST
                | wgpu::TextureUsages::COPY_SRC,
        )?;
        let view = texture.create_view(&wgpu::TextureViewDescriptor::default());
        let texture = Self {
            dims,
            level,
            texture_dims,
            texture,
            view,
            max: [0.0; 3],
            p999: [0.0; 3],
        };
        Ok((texture, alloc))
    }

    /// The error of this texture refused by the device (`detail`: its words).
    pub fn out_of_memory(&self, detail: String) -> RenderVolumeError {
        out_of_memory("features", self.texture_dims, FEATURE_FORMAT, detail)
    }

    /// The texture's bytes on the device.
    pub fn bytes(&self) -> u64 {
        texture_bytes(self.texture_dims, u64::from(FEATURE_TEXEL_BYTES))
    }

    /// Level `level` of the features `components` as a texture ([`pool_texels`], the pool
    /// kernel's twin); level 0 is [`Self::from_components`].
    pub fn from_components_level(
        ctx: &GpuContext,
        dims: [u32; 3],
        level: u32,
        components: &Components3,
        label: &str,
    ) -> Result<Self, RenderVolumeError> {
        if level == 0 {
            return Self::from_components(ctx, dims, components, label);
        }
        let want = dims.iter().map(|&d| d as usize).product::<usize>();
        if let Some(c) = components.iter().find(|c| c.len() != want) {
            return Err(RenderVolumeError::Length { got: c.len(), want });
        }
        let (mut tex, _) = Self::new_level_checked(ctx, dims, level, label)?;
        let texels = pool_texels(components, dims, level);
        let td = tex.texture_dims;
        write_slices(
            ctx,
            &tex.texture,
            td,
            FEATURE_TEXEL_BYTES,
            0,
            td[2],
            bytemuck::cast_slice(&texels),
        );
        (tex.max, tex.p999) = feature_statistics(components);
        Ok(tex)
    }

    /// A feature texture filled from CPU components (e.g. the CPU reference's output).
    pub fn from_components(
        ctx: &GpuContext,
        dims: [u32; 3],
        components: &Components3,
        label: &str,
    ) -> Result<Self, RenderVolumeError> {
        let mut tex = Self::new(ctx, dims, label)?;
        let want = dims.iter().map(|&d| d as usize).product::<usize>();
        if let Some(c) = components.iter().find(|c| c.len() != want) {
            return Err(RenderVolumeError::Length { got: c.len(), want });
        }
        let per = slices_per_chunk(dims, FEATURE_TEXEL_BYTES, 32 << 20);
        let slice = dims[0] as usize * dims[1] as usize;
        let mut texels: Vec<u32> = Vec::with_capacity(slice * per as usize);
        let mut z0 = 0;
        while z0 < dims[2] {
            let nz = per.min(dims[2] - z0);
            let range = z0 as usize * slice..(z0 + nz) as usize * slice;
            texels.clear();
            texels.extend(
                range.map(|idx| encode_rgb9e5(std::array::from_fn(|c| components[c][idx]))),
            );
            write_slices(
                ctx,
                &tex.texture,
                dims,
                FEATURE_TEXEL_BYTES,
                z0,
                nz,
                bytemuck::cast_slice(&texels),
            );
            z0 += nz;
        }
        (tex.max, tex.p999) = feature_statistics(components);
        Ok(tex)
    }
}

/// Decodes feature texels (`Rgb9e5Ufloat`, as copied out of a feature texture) into
/// `(V, A, B, 0)`.
pub fn decode_feature_texels(bytes: &[u8]) -> impl Iterator<Item = [f32; 4]> + '_ {
    bytes.chunks_exact(4).map(|b| {
        let [v, a, c] = decode_rgb9e5(u32::from_le_bytes([b[0], b[1], b[2], b[3]]));
        [v, a, c, 0.0]
    })
}

/// Native only (tests, export): a feature texture's texels `(V, A, B, 0)` as f32, i fastest.
#[cfg(not(target_arch = "wasm32"))]
pub fn read_texture_blocking(
    ctx: &GpuContext,
    tex: &FeatureTexture,
) -> Result<Vec<f32>, crate::gpu::readback::ReadbackError> {
    let bytes = crate::gpu::readback::read_texture_blocking(
        ctx,
        &tex.texture,
        tex.texture_dims,
        FEATURE_TEXEL_BYTES,
    )?;
    Ok(decode_feature_texels(&bytes).flatten().collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rounding_up_never_falls_below_a_voxel_of_the_block() {
        let mut rng = crate::cpu::testing::Lcg::new(99);
        let mut next = || rng.unit();
        for _ in 0..100_000 {
            // Within the format's range (above it every encoding clamps).
            let scale = 2f32.powf(next() * 22.0 - 15.0);
            // Two voxels of a block: a bright vessel and a faint blob.
            let a = [next() * scale * 300.0, 0.0, next() * scale];
            let b = [next() * scale, next() * scale, next() * scale * 2.0];
            let m: [f32; 3] = std::array::from_fn(|c| a[c].max(b[c]));
            let up = decode_rgb9e5(encode_rgb9e5_up(m));
            for v in [a, b] {
                let dense = feature_texel(v);
                for c in 0..3 {
                    assert!(
                        up[c] >= v[c] && up[c] >= dense[c],
                        "{m:?} -> {up:?}, voxel {v:?}"
                    );
                }
            }
            // A texel read back encodes to itself (a block finished by a later chunk).
            assert_eq!(decode_rgb9e5(encode_rgb9e5_up(up)), up);
        }
    }

    #[test]
    fn shared_exponent_round_trip() {
        // Exact where the mantissas hold the values.
        for v in [
            [0.0, 0.0, 0.0],
            [1.0, 0.5, 0.25],
            [511.0, 3.0, 0.0],
            [65408.0, 0.0, 128.0],
        ] {
            assert_eq!(feature_texel(v), v, "{v:?}");
        }
        // Clamped: negative and NaN to 0, above the range to the maximum.
        assert_eq!(feature_texel([-1.0, f32::NAN, 1e9]), [0.0, 0.0, 65408.0]);
        // Rounding carries into the exponent: 511.75 needs 2^10 steps of 1.
        assert_eq!(feature_texel([511.75, 0.0, 0.0]), [512.0, 0.0, 0.0]);
        // Every channel within half a step of the texel's largest: (1/512 .. 1/1024 of it).
        let mut rng = crate::cpu::testing::Lcg::new(12345);
        let mut next = || rng.unit();
        for _ in 0..200_000 {
            let scale = 2f32.powf(next() * 35.0 - 20.0);
            let v = [next() * scale, next() * scale * next(), next() * scale];
            let t = feature_texel(v);
            let m = v[0].max(v[1]).max(v[2]);
            for c in 0..3 {
                let step = (m / 256.0).max(2f32.powi(-24));
                assert!((t[c] - v[c]).abs() <= 0.5 * step, "{v:?} -> {t:?}");
            }
        }
    }
}
