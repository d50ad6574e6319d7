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

use glam::{DAffine3, DVec2, DVec3};

use crate::gpu::readback::{self, ReadbackError};
use crate::gpu::volume_texture::{FeatureTexture, RenderVolume};
use crate::gpu::{GpuContext, shaders};
use crate::render::camera::Camera;

/// Mirrors `Params` in raycast.wgsl (keep in sync).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct Params {
    pub origin_v: [f32; 3],
    pub step_mm: f32,
    pub du_v: [f32; 3],
    pub slab_lo: f32,
    pub dv_v: [f32; 3],
    pub slab_hi: f32,
    pub dir_v: [f32; 3],
    pub mode: u32,
    pub dims: [u32; 3],
    pub flags: u32,
    pub feature_scale: [f32; 3],
    pub window_lo: f32,
    pub out_size: [u32; 2],
    pub window_hi: f32,
    pub max_steps: u32,
}
const _: () = assert!(std::mem::size_of::<Params>() == 112);

impl Params {
    /// The same frame with empty-space skipping on (the shader then reads the bricks; the CPU
    /// twin skips as it does when its scene has bricks).
    pub fn with_skipping(mut self) -> Self {
        self.flags |= FLAG_BRICKS;
        self
    }
}

const FLAG_FEATURES: u32 = 1;
const FLAG_INTENSITY: u32 = 2;
const FLAG_FILTERED: u32 = 4;
const FLAG_BRICKS: u32 = 8;

/// Edge of the bricks of the empty-space skipping, voxels (raycast_bricks.wgsl).
pub const BRICK: u32 = 8;

/// Brick counts per axis for a volume of `dims` (brick b covers positions `[8b, 8b + 8]`).
pub fn brick_dims(dims: [u32; 3]) -> [u32; 3] {
    dims.map(|n| n.saturating_sub(1).div_ceil(BRICK).max(1))
}
const BIG: f32 = 3.0e38;

/// Colours of the feature channels (linear 0..1 RGB): vesselness, airwayness, blobness.
pub const CHANNEL_COLOURS: [[f32; 3]; 3] = [[1.0, 0.0, 0.0], [0.0, 0.4, 1.0], [1.0, 1.0, 0.0]];

/// Intensity projection.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Projection {
    /// Maximum intensity projection.
    #[default]
    Mip,
    /// Minimum intensity projection (airways, lung).
    MinIp,
}

/// One feature channel's display.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ChannelDisplay {
    pub on: bool,
    /// 1 = the feature's largest value in the volume is full colour; 2 = half of it is.
    pub gain: f32,
}

impl Default for ChannelDisplay {
    fn default() -> Self {
        Self {
            on: true,
            gain: 1.0,
        }
    }
}

/// A slab: only samples within `thickness_mm / 2` of `centre_mm` along the view count.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Slab {
    pub centre_mm: DVec3,
    pub thickness_mm: f64,
}

/// Everything about a frame except the camera and the data.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RenderSettings {
    pub projection: Projection,
    /// Grey window `(lo, hi)` in physical units (HU).
    pub window: (f32, f32),
    /// Grey on or off.
    pub show_intensity: bool,
    /// Vesselness (red), airwayness (blue), blobness (yellow).
    pub channels: [ChannelDisplay; 3],
    /// `None`: the whole volume.
    pub slab: Option<Slab>,
    /// Sample spacing along the ray as a fraction of the smallest voxel spacing.
    pub step_fraction: f32,
    /// Trilinear interpolation by the texture unit (one sample) instead of eight `textureLoad`s
    /// in the shader: faster, but the CPU twin matches it only within a tolerance.
    pub hardware_filtering: bool,
}

impl Default for RenderSettings {
    fn default() -> Self {
        Self {
            projection: Projection::Mip,
            window: (-160.0, 240.0),
            show_intensity: true,
            channels: [ChannelDisplay::default(); 3],
            slab: None,
            step_fraction: 0.5,
            hardware_filtering: false,
        }
    }
}

/// What a pixel shows most (the channel whose depth a pick reports).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Channel {
    Intensity,
    Vesselness,
    Airwayness,
    Blobness,
}

impl Channel {
    fn from_code(code: f32) -> Option<Self> {
        match code.round() as i32 {
            0 => Some(Self::Intensity),
            1 => Some(Self::Vesselness),
            2 => Some(Self::Airwayness),
            3 => Some(Self::Blobness),
            _ => None,
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Self::Intensity => "intensity",
            Self::Vesselness => "vesselness",
            Self::Airwayness => "airwayness",
            Self::Blobness => "blobness",
        }
    }
}

/// The geometry of the volume a frame was rendered from.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VolumeGeometry {
    pub dims: [u32; 3],
    pub spacing_mm: [f32; 3],
    pub world_from_voxel: DAffine3,
}

impl VolumeGeometry {
    pub fn of(volume: &RenderVolume) -> Self {
        Self {
            dims: volume.dims,
            spacing_mm: volume.spacing_mm,
            world_from_voxel: volume.world_from_voxel,
        }
    }

    pub fn of_volume(volume: &crate::Volume) -> Self {
        Self {
            dims: volume.dims.map(|d| u32::try_from(d).unwrap_or(u32::MAX)),
            spacing_mm: volume.spacing_mm.map(|s| s as f32),
            world_from_voxel: volume.world_from_voxel(),
        }
    }
}

