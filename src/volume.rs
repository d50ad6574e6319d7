//! The `Volume` model: voxels in a compact type plus the scanner geometry (LPS patient space).
//!
//! Conventions (shared by every module; see ARCHITECTURE.md):
//! - Voxel index `(i, j, k)`, `i` fastest in memory: `index = i + nx * (j + ny * k)`.
//! - World space is DICOM's patient space, LPS, in millimetres.
//! - `world_from_voxel * (i, j, k) = origin_mm + direction * diag(spacing_mm) * (i, j, k)`, where
//!   `direction`'s columns are the unit directions of the i, j and k axes in LPS.
//! - The physical value of a voxel (HU for CT) is `raw * value_slope + value_intercept`.

use glam::{DAffine3, DMat3, DVec3};

pub mod packed;
mod reduce;
pub use packed::Packed;

/// What kind of scan the voxels come from, as far as the file tells.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Modality {
    /// Computed tomography; values are Hounsfield units after rescale.
    Ct,
    /// Magnetic resonance; values are arbitrary scanner units.
    Mr,
    /// Positron emission tomography; values in SUVbw when the header allows it, else in the
    /// series' own unit ([`Volume::pet`] says which).
    Pt,
    /// A synthetic volume made by this program (phantoms); values in HU.
    Phantom,
    #[default]
    Unknown,
}

impl Modality {
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Ct => "CT",
            Self::Mr => "MR",
            Self::Pt => "PT",
            Self::Phantom => "phantom",
            Self::Unknown => "unknown",
        }
    }
}

/// Voxel storage in the smallest type the data needs. A 512x512x2000 CT stays i16 (1 GiB), and
/// conversion to f32 happens per chunk on the way to the GPU or the CPU reference.
#[derive(Clone, Debug, PartialEq)]
pub enum Voxels {
    U8(Vec<u8>),
    I16(Vec<i16>),
    U16(Vec<u16>),
    F32(Vec<f32>),
    /// u8, i16 or u16 voxels packed brick by brick, lossless ([`Voxels::packed`]).
    Packed(Packed),
}

impl Voxels {
    pub fn len(&self) -> usize {
        match self {
            Self::U8(v) => v.len(),
            Self::I16(v) => v.len(),
            Self::U16(v) => v.len(),
            Self::F32(v) => v.len(),
            Self::Packed(p) => p.len(),
        }
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Bytes the voxels occupy.
    pub fn byte_len(&self) -> usize {
        match self {
            Self::Packed(p) => p.byte_len(),
            _ => self.len() * self.bytes_per_voxel(),
        }
    }

    /// The raw stored value at a linear index, as f32 (no rescale).
    #[inline]
    pub fn raw_f32(&self, index: usize) -> f32 {
        match self {
            Self::U8(v) => f32::from(v[index]),
            Self::I16(v) => f32::from(v[index]),
            Self::U16(v) => f32::from(v[index]),
            Self::F32(v) => v[index],
            Self::Packed(p) => p.get(index) as f32,
        }
    }

    pub fn type_name(&self) -> &'static str {
        match self {
            Self::U8(_) => "u8",
            Self::I16(_) => "i16",
            Self::U16(_) => "u16",
            Self::F32(_) => "f32",
            Self::Packed(p) => match p.stored() {
                packed::Stored::U8 => "u8 (packed)",
                packed::Stored::I16 => "i16 (packed)",
                packed::Stored::U16 => "u16 (packed)",
            },
        }
    }

    /// Bytes per voxel of the type the voxels have (packed ones: of their unpacked type).
    pub fn bytes_per_voxel(&self) -> usize {
        match self {
            Self::U8(_) => 1,
            Self::I16(_) | Self::U16(_) => 2,
            Self::F32(_) => 4,
            Self::Packed(p) => match p.stored() {
                packed::Stored::U8 => 1,
                packed::Stored::I16 | packed::Stored::U16 => 2,
            },
        }
    }

