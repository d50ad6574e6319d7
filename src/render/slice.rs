//! Slices for the slice panes, rendered on the GPU (shaders/slice.wgsl) from the textures the MIP
//! reads: the intensity (`RenderVolume`, windowed to grey) and optionally one method's features
//! (`FeatureTexture`), composited as the MIP does: over the grey, in this order, red =
//! vesselness, blue = airwayness, yellow = blobness, each with opacity
//! `clamp(value * scale, 0, 1) * opacity` (scale = gain / the feature's maximum, as in the MIP).
//! The result is an `Rgba8Unorm` texture the app registers with egui. Its CPU twin is
//! [`cpu_twin`].
//!
//! Image layout: pixel (x, y) is the voxel whose `across` index is x and `vertical` index is y on
//! slice `index` of the `fixed` axis (no flips; the pane flips for patient orientation).

use crate::cpu::Components3;
use crate::gpu::kernel::{bind_group, params_buffer};
use crate::gpu::volume_texture::{FeatureTexture, RenderVolume};
use crate::gpu::{GpuContext, checks, shaders};
use crate::render::{no_features_view, output_texture, submit_dispatch};

/// Colours of vesselness, airwayness and blobness: the MIP's (`render::raycast::CHANNEL_COLOURS`;
/// shaders/slice.wgsl and raycast.wgsl repeat them as WGSL constants).
pub const FEATURE_RGB: [[f32; 3]; 3] = crate::render::raycast::CHANNEL_COLOURS;

/// Mirrors `Params` in slice.wgsl (keep in sync).
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
struct Params {
    dims: [u32; 3],
    fixed_axis: u32,
    across_axis: u32,
    vertical_axis: u32,
    index: u32,
    overlay: u32,
    out_size: [u32; 2],
    window_lo: f32,
    window_hi: f32,
    scale: [f32; 4],
    feature_level: u32,
    _pad: [u32; 3],
}
const _: () = assert!(std::mem::size_of::<Params>() == 80);

/// Which plane of the volume: the voxel axis held fixed at `index`, and the voxel axes that run
/// across (image x) and vertically (image y).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct SlicePlane {
    pub fixed: usize,
    pub across: usize,
    pub vertical: usize,
    pub index: u32,
}

impl SlicePlane {
    /// Image width and height for a volume of `dims`.
    pub fn size(&self, dims: [u32; 3]) -> [u32; 2] {
        [dims[self.across.min(2)], dims[self.vertical.min(2)]]
    }

    fn valid(&self) -> bool {
        let mut axes = [self.fixed, self.across, self.vertical];
        axes.sort_unstable();
        axes == [0, 1, 2]
    }
}

/// How the features are composited over the grey.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Overlay {
    /// Per feature (V, A, B): opacity = clamp(value * scale, 0, 1) * `opacity`; 0 switches it
    /// off.
    pub scale: [f32; 3],
    /// Opacity of a feature at full weight, 0..1.
    pub opacity: f32,
}

/// Everything one slice image depends on, apart from the textures.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SliceRequest {
    pub plane: SlicePlane,
    /// Display window (lo, hi) in physical units.
    pub window: (f32, f32),
    pub overlay: Option<Overlay>,
}

/// A rendered slice on the GPU.
pub struct SliceImage {
    pub texture: wgpu::Texture,
    pub view: wgpu::TextureView,
    pub size: [u32; 2],
}

/// Why a slice could not be rendered.
#[derive(Debug, thiserror::Error, Clone, PartialEq)]
#[non_exhaustive]
pub enum SliceError {
    #[error("slice axes {0:?} are not a permutation of 0, 1, 2")]
    Axes([usize; 3]),
    #[error("slice {index} is outside the volume ({count} slices along axis {axis})")]
    Index { index: u32, count: u32, axis: usize },
    #[error("the feature texture ({0:?}) is not on the volume's grid ({1:?})")]
    FeatureDims([u32; 3], [u32; 3]),
}

