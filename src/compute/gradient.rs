//! The RST's gradient volume on the GPU (shaders/gradient.wgsl): central differences in mm of an
//! already smoothed slab, borders replicated. It is the second half of
//! [`crate::cpu::GradientVolume::new`] (the Gaussian smoothing before it is another kernel's).
//! Two outputs: three f32 buffers gx, gy, gz ([`Gradient::record`]), or (I, gx, gy, gz) packed
//! in one rgba32float 3D texture ([`Gradient::record`]), the input of the RST kernel.
//!
//! Also holds what the RST and gradient kernels share: [`RecordError`] and the checks that make
//! a bad size an error instead of a wgpu validation panic.

use crate::gpu::kernel::Recorder;
use crate::gpu::kernel::{SlabGrid, WORKGROUP, params_buffer};
use crate::gpu::{GpuContext, shaders};

use crate::gpu::checks::RecordError;

/// Checks that `buffer` can be bound as a storage buffer of `bytes` bytes and returns that
/// binding (only the bytes the kernel uses are bound, so a larger buffer is fine).
pub(crate) fn storage_binding<'a>(
    ctx: &GpuContext,
    name: &'static str,
    buffer: &'a wgpu::Buffer,
    bytes: u64,
) -> Result<wgpu::BindingResource<'a>, RecordError> {
    if !buffer.usage().contains(wgpu::BufferUsages::STORAGE) {
        return Err(RecordError::NotStorage { what: name });
    }
    if buffer.size() < bytes {
        return Err(RecordError::BufferTooSmall {
            what: name,
            needed: bytes,
            have: buffer.size(),
        });
    }
    let limit = ctx.limits.max_storage_buffer_binding_size;
    if bytes > limit {
        return Err(RecordError::BindingTooLarge {
            what: name,
            bytes,
            limit,
        });
    }
    Ok(wgpu::BindingResource::Buffer(wgpu::BufferBinding {
        buffer,
        offset: 0,
        size: wgpu::BufferSize::new(bytes),
    }))
}

/// Checks that `texture` is a 3D texture of `PACKED_FORMAT` and the slab's dims with `usage`.
pub(crate) fn check_packed(
    texture: &wgpu::Texture,
    grid: &SlabGrid,
    usage: wgpu::TextureUsages,
) -> Result<(), RecordError> {
    let size = texture.size();
    let got = [size.width, size.height, size.depth_or_array_layers];
    if texture.dimension() != wgpu::TextureDimension::D3
        || texture.format() != PACKED_FORMAT
        || got != grid.dims
        || !texture.usage().contains(usage)
        || texture.mip_level_count() != 1
    {
        return Err(RecordError::WrongTexture {
            want: grid.dims,
            got,
            format: texture.format(),
            usage,
        });
    }
    Ok(())
}

/// Workgroup counts of an `(8, 8, 1)` dispatch over `dims`, checked against the device's limit.
pub(crate) fn workgroups(ctx: &GpuContext, dims: [u32; 3]) -> Result<[u32; 3], RecordError> {
    let groups = SlabGrid::new(dims, [1.0; 3]).workgroups(WORKGROUP);
    let limit = ctx.limits.max_compute_workgroups_per_dimension;
    if groups.iter().any(|&g| g > limit) {
        return Err(RecordError::TooManyWorkgroups {
            what: "dispatch",
            groups: groups.iter().copied().max().unwrap_or(0),
            limit,
        });
    }
    Ok(groups)
}

/// The slab's voxel count, or an error for an empty slab.
pub(crate) fn voxel_count(grid: &SlabGrid) -> Result<u64, RecordError> {
    if grid.is_empty() {
        let [nx, ny, nz] = grid.dims;
        return Err(RecordError::EmptySlab { nx, ny, nz });
    }
    Ok(grid.len())
}

pub(crate) fn compute_pipeline(
    ctx: &GpuContext,
    shader: &str,
    entry: &str,
) -> Result<wgpu::ComputePipeline, shaders::ShaderSourceError> {
    let module = shaders::create_module(&ctx.device, shader)?;
    Ok(ctx
        .device
        .create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some(entry),
            layout: None,
            module: &module,
            entry_point: Some(entry),
            compilation_options: Default::default(),
            cache: None,
        }))
}

/// Mirrors `Params` in gradient.wgsl (keep in sync).
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
struct Params {
    dims: [u32; 3],
    _pad0: u32,
    two_spacing: [f32; 3],
    _pad1: f32,
}
const _: () = assert!(std::mem::size_of::<Params>() == 32);

/// The format of the packed (I, gx, gy, gz) texture.
pub const PACKED_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba32Float;

/// A texture for [`Gradient::record`] and [`crate::compute::rst::Rst::record`]: 3D,
/// rgba32float, the slab's dims, usable as a storage texture (written) and a sampled texture
/// (read with `textureLoad`, or with a linear sampler by the RST's hardware-filtered path where
/// the device has FLOAT32_FILTERABLE), and as a copy source (readback in tests).
pub fn packed_texture(
    ctx: &GpuContext,
    grid: &SlabGrid,
    label: &str,
) -> Result<wgpu::Texture, RecordError> {
    voxel_count(grid)?;
    let limit = ctx.limits.max_texture_dimension_3d;
    let [nx, ny, nz] = grid.dims;
    if grid.dims.iter().any(|&d| d > limit) {
        return Err(RecordError::TextureTooLarge { nx, ny, nz, limit });
    }
    Ok(ctx.device.create_texture(&wgpu::TextureDescriptor {
        label: Some(label),
        size: wgpu::Extent3d {
            width: nx,
            height: ny,
            depth_or_array_layers: nz,
        },
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D3,
        format: PACKED_FORMAT,
        usage: wgpu::TextureUsages::STORAGE_BINDING
            | wgpu::TextureUsages::TEXTURE_BINDING
            | wgpu::TextureUsages::COPY_SRC
            | wgpu::TextureUsages::COPY_DST,
        view_formats: &[],
    }))
}

