//! The render target and what is read back from it: the image, the per-pixel depths and the
//! picks they give (a pixel's depth turned back into a world point and a voxel), and the
//! feature texel at a picked voxel.

use glam::{DVec2, DVec3};

use crate::gpu::GpuContext;
use crate::gpu::readback::{PendingRead, PendingTexture, ReadbackError};
use crate::gpu::volume_texture::FeatureTexture;
use crate::render::camera::Camera;
use crate::render::output_texture;
use crate::render::probe::TexelProbe;

use super::RaycastError;
use super::settings::{Params, VolumeGeometry};

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
    pub(super) pick: wgpu::Buffer,
    pub(super) params: wgpu::Buffer,
    pub(super) rendered: Option<RenderedView>,
}

impl RaycastTarget {
    pub fn new(ctx: &GpuContext, size: [u32; 2]) -> Result<Self, RaycastError> {
        let max = ctx.limits.max_texture_dimension_2d;
        if size[0] == 0 || size[1] == 0 || size[0] > max || size[1] > max {
            return Err(RaycastError::Size(size[0], size[1], max));
        }
        let (texture, view) = output_texture(
            ctx,
            "raycast image",
            wgpu::TextureDimension::D2,
            [size[0], size[1], 1],
            wgpu::TextureFormat::Rgba8Unorm,
        );
        let pick = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("raycast pick"),
            size: u64::from(size[0]) * u64::from(size[1]) * 8,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        let params = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("raycast params"),
            size: std::mem::size_of::<Params>() as u64,
            // Storage, not uniform: see `kernel::params_buffer`.
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
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
        let read = PendingRead::start_with(ctx, 8, "raycast pick", |encoder, staging| {
            encoder.copy_buffer_to_buffer(&self.pick, offset, staging, 0, 8);
        });
        Some(PendingPick {
            view,
            pixel,
            read: Some(read),
            ctx: ctx.clone(),
        })
    }

    /// The pick of `pixel` of the last frame, awaited (works on wasm; natively something must
    /// poll the device, see [`Self::pick_blocking`]).
    pub async fn pick(
        &self,
        ctx: &GpuContext,
        pixel: [u32; 2],
    ) -> Result<Option<Pick>, RaycastError> {
        match self.start_pick(ctx, pixel) {
            Some(pending) => pending.finish().await,
            None => Ok(None),
        }
    }

    /// Native only: the pick of `pixel` of the last frame, waiting for the GPU.
    #[cfg(not(target_arch = "wasm32"))]
    pub fn pick_blocking(
        &self,
        ctx: &GpuContext,
        pixel: [u32; 2],
    ) -> Result<Option<Pick>, RaycastError> {
        self.start_pick(ctx, pixel)
            .map_or(Ok(None), |pending| pending.wait())
    }

    /// Starts reading the whole image back (the last frame, or the rows drawn so far): poll it
    /// once per frame; it gives tightly packed RGBA8 rows, top row first. Frames rendered into
    /// this target after this call do not change what it reads (the copy is queued first).
    pub fn start_image_read(&self, ctx: &GpuContext) -> PendingTexture {
        let [w, h] = self.size;
        PendingTexture::start(ctx, &self.texture, [w, h, 1], 4)
    }

    /// Native only: the whole image as tightly packed RGBA8 rows, top row first.
    #[cfg(not(target_arch = "wasm32"))]
    pub fn read_image_blocking(&self, ctx: &GpuContext) -> Result<Vec<u8>, RaycastError> {
        Ok(self.start_image_read(ctx).wait(ctx)?)
    }

    /// Native only: every pixel's `(depth, channel code)` (tests).
    #[cfg(not(target_arch = "wasm32"))]
    pub fn read_depths_blocking(&self, ctx: &GpuContext) -> Result<Vec<[f32; 2]>, RaycastError> {
        let n = self.size[0] as usize * self.size[1] as usize;
        let bytes = crate::gpu::readback::read_bytes_blocking(ctx, &self.pick, n as u64 * 8)?;
        let values: Vec<f32> = bytemuck::pod_collect_to_vec(&bytes);
        Ok(values.chunks_exact(2).map(|c| [c[0], c[1]]).collect())
    }
}