/// Where a pixel's maximum came from.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pick {
    pub pixel: [u32; 2],
    pub channel: Channel,
    /// Depth along the ray, mm (from the plane through the camera's centre).
    pub depth_mm: f64,
    /// The point, LPS mm.
    pub world_mm: DVec3,
    /// The point in continuous voxel coordinates.
    pub voxel_f: DVec3,
    /// The nearest voxel (clamped into the volume).
    pub voxel: [usize; 3],
}

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

/// Builds the shader's parameters: a pure function of the geometry, the camera and the
/// settings, shared by the GPU and the CPU twin. `feature_max` is each feature's largest value
/// (`None`: no features bound).
pub fn params(
    geometry: &VolumeGeometry,
    camera: &Camera,
    settings: &RenderSettings,
    size: [u32; 2],
    feature_max: Option<[f32; 3]>,
) -> Params {
    let voxel_from_world = geometry.world_from_voxel.inverse();
    let m = voxel_from_world.matrix3;
    let (right, up, forward) = camera.basis();
    let s = camera.mm_per_pixel(size);
    let origin_world = camera.ray(0.5, 0.5, size).origin;
    let f3 = |v: DVec3| [v.x as f32, v.y as f32, v.z as f32];
    let min_spacing = geometry
        .spacing_mm
        .iter()
        .copied()
        .fold(f32::INFINITY, f32::min);
    let fraction = if settings.step_fraction.is_finite() && settings.step_fraction > 0.0 {
        settings.step_fraction.clamp(0.05, 4.0)
    } else {
        0.5
    };
    let step = (fraction * min_spacing).max(1e-4);
    let (slab_lo, slab_hi) = match settings.slab {
        Some(slab) if slab.thickness_mm.is_finite() && slab.thickness_mm > 0.0 => {
            let tc = (slab.centre_mm - camera.centre_mm).dot(forward);
            let h = 0.5 * slab.thickness_mm;
            ((tc - h) as f32, (tc + h) as f32)
        }
        _ => (-BIG, BIG),
    };
    // The summed edges of the box bound any chord through it.
    let chord: f64 = (0..3)
        .map(|a| (geometry.world_from_voxel.matrix3.col(a) * f64::from(geometry.dims[a])).length())
        .sum();
    let max_steps = (chord / f64::from(step)).ceil() as u32 + 2;
    let mut flags = 0;
    let mut feature_scale = [0.0f32; 3];
    if let Some(max) = feature_max {
        for c in 0..3 {
            let ch = settings.channels[c];
            if ch.on && max[c] > 0.0 && ch.gain.is_finite() && ch.gain > 0.0 {
                feature_scale[c] = ch.gain / max[c];
            }
        }
        if feature_scale.iter().any(|&x| x > 0.0) {
            flags |= FLAG_FEATURES;
        }
    }
    if settings.show_intensity {
        flags |= FLAG_INTENSITY;
    }
    if settings.hardware_filtering {
        flags |= FLAG_FILTERED;
    }
    Params {
        origin_v: f3(voxel_from_world.transform_point3(origin_world)),
        step_mm: step,
        du_v: f3(m * (right * s)),
        slab_lo,
        dv_v: f3(m * (-up * s)),
        slab_hi,
        dir_v: f3(m * forward),
        mode: match settings.projection {
            Projection::Mip => 0,
            Projection::MinIp => 1,
        },
        dims: geometry.dims,
        flags,
        feature_scale,
        window_lo: settings.window.0,
        out_size: size,
        window_hi: settings.window.1,
        max_steps,
    }
}

/// What a frame was rendered from: enough to turn a pixel's depth into a point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RenderedView {
    pub camera: Camera,
    pub size: [u32; 2],
    pub geometry: VolumeGeometry,
}

impl RenderedView {
    /// The pick of `pixel` from the shader's `(depth, channel)`; `None` where the ray missed.
    pub fn pick_from(&self, pixel: [u32; 2], depth_channel: [f32; 2]) -> Option<Pick> {
        let channel = Channel::from_code(depth_channel[1])?;
        let depth = f64::from(depth_channel[0]);
        let world = self.camera.pixel_ray(pixel, self.size).at(depth);
        let voxel_f = self
            .geometry
            .world_from_voxel
            .inverse()
            .transform_point3(world);
        let voxel = std::array::from_fn(|a| {
            let top = f64::from(self.geometry.dims[a].max(1) - 1);
            voxel_f[a].round().clamp(0.0, top) as usize
        });
        Some(Pick {
            pixel,
            channel,
            depth_mm: depth,
            world_mm: world,
            voxel_f,
            voxel,
        })
    }
}

/// The image a ray caster draws into (an `Rgba8Unorm` texture egui can show) and the per-pixel
/// depths picks read. Reused across frames while its size stays.
pub struct RaycastTarget {
    pub size: [u32; 2],
    pub texture: wgpu::Texture,
    pub view: wgpu::TextureView,
    pick: wgpu::Buffer,
    params: wgpu::Buffer,
    rendered: Option<RenderedView>,
}

