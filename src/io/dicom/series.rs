//! Assembling DICOM files into one volume: grouping by SeriesInstanceUID and orientation into
//! stacks (`listing` lists them; the CT or MR stack with the most images is loaded unless
//! another is chosen), ordering frames by ImagePositionPatient projected on the
//! slice normal, slice spacing from the positions (with warnings for a disagreeing
//! SliceThickness, uneven or missing slices), rescale, and pixel decoding frame by frame.

use std::collections::BTreeMap;

use dicom_pixeldata::PixelDecoder;
use glam::DVec3;

use super::{FileHeader, FrameInfo, NATIVE_SYNTAXES, check_transfer_syntax, encapsulated, open};
use crate::io::geometry::checked_grid;
use crate::io::raw;
use crate::io::{InputFile, Limits, LoadError};
use crate::volume::{PetScale, Volume, Voxels};

/// One frame of the chosen series: which file, which frame in it, and its header values.
pub(super) struct Frame<'a> {
    pub file: usize,
    pub frame: usize,
    pub info: &'a FrameInfo,
}

/// What the headers of a series' images say for the user, sorted so that the volume does not
/// depend on the order the files came in.
pub(super) fn header_warnings<'a>(headers: impl Iterator<Item = &'a FileHeader>) -> Vec<String> {
    let mut file_warnings: Vec<String> = headers.flat_map(|h| h.warnings.iter().cloned()).collect();
    file_warnings.sort();
    file_warnings.dedup();
    file_warnings
}

/// The error when no file holds an image: the first file's own error if there was one.
pub(super) fn no_image_error(names: &[&str]) -> LoadError {
    match names {
        [one] => LoadError::Dicom {
            file: (*one).to_owned(),
            message: "holds no image (no Rows and Columns)".to_owned(),
        },
        many => LoadError::DicomSeries {
            series: "-".to_owned(),
            message: format!(
                "none of the {} DICOM files holds an image ({}{})",
                many.len(),
                many.iter().take(3).copied().collect::<Vec<_>>().join(", "),
                if many.len() > 3 { ", ..." } else { "" }
            ),
        },
    }
}

/// Images that make one volume: one series' images of one size and one orientation.
#[derive(Clone, Debug)]
pub(super) struct Stack {
    pub series_uid: String,
    pub rows: u32,
    pub cols: u32,
    /// Which of the series' orientations of this size (0 for the first met).
    pub stack: usize,
    /// The stack's ImageOrientationPatient (`None` when its images have none).
    pub orientation: Option<[f64; 6]>,
    /// Indices into the headers grouped, in a fixed order.
    pub members: Vec<usize>,
    /// Frames of all members.
    pub frames: usize,
}

/// Groups images (named headers) by series and image size, which must be shared within a
/// volume, and splits a series into stacks by ImageOrientationPatient (as dcm2niix does): a
/// localizer, a sagittal slice among axial ones or a slice rotated in plane is not stacked with
/// the others. Files are visited in a fixed order and the stacks are sorted (series UID, size,
/// orientation met first), so the grouping does not depend on the order the files came in.
/// The file loader, the series list and the streaming builder share it.
pub(super) fn group_stacks(headers: &[(&str, &FileHeader)]) -> Vec<Stack> {
    let mut order: Vec<usize> = (0..headers.len()).collect();
    order.sort_by(|&a, &b| {
        let (ha, hb) = (headers[a].1, headers[b].1);
        (&ha.sop_instance_uid, headers[a].0).cmp(&(&hb.sop_instance_uid, headers[b].0))
    });
    let mut known_orientations: BTreeMap<(String, u32, u32), Vec<[f64; 6]>> = BTreeMap::new();
    let mut groups: BTreeMap<(String, u32, u32, usize), Vec<usize>> = BTreeMap::new();
    for h_index in order {
        let h = headers[h_index].1;
        let series_key = (h.series_uid.clone(), h.rows, h.cols);
        let known = known_orientations.entry(series_key).or_default();
        // Files without an orientation join the first stack.
        let stack = match h.frames.iter().find_map(|f| f.orientation) {
            None => 0,
            Some(o) => match known
                .iter()
                .position(|k| k.iter().zip(&o).all(|(a, b)| (a - b).abs() < 1e-3))
            {
                Some(i) => i,
                None => {
                    known.push(o);
                    known.len() - 1
                }
            },
        };
        groups
            .entry((h.series_uid.clone(), h.rows, h.cols, stack))
            .or_default()
            .push(h_index);
    }
    groups
        .into_iter()
        .map(|((series_uid, rows, cols, stack), members)| {
            let orientation = known_orientations
                .get(&(series_uid.clone(), rows, cols))
                .and_then(|k| k.get(stack))
                .copied();
            let frames = members.iter().map(|&m| headers[m].1.frames.len()).sum();
            Stack {
                series_uid,
                rows,
                cols,
                stack,
                orientation,
                members,
                frames,
            }
        })
        .collect()
}

/// The stack to load when none is chosen: the CT or MR stack with the most images, the first
/// of equals (the archive's chooser, [`crate::io::dicomweb::choose_series`], on the stacks).
pub(super) fn default_stack(stacks: &[Stack], headers: &[(&str, &FileHeader)]) -> Option<usize> {
    let infos: Vec<crate::io::dicomweb::SeriesInfo> = stacks
        .iter()
        .map(|s| crate::io::dicomweb::SeriesInfo {
            series_uid: s.series_uid.clone(),
            modality: s
                .members
                .first()
                .map(|&m| headers[m].1.modality_name.clone()),
            instances: Some(s.frames as u64),
            ..Default::default()
        })
        .collect();
    crate::io::dicomweb::choose_series(&infos)
}