    /// The same voxels packed ([`Packed`]) when they are integers of a volume of `dims`, and
    /// packing makes them smaller; otherwise as they are.
    pub fn packed(self, dims: [usize; 3]) -> Self {
        let p = match &self {
            Self::U8(v) => Packed::pack(v, dims, packed::Stored::U8),
            Self::I16(v) => Packed::pack(v, dims, packed::Stored::I16),
            Self::U16(v) => Packed::pack(v, dims, packed::Stored::U16),
            _ => None,
        };
        match p {
            Some(p) if p.byte_len() < self.byte_len() => Self::Packed(p),
            _ => self,
        }
    }
}

/// What a PET series' values mean.
#[derive(Clone, Debug, PartialEq)]
pub struct PetScale {
    /// Units (0054,1001) as written ("BQML", "CNTS", "GML"; empty when missing).
    pub units: String,
    /// SUVbw per unit of the rescaled stored value. When known, it is folded into
    /// `value_slope` and `value_intercept`, so the volume's physical values are SUV.
    pub suv_factor: Option<f64>,
    /// How the factor was found (the QIBA rule's branch), or why it could not be.
    pub rule: String,
}

/// A 3D scalar volume with its scanner geometry.
#[derive(Clone, Debug, PartialEq)]
pub struct Volume {
    /// Number of voxels along i, j, k.
    pub dims: [usize; 3],
    /// Distance between voxel centres along i, j, k, in mm (always > 0).
    pub spacing_mm: [f64; 3],
    /// LPS position of the centre of voxel (0, 0, 0), in mm.
    pub origin_mm: [f64; 3],
    /// Direction cosines: column `c` is the LPS unit direction of voxel axis `c`.
    pub direction: DMat3,
    pub voxels: Voxels,
    /// Physical value = raw * value_slope + value_intercept.
    pub value_slope: f32,
    pub value_intercept: f32,
    pub modality: Modality,
    /// For a PET series: its unit and SUV factor.
    pub pet: Option<PetScale>,
    /// DICOM's FrameOfReferenceUID: volumes that share it share one patient space (a PET and
    /// the CT of the same PET/CT scan). `None` for other formats.
    pub frame_of_reference: Option<String>,
    /// Where the volume came from (file name, "phantom: sphere", ...), for the user.
    pub source: String,
    /// Things the user should know (uneven slices, 4D file reduced to its first volume, ...).
    pub warnings: Vec<String>,
}

impl Volume {
    /// Whether the values look like Hounsfield units of a CT: told so by the file, or air at
    /// about -1000 HU present (`range`, the values' minimum and maximum) in a volume of unknown
    /// modality.
    pub fn looks_like_ct(&self, range: Option<(f32, f32)>) -> bool {
        match self.modality {
            Modality::Ct => true,
            Modality::Unknown => {
                range.is_some_and(|(lo, hi)| (-1100.0..=-900.0).contains(&lo) && hi > 100.0)
            }
            Modality::Mr | Modality::Pt | Modality::Phantom => false,
        }
    }

    /// An axis-aligned volume (identity direction, origin at 0) holding physical values as f32.
    pub fn from_f32(dims: [usize; 3], spacing_mm: [f64; 3], values: Vec<f32>) -> Self {
        debug_assert_eq!(values.len(), dims[0] * dims[1] * dims[2]);
        Self {
            dims,
            spacing_mm,
            origin_mm: [0.0; 3],
            direction: DMat3::IDENTITY,
            voxels: Voxels::F32(values),
            value_slope: 1.0,
            value_intercept: 0.0,
            modality: Modality::Unknown,
            pet: None,
            frame_of_reference: None,
            source: String::new(),
            warnings: Vec::new(),
        }
    }

    /// The same volume (geometry, rescale, modality, notes) with other voxels (of its size, or
    /// the caller sets the geometry that goes with them).
    pub fn with_voxels(&self, voxels: Voxels) -> Self {
        Self {
            dims: self.dims,
            spacing_mm: self.spacing_mm,
            origin_mm: self.origin_mm,
            direction: self.direction,
            voxels,
            value_slope: self.value_slope,
            value_intercept: self.value_intercept,
            modality: self.modality,
            pet: self.pet.clone(),
            frame_of_reference: self.frame_of_reference.clone(),
            source: self.source.clone(),
            warnings: self.warnings.clone(),
        }
    }

