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

use shapecast::cpu::eigen::{eigenvalues_sorted, frobenius};
use shapecast::cpu::features::{
    FeatureMap, HessianMethod, frangi, frangi_default_c, hessian_eigen_multiscale,
    hessian_features_multiscale, map_eigenvalues, sym_at,
};
use shapecast::cpu::hessian_volume;
use shapecast::gpu::GpuContext;
use shapecast::gpu::eigen_features::{
    EigenFeatures, Mapping, TensorOutput, frangi_c_from_norm_bits, norm_buffer,
};
use shapecast::gpu::hessian::{Hessian, HessianKernels};
use shapecast::gpu::kernel::SlabGrid;

/// The six normalised Hessian component buffers of `values` on the GPU.
fn gpu_hessian(
    ctx: &GpuContext,
    sg: &SlabGrid,
    spacing: [f64; 3],
    values: &[f32],
    sigma: f64,
) -> Vec<wgpu::Buffer> {
    let n = values.len();
    let hessian = Hessian::new(ctx).expect("shader");
    let kernels = HessianKernels::new(ctx, sigma, spacing, true);
    let input = upload(ctx, values);
    let tmp = buffer(ctx, n);
    let out: Vec<wgpu::Buffer> = (0..6).map(|_| buffer(ctx, n)).collect();
    let mut enc = encoder(ctx);
    hessian
        .record(
            ctx,
            &mut enc,
            sg,
            &kernels,
            &input,
            &tmp,
            std::array::from_fn(|c| &out[c]),
        )
        .expect("record");
    submit(ctx, enc);
    out
}

fn refs(v: &[wgpu::Buffer]) -> [&wgpu::Buffer; 6] {
    std::array::from_fn(|c| &v[c])
}

/// Compares a GPU component-major output with the CPU's per voxel. A voxel may differ by more
/// than `tol` only where the CPU's eigenvalues `eig` have two magnitudes within `tie` of each
/// other with opposite signs (sorting by magnitude may then pick either; f32 against f64); such
/// voxels are counted and must stay below 0.5%. Returns (max error outside ties, tie voxels).
fn compare_with_ties(
    what: &str,
    gpu: &[f32],
    cpu: &[Vec<f32>],
    eig: &[[f64; 3]],
    tol: f32,
    tie: f64,
) -> (f32, usize) {
    let n = eig.len();
    let mut worst = 0.0f32;
    let mut ties = 0;
    for i in 0..n {
        let err = (0..cpu.len())
            .map(|c| (gpu[c * n + i] - cpu[c][i]).abs())
            .fold(
                0.0f32,
                |m, e| if e.is_nan() { f32::INFINITY } else { m.max(e) },
            );
        if err <= tol {
            worst = worst.max(err);
            continue;
        }
        let l = eig[i];
        let near_tie = (0..3).any(|a| {
            (a + 1..3).any(|b| l[a] * l[b] < 0.0 && (l[a].abs() - l[b].abs()).abs() <= tie)
        });
        assert!(
            near_tie,
            "{what}: voxel {i}: error {err:e} > {tol:e}, CPU eigenvalues {l:?}, GPU {:?} CPU {:?}",
            (0..cpu.len()).map(|c| gpu[c * n + i]).collect::<Vec<_>>(),
            (0..cpu.len()).map(|c| cpu[c][i]).collect::<Vec<_>>(),
        );
        ties += 1;
    }
    assert!(
        ties * 200 <= n,
        "{what}: {ties} of {n} voxels differ at magnitude ties"
    );
    (worst, ties)
}