/// Notes on the stacks that were not loaded: another orientation of the chosen series, or
/// another series.
pub(super) fn other_stack_notes(
    stacks: &[Stack],
    chosen: usize,
    headers: &[(&str, &FileHeader)],
    notes: &mut Vec<String>,
) {
    let Some(c) = stacks.get(chosen) else {
        return;
    };
    for (i, s) in stacks.iter().enumerate() {
        let Some(&first) = s.members.first() else {
            continue;
        };
        if i == chosen {
            continue;
        }
        let h = headers[first].1;
        if (&s.series_uid, s.rows, s.cols) == (&c.series_uid, c.rows, c.cols) {
            notes.push(format!(
                "{} image(s) of series {} were not stacked with the others: their ImageOrientationPatient {:?} differs from the loaded images' {:?} (a localizer, another plane or a rotated slice?); first: {}",
                s.frames,
                s.series_uid,
                s.orientation.unwrap_or_default(),
                c.orientation.unwrap_or_default(),
                headers[first].0
            ));
        } else {
            notes.push(format!(
                "another series was not loaded: {} \"{}\" ({} images of {}x{}, {})",
                s.series_uid, h.series_description, s.frames, s.cols, s.rows, h.modality_name
            ));
        }
    }
}

/// The stack to load among images (named headers; [`group_stacks`], [`default_stack`]): its
/// series UID and its members (indices into `headers`), with notes on the others. The
/// streaming builder ([`super::stream::SeriesBuilder`]) uses it.
pub(super) fn choose_stack(
    headers: &[(&str, &FileHeader)],
    notes: &mut Vec<String>,
) -> Result<(String, Vec<usize>), LoadError> {
    let mut stacks = group_stacks(headers);
    let chosen = default_stack(&stacks, headers).ok_or_else(|| LoadError::DicomSeries {
        series: "-".to_owned(),
        message: "no series".to_owned(),
    })?;
    other_stack_notes(&stacks, chosen, headers, notes);
    let stack = stacks.swap_remove(chosen);
    Ok((stack.series_uid, stack.members))
}

/// Geometry and voxels of one series.
///
/// With `release` this is the last read of the files: each lets its pixel bytes go as they are
/// decoded ([`crate::io::FileSource::release_before`]; the browser's bytes shrink as the voxels
/// grow).
pub(super) fn assemble(
    series: &str,
    files: &[(&InputFile, &FileHeader)],
    limits: &Limits,
    release: bool,
) -> Result<Volume, LoadError> {
    let named: Vec<(&str, &FileHeader)> =
        files.iter().map(|(f, h)| (f.name.as_str(), *h)).collect();
    let mut layout = layout(&named)?;
    let (voxels, value_slope, value_intercept) = read_pixels(
        series,
        files,
        &layout.frames,
        limits,
        release,
        &mut layout.warnings,
    )?;
    Ok(layout.into_volume(series, &named, voxels, value_slope, value_intercept))
}

/// The geometry of one stack of images and the order of its frames (slot `s` of the volume is
/// `frames[s]`), from the headers alone.
pub(super) struct Layout<'a> {
    pub frames: Vec<Frame<'a>>,
    pub dims: [usize; 3],
    pub spacing_mm: [f64; 3],
    pub origin_mm: [f64; 3],
    pub direction: glam::DMat3,
    pub warnings: Vec<String>,
}

impl Layout<'_> {
    /// The volume of this layout with its voxels (files named as in [`layout`]).
    pub(super) fn into_volume(
        self,
        series: &str,
        files: &[(&str, &FileHeader)],
        voxels: Voxels,
        value_slope: f32,
        value_intercept: f32,
    ) -> Volume {
        let source = if files.len() == 1 {
            files[0].0.to_owned()
        } else {
            format!("DICOM series {series} ({} files)", files.len())
        };
        let mut warnings = self.warnings;
        let pet = pet_scale(files, &mut warnings);
        // A known SUV factor is folded into the rescale: the volume's values are then SUV.
        let suv = pet.as_ref().and_then(|p| p.suv_factor).unwrap_or(1.0);
        Volume {
            dims: self.dims,
            spacing_mm: self.spacing_mm,
            origin_mm: self.origin_mm,
            direction: self.direction,
            voxels,
            value_slope: (f64::from(value_slope) * suv) as f32,
            value_intercept: (f64::from(value_intercept) * suv) as f32,
            modality: files[0].1.modality,
            pet,
            frame_of_reference: files[0].1.frame_of_reference.clone(),
            source,
            warnings,
        }
    }
}

/// A PET series' unit and SUVbw factor from its images' tags (the QIBA rule,
/// [`super::suv::suv_factor`]). Without a factor the PET keeps its own unit, and a warning names
/// what is missing or contradictory.
fn pet_scale(files: &[(&str, &FileHeader)], warnings: &mut Vec<String>) -> Option<PetScale> {
    let tags: Vec<super::suv::PetTags> = files.iter().filter_map(|(_, h)| h.pet.clone()).collect();
    let first = tags.first()?;
    let units = first.units.clone().unwrap_or_default();
    Some(match super::suv::suv_factor(&tags) {
        Ok(f) => PetScale {
            units,
            suv_factor: Some(f.factor),
            rule: f.rule,
        },
        Err(e) => {
            let shown = if units.is_empty() {
                "its stored unit"
            } else {
                units.as_str()
            };
            warnings.push(format!("PET shown in {shown}, not SUV: {e}"));
            PetScale {
                units,
                suv_factor: None,
                rule: e.to_string(),
            }
        }
    })
}

