//! Refinement of thick axes by an integer factor before the features, and the features taken
//! back at the input voxel centres (docs/science.md, "Thick slices").
//!
//! The rules (measured, see docs/reproduction.md):
//! - The Hessian family refines an axis whose spacing exceeds the smallest scale, by
//!   `f = ceil(spacing / sigma_min)` (at most [`MAX_REFINEMENT`]), so that the sampled Gaussian
//!   derivative kernels span at least one voxel per sigma ([`refinement_factors`]).
//! - The RST (consistent rule), when asked (`Request::refine_slices`), refines the slice axis z
//!   until its spacing is at most four ray steps or the finest spacing
//!   ([`rst_refinement_factors`]); its opacity lengths L_i still come from the acquired spacing
//!   (refinement adds no sharpness), and it is evaluated at the input voxels only. The structure tensor and the paper's literal rule run on the input grid.
//!
//! The refined grid keeps every input voxel centre as a grid point (voxel `i` becomes voxel
//! `f * i`), values between them are linear along that axis, and the features are read back at
//! the input centres exactly: never by interpolating features or eigenvalues (which would break
//! the magnitude order of eigenvalues and blur peaks).

use super::{Grid, parallel};

/// The largest refinement factor of one axis (a 5 mm axis with sigma 0.7 mm needs 8).
pub const MAX_REFINEMENT: usize = 8;

/// Per-axis integer refinement factors for scales down to `sigma_min_mm` (1 = as is).
pub fn refinement_factors(grid: &Grid, sigma_min_mm: f64) -> [usize; 3] {
    std::array::from_fn(|a| {
        let s = grid.spacing_mm[a];
        // NaN scales or spacings refine nothing.
        let refine = sigma_min_mm > 0.0 && s > sigma_min_mm;
        if grid.dims[a] < 2 || !refine {
            return 1;
        }
        ((s / sigma_min_mm - 1e-9).ceil() as usize).clamp(1, MAX_REFINEMENT)
    })
}

/// The RST's refinement: the slice axis z by `f = ceil(s_z / max(4 dr, s_min))` (at most
/// [`MAX_REFINEMENT`]), with `dr` the ray step and `s_min` the finest spacing; x and y as they are.
/// An isotropic grid is never refined; 0.6 x 0.6 x 5 mm at dr 0.25 mm is refined by 5 (to 1 mm),
/// 0.7 x 0.7 x 2.5 mm by 3.
pub fn rst_refinement_factors(grid: &Grid, step_mm: f64) -> [usize; 3] {
    let s_min = (0..3)
        .filter(|&a| grid.dims[a] > 1)
        .map(|a| grid.spacing_mm[a])
        .fold(f64::INFINITY, f64::min);
    let target = (4.0 * step_mm).max(s_min);
    let s = grid.spacing_mm[2];
    // NaN steps or spacings refine nothing.
    if grid.dims[2] < 2 || !(target.is_finite() && target > 0.0 && s > target) {
        return [1; 3];
    }
    [
        1,
        1,
        ((s / target - 1e-9).ceil() as usize).clamp(1, MAX_REFINEMENT),
    ]
}

/// The grid refined by `factors`: `(n - 1) * f + 1` voxels at spacing `s / f`, the same first
/// and last voxel centre.
pub fn refined_grid(grid: &Grid, factors: [usize; 3]) -> Grid {
    let mut out = *grid;
    for (a, &f) in factors.iter().enumerate() {
        let f = f.max(1);
        if f > 1 && grid.dims[a] > 1 {
            out.dims[a] = (grid.dims[a] - 1) * f + 1;
            out.spacing_mm[a] = grid.spacing_mm[a] / f as f64;
        }
    }
    out
}

/// The linear tap of refined index `t` (whole-grid) on a source axis of `n` voxels refined by
/// `f`: the source voxels `(i0, i1)` and the weight of `i1`. Exact: `t = f * i` gives `(i, _, 0)`.
pub fn refine_tap(t: usize, f: usize, n: usize) -> (usize, usize, f64) {
    let f = f.max(1);
    let last = n.max(1) - 1;
    let i0 = (t / f).min(last);
    let rem = if t / f > last { 0 } else { t % f };
    (i0, (i0 + 1).min(last), rem as f64 / f as f64)
}

/// `values` on `grid` refined by `factors` (linear along refined axes; input voxels kept
/// bit for bit).
pub fn refine_linear(grid: &Grid, values: &[f32], factors: [usize; 3]) -> (Grid, Vec<f32>) {
    let fine = refined_grid(grid, factors);
    if fine == *grid {
        return (*grid, values.to_vec());
    }
    let taps: [Vec<(usize, usize, f64)>; 3] = std::array::from_fn(|a| {
        (0..fine.dims[a])
            .map(|t| refine_tap(t, factors[a], grid.dims[a]))
            .collect()
    });
    (fine, trilinear_at_taps(grid, values, &fine, &taps))
}

