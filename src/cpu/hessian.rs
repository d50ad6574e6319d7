//! Hessian by separable Gaussian derivative kernels (docs/science.md, Hessian features, item 1),
//! for a whole volume and at one voxel. Components per mm^2, optionally gamma-normalised
//! (multiplied by sigma_mm^2, Lindeberg's gamma = 1).

use super::Grid;
use super::eigen::Sym3;
use super::gaussian::{GaussianOrder, convolve_axis, derivative_kernel};

/// The three kernels (orders 0, 1, 2) of `sigma_mm` on each axis.
fn kernels(grid: &Grid, sigma_mm: f64) -> [[Vec<f64>; 3]; 3] {
    std::array::from_fn(|axis| {
        let s = grid.spacing_mm[axis];
        [
            derivative_kernel(sigma_mm, s, GaussianOrder::Smooth),
            derivative_kernel(sigma_mm, s, GaussianOrder::First),
            derivative_kernel(sigma_mm, s, GaussianOrder::Second),
        ]
    })
}

/// The derivative orders `(x, y, z)` of the six components `[xx, yy, zz, xy, xz, yz]`.
const ORDERS: [[usize; 3]; 6] = [
    [2, 0, 0],
    [0, 2, 0],
    [0, 0, 2],
    [1, 1, 0],
    [1, 0, 1],
    [0, 1, 1],
];

/// The six Hessian components `[xx, yy, zz, xy, xz, yz]` of the whole volume at `sigma_mm`,
/// multiplied by `sigma_mm^2` when `normalised` (gamma = 1).
pub fn hessian_volume(
    grid: &Grid,
    values: &[f32],
    sigma_mm: f64,
    normalised: bool,
) -> [Vec<f32>; 6] {
    let k = kernels(grid, sigma_mm);
    // x pass once per order, then y and z per component.
    let x_pass: [Vec<f32>; 3] = std::array::from_fn(|o| convolve_axis(grid, values, 0, &k[0][o]));
    let scale = if normalised {
        (sigma_mm * sigma_mm) as f32
    } else {
        1.0
    };
    ORDERS.map(|[ox, oy, oz]| {
        let y = convolve_axis(grid, &x_pass[ox], 1, &k[1][oy]);
        let mut z = convolve_axis(grid, &y, 2, &k[2][oz]);
        if scale != 1.0 {
            z.iter_mut().for_each(|v| *v *= scale);
        }
        z
    })
}

/// The Hessian at one voxel, identical in arithmetic to [`hessian_volume`] up to f32 rounding of
/// intermediate passes (which this one keeps in f64). For tests and probing single points.
pub fn hessian_at(
    grid: &Grid,
    values: &[f32],
    ijk: [usize; 3],
    sigma_mm: f64,
    normalised: bool,
) -> Sym3 {
    let k = kernels(grid, sigma_mm);
    let clamp = |p: i64, a: usize| p.clamp(0, grid.dims[a] as i64 - 1) as usize;
    let r: [i64; 3] = std::array::from_fn(|a| (k[a][0].len() / 2) as i64);
    let mut out = [0.0f64; 6];
    for (tz, dz) in (-r[2]..=r[2]).enumerate() {
        let z = clamp(ijk[2] as i64 + dz, 2);
        // y-then-x reduced sums for every (ox, oy) pair needed.
        let mut xy = [[0.0f64; 3]; 3];
        for (ty, dy) in (-r[1]..=r[1]).enumerate() {
            let y = clamp(ijk[1] as i64 + dy, 1);
            let mut xs = [0.0f64; 3];
            for (tx, dx) in (-r[0]..=r[0]).enumerate() {
                let x = clamp(ijk[0] as i64 + dx, 0);
                let v = f64::from(values[grid.index(x, y, z)]);
                for (o, acc) in xs.iter_mut().enumerate() {
                    *acc += k[0][o][tx] * v;
                }
            }
            for (ox, row) in xy.iter_mut().enumerate() {
                for (oy, acc) in row.iter_mut().enumerate() {
                    *acc += k[1][oy][ty] * xs[ox];
                }
            }
        }
        for (c, [ox, oy, oz]) in ORDERS.iter().enumerate() {
            out[c] += k[2][*oz][tz] * xy[*ox][*oy];
        }
    }
    if normalised {
        out.iter_mut().for_each(|v| *v *= sigma_mm * sigma_mm);
    }
    out
}
