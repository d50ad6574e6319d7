//! Why something the user asked for did not happen ([`AppError`]), kept typed until it is
//! shown: the loaders', the file lister's and the archive's errors as they are, with their
//! sources; [`AppError::message`] is the text the error list shows.

use crate::compute::pipeline::PipelineError;
use crate::gpu::readback::ReadbackError;
use crate::gpu::volume_texture::RenderVolumeError;
use crate::io::LoadError;
use crate::io::dicomweb::DicomWebError;
use crate::render::raycast::RaycastError;
use crate::render::slice::SliceError;

/// An error of the app: a load, a listing, an archive, the device.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum AppError {
    #[error(transparent)]
    Load(#[from] LoadError),

    #[error(transparent)]
    Files(#[from] crate::files::FilesError),

    #[error(transparent)]
    DicomWeb(#[from] DicomWebError),

    /// An archive's work for `action` ("PET", "Store to PACS") that failed.
    #[error("{action}")]
    Archive {
        action: &'static str,
        #[source]
        source: DicomWebError,
    },

    #[error(transparent)]
    Platform(#[from] PlatformError),

    /// The loaded volume cannot be shown on this device.
    #[error("{volume}")]
    Upload {
        volume: String,
        #[source]
        source: RenderVolumeError,
    },

    #[error("unknown phantom {name:?}; known: {known}")]
    UnknownPhantom { name: String, known: String },

    /// A picture, a movie or a store (`action`: "Save movie") that failed.
    #[error("{action}")]
    Export {
        action: &'static str,
        #[source]
        source: ExportError,
    },

    /// A slice pane (`pane`: "axial") could not draw its slice.
    #[error("{pane} pane")]
    Pane {
        pane: &'static str,
        #[source]
        source: SliceError,
    },

    /// A feature computation (`method`: "Hessian") could not start.
    #[error("{method}")]
    Features {
        method: &'static str,
        #[source]
        source: PipelineError,
    },

    /// A state the code should never reach (said rather than panicked on).
    #[error("internal: {0}")]
    Internal(&'static str),

    /// Text the app composed itself, from a part whose errors are not typed yet (the page's
    /// file reads, whose causes are JavaScript values).
    #[error("{0}")]
    Other(String),
}

/// Why a picture or a movie was not made or not saved.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ExportError {
    #[error("no volume is shown")]
    NoVolume,

    #[error("the MIP pane has not been drawn yet; show it first")]
    PaneNotDrawn,

    #[error("the {0} pane is not shown")]
    PaneNotShown(&'static str),

    /// The pane's rectangle (points) holds no pixel of the screenshot.
    #[error("the pane ({0}) is not on the screen")]
    OffScreen(String),

    #[error("the volume shown did not come from an archive")]
    NotFromArchive,

    /// The series shown changed while the rotation to store was made.
    #[error("another series is shown now; not stored")]
    SeriesChanged,

    #[error("the volume was closed")]
    VolumeClosed,

    #[error("stopped: another volume is shown")]
    VolumeReplaced,

    /// The off-screen target or the ray caster.
    #[error(transparent)]
    Render(#[from] RaycastError),

    #[error("reading frame {frame} back")]
    Readback {
        frame: u32,
        #[source]
        source: ReadbackError,
    },

    /// `what`: "the picture as PNG", "the movie", "movie frame 3".
    #[error("encoding {what}")]
    Encode {
        what: String,
        #[source]
        source: png::EncodingError,
    },

    #[error("movie frame {frame} of {frames}: {got} bytes, expected {want}")]
    FrameSize {
        frame: u32,
        frames: u32,
        got: usize,
        want: usize,
    },

    /// The movie was finished before all its frames were in.
    #[error("the movie has {written} of its {frames} frames")]
    Unfinished { written: u32, frames: u32 },

    #[error("the movie's buffer is poisoned")]
    Poisoned,

    #[error(transparent)]
    Save(#[from] SaveError),
}

/// What the platform the app runs on cannot do, or could not set up.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum PlatformError {
    /// `urls`: volumes by URL are downloaded by the page, not the native window.
    #[error("{urls}: opening a volume by URL works in the browser; download it and open the file")]
    UrlsNatively { urls: String },

    /// `urls`: a link's PET by URL, which the native window does not download.
    #[error("{urls}: a PET by URL opens in the browser; natively give --pet PATH")]
    PetUrlsNatively { urls: String },

    /// The page's drops and file inputs could not be set up (the browser's words).
    #[error("drag and drop is unavailable: {0}")]
    DropUnavailable(String),
}

/// Why a file made here (a picture, a movie) did not reach the user.
#[derive(Debug, thiserror::Error)]
pub enum SaveError {
    /// Natively: the file could not be written.
    #[error("writing {path}")]
    Write {
        path: String,
        #[source]
        source: std::io::Error,
    },
    /// In the page: the browser refused the download (its words).
    #[error("the browser refused the download: {0}")]
    Download(String),
}

impl From<String> for AppError {
    fn from(message: String) -> Self {
        Self::Other(message)
    }
}

impl AppError {
    /// `action` ("Save picture") failed because of `source`.
    pub fn export(action: &'static str, source: ExportError) -> Self {
        Self::Export { action, source }
    }

    /// The error and its sources as one line for the user (see [`crate::error::chain`]).
    pub fn message(&self) -> String {
        crate::error::chain(self)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_load_error_is_shown_with_its_source() {
        let e = AppError::from(LoadError::Read {
            file: "scan.nii".to_owned(),
            offset: 352,
            source: std::io::Error::other("input/output error"),
        });
        assert_eq!(
            e.message(),
            "scan.nii: cannot read at byte 352: input/output error"
        );
        let e = AppError::Upload {
            volume: "big.nrrd".to_owned(),
            source: RenderVolumeError::Empty,
        };
        assert_eq!(e.message(), "big.nrrd: the volume is empty");
    }

    #[test]
    fn an_export_is_shown_as_its_action_and_cause() {
        let e = AppError::export(
            "Save movie",
            ExportError::FrameSize {
                frame: 3,
                frames: 2,
                got: 5,
                want: 24,
            },
        );
        assert_eq!(
            e.message(),
            "Save movie: movie frame 3 of 2: 5 bytes, expected 24"
        );
        let e = AppError::Pane {
            pane: "axial",
            source: SliceError::Index {
                index: 70,
                count: 61,
                axis: 2,
            },
        };
        assert_eq!(
            e.message(),
            "axial pane: slice 70 is outside the volume (61 slices along axis 2)"
        );
    }
}
