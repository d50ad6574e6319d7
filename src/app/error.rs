//! Why something the user asked for did not happen ([`AppError`]), kept typed until it is
//! shown: the loaders', the file lister's and the archive's errors as they are, with their
//! sources; [`AppError::message`] is the text the error list shows.

use crate::gpu::volume_texture::RenderVolumeError;
use crate::io::LoadError;
use crate::io::dicomweb::DicomWebError;

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

    /// The loaded volume cannot be shown on this device.
    #[error("{volume}")]
    Upload {
        volume: String,
        #[source]
        source: RenderVolumeError,
    },

    #[error("unknown phantom {name:?}; known: {known}")]
    UnknownPhantom { name: String, known: String },

    /// A state the code should never reach (said rather than panicked on).
    #[error("internal: {0}")]
    Internal(&'static str),

    /// Text the app composed itself, from a part whose errors are not typed yet (the page's
    /// file reads, exports).
    #[error("{0}")]
    Other(String),
}

impl From<String> for AppError {
    fn from(message: String) -> Self {
        Self::Other(message)
    }
}

impl AppError {
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
}