impl RaycastTarget {
    pub fn new(ctx: &GpuContext, size: [u32; 2]) -> Result<Self, RaycastError> {
        let max = ctx.limits.max_texture_dimension_2d;
        if size[0] == 0 || size[1] == 0 || size[0] > max || size[1] > max {
            return Err(RaycastError::Size(size[0], size[1], max));
        }
        let texture = ctx.device.create_texture(&wgpu::TextureDescriptor {
            label: Some("raycast image"),
            size: wgpu::Extent3d {
                width: size[0],
                height: size[1],
                depth_or_array_layers: 1,
            },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: wgpu::TextureFormat::Rgba8Unorm,
            usage: wgpu::TextureUsages::STORAGE_BINDING
                | wgpu::TextureUsages::TEXTURE_BINDING
                | wgpu::TextureUsages::COPY_SRC,
            view_formats: &[],
        });
        let view = texture.create_view(&wgpu::TextureViewDescriptor::default());
        let pick = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("raycast pick"),
            size: u64::from(size[0]) * u64::from(size[1]) * 8,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        let params = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("raycast params"),
            size: std::mem::size_of::<Params>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        Ok(Self {
            size,
            texture,
            view,
            pick,
            params,
            rendered: None,
        })
    }

    /// What the last frame was rendered from (`None` before the first).
    pub fn rendered(&self) -> Option<&RenderedView> {
        self.rendered.as_ref()
    }

    /// Starts reading back the pick of `pixel` of the last frame; `None` before any frame or
    /// outside the image. Poll the result with [`PendingPick::poll`] once per frame (the app),
    /// or await [`Self::pick`] (wasm) / call [`Self::pick_blocking`] (native).
    pub fn start_pick(&self, ctx: &GpuContext, pixel: [u32; 2]) -> Option<PendingPick> {
        let view = self.rendered?;
        if pixel[0] >= self.size[0] || pixel[1] >= self.size[1] {
            return None;
        }
        let offset = (u64::from(pixel[1]) * u64::from(self.size[0]) + u64::from(pixel[0])) * 8;
        let one = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("raycast pick texel"),
            size: 8,
            usage: wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let mut encoder = ctx
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("raycast pick"),
            });
        encoder.copy_buffer_to_buffer(&self.pick, offset, &one, 0, 8);
        ctx.queue.submit([encoder.finish()]);
        let ctx2 = ctx.clone();
        let future = Box::pin(async move { readback::read_bytes(&ctx2, &one, 8).await });
        let mut pending = PendingPick {
            view,
            pixel,
            future: Some(future),
            ctx: ctx.clone(),
        };
        // The first poll records the copy and asks for the mapping.
        pending.poll_once();
        Some(pending)
    }

    /// The pick of `pixel` of the last frame, awaited (works on wasm; natively something must
    /// poll the device, see [`Self::pick_blocking`]).
    pub async fn pick(
        &self,
        ctx: &GpuContext,
        pixel: [u32; 2],
    ) -> Result<Option<Pick>, RaycastError> {
        let Some(mut pending) = self.start_pick(ctx, pixel) else {
            return Ok(None);
        };
        let Some(future) = pending.future.take() else {
            return Ok(None);
        };
        let bytes = future.await?;
        Ok(decode_pick(&pending.view, pending.pixel, &bytes))
    }

    /// Native only: the pick of `pixel` of the last frame, waiting for the GPU.
    #[cfg(not(target_arch = "wasm32"))]
    pub fn pick_blocking(
        &self,
        ctx: &GpuContext,
        pixel: [u32; 2],
    ) -> Result<Option<Pick>, RaycastError> {
        let Some(mut pending) = self.start_pick(ctx, pixel) else {
            return Ok(None);
        };
        loop {
            if let Some(result) = pending.poll() {
                return result;
            }
            ctx.device
                .poll(wgpu::PollType::wait_indefinitely())
                .map_err(ReadbackError::from)?;
        }
    }

    /// Native only: the whole image as tightly packed RGBA8 rows, top row first.
    #[cfg(not(target_arch = "wasm32"))]
    pub fn read_image_blocking(&self, ctx: &GpuContext) -> Result<Vec<u8>, RaycastError> {
        let (buffer, padded) = self.copy_image(ctx);
        let bytes = read_buffer_blocking(ctx, &buffer, buffer.size())?;
        Ok(self.unpad(&bytes, padded))
    }

    /// The image as tightly packed RGBA8 rows, awaited (works on wasm).
    pub async fn read_image(&self, ctx: &GpuContext) -> Result<Vec<u8>, RaycastError> {
        let (buffer, padded) = self.copy_image(ctx);
        let bytes = readback::read_bytes(ctx, &buffer, buffer.size()).await?;
        Ok(self.unpad(&bytes, padded))
    }

    /// Native only: every pixel's `(depth, channel code)` (tests).
    #[cfg(not(target_arch = "wasm32"))]
    pub fn read_depths_blocking(&self, ctx: &GpuContext) -> Result<Vec<[f32; 2]>, RaycastError> {
        let n = self.size[0] as usize * self.size[1] as usize;
        let bytes = read_buffer_blocking(ctx, &self.pick, n as u64 * 8)?;
        let values: Vec<f32> = bytemuck::pod_collect_to_vec(&bytes);
        Ok(values.chunks_exact(2).map(|c| [c[0], c[1]]).collect())
    }

    fn copy_image(&self, ctx: &GpuContext) -> (wgpu::Buffer, u32) {
        let row = self.size[0] * 4;
        let padded =
            row.div_ceil(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT) * wgpu::COPY_BYTES_PER_ROW_ALIGNMENT;
        let buffer = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("raycast image copy"),
            size: u64::from(padded) * u64::from(self.size[1]),
            usage: wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let mut encoder = ctx
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("raycast image copy"),
            });
        encoder.copy_texture_to_buffer(
            wgpu::TexelCopyTextureInfo {
                texture: &self.texture,
                mip_level: 0,
                origin: wgpu::Origin3d::ZERO,
                aspect: wgpu::TextureAspect::All,
            },
            wgpu::TexelCopyBufferInfo {
                buffer: &buffer,
                layout: wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(padded),
                    rows_per_image: Some(self.size[1]),
                },
            },
            wgpu::Extent3d {
                width: self.size[0],
                height: self.size[1],
                depth_or_array_layers: 1,
            },
        );
        ctx.queue.submit([encoder.finish()]);
        (buffer, padded)
    }

    fn unpad(&self, bytes: &[u8], padded: u32) -> Vec<u8> {
        let row = self.size[0] as usize * 4;
        bytes
            .chunks(padded as usize)
            .take(self.size[1] as usize)
            .flat_map(|r| &r[..row.min(r.len())])
            .copied()
            .collect()
    }
}

