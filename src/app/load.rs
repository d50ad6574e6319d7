//! Getting a volume into the app without freezing it: a [`LoadJob`] reads and decodes in steps,
//! one per frame. Natively it reads dropped or given paths (files and folders) a bounded number
//! of bytes per step and hands the loaders files read on demand, as the command line does (the
//! file bytes are never held beside the voxels); in the browser the files arrive already read
//! (asynchronously, by `web_files`), and the job only decodes (a DICOM set is decoded by
//! `web_files` as it is read and never reaches a job). Decoding is one step, announced a frame
//! before it starts so the progress bar says what is being decoded.
//!
//! Files holding several DICOM series load the default one ([`crate::io::SeriesList`]) and keep
//! a [`SeriesSet`], so that another series is one more job ([`LoadSource::Series`]) without the
//! files being given again.

use std::sync::Arc;

use super::error::AppError;
use crate::io::{InputFile, Loaded, SeriesList};
use crate::volume::Volume;

/// The series of files that hold several, kept so that another is a click away: the listing
/// (headers only) and the files (natively, files on disk are read on demand from their paths,
/// so only their first bytes stay in memory; the browser's files and unpacked archives stay as
/// bytes). Cloning shares both.
#[derive(Clone, Debug)]
pub struct SeriesSet {
    pub list: Arc<SeriesList>,
    files: SetFiles,
    /// The entry loaded (or being loaded).
    pub chosen: usize,
}

mod read;

use read::PathReader;

/// The page's `File`s of a set of series (the browser), opaque here: only the page reads them
/// again (`Platform::read_page_series`). Natively none is ever made.
#[derive(Clone)]
pub struct PageFiles(pub std::rc::Rc<dyn std::any::Any>);

impl std::fmt::Debug for PageFiles {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("PageFiles")
    }
}

/// Spacing the app renders the paper's phantoms at (as `shapecast phantom` does by default).
pub const PHANTOM_SPACING_MM: f64 = 0.5;

/// Where a volume comes from.
#[derive(Clone, Debug)]
pub enum LoadSource {
    /// Files already in memory (the browser's reads, the demo CT, tests).
    Files {
        label: String,
        files: Vec<InputFile>,
    },
    /// Paths on this machine: files and folders (walked recursively), read step by step
    /// (natively; a page has no paths, and its load says so).
    Paths(Vec<std::path::PathBuf>),
    /// One of the paper's phantoms by name (`crate::phantom::NAMES`, "fig8-sphere"), or "demo".
    Phantom(String),
    /// Another series of files already listed: `chosen` of the set.
    Series(SeriesSet),
}

impl LoadSource {
    /// What the user is told is being loaded.
    pub fn label(&self) -> String {
        match self {
            Self::Files { label, .. } => label.clone(),
            Self::Paths(paths) => match paths.as_slice() {
                [one] => one.display().to_string(),
                many => format!("{} files and folders", many.len()),
            },
            Self::Phantom(name) => format!("phantom {name}"),
            Self::Series(set) => set.label(),
        }
    }
}

/// Where a [`SeriesSet`]'s files are.
#[derive(Clone, Debug)]
enum SetFiles {
    /// In memory, or natively read on demand from their paths.
    Inputs(Arc<Vec<InputFile>>),
    /// The page's `File`s (the browser): read again, whole and one at a time, when a series
    /// is chosen (by the page, `Platform::read_page_series`), never held
    /// as bytes. Natively a set never holds them (the type has no values there).
    Page(PageFiles),
}

impl SeriesSet {
    /// The series of the page's `files` (by index into `list`'s files), `chosen` loaded.
    pub fn of_page_files(list: SeriesList, files: PageFiles, chosen: usize) -> Self {
        Self {
            list: Arc::new(list),
            files: SetFiles::Page(files),
            chosen,
        }
    }

    /// The page's files of a set read in the browser, when it is one.
    pub fn page_files(&self) -> Option<&PageFiles> {
        match &self.files {
            SetFiles::Page(files) => Some(files),
            SetFiles::Inputs(_) => None,
        }
    }

