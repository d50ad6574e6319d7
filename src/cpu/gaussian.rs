//! Separable Gaussian and Gaussian-derivative kernels in mm, and convolution along one axis with
//! replicated borders (docs/science.md, Hessian features, item 1).
//!
//! Kernels are sampled at integer voxel offsets `x = -r..=r`, with `r = ceil(3 sigma_vox) + 1`
//! (3 sigma plus one voxel) and `sigma_vox = sigma_mm / spacing_mm` per axis:
//! `G(x) = exp(-x^2 / 2 sigma^2) / Z` (Z the sum over all integers, so G is the untruncated
//! sampled Gaussian), `G1(x) = x / sigma^2 G(x)`, `G2(x) = (x^2 - sigma^2) / sigma^4 G(x)`: the
//! Gaussian derivatives themselves, not finite differences of a smoothed volume (those lose
//! 5-10% at 2 voxels). What the cut removes is put on the two end taps, as if the cut tails were
//! gathered there: order 0 then sums to exactly 1, order 1 has exactly `sum x w = 1` (a ramp
//! gives its slope), order 2 sums to exactly 0 (a constant, e.g. air at -1000 HU, gives no
//! curvature). An object that fits inside the support therefore sees the untruncated kernel:
//! the Hessian at the centre of a ball is within 0.3% of the closed form. Dividing by
//! `spacing^order` turns per-voxel derivatives into per-mm ones.
//!
//! Convolution is written as a correlation, `out[i] = sum_x w[x] in[clamp(i + x)]`, so that the
//! order-1 kernel `w[x] ~ x G(x)` gives `+dI/dx`.

use super::{Grid, parallel};

/// Which derivative a 1-D kernel takes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GaussianOrder {
    Smooth = 0,
    First = 1,
    Second = 2,
}

/// Kernel radius in voxels: 3 sigma plus one voxel.
pub fn kernel_radius_vox(sigma_vox: f64) -> usize {
    (3.0 * sigma_vox).ceil() as usize + 1
}

/// The 1-D kernel of `order` for `sigma_mm` on an axis of `spacing_mm`, as weights for offsets
/// `-r..=r` (index `x + r`), already divided by `spacing_mm^order` (derivatives per mm).
/// `sigma_mm <= 0` gives the identity (and central differences for the derivatives).
pub fn derivative_kernel(sigma_mm: f64, spacing_mm: f64, order: GaussianOrder) -> Vec<f64> {
    let sigma_vox = sigma_mm / spacing_mm;
    if sigma_vox <= 0.0 {
        return match order {
            GaussianOrder::Smooth => vec![1.0],
            GaussianOrder::First => vec![-0.5 / spacing_mm, 0.0, 0.5 / spacing_mm],
            GaussianOrder::Second => {
                let s2 = spacing_mm * spacing_mm;
                vec![1.0 / s2, -2.0 / s2, 1.0 / s2]
            }
        };
    }
    let r = kernel_radius_vox(sigma_vox) as i64;
    let s2 = sigma_vox * sigma_vox;
    let gauss = |x: f64| (-x * x / (2.0 * s2)).exp();
    // Z over a support wide enough that the rest is below f64 resolution.
    let wide = r + (10.0 * sigma_vox).ceil() as i64;
    let z: f64 = (-wide..=wide).map(|x| gauss(x as f64)).sum();
    let xs: Vec<f64> = (-r..=r).map(|x| x as f64).collect();
    let g: Vec<f64> = xs.iter().map(|&x| gauss(x) / z).collect();
    let last = xs.len() - 1;
    let rf = r as f64;
    let mut w: Vec<f64> = match order {
        GaussianOrder::Smooth => g.clone(),
        GaussianOrder::First => xs.iter().zip(&g).map(|(x, g)| x / s2 * g).collect(),
        GaussianOrder::Second => xs
            .iter()
            .zip(&g)
            .map(|(x, g)| (x * x - s2) / (s2 * s2) * g)
            .collect(),
    };
    match order {
        GaussianOrder::Smooth => {
            let missing = 1.0 - w.iter().sum::<f64>();
            w[0] += 0.5 * missing;
            w[last] += 0.5 * missing;
        }
        GaussianOrder::First => {
            let m1: f64 = xs.iter().zip(&w).map(|(x, w)| x * w).sum();
            let delta = (1.0 - m1) / (2.0 * rf);
            w[0] -= delta;
            w[last] += delta;
        }
        GaussianOrder::Second => {
            let residual: f64 = w.iter().sum();
            w[0] -= 0.5 * residual;
            w[last] -= 0.5 * residual;
        }
    }
    let scale = spacing_mm.powi(order as i32);
    w.iter().map(|v| v / scale).collect()
}

