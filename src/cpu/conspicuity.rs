//! Lesion conspicuity on a real chest CT (issue 13, docs/reproduction.md "Real-CT
//! conspicuity"): a reproducible lung mask, the lesion's peak feature over the 99.9th percentile
//! of the lung, and the lesion's rank among the lung's blobs, for the Hessian Li and the RST Li
//! blobness of the lung preset.
//!
//! The lung mask (`lung_mask`), in HU:
//! 1. air: voxels below `LUNG_AIR_BELOW_HU` (-400 HU);
//! 2. its 6-connected components that touch no in-plane border of the volume (air outside the
//!    body, the table's) and hold at least `LUNG_MIN_ML` (bowel gas is smaller): the lungs with
//!    the airways;
//! 3. per axial slice, holes of that mask up to `LUNG_HOLE_MAX_MM2` (vessels, airway walls,
//!    nodules up to ~30 mm) are filled; larger islands (the heart or the liver dome cut by a
//!    thick slice) are not lung.
//!
//! The lesion (a label) is kept apart: its zone, the label grown by `LESION_ZONE_MM`, is taken out
//! of the lung before the percentile and the ranking, so the lesion's own response (which spills
//! over its edge) neither raises the lung's percentile nor competes with itself.

use super::pipeline::{Method, Request, RequestError, compute};
use super::rst::{DEFAULT_SIGMA_G_MM, GradientVolume, RstParams, rst_eigen_at};
use super::tf::{NOISE_BAND_HU, Preset, TransferFunction, auto_transfer_function};
use super::{FeatureMap, Grid, Samples, gaussian, map_eigenvalues, parallel, rays};

/// Lung air is below this (HU); parenchyma is about -850, soft tissue above -100.
pub const LUNG_AIR_BELOW_HU: f32 = -400.0;
/// Air components smaller than this (ml) are not lung (bowel gas).
pub const LUNG_MIN_ML: f64 = 100.0;
/// In-slice holes of the air mask up to this area (mm^2; a disc of 15 mm radius) are lung.
pub const LUNG_HOLE_MAX_MM2: f64 = std::f64::consts::PI * 15.0 * 15.0;
/// The lesion's zone: its label grown by this distance (mm).
pub const LESION_ZONE_MM: f64 = 10.0;

/// A box of voxels, `lo` inclusive, `hi` exclusive, per axis.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Region {
    pub lo: [usize; 3],
    pub hi: [usize; 3],
}

impl Region {
    /// The whole grid.
    pub fn all(grid: &Grid) -> Self {
        Self {
            lo: [0; 3],
            hi: grid.dims,
        }
    }

    /// The smallest box holding every `true` voxel of `mask`, if any.
    pub fn bounding(grid: &Grid, mask: &[bool]) -> Option<Self> {
        let mut lo = grid.dims;
        let mut hi = [0; 3];
        for (n, _) in mask.iter().enumerate().filter(|(_, m)| **m) {
            let ijk = grid.ijk(n);
            for a in 0..3 {
                lo[a] = lo[a].min(ijk[a]);
                hi[a] = hi[a].max(ijk[a] + 1);
            }
        }
        (hi[0] > 0).then_some(Self { lo, hi })
    }

    /// This box grown by `margin` voxels per axis on every side, clipped to the grid.
    pub fn grown(&self, grid: &Grid, m: [usize; 3]) -> Self {
        Self {
            lo: std::array::from_fn(|a| self.lo[a].saturating_sub(m[a])),
            hi: std::array::from_fn(|a| (self.hi[a] + m[a]).min(grid.dims[a])),
        }
    }

    pub fn dims(&self) -> [usize; 3] {
        std::array::from_fn(|a| self.hi[a].saturating_sub(self.lo[a]))
    }

    pub fn contains(&self, ijk: [usize; 3]) -> bool {
        (0..3).all(|a| self.lo[a] <= ijk[a] && ijk[a] < self.hi[a])
    }

    /// The grid of this box (same spacing).
    pub fn grid(&self, grid: &Grid) -> Grid {
        Grid::new(self.dims(), grid.spacing_mm)
    }