#[test]
fn hessian_and_eigenvalues_match_cpu() {
    let Some(ctx) = test_context() else { return };
    let (grid, values) = phantom();
    let sg = slab_grid(&grid);
    let n = grid.len();
    let ef = EigenFeatures::new(&ctx).expect("shader");
    for sigma in [0.7, 1.5] {
        let cpu = hessian_volume(&grid, &values, sigma, true);
        let gpu_bufs = gpu_hessian(&ctx, &sg, grid.spacing_mm, &values, sigma);
        let scale = cpu.iter().map(|c| max_abs(c)).fold(0.0, f32::max);
        let mut worst_h = 0.0f32;
        for c in 0..6 {
            let gpu = read(&ctx, &gpu_bufs[c], n);
            worst_h = worst_h.max(max_err(&gpu, &cpu[c]) / scale);
        }
        assert!(
            worst_h < 1e-5,
            "sigma {sigma}: Hessian component error {worst_h:e} of the largest"
        );
        // Eigenvalues on the GPU's Hessian against the CPU's eigenvalues of the CPU's Hessian.
        let out = buffer(&ctx, 4 * n);
        let mut enc = encoder(&ctx);
        ef.record(
            &ctx,
            &mut enc,
            &sg,
            refs(&gpu_bufs),
            (0, sg.dims[2]),
            TensorOutput::Eigen,
            false,
            &out,
        )
        .expect("record");
        submit(&ctx, enc);
        let gpu = read(&ctx, &out, 4 * n);
        let eig: Vec<[f64; 3]> = (0..n)
            .map(|i| eigenvalues_sorted(&sym_at(&cpu, i)))
            .collect();
        let cpu_eig: Vec<Vec<f32>> = (0..3)
            .map(|c| eig.iter().map(|l| l[c] as f32).collect())
            .collect();
        let largest = max_abs(&cpu_eig[0]);
        let (err, ties) = compare_with_ties(
            "eigenvalues",
            &gpu[..3 * n],
            &cpu_eig,
            &eig,
            1e-3 * largest,
            1e-3 * f64::from(largest),
        );
        // The 4th component is the tensor's Frobenius norm.
        let norms: Vec<f32> = (0..n).map(|i| frobenius(&sym_at(&cpu, i)) as f32).collect();
        let norm_err = max_err(&gpu[3 * n..], &norms) / max_abs(&norms);
        assert!(norm_err < 1e-5, "norm error {norm_err:e}");
        eprintln!(
            "sigma {sigma} mm: Hessian components max error {worst_h:.2e} of the largest |H|; eigenvalues max error {:.2e} of the largest |l| ({largest:.2}) with {ties} tie voxels; norm {norm_err:.2e}",
            err / largest
        );
    }
}

/// `R diag(d) R^T` for the rotation of angles `(a, b, c)` (z, then x, then z again).
fn rotated(d: [f64; 3], angles: [f64; 3]) -> [f64; 6] {
    let rot = |axis: usize, t: f64| {
        let (s, c) = t.sin_cos();
        let mut m = [[0.0; 3]; 3];
        m[axis][axis] = 1.0;
        let (p, q) = ((axis + 1) % 3, (axis + 2) % 3);
        m[p][p] = c;
        m[p][q] = -s;
        m[q][p] = s;
        m[q][q] = c;
        m
    };
    let mul = |a: [[f64; 3]; 3], b: [[f64; 3]; 3]| {
        let mut m = [[0.0; 3]; 3];
        for i in 0..3 {
            for j in 0..3 {
                m[i][j] = (0..3).map(|k| a[i][k] * b[k][j]).sum();
            }
        }
        m
    };
    let r = mul(mul(rot(2, angles[0]), rot(0, angles[1])), rot(2, angles[2]));
    let a = |i: usize, j: usize| (0..3).map(|k| r[i][k] * d[k] * r[j][k]).sum::<f64>();
    [a(0, 0), a(1, 1), a(2, 2), a(0, 1), a(0, 2), a(1, 2)]
}