/// Native only: reads a buffer back, polling the device until the mapping has completed. Unlike
/// a single wait, this is safe when other threads poll the same device at the same time (one of
/// them may still be running this mapping's callback when the wait returns).
#[cfg(not(target_arch = "wasm32"))]
fn read_buffer_blocking(
    ctx: &GpuContext,
    src: &wgpu::Buffer,
    size: u64,
) -> Result<Vec<u8>, RaycastError> {
    let mut future = Box::pin(readback::read_bytes(ctx, src, size));
    let mut cx = std::task::Context::from_waker(std::task::Waker::noop());
    loop {
        if let std::task::Poll::Ready(result) = future.as_mut().poll(&mut cx) {
            return result.map_err(RaycastError::from);
        }
        ctx.device
            .poll(wgpu::PollType::wait_indefinitely())
            .map_err(ReadbackError::from)?;
        std::thread::yield_now();
    }
}

type PickFuture =
    std::pin::Pin<Box<dyn std::future::Future<Output = Result<Vec<u8>, ReadbackError>>>>;

/// A pick being read back; poll it once per frame.
pub struct PendingPick {
    view: RenderedView,
    pixel: [u32; 2],
    future: Option<PickFuture>,
    ctx: GpuContext,
}

impl PendingPick {
    /// The pixel asked about.
    pub fn pixel(&self) -> [u32; 2] {
        self.pixel
    }

    /// `Some` once the readback finished: the pick, or `None` where the ray missed the volume.
    /// Never blocks (natively it lets the device run its callbacks; in the browser they run on
    /// their own).
    pub fn poll(&mut self) -> Option<Result<Option<Pick>, RaycastError>> {
        let _ = self.ctx.device.poll(wgpu::PollType::Poll);
        self.poll_once()
    }

    fn poll_once(&mut self) -> Option<Result<Option<Pick>, RaycastError>> {
        let future = self.future.as_mut()?;
        let mut cx = std::task::Context::from_waker(std::task::Waker::noop());
        match future.as_mut().poll(&mut cx) {
            std::task::Poll::Pending => None,
            std::task::Poll::Ready(result) => {
                self.future = None;
                Some(
                    result
                        .map(|bytes| decode_pick(&self.view, self.pixel, &bytes))
                        .map_err(RaycastError::from),
                )
            }
        }
    }
}

fn decode_pick(view: &RenderedView, pixel: [u32; 2], bytes: &[u8]) -> Option<Pick> {
    let values: [f32; 2] = bytemuck::pod_read_unaligned(bytes.get(..8)?);
    view.pick_from(pixel, values)
}

/// The ray caster's pipeline and the stand-in for "no features".
pub struct Raycaster {
    pipeline: wgpu::ComputePipeline,
    no_features: wgpu::TextureView,
    linear_clamp: wgpu::Sampler,
    bricks_intensity: wgpu::ComputePipeline,
    bricks_features: wgpu::ComputePipeline,
}

/// Brick extrema of one texture (the volume's intensity, or one method's features), for
/// empty-space skipping: made once per texture with [`Raycaster::intensity_bricks`] or
/// [`Raycaster::feature_bricks`], used every frame. Holds a handle of its source, so it is only
/// ever used with that texture.
pub struct Bricks {
    pub dims: [u32; 3],
    pub texture: wgpu::Texture,
    pub view: wgpu::TextureView,
    source: wgpu::Texture,
}

impl Bricks {
    /// Native only: the brick values (tests), brick x fastest.
    #[cfg(not(target_arch = "wasm32"))]
    pub fn read_blocking(&self, ctx: &GpuContext) -> Result<Vec<[f32; 4]>, RaycastError> {
        let [w, h, d] = self.dims;
        let row = w * 8;
        let padded =
            row.div_ceil(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT) * wgpu::COPY_BYTES_PER_ROW_ALIGNMENT;
        let buffer = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("bricks copy"),
            size: u64::from(padded) * u64::from(h) * u64::from(d),
            usage: wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let mut encoder = ctx
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("bricks copy"),
            });
        encoder.copy_texture_to_buffer(
            wgpu::TexelCopyTextureInfo {
                texture: &self.texture,
                mip_level: 0,
                origin: wgpu::Origin3d::ZERO,
                aspect: wgpu::TextureAspect::All,
            },
            wgpu::TexelCopyBufferInfo {
                buffer: &buffer,
                layout: wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(padded),
                    rows_per_image: Some(h),
                },
            },
            wgpu::Extent3d {
                width: w,
                height: h,
                depth_or_array_layers: d,
            },
        );
        ctx.queue.submit([encoder.finish()]);
        let bytes = read_buffer_blocking(ctx, &buffer, buffer.size())?;
        Ok(bytes
            .chunks(padded as usize)
            .flat_map(|r| r[..row as usize].chunks_exact(8).map(decode_texel))
            .collect())
    }

    /// Whether these are the bricks of `texture`.
    pub fn of(&self, texture: &wgpu::Texture) -> bool {
        self.source == *texture
    }
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
        let volume_ok = self.bricks.is_some_and(|b| b.of(&self.volume.intensity));
        let features_ok = match self.features {
            None => true,
            Some(f) => self.feature_bricks.is_some_and(|b| b.of(&f.texture)),
        };
        volume_ok && features_ok
    }
}