/// The sum of a kernel's taps as the convolutions use it ([`convolve_axis`], and the GPU's
/// gaussian.wgsl through `crate::compute::gaussian`). Derivative kernels (orders 1 and 2, central
/// differences) sum to 0 by construction, but their f64 taps only to ~1e-17 of their size;
/// that is taken as exactly 0, so that a constant gives exactly zero derivatives. Otherwise
/// ~1e-17 of the value survives as "curvature", and a map that is free of scale turns it into
/// features: Frangi's, with its default c (half the largest norm), gave 0.101 everywhere on
/// a constant volume.
pub fn tap_sum(kernel: &[f64]) -> f64 {
    let sum: f64 = kernel.iter().sum();
    let size: f64 = kernel.iter().map(|w| w.abs()).sum();
    if sum.abs() <= 1e-9 * size { 0.0 } else { sum }
}

/// Correlates `src` with the 1-D `kernel` (odd length, centred) along `axis`, borders replicated.
///
/// The sum is taken about the centre voxel's value as gaussian.wgsl takes it about a nearby
/// one: `out = v_c * tap_sum + sum w (v - v_c)`, so that a constant line gives exactly
/// `v_c * tap_sum` (its value, or 0 for a derivative; see [`tap_sum`]).
pub fn convolve_axis(grid: &Grid, src: &[f32], axis: usize, kernel: &[f64]) -> Vec<f32> {
    let [nx, ny, nz] = grid.dims;
    let mut out = vec![0.0f32; grid.len()];
    if out.is_empty() {
        return out;
    }
    let r = (kernel.len() / 2) as i64;
    let sum = tap_sum(kernel);
    let n_axis = grid.dims[axis] as i64;
    let stride = [1, nx, nx * ny][axis];
    let slice_len = nx * ny;
    parallel::for_each_chunk(&mut out, slice_len, |k, slice| {
        for j in 0..ny {
            for i in 0..nx {
                let ijk = [i, j, k];
                let centre = i + nx * (j + ny * k);
                let pos = ijk[axis] as i64;
                let base = centre - ijk[axis] * stride;
                let v_c = f64::from(src[centre]);
                let mut acc = 0.0f64;
                for (t, w) in kernel.iter().enumerate() {
                    let q = (pos + t as i64 - r).clamp(0, n_axis - 1) as usize;
                    acc += w * (f64::from(src[base + q * stride]) - v_c);
                }
                slice[i + nx * j] = (v_c * sum + acc) as f32;
            }
        }
    });
    let _ = nz;
    out
}

/// Applies one kernel per axis (x, then y, then z).
pub fn separable(grid: &Grid, src: &[f32], kernels: [&[f64]; 3]) -> Vec<f32> {
    let a = convolve_axis(grid, src, 0, kernels[0]);
    let b = convolve_axis(grid, &a, 1, kernels[1]);
    convolve_axis(grid, &b, 2, kernels[2])
}

/// Gaussian smoothing with `sigma_mm` (isotropic in mm, so per-axis in voxels).
pub fn gaussian_smooth(grid: &Grid, src: &[f32], sigma_mm: f64) -> Vec<f32> {
    let k: [Vec<f64>; 3] = std::array::from_fn(|a| {
        derivative_kernel(sigma_mm, grid.spacing_mm[a], GaussianOrder::Smooth)
    });
    separable(grid, src, [&k[0], &k[1], &k[2]])
}

#[cfg(test)]
mod tests {
    use super::*;

    fn apply(kernel: &[f64], f: impl Fn(f64) -> f64) -> f64 {
        let r = (kernel.len() / 2) as f64;
        kernel
            .iter()
            .enumerate()
            .map(|(t, w)| w * f(t as f64 - r))
            .sum()
    }

    #[test]
    fn kernels_are_exact_on_constants_and_ramps() {
        for sigma_mm in [0.3, 0.7, 1.0, 2.5, 6.0] {
            let s = 0.7;
            let k0 = derivative_kernel(sigma_mm, s, GaussianOrder::Smooth);
            let k1 = derivative_kernel(sigma_mm, s, GaussianOrder::First);
            let k2 = derivative_kernel(sigma_mm, s, GaussianOrder::Second);
            assert_eq!(k0.len(), 2 * kernel_radius_vox(sigma_mm / s) + 1);
            // f(x_mm) = 3 + 2 x_mm: value 3, slope 2, curvature 0.
            let f = |x_vox: f64| 3.0 + 2.0 * x_vox * s;
            assert!((apply(&k0, f) - 3.0).abs() < 1e-12);
            assert!((apply(&k1, f) - 2.0).abs() < 1e-12);
            assert!(apply(&k2, f).abs() < 1e-12);
            // A parabola's curvature within 2% (the cut tails carry a little of x^2's moment),
            // from one voxel up: below that a sampled Gaussian is no Gaussian (the CLI warns).
            if sigma_mm < s {
                continue;
            }
            let c = apply(&k2, |x_vox: f64| 0.5 * (x_vox * s).powi(2));
            assert!((c - 1.0).abs() < 0.02, "sigma {sigma_mm}: {c}");
        }
    }
}
