//! The radial structure tensor on the GPU (shaders/rst.wgsl): the ray kernel whose twin is
//! [`crate::cpu::rst_tensor_at`], at the same sample positions, with both opacity rules.
//!
//! Use: build [`Rst`] once per device; build [`RstRays`] once per run (ray set, opacity lengths
//! and steps computed here on the CPU with the twin's own functions, uploaded once); then
//! [`Rst::record`] per dispatch into the caller's command encoder, over the output slices
//! `out_z0 .. out_z0 + out_nz` of a slab whose smoothed intensity and gradient are packed as
//! (I, gx, gy, gz) in one rgba32float 3D texture ([`crate::compute::gradient::packed_texture`],
//! written by [`Gradient::record`] from the smoothed intensity).
//!
//! Why a texture and not four storage buffers: the kernel reads 8 corners x 4 values per ray
//! sample; on lavapipe one `textureLoad` of four channels costs about as much as one scalar
//! storage-buffer load (llvmpipe loads storage buffers lane by lane), so the texture made the
//! kernel 2.3x faster there (measured: 48^3 voxels, 42 rays, R 15 mm: 6.3 s of CPU time instead
//! of 14.6 s), and GPUs cache textures in 3D, which suits rays in every direction. A texture is
//! also not bound by `max_storage_buffer_binding_size` (only by `max_texture_dimension_3d` per
//! axis).
//!
//! Two fetch paths, chosen when the kernel is built: [`Rst::new`] reads (I, g) with 8
//! `textureLoad`s and the twin's weights in f32 (the bit-level twin tests); [`Rst::with_options`]
//! with [`RstOptions::hardware_filtering`] reads it with one `textureSampleLevel` through a linear
//! clamp-to-edge sampler (texture coordinates `(voxel + 0.5) / dims`, positions clamped onto the
//! slab first, as the twin clamps them), within a tolerance of the twin (tests/gpu/rst.rs).
//! The filtered path keeps the rgba32float texture and needs FLOAT32_FILTERABLE
//! (`float32-filterable` in WebGPU), which [`crate::gpu::context`] requests wherever the adapter
//! offers it (lavapipe does; Chrome exposes it since version 119 where the GPU can); without it the
//! kernel falls back to the exact path ([`Rst::hardware_filtering`] says which one runs). Not
//! rgba16float, which core WebGPU does filter everywhere: half floats hold I only to 0.5-2 HU in
//! the CT range (the transfer function's ramp is 10-30 HU) and would change the slab's memory and
//! the gradient kernel's output format; a device without the feature loses speed, not precision.
//! Measured on lavapipe (sphere next to cylinder, 42 rays, R 15 mm, dr 0.25 mm, Li features,
//! ~2,265 ray samples per voxel; `time_exact_against_hardware_filtering` in tests/gpu/rst.rs):
//! 48^3 voxels 4.47 s of CPU time exact, 2.34 s filtered (1.9x); 64^3 10.5 s and 5.44 s (1.9x).
//!
//! Sizing a slab for it: the rays read [`RstRays::halo_slices`] slices of (I, g) beyond each side
//! of the output range; the gradient needs [`Gradient::HALO_SLICES`] more of smoothed intensity,
//! and the smoothing its own kernel radius on top ([`RstRays::total_halo_slices`] adds the
//! first two). Memory: [`Rst::INPUT_BYTES_PER_VOXEL`] per slab voxel (the packed texture),
//! [`RstOutput::bytes_per_voxel`] per output voxel.

use crate::compute::gradient::{
    Gradient, check_packed, entry, storage_binding, voxel_count, workgroups,
};
use crate::cpu::rst::{ALPHA_STOP, opacity_length_mm};
use crate::cpu::{FeatureMap, OpacityRule, RstParams};
use crate::gpu::checks::RecordError;
use crate::gpu::kernel::Recorder;
use crate::gpu::kernel::{SlabGrid, params_buffer};
use crate::gpu::{GpuContext, shaders};

mod rays;

pub use rays::{RstConfigError, RstRays};

/// Mirrors `Params` in rst.wgsl (keep in sync).
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
struct Params {
    dims: [u32; 3],
    n_rays: u32,
    out_z0: u32,
    out_nz: u32,
    n_steps: u32,
    rule: u32,
    step_mm: f32,
    dr_vox: f32,
    d_min: f32,
    d_max: f32,
    mode: u32,
    map: u32,
    alpha_stop: f32,
    trans_stop: f32,
    row0: u32,
    n_rows: u32,
    z_stride: u32,
    _pad: u32,
}
const _: () = assert!(std::mem::size_of::<Params>() == 80);

/// Mirrors `Ray` in rst.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
struct GpuRay {
    dir_len: [f32; 4],
    step_vox: [f32; 4],
}
const _: () = assert!(std::mem::size_of::<GpuRay>() == 32);

