//! Slab planning: which slices of a volume each GPU step uploads, computes and delivers, so that
//! volumes of any length run on devices whose single allocations are capped.
//!
//! Two grids take part (SCIENCE.md, thick slices): the input grid, on which results are
//! delivered, and the compute grid (thick axes refined to <= 1.25 mm,
//! [`crate::cpu::resample::refined_grid`]). A slab delivers input slices `out_z`; they are
//! interpolated from compute slices `core_c`; computing those needs `halo` more compute slices on
//! each side (`slab_c`), which are resampled from input slices `in_z`. Positions along z are in
//! grid mm from slice 0 on both grids (the grids share their first and last slice).

use std::ops::Range;

use crate::cpu::Grid;

/// The slices one slab touches, on both grids.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Slab {
    /// Input-grid slices this slab delivers.
    pub out_z: Range<usize>,
    /// Compute-grid slices whose results are needed for `out_z`.
    pub core_c: Range<usize>,
    /// Compute-grid slices computed: `core_c` and the halo, clamped to the volume.
    pub slab_c: Range<usize>,
    /// Input-grid slices uploaded to resample `slab_c` from.
    pub in_z: Range<usize>,
}

/// Why no plan fits the device.
#[derive(Debug, thiserror::Error, Clone, PartialEq)]
#[non_exhaustive]
pub enum PlanError {
    #[error(
        "one slice of {nx}x{ny} voxels with a halo of {halo} slices needs {need} bytes per buffer; this GPU allows {limit}"
    )]
    SliceTooLarge {
        nx: usize,
        ny: usize,
        halo: usize,
        need: u64,
        limit: u64,
    },
    #[error("the volume is empty")]
    Empty,
}

/// Input slices `[lo, hi)` whose linear interpolation gives the positions `z_mm` of
/// `[first, last]` on a grid of spacing `to`, read from a grid of spacing `from` with `n` slices;
/// one extra slice on each side absorbs f32/f64 rounding of the interpolation positions.
fn support(first: usize, last: usize, to: f64, from: f64, n: usize) -> Range<usize> {
    let lo = ((first as f64 * to / from).floor() as usize).saturating_sub(1);
    let hi = ((last as f64 * to / from).floor() as usize + 3).min(n);
    lo.min(n.saturating_sub(1))..hi
}

