//! A feature job's per-slab GPU buffers (allocated once at the largest slab's size) and the
//! small helpers that size them and place a slab: bytes per voxel for the memory budget, the
//! halo a method needs, a box's kernel grid, a core's place within its brick.

use super::PipelineError;
use crate::compute::slab::Brick;
use crate::cpu::Grid;
use crate::cpu::gaussian::kernel_radius_vox;
use crate::cpu::pipeline::{Method, Request, Resolved};
use crate::gpu::GpuContext;
use crate::gpu::kernel::{SlabGrid, f32_buffer};

/// Per-slab GPU buffers, allocated once at the largest slab's size and reused.
pub(super) struct Buffers {
    /// Input-grid slices of a slab.
    pub(super) input: wgpu::Buffer,
    /// The slab on the compute grid (only when it differs from the input grid).
    pub(super) vol: Option<wgpu::Buffer>,
    /// Scratch for separable passes and smoothing.
    pub(super) tmp: [wgpu::Buffer; 2],
    /// Six tensor components (Hessian); I, gx, gy, gz (RST); I, gx, gy, gz and six tensor
    /// components (structure tensor).
    pub(super) work: Vec<wgpu::Buffer>,
    /// Features of the core on the compute grid, component-major (3, or 4 for eigenvalues); the
    /// RST's at the core's input slices only.
    pub(super) out_core: wgpu::Buffer,
    /// One RST dispatch's output block.
    pub(super) chunk_out: Option<wgpu::Buffer>,
    /// Features on the input grid (only when the grids differ and the method's features are
    /// subsampled: not the RST's).
    pub(super) out_in: Option<wgpu::Buffer>,
    /// Noise windows, small.
    pub(super) small: wgpu::Buffer,
    /// Largest tensor norm (Frangi's c).
    pub(super) norm: wgpu::Buffer,
}

/// Bytes per compute voxel of a method's working buffers (for the memory budget).
pub(super) fn bytes_per_voxel(method: Method, resampled: bool) -> u64 {
    let base = match method {
        // input + 6 components + 2 scratch
        Method::Hessian | Method::Li | Method::Frangi => 9 * 4,
        // input + gradient (3) + 6 components + 2 scratch
        Method::Gst => 12 * 4,
        // input + I + 2 scratch + the (I, g) texture
        Method::Rst => 4 * 4 + 16,
    };
    // + the features of the core (3 components), + the compute-grid copy when resampling
    base + 12 + if resampled { 4 } else { 0 }
}

/// Halo in compute voxels per axis (x unused: rows are whole) that `method` needs.
pub(super) fn halo_of(req: &Request, r: &Resolved) -> [usize; 3] {
    let s = r.compute.spacing_mm;
    std::array::from_fn(|a| match req.method {
        Method::Hessian | Method::Li | Method::Frangi => r
            .sigmas_mm
            .iter()
            .map(|&sigma| kernel_radius_vox(sigma / s[a]))
            .max()
            .unwrap_or(0),
        Method::Gst => {
            let rho = r.sigmas_mm.iter().copied().fold(0.0, f64::max);
            kernel_radius_vox(req.sigma_g_mm / s[a]) + 1 + kernel_radius_vox(rho / s[a])
        }
        Method::Rst => {
            let k = (r.radius_mm / r.step_mm + 1e-6).floor();
            let reach = k * r.step_mm / s[a];
            kernel_radius_vox(req.sigma_g_mm / s[a]) + 1 + reach.ceil() as usize + 1
        }
    })
}

pub(super) fn to_u32(v: usize) -> u32 {
    u32::try_from(v).unwrap_or(u32::MAX)
}

/// The kernels' grid of a box of `grid` with these ranges' lengths.
pub(super) fn box_grid(grid: &Grid, ranges: &[std::ops::Range<usize>; 3]) -> SlabGrid {
    SlabGrid::new(
        std::array::from_fn(|a| to_u32(ranges[a].len())),
        grid.spacing_mm.map(|s| s as f32),
    )
}

