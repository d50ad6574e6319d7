//! Readers and writers of volume files. Everything here takes bytes and returns a `Volume` or a
//! typed error; nothing here touches wgpu or the file system (the CLI and the web page read files).
//!
//! The entry point is [`load`]: it sniffs each file by content (not only by extension), pairs
//! headers with their data files (.hdr/.img, .nhdr + data, .mhd + .raw), and gathers DICOM files
//! into series ([`list_series`] lists them from their headers; [`load`] loads the default one). Every size a header declares is checked against the bytes present and
//! against [`Limits`] before anything is allocated.

mod dicom;
pub mod dicomweb;
mod error;
mod geometry;
mod input;
#[cfg(target_arch = "wasm32")]
pub mod js;
mod metaimage;
pub mod nifti;
mod nrrd;
mod raw;
pub mod url;
pub mod zip;

pub use dicom::{
    FolderRead, FolderReader, SeriesBuilder, SeriesEntry, SeriesList, SliceOrientation,
    decodable_transfer_syntaxes, entry_builder, finish_entry, load_entry,
};
pub use error::{Corruption, DicomProblem, LoadError, SeriesProblem};
pub use input::{Chunk, Chunked, FileSource, HEAD_BYTES, InputFile, MemorySource};

use crate::volume::Volume;

/// A loaded volume and what the loader wants the user to know about the files it was given
/// (other DICOM series that were not chosen, files that were ignored). Problems with the volume
/// itself are in `volume.warnings`.
#[derive(Clone, Debug)]
pub struct Loaded {
    pub volume: Volume,
    pub notes: Vec<String>,
    /// Who and what a DICOM series is (its first image's header); `None` for other formats.
    pub patient: Option<Patient>,
}

/// The patient and study of a DICOM series, as its header (or an archive's QIDO-RS answer)
/// says: for the user's own screen only, never written into a link, a log line or a request.
/// `Debug` shows none of it.
#[derive(Clone, Default, PartialEq, Eq)]
pub struct Patient {
    /// PatientName as written (`Family^Given`).
    pub name: Option<String>,
    pub id: Option<String>,
    /// PatientBirthDate, `YYYYMMDD`.
    pub birth_date: Option<String>,
    /// StudyDate, `YYYYMMDD`.
    pub study_date: Option<String>,
    pub series_description: Option<String>,
}

impl std::fmt::Debug for Patient {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Patient(..)")
    }
}

/// What a user should know before two volumes are read in one patient space (a PET over its
/// CT): `None` when both carry the same FrameOfReferenceUID, else a sentence saying that the
/// frames differ or are not known, and that they are placed by their patient coordinates anyway.
pub fn frame_of_reference_note(primary: &Volume, other: &Volume) -> Option<String> {
    match (&primary.frame_of_reference, &other.frame_of_reference) {
        (Some(a), Some(b)) if a == b => None,
        (Some(_), Some(_)) => Some(format!(
            "{} and {} have different frames of reference (FrameOfReferenceUID): they are placed by their patient coordinates, which may not match",
            primary.source, other.source
        )),
        _ => Some(format!(
            "the frame of reference of {} or {} is not known (no FrameOfReferenceUID): they are placed by their patient coordinates",
            primary.source, other.source
        )),
    }
}

/// Memory caps applied before allocating. The defaults let a 512x512x2000 i16 CT (1 GiB) through.
#[derive(Clone, Copy, Debug)]
pub struct Limits {
    /// Largest voxel buffer a loader may allocate, in bytes.
    pub max_voxel_bytes: u64,
    /// Largest output of any one decompression (gzip, zlib), in bytes.
    pub max_decompressed_bytes: u64,
}

impl Default for Limits {
    fn default() -> Self {
        // wasm32 has a 4 GiB address space in total, so the browser gets lower caps.
        if cfg!(target_arch = "wasm32") {
            Self {
                max_voxel_bytes: 1536 << 20,
                max_decompressed_bytes: 2 << 30,
            }
        } else {
            Self {
                max_voxel_bytes: 4 << 30,
                max_decompressed_bytes: 8 << 30,
            }
        }
    }
}