    /// The box's voxels of `values` (on `grid`), in the box grid's order.
    pub fn crop<T: Copy>(&self, grid: &Grid, values: &[T]) -> Vec<T> {
        let d = self.dims();
        let mut out = Vec::with_capacity(d[0] * d[1] * d[2]);
        for k in self.lo[2]..self.hi[2] {
            for j in self.lo[1]..self.hi[1] {
                let start = grid.index(self.lo[0], j, k);
                out.extend_from_slice(&values[start..start + d[0]]);
            }
        }
        out
    }
}

/// The lung mask of a CT in HU (module documentation, steps 1 to 3).
///
/// One byte a voxel besides the result (a state per voxel; a component is flood-filled once to
/// learn its size and whether it touches the border, and once more to mark it as lung), so
/// that the viewer can make a findings list of a large CT in the tab.
pub fn lung_mask<H: Samples + ?Sized>(grid: &Grid, hu: &H) -> Vec<bool> {
    // Not air; air not reached yet; air of a measured component; air of the lungs. Distinct
    // components never touch (they would be one), so a second flood from a seed stays in its own.
    const OTHER: u8 = 0;
    const AIR: u8 = 1;
    const MEASURED: u8 = 2;
    const LUNG: u8 = 3;
    let voxel_ml = grid.spacing_mm.iter().product::<f64>() / 1000.0;
    let mut state: Vec<u8> = (0..grid.len())
        .map(|n| {
            if hu.at(n) < LUNG_AIR_BELOW_HU {
                AIR
            } else {
                OTHER
            }
        })
        .collect();
    let mut queue = std::collections::VecDeque::new();
    for seed in 0..grid.len() {
        if state[seed] != AIR {
            continue;
        }
        // One 6-connected component of air, flood-filled from `seed`: its size and whether it
        // touches the in-plane border.
        let (count, touches_border) = flood(grid, &mut state, &mut queue, seed, AIR, MEASURED);
        if !touches_border && count as f64 * voxel_ml >= LUNG_MIN_ML {
            flood(grid, &mut state, &mut queue, seed, MEASURED, LUNG);
        }
    }
    drop(queue);
    // In place (a Vec's own allocation, u8 to bool).
    let mut lung: Vec<bool> = state.into_iter().map(|s| s == LUNG).collect();
    let hole_max_voxels = LUNG_HOLE_MAX_MM2 / (grid.spacing_mm[0] * grid.spacing_mm[1]);
    for k in 0..grid.dims[2] {
        fill_small_holes(grid, &mut lung, k, hole_max_voxels);
    }
    lung
}

/// Flood-fills the 6-connected voxels of state `from` reachable from `seed` (which has state
/// `from`), setting them to `to`: how many there were and whether one lies on the in-plane
/// border of the volume.
fn flood(
    grid: &Grid,
    state: &mut [u8],
    queue: &mut std::collections::VecDeque<usize>,
    seed: usize,
    from: u8,
    to: u8,
) -> (usize, bool) {
    let [nx, ny, _] = grid.dims;
    let mut count = 0;
    let mut touches_border = false;
    state[seed] = to;
    queue.push_back(seed);
    // Breadth first: the queue holds a front (a surface), where a stack can hold most of a
    // large component (the air around a body is a third of a CT).
    while let Some(n) = queue.pop_front() {
        count += 1;
        let ijk = grid.ijk(n);
        touches_border |= ijk[0] == 0 || ijk[1] == 0 || ijk[0] + 1 == nx || ijk[1] + 1 == ny;
        for (di, dj, dk) in NEIGHBOURS_6 {
            let Some([a, b, c]) = neighbour(grid, ijk, [di, dj, dk]) else {
                continue;
            };
            let m = grid.index(a, b, c);
            if state[m] == from {
                state[m] = to;
                queue.push_back(m);
            }
        }
    }
    (count, touches_border)
}

const NEIGHBOURS_6: [(isize, isize, isize); 6] = [
    (-1, 0, 0),
    (1, 0, 0),
    (0, -1, 0),
    (0, 1, 0),
    (0, 0, -1),
    (0, 0, 1),
];

