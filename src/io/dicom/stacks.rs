//! Grouping DICOM images into stacks: one series' images of one size and one orientation, and
//! which stack loads when none is chosen.

use std::collections::BTreeMap;

use super::FileHeader;
use crate::io::{LoadError, SeriesProblem};

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
        problem: SeriesProblem::NoSeries,
    })?;
    other_stack_notes(&stacks, chosen, headers, notes);
    let stack = stacks.swap_remove(chosen);
    Ok((stack.series_uid, stack.members))
}
