//! A set of DICOM files read one at a time where they cannot be read on demand (the browser's
//! dropped or chosen folders: a `File` is read whole, asynchronously). Each file's header goes
//! into the series list, and while every image so far belongs to one series its pixels are
//! decoded at once into a [`SeriesBuilder`]; then the file's bytes are dropped. So a folder of
//! one series costs one file plus the voxels (issue "hostile files": 1.5x the voxels at most),
//! not all its files plus the voxels. A folder of several series is listed in the same pass
//! and the chosen one read again, file by file, into a new builder ([`FolderRead::List`],
//! [`SeriesList::members`]).

use super::read_header;
use super::series;
use super::stream::SeriesBuilder;
use super::{FileHeader, SeriesList};
use crate::io::{InputFile, Limits, LoadError, Loaded};

/// What a folder read gave.
pub enum FolderRead {
    /// One stack: its volume, decoded as the files were read.
    Loaded(Box<Loaded>),
    /// Several stacks: load one by pushing the files of [`SeriesList::members`] into a new
    /// [`SeriesBuilder`] (the list's notes go with it).
    List(SeriesList),
}

/// Reads a DICOM set file by file (see the module documentation).
pub struct FolderReader {
    limits: Limits,
    /// Every file given, DICOM or not, in the order given (the indices of the list).
    names: Vec<String>,
    headers: Vec<(usize, FileHeader)>,
    notes: Vec<String>,
    first_error: Option<LoadError>,
    /// Decodes while every image so far belongs to one series; dropped at the first image of
    /// another.
    builder: Option<SeriesBuilder>,
    series_uid: Option<String>,
}

impl FolderReader {
    pub fn new(limits: Limits) -> Self {
        Self {
            builder: Some(SeriesBuilder::new(limits)),
            limits,
            names: Vec::new(),
            headers: Vec::new(),
            notes: Vec::new(),
            first_error: None,
            series_uid: None,
        }
    }

    /// How many files will be given: the voxels are then reserved once, at the first image's
    /// size, instead of grown (growing a buffer holds the old and the new one at once).
    pub fn expect_files(&mut self, count: usize) {
        if let Some(builder) = &mut self.builder {
            builder.expect_images(count);
        }
    }

    /// Files given so far.
    pub fn files(&self) -> usize {
        self.names.len()
    }

    /// Whether the pixels are still being decoded as the files arrive (one series so far).
    pub fn decoding(&self) -> bool {
        self.builder.is_some()
    }

    /// A file that is not DICOM: listed as ignored, as [`crate::io::list_series`] does.
    pub fn ignore(&mut self, name: String) {
        self.notes.push(format!("{name}: ignored (not DICOM)"));
        self.names.push(name);
    }

    /// Reads one DICOM file's header and, while the set is one series, decodes its pixels;
    /// its bytes are dropped on return. A file without an image or with an unreadable header
    /// is noted and skipped (as listing does); pixels that cannot be decoded, or more voxels
    /// than the limits allow, are an error.
    pub fn push(&mut self, file: InputFile) -> Result<(), LoadError> {
        let index = self.names.len();
        self.names.push(file.name.clone());
        match read_header(&file, &self.limits) {
            Ok(Some(header)) => {
                let first = self
                    .series_uid
                    .get_or_insert_with(|| header.series_uid.clone());
                if *first != header.series_uid {
                    // A second series: list only, and load the chosen one afterwards.
                    self.builder = None;
                }
                self.headers.push((index, header));
                if let Some(builder) = &mut self.builder {
                    builder.push(file)?;
                }
            }
            Ok(None) => self
                .notes
                .push(format!("{}: DICOM without an image (skipped)", file.name)),
            Err(e) => {
                self.notes
                    .push(format!("skipped: {}", crate::error::chain(&e)));
                self.first_error.get_or_insert(e);
            }
        }
        Ok(())
    }

    /// The volume when the files held one stack, else the list to choose from.
    pub fn finish(self) -> Result<FolderRead, LoadError> {
        if self.headers.is_empty() {
            let names: Vec<&str> = self.names.iter().map(String::as_str).collect();
            return Err(self
                .first_error
                .unwrap_or_else(|| series::no_image_error(&names)));
        }
        let list = SeriesList::from_headers(self.names, self.headers, self.notes);
        match self.builder {
            Some(builder) if list.entries().len() == 1 => {
                Ok(FolderRead::Loaded(Box::new(finish_entry(&list, builder)?)))
            }
            _ => Ok(FolderRead::List(list)),
        }
    }
}

/// Loads entry `index` of `list` from its files, given one at a time by `read` (file index ->
/// the file, read whole): decoded as they come, each dropped after. The list's notes go with
/// the volume. (The browser's asynchronous reads run the same three steps:
/// [`SeriesList::members`], [`entry_builder`], [`finish_entry`].)
pub fn load_entry(
    list: &SeriesList,
    index: usize,
    limits: &Limits,
    mut read: impl FnMut(usize) -> Result<InputFile, LoadError>,
) -> Result<Loaded, LoadError> {
    let members = list.members(index);
    let mut builder = entry_builder(members.len(), limits);
    for i in members {
        builder.push(read(i)?)?;
    }
    finish_entry(list, builder)
}

/// The builder for an entry of `images` files.
pub fn entry_builder(images: usize, limits: &Limits) -> SeriesBuilder {
    let mut builder = SeriesBuilder::new(*limits);
    builder.expect_images(images);
    builder
}

/// The volume of an entry's builder, with the list's notes first.
pub fn finish_entry(list: &SeriesList, builder: SeriesBuilder) -> Result<Loaded, LoadError> {
    let mut loaded = builder.finish()?;
    let mut notes = list.notes().to_vec();
    notes.append(&mut loaded.notes);
    loaded.notes = notes;
    Ok(loaded)
}