/// Fills, in slice `k` of `mask`, every 4-connected region of `false` that touches no border of
/// the slice and has at most `max_voxels` voxels.
fn fill_small_holes(grid: &Grid, mask: &mut [bool], k: usize, max_voxels: f64) {
    let [nx, ny, _] = grid.dims;
    let mut seen = vec![false; nx * ny];
    let mut stack = Vec::new();
    let mut members = Vec::new();
    for seed in 0..nx * ny {
        if seen[seed] || mask[grid.index(seed % nx, seed / nx, k)] {
            continue;
        }
        members.clear();
        seen[seed] = true;
        stack.push(seed);
        let mut touches_border = false;
        while let Some(p) = stack.pop() {
            members.push(p);
            let (i, j) = (p % nx, p / nx);
            touches_border |= i == 0 || j == 0 || i + 1 == nx || j + 1 == ny;
            let mut visit = |a: usize, b: usize| {
                let q = a + nx * b;
                if !seen[q] && !mask[grid.index(a, b, k)] {
                    seen[q] = true;
                    stack.push(q);
                }
            };
            if i > 0 {
                visit(i - 1, j);
            }
            if i + 1 < nx {
                visit(i + 1, j);
            }
            if j > 0 {
                visit(i, j - 1);
            }
            if j + 1 < ny {
                visit(i, j + 1);
            }
        }
        if !touches_border && members.len() as f64 <= max_voxels {
            for &p in &members {
                mask[grid.index(p % nx, p / nx, k)] = true;
            }
        }
    }
}

/// `mask` grown by `radius_mm` (every voxel within that grid-mm distance of a `true` voxel).
pub fn grow_mm(grid: &Grid, mask: &[bool], radius_mm: f64) -> Vec<bool> {
    let r: [isize; 3] = std::array::from_fn(|a| (radius_mm / grid.spacing_mm[a]).floor() as isize);
    let mut offsets = Vec::new();
    for dk in -r[2]..=r[2] {
        for dj in -r[1]..=r[1] {
            for di in -r[0]..=r[0] {
                let d2: f64 = [di, dj, dk]
                    .iter()
                    .zip(grid.spacing_mm)
                    .map(|(d, s)| (*d as f64 * s).powi(2))
                    .sum();
                if d2 <= radius_mm * radius_mm {
                    offsets.push([di, dj, dk]);
                }
            }
        }
    }
    let mut out = mask.to_vec();
    for (n, _) in mask.iter().enumerate().filter(|(_, m)| **m) {
        let ijk = grid.ijk(n);
        // Only surface voxels can reach outside the mask.
        let inner = NEIGHBOURS_6.iter().all(|&(di, dj, dk)| {
            neighbour(grid, ijk, [di, dj, dk]).is_none_or(|m| mask[grid.index(m[0], m[1], m[2])])
        });
        if inner {
            continue;
        }
        for &o in &offsets {
            if let Some(m) = neighbour(grid, ijk, o) {
                out[grid.index(m[0], m[1], m[2])] = true;
            }
        }
    }
    out
}

fn neighbour(grid: &Grid, ijk: [usize; 3], d: [isize; 3]) -> Option<[usize; 3]> {
    let mut out = [0; 3];
    for a in 0..3 {
        out[a] = ijk[a]
            .checked_add_signed(d[a])
            .filter(|&v| v < grid.dims[a])?;
    }
    Some(out)
}

/// How a lesion stands out of the lung in one feature.
#[derive(Clone, Debug, PartialEq)]
pub struct Conspicuity {
    /// The largest feature value on the lesion's label, and where (voxel of the full grid).
    pub lesion_peak: f64,
    pub lesion_peak_voxel: [usize; 3],
    /// The 99.9th percentile (nearest rank) of the feature over the lung outside the lesion's
    /// zone, zeros included, and the number of those voxels.
    pub lung_p999: f64,
    pub lung_voxels: usize,
    /// `lesion_peak / lung_p999` (infinite when the percentile is 0).
    pub ratio: f64,
    /// 1 + the number of blobs (26-connected groups of lung voxels outside the lesion's zone)
    /// whose feature exceeds the lesion's peak.
    pub rank: usize,
    /// The strongest lung voxel outside the lesion's zone: value and voxel.
    pub strongest_other: (f64, [usize; 3]),
}

