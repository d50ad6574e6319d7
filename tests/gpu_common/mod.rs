//! Helpers shared by the GPU feature-kernel tests (tests/gpu/hessian.rs, tests/gpu/resample.rs):
//! small phantoms, upload / record / read back, and error measures against the CPU twins.
#![allow(dead_code)]

use shapecast::cpu::Grid;
use shapecast::gpu::GpuContext;
use shapecast::gpu::kernel::{SlabGrid, f32_buffer, f32_buffer_init};
use shapecast::gpu::readback::read_f32_blocking;
use shapecast::phantom::{Phantom, Shape};

/// The anisotropic test spacing.
pub const SPACING: [f64; 3] = [0.6, 0.8, 1.1];

/// 13 x 17 x 11 voxels (not multiples of 8) at 0.6 x 0.8 x 1.1 mm, background 40 HU: a bright
/// sphere (r 2 mm, 140 HU), a bright tilted cylinder (r 1.2 mm, 140 HU) and a dark tilted
/// capsule (r 1 mm, -400 HU, an airway-like lumen), so that vesselness, airwayness and
/// blobness all occur.
pub fn phantom() -> (Grid, Vec<f32>) {
    let (grid, values) = phantom_at(SPACING);
    assert_eq!(grid.dims, [13, 17, 11]);
    (grid, values)
}

/// The same objects at another spacing (e.g. finer along z for a slab with room for halos).
pub fn phantom_at(spacing_mm: [f64; 3]) -> (Grid, Vec<f32>) {
    let p = Phantom::new(
        "gpu-test",
        [0.0; 3],
        [12.0 * SPACING[0], 16.0 * SPACING[1], 10.0 * SPACING[2]],
        40.0,
    )
    .with(
        Shape::Sphere {
            centre_mm: [3.6, 3.5, 5.0],
            radius_mm: 2.0,
        },
        140.0,
    )
    .with(
        Shape::Cylinder {
            a_mm: [0.0, 10.0, 0.0],
            b_mm: [7.2, 11.0, 11.0],
            radius_mm: 1.2,
        },
        140.0,
    )
    .with(
        Shape::Capsule {
            a_mm: [0.5, 6.8, 9.0],
            b_mm: [6.7, 6.8, 2.0],
            radius_mm: 1.0,
        },
        -400.0,
    );
    let v = p.render(spacing_mm);
    (Grid::of(&v), v.to_f32())
}

pub fn slab_grid(grid: &Grid) -> SlabGrid {
    SlabGrid::new(
        grid.dims.map(|d| d as u32),
        grid.spacing_mm.map(|s| s as f32),
    )
}

pub fn upload(ctx: &GpuContext, data: &[f32]) -> wgpu::Buffer {
    f32_buffer_init(&ctx.device, "test input", data)
}

pub fn buffer(ctx: &GpuContext, len: usize) -> wgpu::Buffer {
    f32_buffer(&ctx.device, "test buffer", len as u64)
}

pub fn encoder(ctx: &GpuContext) -> wgpu::CommandEncoder {
    ctx.device
        .create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("test"),
        })
}

pub fn submit(ctx: &GpuContext, encoder: wgpu::CommandEncoder) {
    ctx.queue.submit([encoder.finish()]);
}

pub fn read(ctx: &GpuContext, buffer: &wgpu::Buffer, len: usize) -> Vec<f32> {
    read_f32_blocking(ctx, buffer, len).expect("readback")
}

pub fn max_abs(v: &[f32]) -> f32 {
    v.iter().fold(0.0f32, |m, x| m.max(x.abs()))
}

pub fn range(v: &[f32]) -> f32 {
    let lo = v.iter().copied().fold(f32::INFINITY, f32::min);
    let hi = v.iter().copied().fold(f32::NEG_INFINITY, f32::max);
    hi - lo
}

/// Largest |a - b|, with NaN counted as infinitely wrong.
pub fn max_err(a: &[f32], b: &[f32]) -> f32 {
    assert_eq!(a.len(), b.len());
    a.iter().zip(b).fold(0.0f32, |m, (x, y)| {
        let d = (x - y).abs();
        if d.is_nan() { f32::INFINITY } else { m.max(d) }
    })
}

/// The slices `z0 .. z0 + nz` of a volume on `grid`.
pub fn slices(grid: &Grid, v: &[f32], z0: usize, nz: usize) -> Vec<f32> {
    let plane = grid.dims[0] * grid.dims[1];
    v[z0 * plane..(z0 + nz) * plane].to_vec()
}