    /// The unit of the physical values, for the user: "HU" (CT and phantoms), "SUV" (a PET
    /// with its SUV factor), the PET's own unit without one, "" when unknown.
    pub fn unit(&self) -> &str {
        match self.modality {
            Modality::Ct | Modality::Phantom => "HU",
            Modality::Pt => match &self.pet {
                Some(p) if p.suv_factor.is_some() => "SUV",
                Some(p) => p.units.as_str(),
                None => "",
            },
            Modality::Mr | Modality::Unknown => "",
        }
    }

    pub fn voxel_count(&self) -> usize {
        self.dims[0] * self.dims[1] * self.dims[2]
    }

    #[inline]
    pub fn linear_index(&self, i: usize, j: usize, k: usize) -> usize {
        i + self.dims[0] * (j + self.dims[1] * k)
    }

    /// Physical value (HU for CT) at a linear index.
    #[inline]
    pub fn value(&self, index: usize) -> f32 {
        self.voxels.raw_f32(index) * self.value_slope + self.value_intercept
    }

    /// Physical value at voxel (i, j, k).
    #[inline]
    pub fn value_at(&self, i: usize, j: usize, k: usize) -> f32 {
        self.value(self.linear_index(i, j, k))
    }

    /// Writes the physical values of voxels `start..start + out.len()` into `out`, as every
    /// computation sees them (the GPU upload, the CPU reference, the rendered volume): a voxel
    /// that is not finite (NaN or +-inf: missing data, or a rescale that overflows) is replaced
    /// by the nearest finite value along its row (the i axis, the lower index on a tie), and
    /// in a row without any finite value by the minimum finite value of its slice (of the
    /// volume for a slice without any; 0 when there is none). One missing voxel then moves a feature as one wrong voxel would, instead of
    /// spreading NaN over everything a kernel reaches (a whole blob's features). The result does
    /// not depend on how a caller splits the volume into chunks. [`Self::value`] still gives
    /// the stored value; [`Self::non_finite_count`] says how many voxels are replaced.
    pub fn values_into(&self, start: usize, out: &mut [f32]) {
        let mut all_finite = true;
        if let Voxels::Packed(p) = &self.voxels {
            // Decoded a run at a time rather than voxel by voxel.
            let mut raw = [0i32; 4096];
            for (n, chunk) in out.chunks_mut(raw.len()).enumerate() {
                let raw = &mut raw[..chunk.len()];
                p.decode_into(start + n * 4096, raw);
                for (o, &r) in chunk.iter_mut().zip(raw.iter()) {
                    *o = r as f32 * self.value_slope + self.value_intercept;
                    all_finite &= o.is_finite();
                }
            }
        } else {
            for (n, o) in out.iter_mut().enumerate() {
                *o = self.value(start + n);
                all_finite &= o.is_finite();
            }
        }
        if !all_finite {
            self.replace_non_finite(start, out);
        }
    }

    /// The replacement rule of [`Self::values_into`] for `out` = the values of voxels
    /// `start..start + out.len()`, row by row: O(row length) per row holding a non-finite
    /// value; a row without any finite value costs one pass over its slice (once per slice
    /// and call), and over the volume only when the whole slice is missing.
    fn replace_non_finite(&self, start: usize, out: &mut [f32]) {
        let nx = self.dims[0].max(1);
        let plane = nx * self.dims[1].max(1);
        let end = start + out.len();
        let mut row = vec![0.0f32; nx];
        let mut fill = vec![0.0f32; nx];
        let mut slice_min: Option<(usize, Option<f32>)> = None;
        let mut volume_min: Option<f32> = None;
        let mut row_start = start - start % nx;
        while row_start < end {
            let lo = row_start.max(start);
            let hi = (row_start + nx).min(end);
            if out[lo - start..hi - start].iter().any(|v| !v.is_finite()) {
                // The whole row, also the part outside this chunk.
                let len = nx.min(self.voxel_count().saturating_sub(row_start));
                for (i, r) in row[..len].iter_mut().enumerate() {
                    *r = self.value(row_start + i);
                }
                if nearest_finite_in_row(&row[..len], &mut fill[..len]).is_none() {
                    // The minimum finite value of the row's slice (outside a scanner's field
                    // of view: about its air), else of the volume, else 0.
                    let k = row_start / plane;
                    if slice_min.is_none_or(|(sk, _)| sk != k) {
                        let first = k * plane;
                        let last = (first + plane).min(self.voxel_count());
                        let min = (first..last)
                            .map(|i| self.value(i))
                            .filter(|v| v.is_finite())
                            .reduce(f32::min);
                        slice_min = Some((k, min));
                    }
                    let v = match slice_min {
                        Some((_, Some(min))) => min,
                        _ => *volume_min
                            .get_or_insert_with(|| self.value_range().map_or(0.0, |(min, _)| min)),
                    };
                    fill[..len].iter_mut().for_each(|f| *f = v);
                }
                for idx in lo..hi {
                    let o = &mut out[idx - start];
                    if !o.is_finite() {
                        *o = fill[idx - row_start];
                    }
                }
            }
            row_start += nx;
        }
    }