/// Conspicuity of a feature given on the voxels of `region` (of `grid`; `feature` in the
/// region's order), over the voxels of `lung` and `lesion` (full-grid masks) inside the region.
/// `None` when the region holds no lesion or no lung voxel.
pub fn conspicuity(
    grid: &Grid,
    region: &Region,
    feature: &[f32],
    lung: &[bool],
    lesion: &[bool],
    lesion_zone: &[bool],
) -> Option<Conspicuity> {
    let rgrid = region.grid(grid);
    let full = |r: usize| {
        let ijk = rgrid.ijk(r);
        grid.index(
            ijk[0] + region.lo[0],
            ijk[1] + region.lo[1],
            ijk[2] + region.lo[2],
        )
    };
    let mut lesion_peak: Option<(f64, usize)> = None;
    let mut others = Vec::new();
    for (r, &v) in feature.iter().enumerate() {
        let n = full(r);
        let v = f64::from(v);
        if lesion[n] && lesion_peak.is_none_or(|(p, _)| v > p) {
            lesion_peak = Some((v, n));
        }
        if lung[n] && !lesion_zone[n] {
            others.push((v, r));
        }
    }
    let (peak, peak_at) = lesion_peak?;
    if others.is_empty() {
        return None;
    }
    let mut values: Vec<f64> = others.iter().map(|(v, _)| *v).collect();
    values.sort_by(f64::total_cmp);
    let rank_index = ((0.999 * values.len() as f64).ceil() as usize).clamp(1, values.len()) - 1;
    let p999 = values[rank_index];
    let (strongest, strongest_at) = others
        .iter()
        .copied()
        .fold((f64::NEG_INFINITY, 0), |b, o| if o.0 > b.0 { o } else { b });
    // Blobs above the lesion's peak: 26-connected groups within the region.
    let mut above = vec![false; rgrid.len()];
    for &(v, r) in &others {
        above[r] = v > peak;
    }
    let mut groups = 0;
    let mut stack = Vec::new();
    for seed in 0..above.len() {
        if !above[seed] {
            continue;
        }
        groups += 1;
        above[seed] = false;
        stack.push(seed);
        while let Some(r) = stack.pop() {
            let ijk = rgrid.ijk(r);
            for dk in -1..=1 {
                for dj in -1..=1 {
                    for di in -1..=1 {
                        if let Some(m) = neighbour(&rgrid, ijk, [di, dj, dk]) {
                            let q = rgrid.index(m[0], m[1], m[2]);
                            if above[q] {
                                above[q] = false;
                                stack.push(q);
                            }
                        }
                    }
                }
            }
        }
    }
    let to_full = |r: usize| {
        let ijk = rgrid.ijk(r);
        std::array::from_fn(|a| ijk[a] + region.lo[a])
    };
    Some(Conspicuity {
        lesion_peak: peak,
        lesion_peak_voxel: grid.ijk(peak_at),
        lung_p999: p999,
        lung_voxels: values.len(),
        ratio: if p999 > 0.0 {
            peak / p999
        } else {
            f64::INFINITY
        },
        rank: 1 + groups,
        strongest_other: (strongest, to_full(strongest_at)),
    })
}

/// Both blobness measures of one lesion study.
#[derive(Clone, Debug, PartialEq)]
pub struct LesionStudy {
    /// The region the features were evaluated on, and the crop they were computed on.
    pub region: Region,
    pub crop: Region,
    /// The RST's transfer function (the preset's, refined by the whole volume's noise) and the
    /// noise measured.
    pub tf: TransferFunction,
    pub noise_sigma_hu: Option<f64>,
    pub hessian_li: Conspicuity,
    pub rst_li: Conspicuity,
}

