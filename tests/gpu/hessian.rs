//! The Hessian-side GPU kernels (Gaussian passes, Hessian, eigenvalues and feature maps,
//! multi-scale, Frangi's c, structure tensor) on the test adapter (lavapipe in CI), each against
//! its CPU twin in `shapecast::cpu` on a 13 x 17 x 11 phantom with 0.6 x 0.8 x 1.1 mm voxels.
//! Every test prints what it measured.

use crate::gpu_common;

use gpu_common::*;
use shapecast::compute::gaussian::{AxisPass, Gaussian, PassKernels, SeparableKernel};
use shapecast::cpu::gaussian::{GaussianOrder, derivative_kernel, separable};
use shapecast::gpu::context::test_context;
use shapecast::gpu::kernel::Recorder;

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
                    .record_separable(
                        &mut Recorder::new(&ctx, &mut enc),
                        &sg,
                        &k,
                        &src,
                        &tmp,
                        &dst,
                    )
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

/// The block kernels with one, two and three kernels per pass (a `PassKernels::Set`, as the
/// Hessian uses them) along every axis of a slab with long lines (several blocks per line, the
/// last one partial), including the zero-padded mix of radii at sigma 0 (identity and central
/// differences), against the CPU's `convolve_axis` per order; and kernels too long for the
/// uniform array (radius > 127), which fall back to one output per invocation.
#[test]
fn gaussian_multi_order_and_fallback_match_cpu() {
    use shapecast::compute::gaussian::{AxisTapSet, MAX_TAPS};
    use shapecast::cpu::gaussian::convolve_axis;
    let Some(ctx) = test_context() else { return };
    let gauss = Gaussian::new(&ctx).expect("shader");
    // Relative to the output's range (as gaussian_passes_match_cpu), or for nearly constant
    // outputs to the input's range times the kernel's absolute sum (what f32 rounding scales with).
    let check = |what: &str, gpu: &[f32], cpu: &[f32], input: &[f32], k: &[f64]| -> f32 {
        let abs_sum: f64 = k.iter().map(|w| w.abs()).sum();
        let scale = range(cpu).max(abs_sum as f32 * range(input));
        let rel = max_err(gpu, cpu) / scale.max(f32::MIN_POSITIVE);
        assert!(rel < 1e-5, "{what}: max error {rel:e} of {scale:e}");
        rel
    };
    let mut worst = 0.0f32;
    let mut fallbacks = 0;
    // 25 x 52 x 37 voxels: every axis longer than BLOCK and BLOCK3, none a multiple of them.
    let (long, long_values) = phantom_at([0.3, 0.25, 0.3]);
    let (small, small_values) = phantom();
    let cases: [(&shapecast::cpu::Grid, &Vec<f32>, f64, f64); 4] = [
        (&long, &long_values, 1.0, 1.0),
        (&long, &long_values, 0.0, 2.5),
        // sigma 0.5 mm: radius 3 on x (0.3 mm voxels), 2 on y.
        (&long, &long_values, 0.5, 1.0),
        // Radii 201 (x), 151 (y): past MAX_TAPS, the fallback; 111 (z): the block kernels.
        (&small, &small_values, 40.0, 1.0),
    ];
    for (grid, values, sigma, scale) in cases {
        let sg = slab_grid(grid);
        let n = grid.len();
        let shifted: Vec<f32> = values.iter().map(|v| v - 1000.0).collect();
        for axis in 0..3 {
            let set = AxisTapSet::new(&ctx, sigma, grid.spacing_mm[axis], scale);
            if 2 * set.radius() as usize + 1 > MAX_TAPS {
                fallbacks += 1;
            }
            let kernels: Vec<Vec<f64>> = O
                .iter()
                .map(|&o| {
                    derivative_kernel(sigma, grid.spacing_mm[axis], o)
                        .into_iter()
                        .map(|w| w * scale)
                        .collect()
                })
                .collect();
            for input in [values, &shifted] {
                let src = upload(&ctx, input);
                let cpu: Vec<Vec<f32>> = kernels
                    .iter()
                    .map(|k| convolve_axis(grid, input, axis, k))
                    .collect();
                for outputs in 1..=3 {
                    let dst: Vec<wgpu::Buffer> = (0..outputs).map(|_| buffer(&ctx, n)).collect();
                    let refs: Vec<&wgpu::Buffer> = dst.iter().collect();
                    let mut enc = encoder(&ctx);
                    gauss
                        .record_pass(
                            &mut Recorder::new(&ctx, &mut enc),
                            &AxisPass {
                                grid: &sg,
                                axis,
                                region: None,
                                kernels: PassKernels::Set(&set),
                                src: &src,
                                dst: &refs,
                            },
                        )
                        .expect("record");
                    submit(&ctx, enc);
                    for (o, d) in dst.iter().enumerate() {
                        let what = format!(
                            "{:?} sigma {sigma} axis {axis} order {o} of {outputs}",
                            grid.dims
                        );
                        let gpu = read(&ctx, d, n);
                        worst = worst.max(check(&what, &gpu, &cpu[o], input, &kernels[o]));
                    }
                }
            }
        }
    }
    assert_eq!(
        fallbacks, 2,
        "x and y of the sigma 40 mm case need the fallback"
    );
    eprintln!(
        "multi-order passes and fallback: worst max error {worst:.2e} of the output's scale (bound 1e-5)"
    );
}