/// The core's slices and rows within its brick: `((z0, nz), (y0, ny))`.
pub(super) fn core_in_slab(b: &Brick) -> ((u32, u32), (u32, u32)) {
    let local = |a: usize| {
        (
            to_u32(b.core_c[a].start - b.slab_c[a].start),
            to_u32(b.core_c[a].len()),
        )
    };
    (local(2), local(1))
}

/// The first voxel of each range.
pub(super) fn starts(ranges: &[std::ops::Range<usize>; 3]) -> [u32; 3] {
    std::array::from_fn(|a| to_u32(ranges[a].start))
}

impl Buffers {
    /// The bytes of all the buffers.
    pub(super) fn bytes(&self) -> u64 {
        [&self.input, &self.out_core, &self.small, &self.norm]
            .into_iter()
            .chain(&self.tmp)
            .chain(&self.work)
            .chain(self.vol.iter())
            .chain(self.chunk_out.iter())
            .chain(self.out_in.iter())
            .map(wgpu::Buffer::size)
            .sum()
    }

    /// The error of these buffers refused by the device (`detail`: its words).
    pub(super) fn refused(&self, detail: String) -> PipelineError {
        PipelineError::OutOfMemory {
            what: "the feature job's brick buffers",
            bytes: self.bytes(),
            detail,
        }
    }

    pub(super) fn new(
        ctx: &GpuContext,
        bricks: &[Brick],
        noise_bricks: &[Brick],
        resampled: bool,
        req: &Request,
        rst_slices: usize,
    ) -> Self {
        let d = &ctx.device;
        let all = || bricks.iter().chain(noise_bricks);
        let in_n = all().map(Brick::input_len).max().unwrap_or(1);
        let slab_n = all().map(Brick::slab_len).max().unwrap_or(1);
        let rows = |b: &Brick| (b.slab_c[0].len() * b.slab_c[1].len()) as u64;
        // The RST writes its features at the input voxels only (z's refinement is its rays'):
        // nothing to subsample.
        let subsampled = resampled && req.method != Method::Rst;
        // Features of a brick's core slices (the RST's: its input slices), whole brick planes.
        let core_n = bricks
            .iter()
            .map(|b| {
                let slices = if req.method == Method::Rst {
                    b.out[2].len()
                } else {
                    b.core_c[2].len()
                };
                rows(b) * slices as u64
            })
            .max()
            .unwrap_or(1);
        let out_n = bricks.iter().map(Brick::out_len).max().unwrap_or(1);
        let plane_n = bricks.iter().map(rows).max().unwrap_or(1);
        let work_count = match req.method {
            Method::Rst => 1,
            Method::Gst => 10,
            _ => 6,
        };
        let out_components = if req.eigen && req.method != Method::Rst {
            4
        } else {
            3
        };
        let noise_n = all()
            .map(|b| {
                let [nwx, nwy] =
                    crate::cpu::tf::noise_window_counts([b.slab_c[0].len(), b.slab_c[1].len(), 1]);
                (nwx * nwy * b.core_c[2].len()) as u64
            })
            .max()
            .unwrap_or(1)
            .max(1);
        Self {
            input: f32_buffer(d, "brick input", in_n),
            vol: resampled.then(|| f32_buffer(d, "brick on the compute grid", slab_n)),
            tmp: [
                f32_buffer(d, "brick scratch 0", slab_n),
                f32_buffer(d, "brick scratch 1", slab_n),
            ],
            work: (0..work_count)
                .map(|_| f32_buffer(d, "brick work", slab_n))
                .collect(),
            out_core: f32_buffer(d, "brick features", out_components * core_n),
            chunk_out: (req.method == Method::Rst)
                .then(|| f32_buffer(d, "RST block", 3 * plane_n * rst_slices as u64)),
            out_in: subsampled.then(|| f32_buffer(d, "features on the input grid", 3 * out_n)),
            small: f32_buffer(d, "noise windows", noise_n),
            norm: crate::compute::eigen_features::norm_buffer(ctx),
        }
    }
}