    /// How many voxels have a physical value that is NaN or infinite (replaced in
    /// [`Self::values_into`]).
    pub fn non_finite_count(&self) -> usize {
        // Integer voxels (|raw| <= 65535) under a finite rescale that cannot overflow f32 are
        // all finite: no need to look at each.
        let integer = !matches!(self.voxels, Voxels::F32(_));
        let bound =
            65535.0 * f64::from(self.value_slope).abs() + f64::from(self.value_intercept).abs();
        if integer && bound < 1e37 {
            return 0;
        }
        (0..self.voxel_count())
            .filter(|&i| !self.value(i).is_finite())
            .count()
    }

    /// The warning for the user when some voxels are not finite, naming how many.
    pub fn non_finite_warning(&self) -> Option<String> {
        let n = self.non_finite_count();
        (n > 0).then(|| {
            format!(
                "{n} of {} voxels are NaN or infinite: the features use the nearest finite value along each one's row (i axis) instead",
                self.voxel_count()
            )
        })
    }

    /// All physical values as f32, non-finite ones replaced as in [`Self::values_into`].
    /// Allocates 4 bytes per voxel: for small volumes and tests; large volumes go through
    /// [`Self::values_into`] chunk by chunk.
    pub fn to_f32(&self) -> Vec<f32> {
        let mut out = vec![0.0; self.voxel_count()];
        self.values_into(0, &mut out);
        out
    }

    /// Minimum and maximum physical value, or `None` for an empty volume.
    pub fn value_range(&self) -> Option<(f32, f32)> {
        let n = self.voxel_count();
        if n == 0 {
            return None;
        }
        // Packed voxels know their range brick by brick (integers: finite under a finite
        // rescale).
        if let Voxels::Packed(p) = &self.voxels {
            let (lo, hi) = p.range()?;
            let (a, b) = (
                lo as f32 * self.value_slope + self.value_intercept,
                hi as f32 * self.value_slope + self.value_intercept,
            );
            if a.is_finite() && b.is_finite() {
                return Some((a.min(b), a.max(b)));
            }
        }
        let mut lo = f32::INFINITY;
        let mut hi = f32::NEG_INFINITY;
        for idx in 0..n {
            let v = self.value(idx);
            if v.is_finite() {
                lo = lo.min(v);
                hi = hi.max(v);
            }
        }
        (lo <= hi).then_some((lo, hi))
    }

    /// The physical value at an LPS point (mm), trilinear between voxel centres (non-finite
    /// voxels as [`Self::value`] gives them); `None` outside the voxel centres' box. How a PET is
    /// read at a CT's point: on its own grid, never resampled into a copy.
    pub fn value_at_world(&self, p_world: DVec3) -> Option<f32> {
        self.value_at_continuous(self.voxel_from_world().transform_point3(p_world))
    }

