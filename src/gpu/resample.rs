//! Linear resampling between two grids with an mm offset (shaders/resample.wgsl), per slab:
//! thick axes to <= 1.25 mm before the features and the features back onto the input grid
//! (SCIENCE.md, "What real scans taught us", item 4). Twin: [`crate::cpu::resample_linear`].
//!
//! Convention (the CPU's, grid mm): source voxel `s` of a slab sits at
//! `src_origin_mm + s * src_spacing_mm`, destination voxel `t` at
//! `dst_origin_mm + t * dst_spacing_mm`, per axis. The destination reads the source at
//! `u = (dst_origin + t * dst_spacing - src_origin) / src_spacing` (source voxels), clamped into
//! `[0, n - 1]`, linear between `floor(u)` and the next voxel. With both origins 0 this is the
//! CPU's `u = t * to / from` exactly (same f64 expression); [`crate::cpu::resample::refined_grid`]
//! keeps the first voxel centre and the extent, so whole-volume grids share origin 0. For slabs,
//! origins are `z0 * spacing` of each slab's first slice in its whole grid, and the source slab
//! must hold [`source_slices`] of the destination slices (clamping then happens only at the
//! volume's ends, as on the CPU). The per-axis neighbours and weights are computed here in f64
//! and uploaded, so the GPU interpolates with the CPU's taps.

use crate::gpu::checks::{self, RecordError};
use crate::gpu::kernel::{SlabGrid, WORKGROUP};
use crate::gpu::{GpuContext, shaders};

/// Mirrors `Params` in resample.wgsl (keep in sync).
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
struct Params {
    src_dims: [u32; 3],
    components: u32,
    dst_dims: [u32; 3],
    _pad: u32,
}
const _: () = assert!(std::mem::size_of::<Params>() == 32);

/// Mirrors `Tap` in resample.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct Tap {
    pub i0: u32,
    pub i1: u32,
    /// Weight of `i1`.
    pub w: f32,
    _pad: u32,
}
const _: () = assert!(std::mem::size_of::<Tap>() == 16);

/// Where the two grids lie, per axis, in grid mm.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ResampleGeometry {
    pub src_origin_mm: [f64; 3],
    pub src_spacing_mm: [f64; 3],
    pub dst_origin_mm: [f64; 3],
    pub dst_spacing_mm: [f64; 3],
}

impl ResampleGeometry {
    /// Two whole grids with the same first voxel centre (as `refined_grid` makes them).
    pub fn same_origin(src_spacing_mm: [f64; 3], dst_spacing_mm: [f64; 3]) -> Self {
        Self {
            src_origin_mm: [0.0; 3],
            src_spacing_mm,
            dst_origin_mm: [0.0; 3],
            dst_spacing_mm,
        }
    }

    /// Slabs along z of two whole grids sharing origin 0: the source slab starts at whole-grid
    /// slice `src_z0`, the destination slab at `dst_z0`.
    pub fn z_slabs(
        src_spacing_mm: [f64; 3],
        src_z0: u32,
        dst_spacing_mm: [f64; 3],
        dst_z0: u32,
    ) -> Self {
        Self {
            src_origin_mm: [0.0, 0.0, f64::from(src_z0) * src_spacing_mm[2]],
            src_spacing_mm,
            dst_origin_mm: [0.0, 0.0, f64::from(dst_z0) * dst_spacing_mm[2]],
            dst_spacing_mm,
        }
    }

    /// Source position (voxels, unclamped) of destination index `t` along `axis`.
    fn position(&self, axis: usize, t: u32) -> f64 {
        let p = self.dst_origin_mm[axis] + f64::from(t) * self.dst_spacing_mm[axis];
        (p - self.src_origin_mm[axis]) / self.src_spacing_mm[axis]
    }
}

/// The neighbours and weight along `axis` for every destination index (the CPU's taps).
pub fn axis_taps(geometry: &ResampleGeometry, axis: usize, n_src: u32, n_dst: u32) -> Vec<Tap> {
    (0..n_dst).map(|t| tap(geometry, axis, n_src, t)).collect()
}

