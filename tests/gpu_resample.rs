//! Linear resampling (shaders/resample.wgsl) on the test adapter against the CPU twin
//! `resample_linear`: thick axes refined as `refined_grid` does and back, whole volume and slab
//! by slab with mm offsets, several components at once.

mod gpu_common;

use gpu_common::*;
use shapecast::cpu::Grid;
use shapecast::cpu::resample::{MAX_FEATURE_SPACING_MM, refined_grid, resample_linear};
use shapecast::gpu::context::test_context;
use shapecast::gpu::resample::{Resample, ResampleGeometry, source_slices};

/// The phantom at 0.6 x 1.6 x 2.5 mm (two thick axes) and its refined grid.
fn thick() -> (Grid, Vec<f32>, Grid) {
    let (grid, values) = phantom_at([0.6, 1.6, 2.5]);
    let fine = refined_grid(&grid, MAX_FEATURE_SPACING_MM);
    assert!(fine.dims[1] > grid.dims[1] && fine.dims[2] > grid.dims[2]);
    assert_eq!(fine.dims[0], grid.dims[0]);
    (grid, values, fine)
}

fn dims32(g: &Grid) -> [u32; 3] {
    g.dims.map(|d| d as u32)
}

#[test]
fn resample_whole_volume_matches_cpu() {
    let Some(ctx) = test_context() else { return };
    let (grid, values, fine) = thick();
    let rs = Resample::new(&ctx).expect("shader");
    let cpu_up = resample_linear(&grid, &values, &fine);
    let cpu_down = resample_linear(&fine, &cpu_up, &grid);
    let src = upload(&ctx, &values);
    let up = buffer(&ctx, fine.len());
    let down = buffer(&ctx, grid.len());
    let mut enc = encoder(&ctx);
    let g_up = ResampleGeometry::same_origin(grid.spacing_mm, fine.spacing_mm);
    let g_down = ResampleGeometry::same_origin(fine.spacing_mm, grid.spacing_mm);
    rs.record(
        &ctx,
        &mut enc,
        &src,
        dims32(&grid),
        &up,
        dims32(&fine),
        1,
        &g_up,
    )
    .expect("record");
    submit(&ctx, enc);
    let gpu_up = read(&ctx, &up, fine.len());
    // Down from the CPU's fine volume, so the two directions are measured separately.
    let fine_cpu = upload(&ctx, &cpu_up);
    let mut enc = encoder(&ctx);
    rs.record(
        &ctx,
        &mut enc,
        &fine_cpu,
        dims32(&fine),
        &down,
        dims32(&grid),
        1,
        &g_down,
    )
    .expect("record");
    submit(&ctx, enc);
    let gpu_down = read(&ctx, &down, grid.len());
    let r = range(&values);
    let e_up = max_err(&gpu_up, &cpu_up) / r;
    let e_down = max_err(&gpu_down, &cpu_down) / r;
    eprintln!(
        "resample {:?} -> {:?} voxels: max error {e_up:.2e} of the range; back: {e_down:.2e}",
        grid.dims, fine.dims
    );
    assert!(e_up < 1e-6 && e_down < 1e-6, "up {e_up:e} down {e_down:e}");
}

/// The refined grid computed slab by slab (three destination slabs along z, each from the
/// source slices `source_slices` names, positioned by mm origins), three components at once,
/// equals the CPU's whole-volume result.
#[test]
fn resample_by_slabs_matches_whole_volume() {
    let Some(ctx) = test_context() else { return };
    let (grid, values, fine) = thick();
    let rs = Resample::new(&ctx).expect("shader");
    // Three components: the volume, its negative and its square root of |v|.
    let comps: [Vec<f32>; 3] = [
        values.clone(),
        values.iter().map(|v| -v).collect(),
        values.iter().map(|v| v.abs().sqrt()).collect(),
    ];
    let cpu: Vec<Vec<f32>> = comps
        .iter()
        .map(|c| resample_linear(&grid, c, &fine))
        .collect();
    let plane_src = grid.dims[0] * grid.dims[1];
    let plane_dst = fine.dims[0] * fine.dims[1];
    let depth = fine.dims[2];
    let bounds = [0, depth / 3, 2 * depth / 3 + 1, depth];
    let mut worst = 0.0f32;
    for w in bounds.windows(2) {
        let (d0, dn) = (w[0], w[1] - w[0]);
        let (s0, sn) = source_slices(
            grid.spacing_mm[2],
            grid.dims[2] as u32,
            fine.spacing_mm[2],
            d0 as u32,
            dn as u32,
        );
        let (s0, sn) = (s0 as usize, sn as usize);
        let src: Vec<f32> = comps
            .iter()
            .flat_map(|c| c[s0 * plane_src..(s0 + sn) * plane_src].to_vec())
            .collect();
        let src_buf = upload(&ctx, &src);
        let dst = buffer(&ctx, 3 * plane_dst * dn);
        let geom =
            ResampleGeometry::z_slabs(grid.spacing_mm, s0 as u32, fine.spacing_mm, d0 as u32);
        let src_dims = [grid.dims[0] as u32, grid.dims[1] as u32, sn as u32];
        let dst_dims = [fine.dims[0] as u32, fine.dims[1] as u32, dn as u32];
        let mut enc = encoder(&ctx);
        rs.record(&ctx, &mut enc, &src_buf, src_dims, &dst, dst_dims, 3, &geom)
            .expect("record");
        submit(&ctx, enc);
        let gpu = read(&ctx, &dst, 3 * plane_dst * dn);
        for c in 0..3 {
            let want = &cpu[c][d0 * plane_dst..(d0 + dn) * plane_dst];
            let got = &gpu[c * plane_dst * dn..(c + 1) * plane_dst * dn];
            let e = max_err(got, want) / range(&comps[c]);
            worst = worst.max(e);
            assert!(e < 1e-6, "slab {d0}+{dn} component {c}: {e:e}");
        }
        eprintln!(
            "destination slices {d0}..{} from source slices {s0}..{}",
            d0 + dn,
            s0 + sn
        );
    }
    eprintln!("resample by slabs: worst error {worst:.2e} of each component's range");
    // The source range is not padded at the front: starting the middle slab's source one slice
    // later (slab origin moved with it) changes its first destination slice.
    let (d0, dn) = (bounds[1], bounds[2] - bounds[1]);
    let (s0, sn) = source_slices(
        grid.spacing_mm[2],
        grid.dims[2] as u32,
        fine.spacing_mm[2],
        d0 as u32,
        dn as u32,
    );
    let (s0, sn) = (s0 as usize + 1, sn as usize - 1);
    let src_buf = upload(&ctx, &values[s0 * plane_src..(s0 + sn) * plane_src]);
    let dst = buffer(&ctx, plane_dst * dn);
    let geom = ResampleGeometry::z_slabs(grid.spacing_mm, s0 as u32, fine.spacing_mm, d0 as u32);
    let src_dims = [grid.dims[0] as u32, grid.dims[1] as u32, sn as u32];
    let dst_dims = [fine.dims[0] as u32, fine.dims[1] as u32, dn as u32];
    let mut enc = encoder(&ctx);
    rs.record(&ctx, &mut enc, &src_buf, src_dims, &dst, dst_dims, 1, &geom)
        .expect("record");
    submit(&ctx, enc);
    let short = read(&ctx, &dst, plane_dst);
    let want = &cpu[0][d0 * plane_dst..(d0 + 1) * plane_dst];
    assert!(
        max_err(&short, want) > 1e-2 * range(&values),
        "a slice less did not matter"
    );
}