impl Raycaster {
    pub fn new(ctx: &GpuContext) -> Result<Self, RaycastError> {
        let module = shaders::create_module(&ctx.device, "raycast.wgsl")?;
        let pipeline = ctx
            .device
            .create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some("raycast"),
                layout: None,
                module: &module,
                entry_point: Some("main"),
                compilation_options: Default::default(),
                cache: None,
            });
        let no_features = ctx
            .device
            .create_texture(&wgpu::TextureDescriptor {
                label: Some("raycast no features"),
                size: wgpu::Extent3d {
                    width: 1,
                    height: 1,
                    depth_or_array_layers: 1,
                },
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D3,
                format: crate::gpu::volume_texture::FEATURE_FORMAT,
                usage: wgpu::TextureUsages::TEXTURE_BINDING,
                view_formats: &[],
            })
            .create_view(&wgpu::TextureViewDescriptor::default());
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
        let make = |entry: &str| {
            ctx.device
                .create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                    label: Some(entry),
                    layout: None,
                    module: &bricks_module,
                    entry_point: Some(entry),
                    compilation_options: Default::default(),
                    cache: None,
                })
        };
        Ok(Self {
            pipeline,
            no_features,
            linear_clamp,
            bricks_intensity: make("bricks_intensity"),
            bricks_features: make("bricks_features"),
        })
    }

    /// The brick extrema of the volume's intensity (one small compute pass).
    pub fn intensity_bricks(&self, ctx: &GpuContext, volume: &RenderVolume) -> Bricks {
        self.bricks(
            ctx,
            &self.bricks_intensity,
            &volume.intensity,
            &volume.intensity_view,
            volume.dims,
        )
    }

    /// The brick extrema of one method's features.
    pub fn feature_bricks(&self, ctx: &GpuContext, features: &FeatureTexture) -> Bricks {
        self.bricks(
            ctx,
            &self.bricks_features,
            &features.texture,
            &features.view,
            features.dims,
        )
    }

    fn bricks(
        &self,
        ctx: &GpuContext,
        pipeline: &wgpu::ComputePipeline,
        source: &wgpu::Texture,
        source_view: &wgpu::TextureView,
        dims: [u32; 3],
    ) -> Bricks {
        let nb = brick_dims(dims);
        let texture = ctx.device.create_texture(&wgpu::TextureDescriptor {
            label: Some("raycast bricks"),
            size: wgpu::Extent3d {
                width: nb[0],
                height: nb[1],
                depth_or_array_layers: nb[2],
            },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D3,
            format: wgpu::TextureFormat::Rgba16Float,
            usage: wgpu::TextureUsages::STORAGE_BINDING
                | wgpu::TextureUsages::TEXTURE_BINDING
                | wgpu::TextureUsages::COPY_SRC,
            view_formats: &[],
        });
        let view = texture.create_view(&wgpu::TextureViewDescriptor::default());
        let bind_group = ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("raycast bricks"),
            layout: &pipeline.get_bind_group_layout(0),
            entries: &[
                entry(0, wgpu::BindingResource::TextureView(source_view)),
                entry(1, wgpu::BindingResource::TextureView(&view)),
            ],
        });
        let mut encoder = ctx
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("raycast bricks"),
            });
        {
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("raycast bricks"),
                timestamp_writes: None,
            });
            pass.set_pipeline(pipeline);
            pass.set_bind_group(0, &bind_group, &[]);
            pass.dispatch_workgroups(nb[0].div_ceil(4), nb[1].div_ceil(4), nb[2].div_ceil(4));
        }
        ctx.queue.submit([encoder.finish()]);
        Bricks {
            dims: nb,
            texture,
            view,
            source: source.clone(),
        }
    }

    /// Renders one frame into `target` (submitted; not waited for). Bricks in the scene turn
    /// on empty-space skipping, which does not change the picture or the picks.
    pub fn render(
        &self,
        ctx: &GpuContext,
        scene: &Scene<'_>,
        camera: &Camera,
        settings: &RenderSettings,
        target: &mut RaycastTarget,
    ) -> Result<(), RaycastError> {
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
            features.map(|f| f.max),
        );
        let skipping = scene.skipping();
        let p = if skipping { p.with_skipping() } else { p };
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
        let bind_group = ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("raycast"),
            layout: &self.pipeline.get_bind_group_layout(0),
            entries: &[
                entry(0, target.params.as_entire_binding()),
                entry(
                    1,
                    wgpu::BindingResource::TextureView(&volume.intensity_view),
                ),
                entry(2, wgpu::BindingResource::TextureView(feature_view)),
                entry(3, wgpu::BindingResource::TextureView(&target.view)),
                entry(4, target.pick.as_entire_binding()),
                entry(5, wgpu::BindingResource::Sampler(&self.linear_clamp)),
                entry(6, wgpu::BindingResource::TextureView(brick_view)),
                entry(7, wgpu::BindingResource::TextureView(feature_brick_view)),
            ],
        });
        let mut encoder = ctx
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("raycast"),
            });
        {
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("raycast"),
                timestamp_writes: None,
            });
            pass.set_pipeline(&self.pipeline);
            pass.set_bind_group(0, &bind_group, &[]);
            pass.dispatch_workgroups(target.size[0].div_ceil(8), target.size[1].div_ceil(8), 1);
        }
        ctx.queue.submit([encoder.finish()]);
        target.rendered = Some(RenderedView {
            camera: *camera,
            size: target.size,
            geometry,
        });
        Ok(())
    }
}

