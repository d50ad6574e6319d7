//! Findings: the ranked list of round things a reader should look at (docs/science.md,
//! "Findings"), from a blobness volume on the CT's grid and the CT itself. Pure CPU code on
//! arrays: the command line (`shapecast findings`) and the app (its findings panel) call the
//! same [`find`].
//!
//! 1. **Where.** The preset says what the list is for ([`Gate`]): lung nodules lie in the lung
//!    ([`lung_mask`]) or against it, lymph nodes in soft tissue inside the body, away from the
//!    skin; the other presets take anything inside the body.
//! 2. **How bright.** The feature's 99.9th percentile over that domain is the reference: a
//!    candidate's score is its peak feature over it, and only local maxima above it (score > 1)
//!    are candidates. The reference comes from the volume, as the presets' noise-refined
//!    transfer functions do; no constant is tuned to a scan.
//! 3. **One per structure.** Maxima are taken from the strongest down. Each grows its region:
//!    the voxels 26-connected to the peak within the preset's ray length R whose HU lie within
//!    the transfer function's band of the core's (the mean of the 3 x 3 x 3 voxels at the peak):
//!    `core - (d_min + d_max) / 2 <= HU <= core + (d_min + d_max)`, the edge the RST's rays stop
//!    at, and no farther than twice the reach of the feature's half maximum (a vessel of the
//!    same HU that touches a nodule is not the nodule). A weaker maximum inside an earlier region, or in its feature's half-maximum
//!    neighbourhood, is merged into it. Size (volume, equivalent diameter) and HU (mean, max) are
//!    the region's.
//! 4. **Not a nodule or a node.** A region of mean HU above [`DENSE_ABOVE_HU`] is bone, metal or
//!    undiluted contrast; a region outside the preset's domain, a region that reaches a face of
//!    the volume (cut by the field of view: its shape unknown, its features near the face the
//!    kernels' padding), or one smaller than [`SMALLEST_MM`], is dropped. All are counted.

use std::collections::HashMap;

use super::conspicuity::lung_mask;
use super::tf::{
    NOISE_BAND_HU, Preset, TransferFunction, auto_transfer_function, estimate_noise_sigma,
};
use super::{Grid, Samples};

/// Regions of mean HU above this are bone, metal or undiluted contrast, not nodules or nodes.
pub const DENSE_ABOVE_HU: f64 = 700.0;
/// Soft tissue (a lymph node's core): fat is below, contrast-filled vessels and bone above.
pub const SOFT_TISSUE_HU: (f64, f64) = (-100.0, 200.0);
/// Air below this (HU), as the lung mask's.
pub const AIR_BELOW_HU: f32 = super::conspicuity::LUNG_AIR_BELOW_HU;
/// A soft-tissue or body candidate lies at least this far from the air outside the body (skin
/// folds, the table's edges), mm.
pub const SKIN_MARGIN_MM: f64 = 10.0;
/// A lung candidate whose peak is not in the lung mask needs at least this share of its
/// region's outer neighbours to be lung (a juxtapleural nodule, a mass larger than the mask's
/// filled holes).
pub const LUNG_CONTACT_MIN: f64 = 0.25;
/// Regions smaller than a sphere of this diameter (mm) are not findings: below 3 mm a "nodule"
/// is a voxel or two of noise or a vessel's cross-section (LIDC-IDRI's readers marked nodules
/// from 3 mm).
pub const SMALLEST_MM: f64 = 3.0;
/// Findings listed before "more".
pub const SHOWN: usize = 30;

/// Where a preset's findings may lie.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Gate {
    /// In the lung or against it (lung nodules).
    Lung,
    /// Soft tissue inside the body, not in the lung (lymph nodes).
    SoftTissue,
    /// Anywhere inside the body.
    Body,
}

impl Gate {
    pub fn of(preset: Preset) -> Self {
        match preset {
            Preset::LungNodules => Self::Lung,
            Preset::LymphNodes => Self::SoftTissue,
            Preset::Airways | Preset::Vessels => Self::Body,
        }
    }

    pub fn describe(self) -> &'static str {
        match self {
            Self::Lung => "in or against the lung",
            Self::SoftTissue => "soft tissue inside the body",
            Self::Body => "inside the body",
        }
    }
}

