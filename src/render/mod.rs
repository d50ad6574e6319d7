//! Rendering: the orbit camera, the MIP ray caster with its picks, the slice panes and the
//! status bar's texel probe. Reads the volume textures of `crate::gpu::volume_texture`; never
//! `crate::compute`.
//!
//! Here, what the render passes share: each is one dispatch into a texture it writes and that is
//! later shown or copied, with a one-texel stand-in where no features are bound.

pub mod camera;
pub mod fusion;
pub mod probe;
pub mod raycast;
pub mod slice;

use crate::gpu::volume_texture::FEATURE_FORMAT;
use crate::gpu::{GpuContext, checks, kernel};

/// A texture a render pass writes (storage) and that is then shown (sampled) or read back
/// (copied), with its view.
pub(crate) fn output_texture(
    ctx: &GpuContext,
    label: &str,
    dimension: wgpu::TextureDimension,
    size: [u32; 3],
    format: wgpu::TextureFormat,
) -> (wgpu::Texture, wgpu::TextureView) {
    let usage = wgpu::TextureUsages::STORAGE_BINDING
        | wgpu::TextureUsages::TEXTURE_BINDING
        | wgpu::TextureUsages::COPY_SRC;
    let texture = kernel::texture(&ctx.device, label, dimension, size, format, usage);
    let view = texture.create_view(&wgpu::TextureViewDescriptor::default());
    (texture, view)
}

/// A one-texel feature texture, bound where a pass shows no features (every binding needs a
/// texture).
pub(crate) fn no_features_view(ctx: &GpuContext, label: &str) -> wgpu::TextureView {
    kernel::texture(
        &ctx.device,
        label,
        wgpu::TextureDimension::D3,
        [1, 1, 1],
        FEATURE_FORMAT,
        wgpu::TextureUsages::TEXTURE_BINDING,
    )
    .create_view(&wgpu::TextureViewDescriptor::default())
}

/// Records one dispatch in an encoder of its own and submits it (not waited for).
pub(crate) fn submit_dispatch(
    ctx: &GpuContext,
    label: &str,
    pipeline: &wgpu::ComputePipeline,
    bind_group: &wgpu::BindGroup,
    groups: [u32; 3],
) {
    let mut encoder = ctx
        .device
        .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some(label) });
    checks::dispatch(&mut encoder, label, pipeline, bind_group, groups);
    ctx.queue.submit([encoder.finish()]);
}
