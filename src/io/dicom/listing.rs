//! The series in a set of DICOM files, from their headers alone (no pixel is decoded): what a
//! list shows of each (modality, description, images, slice thickness, orientation), the
//! default choice, and loading exactly the one chosen from the same files. The grouping is the
//! loader's own (`stacks::group_stacks`): one entry per stack the loader can load.

use glam::DVec3;

use super::series;
use super::stacks::{self, Stack};
use super::{FileHeader, read_header};
use crate::io::{InputFile, Limits, LoadError, Loaded, SeriesProblem};

/// The plane of a stack's images, from its ImageOrientationPatient.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SliceOrientation {
    Axial,
    Coronal,
    Sagittal,
    /// More than [`SliceOrientation::OBLIQUE_DEGREES`] from each of the three planes.
    Oblique,
    /// No ImageOrientationPatient, or one that gives no plane.
    Unknown,
}

impl SliceOrientation {
    /// Largest angle between the slice normal and a patient axis still named by that axis'
    /// plane.
    pub const OBLIQUE_DEGREES: f64 = 10.0;

    /// The plane of images whose rows and columns run along `orientation`'s two directions.
    pub fn from_orientation(orientation: Option<[f64; 6]>) -> Self {
        let Some(o) = orientation else {
            return Self::Unknown;
        };
        let normal = DVec3::new(o[0], o[1], o[2]).cross(DVec3::new(o[3], o[4], o[5]));
        if !normal.is_finite() || normal.length() < 0.5 {
            return Self::Unknown;
        }
        let n = normal.normalize().abs();
        let (axis, largest) = [
            (Self::Sagittal, n.x),
            (Self::Coronal, n.y),
            (Self::Axial, n.z),
        ]
        .into_iter()
        .fold(
            (Self::Unknown, -1.0),
            |best, c| if c.1 > best.1 { c } else { best },
        );
        if largest >= Self::OBLIQUE_DEGREES.to_radians().cos() {
            axis
        } else {
            Self::Oblique
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Self::Axial => "axial",
            Self::Coronal => "coronal",
            Self::Sagittal => "sagittal",
            Self::Oblique => "oblique",
            Self::Unknown => "unknown",
        }
    }
}

/// One stack of a [`SeriesList`]: a series, or one orientation of a series whose images lie in
/// several planes. No patient data.
#[derive(Clone, Debug, PartialEq)]
pub struct SeriesEntry {
    pub series_uid: String,
    /// SeriesNumber.
    pub number: Option<i64>,
    /// Modality as written ("CT", "MR", "SEG", ...; empty when missing).
    pub modality: String,
    /// SeriesDescription (empty when missing).
    pub description: String,
    /// Images (frames) in the stack.
    pub images: usize,
    /// Files holding them.
    pub files: usize,
    pub rows: u32,
    pub cols: u32,
    /// SliceThickness of the first image that has one.
    pub slice_thickness_mm: Option<f64>,
    /// SpacingBetweenSlices of the first image that has one.
    pub spacing_between_slices_mm: Option<f64>,
    pub orientation: SliceOrientation,
    /// Which stack of its series this is and how many there are (series UID and image size
    /// alike): `(0, 1)` for a series that is one stack.
    pub part: (usize, usize),
}

impl SeriesEntry {
    /// The slice thickness to show: SliceThickness, else SpacingBetweenSlices.
    pub fn thickness_mm(&self) -> Option<f64> {
        self.slice_thickness_mm.or(self.spacing_between_slices_mm)
    }
}

/// The stacks of a set of DICOM files ([`crate::io::list_series`]), with what [`Self::load`]
/// needs to load any of them from the same files without reading the other files' headers
/// again.
#[derive(Clone, Debug)]
pub struct SeriesList {
    entries: Vec<SeriesEntry>,
    /// Files ignored or skipped while listing, for the user.
    notes: Vec<String>,
    /// The headers of the files that hold an image: (index into the files given, header).
    headers: Vec<(usize, FileHeader)>,
    stacks: Vec<Stack>,
    /// The names of the files given, so that `load` can check it gets the same.
    names: Vec<String>,
}

