//! Refinement by integer factors and subsampling (shaders/resample.wgsl) on the test adapter
//! against the CPU twins `refine_linear` and `subsample`: whole volume, brick by brick (blocks
//! in y and z with their whole-grid origins), several components at once; input voxels survive
//! the round trip bit for bit.

use crate::gpu_common;

use gpu_common::*;
use shapecast::compute::resample::{Resample, ResampleGeometry, Volumes};
use shapecast::cpu::Grid;
use shapecast::cpu::resample::{refine_linear, refined_grid, subsample};
use shapecast::gpu::context::test_context;
use shapecast::gpu::kernel::Recorder;

const FACTORS: [usize; 3] = [1, 2, 3];

/// The phantom at 0.6 x 1.6 x 2.5 mm (two thick axes) and its refined grid.
fn thick() -> (Grid, Vec<f32>, Grid) {
    let (grid, values) = phantom_at([0.6, 1.6, 2.5]);
    let fine = refined_grid(&grid, FACTORS);
    assert!(fine.dims[1] > grid.dims[1] && fine.dims[2] > grid.dims[2]);
    assert_eq!(fine.dims[0], grid.dims[0]);
    (grid, values, fine)
}

fn dims32(g: &Grid) -> [u32; 3] {
    g.dims.map(|d| d as u32)
}

fn f32s() -> [u32; 3] {
    FACTORS.map(|f| f as u32)
}

#[test]
fn resample_whole_volume_matches_cpu() {
    let Some(ctx) = test_context() else { return };
    let (grid, values, fine) = thick();
    let rs = Resample::new(&ctx).expect("shader");
    let (_, cpu_up) = refine_linear(&grid, &values, FACTORS);
    let cpu_down = subsample(&fine, &cpu_up, FACTORS, &grid);
    assert_eq!(
        cpu_down, values,
        "the CPU round trip keeps the input voxels"
    );
    let src = upload(&ctx, &values);
    let up = buffer(&ctx, fine.len());
    let down = buffer(&ctx, grid.len());
    let mut enc = encoder(&ctx);
    let g_up = ResampleGeometry::refine(f32s(), dims32(&grid));
    let g_down = ResampleGeometry::subsample(f32s(), dims32(&fine));
    rs.record(
        &mut Recorder::new(&ctx, &mut enc),
        Volumes::new(&src, dims32(&grid)),
        Volumes::new(&up, dims32(&fine)),
        1,
        &g_up,
    )
    .expect("record");
    rs.record(
        &mut Recorder::new(&ctx, &mut enc),
        Volumes::new(&up, dims32(&fine)),
        Volumes::new(&down, dims32(&grid)),
        1,
        &g_down,
    )
    .expect("record");
    submit(&ctx, enc);
    let gpu_up = read(&ctx, &up, fine.len());
    let gpu_down = read(&ctx, &down, grid.len());
    let r = range(&values);
    let e_up = max_err(&gpu_up, &cpu_up) / r;
    eprintln!(
        "refine {:?} -> {:?} voxels: max error {e_up:.2e} of the range",
        grid.dims, fine.dims
    );
    assert!(e_up < 1e-6, "up {e_up:e}");
    // Input voxels are grid points of the refined grid: kept exactly, there and back.
    for k in 0..grid.dims[2] {
        for j in 0..grid.dims[1] {
            for i in 0..grid.dims[0] {
                let v = values[grid.index(i, j, k)];
                assert_eq!(gpu_up[fine.index(i, 2 * j, 3 * k)], v);
            }
        }
    }
    assert_eq!(gpu_down, values, "subsampling is exact");
}

