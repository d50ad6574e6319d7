//! Separable Gaussian and Gaussian-derivative passes in mm (shaders/gaussian.wgsl): one 1-D
//! correlation along one axis of a slab per dispatch, replicated borders, taps from the CPU
//! twin's own [`crate::cpu::derivative_kernel`] (same taps, including the tail mass on the end
//! taps), so the GPU and `crate::cpu::gaussian` compute the same sums (f32 against f64).
//!
//! Taps are uploaded once per (sigma, spacing, order) as an [`AxisTaps`] and reused for every
//! slab; `record_*` methods only record into the caller's encoder (no submit).

use crate::cpu::gaussian::{GaussianOrder, derivative_kernel, kernel_radius_vox};
use crate::gpu::checks::{self, RecordError};
use crate::gpu::kernel::{SlabGrid, WORKGROUP};
use crate::gpu::{GpuContext, shaders};

/// Mirrors `Params` in gaussian.wgsl (keep in sync).
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
struct Params {
    dims: [u32; 3],
    axis: u32,
    radius: u32,
    tap_sum: f32,
    _pad: [u32; 2],
}
const _: () = assert!(std::mem::size_of::<Params>() == 32);

/// One 1-D kernel on the GPU: `2 radius + 1` f32 taps for offsets `-radius..=radius`.
#[derive(Debug)]
pub struct AxisTaps {
    buffer: wgpu::Buffer,
    radius: u32,
    sum: f32,
}

impl AxisTaps {
    /// The CPU twin's kernel of `order` for `sigma_mm` on an axis of `spacing_mm` (per mm),
    /// multiplied by `scale` (e.g. sigma^2 for the gamma-normalised Hessian, folded into one
    /// pass; 1 otherwise).
    pub fn new(
        ctx: &GpuContext,
        sigma_mm: f64,
        spacing_mm: f64,
        order: GaussianOrder,
        scale: f64,
    ) -> Self {
        let w: Vec<f64> = derivative_kernel(sigma_mm, spacing_mm, order)
            .into_iter()
            .map(|v| v * scale)
            .collect();
        Self::from_weights(ctx, &w)
    }

    /// Any odd-length centred kernel (correlation weights for offsets `-r..=r`).
    pub fn from_weights(ctx: &GpuContext, weights: &[f64]) -> Self {
        let taps: Vec<f32> = weights.iter().map(|&w| w as f32).collect();
        let sum = weights.iter().sum::<f64>() as f32;
        Self {
            buffer: crate::gpu::kernel::f32_buffer_init(&ctx.device, "gaussian taps", &taps),
            radius: (weights.len() / 2) as u32,
            sum,
        }
    }

    /// Kernel radius in voxels (the halo one pass along this axis needs).
    pub fn radius(&self) -> u32 {
        self.radius
    }
}

/// Three 1-D kernels (x, y, z) of one separable filter: smoothing or a derivative with per-axis
/// orders, for `sigma_mm` on a grid of `spacing_mm` (anisotropic: per-axis sigma in voxels).
#[derive(Debug)]
pub struct SeparableKernel {
    pub axes: [AxisTaps; 3],
}

impl SeparableKernel {
    /// Derivative of `orders` (x, y, z) at `sigma_mm`, per mm.
    pub fn new(
        ctx: &GpuContext,
        sigma_mm: f64,
        spacing_mm: [f64; 3],
        orders: [GaussianOrder; 3],
    ) -> Self {
        Self {
            axes: std::array::from_fn(|a| {
                AxisTaps::new(ctx, sigma_mm, spacing_mm[a], orders[a], 1.0)
            }),
        }
    }

    /// Plain Gaussian smoothing at `sigma_mm` (as [`crate::cpu::gaussian_smooth`]).
    pub fn smooth(ctx: &GpuContext, sigma_mm: f64, spacing_mm: [f64; 3]) -> Self {
        Self::new(ctx, sigma_mm, spacing_mm, [GaussianOrder::Smooth; 3])
    }
}

