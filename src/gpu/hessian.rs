//! The six sigma^2-normalised Hessian components of a slab at one sigma, by separable Gaussian
//! derivative kernels (twin: [`crate::cpu::hessian_volume`]; not finite differences), written to
//! six separate f32 buffers `[xx, yy, zz, xy, xz, yz]` (each must fit one binding).
//!
//! Passes are shared: the z pass of orders 0, 1, 2 runs once on the input, then one y pass and
//! one x pass per component (15 passes, the minimum for six separable components), and the
//! sigma^2 normalisation is folded into the x taps. The z results are parked in output buffers
//! not yet written, so the working set is one temporary plus the six outputs.

use crate::cpu::gaussian::GaussianOrder;
use crate::gpu::checks::RecordError;
use crate::gpu::gaussian::{AxisTaps, Gaussian};
use crate::gpu::kernel::SlabGrid;
use crate::gpu::{GpuContext, shaders};

/// The 9 kernels (3 axes x orders 0, 1, 2) of one sigma on one spacing, uploaded once and
/// reused for every slab.
#[derive(Debug)]
pub struct HessianKernels {
    /// `taps[axis][order]`; the x (axis 0) taps carry the sigma^2 normalisation.
    taps: [[AxisTaps; 3]; 3],
    sigma_mm: f64,
}

impl HessianKernels {
    /// Kernels for `sigma_mm` on a grid of `spacing_mm`; `normalised` multiplies the result by
    /// sigma^2 (Lindeberg's gamma = 1, as the features use).
    pub fn new(ctx: &GpuContext, sigma_mm: f64, spacing_mm: [f64; 3], normalised: bool) -> Self {
        const ORDERS: [GaussianOrder; 3] = [
            GaussianOrder::Smooth,
            GaussianOrder::First,
            GaussianOrder::Second,
        ];
        let norm = if normalised { sigma_mm * sigma_mm } else { 1.0 };
        Self {
            taps: std::array::from_fn(|axis| {
                let scale = if axis == 0 { norm } else { 1.0 };
                ORDERS.map(|o| AxisTaps::new(ctx, sigma_mm, spacing_mm[axis], o, scale))
            }),
            sigma_mm,
        }
    }

    pub fn sigma_mm(&self) -> f64 {
        self.sigma_mm
    }

    /// Radius of the z kernels: the halo (slices) a slab needs on each side.
    pub fn halo_slices(&self) -> u32 {
        self.taps[2].iter().map(AxisTaps::radius).max().unwrap_or(0)
    }
}

/// Slices of halo the Hessian at `sigma_mm` needs on each side of a slab with z spacing
/// `spacing_z_mm` (the z kernel radius, 3 sigma + 1 voxel).
pub fn halo_slices(sigma_mm: f64, spacing_z_mm: f64) -> u32 {
    crate::gpu::gaussian::halo_slices(sigma_mm, spacing_z_mm)
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

/// The Hessian passes (the Gaussian convolution pipeline, driven 15 times).
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
    #[allow(clippy::too_many_arguments)]
    pub fn record(
        &self,
        ctx: &GpuContext,
        encoder: &mut wgpu::CommandEncoder,
        grid: &SlabGrid,
        kernels: &HessianKernels,
        input: &wgpu::Buffer,
        tmp: &wgpu::Buffer,
        out: [&wgpu::Buffer; 6],
    ) -> Result<(), RecordError> {
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
        let mut pass = |axis: usize, taps: &AxisTaps, src: &wgpu::Buffer, dst: &wgpu::Buffer| {
            g.record_axis(ctx, encoder, grid, axis, taps, src, dst)
        };
        // z passes of orders 0, 1, 2, parked in outputs written last.
        let (z0, z1, z2) = (yz, xz, xy);
        pass(2, &z[0], input, z0)?;
        pass(2, &z[1], input, z1)?;
        pass(2, &z[2], input, z2)?;
        // Each component: y pass into tmp, x pass into its output. The order frees the parked
        // z results before their buffers are overwritten.
        pass(1, &y[0], z0, tmp)?;
        pass(0, &x[2], tmp, xx)?;
        pass(1, &y[2], z0, tmp)?;
        pass(0, &x[0], tmp, yy)?;
        pass(1, &y[0], z2, tmp)?;
        pass(0, &x[0], tmp, zz)?;
        pass(1, &y[1], z0, tmp)?;
        pass(0, &x[1], tmp, xy)?; // z2 (in xy) no longer needed
        pass(1, &y[1], z1, tmp)?;
        pass(0, &x[0], tmp, yz)?; // z0 (in yz) no longer needed
        pass(1, &y[0], z1, tmp)?;
        pass(0, &x[1], tmp, xz) // z1 (in xz) read by the y pass just before
    }
}