/// What a file's content says it is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    /// NIfTI-1 or NIfTI-2 (single file, or the header of a .hdr/.img pair), or Analyze 7.5.
    Nifti,
    /// NIfTI inside gzip (.nii.gz).
    NiftiGz,
    Nrrd,
    MetaImage,
    Dicom,
    /// Not recognised: a data file of a detached header, or something else.
    Unknown,
}

/// Identifies a file by its first bytes (the name only breaks ties for headerless data).
pub fn sniff(name: &str, bytes: &[u8]) -> Format {
    if raw::is_gzip(bytes) {
        // Peek at the first kilobyte of the decompressed stream.
        if let Ok((head, _)) = raw::gunzip_prefix(name, bytes, 1024)
            && nifti::looks_like_header(&head)
        {
            return Format::NiftiGz;
        }
        return Format::Unknown;
    }
    if bytes.starts_with(b"NRRD000") {
        return Format::Nrrd;
    }
    if nifti::looks_like_header(bytes) {
        return Format::Nifti;
    }
    if bytes.len() >= 132 && &bytes[128..132] == b"DICM" {
        return Format::Dicom;
    }
    if metaimage::looks_like_header(bytes) {
        return Format::MetaImage;
    }
    if dicom::looks_like_bare_dataset(bytes) {
        return Format::Dicom;
    }
    Format::Unknown
}

/// [`sniff`] of a given file: a file read on demand is sniffed from its first bytes, except
/// that a gzip stream is inflated from the file (its header's optional fields may be longer
/// than the bytes held).
fn sniff_file(f: &InputFile) -> Format {
    if f.is_on_demand() && raw::is_gzip(&f.bytes) {
        return match raw::gunzip_prefix_data(&f.name, f.data(), 1024) {
            Ok((head, _)) if nifti::looks_like_header(&head) => Format::NiftiGz,
            _ => Format::Unknown,
        };
    }
    sniff(&f.name, &f.bytes)
}

/// The last path component of a name, for pairing headers with data files and for messages.
pub(crate) fn base_name(name: &str) -> &str {
    name.rsplit(['/', '\\']).next().unwrap_or(name)
}

/// A warning when a header names its data file by a path (`../x/passwd`): only the last
/// component is matched against the files given, and the user is told which one was used.
pub(crate) fn path_note(field: &str, wanted: &str, used: &str) -> Option<String> {
    let wanted = wanted.trim();
    (base_name(wanted) != wanted).then(|| {
        format!(
            "header field {field} names the path \"{wanted}\"; only its file name is matched, and the given file {used} was used"
        )
    })
}

/// Finds the companion data file a header names, among the files the user gave.
#[derive(Clone, Copy)]
pub(crate) struct Companions<'a> {
    files: &'a [InputFile],
}

impl<'a> Companions<'a> {
    pub(crate) fn new(files: &'a [InputFile]) -> Self {
        Self { files }
    }

    /// The one data file a header's `field` names (`wanted`): a list or a pattern of files (one
    /// per slice) is refused as `unsupported` (what, then why), a file not given is
    /// `MissingDataFile`, and a header that names a path gets a note in `warnings`.
    pub(crate) fn data_file(
        &self,
        header: &str,
        field: &str,
        wanted: &str,
        unsupported: (&str, &str),
        warnings: &mut Vec<String>,
    ) -> Result<&'a InputFile, LoadError> {
        if wanted.starts_with("LIST")
            || wanted.contains('%')
            || wanted.split_whitespace().count() > 1
        {
            let (what, why) = unsupported;
            return Err(LoadError::unsupported(
                header,
                what,
                format!("\"{wanted}\" ({why})"),
            ));
        }
        let f = self
            .find(wanted)
            .ok_or_else(|| LoadError::MissingDataFile {
                file: header.to_owned(),
                data_file: wanted.to_owned(),
            })?;
        if let Some(note) = path_note(field, wanted, &f.name) {
            warnings.push(note);
        }
        Ok(f)
    }

    /// A file whose last path component equals that of `wanted` (exactly, else ignoring case).
    pub(crate) fn find(&self, wanted: &str) -> Option<&'a InputFile> {
        let wanted = base_name(wanted.trim());
        self.files
            .iter()
            .find(|f| base_name(&f.name) == wanted)
            .or_else(|| {
                self.files
                    .iter()
                    .find(|f| base_name(&f.name).eq_ignore_ascii_case(wanted))
            })
    }
}