    /// The same files with entry `index` chosen.
    pub fn with_chosen(&self, index: usize) -> Self {
        Self {
            chosen: index,
            ..self.clone()
        }
    }

    /// What the user is told is being loaded: "series 3 (CT, 93 images)".
    pub fn label(&self) -> String {
        match self.list.entries().get(self.chosen) {
            Some(e) => format!(
                "series {} ({}, {} images)",
                e.number.map_or_else(|| "-".to_owned(), |n| n.to_string()),
                if e.modality.is_empty() {
                    "?"
                } else {
                    e.modality.as_str()
                },
                e.images
            ),
            None => "a series".to_owned(),
        }
    }
}

/// What one step of a job came to.
#[derive(Debug)]
pub enum LoadStep {
    /// Still working: `fraction` (0..1) done, now doing `what`.
    Working {
        fraction: f32,
        what: String,
    },
    Done(Box<Loaded>),
    /// The message names the file and the problem.
    Failed(AppError),
}

enum Stage {
    Listing(Vec<std::path::PathBuf>),
    Reading {
        reader: PathReader,
        skipped: Vec<String>,
    },
    Decode {
        files: Vec<InputFile>,
        announced: bool,
        /// What the folder walk skipped, put first among the loaded volume's notes.
        skipped: Vec<String>,
    },
    Series {
        set: SeriesSet,
        announced: bool,
    },
    Phantom {
        name: String,
        announced: bool,
    },
    Finished,
}

/// A load in progress.
pub struct LoadJob {
    label: String,
    stage: Stage,
    /// The series list of the files loaded, when they held several series.
    series: Option<SeriesSet>,
}

impl LoadJob {
    pub fn new(source: LoadSource) -> Self {
        let label = source.label();
        let stage = match source {
            LoadSource::Files { files, .. } => Stage::Decode {
                files,
                announced: false,
                skipped: Vec::new(),
            },
            LoadSource::Series(set) => Stage::Series {
                set,
                announced: false,
            },
            LoadSource::Paths(paths) => Stage::Listing(paths),
            LoadSource::Phantom(name) => Stage::Phantom {
                name,
                announced: false,
            },
        };
        Self {
            label,
            stage,
            series: None,
        }
    }

    pub fn label(&self) -> &str {
        &self.label
    }

    /// The series list of what was loaded, once the job is done, when the files held more
    /// than one series.
    pub fn take_series(&mut self) -> Option<SeriesSet> {
        self.series.take()
    }

