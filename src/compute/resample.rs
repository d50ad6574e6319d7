//! Linear resampling between blocks of two grids related by integer factors
//! (shaders/resample.wgsl), per brick: thick axes refined before the Hessian and the features
//! taken back at the input voxels by subsampling (docs/science.md, "Thick slices"). Twins:
//! [`crate::cpu::resample::refine_linear`] and [`crate::cpu::resample::subsample`].
//!
//! Convention: each axis maps whole-grid indices with an integer factor ([`AxisMap`]); a
//! block's voxel `t` is whole-grid voxel `origin + t`. The neighbours and weights are computed
//! here with the CPU twin's own integer taps and uploaded, so refining keeps the input voxels
//! bit for bit and subsampling is a plain copy. The caller uploads a source block that holds
//! every voxel the destination reads (the brick plan's `input` ranges); clamping happens only at
//! the whole volume's ends, as on the CPU.

use crate::gpu::checks::{self, RecordError};
use crate::gpu::kernel::Recorder;
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

/// How a destination axis maps onto a source axis: whole-grid indices with integer factors, so
/// that the taps are exact (no mm arithmetic to round).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AxisMap {
    /// Destination = source refined by `f` ([`crate::cpu::resample::refine_tap`]): destination
    /// whole-grid voxel `T` reads source voxels `T / f` and the next, weight `(T % f) / f`.
    Refine { f: u32 },
    /// Destination = every `f`-th source voxel ([`crate::cpu::resample::subsample`]):
    /// destination whole-grid voxel `T` is source voxel `f * T` (weight 0).
    Subsample { f: u32 },
}

/// Where a source block and a destination block lie in their whole grids, per axis.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ResampleGeometry {
    pub map: [AxisMap; 3],
    /// Whole-grid index of the source block's first voxel, per axis.
    pub src_origin: [u32; 3],
    /// Whole-grid index of the destination block's first voxel, per axis.
    pub dst_origin: [u32; 3],
    /// Voxels of the source's whole grid per axis (clamping happens at its ends only).
    pub src_whole: [u32; 3],
}

impl ResampleGeometry {
    /// Whole grids refined by `factors`.
    pub fn refine(factors: [u32; 3], src_whole: [u32; 3]) -> Self {
        Self::whole(factors.map(|f| AxisMap::Refine { f }), src_whole)
    }

    /// Whole grids subsampled by `factors`.
    pub fn subsample(factors: [u32; 3], src_whole: [u32; 3]) -> Self {
        Self::whole(factors.map(|f| AxisMap::Subsample { f }), src_whole)
    }

    /// Whole grids mapped by `map`.
    fn whole(map: [AxisMap; 3], src_whole: [u32; 3]) -> Self {
        Self {
            map,
            src_origin: [0; 3],
            dst_origin: [0; 3],
            src_whole,
        }
    }

    /// The same mapping between blocks starting at `src_origin` and `dst_origin`.
    pub fn blocks(mut self, src_origin: [u32; 3], dst_origin: [u32; 3]) -> Self {
        self.src_origin = src_origin;
        self.dst_origin = dst_origin;
        self
    }
}

/// The neighbours and weight along `axis` for every destination index (the CPU's taps).
pub fn axis_taps(geometry: &ResampleGeometry, axis: usize, n_src: u32, n_dst: u32) -> Vec<Tap> {
    (0..n_dst).map(|t| tap(geometry, axis, n_src, t)).collect()
}

/// The neighbours (block-local) and weight along `axis` of destination index `t`, clamped into
/// the source block of `n_src` voxels.
fn tap(geometry: &ResampleGeometry, axis: usize, n_src: u32, t: u32) -> Tap {
    let whole_t = u64::from(geometry.dst_origin[axis]) + u64::from(t);
    let whole_n = geometry.src_whole[axis].max(1) as usize;
    let (i0, i1, w) = match geometry.map[axis] {
        AxisMap::Refine { f } => {
            crate::cpu::resample::refine_tap(whole_t as usize, f.max(1) as usize, whole_n)
        }
        AxisMap::Subsample { f } => {
            let i = (u64::from(f.max(1)) * whole_t).min(whole_n as u64 - 1) as usize;
            (i, i, 0.0)
        }
    };
    let last = n_src.max(1) - 1;
    let local = |i: usize| {
        (i as u64)
            .saturating_sub(u64::from(geometry.src_origin[axis]))
            .min(u64::from(last)) as u32
    };
    Tap {
        i0: local(i0),
        i1: local(i1),
        w: w as f32,
        _pad: 0,
    }
}

/// A buffer of volumes of `dims` voxels each, stored component-major: what [`Resample`] reads
/// and writes.
#[derive(Clone, Copy, Debug)]
pub struct Volumes<'a> {
    pub buffer: &'a wgpu::Buffer,
    pub dims: [u32; 3],
}

impl<'a> Volumes<'a> {
    pub fn new(buffer: &'a wgpu::Buffer, dims: [u32; 3]) -> Self {
        Self { buffer, dims }
    }
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

    /// Records `dst` = `src` resampled linearly, for `components` volumes in each buffer.
    pub fn record(
        &self,
        rec: &mut Recorder<'_>,
        src: Volumes<'_>,
        dst: Volumes<'_>,
        components: u32,
        geometry: &ResampleGeometry,
    ) -> Result<(), RecordError> {
        let (
            Volumes {
                buffer: src,
                dims: src_dims,
            },
            Volumes {
                buffer: dst,
                dims: dst_dims,
            },
        ) = (src, dst);
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
            rec.ctx,
            "resample src",
            src,
            checks::f32_bytes(src_grid.len(), c),
        )?;
        checks::buffer(
            rec.ctx,
            "resample dst",
            dst,
            checks::f32_bytes(dst_grid.len(), c),
        )?;
        let groups = checks::workgroups(rec.ctx, "resample", dst_grid.workgroups(WORKGROUP))?;
        let mut taps = Vec::new();
        for axis in 0..3 {
            taps.extend(axis_taps(geometry, axis, src_dims[axis], dst_dims[axis]));
        }
        let taps = crate::gpu::kernel::storage_buffer_init(&rec.ctx.device, "resample taps", &taps);
        let params = Params {
            src_dims,
            components,
            dst_dims,
            _pad: 0,
        };
        let params = crate::gpu::kernel::params_buffer(&rec.ctx.device, "resample params", &params);
        let bind_group = rec
            .ctx
            .device
            .create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("resample"),
                layout: &self.pipeline.get_bind_group_layout(0),
                entries: &[
                    checks::entry(0, &params),
                    checks::entry(1, src),
                    checks::entry(2, &taps),
                    checks::entry(3, dst),
                ],
            });
        checks::dispatch(rec.encoder, "resample", &self.pipeline, &bind_group, groups);
        Ok(())
    }
}
