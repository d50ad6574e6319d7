//! The general structure tensor (paper eq. 5), for comparison only: the six components of
//! g g^T, each smoothed with a Gaussian of the neighbourhood scale rho.

use super::eigen::eigenvalues_sorted;
use super::features::{FeatureMap, map_eigenvalues, sym_at};
use super::gaussian::gaussian_smooth;
use super::rst::GradientVolume;
use super::{Components3, Grid, parallel};

/// The six smoothed components `[xx, yy, zz, xy, xz, yz]` of g g^T (g from `gv`, i.e. sigma_g
/// smoothing then central differences), neighbourhood scale `rho_mm`.
pub fn structure_tensor_volume(gv: &GradientVolume, rho_mm: f64) -> [Vec<f32>; 6] {
    let grid: Grid = gv.grid;
    const PAIRS: [(usize, usize); 6] = [(0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2)];
    PAIRS.map(|(a, b)| {
        let prod: Vec<f32> = gv.gradient.iter().map(|g| g[a] * g[b]).collect();
        gaussian_smooth(&grid, &prod, rho_mm)
    })
}

/// Eigenvalues (all >= 0) sorted by magnitude, per voxel.
pub fn structure_tensor_eigen(gv: &GradientVolume, rho_mm: f64) -> Components3 {
    let s = structure_tensor_volume(gv, rho_mm);
    let per: Vec<[f32; 3]> = parallel::map_indices(gv.grid.len(), |i| {
        eigenvalues_sorted(&sym_at(&s, i)).map(|v| v as f32)
    });
    std::array::from_fn(|c| per.iter().map(|v| v[c]).collect())
}

/// `[V, A, B]` of the structure tensor. Its eigenvalues are never negative, so they are mapped
/// as a bright structure's would be (the map applied to `-l`): B is then the third eigenvalue,
/// the quantity the paper's fig. 6d shows.
pub fn structure_tensor_features(gv: &GradientVolume, rho_mm: f64, map: FeatureMap) -> Components3 {
    let s = structure_tensor_volume(gv, rho_mm);
    let per: Vec<[f32; 3]> = parallel::map_indices(gv.grid.len(), |i| {
        let l = eigenvalues_sorted(&sym_at(&s, i));
        map_eigenvalues(l.map(|v| -v), map).map(|v| v as f32)
    });
    std::array::from_fn(|c| per.iter().map(|v| v[c]).collect())
}