fn entry(binding: u32, resource: wgpu::BindingResource<'_>) -> wgpu::BindGroupEntry<'_> {
    wgpu::BindGroupEntry { binding, resource }
}

/// Copies the feature texel of `voxel` into a small buffer (8 bytes: four half floats).
fn copy_feature_texel(
    ctx: &GpuContext,
    features: &FeatureTexture,
    voxel: [usize; 3],
) -> Option<wgpu::Buffer> {
    let v: [u32; 3] = std::array::from_fn(|a| u32::try_from(voxel[a]).unwrap_or(u32::MAX));
    if (0..3).any(|a| v[a] >= features.dims[a]) {
        return None;
    }
    let buffer = ctx.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("feature texel"),
        size: 8,
        usage: wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    let mut encoder = ctx
        .device
        .create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("feature texel"),
        });
    encoder.copy_texture_to_buffer(
        wgpu::TexelCopyTextureInfo {
            texture: &features.texture,
            mip_level: 0,
            origin: wgpu::Origin3d {
                x: v[0],
                y: v[1],
                z: v[2],
            },
            aspect: wgpu::TextureAspect::All,
        },
        wgpu::TexelCopyBufferInfo {
            buffer: &buffer,
            layout: wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: None,
                rows_per_image: None,
            },
        },
        wgpu::Extent3d {
            width: 1,
            height: 1,
            depth_or_array_layers: 1,
        },
    );
    ctx.queue.submit([encoder.finish()]);
    Some(buffer)
}

fn decode_texel(bytes: &[u8]) -> [f32; 4] {
    std::array::from_fn(|c| {
        let b = [
            bytes.get(2 * c).copied().unwrap_or(0),
            bytes.get(2 * c + 1).copied().unwrap_or(0),
        ];
        half::f16::from_le_bytes(b).to_f32()
    })
}

/// The feature values `(V, A, B, 0)` the GPU holds at `voxel` (for the status bar and
/// `--pick`); zeros outside the volume. Awaited (works on wasm).
pub async fn read_feature_texel(
    ctx: &GpuContext,
    features: &FeatureTexture,
    voxel: [usize; 3],
) -> Result<[f32; 4], RaycastError> {
    let Some(buffer) = copy_feature_texel(ctx, features, voxel) else {
        return Ok([0.0; 4]);
    };
    Ok(decode_texel(&readback::read_bytes(ctx, &buffer, 8).await?))
}

/// Native only: [`read_feature_texel`], waiting for the GPU.
#[cfg(not(target_arch = "wasm32"))]
pub fn read_feature_texel_blocking(
    ctx: &GpuContext,
    features: &FeatureTexture,
    voxel: [usize; 3],
) -> Result<[f32; 4], RaycastError> {
    let Some(buffer) = copy_feature_texel(ctx, features, voxel) else {
        return Ok([0.0; 4]);
    };
    Ok(decode_texel(&read_buffer_blocking(ctx, &buffer, 8)?))
}

/// The data of the CPU twin: exactly the values the GPU textures hold (half floats, features
/// clamped to the half range as [`FeatureTexture::from_components`] does), as f32.
pub struct TwinScene {
    pub dims: [u32; 3],
    pub intensity: Vec<f32>,
    pub features: Option<Vec<[f32; 4]>>,
    pub feature_max: Option<[f32; 3]>,
    /// Brick extrema ([`cpu_bricks`]): intensity `(max, min)`, features `(max V, A, B)`; the
    /// twin skips bricks as the shader does when the params ask for it.
    pub bricks: Option<Vec<[f32; 4]>>,
    pub feature_bricks: Option<Vec<[f32; 4]>>,
}

impl TwinScene {
    /// The scene [`RenderVolume::upload`] and [`FeatureTexture::from_components`] would make.
    pub fn new(volume: &crate::Volume, components: Option<&crate::cpu::Components3>) -> Self {
        let half = |v: f32| half::f16::from_f32(v).to_f32();
        let intensity: Vec<f32> = volume.to_f32().into_iter().map(half).collect();
        let features: Option<Vec<[f32; 4]>> = components.map(|c| {
            (0..volume.voxel_count())
                .map(|n| {
                    [
                        half(c[0][n].clamp(-65504.0, 65504.0)),
                        half(c[1][n].clamp(-65504.0, 65504.0)),
                        half(c[2][n].clamp(-65504.0, 65504.0)),
                        0.0,
                    ]
                })
                .collect()
        });
        let feature_max =
            components.map(|c| std::array::from_fn(|k| c[k].iter().copied().fold(0.0, f32::max)));
        let dims = volume.dims.map(|d| u32::try_from(d).unwrap_or(u32::MAX));
        let bricks = cpu_bricks(dims, &intensity, |v: &f32| [*v, *v, *v]);
        let feature_bricks = features
            .as_ref()
            .map(|f| cpu_bricks(dims, f, |v: &[f32; 4]| [v[0], v[1], v[2]]));
        Self {
            dims,
            intensity,
            features,
            feature_max,
            bricks: Some(bricks.into_iter().map(|b| [b[0], b[1], 0.0, 0.0]).collect()),
            feature_bricks: feature_bricks
                .map(|fb| fb.into_iter().map(|b| [b[0], b[2], b[3], 0.0]).collect()),
        }
    }
}

