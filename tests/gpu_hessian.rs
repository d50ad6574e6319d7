//! The Hessian-side GPU kernels (Gaussian passes, Hessian, eigenvalues and feature maps,
//! multi-scale, Frangi's c, structure tensor) on the test adapter (lavapipe in CI), each against
//! its CPU twin in `shapecast::cpu` on a 13 x 17 x 11 phantom with 0.6 x 0.8 x 1.1 mm voxels.
//! Every test prints what it measured.

mod gpu_common;

use gpu_common::*;
use shapecast::cpu::gaussian::{GaussianOrder, derivative_kernel, separable};
use shapecast::gpu::context::test_context;
use shapecast::gpu::gaussian::{Gaussian, SeparableKernel};

const O: [GaussianOrder; 3] = [
    GaussianOrder::Smooth,
    GaussianOrder::First,
    GaussianOrder::Second,
];

#[test]
fn gaussian_passes_match_cpu() {
    let Some(ctx) = test_context() else { return };
    let (grid, values) = phantom();
    let sg = slab_grid(&grid);
    let n = grid.len();
    let gauss = Gaussian::new(&ctx).expect("shader");
    // Plain and offset by -1000 HU (air-like values: the derivatives must not lose precision).
    let shifted: Vec<f32> = values.iter().map(|v| v - 1000.0).collect();
    let mut worst = 0.0f32;
    // sigma 0.5 mm is below one voxel on every axis; 3 mm gives a z kernel (radius 10) nearly
    // as long as the 11 slices, so border replication is exercised heavily.
    for sigma in [0.5, 1.0, 3.0] {
        for orders in [
            [0, 0, 0],
            [1, 0, 0],
            [0, 1, 0],
            [0, 0, 1],
            [2, 0, 0],
            [0, 2, 1],
            [1, 1, 2],
        ] {
            let orders = orders.map(|o| O[o]);
            for input in [&values, &shifted] {
                let kernels: [Vec<f64>; 3] = std::array::from_fn(|a| {
                    derivative_kernel(sigma, grid.spacing_mm[a], orders[a])
                });
                let cpu = separable(&grid, input, [&kernels[0], &kernels[1], &kernels[2]]);
                let k = SeparableKernel::new(&ctx, sigma, grid.spacing_mm, orders);
                let (src, tmp, dst) = (upload(&ctx, input), buffer(&ctx, n), buffer(&ctx, n));
                let mut enc = encoder(&ctx);
                gauss
                    .record_separable(&ctx, &mut enc, &sg, &k, &src, &tmp, &dst)
                    .expect("record");
                submit(&ctx, enc);
                let gpu = read(&ctx, &dst, n);
                let rel = max_err(&gpu, &cpu) / range(&cpu).max(f32::MIN_POSITIVE);
                worst = worst.max(rel);
                assert!(
                    rel < 1e-5,
                    "sigma {sigma} orders {orders:?}: max error {rel:e} of the output's range"
                );
            }
        }
    }
    eprintln!("gaussian passes: worst max error {worst:.2e} of the output's range (bound 1e-5)");
}
