//! Brick planning: which voxels of a volume each GPU step uploads, computes and delivers, so that
//! volumes of any size run on devices whose single allocations are capped (WebGPU's defaults:
//! 128 MiB per storage binding, 256 MiB per buffer).
//!
//! A brick is a box of whole rows along x (full-length rows have no x halo) tiled in y and z.
//! Two grids take part: the input grid, on which results are delivered, and the compute grid,
//! the input refined by integer factors per axis ([`crate::cpu::resample`]; input voxel `i` is
//! compute voxel `f * i`). A brick delivers input voxels `out`; they are the compute voxels
//! `f * out` of its core `core_c` (cores tile the compute grid); computing those needs `halo[a]` more compute voxels on each
//! side of axis `a` (`slab_c`), which are refined from input voxels `input`. The plan picks the
//! tiling with the fewest computed voxels whose bricks fit `max_brick_voxels`.

use std::ops::Range;

use crate::cpu::Grid;

/// The voxels one brick touches, per axis, on both grids (x is always whole).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Brick {
    /// Input-grid voxels this brick delivers.
    pub out: [Range<usize>; 3],
    /// Compute-grid voxels whose results are delivered (`f * out`, and the voxels up to the
    /// next brick's, so that cores tile the compute grid).
    pub core_c: [Range<usize>; 3],
    /// Compute-grid voxels computed: `core_c` and the halo, clamped to the volume.
    pub slab_c: [Range<usize>; 3],
    /// Input-grid voxels uploaded to refine `slab_c` from.
    pub input: [Range<usize>; 3],
}

impl Brick {
    /// Compute voxels of the brick (with its halo).
    pub fn slab_len(&self) -> u64 {
        self.slab_c.iter().map(|r| r.len() as u64).product()
    }

    /// Compute voxels of its core.
    pub fn core_len(&self) -> u64 {
        self.core_c.iter().map(|r| r.len() as u64).product()
    }

    /// Input voxels it uploads.
    pub fn input_len(&self) -> u64 {
        self.input.iter().map(|r| r.len() as u64).product()
    }

    /// Input voxels it delivers.
    pub fn out_len(&self) -> u64 {
        self.out.iter().map(|r| r.len() as u64).product()
    }
}

/// Why no plan fits the device.
#[derive(Debug, thiserror::Error, Clone, PartialEq)]
#[non_exhaustive]
pub enum PlanError {
    #[error(
        "one row of {nx} voxels with a halo of {halo_y} rows and {halo_z} slices needs {need} voxels per buffer; this GPU allows {limit}"
    )]
    BrickTooLarge {
        nx: usize,
        halo_y: usize,
        halo_z: usize,
        need: u64,
        limit: u64,
    },
    #[error("the volume is empty")]
    Empty,
}

/// A plan: the bricks and what they cost.
#[derive(Clone, Debug, PartialEq)]
pub struct Plan {
    pub bricks: Vec<Brick>,
    /// Computed voxels over delivered compute voxels (1.0 = no halo recomputed).
    pub overhead: f64,
}

impl Plan {
    /// The largest brick's compute voxels (sizes the buffers).
    pub fn max_slab_len(&self) -> u64 {
        self.bricks.iter().map(Brick::slab_len).max().unwrap_or(0)
    }
}

/// What one brick may hold, in compute voxels.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BrickLimits {
    /// The brick with its halo (one buffer of f32 per component).
    pub slab_voxels: u64,
    /// Whole rows of the brick for its core slices (the feature outputs).
    pub out_voxels: u64,
}

impl BrickLimits {
    /// The same cap for both.
    pub fn voxels(n: u64) -> Self {
        Self {
            slab_voxels: n,
            out_voxels: n,
        }
    }
}

/// One axis split into `tiles` near-equal input ranges, with the compute ranges of each.
fn axis_tiles(
    n_in: usize,
    f: usize,
    n_c: usize,
    halo: usize,
    tiles: usize,
) -> Vec<[Range<usize>; 4]> {
    let tiles = tiles.clamp(1, n_in.max(1));
    let base = n_in / tiles;
    let extra = n_in % tiles;
    let mut out = Vec::with_capacity(tiles);
    let mut start = 0;
    for t in 0..tiles {
        let len = base + usize::from(t < extra);
        let end = start + len;
        // Cores tile the compute grid: a core runs up to the next tile's first input voxel, so
        // whole-volume passes (Frangi's c) see every compute voxel once.
        let core = f * start..(f * end).min(n_c);
        let slab = core.start.saturating_sub(halo)..(core.end + halo).min(n_c);
        // Refined voxel c lies between input voxels floor(c / f) and the next.
        let input = slab.start / f..((slab.end - 1).div_ceil(f) + 1).min(n_in);
        out.push([start..end, core, slab, input]);
        start = end;
    }
    out
}