/// The refined grid computed block by block (tiles in y and z of the refined grid, each from
/// the input voxels its taps read), three components at once, equals the CPU's whole-volume
/// result; a block whose source misses one slice differs.
#[test]
fn resample_by_blocks_matches_whole_volume() {
    let Some(ctx) = test_context() else { return };
    let (grid, values, fine) = thick();
    let rs = Resample::new(&ctx).expect("shader");
    let comps: [Vec<f32>; 3] = [
        values.clone(),
        values.iter().map(|v| -v).collect(),
        values.iter().map(|v| v.abs().sqrt()).collect(),
    ];
    let cpu: Vec<Vec<f32>> = comps
        .iter()
        .map(|c| refine_linear(&grid, c, FACTORS).1)
        .collect();
    let [nx, ny, nz] = fine.dims;
    let ys = [0, ny / 2, ny];
    let zs = [0, nz / 3, 2 * nz / 3 + 1, nz];
    let mut worst = 0.0f32;
    for wy in ys.windows(2) {
        for wz in zs.windows(2) {
            let (y0, y1, z0, z1) = (wy[0], wy[1], wz[0], wz[1]);
            // Input voxels the block reads: floor(c / f) to the next one.
            let (sy0, sy1) = (y0 / 2, ((y1 - 1).div_ceil(2) + 1).min(grid.dims[1]));
            let (sz0, sz1) = (z0 / 3, ((z1 - 1).div_ceil(3) + 1).min(grid.dims[2]));
            let mut src = Vec::new();
            for c in &comps {
                for k in sz0..sz1 {
                    for j in sy0..sy1 {
                        let at = grid.index(0, j, k);
                        src.extend_from_slice(&c[at..at + nx]);
                    }
                }
            }
            let src_buf = upload(&ctx, &src);
            let n_dst = nx * (y1 - y0) * (z1 - z0);
            let dst = buffer(&ctx, 3 * n_dst);
            let geom = ResampleGeometry::refine(f32s(), dims32(&grid))
                .blocks([0, sy0 as u32, sz0 as u32], [0, y0 as u32, z0 as u32]);
            let src_dims = [nx as u32, (sy1 - sy0) as u32, (sz1 - sz0) as u32];
            let dst_dims = [nx as u32, (y1 - y0) as u32, (z1 - z0) as u32];
            let mut enc = encoder(&ctx);
            rs.record(
                &mut Recorder::new(&ctx, &mut enc),
                Volumes::new(&src_buf, src_dims),
                Volumes::new(&dst, dst_dims),
                3,
                &geom,
            )
            .expect("record");
            submit(&ctx, enc);
            let gpu = read(&ctx, &dst, 3 * n_dst);
            for c in 0..3 {
                let mut e = 0.0f32;
                for k in z0..z1 {
                    for j in y0..y1 {
                        for i in 0..nx {
                            let got = gpu[c * n_dst + i + nx * ((j - y0) + (y1 - y0) * (k - z0))];
                            e = e.max((got - cpu[c][fine.index(i, j, k)]).abs());
                        }
                    }
                }
                let e = e / range(&comps[c]);
                worst = worst.max(e);
                assert!(
                    e < 1e-6,
                    "block y {y0}..{y1} z {z0}..{z1} component {c}: {e:e}"
                );
            }
        }
    }
    eprintln!("refine by blocks: worst error {worst:.2e} of each component's range");
    // A source one slice short at the front (its origin moved with it) reads the wrong slice.
    let (z0, z1) = (zs[1], zs[2]);
    let (sz0, sz1) = (z0 / 3 + 1, ((z1 - 1).div_ceil(3) + 1).min(grid.dims[2]));
    let plane = grid.dims[0] * grid.dims[1];
    let src_buf = upload(&ctx, &values[sz0 * plane..sz1 * plane]);
    let n_dst = nx * ny * (z1 - z0);
    let dst = buffer(&ctx, n_dst);
    let geom = ResampleGeometry::refine(f32s(), dims32(&grid))
        .blocks([0, 0, sz0 as u32], [0, 0, z0 as u32]);
    let src_dims = [nx as u32, grid.dims[1] as u32, (sz1 - sz0) as u32];
    let dst_dims = [nx as u32, ny as u32, (z1 - z0) as u32];
    let mut enc = encoder(&ctx);
    rs.record(
        &mut Recorder::new(&ctx, &mut enc),
        Volumes::new(&src_buf, src_dims),
        Volumes::new(&dst, dst_dims),
        1,
        &geom,
    )
    .expect("record");
    submit(&ctx, enc);
    let short = read(&ctx, &dst, nx * ny);
    let want = &cpu[0][z0 * nx * ny..(z0 + 1) * nx * ny];
    assert!(
        max_err(&short, want) > 1e-2 * range(&values),
        "a slice less did not matter"
    );
}
