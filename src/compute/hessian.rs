//! The six sigma^2-normalised Hessian components of a slab at one sigma, by separable Gaussian
//! derivative kernels (twin: [`crate::cpu::hessian_volume`]; not finite differences), written to
//! six separate f32 buffers `[xx, yy, zz, xy, xz, yz]` (each must fit one binding).
//!
//! Passes are shared: one z pass reads the input once for orders 0, 1, 2; one y pass per z result
//! computes every y order that result needs (3, 2 and 1 orders, each reading its input once);
//! then one x pass per component (10 dispatches, 15 convolutions; the x passes cannot share an
//! input). The sigma^2 normalisation is folded into the x taps. Intermediate results are parked
//! in output buffers not yet written, so the working set is one temporary plus the six outputs.

use crate::compute::gaussian::{
    AxisPass, AxisTapSet, Gaussian, PassKernels, Region, cut_axis, whole,
};
use crate::gpu::checks::RecordError;
use crate::gpu::kernel::{Recorder, SlabGrid};
use crate::gpu::{GpuContext, shaders};
use std::ops::Range;

/// The 9 kernels (3 axes x orders 0, 1, 2) of one sigma on one spacing, uploaded once and
/// reused for every slab.
#[derive(Debug)]
pub struct HessianKernels {
    /// `taps[axis]`, orders 0, 1, 2; the x (axis 0) taps carry the sigma^2 normalisation.
    taps: [AxisTapSet; 3],
    sigma_mm: f64,
}

impl HessianKernels {
    /// Kernels for `sigma_mm` on a grid of `spacing_mm`; `normalised` multiplies the result by
    /// sigma^2 (Lindeberg's gamma = 1, as the features use).
    pub fn new(ctx: &GpuContext, sigma_mm: f64, spacing_mm: [f64; 3], normalised: bool) -> Self {
        let norm = if normalised { sigma_mm * sigma_mm } else { 1.0 };
        Self {
            taps: std::array::from_fn(|axis| {
                let scale = if axis == 0 { norm } else { 1.0 };
                AxisTapSet::new(ctx, sigma_mm, spacing_mm[axis], scale)
            }),
            sigma_mm,
        }
    }

    pub fn sigma_mm(&self) -> f64 {
        self.sigma_mm
    }

    /// Radius of the z kernels: the halo (slices) a slab needs on each side.
    pub fn halo_slices(&self) -> u32 {
        self.taps[2].radius()
    }
}

/// Slices of halo the Hessian at `sigma_mm` needs on each side of a slab with z spacing
/// `spacing_z_mm` (the z kernel radius, 3 sigma + 1 voxel).
pub fn halo_slices(sigma_mm: f64, spacing_z_mm: f64) -> u32 {
    crate::compute::gaussian::halo_slices(sigma_mm, spacing_z_mm)
}

/// The largest halo over several scales (multi-scale features run every sigma on one slab).
pub fn halo_slices_multiscale(sigmas_mm: &[f64], spacing_z_mm: f64) -> u32 {
    sigmas_mm
        .iter()
        .map(|&s| halo_slices(s, spacing_z_mm))
        .max()
        .unwrap_or(0)
}

/// Bytes per slab voxel of the Hessian's buffers besides its input: six components and one
/// temporary, f32 each.
pub const BYTES_PER_VOXEL: u64 = 7 * 4;

/// The Hessian passes (the Gaussian convolution pipelines, driven 10 times).
pub struct Hessian {
    gaussian: Gaussian,
}

impl Hessian {
    pub fn new(ctx: &GpuContext) -> Result<Self, shaders::ShaderSourceError> {
        Ok(Self {
            gaussian: Gaussian::new(ctx)?,
        })
    }

