//! The general structure tensor (paper eq. 5; twin: `crate::cpu::structure_tensor`): the six
//! components of g g^T from three gradient component buffers (the gradient kernel belongs to
//! the RST module), each smoothed with a Gaussian of the neighbourhood scale rho (mm), into six
//! buffers `[xx, yy, zz, xy, xz, yz]`. Its eigenvalues and features then come from
//! [`crate::compute::eigen_features`] with `TensorOutput::structure_tensor(map)` (the map of `-l`)
//! or `TensorOutput::Eigen`.

use crate::compute::gaussian::{Gaussian, SeparableKernel};
use crate::gpu::checks::{self, RecordError};
use crate::gpu::kernel::{Recorder, SlabGrid, WORKGROUP};
use crate::gpu::{GpuContext, shaders};

/// Mirrors `Params` in structure_tensor.wgsl (keep in sync).
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
struct Params {
    dims: [u32; 3],
    a: u32,
    b: u32,
    _pad: [u32; 3],
}
const _: () = assert!(std::mem::size_of::<Params>() == 32);

/// The axis pairs of the six components, in the order `[xx, yy, zz, xy, xz, yz]`.
const PAIRS: [(u32, u32); 6] = [(0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2)];

/// Slices of halo the smoothing with `rho_mm` needs on each side of a slab (z spacing
/// `spacing_z_mm`), on top of the halo of the gradient it reads (sigma_g's kernel + 1 slice for
/// the central difference, the gradient kernel's business).
pub fn halo_slices(rho_mm: f64, spacing_z_mm: f64) -> u32 {
    crate::compute::gaussian::halo_slices(rho_mm, spacing_z_mm)
}

/// Bytes per slab voxel of the structure tensor's buffers besides the gradient (3 x f32): six
/// components and two temporaries, f32 each.
pub const BYTES_PER_VOXEL: u64 = 8 * 4;

/// The outer-product pipeline and the Gaussian passes.
pub struct StructureTensor {
    product: wgpu::ComputePipeline,
    gaussian: Gaussian,
}

impl StructureTensor {
    pub fn new(ctx: &GpuContext) -> Result<Self, shaders::ShaderSourceError> {
        let [product] = checks::pipelines(ctx, "structure_tensor.wgsl", ["outer_product"])?;
        Ok(Self {
            product,
            gaussian: Gaussian::new(ctx)?,
        })
    }

    /// Records the six smoothed components of g g^T into `out`; `gradient` = `[g_x, g_y, g_z]`,
    /// `rho` = `SeparableKernel::smooth(ctx, rho_mm, spacing_mm)`, `tmp` two temporaries.
    /// Eleven different buffers of `grid.len()` f32 each.
    pub fn record(
        &self,
        rec: &mut Recorder<'_>,
        grid: &SlabGrid,
        rho: &SeparableKernel,
        gradient: [&wgpu::Buffer; 3],
        tmp: [&wgpu::Buffer; 2],
        out: [&wgpu::Buffer; 6],
    ) -> Result<(), RecordError> {
        let all: Vec<&wgpu::Buffer> = gradient.iter().chain(&tmp).chain(&out).copied().collect();
        checks::distinct(
            &all,
            "structure tensor: gradient, temporaries and outputs must be different buffers",
        )?;
        if grid.is_empty() {
            return Ok(());
        }
        let bytes = checks::f32_bytes(grid.len(), 1);
        for g in gradient {
            checks::buffer(rec.ctx, "gradient component", g, bytes)?;
        }
        checks::buffer(rec.ctx, "structure tensor temporary", tmp[0], bytes)?;
        let groups = checks::workgroups(rec.ctx, "outer product", grid.workgroups(WORKGROUP))?;
        let layout = self.product.get_bind_group_layout(0);
        for (c, &(a, b)) in PAIRS.iter().enumerate() {
            let params = Params {
                dims: grid.dims,
                a,
                b,
                _pad: [0; 3],
            };
            let params = crate::gpu::kernel::params_buffer(&rec.ctx.device, "gg^T params", &params);
            let bind_group = rec
                .ctx
                .device
                .create_bind_group(&wgpu::BindGroupDescriptor {
                    label: Some("outer product"),
                    layout: &layout,
                    entries: &[
                        checks::entry(0, &params),
                        checks::entry(1, gradient[0]),
                        checks::entry(2, gradient[1]),
                        checks::entry(3, gradient[2]),
                        checks::entry(4, tmp[0]),
                    ],
                });
            checks::dispatch(
                rec.encoder,
                "outer product",
                &self.product,
                &bind_group,
                groups,
            );
            self.gaussian
                .record_separable(rec, grid, rho, tmp[0], tmp[1], out[c])?;
        }
        Ok(())
    }
}