/// Why a lesion study cannot run.
#[derive(Debug, thiserror::Error, PartialEq)]
#[non_exhaustive]
pub enum StudyError {
    #[error("the label and the image differ in size ({0} and {1} voxels)")]
    LabelSize(usize, usize),
    #[error("the label marks no voxel")]
    EmptyLabel,
    #[error("the evaluation region holds no lung voxel outside the lesion's zone")]
    NoLung,
    #[error("the evaluation region does not hold the whole lesion")]
    LesionOutside,
    #[error(transparent)]
    Request(#[from] RequestError),
}

/// The lung-preset Hessian Li and RST Li blobness of a CT (`hu`) with a lesion `label`
/// (non-zero voxels), evaluated on the voxels of `region` (which must hold the whole lesion).
/// Features are computed on a crop that reaches the
/// kernels' and the rays' support beyond the region, so they equal the whole volume's there; the
/// RST's transfer function comes from the whole volume's noise, as the app's would.
pub fn lesion_study(
    grid: &Grid,
    hu: &[f32],
    label: &[f32],
    region: Region,
) -> Result<LesionStudy, StudyError> {
    if label.len() != hu.len() || hu.len() != grid.len() {
        return Err(StudyError::LabelSize(label.len(), hu.len()));
    }
    let preset = Preset::LungNodules;
    let lesion: Vec<bool> = label.iter().map(|&v| v != 0.0).collect();
    let lesion_box = Region::bounding(grid, &lesion).ok_or(StudyError::EmptyLabel)?;
    if !(region.contains(lesion_box.lo) && region.contains(lesion_box.hi.map(|v| v - 1))) {
        return Err(StudyError::LesionOutside);
    }
    let zone = grow_mm(grid, &lesion, LESION_ZONE_MM);
    let lung = lung_mask(grid, hu);

    // Support beyond the region, per axis: the widest Hessian kernel (3 sigma + 1 voxel, also
    // on a refined axis) and the rays (R, then the trilinear cell, the central difference and
    // the sigma_g kernel), and a voxel to spare.
    let sigma_max = preset.sigmas_mm().into_iter().fold(0.0, f64::max);
    let margin: [usize; 3] = std::array::from_fn(|a| {
        let s = grid.spacing_mm[a];
        let hessian = (3.0 * sigma_max / s).ceil() as usize + 1;
        let rays = (preset.radius_mm() / s).ceil() as usize
            + 2
            + gaussian::kernel_radius_vox(DEFAULT_SIGMA_G_MM / s);
        hessian.max(rays) + 1
    });
    let crop = region.grown(grid, margin);
    let cgrid = crop.grid(grid);
    let cvalues = crop.crop(grid, hu);
    let inner = Region {
        lo: std::array::from_fn(|a| region.lo[a] - crop.lo[a]),
        hi: std::array::from_fn(|a| region.hi[a] - crop.lo[a]),
    };

    // Hessian Li blobness, the lung preset's scales, through the pipeline users run.
    let mut req = Request::new(Method::Li);
    req.preset = preset;
    let hessian = compute(&cgrid, &cvalues, &req)?;
    let hessian_b = inner.crop(&cgrid, &hessian.components[2]);

    // RST Li blobness at the lung and lesion voxels of the region (elsewhere unused).
    let smoothed = gaussian::gaussian_smooth(grid, hu, DEFAULT_SIGMA_G_MM);
    let noise = super::tf::estimate_noise_sigma(grid, &smoothed, NOISE_BAND_HU);
    drop(smoothed);
    let tf = auto_transfer_function(preset.transfer_function(), noise);
    let params = RstParams {
        rays: rays::ray_set(42).unwrap_or_default(),
        radius_mm: preset.radius_mm(),
        tf,
        ..RstParams::paper_defaults()
    };
    let gv = GradientVolume::new(&cgrid, &cvalues, DEFAULT_SIGMA_G_MM);
    let rgrid = region.grid(grid);
    let rst_b: Vec<f32> = parallel::map_indices(rgrid.len(), |r| {
        let ijk = rgrid.ijk(r);
        let n = grid.index(
            ijk[0] + region.lo[0],
            ijk[1] + region.lo[1],
            ijk[2] + region.lo[2],
        );
        if !(lung[n] || zone[n]) {
            return 0.0;
        }
        let x = cgrid.position_mm(std::array::from_fn(|a| ijk[a] + inner.lo[a]));
        map_eigenvalues(rst_eigen_at(&gv, x, &params), FeatureMap::Li)[2] as f32
    });
    let measure =
        |f: &[f32]| conspicuity(grid, &region, f, &lung, &lesion, &zone).ok_or(StudyError::NoLung);
    Ok(LesionStudy {
        region,
        crop,
        tf,
        noise_sigma_hu: noise,
        hessian_li: measure(&hessian_b)?,
        rst_li: measure(&rst_b)?,
    })
}