/// One candidate.
#[derive(Clone, Debug, PartialEq)]
pub struct Finding {
    /// 1 for the strongest.
    pub rank: usize,
    /// The voxel of the feature's peak (where a click on the finding goes).
    pub voxel: [usize; 3],
    /// The peak feature value.
    pub feature: f32,
    /// The peak over the domain's 99.9th percentile.
    pub score: f64,
    /// The region's volume, ml, and the diameter of the sphere of that volume, mm.
    pub volume_ml: f64,
    pub diameter_mm: f64,
    pub mean_hu: f64,
    pub max_hu: f64,
    /// The region reached its limit (the preset's ray length R, or twice the reach of the
    /// feature's half maximum): its size is a lower bound.
    pub bounded: bool,
    /// Weaker maxima merged into this finding.
    pub merged: usize,
}

/// The ranked candidates of a volume and what was left out.
#[derive(Clone, Debug, PartialEq)]
pub struct Findings {
    pub gate: Gate,
    /// The feature's 99.9th percentile over the gate's domain (score 1).
    pub reference: f32,
    /// The transfer function whose band bounds the regions, and the CT's noise it was refined
    /// by (HU; `None` where no 11 x 11 window lies in soft tissue).
    pub tf: TransferFunction,
    pub noise_hu: Option<f64>,
    /// Every candidate, strongest first ([`SHOWN`] of them are listed before "more").
    pub findings: Vec<Finding>,
    /// Candidates dropped as outside the domain, as dense (bone, metal, contrast), as cut by
    /// the volume's edge, and as smaller than [`SMALLEST_MM`].
    pub outside: usize,
    pub dense: usize,
    pub cut: usize,
    pub small: usize,
}

/// Why findings cannot be computed.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum FindingsError {
    #[error("the feature has {feature} voxels and the CT {hu}; the grid holds {grid}")]
    Length {
        feature: usize,
        hu: usize,
        grid: usize,
    },
}

/// The findings of `feature` (a blobness on `grid`) in the CT `hu`, for `preset` (module
/// documentation). The regions' HU band is the preset's transfer function refined by the CT's
/// own noise ([`auto_transfer_function`] of the noise of `hu` itself, which the regions read).
pub fn find<H: Samples + ?Sized>(
    grid: &Grid,
    hu: &H,
    feature: &[f32],
    preset: Preset,
) -> Result<Findings, FindingsError> {
    if hu.count() != grid.len() || feature.len() != grid.len() {
        return Err(FindingsError::Length {
            feature: feature.len(),
            hu: hu.count(),
            grid: grid.len(),
        });
    }
    let gate = Gate::of(preset);
    let noise_hu = estimate_noise_sigma(grid, hu, NOISE_BAND_HU);
    let tf = auto_transfer_function(preset.transfer_function(), noise_hu);
    let domain = Domain::new(gate, grid, hu);
    let reference = percentile_999(|| {
        (0..grid.len())
            .filter(|&n| domain.contains(n))
            .map(|n| feature[n])
    });
    let mut result = Findings {
        gate,
        reference,
        tf,
        noise_hu,
        findings: Vec::new(),
        outside: 0,
        dense: 0,
        cut: 0,
        small: 0,
    };
    if reference.is_nan() || reference <= 0.0 {
        return Ok(result);
    }
    let mut maxima = local_maxima(grid, feature, reference);
    maxima.sort_by(|a, b| feature[*b].total_cmp(&feature[*a]).then(a.cmp(b)));

    let radius_mm = preset.radius_mm();
    let half_band = 0.5 * (tf.d_min + tf.d_max);
    // Voxel -> the candidate (kept or dropped) whose region holds it.
    let mut owner: HashMap<usize, Owner> = HashMap::new();
    for peak in maxima {
        if let Some(&o) = owner.get(&peak) {
            if let Owner::Kept(f) = o {
                result.findings[f].merged += 1;
            }
            continue;
        }
        let core = core_hu(grid, hu, peak);
        let band = (core - half_band, core + 2.0 * half_band);
        let halo = grow(grid, peak, radius_mm, |n| feature[n] >= 0.5 * feature[peak]);
        // A structure reaches about twice as far as its feature's half maximum: beyond that a
        // region of the same HU is a neighbour it touches (a vessel), not itself.
        let c = grid.ijk(peak);
        let halo_mm = halo
            .voxels
            .iter()
            .map(|&n| distance_mm(grid, c, grid.ijk(n)))
            .fold(0.0, f64::max);
        let reach_mm =
            radius_mm.min(2.0 * halo_mm + grid.spacing_mm.iter().fold(0.0f64, |a, &b| a.max(b)));
        // Voxels of an earlier candidate's region are a border: regions never overlap.
        let region = grow(grid, peak, reach_mm, |n| {
            let v = f64::from(hu.at(n));
            band.0 <= v && v <= band.1 && !owner.contains_key(&n)
        });
        let values = region.voxels.iter().map(|&n| f64::from(hu.at(n)));
        let mean_hu = values.clone().sum::<f64>() / region.voxels.len() as f64;
        let max_hu = values.fold(f64::NEG_INFINITY, f64::max);
        let voxel_ml = grid.spacing_mm.iter().product::<f64>() / 1000.0;
        let volume_ml = region.voxels.len() as f64 * voxel_ml;
        let diameter_mm = (6.0 * volume_ml * 1000.0 / std::f64::consts::PI).cbrt();
        let keep = if mean_hu > DENSE_ABOVE_HU {
            result.dense += 1;
            false
        } else if !domain.admits(peak, core, &region.voxels) {
            result.outside += 1;
            false
        } else if touches_face(grid, &region.voxels) {
            result.cut += 1;
            false
        } else if diameter_mm < SMALLEST_MM {
            result.small += 1;
            false
        } else {
            true
        };
        let who = if keep {
            result.findings.push(Finding {
                rank: result.findings.len() + 1,
                voxel: grid.ijk(peak),
                feature: feature[peak],
                score: f64::from(feature[peak]) / f64::from(reference),
                volume_ml,
                diameter_mm,
                mean_hu,
                max_hu,
                bounded: region.bounded,
                merged: 0,
            });
            Owner::Kept(result.findings.len() - 1)
        } else {
            Owner::Dropped
        };
        // A kept finding also claims its feature's half-maximum neighbourhood (its weaker
        // maxima); a dropped candidate only its own HU region, so that a nodule beside a
        // dense rib is not hidden in the rib's halo.
        let halo = if keep { halo.voxels } else { Vec::new() };
        for n in region.voxels.into_iter().chain(halo) {
            owner.entry(n).or_insert(who);
        }
    }
    Ok(result)
}