/// The values of `to` by trilinear interpolation of `values` (on `from`) at per-axis `taps`:
/// for every index of `to` along an axis, the two source indices and the upper one's weight.
fn trilinear_at_taps(
    from: &Grid,
    values: &[f32],
    to: &Grid,
    taps: &[Vec<(usize, usize, f64)>; 3],
) -> Vec<f32> {
    let plane = to.dims[0] * to.dims[1];
    let mut out = vec![0.0f32; to.len()];
    parallel::for_each_chunk(&mut out, plane, |k, slice| {
        let (z0, z1, wz) = taps[2][k];
        for j in 0..to.dims[1] {
            let (y0, y1, wy) = taps[1][j];
            for i in 0..to.dims[0] {
                let (x0, x1, wx) = taps[0][i];
                slice[i + to.dims[0] * j] =
                    trilinear(from, values, [x0, x1], [y0, y1], [z0, z1], [wx, wy, wz]);
            }
        }
    });
    out
}

/// Trilinear interpolation with f64 arithmetic; a zero weight takes the first voxel exactly.
pub fn trilinear(
    grid: &Grid,
    values: &[f32],
    x: [usize; 2],
    y: [usize; 2],
    z: [usize; 2],
    w: [f64; 3],
) -> f32 {
    let v = |i: usize, j: usize, k: usize| f64::from(values[grid.index(i, j, k)]);
    let lerp = |a: f64, b: f64, w: f64| if w == 0.0 { a } else { a + (b - a) * w };
    let c00 = lerp(v(x[0], y[0], z[0]), v(x[1], y[0], z[0]), w[0]);
    let c10 = lerp(v(x[0], y[1], z[0]), v(x[1], y[1], z[0]), w[0]);
    let c01 = lerp(v(x[0], y[0], z[1]), v(x[1], y[0], z[1]), w[0]);
    let c11 = lerp(v(x[0], y[1], z[1]), v(x[1], y[1], z[1]), w[0]);
    lerp(lerp(c00, c10, w[1]), lerp(c01, c11, w[1]), w[2]) as f32
}

/// The values of `fine` (refined from `coarse` by `factors`) at the voxel centres of `coarse`:
/// voxel `(i, j, k)` takes fine voxel `(f_x i, f_y j, f_z k)`, with no interpolation.
pub fn subsample(fine: &Grid, values: &[f32], factors: [usize; 3], coarse: &Grid) -> Vec<f32> {
    let plane = coarse.dims[0] * coarse.dims[1];
    let mut out = vec![0.0f32; coarse.len()];
    let f = factors.map(|f| f.max(1));
    parallel::for_each_chunk(&mut out, plane, |k, slice| {
        for j in 0..coarse.dims[1] {
            for i in 0..coarse.dims[0] {
                slice[i + coarse.dims[0] * j] = values[fine.index(f[0] * i, f[1] * j, f[2] * k)];
            }
        }
    });
    out
}

/// Samples `values` (on `from`) at the voxel centres of `to` (same origin, grid mm) by
/// trilinear interpolation, clamping at the borders: a general resampler for tests and tools
/// (the feature pipelines use [`refine_linear`] and [`subsample`]).
pub fn resample_linear(from: &Grid, values: &[f32], to: &Grid) -> Vec<f32> {
    // Per axis, the two source indices and the weight of the upper one, for every target index.
    let taps: [Vec<(usize, usize, f64)>; 3] = std::array::from_fn(|a| {
        (0..to.dims[a])
            .map(|t| {
                let max = (from.dims[a] - 1) as f64;
                let u = (t as f64 * to.spacing_mm[a] / from.spacing_mm[a]).clamp(0.0, max);
                let f = u.floor();
                let i0 = f as usize;
                (i0, (i0 + 1).min(from.dims[a] - 1), u - f)
            })
            .collect()
    });
    trilinear_at_taps(from, values, to, &taps)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_axes_coarser_than_the_smallest_scale_are_refined_by_an_integer() {
        let g = Grid::new([4, 5, 6], [0.7, 0.7, 5.0]);
        assert_eq!(refinement_factors(&g, 1.5), [1, 1, 4]);
        assert_eq!(refinement_factors(&g, 5.0), [1, 1, 1]);
        assert_eq!(refinement_factors(&g, 0.1), [7, 7, MAX_REFINEMENT]);
        let iso = Grid::new([4, 5, 6], [1.5, 1.5, 1.5]);
        assert_eq!(refinement_factors(&iso, 1.5), [1, 1, 1]);
        assert_eq!(refinement_factors(&iso, 1.0), [2, 2, 2]);
        let fine = refined_grid(&g, [1, 1, 4]);
        assert_eq!(fine.dims, [4, 5, 21]);
        assert!((fine.spacing_mm[2] - 1.25).abs() < 1e-12);
    }

    #[test]
    fn refinement_keeps_input_voxels_and_subsampling_returns_them_bit_for_bit() {
        let grid = Grid::new([4, 5, 6], [0.7, 2.1, 5.0]);
        let v: Vec<f32> = (0..grid.len())
            .map(|n| {
                let [i, j, k] = grid.ijk(n);
                ((i * 7 + j * 3 + k * 11) as f32).sin() * 100.0 + 0.1
            })
            .collect();
        let f = [1, 2, 4];
        let (fine, up) = refine_linear(&grid, &v, f);
        assert_eq!(fine.dims, [4, 9, 21]);
        let back = subsample(&fine, &up, f, &grid);
        assert_eq!(back, v);
        // Between input slices the values are linear.
        let a = up[fine.index(1, 2, 4)];
        let b = up[fine.index(1, 2, 8)];
        let mid = up[fine.index(1, 2, 6)];
        assert!((mid - 0.5 * (a + b)).abs() < 1e-4);
    }
}
