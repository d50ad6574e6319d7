//! The per-file header scan: every frame's geometry and values (classic or enhanced
//! multi-frame), the pixel description, and the study's and patient's attributes.

use super::*;

// Lookups use `get`, never `element_opt`: a missing tag through `element_opt` builds an error
// with a captured backtrace (~95 us), which made a header of a million frames take minutes.

pub(super) fn elem_str(obj: &InMemDicomObject, tag: dicom_core::Tag) -> Option<String> {
    let e = obj.get(tag)?;
    let s = e.to_str().ok()?;
    let s = s.trim_matches(['\0', ' ']).to_owned();
    (!s.is_empty()).then_some(s)
}

pub(super) fn elem_floats(obj: &InMemDicomObject, tag: dicom_core::Tag) -> Option<Vec<f64>> {
    let v = obj.get(tag)?.to_multi_float64().ok()?;
    v.iter().all(|x| x.is_finite()).then_some(v)
}

pub(super) fn elem_int(obj: &InMemDicomObject, tag: dicom_core::Tag) -> Option<i64> {
    let e = obj.get(tag)?;
    e.to_int::<i64>().ok().or_else(|| {
        e.to_float64()
            .ok()
            .filter(|f| f.is_finite() && f.fract() == 0.0)
            .map(|f| f as i64)
    })
}

/// The first item of a sequence.
pub(super) fn first_item(
    obj: &InMemDicomObject,
    tag: dicom_core::Tag,
) -> Option<&InMemDicomObject> {
    obj.get(tag)?.items()?.first()
}
pub(super) fn frame_info(levels: &[Option<&InMemDicomObject>]) -> FrameInfo {
    // The first level that has a value wins: per-frame group, shared group, top level.
    let find = |seq: Option<dicom_core::Tag>, tag: dicom_core::Tag| -> Option<Vec<f64>> {
        levels.iter().flatten().find_map(|obj| match seq {
            Some(s) => first_item(obj, s).and_then(|i| elem_floats(i, tag)),
            None => elem_floats(obj, tag),
        })
    };
    // A tag of a functional group (inside its sequence), else the same tag outside any.
    let grouped = |seq, tag| find(Some(seq), tag).or_else(|| find(None, tag));
    let first = |seq, tag| grouped(seq, tag).and_then(|v| v.first().copied());
    let position = grouped(tags::PLANE_POSITION_SEQUENCE, tags::IMAGE_POSITION_PATIENT)
        .filter(|v| v.len() == 3)
        .map(|v| DVec3::new(v[0], v[1], v[2]));
    let orientation = grouped(
        tags::PLANE_ORIENTATION_SEQUENCE,
        tags::IMAGE_ORIENTATION_PATIENT,
    )
    .filter(|v| v.len() == 6)
    .map(|v| std::array::from_fn(|i| v[i]));
    let pixel_spacing = grouped(tags::PIXEL_MEASURES_SEQUENCE, tags::PIXEL_SPACING)
        .or_else(|| find(None, tags::IMAGER_PIXEL_SPACING))
        .filter(|v| v.len() == 2 && v[0] > 0.0 && v[1] > 0.0)
        .map(|v| [v[0], v[1]]);
    let measure = |tag| first(tags::PIXEL_MEASURES_SEQUENCE, tag).filter(|t| *t > 0.0);
    let thickness = measure(tags::SLICE_THICKNESS);
    let spacing_between = measure(tags::SPACING_BETWEEN_SLICES);
    let rescale = |tag| first(tags::PIXEL_VALUE_TRANSFORMATION_SEQUENCE, tag);
    let slope = rescale(tags::RESCALE_SLOPE)
        .filter(|s| *s != 0.0)
        .unwrap_or(1.0);
    let intercept = rescale(tags::RESCALE_INTERCEPT).unwrap_or(0.0);
    FrameInfo {
        position,
        orientation,
        pixel_spacing,
        thickness,
        spacing_between,
        slope,
        intercept,
    }
}

/// Frames of a classic multi-frame file (no functional groups) that all carry its one
/// ImagePositionPatient (the first frame's) are stacked from
/// it along the slice normal, SpacingBetweenSlices (else SliceThickness) apart, as the NM image
/// module defines and dcm2niix reads them. Taken as they were, every frame would sit at one
/// position and all but the first be dropped as duplicates. Without a spacing, only the first
/// frame keeps the position (the frames are then ordered by number).
pub(super) fn stack_shared_position(
    name: &str,
    frames: &mut [FrameInfo],
    warnings: &mut Vec<String>,
) {
    let Some(p0) = frames.first().and_then(|f| f.position) else {
        return;
    };
    if frames.len() < 2
        || frames
            .iter()
            .any(|f| f.position.is_none_or(|p| (p - p0).length() > 1e-6))
    {
        return;
    }
    let normal = frames[0].orientation.map(|o| {
        DVec3::new(o[0], o[1], o[2])
            .cross(DVec3::new(o[3], o[4], o[5]))
            .normalize_or_zero()
    });
    let step = frames[0]
        .spacing_between
        .map(|s| (s, "SpacingBetweenSlices"))
        .or(frames[0].thickness.map(|t| (t, "SliceThickness")));
    let normal = normal.filter(|n| n.length() > 0.5);
    if let (Some(normal), Some((step, field))) = (normal, step) {
        for (k, f) in frames.iter_mut().enumerate() {
            f.position = Some(p0 + normal * (step * k as f64));
        }
        warnings.push(format!(
            "{name}: its {} frames share one ImagePositionPatient (no per-frame positions); they are stacked from it along the slice normal (row x column direction), {step} mm apart ({field})",
            frames.len()
        ));
        return;
    }
    for f in frames.iter_mut().skip(1) {
        f.position = None;
    }
    let missing = if normal.is_none() {
        "no ImageOrientationPatient gives the slice normal"
    } else {
        "neither SpacingBetweenSlices nor SliceThickness says how far apart they are"
    };
    warnings.push(format!(
        "{name}: its {} frames share one ImagePositionPatient and {missing}; they are ordered by frame number",
        frames.len()
    ));
}