/// The feature's 99.9th percentile over a gate's domain on this CT: score 1 of its findings.
/// (PET hot spots read the CT's shape against the soft tissue's, whatever the preset.)
pub fn reference<H: Samples + ?Sized>(grid: &Grid, hu: &H, feature: &[f32], gate: Gate) -> f32 {
    if hu.count() != grid.len() || feature.len() != grid.len() {
        return 0.0;
    }
    let domain = Domain::new(gate, grid, hu);
    percentile_999(|| {
        (0..grid.len())
            .filter(|&n| domain.contains(n))
            .map(|n| feature[n])
    })
}

#[derive(Clone, Copy, Debug)]
enum Owner {
    Kept(usize),
    Dropped,
}

/// Where a gate's findings may lie, on one CT.
struct Domain<'a, H: Samples + ?Sized> {
    gate: Gate,
    grid: &'a Grid,
    hu: &'a H,
    /// The lung mask; empty for the body gate, which does not read it.
    lung: Vec<bool>,
    /// The air around the body ([`outside_air`]); empty for the lung gate.
    outside: Vec<bool>,
}

impl<'a, H: Samples + ?Sized> Domain<'a, H> {
    /// The masks `gate` reads, and only those (a byte a voxel each): the lung for the lung and
    /// soft-tissue gates, the air around the body for the soft-tissue and body gates.
    fn new(gate: Gate, grid: &'a Grid, hu: &'a H) -> Self {
        let lung = match gate {
            Gate::Lung | Gate::SoftTissue => lung_mask(grid, hu),
            Gate::Body => Vec::new(),
        };
        let outside = match gate {
            Gate::SoftTissue | Gate::Body => outside_air(grid, hu),
            Gate::Lung => Vec::new(),
        };
        Self {
            gate,
            grid,
            hu,
            lung,
            outside,
        }
    }

    /// Whether voxel `n` counts towards the reference percentile.
    fn contains(&self, n: usize) -> bool {
        match self.gate {
            Gate::Lung => self.lung[n],
            Gate::SoftTissue => !self.lung[n] && !self.outside[n] && self.hu.at(n) >= AIR_BELOW_HU,
            Gate::Body => !self.outside[n],
        }
    }

    /// Whether a candidate (peak voxel, core HU, region) lies where the gate wants it.
    fn admits(&self, peak: usize, core: f64, region: &[usize]) -> bool {
        let (grid, lung, outside) = (self.grid, &self.lung, &self.outside);
        match self.gate {
            Gate::Lung => lung[peak] || lung_contact(grid, lung, region) >= LUNG_CONTACT_MIN,
            Gate::SoftTissue => {
                !lung[peak]
                    && self.hu.at(peak) >= AIR_BELOW_HU
                    && (SOFT_TISSUE_HU.0..=SOFT_TISSUE_HU.1).contains(&core)
                    && !near(grid, outside, peak, SKIN_MARGIN_MM)
            }
            Gate::Body => !outside[peak] && !near(grid, outside, peak, SKIN_MARGIN_MM),
        }
    }
}

