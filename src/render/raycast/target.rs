//! The render target and what is read back from it: the image, the per-pixel depths and the
//! picks they give (a pixel's depth turned back into a world point and a voxel), and the
//! feature texel at a picked voxel.

use glam::{DVec2, DVec3};

use crate::gpu::GpuContext;
use crate::gpu::readback::{self, ReadbackError};
use crate::gpu::volume_texture::FeatureTexture;
use crate::render::camera::Camera;

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
        let [w, h] = self.size;
        Ok(readback::read_texture_blocking(
            ctx,
            &self.texture,
            [w, h, 1],
            4,
        )?)
    }

    /// Native only: every pixel's `(depth, channel code)` (tests).
    #[cfg(not(target_arch = "wasm32"))]
    pub fn read_depths_blocking(&self, ctx: &GpuContext) -> Result<Vec<[f32; 2]>, RaycastError> {
        let n = self.size[0] as usize * self.size[1] as usize;
        let bytes = read_buffer_blocking(ctx, &self.pick, n as u64 * 8)?;
        let values: Vec<f32> = bytemuck::pod_collect_to_vec(&bytes);
        Ok(values.chunks_exact(2).map(|c| [c[0], c[1]]).collect())
    }
}

/// Native only: reads a buffer back, blocking (the one readback, `gpu::readback`).
#[cfg(not(target_arch = "wasm32"))]
pub(super) fn read_buffer_blocking(
    ctx: &GpuContext,
    src: &wgpu::Buffer,
    size: u64,
) -> Result<Vec<u8>, RaycastError> {
    Ok(readback::read_bytes_blocking(ctx, src, size)?)
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

pub(super) fn decode_texel(bytes: &[u8]) -> [f32; 4] {
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

/// The continuous pixel under a point of the widget/image (helper for callers mapping UI
/// positions): `uv` in 0..1 across the image.
pub fn pixel_of_uv(uv: DVec2, size: [u32; 2]) -> Option<[u32; 2]> {
    let x = uv.x * f64::from(size[0]);
    let y = uv.y * f64::from(size[1]);
    let inside = x >= 0.0 && y >= 0.0 && x < f64::from(size[0]) && y < f64::from(size[1]);
    inside.then_some([x as u32, y as u32])
}