// The numbers of rst.wgsl and feature_maps.wgsl.
const RULE_CONSISTENT: u32 = 0;
const RULE_PAPER: u32 = 1;
const MODE_TENSOR: u32 = 0;
const MODE_EIGEN: u32 = 1;
const MODE_FEATURES: u32 = 2;
const MODE_SAMPLE_COUNT: u32 = 3;
const MAP_SIMPLE: u32 = 0;
const MAP_LI: u32 = 1;

/// The most steps per ray a run may ask for (a runaway loop would hang the device).
pub const MAX_STEPS: usize = 1 << 16;
/// The most rays a run may ask for.
pub const MAX_RAYS: usize = 4096;

/// What the kernel writes per output voxel, component-major (`c * n_out + index`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RstOutput {
    /// The symmetrised tensor Ts = (T + T^T) / N_R: six components `[xx, yy, zz, xy, xz, yz]`
    /// (the order of [`crate::cpu::Sym3`]).
    Tensor,
    /// Eigenvalues `[l0, l1, l2]`, `|l0| >= |l1| >= |l2|` (shaders/eigen.wgsl).
    Eigen,
    /// `[V, A, B]` with the simple (eq. 1) or Li (eq. 2) map (shaders/feature_maps.wgsl).
    Features(FeatureMap),
    /// One component: the number of ray samples taken at the voxel (excluding the centre), as
    /// f32. For benchmarks (ray samples per second).
    SampleCount,
}

impl RstOutput {
    pub fn components(self) -> u32 {
        match self {
            Self::Tensor => 6,
            Self::Eigen | Self::Features(_) => 3,
            Self::SampleCount => 1,
        }
    }

    /// Bytes of output per output voxel (f32 components).
    pub fn bytes_per_voxel(self) -> u64 {
        u64::from(self.components()) * 4
    }

    fn mode_and_map(self) -> (u32, u32) {
        match self {
            Self::Tensor => (MODE_TENSOR, 0),
            Self::Eigen => (MODE_EIGEN, 0),
            Self::Features(FeatureMap::Simple) => (MODE_FEATURES, MAP_SIMPLE),
            Self::Features(FeatureMap::Li) => (MODE_FEATURES, MAP_LI),
            Self::SampleCount => (MODE_SAMPLE_COUNT, 0),
        }
    }
}

/// The slab's (I, g) and the rays: what [`Rst::record`] reads.
#[derive(Clone, Copy)]
pub struct RstInputs<'a> {
    /// Smoothed intensity I and gradient g (HU/mm) of the slab as (I, gx, gy, gz): a 3D
    /// rgba32float texture of the slab's dims with TEXTURE_BINDING usage
    /// ([`crate::compute::gradient::packed_texture`], filled by [`Gradient::record`]).
    pub volume: &'a wgpu::Texture,
    pub rays: &'a RstRays,
}

/// One dispatch: the slab's grid, the output slices and what to write.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RstDispatch {
    /// The slab (with its halo). Its spacing must be the one the rays were built for.
    pub grid: SlabGrid,
    /// First output slice (slab index).
    pub out_z0: u32,
    /// Number of output slices; the output buffer holds `nx * ny * out_nz` voxels per component.
    pub out_nz: u32,
    /// Slab slices from one output slice to the next (output slice `k` is slab slice
    /// `out_z0 + k * z_stride`): 1, or the refinement factor of z, so that a refined slab is
    /// evaluated at its input voxels only.
    pub z_stride: u32,
    /// `Some([j0, nj])`: compute only the rows `j0 .. j0 + nj` of the output slices (the rest of
    /// the output buffer is left as it is), to split a slice into smaller dispatches where the
    /// device is slow (lavapipe: ~30 s for one 512 x 512 slice at the defaults). `None`: all rows.
    pub rows: Option<[u32; 2]>,
    pub output: RstOutput,
}

impl RstDispatch {
    /// All rows of the output slices `out_z0 .. out_z0 + out_nz` of `grid`.
    pub fn slices(grid: SlabGrid, out_z0: u32, out_nz: u32, output: RstOutput) -> Self {
        Self {
            grid,
            out_z0,
            out_nz,
            z_stride: 1,
            rows: None,
            output,
        }
    }

    /// The rows `[j0, nj]` this dispatch computes.
    pub fn row_range(&self) -> [u32; 2] {
        self.rows.unwrap_or([0, self.grid.dims[1]])
    }

    /// Output voxels the output buffer holds (every row of the output slices).
    pub fn out_voxels(&self) -> u64 {
        u64::from(self.grid.dims[0]) * u64::from(self.grid.dims[1]) * u64::from(self.out_nz)
    }

    /// Bytes the output buffer needs.
    pub fn out_bytes(&self) -> u64 {
        self.out_voxels() * self.output.bytes_per_voxel()
    }
}