/// The slice kernel's pipeline and a 1-voxel stand-in for "no features".
pub struct SliceRenderer {
    pipeline: wgpu::ComputePipeline,
    no_features: wgpu::TextureView,
}

impl SliceRenderer {
    pub fn new(ctx: &GpuContext) -> Result<Self, shaders::ShaderSourceError> {
        let module = shaders::create_module(&ctx.device, "slice.wgsl")?;
        Ok(Self {
            pipeline: checks::labelled_pipeline(ctx, "slice", &module, "main"),
            no_features: no_features_view(ctx, "slice: no features"),
        })
    }

    /// Renders one slice. `reuse` is written into when it has the right size (the egui
    /// registration of its view stays valid); otherwise a new image is made.
    pub fn render(
        &self,
        ctx: &GpuContext,
        volume: &RenderVolume,
        features: Option<&FeatureTexture>,
        request: &SliceRequest,
        reuse: Option<SliceImage>,
    ) -> Result<SliceImage, SliceError> {
        let plane = request.plane;
        if !plane.valid() {
            return Err(SliceError::Axes([
                plane.fixed,
                plane.across,
                plane.vertical,
            ]));
        }
        let count = volume.dims[plane.fixed];
        if plane.index >= count {
            return Err(SliceError::Index {
                index: plane.index,
                count,
                axis: plane.fixed,
            });
        }
        if let Some(f) = features
            && f.dims != volume.dims
        {
            return Err(SliceError::FeatureDims(f.dims, volume.dims));
        }
        let size = plane.size(volume.dims);
        let image = match reuse {
            Some(image) if image.size == size => image,
            _ => new_image(ctx, size),
        };
        let overlay = request.overlay.filter(|_| features.is_some());
        let scale = overlay.map_or([0.0; 4], |o| {
            [
                o.scale[0],
                o.scale[1],
                o.scale[2],
                o.opacity.clamp(0.0, 1.0),
            ]
        });
        let params = Params {
            dims: volume.dims,
            fixed_axis: plane.fixed as u32,
            across_axis: plane.across as u32,
            vertical_axis: plane.vertical as u32,
            index: plane.index,
            overlay: u32::from(overlay.is_some()),
            out_size: size,
            // The texture holds values times the volume's scale; the window follows them.
            window_lo: request.window.0 * volume.value_scale,
            window_hi: request.window.1 * volume.value_scale,
            scale,
            feature_level: features.map_or(0, |f| f.level),
            _pad: [0; 3],
        };
        let params_buf = params_buffer(&ctx.device, "slice params", &params);
        let feature_view = features.map_or(&self.no_features, |f| &f.view);
        let bind_group = bind_group(
            &ctx.device,
            "slice",
            &self.pipeline,
            [
                params_buf.as_entire_binding(),
                wgpu::BindingResource::TextureView(&volume.intensity_view),
                wgpu::BindingResource::TextureView(feature_view),
                wgpu::BindingResource::TextureView(&image.view),
            ],
        );
        let groups = [size[0].div_ceil(8), size[1].div_ceil(8), 1];
        submit_dispatch(ctx, "slice", &self.pipeline, &bind_group, groups);
        Ok(image)
    }
}

fn new_image(ctx: &GpuContext, size: [u32; 2]) -> SliceImage {
    let (texture, view) = output_texture(
        ctx,
        "slice image",
        wgpu::TextureDimension::D2,
        [size[0].max(1), size[1].max(1), 1],
        wgpu::TextureFormat::Rgba8Unorm,
    );
    SliceImage {
        texture,
        view,
        size,
    }
}

/// The value a half-float texture holds for `v` (what the GPU reads).
fn as_f16(v: f32) -> f32 {
    half::f16::from_f32(v).to_f32()
}

