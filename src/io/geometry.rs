//! Turning the axis vectors a header declares into the `Volume` geometry (spacing + unit
//! direction columns), with the checks every format needs (finite, non-degenerate, sheared).

use glam::{DMat3, DVec3};

use super::LoadError;
use crate::volume::{Modality, Volume, Voxels};

/// Where a header puts the voxels, checked: what a `Volume` takes from the geometry.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Grid {
    pub spacing_mm: [f64; 3],
    pub origin_mm: [f64; 3],
    pub direction: DMat3,
}

/// The grid a header declares: `axes` the LPS vectors of one step along i, j, k and `origin`
/// the LPS centre of voxel (0, 0, 0), each with the header field it came from (for errors),
/// checked by [`from_axis_vectors`] and [`check_origin`].
pub(crate) fn checked_grid(
    file: &str,
    axes: (&str, [DVec3; 3]),
    origin: (&str, DVec3),
    warnings: &mut Vec<String>,
) -> Result<Grid, LoadError> {
    let (spacing_mm, direction) = from_axis_vectors(file, axes.0, axes.1, warnings)?;
    let origin_mm = check_origin(file, origin.0, origin.1)?;
    Ok(Grid {
        spacing_mm,
        origin_mm,
        direction,
    })
}

impl Grid {
    /// The volume of `voxels` on this grid, values as stored (slope 1, intercept 0), modality
    /// unknown: a loader whose header says otherwise overrides those fields.
    pub(crate) fn volume(
        self,
        dims: [usize; 3],
        voxels: Voxels,
        source: String,
        warnings: Vec<String>,
    ) -> Volume {
        Volume {
            dims,
            spacing_mm: self.spacing_mm,
            origin_mm: self.origin_mm,
            direction: self.direction,
            voxels,
            value_slope: 1.0,
            value_intercept: 0.0,
            modality: Modality::Unknown,
            pet: None,
            frame_of_reference: None,
            source,
            warnings,
        }
    }
}

/// Spacing and direction columns from the three LPS vectors that one voxel step along i, j, k
/// moves (the columns of the 3x3 part of world_from_voxel). Refuses zero, non-finite or
/// coplanar axes; notes a sheared (non-orthogonal) grid such as a gantry-tilted CT, whose
/// geometry is kept as it is rather than squared up.
pub(crate) fn from_axis_vectors(
    file: &str,
    field: &str,
    axes_lps: [DVec3; 3],
    warnings: &mut Vec<String>,
) -> Result<([f64; 3], DMat3), LoadError> {
    let mut spacing_mm = [0.0; 3];
    let mut cols = [DVec3::ZERO; 3];
    for (a, v) in axes_lps.iter().enumerate() {
        let len = v.length();
        if !len.is_finite() || len <= 0.0 || !v.is_finite() {
            return Err(LoadError::header(
                file,
                field,
                format!(
                    "axis {a} has length {len} (vector {v:?}); expected a finite non-zero step"
                ),
            ));
        }
        spacing_mm[a] = len;
        cols[a] = *v / len;
    }
    let direction = DMat3::from_cols(cols[0], cols[1], cols[2]);
    let det = direction.determinant();
    if !det.is_finite() || det.abs() < 1e-6 {
        return Err(LoadError::header(
            file,
            field,
            "the three axes are (nearly) coplanar, so the grid has no volume",
        ));
    }
    let max_dot = [(0, 1), (0, 2), (1, 2)]
        .iter()
        .map(|&(a, b)| cols[a].dot(cols[b]).abs())
        .fold(0.0, f64::max);
    if max_dot > 1e-4 {
        let angle_deg = max_dot.clamp(0.0, 1.0).asin().to_degrees();
        warnings.push(format!(
            "the voxel axes are not orthogonal (sheared by about {angle_deg:.2} degrees, as from a gantry tilt); the geometry is kept as sheared"
        ));
    }
    Ok((spacing_mm, direction))
}

/// Checks that an origin is finite.
pub(crate) fn check_origin(file: &str, field: &str, origin: DVec3) -> Result<[f64; 3], LoadError> {
    if !origin.is_finite() {
        return Err(LoadError::header(
            file,
            field,
            format!("origin {origin:?} is not finite"),
        ));
    }
    Ok(origin.to_array())
}

/// RAS (NIfTI, NRRD "right-anterior-superior") to LPS: negate x and y.
pub(crate) fn ras_to_lps(v: DVec3) -> DVec3 {
    DVec3::new(-v.x, -v.y, v.z)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // a failed unwrap is a failed test
mod tests {
    use super::*;

    #[test]
    fn shear_is_kept_and_noted() {
        let mut w = Vec::new();
        let axes = [DVec3::X * 0.5, DVec3::new(0.0, 1.0, 0.2), DVec3::Z * 2.0];
        let (s, d) = from_axis_vectors("t", "f", axes, &mut w).unwrap();
        assert!((s[1] - 1.04f64.sqrt()).abs() < 1e-12);
        assert!((d.y_axis - DVec3::new(0.0, 1.0, 0.2) / 1.04f64.sqrt()).length() < 1e-12);
        assert_eq!(w.len(), 1);
        assert!(from_axis_vectors("t", "f", [DVec3::X, DVec3::X, DVec3::Z], &mut w).is_err());
        assert!(from_axis_vectors("t", "f", [DVec3::ZERO, DVec3::Y, DVec3::Z], &mut w).is_err());
    }
}
