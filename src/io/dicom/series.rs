//! Assembling DICOM files into one volume: grouping by SeriesInstanceUID and orientation into
//! stacks (`listing` lists them; the CT or MR stack with the most images is loaded unless
//! another is chosen), ordering frames by ImagePositionPatient projected on the
//! slice normal, slice spacing from the positions (with warnings for a disagreeing
//! SliceThickness, uneven or missing slices), rescale, and pixel decoding frame by frame.

use glam::DVec3;

use super::decode::{check_before_decoding, with_pixel_data};
use super::pixels::{pixel_target, volume_rescale};
use super::{FileHeader, FrameInfo};
use crate::io::geometry::checked_grid;
use crate::io::raw;
use crate::io::{DicomProblem, InputFile, Limits, LoadError, SeriesProblem};
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
            problem: DicomProblem::NoImage,
        },
        many => LoadError::DicomSeries {
            series: "-".to_owned(),
            problem: SeriesProblem::NoImage {
                files: many.len(),
                names: format!(
                    "{}{}",
                    many.iter().take(3).copied().collect::<Vec<_>>().join(", "),
                    if many.len() > 3 { ", ..." } else { "" }
                ),
            },
        },
    }
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
                problem: SeriesProblem::MixedPixels {
                    file: f.to_string(),
                    first: name0.to_string(),
                },
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
        // Loaders fill dense buffers (`PixelType::empty`); only the viewer packs a volume,
        // after loading. Said rather than written into nothing.
        Voxels::Packed(_) => Err(LoadError::unsupported(
            name,
            "voxel buffer",
            "internal: a packed buffer cannot be filled",
        )),
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
        // Loaders fill dense buffers; only the viewer packs a volume, after loading.
        Voxels::Packed(_) => {}
    }
}