/// How [`Rst`] is built.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RstOptions {
    /// Read (I, g) with one hardware-filtered `textureSampleLevel` per ray step instead of 8
    /// `textureLoad`s: faster, but the texture unit's interpolation weights (8 fractional bits
    /// on many GPUs) make it agree with the CPU twin only within a tolerance (tests/gpu/rst.rs,
    /// `filtered_bounds`: with the consistent rule, eigenvalues within 5e-3 of the largest
    /// |eigenvalue| and 99% of voxels within 1e-3; looser for the paper's rule). Honoured
    /// only where the device has FLOAT32_FILTERABLE (see [`Rst::hardware_filtering_available`]);
    /// elsewhere the exact path runs. Off by default (the exact path).
    pub hardware_filtering: bool,
    /// For tests, 0 otherwise: the exact path with its trilinear weights truncated to multiples
    /// of `1 / emulated_weight_steps` (256: a texture unit with 8 fractional bits), to measure
    /// what hardware filtering costs on such GPUs on a device that filters more precisely.
    /// Ignored when the hardware-filtered path runs.
    pub emulated_weight_steps: u32,
}

/// The RST kernel's pipeline (one fetch path, fixed when it is built).
pub struct Rst {
    pipeline: wgpu::ComputePipeline,
    layout: wgpu::BindGroupLayout,
    sampler: wgpu::Sampler,
    hardware_filtering: bool,
}

impl Rst {
    /// Bytes per slab voxel of the input (I, gx, gy, gz as rgba32float).
    pub const INPUT_BYTES_PER_VOXEL: u64 = 16;

    /// The exact kernel: (I, g) from 8 `textureLoad`s with the twin's weights.
    pub fn new(ctx: &GpuContext) -> Result<Self, shaders::ShaderSourceError> {
        Self::with_options(ctx, RstOptions::default())
    }