/// The longest core and the longest compute range (with halo) of an axis split into `tiles`.
fn longest(n_in: usize, f: usize, n_c: usize, halo: usize, tiles: usize) -> (usize, usize) {
    let t = axis_tiles(n_in, f, n_c, halo, tiles);
    let core = t.iter().map(|t| t[1].len()).max().unwrap_or(0);
    let slab = t.iter().map(|t| t[2].len()).max().unwrap_or(0);
    (core, slab)
}

/// Bricks for an input grid refined by `factors`, with `halo` compute voxels per axis (x is
/// ignored: rows are whole), each within `limits`.
/// `max_y_tiles = Some(1)` keeps whole planes (passes that measure whole slices).
pub fn plan(
    input: &Grid,
    factors: [usize; 3],
    halo: [usize; 3],
    limits: BrickLimits,
    max_y_tiles: Option<usize>,
) -> Result<Plan, PlanError> {
    if input.is_empty() {
        return Err(PlanError::Empty);
    }
    let f = factors.map(|f| f.max(1));
    let compute = crate::cpu::resample::refined_grid(input, f);
    let [nxc, nyc, nzc] = compute.dims;
    let [_, ny, nz] = input.dims;
    let nx_c = nxc as u64;
    let mut best: Option<(u64, usize, usize)> = None;
    let y_tiles_max = max_y_tiles.unwrap_or(ny).clamp(1, ny);
    for ty in 1..=y_tiles_max {
        let sy = longest(ny, f[1], nyc, halo[1], ty).1 as u64;
        // The fewest z tiles whose longest brick fits.
        let fits = |tz: usize| {
            let (core, slab) = longest(nz, f[2], nzc, halo[2], tz);
            nx_c * sy * slab as u64 <= limits.slab_voxels
                && nx_c * sy * core as u64 <= limits.out_voxels
        };
        if !fits(nz) {
            continue;
        }
        let (mut lo, mut hi) = (1usize, nz);
        while lo < hi {
            let mid = (lo + hi) / 2;
            if fits(mid) {
                hi = mid;
            } else {
                lo = mid + 1;
            }
        }
        let tz = lo;
        let sum = |n_in, f, n_c, h, t| -> u64 {
            axis_tiles(n_in, f, n_c, h, t)
                .iter()
                .map(|r| r[2].len() as u64)
                .sum()
        };
        let cost = nx_c * sum(ny, f[1], nyc, halo[1], ty) * sum(nz, f[2], nzc, halo[2], tz);
        let better = match best {
            None => true,
            // Fewer computed voxels; on a tie (within 1%), fewer bricks.
            Some((c, by, bz)) => {
                (cost as f64) < 0.99 * c as f64
                    || ((cost as f64) <= 1.01 * c as f64 && ty * tz < by * bz)
            }
        };
        if better {
            best = Some((cost, ty, tz));
        }
        // More y tiles than needed for a one-brick-deep z only adds halo.
        if tz == 1 {
            break;
        }
    }
    let Some((cost, ty, tz)) = best else {
        return Err(PlanError::BrickTooLarge {
            nx: nxc,
            halo_y: halo[1],
            halo_z: halo[2],
            need: nx_c
                * if y_tiles_max == 1 {
                    nyc as u64
                } else {
                    (1 + 2 * halo[1]).min(nyc) as u64
                }
                * (1 + 2 * halo[2]).min(nzc) as u64,
            limit: limits.slab_voxels,
        });
    };
    let ys = axis_tiles(ny, f[1], nyc, halo[1], ty);
    let zs = axis_tiles(nz, f[2], nzc, halo[2], tz);
    let mut bricks = Vec::with_capacity(ys.len() * zs.len());
    for z in &zs {
        for y in &ys {
            bricks.push(Brick {
                out: [0..input.dims[0], y[0].clone(), z[0].clone()],
                core_c: [0..nxc, y[1].clone(), z[1].clone()],
                slab_c: [0..nxc, y[2].clone(), z[2].clone()],
                input: [0..input.dims[0], y[3].clone(), z[3].clone()],
            });
        }
    }
    Ok(Plan {
        bricks,
        overhead: cost as f64 / compute.len() as f64,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cpu::resample::refined_grid;

    fn check_cover(input: &Grid, f: [usize; 3], halo: [usize; 3], plan: &Plan) {
        let compute = refined_grid(input, f);
        let mut hit = vec![0u8; input.len()];
        for b in &plan.bricks {
            for a in 0..3 {
                assert_eq!(b.core_c[a].start, f[a] * b.out[a].start);
                assert_eq!(b.core_c[a].end, (f[a] * b.out[a].end).min(compute.dims[a]));
                // The halo is complete unless clamped by the volume.
                if a > 0 {
                    assert!(
                        b.slab_c[a].start == 0 || b.core_c[a].start - b.slab_c[a].start >= halo[a]
                    );
                    assert!(
                        b.slab_c[a].end == compute.dims[a]
                            || b.slab_c[a].end - b.core_c[a].end >= halo[a]
                    );
                }
                // Every computed voxel can be refined from the uploaded input voxels.
                for c in b.slab_c[a].clone() {
                    let lo = c / f[a];
                    assert!(b.input[a].contains(&lo), "{b:?} axis {a} c {c}");
                    if c % f[a] != 0 {
                        assert!(b.input[a].contains(&(lo + 1)));
                    }
                }
            }
            for k in b.out[2].clone() {
                for j in b.out[1].clone() {
                    for i in b.out[0].clone() {
                        hit[input.index(i, j, k)] += 1;
                    }
                }
            }
        }
        // Delivered voxels tile the input exactly once.
        assert!(hit.iter().all(|&h| h == 1));
    }

    #[test]
    fn small_volumes_are_one_brick() {
        let g = Grid::new([64, 48, 100], [0.7, 0.7, 1.0]);
        let p = plan(&g, [1; 3], [5; 3], BrickLimits::voxels(1 << 30), None).expect("plan");
        assert_eq!(p.bricks.len(), 1);
        assert_eq!(p.overhead, 1.0);
        check_cover(&g, [1; 3], [5; 3], &p);
    }

    #[test]
    fn bricks_tile_y_and_z_and_refine_by_integers() {
        for (dims, f, halo, cap) in [
            ([32, 40, 61], [1, 1, 4], [0, 7, 7], 32 * 30 * 40),
            ([32, 40, 61], [1, 2, 4], [0, 9, 3], 32 * 25 * 25),
            ([16, 64, 7], [1, 1, 2], [0, 4, 2], 16 * 20 * 13),
            ([16, 17, 2], [1, 1, 3], [0, 2, 1], 16 * 17 * 4),
            ([20, 30, 40], [1, 1, 1], [0, 5, 5], 20 * 30 * 40 / 3),
        ] {
            let g = Grid::new(dims, [0.6, 0.6, 2.0]);
            let p = plan(&g, f, halo, BrickLimits::voxels(cap as u64), None).expect("plan");
            check_cover(&g, f, halo, &p);
            assert!(p.max_slab_len() <= cap as u64);
            let whole = plan(&g, f, halo, BrickLimits::voxels(cap as u64), Some(1));
            if let Ok(w) = whole {
                check_cover(&g, f, halo, &w);
                assert!(w.bricks.iter().all(|b| b.out[1] == (0..dims[1])));
            }
        }
    }

    #[test]
    fn a_512_wide_ct_keeps_halo_overhead_low_within_webgpu_default_limits() {
        // 512 x 512 x 141 at 0.7 x 0.7 x 2 mm; 128 MiB binding = 32 Mi f32 voxels.
        let g = Grid::new([512, 512, 141], [0.7, 0.7, 2.0]);
        // Hessian at sigma 5 mm: 23 rows and 9 slices of halo; 128 MiB per binding holds
        // 32 Mi f32 per brick buffer, or 3 feature components of 10.7 M voxels.
        let webgpu = BrickLimits {
            slab_voxels: 32 << 20,
            out_voxels: (128 << 20) / 12,
        };
        let p = plan(&g, [1; 3], [0, 23, 9], webgpu, None).expect("plan");
        check_cover(&g, [1; 3], [0, 23, 9], &p);
        println!("{} bricks, overhead {:.3}", p.bricks.len(), p.overhead);
        assert!(p.overhead < 1.3, "{}", p.overhead);
        // Whole planes only (z slabs, as before bricks) cost far more halo.
        let z_only = plan(&g, [1; 3], [0, 23, 9], webgpu, Some(1)).expect("plan");
        assert!(
            z_only.overhead > p.overhead,
            "{} vs {}",
            z_only.overhead,
            p.overhead
        );
    }

    #[test]
    fn a_row_too_large_for_the_device_is_refused_with_its_size() {
        let g = Grid::new([512, 512, 40], [0.7, 0.7, 1.0]);
        let err = plan(
            &g,
            [1; 3],
            [0, 10, 10],
            BrickLimits::voxels(512 * 15 * 15),
            None,
        )
        .expect_err("too large");
        assert!(err.to_string().contains("512 voxels"), "{err}");
    }
}