/// The gradient kernel's pipelines.
pub struct Gradient {
    pipeline: wgpu::ComputePipeline,
    packed: wgpu::ComputePipeline,
}

/// The three gradient components (HU/mm), one f32 buffer each, `nx * ny * nz` voxels of the slab.
#[derive(Clone, Copy, Debug)]
pub struct GradientBuffers<'a> {
    pub gx: &'a wgpu::Buffer,
    pub gy: &'a wgpu::Buffer,
    pub gz: &'a wgpu::Buffer,
}

impl Gradient {
    /// Slices of smoothed intensity the kernel reads beyond each side of the slices whose
    /// gradient must be right (the central-difference stencil).
    pub const HALO_SLICES: u32 = 1;
    /// Bytes per slab voxel of the input (smoothed intensity, f32).
    pub const INPUT_BYTES_PER_VOXEL: u64 = 4;
    /// Bytes per slab voxel of the buffer outputs (gx, gy, gz, f32).
    pub const OUTPUT_BYTES_PER_VOXEL: u64 = 12;
    /// Bytes per slab voxel of the packed output (I, gx, gy, gz as rgba32float).
    pub const PACKED_BYTES_PER_VOXEL: u64 = 16;

    pub fn new(ctx: &GpuContext) -> Result<Self, shaders::ShaderSourceError> {
        Ok(Self {
            pipeline: compute_pipeline(ctx, "gradient.wgsl", "gradient")?,
            packed: compute_pipeline(ctx, "gradient.wgsl", "gradient_packed")?,
        })
    }

    fn params_buffer(ctx: &GpuContext, grid: &SlabGrid) -> wgpu::Buffer {
        let params = Params {
            dims: grid.dims,
            _pad0: 0,
            two_spacing: grid.spacing_mm.map(|s| 2.0 * s),
            _pad1: 0.0,
        };
        params_buffer(&ctx.device, "gradient params", &params)
    }

    /// Records the gradient of the smoothed `intensity` of `grid` (every voxel of the slab; the
    /// slab's edge slices replicate the border, as the CPU twin does at the volume's) into `out`:
    /// three buffers, or (I, gx, gy, gz) texels. Nothing is submitted.
    pub fn record(
        &self,
        rec: &mut Recorder<'_>,
        grid: &SlabGrid,
        intensity: &wgpu::Buffer,
        out: GradientOutput<'_>,
    ) -> Result<(), RecordError> {
        let bytes = voxel_count(grid)? * 4;
        match out {
            GradientOutput::Packed(texture) => {
                check_packed(texture, grid, wgpu::TextureUsages::STORAGE_BINDING)?;
            }
            GradientOutput::Buffers(out) => {
                for (name, b) in [("gx", out.gx), ("gy", out.gy), ("gz", out.gz)] {
                    if b == intensity {
                        return Err(RecordError::Aliased(name));
                    }
                }
                if out.gx == out.gy || out.gx == out.gz || out.gy == out.gz {
                    return Err(RecordError::Aliased("gradient output"));
                }
            }
        }
        let groups = workgroups(rec.ctx, grid.dims)?;
        let params_buf = Self::params_buffer(rec.ctx, grid);
        let view;
        let mut entries = vec![
            entry(0, params_buf.as_entire_binding()),
            entry(1, storage_binding(rec.ctx, "intensity", intensity, bytes)?),
        ];
        let (label, pipeline) = match out {
            GradientOutput::Packed(texture) => {
                view = texture.create_view(&wgpu::TextureViewDescriptor::default());
                entries.push(entry(5, wgpu::BindingResource::TextureView(&view)));
                ("gradient packed", &self.packed)
            }
            GradientOutput::Buffers(out) => {
                entries.push(entry(2, storage_binding(rec.ctx, "gx", out.gx, bytes)?));
                entries.push(entry(3, storage_binding(rec.ctx, "gy", out.gy, bytes)?));
                entries.push(entry(4, storage_binding(rec.ctx, "gz", out.gz, bytes)?));
                ("gradient", &self.pipeline)
            }
        };
        let bind_group = rec
            .ctx
            .device
            .create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some(label),
                layout: &pipeline.get_bind_group_layout(0),
                entries: &entries,
            });
        crate::gpu::checks::dispatch(rec.encoder, label, pipeline, &bind_group, groups);
        Ok(())
    }
}

/// Where [`Gradient::record`] writes.
#[derive(Clone, Copy, Debug)]
pub enum GradientOutput<'a> {
    /// The three components, one buffer each (the structure tensor's input).
    Buffers(GradientBuffers<'a>),
    /// A texture from [`packed_texture`] of the slab's size, (I, gx, gy, gz) per texel (the RST
    /// kernel's input).
    Packed(&'a wgpu::Texture),
}

pub(crate) fn entry(binding: u32, resource: wgpu::BindingResource<'_>) -> wgpu::BindGroupEntry<'_> {
    wgpu::BindGroupEntry { binding, resource }
}