/// Reads the headers of `files[i]` for every `i` of `dicom` and groups them into stacks.
/// `notes` (files ignored by the caller) are kept with the list.
pub(crate) fn list_series(
    files: &[InputFile],
    dicom: &[usize],
    mut notes: Vec<String>,
    limits: &Limits,
) -> Result<SeriesList, LoadError> {
    let mut headers: Vec<(usize, FileHeader)> = Vec::new();
    let mut first_error = None;
    for &i in dicom {
        let Some(f) = files.get(i) else { continue };
        match read_header(f, limits) {
            Ok(Some(h)) => headers.push((i, h)),
            Ok(None) => notes.push(format!("{}: DICOM without an image (skipped)", f.name)),
            Err(e) => {
                notes.push(format!("skipped: {}", crate::error::chain(&e)));
                first_error.get_or_insert(e);
            }
        }
    }
    if headers.is_empty() {
        return Err(first_error.unwrap_or_else(|| {
            let names: Vec<&str> = dicom
                .iter()
                .filter_map(|&i| files.get(i))
                .map(|f| f.name.as_str())
                .collect();
            series::no_image_error(&names)
        }));
    }
    let names = files.iter().map(|f| f.name.clone()).collect();
    Ok(SeriesList::from_headers(names, headers, notes))
}

impl SeriesList {
    /// The list of files named `names` whose headers (by index into `names`) are `headers`;
    /// `notes` (files ignored or skipped) are kept with it.
    pub(super) fn from_headers(
        names: Vec<String>,
        headers: Vec<(usize, FileHeader)>,
        notes: Vec<String>,
    ) -> Self {
        let named: Vec<(&str, &FileHeader)> = headers
            .iter()
            .map(|(i, h)| (names.get(*i).map_or("", String::as_str), h))
            .collect();
        let stacks = stacks::group_stacks(&named);
        let entries = stacks
            .iter()
            .map(|s| {
                let member = |m: usize| &headers[m].1;
                // A stack is never empty (`group_stacks` makes one per image met).
                let first = s.members.first().map(|&m| member(m));
                let frame_value = |get: fn(&super::FrameInfo) -> Option<f64>| {
                    s.members
                        .iter()
                        .flat_map(|&m| member(m).frames.iter())
                        .find_map(get)
                };
                let same_series = stacks
                    .iter()
                    .filter(|o| (&o.series_uid, o.rows, o.cols) == (&s.series_uid, s.rows, s.cols))
                    .count();
                SeriesEntry {
                    series_uid: s.series_uid.clone(),
                    number: first.and_then(|h| h.series_number),
                    modality: first.map_or_else(String::new, |h| h.modality_name.clone()),
                    description: first.map_or_else(String::new, |h| h.series_description.clone()),
                    images: s.frames,
                    files: s.members.len(),
                    rows: s.rows,
                    cols: s.cols,
                    slice_thickness_mm: frame_value(|f| f.thickness),
                    spacing_between_slices_mm: frame_value(|f| f.spacing_between),
                    orientation: SliceOrientation::from_orientation(s.orientation),
                    part: (s.stack, same_series),
                }
            })
            .collect();
        Self {
            entries,
            notes,
            headers,
            stacks,
            names,
        }
    }

    /// The name of file `index` of the files listed ("" beyond them).
    pub fn file_name(&self, index: usize) -> &str {
        self.names.get(index).map_or("", String::as_str)
    }

    /// The indices (into the files listed) of the files that hold entry `index`'s images.
    pub fn members(&self, index: usize) -> Vec<usize> {
        self.stacks.get(index).map_or_else(Vec::new, |s| {
            s.members
                .iter()
                .filter_map(|&m| self.headers.get(m).map(|(i, _)| *i))
                .collect()
        })
    }

    /// The stacks, sorted by series UID, image size and orientation (so that the list does not
    /// depend on the order the files came in).
    pub fn entries(&self) -> &[SeriesEntry] {
        &self.entries
    }

    /// Files that were ignored or skipped (not DICOM, no image, unreadable).
    pub fn notes(&self) -> &[String] {
        &self.notes
    }

    /// The entry to load when none is chosen: the CT or MR stack with the most images, the
    /// first of equals (the archive's rule, `dicomweb::choose_series`).
    pub fn default_choice(&self) -> usize {
        let named = self.named_headers();
        stacks::default_stack(&self.stacks, &named).unwrap_or(0)
    }

    /// Notes naming every entry but `chosen` as not loaded (what [`crate::io::load`] tells a
    /// user who sees no list).
    pub fn others_not_loaded(&self, chosen: usize) -> Vec<String> {
        let mut notes = Vec::new();
        stacks::other_stack_notes(&self.stacks, chosen, &self.named_headers(), &mut notes);
        notes
    }

