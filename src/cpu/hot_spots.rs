//! PET hot spots with their CT shape (docs/science.md, "PET hot spots"): the FDG spots a reader
//! of a PET/CT looks at, each with the blobness of the CT at the spot, so that a round node
//! (the paper's lymphoma nodes) is told from a spot that is not round on the CT (brown fat, its
//! Fig. 21). Pure CPU code on two volumes in one patient space: the PET is read on its own grid,
//! the CT's feature on the CT's; neither is resampled into the other.
//!
//! 1. **Reference (PERCIST).** The liver: the largest connected set of PET voxels whose 3 cm
//!    sphere is homogeneous (coefficient of variation below [`LIVER_CV_MAX`]) with a mean SUV in
//!    [`LIVER_SUV`]; its most homogeneous sphere gives the mean and SD, and the threshold is
//!    `1.5 x mean + 2 x SD`. A PET without such a region (cropped, or no liver in view) has no
//!    reference; then the threshold is SUV [`FALLBACK_SUV`], stated as such.
//! 2. **Spots.** Local maxima of the SUV above the threshold, strongest first; each grows its
//!    region (26-connected voxels at or above half its peak and above the threshold); a
//!    maximum whose region reaches an earlier spot's is merged into it. SUVpeak is the mean of
//!    the voxels whose centres lie within the hottest 1 cm³ sphere centred in the spot, and the
//!    spot is where that sphere is; a spot is kept when its SUVpeak is above the threshold
//!    (PERCIST's measurable lesion). Values must be SUV (the caller checks the unit).
//! 3. **CT shape.** Where the CT holds the spot, the CT blobness's largest value within the
//!    spot's radius (at least 5 mm) of it, over the blobness's 99.9th percentile in the CT's
//!    soft tissue ([`crate::cpu::findings::reference`]): "round on CT" at 1 or more, where a
//!    lymph-node finding's score starts.

use std::collections::{HashMap, HashSet};

use glam::DVec3;

use crate::volume::Volume;

/// The radius of a 1 cm³ sphere, mm (SUVpeak's, PERCIST).
pub const PEAK_SPHERE_RADIUS_MM: f64 = 6.2035;
/// PERCIST's liver sphere: 3 cm across.
pub const LIVER_SPHERE_RADIUS_MM: f64 = 15.0;
/// The liver's mean SUV lies in this range (normal liver 1.5-3; PERCIST asks for 1.0-3.0 in a
/// scan it accepts, and fatty or hot livers go a little beyond).
pub const LIVER_SUV: (f64, f64) = (1.0, 4.0);
/// A 3 cm sphere of liver is homogeneous: SD / mean below this (PERCIST's quality check asks
/// for a liver SD within about 20% of the mean).
pub const LIVER_CV_MAX: f64 = 0.2;
/// At least this much homogeneous tissue (ml) is a liver, not the blood pool or the spleen.
pub const LIVER_MIN_ML: f64 = 100.0;
/// The threshold without a liver: SUV 2.5, the classic cut of "FDG-avid".
pub const FALLBACK_SUV: f64 = 2.5;
/// The CT blobness is read at least this far (mm) around a spot's peak.
pub const CT_READ_MIN_MM: f64 = 5.0;

/// Where the threshold came from.
#[derive(Clone, Debug, PartialEq)]
pub struct Reference {
    /// The liver sphere's centre (LPS mm), its mean and SD (SUV); `None`: no liver found.
    pub liver: Option<(DVec3, f64, f64)>,
    /// The SUV a spot's SUVpeak must exceed.
    pub threshold: f64,
}

impl Reference {
    pub fn rule(&self) -> String {
        match self.liver {
            Some((_, mean, sd)) => format!(
                "PERCIST: 1.5 x liver mean + 2 x SD = 1.5 x {mean:.2} + 2 x {sd:.2} = {:.2}",
                self.threshold
            ),
            None => format!(
                "no homogeneous liver in the PET: SUV {FALLBACK_SUV} (FDG-avid), not PERCIST"
            ),
        }
    }
}