/// The slabs for an input grid, its compute grid, a halo (compute slices) and at most
/// `max_slab_voxels` compute voxels per slab (from the device's binding limit and the memory
/// budget). `per_voxel_bytes` is the largest single buffer's bytes per compute voxel, checked
/// against `binding_limit`.
pub fn plan(
    input: &Grid,
    compute: &Grid,
    halo: usize,
    max_slab_voxels: u64,
) -> Result<Vec<Slab>, PlanError> {
    if input.is_empty() || compute.is_empty() {
        return Err(PlanError::Empty);
    }
    let [nxc, nyc, nzc] = compute.dims;
    let plane = (nxc * nyc) as u64;
    let nz_in = input.dims[2];
    let (s_in, s_c) = (input.spacing_mm[2], compute.spacing_mm[2]);
    let max_slices = (max_slab_voxels / plane.max(1)) as usize;
    let same = input == compute;
    let core_of = |z0: usize, z1: usize| {
        if same {
            z0..z1
        } else {
            support(z0, z1 - 1, s_in, s_c, nzc)
        }
    };
    // Compute slices of a slab delivering `t` input slices (the largest over slab positions).
    let slab_len = |t: usize| {
        let worst = (0..=nz_in.saturating_sub(t))
            .step_by((nz_in / 64).max(1))
            .chain([nz_in.saturating_sub(t)])
            .map(|z0| core_of(z0, z0 + t).len())
            .max()
            .unwrap_or(0);
        (worst + 2 * halo).min(nzc)
    };
    if slab_len(1) > max_slices {
        return Err(PlanError::SliceTooLarge {
            nx: nxc,
            ny: nyc,
            halo,
            need: plane * slab_len(1) as u64 * 4,
            limit: max_slab_voxels * 4,
        });
    }
    // The most input slices per slab that fit (binary search on a monotone function).
    let (mut lo, mut hi) = (1usize, nz_in);
    while lo < hi {
        let mid = (lo + hi).div_ceil(2);
        if slab_len(mid) <= max_slices {
            lo = mid;
        } else {
            hi = mid - 1;
        }
    }
    let per = lo;
    let mut slabs = Vec::new();
    let mut z0 = 0;
    while z0 < nz_in {
        let z1 = (z0 + per).min(nz_in);
        let core_c = core_of(z0, z1);
        let slab_c = core_c.start.saturating_sub(halo)..(core_c.end + halo).min(nzc);
        let in_z = if same {
            slab_c.clone()
        } else {
            support(slab_c.start, slab_c.end - 1, s_c, s_in, nz_in)
        };
        slabs.push(Slab {
            out_z: z0..z1,
            core_c,
            slab_c,
            in_z,
        });
        z0 = z1;
    }
    Ok(slabs)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cpu::resample::{MAX_FEATURE_SPACING_MM, refined_grid};

    fn check_cover(input: &Grid, compute: &Grid, halo: usize, slabs: &[Slab]) {
        // Delivered slices tile the input exactly once.
        let mut next = 0;
        for s in slabs {
            assert_eq!(s.out_z.start, next);
            next = s.out_z.end;
            // The halo is complete unless clamped by the volume.
            assert!(s.slab_c.start == 0 || s.core_c.start - s.slab_c.start >= halo);
            assert!(s.slab_c.end == compute.dims[2] || s.slab_c.end - s.core_c.end >= halo);
            if input == compute {
                assert_eq!(s.out_z, s.core_c);
                assert_eq!(s.in_z, s.slab_c);
                continue;
            }
            // Every delivered slice's interpolation support lies in the core.
            for z in s.out_z.clone() {
                let u = z as f64 * input.spacing_mm[2] / compute.spacing_mm[2];
                let lo = u.floor() as usize;
                assert!(
                    s.core_c.contains(&lo.min(compute.dims[2] - 1)),
                    "{s:?} z {z}"
                );
                assert!(s.core_c.contains(&(lo + 1).min(compute.dims[2] - 1)));
            }
            // Every computed slice can be resampled from the uploaded input slices.
            for c in s.slab_c.clone() {
                let u = c as f64 * compute.spacing_mm[2] / input.spacing_mm[2];
                let lo = u.floor() as usize;
                assert!(s.in_z.contains(&lo.min(input.dims[2] - 1)), "{s:?} c {c}");
                assert!(s.in_z.contains(&(lo + 1).min(input.dims[2] - 1)));
            }
        }
        assert_eq!(next, input.dims[2]);
    }

    #[test]
    fn thin_slices_are_their_own_compute_grid() {
        let g = Grid::new([64, 48, 100], [0.7, 0.7, 1.0]);
        let slabs = plan(&g, &g, 5, 64 * 48 * 30).expect("plan");
        assert_eq!(slabs.len(), 5); // 20 delivered + 10 halo = 30 slices each
        assert_eq!(slabs[0].slab_c, 0..25);
        assert_eq!(slabs[1].slab_c, 15..45);
        check_cover(&g, &g, 5, &slabs);
    }

    #[test]
    fn thick_slices_map_through_the_refined_grid() {
        for (nz, dz) in [(61, 5.0), (164, 1.5), (7, 2.5), (2, 3.0)] {
            let g = Grid::new([32, 32, nz], [0.6, 0.6, dz]);
            let c = refined_grid(&g, MAX_FEATURE_SPACING_MM);
            for max_slices in [20usize, 47, 1000] {
                let slabs = plan(&g, &c, 7, (32 * 32 * max_slices) as u64).expect("plan");
                check_cover(&g, &c, 7, &slabs);
                for s in &slabs {
                    assert!(s.slab_c.len() <= max_slices);
                }
            }
        }
    }

    #[test]
    fn a_slice_too_large_for_the_device_is_refused_with_its_size() {
        let g = Grid::new([512, 512, 40], [0.7, 0.7, 1.0]);
        let err = plan(&g, &g, 10, 512 * 512 * 15).expect_err("too large");
        assert!(err.to_string().contains("512x512"), "{err}");
    }
}