/// A pick being read back; poll it once per frame.
pub struct PendingPick {
    view: RenderedView,
    pixel: [u32; 2],
    /// `None` once read.
    read: Option<PendingRead>,
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
        let result = self.read.as_mut()?.poll(&self.ctx)?;
        self.read = None;
        Some(self.decode(result))
    }

    /// The pick, awaited (works on wasm; natively something must poll the device).
    async fn finish(mut self) -> Result<Option<Pick>, RaycastError> {
        match self.read.take() {
            Some(read) => self.decode(read.finish().await),
            None => Ok(None),
        }
    }

    /// Native only: the pick, waiting for the GPU.
    #[cfg(not(target_arch = "wasm32"))]
    fn wait(mut self) -> Result<Option<Pick>, RaycastError> {
        match self.read.take() {
            Some(read) => self.decode(read.wait(&self.ctx)),
            None => Ok(None),
        }
    }

    fn decode(&self, bytes: Result<Vec<u8>, ReadbackError>) -> Result<Option<Pick>, RaycastError> {
        let bytes = bytes?;
        let Some(depth_channel) = bytes.get(..8) else {
            return Ok(None);
        };
        let values: [f32; 2] = bytemuck::pod_read_unaligned(depth_channel);
        Ok(self.view.pick_from(self.pixel, values))
    }
}

/// Starts reading the texel of `voxel`; `None` outside the texture.
fn probe_voxel(
    ctx: &GpuContext,
    features: &FeatureTexture,
    voxel: [usize; 3],
) -> Option<TexelProbe> {
    let v: [u32; 3] = std::array::from_fn(|a| u32::try_from(voxel[a]).unwrap_or(u32::MAX));
    let inside = (0..3).all(|a| v[a] < features.dims[a]);
    inside.then(|| TexelProbe::start(ctx, features, &[v]))
}

/// The one texel a probe of one voxel read.
fn first_texel(texels: Result<Vec<[f32; 4]>, ReadbackError>) -> Result<[f32; 4], RaycastError> {
    Ok(texels?.first().copied().unwrap_or_default())
}

/// The feature values `(V, A, B, 0)` the GPU holds at `voxel` (for the status bar and
/// `--pick`); zeros outside the volume. Awaited (works on wasm).
pub async fn read_feature_texel(
    ctx: &GpuContext,
    features: &FeatureTexture,
    voxel: [usize; 3],
) -> Result<[f32; 4], RaycastError> {
    match probe_voxel(ctx, features, voxel) {
        Some(probe) => first_texel(probe.finish().await),
        None => Ok([0.0; 4]),
    }
}

/// Native only: [`read_feature_texel`], waiting for the GPU.
#[cfg(not(target_arch = "wasm32"))]
pub fn read_feature_texel_blocking(
    ctx: &GpuContext,
    features: &FeatureTexture,
    voxel: [usize; 3],
) -> Result<[f32; 4], RaycastError> {
    probe_voxel(ctx, features, voxel).map_or(Ok([0.0; 4]), |probe| first_texel(probe.wait(ctx)))
}

/// The continuous pixel under a point of the widget/image (helper for callers mapping UI
/// positions): `uv` in 0..1 across the image.
pub fn pixel_of_uv(uv: DVec2, size: [u32; 2]) -> Option<[u32; 2]> {
    let x = uv.x * f64::from(size[0]);
    let y = uv.y * f64::from(size[1]);
    let inside = x >= 0.0 && y >= 0.0 && x < f64::from(size[0]) && y < f64::from(size[1]);
    inside.then_some([x as u32, y as u32])
}