use shapecast::compute::eigen_features::{
    EigenFeatures, EigenPass, Mapping, TensorOutput, frangi_c_from_norm_bits, norm_buffer,
};
use shapecast::compute::hessian::{Hessian, HessianKernels, HessianPass};
use shapecast::cpu::eigen::{eigenvalues_sorted, frobenius};
use shapecast::cpu::features::{
    FeatureMap, HessianMethod, frangi_default_c, hessian_eigen_multiscale,
    hessian_features_multiscale, sym_at,
};
use shapecast::cpu::hessian_volume;
use shapecast::gpu::GpuContext;
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
            &mut Recorder::new(ctx, &mut enc),
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

/// Whether sorted eigenvalues `l` have two magnitudes within `tie` with opposite signs (sorting
/// by magnitude may then pick either order, f32 against f64).
fn near_tie(l: &[f64; 3], tie: f64) -> bool {
    (0..3).any(|a| (a + 1..3).any(|b| l[a] * l[b] < 0.0 && (l[a].abs() - l[b].abs()).abs() <= tie))
}

/// Compares a GPU component-major output with the CPU's per voxel. A voxel may differ by more
/// than `tol` only where the CPU's eigenvalues at one of the scales (`eigs[scale][voxel]`) have
/// a magnitude tie (see [`near_tie`]); such voxels are counted and must stay below 0.5%.
/// Returns (max error outside ties, tie voxels).
fn compare_with_ties(
    what: &str,
    gpu: &[f32],
    cpu: &[Vec<f32>],
    eigs: &[Vec<[f64; 3]>],
    tol: f32,
    tie: f64,
) -> (f32, usize) {
    let n = cpu[0].len();
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
        assert!(
            eigs.iter().any(|e| near_tie(&e[i], tie)),
            "{what}: voxel {i}: error {err:e} > {tol:e}, GPU {:?} CPU {:?}, CPU eigenvalues per scale {:?}",
            (0..cpu.len()).map(|c| gpu[c * n + i]).collect::<Vec<_>>(),
            (0..cpu.len()).map(|c| cpu[c][i]).collect::<Vec<_>>(),
            eigs.iter().map(|e| e[i]).collect::<Vec<_>>(),
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
            &mut Recorder::new(&ctx, &mut enc),
            &sg,
            refs(&gpu_bufs),
            (0, sg.dims[2]),
            EigenPass::Output {
                what: TensorOutput::Eigen,
                accumulate: false,
                out: &out,
            },
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
            std::slice::from_ref(&eig),
            1e-4 * largest,
            1e-4 * f64::from(largest),
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
        &mut Recorder::new(&ctx, &mut enc),
        &sg,
        refs(&bufs),
        (0, 1),
        EigenPass::Output {
            what: TensorOutput::Eigen,
            accumulate: false,
            out: &out,
        },
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

/// CPU eigenvalues of the normalised Hessian per voxel at `sigma`.
fn cpu_eig(grid: &shapecast::cpu::Grid, values: &[f32], sigma: f64) -> Vec<[f64; 3]> {
    let h = hessian_volume(grid, values, sigma, true);
    (0..grid.len())
        .map(|i| eigenvalues_sorted(&sym_at(&h, i)))
        .collect()
}

/// GPU multi-scale output: Hessian per sigma, then `what` accumulated over the scales.
fn gpu_multiscale(
    ctx: &GpuContext,
    grid: &shapecast::cpu::Grid,
    values: &[f32],
    sigmas: &[f64],
    what: &dyn Fn(usize) -> TensorOutput,
) -> Vec<f32> {
    let sg = slab_grid(grid);
    let n = grid.len();
    let ef = EigenFeatures::new(ctx).expect("shader");
    let comps = what(0).components() as usize;
    let out = buffer(ctx, comps * n);
    for (s, &sigma) in sigmas.iter().enumerate() {
        let h = gpu_hessian(ctx, &sg, grid.spacing_mm, values, sigma);
        let mut enc = encoder(ctx);
        ef.record(
            &mut Recorder::new(ctx, &mut enc),
            &sg,
            refs(&h),
            (0, sg.dims[2]),
            EigenPass::Output {
                what: what(s),
                accumulate: s > 0,
                out: &out,
            },
        )
        .expect("record");
        submit(ctx, enc);
    }
    read(ctx, &out, comps * n)
}

/// Simple (eq. 1), Li (eq. 2) and Frangi with an explicit c, at one scale and as the maximum
/// over three scales, against `hessian_features_multiscale`.
#[test]
fn feature_maps_and_multiscale_max_match_cpu() {
    let Some(ctx) = test_context() else { return };
    let (grid, values) = phantom();
    let n = grid.len();
    for sigmas in [vec![1.0], vec![0.7, 1.2, 2.0]] {
        let eigs: Vec<Vec<[f64; 3]>> = sigmas.iter().map(|&s| cpu_eig(&grid, &values, s)).collect();
        let largest = eigs
            .iter()
            .flatten()
            .map(|l| l[0].abs())
            .fold(0.0, f64::max);
        for (name, cpu_method, mapping) in [
            (
                "simple",
                HessianMethod::Map(FeatureMap::Simple),
                Mapping::Map(FeatureMap::Simple),
            ),
            (
                "li",
                HessianMethod::Map(FeatureMap::Li),
                Mapping::Map(FeatureMap::Li),
            ),
            (
                "frangi c=15",
                HessianMethod::Frangi { c: Some(15.0) },
                Mapping::Frangi { c: 15.0 },
            ),
        ] {
            let cpu = hessian_features_multiscale(&grid, &values, &sigmas, cpu_method);
            let gpu = gpu_multiscale(&ctx, &grid, &values, &sigmas, &|_| {
                TensorOutput::hessian(mapping)
            });
            let scale = cpu.iter().map(|c| max_abs(c)).fold(0.0, f32::max);
            // Every feature occurs in the phantom (V, A, and B except for Frangi, which has none).
            let frangi = matches!(mapping, Mapping::Frangi { .. });
            for (c, comp) in cpu.iter().enumerate() {
                let expected = !(frangi && c == 2);
                assert_eq!(
                    max_abs(comp) > 0.05 * scale,
                    expected,
                    "{name}: component {c} max {}",
                    max_abs(comp)
                );
            }
            let (err, ties) =
                compare_with_ties(name, &gpu, &cpu, &eigs, 1e-4 * scale, 1e-4 * largest);
            eprintln!(
                "{name} sigmas {sigmas:?}: max error {:.2e} of the largest feature ({scale:.3}), {ties} tie voxels of {n}",
                err / scale
            );
        }
    }
}

/// Multi-scale eigenvalues: per voxel those of the scale whose normalised Hessian has the
/// largest Frobenius norm (the 4th output component carries the norm between scales).
#[test]
fn multiscale_eigenvalues_pick_the_largest_norm() {
    let Some(ctx) = test_context() else { return };
    let (grid, values) = phantom();
    let n = grid.len();
    let sigmas = [0.7, 1.2, 2.0];
    let cpu = hessian_eigen_multiscale(&grid, &values, &sigmas);
    let gpu = gpu_multiscale(&ctx, &grid, &values, &sigmas, &|_| TensorOutput::Eigen);
    let norms: Vec<Vec<f64>> = sigmas
        .iter()
        .map(|&s| {
            let h = hessian_volume(&grid, &values, s, true);
            (0..n).map(|i| frobenius(&sym_at(&h, i))).collect()
        })
        .collect();
    let eigs: Vec<Vec<[f64; 3]>> = sigmas.iter().map(|&s| cpu_eig(&grid, &values, s)).collect();
    let largest = max_abs(&cpu[0]);
    let tol = 1e-4 * largest;
    let mut worst = 0.0f32;
    let (mut ties, mut norm_ties) = (0, 0);
    // Which scale won on the CPU, and where did several scales come within 1e-5 of the best?
    for i in 0..n {
        let err = (0..3)
            .map(|c| (gpu[c * n + i] - cpu[c][i]).abs())
            .fold(0.0f32, f32::max);
        if err <= tol {
            worst = worst.max(err);
            continue;
        }
        let best = norms.iter().map(|v| v[i]).fold(0.0, f64::max);
        let close = norms.iter().filter(|v| v[i] >= best * (1.0 - 1e-5)).count();
        if close > 1 {
            norm_ties += 1;
        } else {
            assert!(
                eigs.iter()
                    .any(|e| near_tie(&e[i], 1e-4 * f64::from(largest))),
                "voxel {i}: GPU {:?} CPU {:?}",
                (0..3).map(|c| gpu[c * n + i]).collect::<Vec<_>>(),
                (0..3).map(|c| cpu[c][i]).collect::<Vec<_>>()
            );
            ties += 1;
        }
    }
    assert!(
        (ties + norm_ties) * 200 <= n,
        "{ties} + {norm_ties} voxels of {n} differ"
    );
    // The scale choice is real: the winning scale differs between voxels.
    let winners: std::collections::BTreeSet<usize> = (0..n)
        .map(|i| {
            (0..3)
                .max_by(|&a, &b| norms[a][i].total_cmp(&norms[b][i]))
                .unwrap_or(0)
        })
        .collect();
    assert!(
        winners.len() > 1,
        "one scale wins everywhere: the test would not see a wrong choice"
    );
    eprintln!(
        "multi-scale eigenvalues: max error {:.2e} of the largest |l| ({largest:.2}); {ties} sort ties, {norm_ties} norm ties of {n}; winning scales {winners:?}",
        worst / largest
    );
}

/// Frangi's default c over the whole volume, folded from three output ranges (as slabs would),
/// equals the CPU's per scale; Frangi with those c matches the CPU's default-c features.
#[test]
fn frangi_default_c_matches_cpu() {
    let Some(ctx) = test_context() else { return };
    let (grid, values) = phantom();
    let sg = slab_grid(&grid);
    let ef = EigenFeatures::new(&ctx).expect("shader");
    let sigmas = [0.8, 1.6];
    let mut cs = Vec::new();
    for &sigma in &sigmas {
        let h = gpu_hessian(&ctx, &sg, grid.spacing_mm, &values, sigma);
        let bits = norm_buffer(&ctx);
        let mut enc = encoder(&ctx);
        ef.record_clear_norm(&mut enc, &bits);
        for z in [(0, 4), (4, 3), (7, 4)] {
            ef.record(
                &mut Recorder::new(&ctx, &mut enc),
                &sg,
                refs(&h),
                z,
                EigenPass::MaxNorm { norm_bits: &bits },
            )
            .expect("record");
        }
        submit(&ctx, enc);
        let raw = shapecast::gpu::readback::read_bytes_blocking(&ctx, &bits, 4).expect("read");
        let gpu_c = frangi_c_from_norm_bits(u32::from_le_bytes([raw[0], raw[1], raw[2], raw[3]]));
        let cpu_c = frangi_default_c(&hessian_volume(&grid, &values, sigma, true));
        let rel = (gpu_c - cpu_c).abs() / cpu_c;
        eprintln!("sigma {sigma}: Frangi c GPU {gpu_c:.6} CPU {cpu_c:.6} (relative {rel:.1e})");
        assert!(cpu_c > 1.0 && rel < 1e-5, "c: GPU {gpu_c} CPU {cpu_c}");
        // Some range alone gives a smaller c: a per-slab c would be wrong, and folding every
        // range is what makes the result right.
        let mut smallest = f64::INFINITY;
        for z in [(0, 4), (4, 3), (7, 4)] {
            let one = norm_buffer(&ctx);
            let mut enc = encoder(&ctx);
            ef.record(
                &mut Recorder::new(&ctx, &mut enc),
                &sg,
                refs(&h),
                z,
                EigenPass::MaxNorm { norm_bits: &one },
            )
            .expect("record");
            submit(&ctx, enc);
            let raw = shapecast::gpu::readback::read_bytes_blocking(&ctx, &one, 4).expect("read");
            smallest = smallest.min(frangi_c_from_norm_bits(u32::from_le_bytes([
                raw[0], raw[1], raw[2], raw[3],
            ])));
        }
        assert!(
            smallest < 0.99 * gpu_c,
            "every range has the largest norm: {smallest} vs {gpu_c}"
        );
        cs.push(gpu_c);
    }
    let (grid2, values2) = (grid, values);
    let cpu =
        hessian_features_multiscale(&grid2, &values2, &sigmas, HessianMethod::Frangi { c: None });
    let gpu = gpu_multiscale(&ctx, &grid2, &values2, &sigmas, &|s| {
        TensorOutput::hessian(Mapping::Frangi { c: cs[s] })
    });
    let eigs: Vec<Vec<[f64; 3]>> = sigmas
        .iter()
        .map(|&s| cpu_eig(&grid2, &values2, s))
        .collect();
    let largest = eigs
        .iter()
        .flatten()
        .map(|l| l[0].abs())
        .fold(0.0, f64::max);
    let (err, ties) =
        compare_with_ties("frangi default c", &gpu, &cpu, &eigs, 1e-4, 1e-4 * largest);
    eprintln!(
        "frangi with the whole-volume c: max error {err:.2e} (values 0..1), {ties} tie voxels"
    );
}

/// A slab with the halo `hessian::halo_slices` asks for gives, on its output slices, what the
/// whole volume gives there (the pipeline's slab scheme, kernel side).
#[test]
fn slab_with_halo_matches_whole_volume() {
    let Some(ctx) = test_context() else { return };
    // 0.5 mm along z: 23 slices, so that both halos lie inside the volume.
    let (grid, values) = phantom_at([SPACING[0], SPACING[1], 0.5]);
    let ef = EigenFeatures::new(&ctx).expect("shader");
    let (z0, nz) = (10usize, 3usize);
    for sigma in [0.7, 1.0] {
        let halo = shapecast::compute::hessian::halo_slices(sigma, grid.spacing_mm[2]) as usize;
        let kernels = HessianKernels::new(&ctx, sigma, grid.spacing_mm, true);
        assert_eq!(kernels.halo_slices() as usize, halo);
        let (s0, s1) = (z0 - halo, z0 + nz + halo);
        assert!(
            s0 > 0 && s1 < grid.dims[2],
            "halo {halo} does not fit: the test needs a taller volume"
        );
        let slab_cpu_grid =
            shapecast::cpu::Grid::new([grid.dims[0], grid.dims[1], s1 - s0], grid.spacing_mm);
        let sg = slab_grid(&slab_cpu_grid);
        let slab_values = slices(&grid, &values, s0, s1 - s0);
        let h = gpu_hessian(&ctx, &sg, grid.spacing_mm, &slab_values, sigma);
        let plane = grid.dims[0] * grid.dims[1];
        let out = buffer(&ctx, 3 * plane * nz);
        let mut enc = encoder(&ctx);
        let what = TensorOutput::hessian(Mapping::Map(FeatureMap::Li));
        ef.record(
            &mut Recorder::new(&ctx, &mut enc),
            &sg,
            refs(&h),
            ((z0 - s0) as u32, nz as u32),
            EigenPass::Output {
                what,
                accumulate: false,
                out: &out,
            },
        )
        .expect("record");
        submit(&ctx, enc);
        let gpu = read(&ctx, &out, 3 * plane * nz);
        let cpu_all = hessian_features_multiscale(
            &grid,
            &values,
            &[sigma],
            HessianMethod::Map(FeatureMap::Li),
        );
        let cpu: Vec<Vec<f32>> = cpu_all.iter().map(|c| slices(&grid, c, z0, nz)).collect();
        let eig: Vec<[f64; 3]> =
            cpu_eig(&grid, &values, sigma)[z0 * plane..(z0 + nz) * plane].to_vec();
        let scale = cpu_all.iter().map(|c| max_abs(c)).fold(0.0, f32::max);
        let (err, ties) = compare_with_ties(
            "slab",
            &gpu,
            &cpu,
            &[eig],
            1e-4 * scale,
            1e-4 * f64::from(scale),
        );
        eprintln!(
            "sigma {sigma}: slab {s0}..{s1} (halo {halo}) output slices {z0}..{}: max error {:.2e} of the largest, {ties} ties",
            z0 + nz,
            err / scale
        );
        // The halo matters: without it the same slices come out different.
        let bare = slab_grid(&shapecast::cpu::Grid::new(
            [grid.dims[0], grid.dims[1], nz],
            grid.spacing_mm,
        ));
        let h = gpu_hessian(
            &ctx,
            &bare,
            grid.spacing_mm,
            &slices(&grid, &values, z0, nz),
            sigma,
        );
        let out2 = buffer(&ctx, 3 * plane * nz);
        let mut enc = encoder(&ctx);
        ef.record(
            &mut Recorder::new(&ctx, &mut enc),
            &bare,
            refs(&h),
            (0, nz as u32),
            EigenPass::Output {
                what,
                accumulate: false,
                out: &out2,
            },
        )
        .expect("record");
        submit(&ctx, enc);
        let without = read(&ctx, &out2, 3 * plane * nz);
        let flat: Vec<f32> = cpu.concat();
        assert!(
            max_err(&without, &flat) > 1e-2 * scale,
            "sigma {sigma}: no halo gives the same result"
        );
    }
}

/// The general structure tensor from the CPU twin's own gradient (the gradient kernel is the
/// RST module's): six smoothed products, then its eigenvalues and the GST mapping (eq. 1 / Li of
/// -l), against `structure_tensor_eigen` / `structure_tensor_features`.
#[test]
fn structure_tensor_matches_cpu() {
    use shapecast::compute::gaussian::SeparableKernel;
    use shapecast::compute::structure_tensor::StructureTensor;
    use shapecast::cpu::GradientVolume;
    use shapecast::cpu::structure_tensor::{structure_tensor_eigen, structure_tensor_features};
    let Some(ctx) = test_context() else { return };
    let (grid, values) = phantom();
    let sg = slab_grid(&grid);
    let n = grid.len();
    let gv = GradientVolume::new(&grid, &values, 0.7);
    let grads: Vec<wgpu::Buffer> = (0..3)
        .map(|a| upload(&ctx, &gv.gradient.iter().map(|g| g[a]).collect::<Vec<_>>()))
        .collect();
    let st = StructureTensor::new(&ctx).expect("shader");
    let ef = EigenFeatures::new(&ctx).expect("shader");
    for rho in [1.0, 2.0] {
        let kernel = SeparableKernel::smooth(&ctx, rho, grid.spacing_mm);
        let tmp = [buffer(&ctx, n), buffer(&ctx, n)];
        let t: Vec<wgpu::Buffer> = (0..6).map(|_| buffer(&ctx, n)).collect();
        let eig_out = buffer(&ctx, 4 * n);
        let feats: Vec<wgpu::Buffer> = (0..2).map(|_| buffer(&ctx, 3 * n)).collect();
        let mut enc = encoder(&ctx);
        st.record(
            &mut Recorder::new(&ctx, &mut enc),
            &sg,
            &kernel,
            [&grads[0], &grads[1], &grads[2]],
            [&tmp[0], &tmp[1]],
            refs(&t),
        )
        .expect("record");
        let all = (0, sg.dims[2]);
        ef.record(
            &mut Recorder::new(&ctx, &mut enc),
            &sg,
            refs(&t),
            all,
            EigenPass::Output {
                what: TensorOutput::Eigen,
                accumulate: false,
                out: &eig_out,
            },
        )
        .expect("record");
        for (m, map) in [FeatureMap::Simple, FeatureMap::Li].into_iter().enumerate() {
            ef.record(
                &mut Recorder::new(&ctx, &mut enc),
                &sg,
                refs(&t),
                all,
                EigenPass::Output {
                    what: TensorOutput::structure_tensor(map),
                    accumulate: false,
                    out: &feats[m],
                },
            )
            .expect("record");
        }
        submit(&ctx, enc);
        let cpu_eig = structure_tensor_eigen(&gv, rho);
        let gpu_eig = read(&ctx, &eig_out, 4 * n);
        let eig: Vec<[f64; 3]> = (0..n)
            .map(|i| std::array::from_fn(|c| f64::from(cpu_eig[c][i])))
            .collect();
        let largest = max_abs(&cpu_eig[0]);
        assert!(
            cpu_eig.iter().flatten().all(|&l| l >= -1e-3 * largest),
            "GST eigenvalues are >= 0"
        );
        let (e, ties) = compare_with_ties(
            "GST eigenvalues",
            &gpu_eig[..3 * n],
            &cpu_eig,
            std::slice::from_ref(&eig),
            1e-4 * largest,
            1e-4 * f64::from(largest),
        );
        eprintln!(
            "GST rho {rho}: eigenvalues max error {:.2e} of the largest ({largest:.1}), {ties} ties",
            e / largest
        );
        for (m, map) in [FeatureMap::Simple, FeatureMap::Li].into_iter().enumerate() {
            let cpu = structure_tensor_features(&gv, rho, map);
            let gpu = read(&ctx, &feats[m], 3 * n);
            let scale = cpu.iter().map(|c| max_abs(c)).fold(0.0, f32::max);
            // Mapped as bright structures: V and B occur, A (positive l) never does.
            assert!(max_abs(&cpu[0]) > 0.0 && max_abs(&cpu[2]) > 0.0 && max_abs(&cpu[1]) == 0.0);
            let (e, ties) = compare_with_ties(
                "GST features",
                &gpu,
                &cpu,
                std::slice::from_ref(&eig),
                1e-4 * scale,
                1e-4 * f64::from(largest),
            );
            eprintln!(
                "GST rho {rho} {map:?}: max error {:.2e} of the largest feature ({scale:.2}), {ties} ties",
                e / scale
            );
        }
    }
}

/// Wrong sizes and ranges are typed errors before anything is recorded (no wgpu panic).
#[test]
fn record_refuses_wrong_buffers() {
    use shapecast::gpu::checks::RecordError;
    let Some(ctx) = test_context() else { return };
    let sg = SlabGrid::new([13, 17, 11], [0.6, 0.8, 1.1]);
    let n = sg.len() as usize;
    let gauss = Gaussian::new(&ctx).expect("shader");
    let k = SeparableKernel::smooth(&ctx, 1.0, SPACING);
    let (a, b, small) = (buffer(&ctx, n), buffer(&ctx, n), buffer(&ctx, n - 1));
    let mut enc = encoder(&ctx);
    assert!(matches!(
        gauss.record_pass(
            &mut Recorder::new(&ctx, &mut enc),
            &AxisPass {
                grid: &sg,
                axis: 0,
                region: None,
                kernels: PassKernels::One(&k.axes[0]),
                src: &a,
                dst: &[&small],
            }
        ),
        Err(RecordError::BufferTooSmall { .. })
    ));
    assert!(matches!(
        gauss.record_pass(
            &mut Recorder::new(&ctx, &mut enc),
            &AxisPass {
                grid: &sg,
                axis: 0,
                region: None,
                kernels: PassKernels::One(&k.axes[0]),
                src: &a,
                dst: &[&a],
            }
        ),
        Err(RecordError::Invalid(_))
    ));
    assert!(matches!(
        gauss.record_pass(
            &mut Recorder::new(&ctx, &mut enc),
            &AxisPass {
                grid: &sg,
                axis: 3,
                region: None,
                kernels: PassKernels::One(&k.axes[0]),
                src: &a,
                dst: &[&b],
            }
        ),
        Err(RecordError::Invalid(_))
    ));
    let ef = EigenFeatures::new(&ctx).expect("shader");
    let t: Vec<wgpu::Buffer> = (0..6).map(|_| buffer(&ctx, n)).collect();
    let out = buffer(&ctx, 3 * n);
    let what = TensorOutput::hessian(Mapping::Map(FeatureMap::Li));
    assert_eq!(
        ef.record(
            &mut Recorder::new(&ctx, &mut enc),
            &sg,
            refs(&t),
            (8, 4),
            EigenPass::Output {
                what,
                accumulate: false,
                out: &out
            }
        ),
        Err(RecordError::OutputRange {
            z0: 8,
            nz: 4,
            depth: 11
        })
    );
    // Eigenvalues need 4 components: a 3-component buffer is refused.
    assert!(matches!(
        ef.record(
            &mut Recorder::new(&ctx, &mut enc),
            &sg,
            refs(&t),
            (0, 11),
            EigenPass::Output {
                what: TensorOutput::Eigen,
                accumulate: false,
                out: &out
            }
        ),
        Err(RecordError::BufferTooSmall { .. })
    ));
    submit(&ctx, enc);
}

/// The Hessian's passes over a brick's core only (each pass computes what the next reads:
/// `hessian::pass_region`) give, inside the core, the bits of the passes over the whole slab,
/// for a core that starts and ends off the kernels' block boundaries and in several paced parts;
/// outside the core's rows and slices the components are not computed.
#[test]
fn passes_over_a_core_give_the_whole_slabs_bits_there() {
    use shapecast::compute::hessian::{self, PASSES};
    let Some(ctx) = test_context() else { return };
    let (grid, values) = phantom_at([SPACING[0], SPACING[1], 0.5]);
    let sg = slab_grid(&grid);
    let n = values.len();
    let [nx, ny, nz] = sg.dims;
    let sigma = 0.8;
    let whole = gpu_hessian(&ctx, &sg, grid.spacing_mm, &values, sigma);
    let whole: Vec<Vec<f32>> = whole.iter().map(|b| read(&ctx, b, n)).collect();
    let core = [0..nx, 3..ny - 5, 7..nz - 6];
    let hessian_pass = Hessian::new(&ctx).expect("shader");
    let kernels = HessianKernels::new(&ctx, sigma, grid.spacing_mm, true);
    let input = upload(&ctx, &values);
    let tmp = buffer(&ctx, n);
    // NaN marks what no pass wrote.
    let out: Vec<wgpu::Buffer> = (0..6).map(|_| upload(&ctx, &vec![f32::NAN; n])).collect();
    let mut enc = encoder(&ctx);
    let mut computed = 0u64;
    for pass in 0..PASSES {
        let lines = hessian::pass_lines(&sg, &core, pass);
        computed += hessian::pass_voxels(&sg, &core, pass);
        // Three parts per pass, the last possibly empty.
        let step = (lines.end - lines.start).div_ceil(3).max(1);
        let mut at = lines.start;
        while at < lines.end {
            let end = (at + step).min(lines.end);
            hessian_pass
                .record_pass(
                    &mut Recorder::new(&ctx, &mut enc),
                    &HessianPass {
                        grid: &sg,
                        kernels: &kernels,
                        input: &input,
                        tmp: &tmp,
                        out: std::array::from_fn(|c| &out[c]),
                        pass,
                        core: &core,
                        cut: at..end,
                    },
                )
                .expect("record");
            at = end;
        }
    }
    submit(&ctx, enc);
    let (mut inside, mut outside_unwritten, mut outside) = (0usize, 0usize, 0usize);
    for (c, buf) in out.iter().enumerate() {
        let got = read(&ctx, buf, n);
        for k in 0..nz as usize {
            for j in 0..ny as usize {
                for i in 0..nx as usize {
                    let v = i + nx as usize * (j + ny as usize * k);
                    let in_core = core[1].contains(&(j as u32)) && core[2].contains(&(k as u32));
                    if in_core {
                        assert_eq!(
                            got[v].to_bits(),
                            whole[c][v].to_bits(),
                            "component {c} at ({i}, {j}, {k}): {} vs {}",
                            got[v],
                            whole[c][v]
                        );
                        inside += 1;
                    } else {
                        outside += 1;
                        outside_unwritten += usize::from(got[v].is_nan());
                    }
                }
            }
        }
    }
    let work = computed as f64 / (PASSES as u64 * n as u64) as f64;
    eprintln!(
        "core {core:?} of {:?}: {inside} component voxels bit-identical; {outside_unwritten} of {outside} outside left unwritten; the passes computed {work:.2} of the whole slab's outputs",
        sg.dims
    );
    assert_eq!(inside, 6 * (core[1].len() * core[2].len()) * nx as usize);
    // The final x passes write only the core; what lies outside it in some components is an
    // intermediate parked there (z and y passes over the halo rows they must cover).
    assert!(
        outside_unwritten > outside / 3,
        "{outside_unwritten} of {outside}"
    );
    assert!(
        work < 0.6,
        "the passes over the core computed {work:.2} of the slab's"
    );
    // A part outside the pass's lines is refused.
    let mut enc = encoder(&ctx);
    let err = hessian_pass.record_pass(
        &mut Recorder::new(&ctx, &mut enc),
        &HessianPass {
            grid: &sg,
            kernels: &kernels,
            input: &input,
            tmp: &tmp,
            out: std::array::from_fn(|c| &out[c]),
            pass: 1,
            core: &core,
            cut: 0..nz,
        },
    );
    assert!(err.is_err(), "a part beyond the core's slices was recorded");
}