    /// The physical value at a continuous voxel index, trilinear between voxel centres; `None`
    /// outside the voxel centres' box.
    pub fn value_at_continuous(&self, q: DVec3) -> Option<f32> {
        let q = [q.x, q.y, q.z];
        let mut i0 = [0usize; 3];
        let mut w = [0.0f64; 3];
        for a in 0..3 {
            let max = self.dims[a].checked_sub(1)? as f64;
            if !(q[a] >= -1e-6 && q[a] <= max + 1e-6) {
                return None;
            }
            let c = q[a].clamp(0.0, max);
            let f = c.floor().min((max - 1.0).max(0.0));
            i0[a] = f as usize;
            w[a] = c - f;
        }
        let mut sum = 0.0f64;
        for corner in 0..8 {
            let mut weight = 1.0;
            let mut idx = [0usize; 3];
            for a in 0..3 {
                let hi = corner >> a & 1 == 1;
                weight *= if hi { w[a] } else { 1.0 - w[a] };
                idx[a] = (i0[a] + usize::from(hi)).min(self.dims[a] - 1);
            }
            if weight > 0.0 {
                sum += weight * f64::from(self.value_at(idx[0], idx[1], idx[2]));
            }
        }
        Some(sum as f32)
    }

    /// Its grid as a reader is told it: "512 × 512 × 30 voxels, 0.703 × 0.703 × 8.000 mm".
    pub fn grid_text(&self) -> String {
        let ([i, j, k], [x, y, z]) = (self.dims, self.spacing_mm);
        format!("{i} × {j} × {k} voxels, {x:.3} × {y:.3} × {z:.3} mm")
    }

    /// Physical size of the volume's bounding box (centre to centre of the outer voxels), mm.
    pub fn extent_mm(&self) -> [f64; 3] {
        std::array::from_fn(|a| (self.dims[a].max(1) - 1) as f64 * self.spacing_mm[a])
    }

    /// The affine map from continuous voxel index to LPS mm.
    pub fn world_from_voxel(&self) -> DAffine3 {
        let scale = DMat3::from_diagonal(DVec3::from(self.spacing_mm));
        DAffine3 {
            matrix3: self.direction * scale,
            translation: DVec3::from(self.origin_mm),
        }
    }

    /// The affine map from LPS mm to continuous voxel index.
    pub fn voxel_from_world(&self) -> DAffine3 {
        self.world_from_voxel().inverse()
    }
}

/// A value with its unit for the user: two decimals for SUV, whole numbers otherwise (HU,
/// scanner units).
pub fn format_value(value: f32, unit: &str) -> String {
    let digits = if unit == "SUV" { 2 } else { 0 };
    if unit.is_empty() {
        format!("{value:.digits$}")
    } else {
        format!("{value:.digits$} {unit}")
    }
}

/// For each position of `row`, the nearest finite value of `row` (the lower index on a tie),
/// written into `fill`; `None` when `row` has no finite value.
fn nearest_finite_in_row(row: &[f32], fill: &mut [f32]) -> Option<()> {
    // Forward: the last finite value at or before each position and its distance.
    let mut left: Option<(usize, f32)> = None;
    let mut left_at = vec![None; row.len()];
    for (i, &v) in row.iter().enumerate() {
        if v.is_finite() {
            left = Some((i, v));
        }
        left_at[i] = left;
    }
    let mut right: Option<(usize, f32)> = None;
    for i in (0..row.len()).rev() {
        if row[i].is_finite() {
            right = Some((i, row[i]));
        }
        fill[i] = match (left_at[i], right) {
            (Some((l, lv)), Some((r, rv))) => {
                if i - l <= r - i {
                    lv
                } else {
                    rv
                }
            }
            (Some((_, v)), None) | (None, Some((_, v))) => v,
            (None, None) => return None,
        };
    }
    Some(())
}

/// The patient-direction label (DICOM letters, LPS) a direction points towards, most significant
/// component first, e.g. `"L"`, `"PS"`, `"RAI"`. Components below 1/8 of the largest are left out.
pub fn orientation_label(direction_lps: DVec3) -> String {
    let comps = [
        (direction_lps.x, 'L', 'R'),
        (direction_lps.y, 'P', 'A'),
        (direction_lps.z, 'S', 'I'),
    ];
    let largest = comps.iter().map(|c| c.0.abs()).fold(0.0, f64::max);
    if largest == 0.0 {
        return String::new();
    }
    let mut order: Vec<_> = comps.iter().collect();
    order.sort_by(|a, b| b.0.abs().total_cmp(&a.0.abs()));
    order
        .into_iter()
        .filter(|c| c.0.abs() >= largest / 8.0)
        .map(|&(v, pos, neg)| if v > 0.0 { pos } else { neg })
        .collect()
}

#[cfg(test)]
mod tests;
