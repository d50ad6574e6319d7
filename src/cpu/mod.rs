//! The CPU reference of every feature (docs/science.md): plain Rust that follows the equations, the
//! twin every GPU kernel is tested against.
//!
//! Conventions of this module (the GPU kernels must match them):
//! - Values are physical (HU for CT) as `f32`, voxel index `i` fastest (see `volume.rs`);
//!   arithmetic inside a kernel is `f64`, results are stored as `f32`.
//! - Positions are in "grid millimetres": voxel `(i, j, k)` sits at
//!   `(i * s_x, j * s_y, k * s_z)`. The computation works in the voxel frame; direction cosines
//!   do not enter (the features are invariant to a rotation of the frame up to sampling).
//! - Borders are replicated: an index outside the grid is clamped to the nearest voxel, for
//!   convolutions, central differences and trilinear sampling alike.
//! - Feature outputs are three components `[V, A, B]` (vesselness, airwayness, blobness) or three
//!   eigenvalues sorted by magnitude `[l0, l1, l2]`, `|l0| >= |l1| >= |l2|`.

pub mod conspicuity;
pub mod eigen;
pub mod features;
pub mod findings;
pub mod gaussian;
pub mod hessian;
pub mod hot_spots;
pub mod parallel;
pub mod pipeline;
pub mod rays;
pub mod resample;
pub mod rst;
pub mod structure_tensor;
#[cfg(test)]
pub(crate) mod testing;
pub mod tf;

pub use eigen::{Sym3, eigenvalues_sorted};
pub use features::{
    FeatureMap, frangi, frangi_default_c, hessian_eigen_multiscale, hessian_features_multiscale,
    map_eigenvalues,
};
pub use gaussian::{
    GaussianOrder, convolve_axis, derivative_kernel, gaussian_smooth, kernel_radius_vox,
};
pub use hessian::{hessian_at, hessian_volume};
pub use rays::ray_set;
pub use resample::{
    refine_linear, refined_grid, refinement_factors, resample_linear, rst_refinement_factors,
    subsample,
};
pub use rst::{
    GradientVolume, OpacityRule, RstParams, consistent_ray, ray_lengths_mm, rst_eigen,
    rst_eigen_at, rst_features, rst_tensor_at,
};
pub use structure_tensor::{structure_tensor_eigen, structure_tensor_features};
pub use tf::{Preset, TransferFunction, auto_transfer_function, estimate_noise_sigma};

/// Physical values at linear voxel indices (i fastest): a slice of f32, or a volume's compact
/// voxels read through its rescale, so that a computation over a CT (a findings list, the lung
/// mask, the noise) needs no f32 copy of it.
pub trait Samples {
    fn count(&self) -> usize;
    fn at(&self, n: usize) -> f32;
}

impl Samples for [f32] {
    fn count(&self) -> usize {
        self.len()
    }
    #[inline]
    fn at(&self, n: usize) -> f32 {
        self[n]
    }
}

impl Samples for Vec<f32> {
    fn count(&self) -> usize {
        self.len()
    }
    #[inline]
    fn at(&self, n: usize) -> f32 {
        self[n]
    }
}

/// The stored values ([`crate::volume::Volume::value`]): where a voxel is not finite this is
/// not what [`crate::volume::Volume::to_f32`] gives (it replaces such voxels); a caller that
/// must agree with it reads through the volume only when `non_finite_count()` is 0.
impl Samples for crate::volume::Volume {
    fn count(&self) -> usize {
        self.voxel_count()
    }
    #[inline]
    fn at(&self, n: usize) -> f32 {
        self.value(n)
    }
}

/// The sampling grid of a volume: voxel counts and spacing (mm) per axis.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Grid {
    pub dims: [usize; 3],
    pub spacing_mm: [f64; 3],
}

impl Grid {
    pub fn new(dims: [usize; 3], spacing_mm: [f64; 3]) -> Self {
        Self { dims, spacing_mm }
    }

    /// The grid of a [`crate::Volume`] (geometry beyond spacing is kept by the caller).
    pub fn of(volume: &crate::Volume) -> Self {
        Self::new(volume.dims, volume.spacing_mm)
    }

    pub fn len(&self) -> usize {
        self.dims[0] * self.dims[1] * self.dims[2]
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    #[inline]
    pub fn index(&self, i: usize, j: usize, k: usize) -> usize {
        i + self.dims[0] * (j + self.dims[1] * k)
    }

    /// `(i, j, k)` of a linear index.
    #[inline]
    pub fn ijk(&self, index: usize) -> [usize; 3] {
        let i = index % self.dims[0];
        let j = (index / self.dims[0]) % self.dims[1];
        let k = index / (self.dims[0] * self.dims[1]);
        [i, j, k]
    }

    /// Grid-mm position of a voxel centre.
    #[inline]
    pub fn position_mm(&self, ijk: [usize; 3]) -> [f64; 3] {
        std::array::from_fn(|a| ijk[a] as f64 * self.spacing_mm[a])
    }

    /// The voxel nearest to a grid-mm position (clamped into the grid).
    pub fn nearest_voxel(&self, p_mm: [f64; 3]) -> [usize; 3] {
        std::array::from_fn(|a| {
            let v = (p_mm[a] / self.spacing_mm[a]).round();
            v.clamp(0.0, (self.dims[a].max(1) - 1) as f64) as usize
        })
    }

    pub fn min_spacing_mm(&self) -> f64 {
        self.spacing_mm
            .iter()
            .copied()
            .fold(f64::INFINITY, f64::min)
    }
}

/// Three feature or eigenvalue components, one `f32` volume each.
pub type Components3 = [Vec<f32>; 3];