/// Checks that the images of a stack store pixels alike, orders their frames and works out
/// the geometry (the file loader and the streaming builder share it).
pub(super) fn layout<'a>(files: &[(&str, &'a FileHeader)]) -> Result<Layout<'a>, LoadError> {
    let first = files[0].1;
    let name0 = files[0].0;
    let mut warnings = Vec::new();
    if first.samples_per_pixel != 1 {
        return Err(LoadError::unsupported(
            name0,
            "DICOM image",
            format!(
                "{} samples per pixel ({}); only greyscale volumes are loaded",
                first.samples_per_pixel, first.photometric
            ),
        ));
    }
    for (f, h) in files {
        if (h.bits_allocated, h.signed, h.samples_per_pixel)
            != (first.bits_allocated, first.signed, first.samples_per_pixel)
        {
            return Err(LoadError::DicomSeries {
                series: first.series_uid.clone(),
                message: format!(
                    "{f} stores pixels differently from {name0} (BitsAllocated/PixelRepresentation)"
                ),
            });
        }
    }
    if !matches!(first.bits_allocated, 1 | 8 | 16 | 32) {
        return Err(LoadError::unsupported(
            name0,
            "BitsAllocated",
            first.bits_allocated.to_string(),
        ));
    }

    let mut frames: Vec<Frame<'_>> = files
        .iter()
        .enumerate()
        .flat_map(|(fi, (_, h))| {
            h.frames.iter().enumerate().map(move |(k, info)| Frame {
                file: fi,
                frame: k,
                info,
            })
        })
        .collect();

    // Orientation and in-plane spacing from the first frame that has them.
    let iop = frames.iter().find_map(|f| f.info.orientation);
    let (row_dir, col_dir) = match iop {
        Some(o) => (DVec3::new(o[0], o[1], o[2]), DVec3::new(o[3], o[4], o[5])),
        None => {
            warnings.push("no ImageOrientationPatient: axes are assumed to be L, P, S".to_owned());
            (DVec3::X, DVec3::Y)
        }
    };
    let (row_dir, col_dir) = (row_dir.normalize_or_zero(), col_dir.normalize_or_zero());
    let normal = row_dir.cross(col_dir);
    if normal.length() < 0.5 {
        return Err(LoadError::header(
            name0,
            "ImageOrientationPatient",
            format!("{iop:?} does not give two perpendicular directions"),
        ));
    }
    let normal = normal.normalize();
    if frames.iter().any(|f| {
        f.info.orientation.is_some_and(|o| {
            (DVec3::new(o[0], o[1], o[2]) - row_dir).length() > 1e-3
                || (DVec3::new(o[3], o[4], o[5]) - col_dir).length() > 1e-3
        })
    }) {
        warnings.push(
            "ImageOrientationPatient differs between slices; the first slice's is used".to_owned(),
        );
    }
    let ps = frames.iter().find_map(|f| f.info.pixel_spacing);
    let pixel_spacing = ps.unwrap_or_else(|| {
        warnings.push("no PixelSpacing: 1 mm assumed".to_owned());
        [1.0, 1.0]
    });
    if frames.iter().any(|f| {
        f.info.pixel_spacing.is_some_and(|p| {
            (p[0] - pixel_spacing[0]).abs() > 1e-4 || (p[1] - pixel_spacing[1]).abs() > 1e-4
        })
    }) {
        warnings.push("PixelSpacing differs between slices; the first slice's is used".to_owned());
    }

    // Order: by position along the normal when every frame has one; ties (and frames without
    // positions) by InstanceNumber, SOPInstanceUID and frame number, so that the input order of
    // the files never matters.
    let all_positioned = frames.iter().all(|f| f.info.position.is_some());
    let proj = |f: &Frame<'_>| f.info.position.map_or(0.0, |p| p.dot(normal));
    let tie = |f: &Frame<'_>| {
        (
            files[f.file].1.instance_number,
            files[f.file].1.sop_instance_uid.clone(),
            files[f.file].0,
            f.frame,
        )
    };
    if all_positioned {
        frames.sort_by(|a, b| {
            proj(a)
                .total_cmp(&proj(b))
                .then_with(|| tie(a).cmp(&tie(b)))
        });
        let before = frames.len();
        frames.dedup_by(|b, a| (proj(b) - proj(a)).abs() < 1e-3);
        if frames.len() < before {
            warnings.push(format!(
                "{} images share a position with another (several echoes, phases or duplicates?); the first at each position is used",
                before - frames.len()
            ));
        }
    } else {
        if frames.len() > 1 {
            let some = frames.iter().any(|f| f.info.position.is_some());
            warnings.push(format!(
                "ImagePositionPatient is missing on {} images: slices are ordered by InstanceNumber and frame number",
                if some { "some" } else { "all" }
            ));
        }
        frames.sort_by_cached_key(|a| tie(a));
    }

    // The slice step: from the first to the last position (keeping a gantry tilt's shear),
    // else from SpacingBetweenSlices or SliceThickness.
    let n = frames.len();
    let thickness = frames.iter().find_map(|f| f.info.thickness);
    let between = frames.iter().find_map(|f| f.info.spacing_between);
    let first_pos = frames[0].info.position;
    let slice_step = if all_positioned && n > 1 {
        let (p0, p1) = (
            first_pos.unwrap_or_default(),
            frames[n - 1].info.position.unwrap_or_default(),
        );
        let step = (p1 - p0) / (n - 1) as f64;
        let gaps: Vec<f64> = frames
            .windows(2)
            .map(|w| proj(&w[1]) - proj(&w[0]))
            .collect();
        let mut sorted = gaps.clone();
        sorted.sort_by(f64::total_cmp);
        let median = sorted[sorted.len() / 2];
        let (lo, hi) = (sorted[0], sorted[sorted.len() - 1]);
        if hi - lo > (0.01 * median).max(0.005) {
            let missing: usize = gaps
                .iter()
                .map(|g| ((g / median).round() as i64 - 1).max(0) as usize)
                .sum();
            if missing > 0 {
                warnings.push(format!(
                    "uneven slice positions: gaps from {lo:.3} to {hi:.3} mm (median {median:.3} mm); about {missing} slice(s) seem to be missing. The volume uses the average spacing {:.3} mm",
                    step.length()
                ));
            } else {
                warnings.push(format!(
                    "uneven slice positions: gaps from {lo:.3} to {hi:.3} mm (median {median:.3} mm); the volume uses the average spacing {:.3} mm",
                    step.length()
                ));
            }
        }
        if let Some(t) = thickness
            && (t - median).abs() > 0.01 * median.max(t) + 1e-3
        {
            warnings.push(format!(
                "SliceThickness is {t} mm but the slice positions are {median:.3} mm apart; the spacing from the positions is used"
            ));
        }
        step
    } else {
        let s = between.or(thickness).unwrap_or_else(|| {
            if n > 1 {
                warnings.push("no slice positions, SpacingBetweenSlices or SliceThickness: 1 mm between slices assumed".to_owned());
            }
            1.0
        });
        if n > 1 && !all_positioned && (between.is_some() || thickness.is_some()) {
            warnings.push(format!(
                "slice spacing {s} mm taken from {} as the images have no positions",
                if between.is_some() {
                    "SpacingBetweenSlices"
                } else {
                    "SliceThickness"
                }
            ));
        }
        normal * s
    };
    if first_pos.is_none() {
        warnings.push("no ImagePositionPatient: the origin is set to 0".to_owned());
    }
    let axes = [
        row_dir * pixel_spacing[1],
        col_dir * pixel_spacing[0],
        slice_step,
    ];
    let grid = checked_grid(
        name0,
        ("ImagePositionPatient/ImageOrientationPatient", axes),
        ("ImagePositionPatient", first_pos.unwrap_or(DVec3::ZERO)),
        &mut warnings,
    )?;

    Ok(Layout {
        frames,
        dims: [first.cols as usize, first.rows as usize, n],
        spacing_mm: grid.spacing_mm,
        origin_mm: grid.origin_mm,
        direction: grid.direction,
        warnings,
    })
}

