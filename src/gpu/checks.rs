//! Checks the feature kernels' `record_*` methods make before recording, so that a wrong size
//! becomes a typed error instead of a wgpu validation panic.

use crate::gpu::{GpuContext, shaders};

/// Why a kernel could not be recorded or dispatched: the one error of every kernel module, so
/// that a bad size never reaches wgpu's validation (which panics natively).
#[derive(Clone, Debug, thiserror::Error, PartialEq)]
#[non_exhaustive]
pub enum RecordError {
    #[error("{what}: the buffer holds {have} bytes, the kernel needs {needed}")]
    BufferTooSmall {
        what: &'static str,
        needed: u64,
        have: u64,
    },
    #[error("{what}: {bytes} bytes exceed this GPU's storage binding limit ({limit} bytes)")]
    BindingTooLarge {
        what: &'static str,
        bytes: u64,
        limit: u64,
    },
    #[error("{what}: the buffer was not created with STORAGE usage")]
    NotStorage { what: &'static str },
    #[error("{what}: {groups} workgroups along one axis exceed this GPU's limit ({limit})")]
    TooManyWorkgroups {
        what: &'static str,
        groups: u32,
        limit: u32,
    },
    #[error(
        "output slices {z0}..{z0}+{nz} are not a non-empty range inside the slab's {depth} slices"
    )]
    OutputRange { z0: u32, nz: u32, depth: u32 },
    #[error("output rows {j0}..{end} are not a non-empty range inside the slab's {ny} rows")]
    RowRange { j0: u32, end: u64, ny: u32 },
    #[error("the slab is empty ({nx}x{ny}x{nz} voxels)")]
    EmptySlab { nx: u32, ny: u32, nz: u32 },
    #[error("the slab's spacing {slab:?} mm is not the one the rays were built for ({rays:?} mm)")]
    SpacingMismatch { slab: [f32; 3], rays: [f32; 3] },
    #[error(
        "the slab ({nx}x{ny}x{nz} voxels) exceeds this GPU's 3D texture size ({limit} per axis)"
    )]
    TextureTooLarge {
        nx: u32,
        ny: u32,
        nz: u32,
        limit: u32,
    },
    #[error(
        "the packed (I, g) texture must be a 3D rgba32float texture of the slab's size {want:?} with {usage:?} usage; got {got:?} {format:?}"
    )]
    WrongTexture {
        want: [u32; 3],
        got: [u32; 3],
        format: wgpu::TextureFormat,
        usage: wgpu::TextureUsages,
    },
    #[error("the {0} buffer is bound both as an input and as an output")]
    Aliased(&'static str),
    #[error("{0}")]
    Invalid(&'static str),
}

/// `buffer` can hold `needed` bytes and can be bound whole as one storage binding.
pub fn buffer(
    ctx: &GpuContext,
    what: &'static str,
    buffer: &wgpu::Buffer,
    needed: u64,
) -> Result<(), RecordError> {
    if buffer.size() < needed {
        return Err(RecordError::BufferTooSmall {
            what,
            needed,
            have: buffer.size(),
        });
    }
    let limit = ctx.limits.max_storage_buffer_binding_size;
    if buffer.size() > limit {
        return Err(RecordError::BindingTooLarge {
            what,
            bytes: buffer.size(),
            limit,
        });
    }
    Ok(())
}

/// Every workgroup count is within the device's per-dimension limit.
pub fn workgroups(
    ctx: &GpuContext,
    what: &'static str,
    groups: [u32; 3],
) -> Result<[u32; 3], RecordError> {
    let limit = ctx.limits.max_compute_workgroups_per_dimension;
    match groups.iter().find(|&&g| g > limit) {
        Some(&g) => Err(RecordError::TooManyWorkgroups {
            what,
            groups: g,
            limit,
        }),
        None => Ok(groups),
    }
}

/// `buffers` are all different (a kernel may not bind one buffer twice); `Invalid(what)`
/// otherwise.
pub fn distinct(buffers: &[&wgpu::Buffer], what: &'static str) -> Result<(), RecordError> {
    for (n, a) in buffers.iter().enumerate() {
        if buffers[n + 1..].contains(a) {
            return Err(RecordError::Invalid(what));
        }
    }
    Ok(())
}

/// Bytes of `components` f32 values per voxel of `voxels` voxels.
pub fn f32_bytes(voxels: u64, components: u64) -> u64 {
    voxels.saturating_mul(components).saturating_mul(4)
}

/// A bind group entry.
pub fn entry(binding: u32, buffer: &wgpu::Buffer) -> wgpu::BindGroupEntry<'_> {
    wgpu::BindGroupEntry {
        binding,
        resource: buffer.as_entire_binding(),
    }
}

/// A compute pipeline of `entry_point` in `module`, layout derived from the shader.
pub fn pipeline(
    ctx: &GpuContext,
    module: &wgpu::ShaderModule,
    entry_point: &str,
) -> wgpu::ComputePipeline {
    labelled_pipeline(ctx, entry_point, module, entry_point)
}

/// The pipelines of `entry_points` in the shader file `file` (one module for all).
pub fn pipelines<const N: usize>(
    ctx: &GpuContext,
    file: &str,
    entry_points: [&str; N],
) -> Result<[wgpu::ComputePipeline; N], shaders::ShaderSourceError> {
    let module = shaders::create_module(&ctx.device, file)?;
    Ok(entry_points.map(|entry_point| pipeline(ctx, &module, entry_point)))
}

/// [`pipeline`] under another label than its entry point (for shaders whose one entry point is
/// a plain `main`).
pub fn labelled_pipeline(
    ctx: &GpuContext,
    label: &str,
    module: &wgpu::ShaderModule,
    entry_point: &str,
) -> wgpu::ComputePipeline {
    ctx.device
        .create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some(label),
            layout: None,
            module,
            entry_point: Some(entry_point),
            compilation_options: Default::default(),
            cache: None,
        })
}

/// Records one dispatch of `pipeline` with `bind_group` in its own compute pass.
pub fn dispatch(
    encoder: &mut wgpu::CommandEncoder,
    label: &str,
    pipeline: &wgpu::ComputePipeline,
    bind_group: &wgpu::BindGroup,
    groups: [u32; 3],
) {
    let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
        label: Some(label),
        timestamp_writes: None,
    });
    pass.set_pipeline(pipeline);
    pass.set_bind_group(0, bind_group, &[]);
    pass.dispatch_workgroups(groups[0], groups[1], groups[2]);
}