    /// Records the six Hessian components of `input` (one f32 per voxel of `grid`) into
    /// `out = [xx, yy, zz, xy, xz, yz]`, using `tmp`; eight different buffers of `grid.len()`
    /// f32 each (`input` is only read).
    pub fn record(
        &self,
        rec: &mut Recorder<'_>,
        grid: &SlabGrid,
        kernels: &HessianKernels,
        input: &wgpu::Buffer,
        tmp: &wgpu::Buffer,
        out: [&wgpu::Buffer; 6],
    ) -> Result<(), RecordError> {
        let core = whole(grid);
        (0..PASSES).try_for_each(|pass| {
            self.record_pass(
                rec,
                &HessianPass {
                    grid,
                    kernels,
                    input,
                    tmp,
                    out,
                    pass,
                    core: &core,
                    cut: pass_lines(grid, &core, pass),
                },
            )
        })
    }

    /// Records one pass of [`Self::record`] (see [`HessianPass`]).
    pub fn record_pass(
        &self,
        rec: &mut Recorder<'_>,
        p: &HessianPass<'_>,
    ) -> Result<(), RecordError> {
        let (grid, kernels, input, tmp, out, pass) =
            (p.grid, p.kernels, p.input, p.tmp, p.out, p.pass);
        if pass >= PASSES {
            return Err(RecordError::Invalid("Hessian: no such pass"));
        }
        let mut region = pass_region(grid, p.core, pass);
        let across = cut_axis(PASS_AXIS_OUTPUTS[pass].0);
        if p.cut.start < region[across].start || p.cut.end > region[across].end {
            return Err(RecordError::Invalid(
                "Hessian: a pass's part must lie within its lines",
            ));
        }
        region[across] = p.cut.clone();
        let region = &region;
        let all: [&wgpu::Buffer; 8] = [input, tmp, out[0], out[1], out[2], out[3], out[4], out[5]];
        for (n, a) in all.iter().enumerate() {
            if all[n + 1..].contains(a) {
                return Err(RecordError::Invalid(
                    "Hessian: input, tmp and the six outputs must be different buffers",
                ));
            }
        }
        let [x, y, z] = &kernels.taps;
        let [xx, yy, zz, xy, xz, yz] = out;
        let g = &self.gaussian;
        // xx = x2 y0 z0, yy = x0 y2 z0, zz = x0 y0 z2, xy = x1 y1 z0, xz = x1 y0 z1,
        // yz = x0 y1 z1. Every pass reads a buffer no output of the same pass aliases, and
        // overwrites only results already consumed.
        let mut multi = |axis: usize, src: &wgpu::Buffer, dst: &[&wgpu::Buffer]| {
            let kernels = PassKernels::Set([x, y, z][axis]);
            let region = Some(region);
            g.record_pass(
                rec,
                &AxisPass {
                    grid,
                    axis,
                    region,
                    kernels,
                    src,
                    dst,
                },
            )
        };
        // z orders 0, 1, 2 of the input, parked in outputs written last.
        let (z0, z1, z2) = (yz, xz, xy);
        // y orders 0, 1, 2 of z0 (pass 3), then y orders 0, 1 of z1 (pass 7).
        let (z0y0, z0y1, z0y2) = (yy, tmp, xy);
        let (z1y0, z1y1) = (yz, tmp);
        // The x passes apply one order each: (order, src, dst).
        let (order, src, dst) = match pass {
            0 => return multi(2, input, &[z0, z1, z2]),
            // zz = x0 y0 z2.
            1 => return multi(1, z2, &[tmp]),
            2 => return multi(0, tmp, &[zz]),
            // xx, xy, yy from z0 (z2, in xy, is consumed).
            3 => return multi(1, z0, &[z0y0, z0y1, z0y2]),
            4 => (2, z0y0, xx),
            5 => (0, z0y2, yy),
            6 => (1, z0y1, xy),
            // xz, yz from z1 (z0, in yz, is consumed).
            7 => return multi(1, z1, &[z1y0, z1y1]),
            8 => (1, z1y0, xz),
            9 => (0, z1y1, yz),
            _ => return Err(RecordError::Invalid("Hessian: no such pass")),
        };
        let kernels = PassKernels::One(x.order(order));
        g.record_pass(
            rec,
            &AxisPass {
                grid,
                axis: 0,
                region: Some(region),
                kernels,
                src,
                dst: &[dst],
            },
        )
    }
}