    /// Does the next bounded piece of work.
    pub fn step(&mut self) -> LoadStep {
        match std::mem::replace(&mut self.stage, Stage::Finished) {
            Stage::Listing(paths) => match PathReader::list(&paths) {
                Ok((reader, skipped)) => {
                    let what = format!("reading {} files", reader.remaining());
                    self.stage = Stage::Reading { reader, skipped };
                    LoadStep::Working {
                        fraction: 0.0,
                        what,
                    }
                }
                Err(e) => LoadStep::Failed(e),
            },
            Stage::Reading {
                mut reader,
                skipped,
            } => {
                if let Err(e) = reader.read_some() {
                    return LoadStep::Failed(e);
                }
                if reader.remaining() == 0 {
                    self.stage = Stage::Decode {
                        files: reader.into_files(),
                        announced: false,
                        skipped,
                    };
                    return self.step();
                }
                let (done, total) = reader.bytes();
                let fraction = done as f32 / total.max(1) as f32;
                let what = format!(
                    "reading {} of {} files ({:.0} of {:.0} MB)",
                    reader.files_read(),
                    reader.files_read() + reader.remaining(),
                    done as f64 / 1e6,
                    total as f64 / 1e6
                );
                self.stage = Stage::Reading { reader, skipped };
                LoadStep::Working {
                    fraction: 0.5 * fraction,
                    what,
                }
            }
            Stage::Decode {
                files,
                announced,
                skipped,
            } => {
                if !announced {
                    let what = match files.as_slice() {
                        [one] => format!("decoding {}", crate::io::base_name(&one.name)),
                        many => format!("decoding {} files", many.len()),
                    };
                    self.stage = Stage::Decode {
                        files,
                        announced: true,
                        skipped,
                    };
                    return LoadStep::Working {
                        fraction: 0.5,
                        what,
                    };
                }
                let limits = crate::io::Limits::default();
                // Archives (a zipped DICOM series, a header and its data) are unpacked first,
                // then loaded as if their files had been dropped.
                let (files, mut unpacked) = match crate::io::zip::expand(files, &limits) {
                    Ok(r) => r,
                    Err(e) => return LoadStep::Failed(e.into()),
                };
                let loaded = match crate::io::list_series(&files, &limits) {
                    Ok(Some(list)) if list.entries().len() > 1 => {
                        let chosen = list.default_choice();
                        let loaded = list.load(&files, chosen, &limits);
                        if loaded.is_ok() {
                            // In the browser the files hold JavaScript objects (their bytes,
                            // read on demand), which are not `Send`; it has one thread.
                            #[allow(clippy::arc_with_non_send_sync)]
                            let files = Arc::new(files);
                            self.series = Some(SeriesSet {
                                list: Arc::new(list),
                                // Natively, files from paths are already read on demand
                                // (only their first bytes in memory).
                                files: SetFiles::Inputs(files),
                                chosen,
                            });
                        }
                        loaded
                    }
                    // One series: nothing to choose again, so its files' bytes go as
                    // they are decoded (a multi-frame file in the browser).
                    Ok(Some(list)) => list.load_last(&files, list.default_choice(), &limits),
                    Ok(None) => crate::io::load_with(&files, &limits),
                    Err(e) => Err(e),
                };
                match loaded {
                    Ok(mut loaded) => {
                        let mut notes = skipped;
                        notes.append(&mut unpacked);
                        notes.append(&mut loaded.notes);
                        loaded.notes = notes;
                        LoadStep::Done(Box::new(loaded))
                    }
                    Err(e) => LoadStep::Failed(e.into()),
                }
            }
            Stage::Series { set, announced } => {
                if !announced {
                    let what = format!("decoding {}", set.label());
                    self.stage = Stage::Series {
                        set,
                        announced: true,
                    };
                    return LoadStep::Working {
                        fraction: 0.5,
                        what,
                    };
                }
                let limits = crate::io::Limits::default();
                let loaded = match &set.files {
                    SetFiles::Inputs(files) => set.list.load(files, set.chosen, &limits),
                    // Read asynchronously by the page, not by a job.
                    SetFiles::Page(_) => {
                        return LoadStep::Failed(AppError::Internal(
                            "a series of the page's files is read by the page",
                        ));
                    }
                };
                match loaded {
                    Ok(loaded) => {
                        self.series = Some(set);
                        LoadStep::Done(Box::new(loaded))
                    }
                    Err(e) => LoadStep::Failed(e.into()),
                }
            }
            Stage::Phantom { name, announced } => {
                if !announced {
                    let what = format!("rendering phantom {name}");
                    self.stage = Stage::Phantom {
                        name,
                        announced: true,
                    };
                    return LoadStep::Working {
                        fraction: 0.3,
                        what,
                    };
                }
                match phantom_volume(&name) {
                    Some(volume) => LoadStep::Done(Box::new(Loaded {
                        volume,
                        notes: Vec::new(),
                        patient: None,
                    })),
                    None => LoadStep::Failed(AppError::UnknownPhantom {
                        known: format!(
                            "{}, {}",
                            crate::phantom::NAMES.join(", "),
                            crate::phantom::EXTRA_NAMES.join(", ")
                        ),
                        name,
                    }),
                }
            }
            Stage::Finished => LoadStep::Failed(AppError::Internal("the load already finished")),
        }
    }
}

/// A phantom as the app shows it: the paper's objects at 0.5 mm with their default noise, or
/// the synthetic demo.
pub fn phantom_volume(name: &str) -> Option<Volume> {
    if name == "demo" {
        return Some(crate::phantom::demo());
    }
    let p = crate::phantom::Phantom::by_name(name, None)?;
    let noise = p.default_noise_hu;
    Some(p.render_noisy([PHANTOM_SPACING_MM; 3], noise, 1))
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // a failed unwrap is a failed test
mod tests;