/// Slices of halo a Gaussian (or Gaussian-derivative) pass of `sigma_mm` along z needs on each
/// side of a slab, for z spacing `spacing_z_mm`: the kernel radius (3 sigma + 1 voxel; the
/// central difference's 1 voxel when `sigma_mm <= 0`).
pub fn halo_slices(sigma_mm: f64, spacing_z_mm: f64) -> u32 {
    let sigma_vox = sigma_mm / spacing_z_mm;
    if sigma_vox > 0.0 {
        u32::try_from(kernel_radius_vox(sigma_vox)).unwrap_or(u32::MAX)
    } else {
        1
    }
}

/// Bytes per slab voxel of the working buffers of a separable filter besides its input: the
/// output and one temporary, f32 each.
pub const SEPARABLE_BYTES_PER_VOXEL: u64 = 8;

/// The convolution pipeline.
pub struct Gaussian {
    pipeline: wgpu::ComputePipeline,
}

impl Gaussian {
    pub fn new(ctx: &GpuContext) -> Result<Self, shaders::ShaderSourceError> {
        let module = shaders::create_module(&ctx.device, "gaussian.wgsl")?;
        Ok(Self {
            pipeline: checks::pipeline(ctx, &module, "convolve"),
        })
    }

    /// Records `dst = src (*) taps` along `axis` (0, 1, 2) of the slab `grid`; `src` and `dst`
    /// hold `grid.len()` f32 each and must be different buffers.
    #[allow(clippy::too_many_arguments)]
    pub fn record_axis(
        &self,
        ctx: &GpuContext,
        encoder: &mut wgpu::CommandEncoder,
        grid: &SlabGrid,
        axis: usize,
        taps: &AxisTaps,
        src: &wgpu::Buffer,
        dst: &wgpu::Buffer,
    ) -> Result<(), RecordError> {
        if axis > 2 {
            return Err(RecordError::Invalid("axis must be 0, 1 or 2"));
        }
        if src == dst {
            return Err(RecordError::Invalid(
                "a convolution cannot run in place (src == dst)",
            ));
        }
        if grid.is_empty() {
            return Ok(());
        }
        let bytes = checks::f32_bytes(grid.len(), 1);
        checks::buffer(ctx, "gaussian src", src, bytes)?;
        checks::buffer(ctx, "gaussian dst", dst, bytes)?;
        let groups = checks::workgroups(ctx, "gaussian", grid.workgroups(WORKGROUP))?;
        let params = Params {
            dims: grid.dims,
            axis: axis as u32,
            radius: taps.radius,
            tap_sum: taps.sum,
            _pad: [0; 2],
        };
        let params = crate::gpu::kernel::uniform_buffer(&ctx.device, "gaussian params", &params);
        let bind_group = ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("gaussian"),
            layout: &self.pipeline.get_bind_group_layout(0),
            entries: &[
                checks::entry(0, &params),
                checks::entry(1, src),
                checks::entry(2, &taps.buffer),
                checks::entry(3, dst),
            ],
        });
        checks::dispatch(encoder, "gaussian", &self.pipeline, &bind_group, groups);
        Ok(())
    }

    /// Records the separable filter `kernel` (x, then y, then z, as the CPU's `separable`):
    /// `src -> dst -> tmp -> dst`. Three different buffers of `grid.len()` f32.
    #[allow(clippy::too_many_arguments)]
    pub fn record_separable(
        &self,
        ctx: &GpuContext,
        encoder: &mut wgpu::CommandEncoder,
        grid: &SlabGrid,
        kernel: &SeparableKernel,
        src: &wgpu::Buffer,
        tmp: &wgpu::Buffer,
        dst: &wgpu::Buffer,
    ) -> Result<(), RecordError> {
        if src == tmp || src == dst || tmp == dst {
            return Err(RecordError::Invalid(
                "separable filter: src, tmp and dst must be different buffers",
            ));
        }
        self.record_axis(ctx, encoder, grid, 0, &kernel.axes[0], src, dst)?;
        self.record_axis(ctx, encoder, grid, 1, &kernel.axes[1], dst, tmp)?;
        self.record_axis(ctx, encoder, grid, 2, &kernel.axes[2], tmp, dst)
    }
}