    /// The kernel with `options`; asking for hardware filtering on a device that cannot filter
    /// rgba32float gives the exact kernel ([`Self::hardware_filtering`] tells).
    pub fn with_options(
        ctx: &GpuContext,
        options: RstOptions,
    ) -> Result<Self, shaders::ShaderSourceError> {
        let filtered = options.hardware_filtering && Self::hardware_filtering_available(ctx);
        let module = shaders::create_module(&ctx.device, "rst.wgsl")?;
        // An explicit layout: the texture is declared filterable (and the sampler filtering)
        // only for the filtered pipeline, so the exact one binds rgba32float on any device.
        let visibility = wgpu::ShaderStages::COMPUTE;
        let buffer = |binding, ty| wgpu::BindGroupLayoutEntry {
            binding,
            visibility,
            ty: wgpu::BindingType::Buffer {
                ty,
                has_dynamic_offset: false,
                min_binding_size: None,
            },
            count: None,
        };
        let entries = [
            buffer(0, wgpu::BufferBindingType::Storage { read_only: true }),
            wgpu::BindGroupLayoutEntry {
                binding: 1,
                visibility,
                ty: wgpu::BindingType::Texture {
                    sample_type: wgpu::TextureSampleType::Float {
                        filterable: filtered,
                    },
                    view_dimension: wgpu::TextureViewDimension::D3,
                    multisampled: false,
                },
                count: None,
            },
            buffer(2, wgpu::BufferBindingType::Storage { read_only: true }),
            buffer(3, wgpu::BufferBindingType::Storage { read_only: false }),
            wgpu::BindGroupLayoutEntry {
                binding: 4,
                visibility,
                ty: wgpu::BindingType::Sampler(if filtered {
                    wgpu::SamplerBindingType::Filtering
                } else {
                    wgpu::SamplerBindingType::NonFiltering
                }),
                count: None,
            },
        ];
        let layout = ctx
            .device
            .create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some("rst"),
                entries: &entries,
            });
        let pipeline_layout = ctx
            .device
            .create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some("rst"),
                bind_group_layouts: &[Some(&layout)],
                immediate_size: 0,
            });
        let emulated = if filtered {
            0.0
        } else {
            f64::from(options.emulated_weight_steps)
        };
        let constants = [
            ("HARDWARE_FILTERING", if filtered { 1.0 } else { 0.0 }),
            ("EMULATED_WEIGHT_STEPS", emulated),
        ];
        let pipeline = ctx
            .device
            .create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some(if filtered { "rst (filtered)" } else { "rst" }),
                layout: Some(&pipeline_layout),
                module: &module,
                entry_point: Some("rst"),
                compilation_options: wgpu::PipelineCompilationOptions {
                    constants: &constants,
                    ..Default::default()
                },
                cache: None,
            });
        let filter = if filtered {
            wgpu::FilterMode::Linear
        } else {
            wgpu::FilterMode::Nearest
        };
        let sampler = ctx.device.create_sampler(&wgpu::SamplerDescriptor {
            label: Some("rst (I, g)"),
            address_mode_u: wgpu::AddressMode::ClampToEdge,
            address_mode_v: wgpu::AddressMode::ClampToEdge,
            address_mode_w: wgpu::AddressMode::ClampToEdge,
            mag_filter: filter,
            min_filter: filter,
            mipmap_filter: wgpu::MipmapFilterMode::Nearest,
            ..Default::default()
        });
        Ok(Self {
            pipeline,
            layout,
            sampler,
            hardware_filtering: filtered,
        })
    }

    /// Whether the device can run the hardware-filtered path (linear filtering of rgba32float,
    /// FLOAT32_FILTERABLE).
    pub fn hardware_filtering_available(ctx: &GpuContext) -> bool {
        ctx.float32_filterable()
    }

    /// Whether this kernel reads (I, g) through the texture unit's filter (else the exact 8
    /// loads).
    pub fn hardware_filtering(&self) -> bool {
        self.hardware_filtering
    }

    /// Records the RST of the output slices of `params.grid` into `out` (component-major,
    /// `c * out_voxels + i + nx * (j + ny * k)` for output slice `k`, slab slice
    /// `out_z0 + k * z_stride`). Nothing is submitted.
    pub fn record(
        &self,
        rec: &mut Recorder<'_>,
        inputs: &RstInputs<'_>,
        params: &RstDispatch,
        out: &wgpu::Buffer,
    ) -> Result<(), RecordError> {
        let grid = &params.grid;
        voxel_count(grid)?;
        check_packed(inputs.volume, grid, wgpu::TextureUsages::TEXTURE_BINDING)?;
        let nz = grid.dims[2];
        // One past the last slab slice read as an output slice.
        let end = u64::from(params.out_z0)
            + u64::from(params.out_nz.saturating_sub(1)) * u64::from(params.z_stride)
            + 1;
        if params.out_nz == 0 || params.z_stride == 0 || end > u64::from(nz) {
            return Err(RecordError::OutputRange {
                z0: params.out_z0,
                nz: params.out_nz,
                depth: nz,
            });
        }
        let [row0, n_rows] = params.row_range();
        let rows_end = u64::from(row0) + u64::from(n_rows);
        if n_rows == 0 || rows_end > u64::from(grid.dims[1]) {
            return Err(RecordError::RowRange {
                j0: row0,
                end: rows_end,
                ny: grid.dims[1],
            });
        }
        let rays = inputs.rays;
        let rays_spacing = rays.spacing_mm.map(|s| s as f32);
        if rays_spacing != grid.spacing_mm {
            return Err(RecordError::SpacingMismatch {
                slab: grid.spacing_mm,
                rays: rays_spacing,
            });
        }
        let groups = workgroups(rec.ctx, [grid.dims[0], n_rows, params.out_nz])?;
        let (mode, map) = params.output.mode_and_map();
        let gpu_params = Params {
            dims: grid.dims,
            n_rays: rays.n_rays,
            out_z0: params.out_z0,
            out_nz: params.out_nz,
            n_steps: rays.steps,
            rule: match rays.rule {
                OpacityRule::Consistent => RULE_CONSISTENT,
                OpacityRule::Paper => RULE_PAPER,
            },
            step_mm: rays.step_mm as f32,
            dr_vox: rays.dr_vox as f32,
            d_min: rays.d_min as f32,
            d_max: rays.d_max as f32,
            mode,
            map,
            alpha_stop: ALPHA_STOP as f32,
            trans_stop: (1.0 - ALPHA_STOP) as f32,
            row0,
            n_rows,
            z_stride: params.z_stride,
            _pad: 0,
        };
        let params_buf = params_buffer(&rec.ctx.device, "rst params", &gpu_params);
        let ray_bytes = u64::from(rays.n_rays) * std::mem::size_of::<GpuRay>() as u64;
        let view = inputs
            .volume
            .create_view(&wgpu::TextureViewDescriptor::default());
        let entries = [
            entry(0, params_buf.as_entire_binding()),
            entry(1, wgpu::BindingResource::TextureView(&view)),
            entry(
                2,
                storage_binding(rec.ctx, "rays", &rays.buffer, ray_bytes)?,
            ),
            entry(
                3,
                storage_binding(rec.ctx, "output", out, params.out_bytes())?,
            ),
            entry(4, wgpu::BindingResource::Sampler(&self.sampler)),
        ];
        let bind_group = rec
            .ctx
            .device
            .create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("rst"),
                layout: &self.layout,
                entries: &entries,
            });
        crate::gpu::checks::dispatch(rec.encoder, "rst", &self.pipeline, &bind_group, groups);
        Ok(())
    }
}