/// How decoded samples are stored in the volume.
#[derive(Clone, Copy, PartialEq, Debug)]
pub(super) enum Target {
    U8,
    I16,
    U16,
    F32,
}

impl Target {
    /// The compact type that holds a stored sample of these bits without loss (32-bit samples
    /// go to f32).
    pub(super) fn raw(bits_allocated: u16, signed: bool) -> Self {
        match (bits_allocated, signed) {
            (1, _) | (8, false) => Self::U8,
            (8, true) => Self::I16,
            (16, false) => Self::U16,
            (16, true) => Self::I16,
            _ => Self::F32,
        }
    }

    pub(super) fn bytes(self) -> u64 {
        match self {
            Self::U8 => 1,
            Self::I16 | Self::U16 => 2,
            Self::F32 => 4,
        }
    }

    /// An empty voxel buffer of this type.
    pub(super) fn empty(self) -> Voxels {
        match self {
            Self::U8 => Voxels::U8(Vec::new()),
            Self::I16 => Voxels::I16(Vec::new()),
            Self::U16 => Voxels::U16(Vec::new()),
            Self::F32 => Voxels::F32(Vec::new()),
        }
    }
}

/// Whether every frame shares one rescale (then the volume keeps the raw type) and the type the
/// voxels are stored in; differing rescales need physical floats, which the user is told.
pub(super) fn pixel_target(
    first: &FileHeader,
    frames: &[Frame<'_>],
    warnings: &mut Vec<String>,
) -> (Target, bool) {
    let same_rescale = frames.iter().all(|f| {
        f.info.slope == frames[0].info.slope && f.info.intercept == frames[0].info.intercept
    });
    if same_rescale {
        (Target::raw(first.bits_allocated, first.signed), true)
    } else {
        warnings.push("RescaleSlope/RescaleIntercept differ between slices: values are stored as 32-bit floats".to_owned());
        (Target::F32, false)
    }
}

/// The volume's rescale: the frames' own when they share one, else identity (the voxels then
/// hold physical values).
pub(super) fn volume_rescale(frames: &[Frame<'_>], same_rescale: bool) -> (f32, f32) {
    if same_rescale {
        (frames[0].info.slope as f32, frames[0].info.intercept as f32)
    } else {
        (1.0, 0.0)
    }
}

/// Writes one frame's stored samples into `voxels[dst]`: as they are, or (into f32 voxels)
/// through `rescale` = (slope, intercept).
pub(super) fn store_frame(
    voxels: &mut Voxels,
    dst: std::ops::Range<usize>,
    samples: &[i64],
    rescale: (f64, f64),
) {
    match voxels {
        Voxels::U8(v) => v[dst]
            .iter_mut()
            .zip(samples)
            .for_each(|(o, s)| *o = *s as u8),
        Voxels::I16(v) => v[dst]
            .iter_mut()
            .zip(samples)
            .for_each(|(o, s)| *o = *s as i16),
        Voxels::U16(v) => v[dst]
            .iter_mut()
            .zip(samples)
            .for_each(|(o, s)| *o = *s as u16),
        Voxels::F32(v) => {
            let (a, b) = rescale;
            v[dst]
                .iter_mut()
                .zip(samples)
                .for_each(|(o, s)| *o = (*s as f64 * a + b) as f32)
        }
    }
}

/// A file's pixel data, ready for [`Pixels::frame_samples`]: decoded bytes of all frames,
/// native samples where they lie in the file (read a frame at a time), or encapsulated frames
/// decoded one at a time when stored.
pub(super) enum Pixels<'a> {
    Bytes(&'a [u8]),
    InFile {
        file: &'a InputFile,
        offset: u64,
        len: u64,
    },
    Encoded {
        fragments: &'a [&'a [u8]],
        /// The fragments of each frame ([`encapsulated::frame_fragments`]).
        frames: Vec<std::ops::Range<usize>>,
    },
    /// Encapsulated frames of a file read on demand, their fragments read from where they lie
    /// (offset, length) one frame at a time.
    EncodedInFile {
        file: &'a InputFile,
        fragments: &'a [(u64, u64)],
        frames: Vec<std::ops::Range<usize>>,
    },
}

/// Pixels converted at a time: a frame's samples go through an i64 scratch in pieces of at most
/// this many, so that the scratch stays small whatever the frame's size (a 20000 x 20000 frame
/// would otherwise need 3.2 GB of it).
const PIECE_PIXELS: usize = 1 << 18;

impl Pixels<'_> {
    /// Stores frame `frame` of `n_frames` into `voxels` from `dst_start` on ([`store_frame`]),
    /// a piece at a time; `samples` is the scratch.
    #[allow(clippy::too_many_arguments)] // one frame's place: kept explicit rather than bundled
    pub(super) fn store(
        &self,
        h: &FileHeader,
        frame: usize,
        n_frames: usize,
        frame_len: usize,
        voxels: &mut Voxels,
        dst_start: usize,
        rescale: (f64, f64),
        samples: &mut Vec<i64>,
    ) -> Result<(), String> {
        if let Self::EncodedInFile {
            file,
            fragments,
            frames,
        } = self
        {
            let parts = frames
                .get(frame)
                .and_then(|r| fragments.get(r.clone()))
                .ok_or_else(|| format!("no fragment holds frame {frame}"))?;
            let read: Vec<Vec<u8>> = parts
                .iter()
                .map(|&(at, len)| encapsulated::read_range(file, at, len))
                .collect::<Result<_, _>>()
                .map_err(|e| e.to_string())?;
            let refs: Vec<&[u8]> = read.iter().map(Vec::as_slice).collect();
            // The frame's fragments, read: frame 0 of them all.
            let whole = std::iter::once(0..refs.len()).collect::<Vec<_>>();
            let decoded = decode_frame(h, &refs, &whole, 0, frame_len)?;
            return Pixels::Bytes(&decoded)
                .store(h, 0, 1, frame_len, voxels, dst_start, rescale, samples);
        }
        if let Self::Encoded { fragments, frames } = self {
            // One frame decoded, stored, and dropped before the next.
            let decoded = decode_frame(h, fragments, frames, frame, frame_len)?;
            return Pixels::Bytes(&decoded)
                .store(h, 0, 1, frame_len, voxels, dst_start, rescale, samples);
        }
        let bytes = usize::from(h.bits_allocated / 8);
        if !matches!(h.bits_allocated, 8 | 16 | 32) {
            // 1-bit frames (packed or not) are taken whole; other sizes are refused whole.
            samples.clear();
            self.frame_samples(h, frame, n_frames, frame_len, 0, frame_len, samples)?;
            store_frame(voxels, dst_start..dst_start + frame_len, samples, rescale);
            return Ok(());
        }
        let frame_bytes = frame_len as u64 * bytes as u64;
        let len = match self {
            Self::Bytes(d) => d.len() as u64,
            Self::InFile { len, .. } => *len,
            Self::Encoded { .. } | Self::EncodedInFile { .. } => {
                return Err("internal: encoded frames are decoded first".into());
            }
        };
        if (frame as u64 + 1) * frame_bytes > len {
            return Err(format!(
                "pixel data has {len} bytes; frame {frame} of {}x{} pixels at {} bits needs {}",
                h.cols,
                h.rows,
                h.bits_allocated,
                (frame as u64 + 1) * frame_bytes
            ));
        }
        let mut at = 0;
        while at < frame_len {
            let n = PIECE_PIXELS.min(frame_len - at);
            samples.clear();
            self.frame_samples(h, frame, n_frames, frame_len, at, n, samples)?;
            store_frame(voxels, dst_start + at..dst_start + at + n, samples, rescale);
            at += n;
        }
        Ok(())
    }

    /// Lets go the bytes of native samples lying in the file before frame `frame` (frames
    /// are then read in increasing order, none below `frame` again); nothing for the others.
    pub(super) fn release_before_frame(&self, h: &FileHeader, frame: usize, frame_len: usize) {
        match self {
            Self::InFile { file, offset, .. } if matches!(h.bits_allocated, 8 | 16 | 32) => {
                let frame_bytes = frame_len as u64 * u64::from(h.bits_allocated / 8);
                let at = offset.saturating_add((frame as u64).saturating_mul(frame_bytes));
                file.data().release_before(at);
            }
            Self::EncodedInFile {
                file,
                fragments,
                frames,
            } => {
                // Up to the item header of the frame's first fragment.
                if let Some(&(at, _)) = frames.get(frame).and_then(|r| fragments.get(r.start)) {
                    file.data().release_before(at.saturating_sub(8));
                }
            }
            _ => {}
        }
    }

    /// [`frame_samples`] of pixels `first..first + count` of frame `frame` of `n_frames`
    /// (the whole frame for 1-bit data).
    #[allow(clippy::too_many_arguments)] // one piece's place: kept explicit rather than bundled
    fn frame_samples(
        &self,
        h: &FileHeader,
        frame: usize,
        n_frames: usize,
        frame_len: usize,
        first: usize,
        count: usize,
        out: &mut Vec<i64>,
    ) -> Result<(), String> {
        let bytes = u64::from(h.bits_allocated / 8);
        if !matches!(h.bits_allocated, 8 | 16 | 32) {
            return match self {
                Self::Bytes(data) => frame_samples(h, data, frame, n_frames, frame_len, out),
                Self::InFile { .. } | Self::Encoded { .. } | Self::EncodedInFile { .. } => {
                    Err(format!(
                        "BitsAllocated {} is not read from the file directly",
                        h.bits_allocated
                    ))
                }
            };
        }
        let start = (frame as u64 * frame_len as u64 + first as u64) * bytes;
        let piece = count as u64 * bytes;
        match self {
            Self::Bytes(data) => {
                let src = usize::try_from(start)
                    .ok()
                    .and_then(|s| data.get(s..s.checked_add(piece as usize)?))
                    .ok_or("pixel data too short")?;
                frame_samples(h, src, 0, 1, count, out)
            }
            Self::InFile { file, offset, len } => {
                if start + piece > *len {
                    return Err("pixel data too short".to_owned());
                }
                let mut buf = Vec::new();
                buf.try_reserve_exact(piece as usize)
                    .map_err(|_| format!("out of memory for {piece} bytes of a frame"))?;
                buf.resize(piece as usize, 0);
                file.data()
                    .read_at(&file.name, offset + start, &mut buf)
                    .map_err(|e| e.to_string())?;
                frame_samples(h, &buf, 0, 1, count, out)
            }
            Self::Encoded { .. } | Self::EncodedInFile { .. } => {
                Err("internal: encoded frames are decoded first".to_owned())
            }
        }
    }
}