/// One PET hot spot.
#[derive(Clone, Debug, PartialEq)]
pub struct HotSpot {
    /// 1 for the strongest SUVpeak.
    pub rank: usize,
    /// The centre of its hottest 1 cm³ sphere, on the PET's grid and in patient space (LPS mm).
    pub pet_voxel: [usize; 3],
    pub lps_mm: DVec3,
    pub suv_max: f64,
    pub suv_peak: f64,
    /// The region at or above half the peak, ml.
    pub volume_ml: f64,
    /// The CT's blobness there and its score (`None`: the CT does not hold the spot).
    pub ct_blobness: Option<f32>,
    pub ct_score: Option<f64>,
}

impl HotSpot {
    /// "round on CT" (the CT's blobness at the spot scores 1 or more), "not round", or `None`
    /// where the CT does not reach or has no reference.
    pub fn ct_round(&self) -> Option<bool> {
        self.ct_score.map(|s| s >= 1.0)
    }

    /// The CT shape in words, as the list shows it.
    pub fn ct_shape(&self) -> &'static str {
        match (self.ct_blobness, self.ct_round()) {
            (None, _) => "outside the CT",
            (Some(_), None) => "CT shape unknown",
            (Some(_), Some(true)) => "round on CT",
            (Some(_), Some(false)) => "not round",
        }
    }
}

/// The hot spots of a PET and the reference they were cut at.
#[derive(Clone, Debug, PartialEq)]
pub struct HotSpots {
    pub reference: Reference,
    /// Strongest SUVpeak first.
    pub spots: Vec<HotSpot>,
}

/// The CT's blobness and the score-1 value it is read against.
pub struct CtShape<'a> {
    pub ct: &'a Volume,
    pub blobness: &'a [f32],
    pub reference: f32,
}

