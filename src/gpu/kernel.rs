//! What every compute kernel module shares: the grid of the slab it works on, storage buffers of
//! `f32` and tables, parameter structs, textures, bind groups, and workgroup counts.
//!
//! Conventions every kernel follows (ARCHITECTURE.md, its `src/gpu` entry and invariants):
//! - A volume on the GPU is a storage buffer of `f32`, voxel `i` fastest
//!   (`index = i + nx * (j + ny * k)`), physical units; several components of one volume are
//!   stored component-major in one buffer (`c * n + index`).
//! - Kernels run over whole slabs (the caller passes a slab with its halo) and replicate borders
//!   at the slab's edges, exactly as the CPU twins do at the volume's edges; inside a halo the
//!   values are wrong and the caller discards them.
//! - Compute shaders use `@workgroup_size(8, 8, 1)` over `(i, j, k)` unless stated, and check
//!   bounds, so any size works.

/// Where a kernel records: the device and the caller's encoder. Kernels record into it and
/// never submit (the caller decides when the work goes to the queue).
pub struct Recorder<'a> {
    pub ctx: &'a crate::gpu::GpuContext,
    pub encoder: &'a mut wgpu::CommandEncoder,
}

impl<'a> Recorder<'a> {
    pub fn new(ctx: &'a crate::gpu::GpuContext, encoder: &'a mut wgpu::CommandEncoder) -> Self {
        Self { ctx, encoder }
    }
}

/// The grid of the slab a kernel runs on: voxel counts and spacing (mm) per axis.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SlabGrid {
    pub dims: [u32; 3],
    pub spacing_mm: [f32; 3],
}

impl SlabGrid {
    pub fn new(dims: [u32; 3], spacing_mm: [f32; 3]) -> Self {
        Self { dims, spacing_mm }
    }

    /// Voxel count.
    pub fn len(&self) -> u64 {
        self.dims.iter().map(|&d| u64::from(d)).product()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The same slab as the CPU reference's [`crate::cpu::Grid`].
    pub fn to_cpu(&self) -> crate::cpu::Grid {
        crate::cpu::Grid::new(
            self.dims.map(|d| d as usize),
            self.spacing_mm.map(f64::from),
        )
    }

    /// Workgroup counts for a `(wx, wy, wz)` workgroup over every voxel.
    pub fn workgroups(&self, wg: [u32; 3]) -> [u32; 3] {
        std::array::from_fn(|a| self.dims[a].div_ceil(wg[a]).max(1))
    }
}

/// The workgroup size of the volume kernels (`@workgroup_size(8, 8, 1)`).
pub const WORKGROUP: [u32; 3] = [8, 8, 1];

/// A storage buffer of `len` `f32` values (also a copy source and destination).
pub fn f32_buffer(device: &wgpu::Device, label: &str, len: u64) -> wgpu::Buffer {
    device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size: (len * 4).max(4),
        usage: wgpu::BufferUsages::STORAGE
            | wgpu::BufferUsages::COPY_SRC
            | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    })
}

/// A storage buffer holding `data`.
pub fn f32_buffer_init(device: &wgpu::Device, label: &str, data: &[f32]) -> wgpu::Buffer {
    use wgpu::util::DeviceExt as _;
    let bytes: &[u8] = if data.is_empty() {
        &[0; 4]
    } else {
        bytemuck::cast_slice(data)
    };
    device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some(label),
        contents: bytes,
        usage: wgpu::BufferUsages::STORAGE
            | wgpu::BufferUsages::COPY_SRC
            | wgpu::BufferUsages::COPY_DST,
    })
}

/// A read-only storage buffer holding `data` (tables a kernel reads: taps, rays).
pub fn storage_buffer_init<T: bytemuck::Pod>(
    device: &wgpu::Device,
    label: &str,
    data: &[T],
) -> wgpu::Buffer {
    use wgpu::util::DeviceExt as _;
    device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some(label),
        contents: bytemuck::cast_slice(data),
        usage: wgpu::BufferUsages::STORAGE,
    })
}

/// A read-only storage buffer holding one `#[repr(C)]` parameter struct, for kernels whose
/// loops or branches depend on it (`var<storage, read> params`): lavapipe compiles and keeps a
/// new shader variant per dispatch for such uniforms (see shaders/gaussian.wgsl).
pub fn params_buffer<T: bytemuck::Pod>(
    device: &wgpu::Device,
    label: &str,
    value: &T,
) -> wgpu::Buffer {
    use wgpu::util::DeviceExt as _;
    device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some(label),
        contents: bytemuck::bytes_of(value),
        usage: wgpu::BufferUsages::STORAGE,
    })
}

/// A texture of one mip level and one sample, `size` texels (`[w, h, 1]` for a 2D one).
pub fn texture(
    device: &wgpu::Device,
    label: &str,
    dimension: wgpu::TextureDimension,
    size: [u32; 3],
    format: wgpu::TextureFormat,
    usage: wgpu::TextureUsages,
) -> wgpu::Texture {
    device.create_texture(&wgpu::TextureDescriptor {
        label: Some(label),
        size: wgpu::Extent3d {
            width: size[0],
            height: size[1],
            depth_or_array_layers: size[2],
        },
        mip_level_count: 1,
        sample_count: 1,
        dimension,
        format,
        usage,
        view_formats: &[],
    })
}

/// A bind group of `pipeline`'s group 0 in which binding `n` is `resources[n]` (the kernels
/// number their bindings from 0 without gaps).
pub fn bind_group<'a>(
    device: &wgpu::Device,
    label: &str,
    pipeline: &wgpu::ComputePipeline,
    resources: impl IntoIterator<Item = wgpu::BindingResource<'a>>,
) -> wgpu::BindGroup {
    let entries: Vec<wgpu::BindGroupEntry<'a>> = (0..)
        .zip(resources)
        .map(|(binding, resource)| wgpu::BindGroupEntry { binding, resource })
        .collect();
    device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some(label),
        layout: &pipeline.get_bind_group_layout(0),
        entries: &entries,
    })
}