/// Decodes frame `frame` of encapsulated pixel data (RLE with our decoder, JPEG and JPEG 2000
/// with dicom-rs's) into its little-endian samples.
fn decode_frame(
    h: &FileHeader,
    fragments: &[&[u8]],
    frames: &[std::ops::Range<usize>],
    frame: usize,
    frame_len: usize,
) -> Result<Vec<u8>, String> {
    let parts = frames
        .get(frame)
        .and_then(|r| fragments.get(r.clone()))
        .ok_or_else(|| format!("no fragment holds frame {frame}"))?;
    let frame_bytes = frame_len * usize::from(h.bits_allocated.div_ceil(8).max(1));
    if h.transfer_syntax.trim_end_matches(['\0', ' ']) == encapsulated::RLE_LOSSLESS {
        let mut out = Vec::new();
        out.try_reserve_exact(frame_bytes)
            .map_err(|_| format!("out of memory for a frame of {frame_bytes} bytes"))?;
        out.resize(frame_bytes, 0);
        let mut segment = Vec::new();
        encapsulated::decode_rle_frame(
            h,
            parts.first().copied().unwrap_or_default(),
            &mut out,
            &mut segment,
        )
        .map_err(|m| format!("RLE Lossless: {m}"))?;
        return Ok(out);
    }
    // A frame in several fragments is one codestream cut in pieces.
    let joined: Vec<u8>;
    let codestream: &[u8] = match parts {
        [one] => one,
        many => {
            joined = many.concat();
            &joined
        }
    };
    let mut out = Vec::new();
    encapsulated::decode_codestream_frame(h, codestream, &mut out)?;
    if out.len() < frame_bytes {
        return Err(format!(
            "frame {frame} decodes to {} bytes; {}x{} pixels at {} bits need {frame_bytes}",
            out.len(),
            h.cols,
            h.rows,
            h.bits_allocated
        ));
    }
    Ok(out)
}