/// The hot spots of `pet` (values in SUV), each with the CT's shape where `ct` holds it.
pub fn hot_spots(pet: &Volume, ct: Option<&CtShape>) -> HotSpots {
    let suv = pet.to_f32();
    let reference = reference(pet, &suv);
    let threshold = reference.threshold;
    let [nx, ny, _] = pet.dims;
    let index = |i: usize, j: usize, k: usize| i + nx * (j + ny * k);
    let ijk = |n: usize| [n % nx, (n / nx) % ny, n / (nx * ny)];
    let mut maxima: Vec<usize> = (0..suv.len())
        .filter(|&n| {
            let v = suv[n];
            f64::from(v) > threshold
                && neighbours(pet.dims, ijk(n)).all(|m| {
                    let (o, w) = (index(m[0], m[1], m[2]), suv[index(m[0], m[1], m[2])]);
                    w < v || (w == v && o > n) || w.is_nan()
                })
        })
        .collect();
    maxima.sort_by(|a, b| suv[*b].total_cmp(&suv[*a]).then(a.cmp(b)));
    let voxel_ml = pet.spacing_mm.iter().product::<f64>() / 1000.0;
    let world = pet.world_from_voxel();
    let peak_sphere = sphere_offsets(pet.spacing_mm, PEAK_SPHERE_RADIUS_MM);
    // Voxel -> the maximum (kept or dropped) whose region holds it.
    let mut owner: HashMap<usize, usize> = HashMap::new();
    let mut spots = Vec::new();
    for (id, peak) in maxima.into_iter().enumerate() {
        if owner.contains_key(&peak) {
            continue;
        }
        // Its region: down to half its peak (and the threshold). Reaching an earlier spot's
        // region on the way means the two are one structure (less than half the peak between
        // them): this maximum joins it.
        let floor = (0.5 * f64::from(suv[peak])).max(threshold);
        let mut region = vec![peak];
        let mut stack = vec![peak];
        let mut seen = HashSet::from([peak]);
        let mut joins = None;
        while let Some(n) = stack.pop() {
            for m in neighbours(pet.dims, ijk(n)) {
                let m = index(m[0], m[1], m[2]);
                if f64::from(suv[m]) < floor || !seen.insert(m) {
                    continue;
                }
                if let Some(&o) = owner.get(&m) {
                    joins = joins.or(Some(o));
                    continue;
                }
                region.push(m);
                stack.push(m);
            }
        }
        let who = joins.unwrap_or(id);
        for &n in &region {
            owner.insert(n, who);
        }
        if joins.is_some() {
            continue;
        }
        // SUVpeak: the hottest 1 cm³ sphere centred anywhere in the spot (PERCIST); the spot
        // is where that sphere is.
        let (suv_peak, centre) = region
            .iter()
            .map(|&n| (offset_mean(pet.dims, &suv, ijk(n), &peak_sphere), n))
            .filter(|(m, _)| m.is_finite())
            .max_by(|a, b| a.0.total_cmp(&b.0).then(b.1.cmp(&a.1)))
            .unwrap_or((f64::from(suv[peak]), peak));
        let at = ijk(centre);
        let lps = world.transform_point3(DVec3::from(at.map(|v| v as f64)));
        if suv_peak <= threshold {
            continue;
        }
        let volume_ml = region.len() as f64 * voxel_ml;
        let radius_mm = (3.0 * volume_ml * 1000.0 / (4.0 * std::f64::consts::PI))
            .cbrt()
            .max(CT_READ_MIN_MM);
        let ct_blobness = ct.and_then(|c| sphere_max(c.ct, c.blobness, lps, radius_mm));
        let ct_score = ct
            .zip(ct_blobness)
            .filter(|(c, _)| c.reference > 0.0)
            .map(|(c, b)| f64::from(b) / f64::from(c.reference));
        spots.push(HotSpot {
            rank: 0,
            pet_voxel: at,
            lps_mm: lps,
            suv_max: f64::from(suv[peak]),
            suv_peak,
            volume_ml,
            ct_blobness,
            ct_score,
        });
    }
    spots.sort_by(|a, b| b.suv_peak.total_cmp(&a.suv_peak));
    for (i, s) in spots.iter_mut().enumerate() {
        s.rank = i + 1;
    }
    HotSpots { reference, spots }
}

/// The PERCIST reference (module documentation, 1).
pub fn reference(pet: &Volume, suv: &[f32]) -> Reference {
    let liver = find_liver(pet, suv);
    let threshold = match liver {
        Some((_, mean, sd)) => 1.5 * mean + 2.0 * sd,
        None => FALLBACK_SUV,
    };
    Reference { liver, threshold }
}

