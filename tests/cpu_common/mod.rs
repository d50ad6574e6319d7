//! Helpers shared by the CPU reference tests (tests/cpu_*.rs): render a phantom and probe the
//! Hessian or the RST at phantom-frame points.
#![allow(dead_code)]

use shapecast::cpu::{self, FeatureMap, GradientVolume, Grid, RstParams};
use shapecast::phantom::Phantom;

/// Rendered phantom on a grid, with the frame mapping kept.
pub struct Rendered {
    pub phantom: Phantom,
    pub grid: Grid,
    pub values: Vec<f32>,
}

impl Rendered {
    pub fn new(phantom: Phantom, spacing_mm: [f64; 3]) -> Self {
        Self::noisy(phantom, spacing_mm, 0.0, 0)
    }

    pub fn noisy(phantom: Phantom, spacing_mm: [f64; 3], noise_hu: f64, seed: u64) -> Self {
        let v = phantom.render_noisy(spacing_mm, noise_hu, seed);
        Self {
            grid: Grid::of(&v),
            values: v.to_f32(),
            phantom,
        }
    }

    /// The voxel nearest to a phantom-frame point.
    pub fn voxel(&self, p_mm: [f64; 3]) -> [usize; 3] {
        self.grid.nearest_voxel(self.phantom.grid_mm(p_mm))
    }

    /// Eigenvalues of the gamma-normalised Hessian at the voxel nearest to `p_mm`.
    pub fn hessian_eigen(&self, p_mm: [f64; 3], sigma_mm: f64) -> [f64; 3] {
        let h = cpu::hessian_at(&self.grid, &self.values, self.voxel(p_mm), sigma_mm, true);
        cpu::eigenvalues_sorted(&h)
    }

    pub fn gradient(&self, sigma_g_mm: f64) -> GradientVolume {
        GradientVolume::new(&self.grid, &self.values, sigma_g_mm)
    }
}

/// RST eigenvalues at the phantom-frame point `p_mm` (exactly there, by trilinear sampling).
pub fn rst_eigen(
    r: &Rendered,
    gv: &GradientVolume,
    p_mm: [f64; 3],
    params: &RstParams,
) -> [f64; 3] {
    cpu::rst_eigen_at(gv, r.phantom.grid_mm(p_mm), params)
}

/// Simple-map (eq. 1) blobness |l2| of eigenvalues, 0 unless all three are negative.
pub fn blobness(l: [f64; 3]) -> f64 {
    cpu::map_eigenvalues(l, FeatureMap::Simple)[2]
}

/// Simple-map vesselness |l1|.
pub fn vesselness(l: [f64; 3]) -> f64 {
    cpu::map_eigenvalues(l, FeatureMap::Simple)[0]
}

/// Coefficient of variation (population standard deviation over mean).
pub fn cv(xs: &[f64]) -> f64 {
    let n = xs.len() as f64;
    let m = xs.iter().sum::<f64>() / n;
    (xs.iter().map(|x| (x - m).powi(2)).sum::<f64>() / n).sqrt() / m
}