    fn named_headers(&self) -> Vec<(&str, &FileHeader)> {
        self.headers
            .iter()
            .map(|(i, h)| (self.names.get(*i).map_or("", String::as_str), h))
            .collect()
    }

    /// Loads entry `index` from `files`, which must be the files listed (same names, same
    /// order): only that stack's files are read again, for their pixels. The notes are the
    /// list's. The files stay readable, for another entry later ([`Self::load_last`] lets
    /// them go).
    pub fn load(
        &self,
        files: &[InputFile],
        index: usize,
        limits: &Limits,
    ) -> Result<Loaded, LoadError> {
        self.load_entry(files, index, limits, false)
    }

    /// [`Self::load`] as the last read of `files`: each file's pixel bytes are let go as they
    /// are decoded ([`crate::io::FileSource::release_before`]), as a single volume file's are,
    /// so that a multi-frame file's bytes shrink as its voxels grow (the browser's files).
    /// Nothing is let go for a file on disk or bytes in memory; the chunks of a read-on-demand
    /// file cannot be read again.
    pub fn load_last(
        &self,
        files: &[InputFile],
        index: usize,
        limits: &Limits,
    ) -> Result<Loaded, LoadError> {
        self.load_entry(files, index, limits, true)
    }

    fn load_entry(
        &self,
        files: &[InputFile],
        index: usize,
        limits: &Limits,
        release: bool,
    ) -> Result<Loaded, LoadError> {
        let stack = self
            .stacks
            .get(index)
            .ok_or_else(|| LoadError::DicomSeries {
                series: "-".to_owned(),
                problem: SeriesProblem::NotListed {
                    number: index + 1,
                    count: self.stacks.len(),
                },
            })?;
        let same_files = files.len() == self.names.len()
            && files.iter().zip(&self.names).all(|(f, n)| f.name == *n);
        if !same_files {
            return Err(LoadError::DicomSeries {
                series: stack.series_uid.clone(),
                problem: SeriesProblem::FilesChanged {
                    given: files.len(),
                    listed: self.names.len(),
                },
            });
        }
        let chosen: Vec<(&InputFile, &FileHeader)> = stack
            .members
            .iter()
            .filter_map(|&m| self.headers.get(m))
            .filter_map(|(i, h)| Some((files.get(*i)?, h)))
            .collect();
        let Some(&(_, first)) = chosen.first() else {
            return Err(LoadError::DicomSeries {
                series: stack.series_uid.clone(),
                problem: SeriesProblem::NoImageInSeries,
            });
        };
        let mut volume = series::assemble(&stack.series_uid, &chosen, limits, release)?;
        volume
            .warnings
            .extend(series::header_warnings(chosen.iter().map(|(_, h)| *h)));
        if let Some(w) = volume.non_finite_warning() {
            volume.warnings.push(w);
        }
        Ok(Loaded {
            volume,
            notes: self.notes.clone(),
            patient: Some(first.patient.clone()),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn orientations_are_named_by_the_slice_normal() {
        let name = |o: [f64; 6]| SliceOrientation::from_orientation(Some(o));
        assert_eq!(
            name([1.0, 0.0, 0.0, 0.0, 1.0, 0.0]),
            SliceOrientation::Axial
        );
        assert_eq!(
            name([1.0, 0.0, 0.0, 0.0, 0.0, -1.0]),
            SliceOrientation::Coronal
        );
        assert_eq!(
            name([0.0, 1.0, 0.0, 0.0, 0.0, -1.0]),
            SliceOrientation::Sagittal
        );
        // 5 degrees off axial is axial, 20 degrees is oblique.
        let tilted = |deg: f64| {
            let (s, c) = deg.to_radians().sin_cos();
            [1.0, 0.0, 0.0, 0.0, c, s]
        };
        assert_eq!(name(tilted(5.0)), SliceOrientation::Axial);
        assert_eq!(name(tilted(20.0)), SliceOrientation::Oblique);
        assert_eq!(
            name([1.0, 0.0, 0.0, 1.0, 0.0, 0.0]),
            SliceOrientation::Unknown
        );
        assert_eq!(
            name([f64::NAN, 0.0, 0.0, 0.0, 1.0, 0.0]),
            SliceOrientation::Unknown
        );
        assert_eq!(
            SliceOrientation::from_orientation(None),
            SliceOrientation::Unknown
        );
    }
}