/// The neighbours and weight along `axis` of destination index `t`.
fn tap(geometry: &ResampleGeometry, axis: usize, n_src: u32, t: u32) -> Tap {
    let last = n_src.max(1) - 1;
    let u = geometry.position(axis, t);
    // NaN (a zero spacing) reads the first voxel.
    let u = if u.is_nan() {
        0.0
    } else {
        u.clamp(0.0, f64::from(last))
    };
    let f = u.floor();
    let i0 = f as u32;
    Tap {
        i0,
        i1: (i0 + 1).min(last),
        w: (u - f) as f32,
        _pad: 0,
    }
}

/// The whole-grid source slices `(z0, nz)` that destination slices `dst_z0 .. dst_z0 + dst_nz`
/// read (both grids with origin 0, source depth `src_depth`): the halo of resampling.
pub fn source_slices(
    src_spacing_z_mm: f64,
    src_depth: u32,
    dst_spacing_z_mm: f64,
    dst_z0: u32,
    dst_nz: u32,
) -> (u32, u32) {
    let g =
        ResampleGeometry::same_origin([1.0, 1.0, src_spacing_z_mm], [1.0, 1.0, dst_spacing_z_mm]);
    if dst_nz == 0 || src_depth == 0 {
        return (0, 0);
    }
    let first = tap(&g, 2, src_depth, dst_z0).i0;
    let last = tap(&g, 2, src_depth, dst_z0.saturating_add(dst_nz - 1)).i1;
    (first, last - first + 1)
}

/// The resampling pipeline.
pub struct Resample {
    pipeline: wgpu::ComputePipeline,
}

impl Resample {
    pub fn new(ctx: &GpuContext) -> Result<Self, shaders::ShaderSourceError> {
        let module = shaders::create_module(&ctx.device, "resample.wgsl")?;
        Ok(Self {
            pipeline: checks::pipeline(ctx, &module, "resample"),
        })
    }

    /// Records `dst` (grid `dst_dims`) = `src` (grid `src_dims`) resampled linearly, for
    /// `components` volumes stored component-major in each buffer.
    #[allow(clippy::too_many_arguments)]
    pub fn record(
        &self,
        ctx: &GpuContext,
        encoder: &mut wgpu::CommandEncoder,
        src: &wgpu::Buffer,
        src_dims: [u32; 3],
        dst: &wgpu::Buffer,
        dst_dims: [u32; 3],
        components: u32,
        geometry: &ResampleGeometry,
    ) -> Result<(), RecordError> {
        if src == dst {
            return Err(RecordError::Invalid("resample cannot run in place"));
        }
        let src_grid = SlabGrid::new(src_dims, [1.0; 3]);
        let dst_grid = SlabGrid::new(dst_dims, [1.0; 3]);
        if dst_grid.is_empty() || components == 0 {
            return Ok(());
        }
        if src_grid.is_empty() {
            return Err(RecordError::Invalid("resample: the source is empty"));
        }
        let c = u64::from(components);
        checks::buffer(
            ctx,
            "resample src",
            src,
            checks::f32_bytes(src_grid.len(), c),
        )?;
        checks::buffer(
            ctx,
            "resample dst",
            dst,
            checks::f32_bytes(dst_grid.len(), c),
        )?;
        let groups = checks::workgroups(ctx, "resample", dst_grid.workgroups(WORKGROUP))?;
        let mut taps = Vec::new();
        for axis in 0..3 {
            taps.extend(axis_taps(geometry, axis, src_dims[axis], dst_dims[axis]));
        }
        let taps = {
            use wgpu::util::DeviceExt as _;
            ctx.device
                .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                    label: Some("resample taps"),
                    contents: bytemuck::cast_slice(&taps),
                    usage: wgpu::BufferUsages::STORAGE,
                })
        };
        let params = Params {
            src_dims,
            components,
            dst_dims,
            _pad: 0,
        };
        let params = crate::gpu::kernel::uniform_buffer(&ctx.device, "resample params", &params);
        let bind_group = ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("resample"),
            layout: &self.pipeline.get_bind_group_layout(0),
            entries: &[
                checks::entry(0, &params),
                checks::entry(1, src),
                checks::entry(2, &taps),
                checks::entry(3, dst),
            ],
        });
        checks::dispatch(encoder, "resample", &self.pipeline, &bind_group, groups);
        Ok(())
    }
}
