//! Eigenvalue feature maps (paper eq. 1 and eq. 2, Frangi 1998) and the multi-scale Hessian
//! features with gamma = 1 normalisation (docs/science.md, Hessian features, items 2 and 4).

use super::eigen::{Sym3, eigenvalues_sorted, frobenius};
use super::hessian::hessian_volume;
use super::{Components3, Grid, parallel};

/// How three eigenvalues sorted by magnitude become `[V, A, B]`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum FeatureMap {
    /// Paper eq. 1: V = |l1| if l0 <= l1 < 0; A = |l1| if l0 >= l1 > 0; B = |l2| if all < 0.
    Simple,
    /// Paper eq. 2 (Li et al. 2003): V = |l1|(|l1|-|l2|)/|l0|, A likewise for positive,
    /// B = |l2|^2/|l0|.
    #[default]
    Li,
}

/// `[V, A, B]` of eigenvalues `l` sorted by magnitude.
pub fn map_eigenvalues(l: [f64; 3], map: FeatureMap) -> [f64; 3] {
    let [l0, l1, l2] = l;
    let (a0, a1, a2) = (l0.abs(), l1.abs(), l2.abs());
    let bright_tube = l0 < 0.0 && l1 < 0.0;
    let dark_tube = l0 > 0.0 && l1 > 0.0;
    let bright_blob = bright_tube && l2 < 0.0;
    match map {
        FeatureMap::Simple => [
            if bright_tube { a1 } else { 0.0 },
            if dark_tube { a1 } else { 0.0 },
            if bright_blob { a2 } else { 0.0 },
        ],
        FeatureMap::Li => {
            // |l0| > 0 whenever one of the conditions holds (it is the largest magnitude).
            let tube = if a0 > 0.0 { a1 * (a1 - a2) / a0 } else { 0.0 };
            [
                if bright_tube { tube } else { 0.0 },
                if dark_tube { tube } else { 0.0 },
                if bright_blob { a2 * a2 / a0 } else { 0.0 },
            ]
        }
    }
}

/// Frangi's vesselness (alpha = beta = 0.5) of eigenvalues sorted by magnitude, for bright
/// tubes (`bright = true`: l0, l1 < 0) or dark ones. `c` is the structureness scale.
pub fn frangi(l: [f64; 3], c: f64, bright: bool) -> f64 {
    let [l0, l1, l2] = l;
    let right_sign = if bright {
        l0 < 0.0 && l1 < 0.0
    } else {
        l0 > 0.0 && l1 > 0.0
    };
    if !right_sign {
        return 0.0;
    }
    let (alpha, beta) = (0.5, 0.5);
    let ra2 = (l1 / l0).powi(2);
    let rb2 = l2 * l2 / (l0 * l1).abs();
    let s2 = l0 * l0 + l1 * l1 + l2 * l2;
    let c2 = if c > 0.0 { c * c } else { f64::MIN_POSITIVE };
    (1.0 - (-ra2 / (2.0 * alpha * alpha)).exp())
        * (-rb2 / (2.0 * beta * beta)).exp()
        * (1.0 - (-s2 / (2.0 * c2)).exp())
}

/// Frangi's default c as scikit-image computes it: half the largest Frobenius norm of the
/// (normalised) Hessian over the whole volume given.
pub fn frangi_default_c(hessian: &[Vec<f32>; 6]) -> f64 {
    let n = hessian[0].len();
    let max = (0..n)
        .map(|i| frobenius(&sym_at(hessian, i)))
        .fold(0.0f64, f64::max);
    0.5 * max
}

/// The six components at linear index `i` of a component-per-volume Hessian.
#[inline]
pub fn sym_at(h: &[Vec<f32>; 6], i: usize) -> Sym3 {
    std::array::from_fn(|c| f64::from(h[c][i]))
}

/// Which map the multi-scale Hessian features use.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum HessianMethod {
    Map(FeatureMap),
    /// V = Frangi for bright tubes, A = Frangi for dark tubes, B = 0 (Frangi has no blobness).
    /// `c: None` takes scikit-image's default per scale over the whole volume.
    Frangi {
        c: Option<f64>,
    },
}

/// `[V, A, B]` of the sigma^2-normalised Hessian, per voxel and feature the maximum over the
/// scales `sigmas_mm`.
pub fn hessian_features_multiscale(
    grid: &Grid,
    values: &[f32],
    sigmas_mm: &[f64],
    method: HessianMethod,
) -> Components3 {
    let n = grid.len();
    let mut out: Components3 = std::array::from_fn(|_| vec![0.0f32; n]);
    for &sigma_mm in sigmas_mm {
        let h = hessian_volume(grid, values, sigma_mm, true);
        let c = match method {
            HessianMethod::Frangi { c: Some(c) } => c,
            HessianMethod::Frangi { c: None } => frangi_default_c(&h),
            HessianMethod::Map(_) => 0.0,
        };
        let per_voxel: Vec<[f32; 3]> = parallel::map_indices(n, |i| {
            let l = eigenvalues_sorted(&sym_at(&h, i));
            let f = match method {
                HessianMethod::Map(map) => map_eigenvalues(l, map),
                HessianMethod::Frangi { .. } => [frangi(l, c, true), frangi(l, c, false), 0.0],
            };
            f.map(|v| v as f32)
        });
        for (i, f) in per_voxel.iter().enumerate() {
            for c in 0..3 {
                out[c][i] = out[c][i].max(f[c]);
            }
        }
    }
    out
}

/// Eigenvalues `[l0, l1, l2]` per voxel of the sigma^2-normalised Hessian at the scale whose
/// normalised Hessian has the largest Frobenius norm (docs/science.md, Hessian features, item 5).
pub fn hessian_eigen_multiscale(grid: &Grid, values: &[f32], sigmas_mm: &[f64]) -> Components3 {
    let n = grid.len();
    let mut out: Components3 = std::array::from_fn(|_| vec![0.0f32; n]);
    let mut best_norm = vec![-1.0f64; n];
    for &sigma_mm in sigmas_mm {
        let h = hessian_volume(grid, values, sigma_mm, true);
        let per_voxel: Vec<(f64, [f64; 3])> = parallel::map_indices(n, |i| {
            let m = sym_at(&h, i);
            (frobenius(&m), eigenvalues_sorted(&m))
        });
        for (i, (norm, l)) in per_voxel.into_iter().enumerate() {
            if norm > best_norm[i] {
                best_norm[i] = norm;
                for c in 0..3 {
                    out[c][i] = l[c] as f32;
                }
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn maps_follow_the_paper() {
        let sphere = [-3.0, -2.0, -1.0];
        assert_eq!(map_eigenvalues(sphere, FeatureMap::Simple), [2.0, 0.0, 1.0]);
        let li = map_eigenvalues(sphere, FeatureMap::Li);
        assert!((li[0] - 2.0 * 1.0 / 3.0).abs() < 1e-12 && (li[2] - 1.0 / 3.0).abs() < 1e-12);
        assert_eq!(
            map_eigenvalues([3.0, 2.0, -1.0], FeatureMap::Simple),
            [0.0, 2.0, 0.0]
        );
        assert_eq!(
            map_eigenvalues([-3.0, 2.0, 1.0], FeatureMap::Simple),
            [0.0; 3]
        );
        assert!(frangi([-4.0, -4.0, 0.0], 1.0, true) > 0.8);
        assert_eq!(frangi([-4.0, -4.0, 0.0], 1.0, false), 0.0);
    }
}
