//! The shared GPU eigenvalue solver (shaders/eigen.wgsl, through the `eigen_features` kernel)
//! against the f64 Jacobi reference (issue 13, item 4): on a million random hard symmetric
//! matrices (tests/eigen_common), and on the Hessians of a real CT crop, where the CPU's closed
//! form is checked against the same reference so that a disagreement names the wrong solver.

use crate::common;
use crate::eigen_common;
use crate::gpu_common;

use eigen_common::{Rng, hard_matrix, relative_error, sorted_by_magnitude};
use gpu_common::*;
use shapecast::compute::eigen_features::{EigenFeatures, EigenPass, TensorOutput};
use shapecast::compute::hessian::{Hessian, HessianKernels};
use shapecast::cpu::Grid;
use shapecast::cpu::Preset;
use shapecast::cpu::eigen::{eigenvalues_jacobi, eigenvalues_sorted, frobenius};
use shapecast::cpu::features::{hessian_eigen_multiscale, sym_at};
use shapecast::cpu::hessian_volume;
use shapecast::gpu::GpuContext;
use shapecast::gpu::context::test_context;
use shapecast::gpu::kernel::{Recorder, SlabGrid};

/// Eigenvalues (sorted by magnitude, as eigen.wgsl returns them) of the f32 matrices
/// `comps[c][i]` on the GPU, laid out as a `width x (n / width)` slab.
fn gpu_eigenvalues(ctx: &GpuContext, comps: &[Vec<f32>; 6], width: usize) -> Vec<[f64; 3]> {
    let n = comps[0].len();
    assert_eq!(n % width, 0);
    let bufs: Vec<wgpu::Buffer> = comps.iter().map(|c| upload(ctx, c)).collect();
    let sg = SlabGrid::new([width as u32, (n / width) as u32, 1], [1.0; 3]);
    let ef = EigenFeatures::new(ctx).expect("shader");
    let out = buffer(ctx, 4 * n);
    let mut enc = encoder(ctx);
    ef.record(
        &mut Recorder::new(ctx, &mut enc),
        &sg,
        std::array::from_fn(|c| &bufs[c]),
        (0, 1),
        EigenPass::Output {
            what: TensorOutput::Eigen,
            accumulate: false,
            out: &out,
        },
    )
    .expect("record");
    submit(ctx, enc);
    let g = read(ctx, &out, 4 * n);
    (0..n)
        .map(|i| [g[i], g[n + i], g[2 * n + i]].map(f64::from))
        .collect()
}

/// Component-major f32 copies of matrices.
fn components(mats: &[[f64; 6]]) -> [Vec<f32>; 6] {
    std::array::from_fn(|c| mats.iter().map(|m| m[c] as f32).collect())
}

#[test]
fn gpu_solver_matches_jacobi_on_a_million_hard_matrices() {
    let Some(ctx) = test_context() else { return };
    const WIDTH: usize = 1024;
    const ROWS: usize = 1024;
    let mut rng = Rng::new(0x9e0_0013);
    let mats: Vec<[f64; 6]> = (0..WIDTH * ROWS).map(|_| hard_matrix(&mut rng)).collect();
    let comps = components(&mats);
    let gpu = gpu_eigenvalues(&ctx, &comps, WIDTH);
    let mut worst = 0.0f64;
    let mut worst_at = 0;
    for (i, g) in gpu.iter().enumerate() {
        // The reference of the matrix the GPU was given (rounded to f32).
        let m32: [f64; 6] = std::array::from_fn(|c| f64::from(comps[c][i]));
        let want = eigenvalues_jacobi(&m32);
        assert!(sorted_by_magnitude(*g), "{m32:?}: GPU {g:?} not sorted");
        let err = relative_error(*g, want);
        if err > worst {
            worst = err;
            worst_at = i;
        }
    }
    let m32: [f64; 6] = std::array::from_fn(|c| f64::from(comps[c][worst_at]));
    eprintln!(
        "eigen.wgsl on {} hard matrices: worst error {worst:.2e} of the largest |l| (bound 1e-5): {m32:?}: GPU {:?}, Jacobi {:?}",
        gpu.len(),
        gpu[worst_at],
        eigenvalues_jacobi(&m32)
    );
    assert!(worst < 1e-5, "worst {worst:e}");
}