/// The CPU twin of raycast_bricks.wgsl. For each brick: `[max c0, min c0, max c1, max c2]` of
/// the three values `get` gives per voxel (intensity: all three the same).
pub fn cpu_bricks<T>(dims: [u32; 3], values: &[T], get: impl Fn(&T) -> [f32; 3]) -> Vec<[f32; 4]> {
    let nb = brick_dims(dims);
    let d = dims.map(|x| x as usize);
    let mut out = Vec::with_capacity(nb.iter().map(|&x| x as usize).product());
    for bz in 0..nb[2] {
        for by in 0..nb[1] {
            for bx in 0..nb[0] {
                let b = [bx, by, bz];
                let lo: [usize; 3] = std::array::from_fn(|a| (b[a] * BRICK) as usize);
                let hi: [usize; 3] =
                    std::array::from_fn(|a| (lo[a] + BRICK as usize).min(d[a].saturating_sub(1)));
                let mut e = [-BIG, BIG, -BIG, -BIG];
                for k in lo[2]..=hi[2] {
                    for j in lo[1]..=hi[1] {
                        for i in lo[0]..=hi[0] {
                            let v = get(&values[i + d[0] * (j + d[1] * k)]);
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

/// The CPU twin's frame: RGBA8 rows (top first) and `(depth, channel code)` per pixel.
pub struct TwinImage {
    pub rgba: Vec<u8>,
    pub depths: Vec<[f32; 2]>,
    /// Intensity and feature samples evaluated (what skipping saves).
    pub samples: u64,
    pub feature_samples: u64,
}

/// The CPU twin of raycast.wgsl: the same f32 arithmetic, sample by sample.
pub fn cpu_twin(scene: &TwinScene, p: &Params) -> TwinImage {
    let [w, h] = p.out_size;
    let n = w as usize * h as usize;
    let mut rgba = vec![0u8; n * 4];
    let mut depths = vec![[0.0f32, -1.0]; n];
    let mut samples = 0u64;
    let mut feature_samples = 0u64;
    let dims = p.dims;
    let top = [
        dims[0] as f32 - 1.0,
        dims[1] as f32 - 1.0,
        dims[2] as f32 - 1.0,
    ];
    let index = |i: [i32; 3]| {
        i[0] as usize + dims[0] as usize * (i[1] as usize + dims[1] as usize * i[2] as usize)
    };
    let lerp = |a: f32, b: f32, t: f32| a + (b - a) * t;
    for y in 0..h {
        for x in 0..w {
            let pixel = (x + w * y) as usize;
            let o: [f32; 3] = std::array::from_fn(|a| {
                p.origin_v[a] + p.du_v[a] * x as f32 + p.dv_v[a] * y as f32
            });
            let d = p.dir_v;
            let mut t0 = -BIG;
            let mut t1 = BIG;
            let mut empty = false;
            for a in 0..3 {
                let lo = -0.5f32;
                let hi = dims[a] as f32 - 0.5;
                if d[a].abs() < 1e-20 {
                    if o[a] < lo || o[a] > hi {
                        empty = true;
                    }
                } else {
                    let ta = (lo - o[a]) / d[a];
                    let tb = (hi - o[a]) / d[a];
                    t0 = t0.max(ta.min(tb));
                    t1 = t1.min(ta.max(tb));
                }
            }
            if empty {
                t0 = 1.0;
                t1 = 0.0;
            }
            let t0 = t0.max(p.slab_lo);
            let t1 = t1.min(p.slab_hi);
            let k0 = (t0 / p.step_mm).ceil() as i32;
            let k1 = (t1 / p.step_mm).floor() as i32;
            let count = (k1.saturating_sub(k0).saturating_add(1)).min(p.max_steps as i32);
            let out = &mut rgba[pixel * 4..pixel * 4 + 4];
            if t0 > t1 || count <= 0 {
                out.copy_from_slice(&[0, 0, 0, 255]);
                continue;
            }
            let minip = p.mode == 1;
            let use_features = p.flags & FLAG_FEATURES != 0 && scene.features.is_some();
            let mut best_i = if minip { BIG } else { -BIG };
            let mut t_i = 0.0f32;
            let mut best_f = [-BIG; 3];
            let mut t_f = [0.0f32; 3];
            let skip = p.flags & FLAG_BRICKS != 0 && scene.bricks.is_some();
            let nb = brick_dims(dims).map(|x| x as i32);
            let mut last_brick = [-1i32; 3];
            let (mut skip_i, mut skip_f) = (false, false);
            let mut s = 0i32;
            while s < count {
                let t = (k0 + s) as f32 * p.step_mm;
                let q: [f32; 3] = std::array::from_fn(|a| o[a] + d[a] * t);
                let qc: [f32; 3] = std::array::from_fn(|a| q[a].clamp(0.0, top[a]));
                let base: [f32; 3] = std::array::from_fn(|a| qc[a].floor());
                let i0: [i32; 3] = std::array::from_fn(|a| base[a] as i32);
                let i1: [i32; 3] = std::array::from_fn(|a| (i0[a] + 1).min(dims[a] as i32 - 1));
                let f: [f32; 3] = std::array::from_fn(|a| qc[a] - base[a]);
                if skip && let Some(bricks) = &scene.bricks {
                    let b: [i32; 3] =
                        std::array::from_fn(|a| (i0[a] / BRICK as i32).min(nb[a] - 1));
                    if b != last_brick {
                        last_brick = b;
                        let bidx = (b[0] + nb[0] * (b[1] + nb[1] * b[2])) as usize;
                        let bi = bricks[bidx];
                        skip_i = if minip {
                            bi[1] >= best_i
                        } else {
                            bi[0] <= best_i
                        };
                        skip_f = !use_features
                            || scene.feature_bricks.as_ref().is_some_and(|fb| {
                                (0..3)
                                    .all(|c| !(p.feature_scale[c] > 0.0 && fb[bidx][c] > best_f[c]))
                            });
                        let ok = skip_i && skip_f;
                        if ok {
                            let mut te = BIG;
                            for a in 0..3 {
                                if d[a] > 1e-20 && b[a] < nb[a] - 1 {
                                    te = te.min((((b[a] + 1) * BRICK as i32) as f32 - o[a]) / d[a]);
                                } else if d[a] < -1e-20 && b[a] > 0 {
                                    te = te.min(((b[a] * BRICK as i32) as f32 - o[a]) / d[a]);
                                }
                            }
                            let te = te.min(t1) - 0.01 * p.step_mm;
                            let next = (te / p.step_mm).floor() as i32 - k0;
                            if next > s {
                                s = next;
                                continue;
                            }
                        }
                    }
                }
                let corner = |cx: bool, cy: bool, cz: bool| {
                    index([
                        if cx { i1[0] } else { i0[0] },
                        if cy { i1[1] } else { i0[1] },
                        if cz { i1[2] } else { i0[2] },
                    ])
                };
                let tri = |get: &dyn Fn(usize) -> f32| {
                    let v00 = lerp(
                        get(corner(false, false, false)),
                        get(corner(true, false, false)),
                        f[0],
                    );
                    let v10 = lerp(
                        get(corner(false, true, false)),
                        get(corner(true, true, false)),
                        f[0],
                    );
                    let v01 = lerp(
                        get(corner(false, false, true)),
                        get(corner(true, false, true)),
                        f[0],
                    );
                    let v11 = lerp(
                        get(corner(false, true, true)),
                        get(corner(true, true, true)),
                        f[0],
                    );
                    lerp(lerp(v00, v10, f[1]), lerp(v01, v11, f[1]), f[2])
                };
                if !skip_i {
                    samples += 1;
                    let v = tri(&|idx| scene.intensity[idx]);
                    if minip {
                        if v < best_i {
                            best_i = v;
                            t_i = t;
                        }
                    } else if v > best_i {
                        best_i = v;
                        t_i = t;
                    }
                }
                if use_features
                    && !skip_f
                    && let Some(feats) = &scene.features
                {
                    feature_samples += 1;
                    for c in 0..3 {
                        let fv = tri(&|idx| feats[idx][c]);
                        if fv > best_f[c] {
                            best_f[c] = fv;
                            t_f[c] = t;
                        }
                    }
                }
                s += 1;
            }
            let show = p.flags & FLAG_INTENSITY != 0;
            let g = if show {
                ((best_i - p.window_lo) / (p.window_hi - p.window_lo).max(1e-6)).clamp(0.0, 1.0)
            } else {
                0.0
            };
            let a: [f32; 3] = if use_features {
                std::array::from_fn(|c| (best_f[c] * p.feature_scale[c]).clamp(0.0, 1.0))
            } else {
                [0.0; 3]
            };
            let mut rgb = [g; 3];
            for (c, colour) in CHANNEL_COLOURS.iter().enumerate() {
                for k in 0..3 {
                    rgb[k] += (colour[k] - rgb[k]) * a[c];
                }
            }
            for k in 0..3 {
                out[k] = (rgb[k].clamp(0.0, 1.0) * 255.0).round() as u8;
            }
            out[3] = 255;
            let vis = if !show {
                0.0
            } else if minip {
                1.0 - g
            } else {
                g
            };
            let w = [
                vis * (1.0 - a[0]) * (1.0 - a[1]) * (1.0 - a[2]),
                a[0] * (1.0 - a[1]) * (1.0 - a[2]),
                a[1] * (1.0 - a[2]),
                a[2],
            ];
            let mut best_w = w[0];
            let mut pick = [t_i, 0.0];
            for c in 1..4 {
                if w[c] > best_w {
                    best_w = w[c];
                    pick = [t_f[c - 1], c as f32];
                }
            }
            depths[pixel] = pick;
        }
    }
    TwinImage {
        rgba,
        depths,
        samples,
        feature_samples,
    }
}

/// The continuous pixel under a point of the widget/image (helper for callers mapping UI
/// positions): `uv` in 0..1 across the image.
pub fn pixel_of_uv(uv: DVec2, size: [u32; 2]) -> Option<[u32; 2]> {
    let x = uv.x * f64::from(size[0]);
    let y = uv.y * f64::from(size[1]);
    let inside = x >= 0.0 && y >= 0.0 && x < f64::from(size[0]) && y < f64::from(size[1]);
    inside.then_some([x as u32, y as u32])
}