/// The share of the region's outer 6-neighbours that are lung.
fn lung_contact(grid: &Grid, lung: &[bool], region: &[usize]) -> f64 {
    let inside: std::collections::HashSet<usize> = region.iter().copied().collect();
    let mut rim = std::collections::HashSet::new();
    for &n in region {
        for m in neighbours(grid, n, &NEIGHBOURS_6) {
            if !inside.contains(&m) {
                rim.insert(m);
            }
        }
    }
    if rim.is_empty() {
        return 0.0;
    }
    rim.iter().filter(|&&m| lung[m]).count() as f64 / rim.len() as f64
}

/// Whether any voxel of `mask` lies within `mm` of voxel `n`.
fn near(grid: &Grid, mask: &[bool], n: usize, mm: f64) -> bool {
    let c = grid.ijk(n);
    let r: [usize; 3] = std::array::from_fn(|a| (mm / grid.spacing_mm[a]).floor() as usize);
    for k in c[2].saturating_sub(r[2])..(c[2] + r[2] + 1).min(grid.dims[2]) {
        for j in c[1].saturating_sub(r[1])..(c[1] + r[1] + 1).min(grid.dims[1]) {
            for i in c[0].saturating_sub(r[0])..(c[0] + r[0] + 1).min(grid.dims[0]) {
                if distance_mm(grid, c, [i, j, k]) <= mm && mask[grid.index(i, j, k)] {
                    return true;
                }
            }
        }
    }
    false
}

fn distance_mm(grid: &Grid, a: [usize; 3], b: [usize; 3]) -> f64 {
    (0..3)
        .map(|x| ((a[x] as f64 - b[x] as f64) * grid.spacing_mm[x]).powi(2))
        .sum::<f64>()
        .sqrt()
}

/// The mean HU of the (up to) 3 x 3 x 3 voxels around `n`.
fn core_hu<H: Samples + ?Sized>(grid: &Grid, hu: &H, n: usize) -> f64 {
    let mut sum = f64::from(hu.at(n));
    let mut count = 1.0;
    for m in neighbours(grid, n, &NEIGHBOURS_26) {
        sum += f64::from(hu.at(m));
        count += 1.0;
    }
    sum / count
}

/// Whether a region reaches a face of the volume: a structure the scan's field of view cuts
/// (a cropped volume's sides, every scan's first and last slices), whose size and shape are not
/// known and whose features near the face come from the kernels' padding, not from the scan.
/// An axis of fewer than 3 voxels has no inside and is not asked (a single slice's findings are
/// judged in its plane).
fn touches_face(grid: &Grid, voxels: &[usize]) -> bool {
    voxels.iter().any(|&n| {
        let c = grid.ijk(n);
        (0..3).any(|a| grid.dims[a] >= 3 && (c[a] == 0 || c[a] + 1 == grid.dims[a]))
    })
}

struct Region {
    voxels: Vec<usize>,
    /// The region reached the radius.
    bounded: bool,
}

/// The voxels 26-connected to `seed` within `radius_mm` of it where `inside` holds (the seed
/// always).
fn grow(grid: &Grid, seed: usize, radius_mm: f64, inside: impl Fn(usize) -> bool) -> Region {
    let c = grid.ijk(seed);
    let mut seen = std::collections::HashSet::from([seed]);
    let mut stack = vec![seed];
    let mut voxels = Vec::new();
    let mut bounded = false;
    while let Some(n) = stack.pop() {
        voxels.push(n);
        for m in neighbours(grid, n, &NEIGHBOURS_26) {
            if seen.contains(&m) || !inside(m) {
                continue;
            }
            if distance_mm(grid, c, grid.ijk(m)) > radius_mm {
                bounded = true;
                continue;
            }
            seen.insert(m);
            stack.push(m);
        }
    }
    Region { voxels, bounded }
}

/// Voxels above `threshold` that no 26-neighbour exceeds (of equal neighbours, the first in
/// memory order is the maximum).
fn local_maxima(grid: &Grid, feature: &[f32], threshold: f32) -> Vec<usize> {
    (0..grid.len())
        .filter(|&n| {
            let v = feature[n];
            v > threshold
                && neighbours(grid, n, &NEIGHBOURS_26)
                    .all(|m| feature[m] < v || (feature[m] == v && m > n))
        })
        .collect()
}