/// The CPU twin of the kernel: the same image from physical `values` and feature `components`
/// on `dims` (rounded as the GPU textures hold them: half floats, shared-exponent feature
/// texels), row-major, RGBA8.
pub fn cpu_twin(
    values: &[f32],
    dims: [usize; 3],
    features: Option<&Components3>,
    request: &SliceRequest,
) -> Vec<[u8; 4]> {
    cpu_twin_level(values, dims, features, 0, request)
}

/// [`cpu_twin`] with the features at max-pooled level `level` (each voxel shows its block's
/// texel, as the kernel reads a pooled texture).
pub fn cpu_twin_level(
    values: &[f32],
    dims: [usize; 3],
    features: Option<&Components3>,
    level: u32,
    request: &SliceRequest,
) -> Vec<[u8; 4]> {
    let dims_u32 = dims.map(|d| u32::try_from(d).unwrap_or(u32::MAX));
    let pooled = features
        .filter(|_| level > 0)
        .map(|f| crate::gpu::volume_texture::pool_texels(f, dims_u32, level));
    let pooled_dims = crate::gpu::volume_texture::level_dims(dims_u32, level).map(|d| d as usize);
    let plane = request.plane;
    let (w, h) = (dims[plane.across], dims[plane.vertical]);
    // The texture's scale, from the values' range as `RenderVolume::create` takes it.
    let range = values
        .iter()
        .filter(|v| v.is_finite())
        .fold(None, |r: Option<(f32, f32)>, &v| {
            Some(r.map_or((v, v), |(lo, hi)| (lo.min(v), hi.max(v))))
        });
    let scale = crate::gpu::volume_texture::texture_value_scale(range.unwrap_or((0.0, 1.0)));
    let (lo, hi) = (request.window.0 * scale, request.window.1 * scale);
    let mut out = Vec::with_capacity(w * h);
    for y in 0..h {
        for x in 0..w {
            let mut p = [0usize; 3];
            p[plane.fixed] = plane.index as usize;
            p[plane.across] = x;
            p[plane.vertical] = y;
            let n = p[0] + dims[0] * (p[1] + dims[1] * p[2]);
            let v = as_f16(values[n] * scale);
            let g = ((v - lo) / (hi - lo).max(1e-6)).clamp(0.0, 1.0);
            let mut rgb = [g; 3];
            if let (Some(o), Some(f)) = (request.overlay, features) {
                let texel = match &pooled {
                    Some(t) => {
                        let b = p.map(|v| v >> level);
                        let m = b[0] + pooled_dims[0] * (b[1] + pooled_dims[1] * b[2]);
                        crate::gpu::volume_texture::decode_rgb9e5(t[m])
                    }
                    None => crate::gpu::volume_texture::feature_texel([f[0][n], f[1][n], f[2][n]]),
                };
                for (c, colour) in FEATURE_RGB.iter().enumerate() {
                    let a = (texel[c] * o.scale[c]).clamp(0.0, 1.0) * o.opacity.clamp(0.0, 1.0);
                    for (out, col) in rgb.iter_mut().zip(colour) {
                        *out += (col - *out) * a;
                    }
                }
            }
            let u8c = |x: f32| (x.clamp(0.0, 1.0) * 255.0).round() as u8;
            out.push([u8c(rgb[0]), u8c(rgb[1]), u8c(rgb[2]), 255]);
        }
    }
    out
}

/// Native only (tests, export): reads a slice image back, row-major RGBA8, blocking.
#[cfg(not(target_arch = "wasm32"))]
pub fn read_image_blocking(
    ctx: &GpuContext,
    image: &SliceImage,
) -> Result<Vec<[u8; 4]>, crate::gpu::readback::ReadbackError> {
    let [w, h] = image.size;
    let bytes = crate::gpu::readback::read_texture_blocking(ctx, &image.texture, [w, h, 1], 4)?;
    Ok(bytes
        .chunks_exact(4)
        .map(|p| [p[0], p[1], p[2], p[3]])
        .collect())
}
