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

    #[error(transparent)]
    Page(#[from] PageError),

    /// The PET over the CT could not be read or shown; the CT stays.
    #[error("PET")]
    Pet(#[source] Box<AppError>),

    /// Text the app composed itself (a few notes of the app's own).
    #[error("{0}")]
    Other(String),
}

/// What the page (or a file dropped on the native window) could not read or download. `words`
/// are the browser's own (a JavaScript error's message; egui's text for a drop), the one cause
/// it gives.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum PageError {
    #[error("{file}: cannot read: {words}")]
    CannotRead { file: String, words: String },

    #[error("{file}: cannot open: {words}")]
    CannotOpen { file: String, words: String },

    #[error("{folder}: cannot list the folder: {words}")]
    CannotList { folder: String, words: String },

    #[error("{file}: {:.1} GB is more than a browser tab can read as one file (4 GiB at most)", *.bytes / 1e9)]
    FileTooLarge { file: String, bytes: f64 },

    #[error("{label}: the dropped folder holds no files")]
    EmptyDrop { label: String },

    #[error("cannot start a download: {words}")]
    DownloadNotStarted { words: String },

    #[error("{label}: download cancelled")]
    DownloadCancelled { label: String },

    #[error("{url}: {problem}")]
    Download {
        url: String,
        problem: DownloadProblem,
    },

    #[error("{url}: could not fetch the demo CT: {words}")]
    Demo { url: String, words: String },

    #[error("no window object")]
    NoWindow,
}

/// Why a download by URL failed, as the reader is told what to do about it.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum DownloadProblem {
    #[error(
        "this site's Content-Security-Policy does not allow downloads from {host}; whoever hosts Shapecast can add it to connect-src (see \"Deploy\" in Shapecast's README), or download the file and drop it here"
    )]
    Policy { host: String },

    #[error(
        "a page served over HTTPS may not download over plain http; use the https:// address of the file, or download it and drop it here"
    )]
    PlainHttp,

    #[error("no answer from the server (network error); check the address and the connection")]
    NoAnswer,

    /// Another site's server that did not allow this page (`page`) to read its file (CORS).
    #[error(
        "the download was refused or got no answer. The server at {host} must allow this site ({page}) to read the file: it has to send the header Access-Control-Allow-Origin (see \"Deploy\" in Shapecast's README). Check the address, ask the server's administrator, or download the file and drop it here"
    )]
    Refused { host: String, page: String },

    #[error("not found on the server (HTTP {status}); check the address")]
    NotFound { status: u16 },

    #[error(
        "the server at {host} refused access (HTTP {status}): the file needs a login or a permission that a link cannot carry. Open the address in a tab, download the file and drop it here"
    )]
    Forbidden { host: String, status: u16 },

    /// `answer`: "HTTP 503 Service Unavailable".
    #[error("the server at {host} answered {answer}; try again later or check the address")]
    Status { host: String, answer: String },

    #[error("{:.0} MB is more than this browser tab can hold for one volume (at most {:.0} MB); open a smaller or downsampled series, or use the desktop app (shapecast view)", *.bytes as f64 / 1e6, *.most as f64 / 1e6)]
    TooLarge { bytes: u64, most: u64 },

    #[error(
        "the server sent a web page, not a volume (perhaps a login or an error page). Open the address in a tab to see it; a direct link to the file is needed, or download it and drop it here"
    )]
    WebPage,

    #[error("the download broke off after {:.1} MB ({words}); try again", *.bytes as f64 / 1e6)]
    BrokeOff { bytes: u64, words: String },
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
    fn the_page_s_failures_read_as_before_and_a_pet_s_are_named() {
        let e = AppError::from(PageError::Download {
            url: "https://x.org/ct.nii".to_owned(),
            problem: DownloadProblem::Status {
                host: "x.org".to_owned(),
                answer: "HTTP 503 Service Unavailable".to_owned(),
            },
        });
        assert_eq!(
            e.message(),
            "https://x.org/ct.nii: the server at x.org answered HTTP 503 Service Unavailable; try again later or check the address"
        );
        let e = AppError::Pet(Box::new(
            PageError::FileTooLarge {
                file: "pet.nii".to_owned(),
                bytes: 5.0e9,
            }
            .into(),
        ));
        assert_eq!(
            e.message(),
            "PET: pet.nii: 5.0 GB is more than a browser tab can read as one file (4 GiB at most)"
        );
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