/// Opens a file, decodes its pixel data once and hands them to `f`. Native little-endian
/// samples are read where they lie: in memory without a copy, from a file read on demand a
/// frame at a time (no parsed object holds them); others where the parsed object holds them.
///
/// With `release` (the last read of this file: [`crate::io::FileSource::release_before`]),
/// pixel data parsed into memory lets the file's bytes go once parsed; native samples read
/// where they lie are let go frame by frame by the caller ([`Pixels::release_before_frame`]).
/// A deflated data set read on demand has its native samples inflated as they are read
/// ([`super::inflated`]).
pub(super) fn with_pixel_data<R>(
    file: &InputFile,
    header: &FileHeader,
    limits: &Limits,
    release: bool,
    f: impl FnOnce(&Pixels<'_>) -> Result<R, LoadError>,
) -> Result<R, LoadError> {
    if let Some((offset, len)) = header.native_pixels
        && offset.saturating_add(len) <= file.len()
    {
        if !file.is_on_demand() {
            let at = usize::try_from(offset).unwrap_or(usize::MAX);
            let end = usize::try_from(offset + len).unwrap_or(usize::MAX);
            if let Some(data) = file.bytes.get(at..end) {
                return f(&Pixels::Bytes(data));
            }
        } else {
            return f(&Pixels::InFile { file, offset, len });
        }
    }
    if file.is_on_demand()
        && header.transfer_syntax.trim_end_matches(['\0', ' '])
            == super::validate::DEFLATED_EXPLICIT_LE
        && matches!(header.bits_allocated, 8 | 16 | 32)
        && let Some((inflated, offset, len)) = super::inflated::open(file, limits)?
    {
        // A deflated data set read on demand: its frames are inflated as they are read.
        return f(&Pixels::InFile {
            file: &inflated,
            offset,
            len,
        });
    }
    if file.is_on_demand()
        && let Some(at) = header.encapsulated_pixels
        && matches!(header.bits_allocated, 8 | 16)
    {
        // Compressed frames of a file read on demand: located, checked and then read from the
        // file a frame at a time, so the fragments are never all in memory (parsed, they were
        // the file's size again beside the voxels).
        let ts = header.transfer_syntax.trim_end_matches(['\0', ' ']);
        let located = encapsulated::locate_fragments(file, at)?;
        let lens: Vec<u64> = located.fragments.iter().map(|f| f.1).collect();
        if ts == encapsulated::RLE_LOSSLESS {
            let total = usize::try_from(lens.iter().sum::<u64>()).unwrap_or(usize::MAX);
            encapsulated::check_rle_size(&file.name, header, total)?;
        } else {
            for (i, &(offset, len)) in located.fragments.iter().enumerate() {
                let head = encapsulated::read_range(
                    file,
                    offset,
                    len.min(encapsulated::CODESTREAM_HEAD_BYTES),
                )?;
                encapsulated::check_codestream(&file.name, header, i, &head)?;
            }
        }
        let mut failed = None;
        let frames = encapsulated::frames_of_fragments(
            ts,
            header.frames.len(),
            &lens,
            &located.offset_table,
            |i| {
                let (offset, len) = located.fragments[i];
                match encapsulated::read_range(file, offset, len.min(8)) {
                    Ok(head) => encapsulated::starts_codestream(&head),
                    Err(e) => {
                        failed.get_or_insert(e);
                        false
                    }
                }
            },
        );
        if let Some(e) = failed {
            return Err(e);
        }
        if let Some(frames) = frames {
            return f(&Pixels::EncodedInFile {
                file,
                fragments: &located.fragments,
                frames,
            });
        }
        // Frames that cannot be told apart are decoded whole, from the parsed file, below.
    }
    let obj = open(file, false, limits)?;
    if release {
        // The object holds its own copy of everything: the file's bytes are not read again.
        file.data().release_before(file.len());
    }
    let fragments = encapsulated::fragments(&obj);
    if let Some(frags) = &fragments {
        let ts = header.transfer_syntax.trim_end_matches(['\0', ' ']);
        // Checked for every frame before the first is decoded (and before the caller makes
        // the voxel buffer).
        if ts == encapsulated::RLE_LOSSLESS {
            encapsulated::check_rle_size(&file.name, header, frags.iter().map(|f| f.len()).sum())?;
        } else {
            encapsulated::check_codestreams(&file.name, header, frags)?;
        }
        // Frames decoded one at a time: the fragments, one decoded frame and the voxels are
        // what is held, not every frame decoded beside the voxels. RLE, JPEG and JPEG 2000 of
        // 8 or 16 bits; the rest (deflated image frames, 1-bit data) are decoded whole below.
        if !NATIVE_SYNTAXES.contains(&ts)
            && matches!(header.bits_allocated, 8 | 16)
            && let Some(frames) = encapsulated::frame_fragments(
                ts,
                header.frames.len(),
                frags,
                encapsulated::offset_table(&obj),
            )
        {
            return f(&Pixels::Encoded {
                fragments: frags,
                frames,
            });
        }
    }
    let rle_data;
    let decoded;
    let native;
    let data: &[u8] = match &fragments {
        Some(frags)
            if header.transfer_syntax.trim_end_matches(['\0', ' '])
                == encapsulated::RLE_LOSSLESS =>
        {
            rle_data = encapsulated::decode_rle(&file.name, header, frags)?;
            &rle_data
        }
        // Native samples are read where the object holds them: dicom-pixeldata would copy
        // them twice (to bytes, then to a vector), a third and fourth copy of the pixels.
        None if header.bits_allocated != 1
            && let Some(bytes) = native_pixel_bytes(&obj) =>
        {
            native = bytes;
            &native
        }
        _ => {
            if let Some(frags) = &fragments {
                encapsulated::check_codestreams(&file.name, header, frags)?;
            }
            decoded = obj.decode_pixel_data().map_err(|e| LoadError::Dicom {
                file: file.name.clone(),
                message: format!(
                    "cannot decode pixel data ({}): {}",
                    header.transfer_syntax,
                    super::chain(&e)
                ),
            })?;
            decoded.data()
        }
    };
    f(&Pixels::Bytes(data))
}

/// Decodes each file's pixel data once and copies its frames into their slots, reading a
/// file's frames in the file's order; with `release`, letting each file's bytes go behind.
fn read_pixels(
    series: &str,
    files: &[(&InputFile, &FileHeader)],
    frames: &[Frame<'_>],
    limits: &Limits,
    release: bool,
    warnings: &mut Vec<String>,
) -> Result<(Voxels, f32, f32), LoadError> {
    let first = files[0].1;
    let frame_len = first.rows as usize * first.cols as usize;
    let count = (frame_len as u64).saturating_mul(frames.len() as u64);
    // One rescale for the whole volume keeps the raw type; differing ones need physical floats.
    let (target, same_rescale) = pixel_target(first, frames, warnings);
    raw::check_voxel_budget(files[0].0.name.as_str(), count, target.bytes(), limits)?;
    // Compressed frames (RLE, JPEG, JPEG 2000, a deflated data set) cannot be far smaller
    // than the voxels they decode to.
    let file_bytes = files
        .iter()
        .fold(0u64, |n, (f, _)| n.saturating_add(f.len()));
    raw::check_expansion(
        files[0].0.name.as_str(),
        "DICOM pixel data",
        file_bytes,
        count.saturating_mul(target.bytes()),
    )?;
    // And each file for its own frames (one bomb among native slices).
    let frame_bytes = (frame_len as u64).saturating_mul(target.bytes());
    for (f, h) in files {
        raw::check_expansion(
            &f.name,
            "DICOM pixel data",
            f.len(),
            frame_bytes.saturating_mul(h.frames.len() as u64),
        )?;
    }
    let count = count as usize;
    // Reserved, not filled: the buffer grows as frames are stored ([`fill_to`]), so that its
    // pages are touched as the file's bytes are let go, not all before the first frame.
    let allocate = || -> Result<Voxels, LoadError> {
        let mut v = target.empty();
        reserve_exact(&mut v, count, &files[0].0.name)?;
        Ok(v)
    };

    // Slots of each file's frames, so that every file is opened and decoded once.
    let mut slots_of_file: Vec<Vec<(usize, usize)>> = vec![Vec::new(); files.len()];
    for (slot, f) in frames.iter().enumerate() {
        slots_of_file[f.file].push((f.frame, slot));
    }
    // In the file's order (slots are filled in any order), so that what lies behind the frame
    // being read is never read again.
    for slots in &mut slots_of_file {
        slots.sort_unstable();
    }
    // The checks that need no decoding, for every file, before the voxel buffer exists.
    for (fi, slots) in slots_of_file.iter().enumerate() {
        if !slots.is_empty() {
            let (file, header) = files[fi];
            check_before_decoding(file, header)?;
        }
    }
    // Allocated once the first file has passed the checks that need its parsed pixel data
    // (RLE segments, JPEG and JPEG 2000 codestream sizes), so that a small file declaring a
    // huge image is refused before the buffer is made.
    let mut voxels: Option<Voxels> = None;
    let mut samples = Vec::new();
    // Frames are stored in the order they are read (files in the order of their first slot,
    // each file's frames in its own order), so that the buffer fills from its start as the
    // file's bytes are let go, whatever way the frames run; `arrived[a]` is the slot of the
    // a-th frame stored, and the frames are put in slot order once all are in.
    let mut arrived: Vec<usize> = Vec::new();
    arrived
        .try_reserve_exact(frames.len())
        .map_err(|_| LoadError::OutOfMemory {
            file: files[0].0.name.clone(),
            what: "the table of frames".to_owned(),
            bytes: frames.len() as u64 * 8,
        })?;
    let mut file_order: Vec<usize> = (0..files.len())
        .filter(|&fi| !slots_of_file[fi].is_empty())
        .collect();
    file_order.sort_by_key(|&fi| slots_of_file[fi].iter().map(|s| s.1).min());
    for fi in file_order {
        let slots = &slots_of_file[fi];
        let (file, header) = files[fi];
        with_pixel_data(file, header, limits, release, |data| {
            let n_frames = header.frames.len();
            if voxels.is_none() {
                voxels = Some(allocate()?);
            }
            let Some(voxels) = voxels.as_mut() else {
                return Ok(());
            };
            for &(frame, slot) in slots {
                let slice_error = |message: String| LoadError::DicomSlice {
                    series: series.to_owned(),
                    slice: slot,
                    file: file.name.clone(),
                    message,
                };
                if release {
                    data.release_before_frame(header, frame, frame_len);
                }
                let at = arrived.len();
                fill_to(voxels, (at + 1) * frame_len);
                let info = frames[slot].info;
                let rescale = if same_rescale {
                    (1.0, 0.0)
                } else {
                    (info.slope, info.intercept)
                };
                data.store(
                    header,
                    frame,
                    n_frames,
                    frame_len,
                    voxels,
                    at * frame_len,
                    rescale,
                    &mut samples,
                )
                .map_err(slice_error)?;
                arrived.push(slot);
            }
            Ok(())
        })?;
        if release {
            file.data().release_before(file.len());
        }
    }
    let (slope, intercept) = volume_rescale(frames, same_rescale);
    let mut voxels = match voxels {
        Some(v) => v,
        None => allocate()?,
    };
    fill_to(&mut voxels, count);
    if arrived.len() == frames.len() && arrived.iter().enumerate().any(|(a, &s)| a != s) {
        // Slot s takes the frame stored at position order[s] (one frame of scratch).
        let mut order = vec![0usize; frames.len()];
        for (a, &slot) in arrived.iter().enumerate() {
            order[slot] = a;
        }
        super::stream::permute(&mut voxels, &order, frame_len);
    }
    Ok((voxels, slope, intercept))
}

/// Reserves room for `count` voxels in all, exactly (growing within it never reallocates).
pub(super) fn reserve_exact(
    voxels: &mut Voxels,
    count: usize,
    name: &str,
) -> Result<(), LoadError> {
    fn go<T>(v: &mut Vec<T>, count: usize, name: &str) -> Result<(), LoadError> {
        let more = count.saturating_sub(v.len());
        v.try_reserve_exact(more)
            .map_err(|_| LoadError::OutOfMemory {
                file: name.to_owned(),
                what: "voxels".to_owned(),
                bytes: (count as u64).saturating_mul(std::mem::size_of::<T>() as u64),
            })
    }
    match voxels {
        Voxels::U8(v) => go(v, count, name),
        Voxels::I16(v) => go(v, count, name),
        Voxels::U16(v) => go(v, count, name),
        Voxels::F32(v) => go(v, count, name),
    }
}

/// Lengthens the buffer with zeros to `len` voxels, within what was reserved (never shortens).
fn fill_to(voxels: &mut Voxels, len: usize) {
    fn go<T: Clone + Default>(v: &mut Vec<T>, len: usize) {
        if len > v.len() {
            v.resize(len, T::default());
        }
    }
    match voxels {
        Voxels::U8(v) => go(v, len),
        Voxels::I16(v) => go(v, len),
        Voxels::U16(v) => go(v, len),
        Voxels::F32(v) => go(v, len),
    }
}

/// The native PixelData's bytes as the object holds them (little endian), without a copy
/// where the value is bytes (OB) or, on a little-endian machine, 16-bit words (OW).
fn native_pixel_bytes(
    obj: &dicom_object::DefaultDicomObject,
) -> Option<std::borrow::Cow<'_, [u8]>> {
    use dicom_core::value::PrimitiveValue;
    let dicom_core::DicomValue::Primitive(p) =
        obj.get(dicom_dictionary_std::tags::PIXEL_DATA)?.value()
    else {
        return None;
    };
    Some(match p {
        PrimitiveValue::U8(v) => std::borrow::Cow::Borrowed(v.as_slice()),
        PrimitiveValue::U16(v) if cfg!(target_endian = "little") => {
            std::borrow::Cow::Borrowed(bytemuck::cast_slice(v.as_slice()))
        }
        other => other.to_bytes(),
    })
}

/// What can be refused from a file's header and size alone: a transfer syntax without a
/// decoder, 1-bit data in a compressed syntax, RLE data too small to hold the frames.
pub(super) fn check_before_decoding(
    file: &InputFile,
    header: &FileHeader,
) -> Result<(), LoadError> {
    check_transfer_syntax(&file.name, &header.transfer_syntax)?;
    let ts = header.transfer_syntax.trim_end_matches(['\0', ' ']);
    if header.bits_allocated == 1 && !NATIVE_SYNTAXES.contains(&ts) {
        // dicom-rs's RLE and JPEG 2000 decoders handle 8 and 16 bits only.
        return Err(LoadError::UnsupportedTransferSyntax {
            file: file.name.clone(),
            uid: header.transfer_syntax.clone(),
            name: super::transfer_syntax_name(&header.transfer_syntax),
            reason:
                "1-bit (binary segmentation) pixel data can be read only uncompressed or deflated"
                    .to_owned(),
        });
    }
    if ts == encapsulated::RLE_LOSSLESS {
        // The whole file bounds the compressed size.
        encapsulated::check_rle_size(
            &file.name,
            header,
            usize::try_from(file.len()).unwrap_or(usize::MAX),
        )?;
    }
    Ok(())
}

/// The stored values of one frame as i64 (sign-extended or masked to BitsStored), checking that
/// the decoded data hold the whole frame.
pub(super) fn frame_samples(
    h: &FileHeader,
    data: &[u8],
    frame: usize,
    n_frames: usize,
    frame_len: usize,
    out: &mut Vec<i64>,
) -> Result<(), String> {
    let total_pixels = frame_len.saturating_mul(n_frames);
    match h.bits_allocated {
        1 => {
            // Native 1-bit data are expanded to one byte per pixel by dicom-pixeldata; some
            // codecs keep them packed. Either way a pixel is 0 or 1.
            if data.len() >= total_pixels {
                let src = data
                    .get(frame * frame_len..(frame + 1) * frame_len)
                    .ok_or("pixel data too short")?;
                out.extend(src.iter().map(|&b| i64::from(b != 0)));
            } else {
                let start_bit = frame * frame_len;
                let needed = (start_bit + frame_len).div_ceil(8);
                if data.len() < needed {
                    return Err(format!(
                        "pixel data has {} bytes; {} frames of 1-bit pixels need {}",
                        data.len(),
                        n_frames,
                        total_pixels.div_ceil(8)
                    ));
                }
                out.extend(
                    (start_bit..start_bit + frame_len)
                        .map(|bit| i64::from((data[bit / 8] >> (bit % 8)) & 1)),
                );
            }
            Ok(())
        }
        8 | 16 | 32 => {
            let bytes = usize::from(h.bits_allocated / 8);
            let frame_bytes = frame_len * bytes;
            let src = data
                .get(frame * frame_bytes..(frame + 1) * frame_bytes)
                .ok_or_else(|| {
                    format!(
                        "pixel data has {} bytes; frame {} of {}x{} pixels at {} bits needs {}",
                        data.len(),
                        frame,
                        h.cols,
                        h.rows,
                        h.bits_allocated,
                        (frame + 1) * frame_bytes
                    )
                })?;
            let stored = u32::from(h.bits_stored.clamp(1, h.bits_allocated));
            let shift = 64 - stored;
            out.extend(src.chunks_exact(bytes).map(|c| {
                let raw = match bytes {
                    1 => u64::from(c[0]),
                    2 => u64::from(u16::from_le_bytes([c[0], c[1]])),
                    _ => u64::from(u32::from_le_bytes([c[0], c[1], c[2], c[3]])),
                };
                if h.signed {
                    ((raw << shift) as i64) >> shift
                } else {
                    ((raw << shift) >> shift) as i64
                }
            }));
            Ok(())
        }
        other => Err(format!("BitsAllocated {other} is not supported")),
    }
}