/// The liver's 3 cm sphere: (centre LPS mm, mean, SD), or `None`.
fn find_liver(pet: &Volume, suv: &[f32]) -> Option<(DVec3, f64, f64)> {
    // Sphere statistics on a lattice 7.5 mm apart (a quarter of the sphere), each from the
    // sphere's voxels about 3 mm apart: a whole-body PET stays a matter of seconds. The chosen
    // sphere's statistics are then taken from all its voxels.
    let step: [usize; 3] =
        std::array::from_fn(|a| ((7.5 / pet.spacing_mm[a]).round() as usize).max(1));
    let stride: [i64; 3] =
        std::array::from_fn(|a| ((3.0 / pet.spacing_mm[a]).round() as i64).max(1));
    let all = sphere_offsets(pet.spacing_mm, LIVER_SPHERE_RADIUS_MM);
    let sparse: Vec<[i64; 3]> = all
        .iter()
        .copied()
        .filter(|o| (0..3).all(|a| o[a] % stride[a] == 0))
        .collect();
    let lattice: [usize; 3] = std::array::from_fn(|a| pet.dims[a].div_ceil(step[a]));
    let centre = |p: [usize; 3]| -> [usize; 3] { std::array::from_fn(|a| p[a] * step[a]) };
    let mut homogeneous: HashMap<[usize; 3], f64> = HashMap::new();
    for lk in 0..lattice[2] {
        for lj in 0..lattice[1] {
            for li in 0..lattice[0] {
                let p = [li, lj, lk];
                if let Some((mean, sd)) = sphere_stats(pet, suv, centre(p), &sparse)
                    && (LIVER_SUV.0..=LIVER_SUV.1).contains(&mean)
                    && sd < LIVER_CV_MAX * mean
                {
                    homogeneous.insert(p, sd / mean);
                }
            }
        }
    }
    // The largest 26-connected set of homogeneous lattice points; its calmest sphere.
    let cell_ml = (0..3)
        .map(|a| step[a] as f64 * pet.spacing_mm[a])
        .product::<f64>()
        / 1000.0;
    let mut seen: HashSet<[usize; 3]> = HashSet::new();
    let mut best: Option<(usize, [usize; 3])> = None;
    let mut keys: Vec<[usize; 3]> = homogeneous.keys().copied().collect();
    keys.sort();
    for start in keys {
        if !seen.insert(start) {
            continue;
        }
        let mut stack = vec![start];
        let mut members = Vec::new();
        while let Some(p) = stack.pop() {
            members.push(p);
            for m in neighbours(lattice, p) {
                if homogeneous.contains_key(&m) && seen.insert(m) {
                    stack.push(m);
                }
            }
        }
        let calmest = members
            .iter()
            .copied()
            .min_by(|a, b| homogeneous[a].total_cmp(&homogeneous[b]).then(a.cmp(b)))
            .unwrap_or(start);
        if best.is_none_or(|(size, _)| members.len() > size) {
            best = Some((members.len(), calmest));
        }
    }
    let (size, at) = best?;
    if (size as f64) * cell_ml < LIVER_MIN_ML {
        return None;
    }
    let c = centre(at);
    let (mean, sd) = sphere_stats(pet, suv, c, &all)?;
    let voxel = DVec3::from(c.map(|v| v as f64));
    Some((pet.world_from_voxel().transform_point3(voxel), mean, sd))
}

/// The mean of the finite `values` at `centre + offsets` inside `dims` (NaN when none is).
fn offset_mean(dims: [usize; 3], values: &[f32], centre: [usize; 3], offsets: &[[i64; 3]]) -> f64 {
    let (mut n, mut sum) = (0usize, 0.0f64);
    for o in offsets {
        let p: [i64; 3] = std::array::from_fn(|a| centre[a] as i64 + o[a]);
        if (0..3).any(|a| p[a] < 0 || p[a] >= dims[a] as i64) {
            continue;
        }
        let v = values[p[0] as usize + dims[0] * (p[1] as usize + dims[1] * p[2] as usize)];
        if v.is_finite() {
            n += 1;
            sum += f64::from(v);
        }
    }
    if n == 0 { f64::NAN } else { sum / n as f64 }
}

/// Mean and SD of `suv` at `centre + offsets`; `None` when the sphere leaves the volume or
/// meets a non-finite value.
fn sphere_stats(
    pet: &Volume,
    suv: &[f32],
    centre: [usize; 3],
    offsets: &[[i64; 3]],
) -> Option<(f64, f64)> {
    let [nx, ny, _] = pet.dims;
    let (mut n, mut sum, mut sum2) = (0usize, 0.0f64, 0.0f64);
    for o in offsets {
        let p: [i64; 3] = std::array::from_fn(|a| centre[a] as i64 + o[a]);
        if (0..3).any(|a| p[a] < 0 || p[a] >= pet.dims[a] as i64) {
            return None;
        }
        let v = f64::from(suv[p[0] as usize + nx * (p[1] as usize + ny * p[2] as usize)]);
        if !v.is_finite() {
            return None;
        }
        n += 1;
        sum += v;
        sum2 += v * v;
    }
    if n == 0 {
        return None;
    }
    let mean = sum / n as f64;
    Some((mean, (sum2 / n as f64 - mean * mean).max(0.0).sqrt()))
}