/// The shared solver (eigen.wgsl) on hand-picked hard matrices: repeated and near-repeated
/// eigenvalues, opposite signs, zero, diagonal, tiny off-diagonals, and scales from 1e-6 to 1e6
/// (the f32 scaling by the largest entry must keep all of them accurate). Each matrix's error
/// is measured against its own largest |eigenvalue|.
#[test]
fn eigen_solver_handles_degenerate_matrices() {
    let Some(ctx) = test_context() else { return };
    let mut mats: Vec<[f64; 6]> = vec![
        [0.0; 6],
        [1.0, -3.0, 2.0, 0.0, 0.0, 0.0],
        [-2.0, -2.0, -2.0, 1e-17, 0.0, 0.0],
        [5.0, 5.0, 5.0, 1e-9, 2e-9, -1e-9],
    ];
    let shapes = [
        [-5.0, 2.0, 0.5],
        [-1.0, -1.0, -1.0],
        [-1.0, -1.0, 0.0],
        [-1.0, -1.0 + 1e-4, -1e-3],
        [3.0, 3.0, -1.0],
        [2.0, -2.0, 1.0],
        [2.0, -2.0 + 1e-3, 0.1],
        [-1.0, 0.0, 0.0],
        [1.0, 1e-6, -1e-6],
        [-7.0, -6.9999, 3.0],
    ];
    let mut seed = 0x1234_5678_9abc_def0u64;
    let mut next = || {
        seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (seed >> 11) as f64 / (1u64 << 53) as f64
    };
    for scale in [1e-6, 1.0, 1e3, 1e6] {
        for d in shapes {
            for _ in 0..6 {
                let ang = [next() * 6.3, next() * 3.2, next() * 6.3];
                mats.push(rotated(d.map(|x| x * scale), ang));
            }
        }
    }
    let n = mats.len();
    let comps: Vec<Vec<f32>> = (0..6)
        .map(|c| mats.iter().map(|m| m[c] as f32).collect())
        .collect();
    let bufs: Vec<wgpu::Buffer> = comps.iter().map(|c| upload(&ctx, c)).collect();
    let sg = SlabGrid::new([n as u32, 1, 1], [1.0; 3]);
    let ef = EigenFeatures::new(&ctx).expect("shader");
    let out = buffer(&ctx, 4 * n);
    let mut enc = encoder(&ctx);
    ef.record(
        &ctx,
        &mut enc,
        &sg,
        refs(&bufs),
        (0, 1),
        TensorOutput::Eigen,
        false,
        &out,
    )
    .expect("record");
    submit(&ctx, enc);
    let gpu = read(&ctx, &out, 4 * n);
    let mut worst = 0.0f64;
    for (i, m) in mats.iter().enumerate() {
        // The CPU's eigenvalues of the same f32-rounded matrix.
        let m32: [f64; 6] = std::array::from_fn(|c| f64::from(comps[c][i]));
        let l = eigenvalues_sorted(&m32);
        let big = l[0].abs();
        let g = [gpu[i], gpu[n + i], gpu[2 * n + i]].map(f64::from);
        let err = (0..3).map(|c| (g[c] - l[c]).abs()).fold(0.0, f64::max);
        let rel = if big > 0.0 { err / big } else { err };
        // Opposite-sign magnitude ties may come out in either order: compare as sets then.
        let tie = (0..3).any(|a| {
            (a + 1..3).any(|b| l[a] * l[b] < 0.0 && (l[a].abs() - l[b].abs()).abs() <= 1e-4 * big)
        });
        let rel = if tie && rel > 1e-5 {
            let mut gs = g;
            let mut ls = l;
            gs.sort_by(f64::total_cmp);
            ls.sort_by(f64::total_cmp);
            (0..3).map(|c| (gs[c] - ls[c]).abs()).fold(0.0, f64::max) / big
        } else {
            rel
        };
        assert!(
            rel < 1e-5,
            "matrix {m:?}: GPU {g:?} CPU {l:?}: error {rel:e} of |l0|"
        );
        worst = worst.max(rel);
    }
    eprintln!(
        "eigen.wgsl on {n} hard matrices: worst error {worst:.2e} of each matrix's |l0| (bound 1e-5)"
    );
}