/// The nearest-rank 99.9th percentile of the finite values `values()` yields (0 when there
/// are none), in the order of `f32::total_cmp`. Exact, and in constant memory: the values are
/// read twice (a histogram of the upper 16 bits of an order-preserving key, then one of the
/// lower 16 bits within the bucket that holds the rank), never collected, so that the viewer can
/// make a findings list of a large CT in the tab.
fn percentile_999<I: Iterator<Item = f32>>(values: impl Fn() -> I) -> f32 {
    // Unsigned keys in the order of total_cmp: negative floats flipped, positive ones offset.
    let key = |x: f32| {
        let b = x.to_bits();
        if b >> 31 == 1 { !b } else { b | 0x8000_0000 }
    };
    let value = |k: u32| f32::from_bits(if k >> 31 == 1 { k & 0x7fff_ffff } else { !k });
    let finite = || values().filter(|x| x.is_finite()).map(key);
    let mut high = vec![0u64; 1 << 16];
    let mut n = 0u64;
    for k in finite() {
        high[(k >> 16) as usize] += 1;
        n += 1;
    }
    if n == 0 {
        return 0.0;
    }
    // 0-based nearest rank.
    let rank = ((0.999 * n as f64).ceil() as u64).clamp(1, n) - 1;
    let (bucket, rest) = nth_bucket(&high, rank);
    drop(high);
    let mut low = vec![0u64; 1 << 16];
    for k in finite().filter(|k| (k >> 16) as usize == bucket) {
        low[(k & 0xffff) as usize] += 1;
    }
    let (within, _) = nth_bucket(&low, rest);
    value(((bucket as u32) << 16) | within as u32)
}

/// The bucket of `counts` that holds the 0-based `rank`, and the rank within it.
fn nth_bucket(counts: &[u64], mut rank: u64) -> (usize, u64) {
    for (b, &c) in counts.iter().enumerate() {
        if rank < c {
            return (b, rank);
        }
        rank -= c;
    }
    (counts.len() - 1, 0)
}

/// Air (below [`AIR_BELOW_HU`]) 6-connected to a voxel on the volume's in-plane border: the
/// air around the body.
pub fn outside_air<H: Samples + ?Sized>(grid: &Grid, hu: &H) -> Vec<bool> {
    let [nx, ny, nz] = grid.dims;
    let mut outside = vec![false; grid.len()];
    // Breadth first from one border voxel at a time: the queue holds a front, where a stack
    // (or every border voxel queued at once) can hold a large part of the air.
    let mut queue = std::collections::VecDeque::new();
    for k in 0..nz {
        for j in 0..ny {
            for i in 0..nx {
                let border = i == 0 || j == 0 || i + 1 == nx || j + 1 == ny;
                let n = grid.index(i, j, k);
                if !border || outside[n] || hu.at(n) >= AIR_BELOW_HU {
                    continue;
                }
                outside[n] = true;
                queue.push_back(n);
                while let Some(n) = queue.pop_front() {
                    for m in neighbours(grid, n, &NEIGHBOURS_6) {
                        if !outside[m] && hu.at(m) < AIR_BELOW_HU {
                            outside[m] = true;
                            queue.push_back(m);
                        }
                    }
                }
            }
        }
    }
    outside
}

const NEIGHBOURS_6: [[isize; 3]; 6] = [
    [-1, 0, 0],
    [1, 0, 0],
    [0, -1, 0],
    [0, 1, 0],
    [0, 0, -1],
    [0, 0, 1],
];

const NEIGHBOURS_26: [[isize; 3]; 26] = {
    let mut out = [[0; 3]; 26];
    let mut n = 0;
    let mut code = 0;
    while code < 27 {
        let d = [code % 3 - 1, code / 3 % 3 - 1, code / 9 - 1];
        if !(d[0] == 0 && d[1] == 0 && d[2] == 0) {
            out[n] = d;
            n += 1;
        }
        code += 1;
    }
    out
};

/// The in-grid neighbours of voxel `n` at the given offsets.
fn neighbours<'a>(
    grid: &'a Grid,
    n: usize,
    offsets: &'a [[isize; 3]],
) -> impl Iterator<Item = usize> + 'a {
    let c = grid.ijk(n);
    offsets.iter().filter_map(move |d| {
        let i = c[0].checked_add_signed(d[0])?;
        let j = c[1].checked_add_signed(d[1])?;
        let k = c[2].checked_add_signed(d[2])?;
        (i < grid.dims[0] && j < grid.dims[1] && k < grid.dims[2]).then(|| grid.index(i, j, k))
    })
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::expect_used)] // a failed expect is a failed test
mod tests;