/// The centre 64^3 of the real 1.5 mm contrast chest CT (../shared/data).
fn real_ct_crop() -> Option<(Grid, Vec<f32>)> {
    let path = common::shared_data("ct/aorta_ct_cropped.nii.gz")?;
    let v = shapecast::io::load(&[common::input(&path)])
        .expect("loads")
        .volume;
    let all = v.to_f32();
    const N: usize = 64;
    let lo: [usize; 3] = std::array::from_fn(|a| (v.dims[a] - N) / 2);
    let mut crop = Vec::with_capacity(N * N * N);
    for k in 0..N {
        for j in 0..N {
            for i in 0..N {
                crop.push(all[v.linear_index(lo[0] + i, lo[1] + j, lo[2] + k)]);
            }
        }
    }
    let grid = Grid {
        dims: [N; 3],
        spacing_mm: v.spacing_mm,
    };
    Some((grid, crop))
}

/// Both solvers on the same f32 Hessians of a real CT crop (the lymph-node preset's scales),
/// each against Jacobi: worst error of a voxel relative to the largest |l| of the volume (the
/// measure of issue 13) and relative to the voxel's own largest |l|.
#[test]
fn both_solvers_match_jacobi_on_real_ct_hessians() {
    let Some(ctx) = test_context() else { return };
    let Some((grid, values)) = real_ct_crop() else {
        return;
    };
    for sigma in [1.5, 2.0, 3.0, 4.0, 5.0] {
        let h = hessian_volume(&grid, &values, sigma, true);
        let gpu = gpu_eigenvalues(&ctx, &h, grid.dims[0]);
        let reference: Vec<[f64; 3]> = (0..grid.len())
            .map(|i| eigenvalues_jacobi(&sym_at(&h, i)))
            .collect();
        let largest = reference.iter().fold(0.0f64, |m, l| m.max(l[0].abs()));
        let (mut cpu_worst, mut gpu_worst, mut gpu_own) = (0.0f64, 0.0f64, 0.0f64);
        let mut gpu_bad = 0;
        for (i, want) in reference.iter().enumerate() {
            let cpu = eigenvalues_sorted(&sym_at(&h, i));
            let own = want[0].abs().max(f64::MIN_POSITIVE);
            cpu_worst = cpu_worst.max(relative_error(cpu, *want) * own / largest);
            let g = relative_error(gpu[i], *want);
            gpu_own = gpu_own.max(g);
            gpu_worst = gpu_worst.max(g * own / largest);
            if g * own / largest > 1e-4 {
                gpu_bad += 1;
                eprintln!(
                    "sigma {sigma}: voxel {i}: H {:?}: GPU {:?} CPU {cpu:?} Jacobi {want:?}",
                    sym_at(&h, i),
                    gpu[i]
                );
            }
        }
        eprintln!(
            "real CT 64^3, sigma {sigma} mm: worst error of the largest |l| ({largest:.2}): CPU {cpu_worst:.2e}, GPU {gpu_worst:.2e} ({gpu_bad} voxels > 1e-4); GPU per voxel {gpu_own:.2e}"
        );
        assert!(cpu_worst < 1e-9, "CPU {cpu_worst:e}");
        assert!(gpu_worst < 1e-5, "GPU {gpu_worst:e}");
    }
}