/// Voxel offsets whose centres lie within `radius_mm` of a voxel centre (axis-aligned spacing).
fn sphere_offsets(spacing_mm: [f64; 3], radius_mm: f64) -> Vec<[i64; 3]> {
    let reach: [i64; 3] = std::array::from_fn(|a| (radius_mm / spacing_mm[a]).floor() as i64);
    let mut out = Vec::new();
    for k in -reach[2]..=reach[2] {
        for j in -reach[1]..=reach[1] {
            for i in -reach[0]..=reach[0] {
                let d2 = (i as f64 * spacing_mm[0]).powi(2)
                    + (j as f64 * spacing_mm[1]).powi(2)
                    + (k as f64 * spacing_mm[2]).powi(2);
                if d2 <= radius_mm * radius_mm {
                    out.push([i, j, k]);
                }
            }
        }
    }
    out
}

/// The 26-neighbours of `p` inside `dims`.
fn neighbours(dims: [usize; 3], p: [usize; 3]) -> impl Iterator<Item = [usize; 3]> {
    (0..27).filter(|&c| c != 13).filter_map(move |c| {
        let d = [c % 3, c / 3 % 3, c / 9];
        let q: [usize; 3] = std::array::from_fn(|a| (p[a] + d[a]).wrapping_sub(1));
        (0..3).all(|a| q[a] < dims[a]).then_some(q)
    })
}

/// The voxels of `volume` whose centres lie within `radius_mm` of `centre` (LPS mm).
fn sphere_voxels(volume: &Volume, centre: DVec3, radius_mm: f64) -> Vec<[usize; 3]> {
    let c = volume.voxel_from_world().transform_point3(centre);
    let c = [c.x, c.y, c.z];
    let reach: [f64; 3] = std::array::from_fn(|a| radius_mm / volume.spacing_mm[a]);
    let range = |a: usize| {
        let lo = (c[a] - reach[a]).ceil().max(0.0);
        let hi = (c[a] + reach[a]).floor().min(volume.dims[a] as f64 - 1.0);
        if lo.is_nan() || hi.is_nan() || lo > hi {
            return 0..0;
        }
        lo as usize..hi as usize + 1
    };
    let world = volume.world_from_voxel();
    let mut out = Vec::new();
    for k in range(2) {
        for j in range(1) {
            for i in range(0) {
                let p = world.transform_point3(DVec3::new(i as f64, j as f64, k as f64));
                if (p - centre).length() <= radius_mm {
                    out.push([i, j, k]);
                }
            }
        }
    }
    out
}

/// The mean of `volume`'s finite values whose voxel centres lie within `radius_mm` of `centre`
/// (LPS mm); `None` when no voxel centre is that close. SUVpeak with the 1 cm³ sphere.
pub fn sphere_mean(volume: &Volume, centre: DVec3, radius_mm: f64) -> Option<f64> {
    let (mut n, mut sum) = (0usize, 0.0f64);
    for [i, j, k] in sphere_voxels(volume, centre, radius_mm) {
        let x = volume.value_at(i, j, k);
        if x.is_finite() {
            n += 1;
            sum += f64::from(x);
        }
    }
    (n > 0).then(|| sum / n as f64)
}