/// What a header format's reader reads: the header file, the other files given with it (where
/// a detached data file is looked up) and the limits.
#[derive(Clone, Copy)]
pub(crate) struct HeaderInput<'a> {
    pub(crate) file: &'a InputFile,
    pub(crate) companions: Companions<'a>,
    pub(crate) limits: &'a Limits,
}

impl<'a> HeaderInput<'a> {
    pub(crate) fn new(file: &'a InputFile, companions: Companions<'a>, limits: &'a Limits) -> Self {
        Self {
            file,
            companions,
            limits,
        }
    }

    /// The voxel count of a grid of `dims` (`u64::MAX` on overflow), refused when its voxels as
    /// `ty` are stored would be more than the limits allow.
    pub(crate) fn voxel_count(
        &self,
        dims: [usize; 3],
        ty: raw::SampleType,
    ) -> Result<u64, LoadError> {
        let count = raw::checked_product(&dims.map(|d| d as u64)).unwrap_or(u64::MAX);
        raw::check_voxel_budget(&self.file.name, count, ty.output_size() as u64, self.limits)?;
        Ok(count)
    }
}

/// Runs a header format's `read` on `file` given with `companions`, under the default limits.
#[cfg(test)]
pub(crate) fn read_header(
    read: fn(HeaderInput<'_>) -> Result<Volume, LoadError>,
    file: &InputFile,
    companions: &[InputFile],
) -> Result<Volume, LoadError> {
    read(HeaderInput::new(
        file,
        Companions::new(companions),
        &Limits::default(),
    ))
}

/// Loads one volume from the given files with the default [`Limits`].
pub fn load(files: &[InputFile]) -> Result<Loaded, LoadError> {
    load_with(files, &Limits::default())
}

/// Loads one volume from the given files: a single file, a header and its data file, or a set
/// of DICOM files (the CT or MR series with the most images is chosen, as
/// [`SeriesList::default_choice`] says; the others are named in the notes). This is the last
/// read of the files: a source that can let bytes go ([`FileSource::release_before`]) lets the
/// payload's go as the voxels fill.
pub fn load_with(files: &[InputFile], limits: &Limits) -> Result<Loaded, LoadError> {
    if files.is_empty() {
        return Err(LoadError::NoFiles);
    }
    let formats: Vec<Format> = files.iter().map(sniff_file).collect();
    if let Some(list) = list_sniffed(files, &formats, limits)? {
        let chosen = list.default_choice();
        // The last read of the files, as for every other format.
        let mut loaded = list.load_last(files, chosen, limits)?;
        loaded.notes.extend(list.others_not_loaded(chosen));
        return Ok(loaded);
    }
    let primary = formats
        .iter()
        .position(|f| !matches!(f, Format::Dicom | Format::Unknown));

    let companions = Companions::new(files);
    let mut notes = Vec::new();
    let mut loaded = if let Some(p) = primary {
        let file = &files[p];
        let input = HeaderInput::new(file, companions, limits);
        let volume = match formats[p] {
            Format::Nifti | Format::NiftiGz => nifti::read(input)?,
            Format::Nrrd => nrrd::read(input)?,
            Format::MetaImage => metaimage::read(input)?,
            _ => unreachable_format(file)?,
        };
        let used = used_companions(&volume);
        for (f, fmt) in files.iter().zip(&formats) {
            if !std::ptr::eq(f, file)
                && !used.iter().any(|u| base_name(&f.name) == u.as_str())
                && *fmt != Format::Unknown
            {
                notes.push(format!(
                    "{}: ignored (only one volume is loaded at a time)",
                    f.name
                ));
            }
        }
        Loaded {
            volume,
            notes: Vec::new(),
            patient: None,
        }
    } else {
        let file = &files[0];
        let reason = if raw::is_gzip(&file.bytes) {
            "gzip-compressed, but not a NIfTI file; a compressed data file needs its header"
                .to_owned()
        } else if file.is_empty() {
            "the file is empty".to_owned()
        } else {
            "no NIfTI, NRRD, MetaImage or DICOM header found; a raw data file (.img, .raw) needs its header".to_owned()
        };
        return Err(LoadError::UnknownFormat {
            file: file.name.clone(),
            reason,
        });
    };
    notes.append(&mut loaded.notes);
    loaded.notes = notes;
    if let Some(w) = loaded.volume.non_finite_warning() {
        loaded.volume.warnings.push(w);
    }
    Ok(loaded)
}

/// The series in the given files when they are a DICOM set (what [`load`] would gather into a
/// series: several DICOM files, or one without another format beside it), from the headers
/// alone; `Ok(None)` for other files (another format is loaded from them). Each entry loads
/// with [`SeriesList::load`] from the same files.
pub fn list_series(files: &[InputFile], limits: &Limits) -> Result<Option<SeriesList>, LoadError> {
    let formats: Vec<Format> = files.iter().map(sniff_file).collect();
    list_sniffed(files, &formats, limits)
}

/// [`list_series`] of files whose formats are known.
fn list_sniffed(
    files: &[InputFile],
    formats: &[Format],
    limits: &Limits,
) -> Result<Option<SeriesList>, LoadError> {
    let dicom_files: Vec<usize> = (0..files.len())
        .filter(|&i| formats.get(i) == Some(&Format::Dicom))
        .collect();
    let primary = formats
        .iter()
        .any(|f| !matches!(f, Format::Dicom | Format::Unknown));
    if dicom_files.is_empty() || (primary && dicom_files.len() <= 1) {
        return Ok(None);
    }
    let notes = files
        .iter()
        .zip(formats)
        .filter(|(_, f)| **f != Format::Dicom)
        .map(|(f, _)| format!("{}: ignored (not DICOM)", f.name))
        .collect();
    dicom::list_series(files, &dicom_files, notes, limits).map(Some)
}

fn unreachable_format(file: &InputFile) -> Result<Volume, LoadError> {
    Err(LoadError::UnknownFormat {
        file: file.name.clone(),
        reason: "internal: no reader for this format".to_owned(),
    })
}

/// The data files a loader recorded in `volume.source` as "header + data" so that they are
/// not reported as ignored.
fn used_companions(volume: &Volume) -> Vec<String> {
    volume
        .source
        .split(" + ")
        .skip(1)
        .map(|s| base_name(s).to_owned())
        .collect()
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // a failed unwrap is a failed test
mod tests {
    use super::*;

    #[test]
    fn nothing_and_garbage_are_errors() {
        assert!(matches!(load(&[]), Err(LoadError::NoFiles)));
        let r = load(&[InputFile::new("x.bin", vec![1, 2, 3])]);
        assert!(matches!(r, Err(LoadError::UnknownFormat { .. })), "{r:?}");
        let r = load(&[InputFile::new("empty", Vec::new())]);
        assert!(matches!(r, Err(LoadError::UnknownFormat { .. })), "{r:?}");
    }

    #[test]
    fn base_names() {
        assert_eq!(base_name("a/b/c.nii"), "c.nii");
        assert_eq!(base_name("c:\\x\\y.raw"), "y.raw");
        assert_eq!(base_name("plain"), "plain");
    }
}
