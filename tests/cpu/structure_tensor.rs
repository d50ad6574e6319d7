//! The general structure tensor (paper eq. 5) against an independent closed form (issue 13,
//! item 6: untested until now): a plane wave, whose smoothed gradient and smoothed g g^T are
//! known exactly through the kernels' transfer functions, on an anisotropic grid with the wave
//! oblique to every axis (so the off-diagonal components and their placement are checked).

use shapecast::cpu::Grid;
use shapecast::cpu::eigen::eigenvalues_sorted;
use shapecast::cpu::gaussian::{GaussianOrder, derivative_kernel};
use shapecast::cpu::rst::GradientVolume;
use shapecast::cpu::structure_tensor::structure_tensor_volume;

/// Transfer of a symmetric kernel (taps at offsets -r..=r voxels) at `k_per_voxel` radians per
/// voxel: a cosine of that frequency comes out multiplied by this.
fn transfer(kernel: &[f64], k_per_voxel: f64) -> f64 {
    let r = (kernel.len() / 2) as f64;
    kernel
        .iter()
        .enumerate()
        .map(|(t, w)| w * ((t as f64 - r) * k_per_voxel).cos())
        .sum()
}

/// I = A sin(k.x + p). Smoothing by sigma_g multiplies it by G = prod_a transfer(k_a s_a);
/// central differences give g = A G cos(k.x + p) c with c_a = sin(k_a s_a) / s_a; so
/// g g^T = (A G)^2 c c^T (1 + cos 2(k.x + p)) / 2, and smoothing by rho multiplies the cosine by
/// H = prod_a transfer(2 k_a s_a). The tensor has rank one: l0 = |A G c|^2 (1 + H cos) / 2.
#[test]
fn structure_tensor_of_a_plane_wave_matches_the_closed_form() {
    let spacing = [0.8, 1.0, 1.2];
    let dims = [44, 36, 32];
    let grid = Grid::new(dims, spacing);
    let (amp, phase, sigma_g, rho) = (100.0, 0.3, 0.7, 1.5);
    let dir = [1.0f64, 2.0, 0.7];
    let norm = dir.iter().map(|d| d * d).sum::<f64>().sqrt();
    let k: [f64; 3] = std::array::from_fn(|a| std::f64::consts::TAU / 12.0 * dir[a] / norm);
    let pos = |i: usize, j: usize, l: usize| [i, j, l];
    let mut values = vec![0.0f32; grid.len()];
    for l in 0..dims[2] {
        for j in 0..dims[1] {
            for i in 0..dims[0] {
                let x = pos(i, j, l);
                let kx: f64 = (0..3).map(|a| k[a] * x[a] as f64 * spacing[a]).sum();
                values[grid.index(i, j, l)] = (amp * (kx + phase).sin()) as f32;
            }
        }
    }
    let gv = GradientVolume::new(&grid, &values, sigma_g);
    let s = structure_tensor_volume(&gv, rho);

    let smooth = |sigma: f64, a: usize| derivative_kernel(sigma, spacing[a], GaussianOrder::Smooth);
    let g: f64 = (0..3)
        .map(|a| transfer(&smooth(sigma_g, a), k[a] * spacing[a]))
        .product();
    let h: f64 = (0..3)
        .map(|a| transfer(&smooth(rho, a), 2.0 * k[a] * spacing[a]))
        .product();
    let c: [f64; 3] = std::array::from_fn(|a| amp * g * (k[a] * spacing[a]).sin() / spacing[a]);
    // Far enough from the borders (replicated there) for both kernels and the difference.
    let margin: [usize; 3] =
        std::array::from_fn(|a| smooth(sigma_g, a).len() / 2 + 1 + smooth(rho, a).len() / 2);
    let cc = c.iter().map(|x| x * x).sum::<f64>();
    const PAIRS: [(usize, usize); 6] = [(0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2)];
    let (mut worst, mut worst_eig, mut count) = (0.0f64, 0.0f64, 0);
    for l in margin[2]..dims[2] - margin[2] {
        for j in margin[1]..dims[1] - margin[1] {
            for i in margin[0]..dims[0] - margin[0] {
                let idx = grid.index(i, j, l);
                let x = pos(i, j, l);
                let kx: f64 = (0..3).map(|a| k[a] * x[a] as f64 * spacing[a]).sum();
                let f = 0.5 * (1.0 + h * (2.0 * (kx + phase)).cos());
                for (comp, &(a, b)) in PAIRS.iter().enumerate() {
                    let want = c[a] * c[b] * f;
                    worst = worst.max((f64::from(s[comp][idx]) - want).abs() / cc);
                }
                let m: [f64; 6] = std::array::from_fn(|comp| f64::from(s[comp][idx]));
                let e = eigenvalues_sorted(&m);
                let want = [cc * f, 0.0, 0.0];
                for q in 0..3 {
                    worst_eig = worst_eig.max((e[q] - want[q]).abs() / cc);
                }
                count += 1;
            }
        }
    }
    eprintln!(
        "plane wave: |A G c|^2 = {cc:.1}, H = {h:.4}; over {count} interior voxels worst component error {worst:.2e} and eigenvalue error {worst_eig:.2e} of |A G c|^2"
    );
    assert!(count > 1000, "only {count} interior voxels");
    // The tensor varies with position (H is not negligible), so the check sees the smoothing.
    assert!(
        h > 0.05,
        "H {h}: the cosine is smoothed away, the test would see only a constant"
    );
    assert!(worst < 1e-5, "component error {worst:e}");
    assert!(worst_eig < 1e-5, "eigenvalue error {worst_eig:e}");
}