/// Transfer syntaxes whose pixel data are stored as they are (possibly deflated as a whole).
pub(super) const NATIVE_SYNTAXES: &[&str] = &[
    "1.2.840.10008.1.2",
    "1.2.840.10008.1.2.1",
    "1.2.840.10008.1.2.2",
    "1.2.840.10008.1.2.1.99",
    "1.2.840.10008.1.2.8.1",
];

/// Largest frame count accepted from a header before the pixel data are seen.
pub(super) const MAX_FRAMES: i64 = 1 << 20;

/// Reads what a file's header says; `Ok(None)` for a DICOM file without an image (a DICOMDIR,
/// a structured report).
pub(super) fn read_header(
    file: &InputFile,
    limits: &Limits,
) -> Result<Option<FileHeader>, LoadError> {
    let (obj, pixel_data) = open_located(file, true, limits)?;
    let (Some(rows), Some(cols)) = (elem_int(&obj, tags::ROWS), elem_int(&obj, tags::COLUMNS))
    else {
        return Ok(None);
    };
    let name = file.name.as_str();
    if !(1..=65535).contains(&rows) || !(1..=65535).contains(&cols) {
        return Err(LoadError::header(
            name,
            "Rows/Columns",
            format!("{rows} x {cols}"),
        ));
    }
    let mut warnings = Vec::new();
    let n_frames = elem_int(&obj, tags::NUMBER_OF_FRAMES).unwrap_or(1);
    if !(1..=MAX_FRAMES).contains(&n_frames) {
        return Err(LoadError::header(
            name,
            "NumberOfFrames",
            format!("is {n_frames}"),
        ));
    }
    // Every frame needs at least a byte of the file, and uncompressed frames need all their
    // bytes: checked here, before a per-frame table or any pixel buffer is made.
    let file_len = file.len();
    if n_frames as u64 > file_len {
        return Err(LoadError::truncated(
            name,
            format!("{n_frames} frames"),
            n_frames as u64,
            file_len,
        ));
    }
    let ts = obj
        .meta()
        .transfer_syntax()
        .trim_end_matches(['\0', ' '])
        .to_owned();
    let bits = elem_int(&obj, tags::BITS_ALLOCATED)
        .unwrap_or(16)
        .clamp(1, 64) as u64;
    let spp = elem_int(&obj, tags::SAMPLES_PER_PIXEL)
        .unwrap_or(1)
        .clamp(1, 4) as u64;
    let pixel_bytes = (rows as u64 * cols as u64 * spp * n_frames as u64 * bits).div_ceil(8);
    if matches!(
        ts.as_str(),
        "1.2.840.10008.1.2" | "1.2.840.10008.1.2.1" | "1.2.840.10008.1.2.2"
    ) && pixel_bytes > file_len
    {
        return Err(LoadError::truncated(
            name,
            format!("{n_frames} frame(s) of {cols}x{rows} pixels at {bits} bits"),
            pixel_bytes,
            file_len,
        ));
    }
    // Encapsulated frames take at least one fragment each, and every fragment an 8-byte item
    // header: a bound on the frame count before a per-frame table is made.
    if !NATIVE_SYNTAXES.contains(&ts.as_str()) && (n_frames as u64).saturating_mul(8) > file_len {
        return Err(LoadError::truncated(
            name,
            format!("{n_frames} compressed frames (an 8-byte item header each at least)"),
            (n_frames as u64).saturating_mul(8),
            file_len,
        ));
    }
    let out_bytes = rows as u64 * cols as u64 * n_frames as u64 * if bits > 16 { 4 } else { 2 };
    if out_bytes > limits.max_voxel_bytes {
        return Err(LoadError::TooLarge {
            file: name.to_owned(),
            what: format!("{n_frames} frame(s) of {cols}x{rows} pixels"),
            bytes: out_bytes,
            limit: limits.max_voxel_bytes,
        });
    }
    let shared = first_item(&obj, tags::SHARED_FUNCTIONAL_GROUPS_SEQUENCE);
    let per_frame = obj
        .get(tags::PER_FRAME_FUNCTIONAL_GROUPS_SEQUENCE)
        .and_then(|e| e.items());
    if let Some(items) = per_frame
        && items.len() as i64 != n_frames
    {
        warnings.push(format!(
            "{name}: {} per-frame functional groups for {n_frames} frames",
            items.len()
        ));
    }
    let top: &InMemDicomObject = &obj;
    // What the shared group and the top level say is read once; a frame without its own
    // functional group (every frame of a classic or single-frame file) is a copy of it.
    let common = frame_info(&[shared, Some(top)]);
    let mut frames: Vec<FrameInfo> = Vec::new();
    frames
        .try_reserve_exact(n_frames as usize)
        .map_err(|_| LoadError::OutOfMemory {
            file: name.to_owned(),
            what: format!("the table of {n_frames} frames"),
            bytes: n_frames as u64 * std::mem::size_of::<FrameInfo>() as u64,
        })?;
    for f in 0..n_frames as usize {
        frames.push(match per_frame.and_then(|items| items.get(f)) {
            Some(own) => frame_info(&[Some(own), shared, Some(top)]),
            None => common.clone(),
        });
    }
    // Only a classic multi-frame file (no functional groups: its one position is the top
    // level's) is stacked. An enhanced image's frames that share a position, per frame or in
    // the shared group, are phases, echoes or b-values at one place and stay as given.
    if per_frame.is_none() && shared.is_none() {
        stack_shared_position(name, &mut frames, &mut warnings);
    }
    let modality_name = elem_str(&obj, tags::MODALITY).unwrap_or_default();
    let modality = match modality_name.as_str() {
        "CT" => Modality::Ct,
        "MR" => Modality::Mr,
        "PT" => Modality::Pt,
        _ => Modality::Unknown,
    };
    let pet = (modality == Modality::Pt).then(|| suv::PetTags::from_object(&obj));
    let bits_allocated = elem_int(&obj, tags::BITS_ALLOCATED).unwrap_or(16);
    let bits_stored = elem_int(&obj, tags::BITS_STORED).unwrap_or(bits_allocated);
    if !(1..=bits_allocated).contains(&bits_stored) {
        // The samples are masked to 1..=BitsAllocated bits when decoded; say so.
        warnings.push(format!(
            "{name}: BitsStored is {bits_stored} with BitsAllocated {bits_allocated}; {} bits are used",
            bits_stored.clamp(1, bits_allocated.max(1))
        ));
    }
    let ts_trimmed = obj.meta().transfer_syntax().trim_end_matches(['\0', ' ']);
    let native_pixels = pixel_data.filter(|&(_, len)| {
        len != validate::UNDEFINED_LENGTH
            && matches!(ts_trimmed, "1.2.840.10008.1.2" | "1.2.840.10008.1.2.1")
            && matches!(bits_allocated, 8 | 16 | 32)
    });
    let encapsulated_pixels = pixel_data
        .filter(|&(_, len)| len == validate::UNDEFINED_LENGTH)
        .filter(|_| !NATIVE_SYNTAXES.contains(&ts_trimmed))
        .map(|(at, _)| at);
    Ok(Some(FileHeader {
        pet,
        frame_of_reference: elem_str(&obj, tags::FRAME_OF_REFERENCE_UID).filter(|s| !s.is_empty()),
        native_pixels,
        encapsulated_pixels,
        series_uid: elem_str(&obj, tags::SERIES_INSTANCE_UID)
            .unwrap_or_else(|| "(no SeriesInstanceUID)".to_owned()),
        series_description: elem_str(&obj, tags::SERIES_DESCRIPTION).unwrap_or_default(),
        series_number: elem_int(&obj, tags::SERIES_NUMBER),
        sop_instance_uid: elem_str(&obj, tags::SOP_INSTANCE_UID).unwrap_or_default(),
        instance_number: elem_int(&obj, tags::INSTANCE_NUMBER),
        modality,
        modality_name,
        transfer_syntax: obj.meta().transfer_syntax().to_owned(),
        rows: rows as u32,
        cols: cols as u32,
        bits_allocated: u16::try_from(bits_allocated).unwrap_or(0),
        bits_stored: u16::try_from(bits_stored).unwrap_or(0),
        signed: elem_int(&obj, tags::PIXEL_REPRESENTATION) == Some(1),
        samples_per_pixel: u16::try_from(elem_int(&obj, tags::SAMPLES_PER_PIXEL).unwrap_or(1))
            .unwrap_or(0),
        photometric: elem_str(&obj, tags::PHOTOMETRIC_INTERPRETATION)
            .unwrap_or_else(|| "MONOCHROME2".to_owned()),
        frames,
        warnings,
        patient: crate::io::Patient {
            name: elem_str(&obj, tags::PATIENT_NAME),
            id: elem_str(&obj, tags::PATIENT_ID),
            birth_date: elem_str(&obj, tags::PATIENT_BIRTH_DATE),
            study_date: elem_str(&obj, tags::STUDY_DATE),
            series_description: elem_str(&obj, tags::SERIES_DESCRIPTION),
        },
    }))
}
