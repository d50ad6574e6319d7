//! Linear resampling of thick axes to 1.25 mm or finer before features, and back onto the input
//! grid afterwards (SCIENCE.md, "What real scans taught us", item 4).

use super::{Grid, parallel};

/// The largest spacing features are computed on.
pub const MAX_FEATURE_SPACING_MM: f64 = 1.25;

/// The grid with every axis whose spacing exceeds `max_spacing_mm` refined so that the same
/// extent (first to last voxel centre) is covered with spacing <= `max_spacing_mm`.
pub fn refined_grid(grid: &Grid, max_spacing_mm: f64) -> Grid {
    let mut out = *grid;
    for a in 0..3 {
        let (n, s) = (grid.dims[a], grid.spacing_mm[a]);
        if s > max_spacing_mm && n > 1 {
            let extent = (n - 1) as f64 * s;
            let m = (extent / max_spacing_mm - 1e-9).ceil() as usize + 1;
            out.dims[a] = m;
            out.spacing_mm[a] = extent / (m - 1) as f64;
        }
    }
    out
}

/// Samples `values` (on `from`) at the voxel centres of `to` (same origin, grid mm) by
/// trilinear interpolation, clamping at the borders. Resampling to a finer or a coarser grid.
pub fn resample_linear(from: &Grid, values: &[f32], to: &Grid) -> Vec<f32> {
    let plane = to.dims[0] * to.dims[1];
    let mut out = vec![0.0f32; to.len()];
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
    parallel::for_each_chunk(&mut out, plane, |k, slice| {
        let (z0, z1, wz) = taps[2][k];
        for j in 0..to.dims[1] {
            let (y0, y1, wy) = taps[1][j];
            for i in 0..to.dims[0] {
                let (x0, x1, wx) = taps[0][i];
                let v = |x: usize, y: usize, z: usize| f64::from(values[from.index(x, y, z)]);
                let lerp = |a: f64, b: f64, w: f64| a + (b - a) * w;
                let c00 = lerp(v(x0, y0, z0), v(x1, y0, z0), wx);
                let c10 = lerp(v(x0, y1, z0), v(x1, y1, z0), wx);
                let c01 = lerp(v(x0, y0, z1), v(x1, y0, z1), wx);
                let c11 = lerp(v(x0, y1, z1), v(x1, y1, z1), wx);
                let c0 = lerp(c00, c10, wy);
                let c1 = lerp(c01, c11, wy);
                slice[i + to.dims[0] * j] = lerp(c0, c1, wz) as f32;
            }
        }
    });
    out
}

/// Resamples thick axes to <= 1.25 mm; returns the grid used and the values on it (a copy of
/// the input when nothing is thick).
pub fn resample_thick_axes(grid: &Grid, values: &[f32]) -> (Grid, Vec<f32>) {
    let fine = refined_grid(grid, MAX_FEATURE_SPACING_MM);
    if fine == *grid {
        return (*grid, values.to_vec());
    }
    let v = resample_linear(grid, values, &fine);
    (fine, v)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn thick_axis_is_refined_and_linear_data_survives_the_round_trip() {
        let grid = Grid::new([4, 5, 6], [0.7, 0.7, 5.0]);
        let fine = refined_grid(&grid, MAX_FEATURE_SPACING_MM);
        assert_eq!(fine.dims, [4, 5, 21]);
        assert!((fine.spacing_mm[2] - 1.25).abs() < 1e-12);
        let v: Vec<f32> = (0..grid.len())
            .map(|n| {
                let [i, j, k] = grid.ijk(n);
                (i + 2 * j) as f32 + 3.0 * k as f32
            })
            .collect();
        let (g2, up) = resample_thick_axes(&grid, &v);
        assert_eq!(g2, fine);
        let back = resample_linear(&fine, &up, &grid);
        for (a, b) in v.iter().zip(&back) {
            assert!((a - b).abs() < 1e-4);
        }
    }
}