/// GPU multi-scale eigenvalues (the GPU's Hessian per scale, accumulated by `eigen_features` as
/// the pipeline does) against `hessian_eigen_multiscale` on the real CT crop, on its own grid.
///
/// Both solvers are right (above), yet a few voxels differ: the output is a discontinuous
/// function of the Hessians where two scales' normalised norms tie (the scale with the largest
/// norm wins) and where two eigenvalues of opposite signs tie in magnitude (which is l0), and
/// there the GPU's f32 and the CPU's f64 may decide either way. Every voxel that differs by
/// more than 1e-4 of the largest |l| must be such a tie, and they must stay rare. (Issue 13's
/// outliers of 1e-2 of the largest value come from these voxels through the pipelines'
/// interpolation of eigenvalues back onto the input grid, which spreads a tie's jump over its
/// neighbours; e.g. the centre 64^3 of this CT with `features --method hessian --eigen` differed
/// at 3 voxels by up to 2.2e-3, exactly what taking the runner-up scale at the 29 norm ties of
/// the compute grid and interpolating gives.)
#[test]
fn multiscale_eigenvalues_on_real_ct_differ_only_at_ties() {
    let Some(ctx) = test_context() else { return };
    let Some((grid, values)) = real_ct_crop() else {
        return;
    };
    let sigmas = Preset::LymphNodes.sigmas_mm();
    let n = grid.len();
    let sg = slab_grid(&grid);
    let hessian = Hessian::new(&ctx).expect("shader");
    let ef = EigenFeatures::new(&ctx).expect("shader");
    let input = upload(&ctx, &values);
    let tmp = buffer(&ctx, n);
    let h: Vec<wgpu::Buffer> = (0..6).map(|_| buffer(&ctx, n)).collect();
    let out = buffer(&ctx, 4 * n);
    for (s, &sigma) in sigmas.iter().enumerate() {
        let kernels = HessianKernels::new(&ctx, sigma, grid.spacing_mm, true);
        let mut enc = encoder(&ctx);
        hessian
            .record(
                &mut Recorder::new(&ctx, &mut enc),
                &sg,
                &kernels,
                &input,
                &tmp,
                std::array::from_fn(|c| &h[c]),
            )
            .expect("record");
        ef.record(
            &mut Recorder::new(&ctx, &mut enc),
            &sg,
            std::array::from_fn(|c| &h[c]),
            (0, sg.dims[2]),
            EigenPass::Output {
                what: TensorOutput::Eigen,
                accumulate: s > 0,
                out: &out,
            },
        )
        .expect("record");
        submit(&ctx, enc);
    }
    let gpu = read(&ctx, &out, 4 * n);
    let cpu = hessian_eigen_multiscale(&grid, &values, &sigmas);
    let per_scale: Vec<Vec<(f64, [f64; 3])>> = sigmas
        .iter()
        .map(|&sigma| {
            let h = hessian_volume(&grid, &values, sigma, true);
            (0..n)
                .map(|i| {
                    let m = sym_at(&h, i);
                    (frobenius(&m), eigenvalues_sorted(&m))
                })
                .collect()
        })
        .collect();
    let largest = max_abs(&cpu[0]);
    let (mut worst, mut worst_tie) = (0.0f32, 0.0f32);
    let (mut norm_ties, mut sign_ties) = (0, 0);
    for i in 0..n {
        let err = (0..3)
            .map(|c| (gpu[c * n + i] - cpu[c][i]).abs())
            .fold(
                0.0f32,
                |m, e| if e.is_nan() { f32::INFINITY } else { m.max(e) },
            );
        if err <= 1e-4 * largest {
            worst = worst.max(err);
            continue;
        }
        worst_tie = worst_tie.max(err);
        let best = per_scale.iter().map(|p| p[i].0).fold(0.0, f64::max);
        let close: Vec<[f64; 3]> = per_scale
            .iter()
            .filter(|p| p[i].0 >= best * (1.0 - 1e-5))
            .map(|p| p[i].1)
            .collect();
        let sign_tie = |l: &[f64; 3]| {
            (0..3).any(|a| {
                (a + 1..3).any(|b| {
                    l[a] * l[b] < 0.0
                        && (l[a].abs() - l[b].abs()).abs() <= 1e-4 * f64::from(largest)
                })
            })
        };
        if close.len() > 1 {
            norm_ties += 1;
        } else {
            assert!(
                close.iter().any(sign_tie),
                "voxel {i}: GPU {:?} CPU {:?}: no tie explains it",
                (0..3).map(|c| gpu[c * n + i]).collect::<Vec<_>>(),
                (0..3).map(|c| cpu[c][i]).collect::<Vec<_>>()
            );
            sign_ties += 1;
        }
    }
    eprintln!(
        "real CT 64^3, scales {sigmas:?}: GPU vs CPU multi-scale eigenvalues: worst {:.2e} of the largest |l| ({largest:.1}) outside ties; {norm_ties} norm ties and {sign_ties} sign ties of {n} voxels differ (worst {:.2e})",
        worst / largest,
        worst_tie / largest
    );
    assert!(
        worst / largest < 1e-5,
        "outside ties: {:e}",
        worst / largest
    );
    assert!(
        (norm_ties + sign_ties) * 10_000 <= n,
        "{norm_ties} + {sign_ties} of {n} voxels differ"
    );
}