/// One pass (of [`PASSES`], in order) of [`Hessian::record`], computing only what the
/// components need in `core` (a brick's core; its halo is read, not delivered:
/// [`pass_region`]), for the lines `cut` of its cut axis (within [`pass_lines`]): the passes may
/// go in separate submissions, and a pass in parts (the feature job's paced steps), since every
/// intermediate lives in `tmp` and `out` and each output depends on its own line only. A pass's
/// parts must all be recorded before the next pass. Inside `core` the components have the bits
/// of the whole slab's passes.
#[derive(Clone, Debug)]
pub struct HessianPass<'a> {
    pub grid: &'a SlabGrid,
    pub kernels: &'a HessianKernels,
    /// The input, one f32 per voxel of `grid` (only read).
    pub input: &'a wgpu::Buffer,
    pub tmp: &'a wgpu::Buffer,
    /// `[xx, yy, zz, xy, xz, yz]`; with `input` and `tmp` eight different buffers of
    /// `grid.len()` f32.
    pub out: [&'a wgpu::Buffer; 6],
    pub pass: usize,
    pub core: &'a Region,
    pub cut: Range<u32>,
}

/// Passes of [`Hessian::record`] (dispatches: 15 convolutions, the z and y ones shared).
pub const PASSES: usize = 10;

/// The axis each pass convolves along, and how many kernels (outputs) it applies.
const PASS_AXIS_OUTPUTS: [(usize, usize); PASSES] = [
    (2, 3),
    (1, 1),
    (0, 1),
    (1, 3),
    (0, 1),
    (0, 1),
    (0, 1),
    (1, 2),
    (0, 1),
    (0, 1),
];

/// The outputs pass `pass` computes for the components to be right in `core`: the z pass
/// (first) over the core slices only, the y passes over the core's rows of those, the x passes
/// over the core (the later passes read the earlier ones' outputs across the halo of their own
/// axis only). A whole-slab `core` gives the whole slab.
pub fn pass_region(grid: &SlabGrid, core: &Region, pass: usize) -> Region {
    let axis = PASS_AXIS_OUTPUTS.get(pass).map_or(0, |p| p.0);
    let mut r = whole(grid);
    for a in axis..3 {
        r[a] = core[a].start.min(grid.dims[a])..core[a].end.min(grid.dims[a]);
    }
    r
}

/// Lines of pass `pass` that [`Hessian::record_pass`] may be cut into: slices (z) for the x
/// and y passes, rows (y) for the z pass, within [`pass_region`].
pub fn pass_lines(grid: &SlabGrid, core: &Region, pass: usize) -> Range<u32> {
    let axis = PASS_AXIS_OUTPUTS.get(pass).map_or(0, |p| p.0);
    pass_region(grid, core, pass)[cut_axis(axis)].clone()
}

/// Output voxels of pass `pass` for `core` ([`pass_region`]).
pub fn pass_voxels(grid: &SlabGrid, core: &Region, pass: usize) -> u64 {
    pass_region(grid, core, pass)
        .iter()
        .map(|r| u64::from(r.end - r.start))
        .product()
}

/// Storage loads and stores per voxel of pass `pass` with `kernels` (its relative cost, for
/// pacing steps).
pub fn pass_accesses_per_voxel(kernels: &HessianKernels, pass: usize) -> f64 {
    match PASS_AXIS_OUTPUTS.get(pass) {
        Some(&(axis, outputs)) if outputs > 1 => kernels.taps[axis].accesses_per_voxel(outputs),
        Some(&(axis, _)) => kernels.taps[axis].order(0).accesses_per_voxel(),
        None => 0.0,
    }
}