/// The largest of `values` (on `volume`'s grid) within `radius_mm` of `centre`; `None` when the
/// volume holds no voxel centre that close.
fn sphere_max(volume: &Volume, values: &[f32], centre: DVec3, radius_mm: f64) -> Option<f32> {
    sphere_voxels(volume, centre, radius_mm)
        .into_iter()
        .map(|[i, j, k]| values[volume.linear_index(i, j, k)])
        .filter(|v| v.is_finite())
        .reduce(f32::max)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A PET of SUV 0.5 (background) with a homogeneous liver of SUV 2 (+-0.1) and two hot
    /// balls, and a CT whose blobness is high at one ball only.
    fn study() -> (Volume, Volume, Vec<f32>) {
        let dims = [60, 60, 60];
        let mut suv = vec![0.5f32; 60 * 60 * 60];
        let at = |i: usize, j: usize, k: usize| i + 60 * (j + 60 * k);
        for k in 0..60 {
            for j in 0..60 {
                for i in 0..60 {
                    if (5..30).contains(&i) && (5..55).contains(&j) && (5..30).contains(&k) {
                        suv[at(i, j, k)] = 2.0 + 0.1 * (((i + j + k) % 3) as f32 - 1.0);
                    }
                    for (c, v) in [([45, 15, 45], 9.0f32), ([45, 45, 45], 6.0)] {
                        let d2 = (0..3)
                            .map(|a| ([i, j, k][a] as f64 - c[a] as f64).powi(2))
                            .sum::<f64>();
                        if d2 <= 4.0 {
                            suv[at(i, j, k)] = v;
                        }
                    }
                }
            }
        }
        let pet = Volume::from_f32(dims, [4.0; 3], suv);
        // The CT: 2 mm voxels over the same space (origin 0), blobness 10 about the first ball.
        let ct = Volume::from_f32([120; 3], [2.0; 3], vec![40.0; 120 * 120 * 120]);
        let mut blob = vec![0.5f32; 120 * 120 * 120];
        blob[90 + 120 * (30 + 120 * 90)] = 10.0;
        (pet, ct, blob)
    }

    #[test]
    fn the_liver_sets_the_percist_threshold_and_spots_carry_their_ct_shape() {
        let (pet, ct, blob) = study();
        let shape = CtShape {
            ct: &ct,
            blobness: &blob,
            reference: 2.0,
        };
        let found = hot_spots(&pet, Some(&shape));
        let (centre, mean, sd) = found.reference.liver.expect("a liver");
        assert!((mean - 2.0).abs() < 0.05, "{mean}");
        assert!(sd < 0.1, "{sd}");
        assert!(centre.x < 30.0 * 4.0 && centre.z < 30.0 * 4.0, "{centre}");
        assert!((found.reference.threshold - (1.5 * mean + 2.0 * sd)).abs() < 1e-9);
        assert!(found.reference.rule().starts_with("PERCIST"));
        assert_eq!(found.spots.len(), 2, "{found:?}");
        let [a, b] = [&found.spots[0], &found.spots[1]];
        // The sphere of the highest mean sits at the ball's centre.
        assert_eq!((a.rank, a.pet_voxel), (1, [45, 15, 45]));
        assert_eq!(a.suv_max, 9.0);
        // The 1 cm³ sphere on 4 mm voxels holds the peak and its 18 nearest neighbours: all 9.
        assert_eq!(a.suv_peak, 9.0);
        assert_eq!(a.ct_round(), Some(true));
        assert_eq!(b.pet_voxel, [45, 45, 45]);
        assert_eq!(b.ct_round(), Some(false));
        assert!((a.volume_ml - 33.0 * 0.064).abs() < 1e-9, "{}", a.volume_ml);
    }

    #[test]
    fn without_a_liver_or_a_ct_the_fallback_is_stated_and_spots_have_no_shape() {
        let pet = Volume::from_f32([20; 3], [4.0; 3], {
            let mut v = vec![0.5f32; 8000];
            v[10 + 20 * (10 + 20 * 10)] = 7.0;
            v
        });
        let found = hot_spots(&pet, None);
        assert_eq!(found.reference.liver, None);
        assert_eq!(found.reference.threshold, FALLBACK_SUV);
        assert!(found.reference.rule().contains("not PERCIST"));
        // One hot voxel among SUV 0.5: SUVpeak = (7 + 18 x 0.5) / 19 = 0.84, below 2.5: dropped.
        assert!(found.spots.is_empty(), "{found:?}");
    }
}
