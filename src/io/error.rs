//! The typed error every loader returns: each variant names the file and what was wrong with it.

/// Why a volume could not be loaded. Every variant carries the file name (as the user gave it)
/// and enough context to act on: the header field, the slice, the transfer syntax.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum LoadError {
    #[error("no files were given")]
    NoFiles,

    #[error("{file}: not a volume format Shapecast reads ({reason})")]
    UnknownFormat { file: String, reason: String },

    #[error("{file}: truncated: {what} needs {needed} bytes but only {available} are present")]
    Truncated {
        file: String,
        what: String,
        needed: u64,
        available: u64,
    },

    #[error("{file}: header field {field}: {message}")]
    InvalidHeader {
        file: String,
        field: String,
        message: String,
    },

    #[error("{file}: {what} would need {bytes} bytes, more than the limit of {limit} bytes")]
    TooLarge {
        file: String,
        what: String,
        bytes: u64,
        limit: u64,
    },

    #[error("{file}: unsupported {what}: {detail}")]
    Unsupported {
        file: String,
        what: String,
        detail: String,
    },

    #[error("{file}: cannot read: {message}")]
    Read { file: String, message: String },

    #[error("{file}: decompression failed: {message}")]
    Decompress { file: String, message: String },

    #[error(
        "{file}: the data file \"{data_file}\" named in the header was not given (drop it together with the header)"
    )]
    MissingDataFile { file: String, data_file: String },

    #[error("{file}: DICOM: {message}")]
    Dicom { file: String, message: String },

    #[error("{file}: DICOM transfer syntax {uid} ({name}) is not supported: {reason}")]
    UnsupportedTransferSyntax {
        file: String,
        uid: String,
        name: String,
        reason: String,
    },

    #[error("DICOM series {series}: slice {slice} ({file}): {message}")]
    DicomSlice {
        series: String,
        slice: usize,
        file: String,
        message: String,
    },

    #[error("DICOM series {series}: {message}")]
    DicomSeries { series: String, message: String },

    #[error("{file}: out of memory allocating {bytes} bytes for {what}")]
    OutOfMemory {
        file: String,
        what: String,
        bytes: u64,
    },

    #[error("{file}: cannot write: {message}")]
    Write { file: String, message: String },
}

impl LoadError {
    pub(crate) fn header(file: &str, field: &str, message: impl Into<String>) -> Self {
        Self::InvalidHeader {
            file: file.to_owned(),
            field: field.to_owned(),
            message: message.into(),
        }
    }

    /// The header `field`'s `value` parsed as a `T`, or an invalid header saying `problem`.
    pub(crate) fn parse_field<T: std::str::FromStr>(
        file: &str,
        field: &str,
        value: &str,
        problem: &str,
    ) -> Result<T, Self> {
        value
            .parse()
            .map_err(|_| Self::header(file, field, problem))
    }

    /// A header line that is not of the form `expected` (its first 80 characters quoted).
    pub(crate) fn header_line(file: &str, line: &str, expected: &str) -> Self {
        let line: String = line.chars().take(80).collect();
        Self::header(
            file,
            "header line",
            format!("\"{line}\" is not \"{expected}\""),
        )
    }

    pub(crate) fn unsupported(file: &str, what: &str, detail: impl Into<String>) -> Self {
        Self::Unsupported {
            file: file.to_owned(),
            what: what.to_owned(),
            detail: detail.into(),
        }
    }

    pub(crate) fn truncated(
        file: &str,
        what: impl Into<String>,
        needed: u64,
        available: u64,
    ) -> Self {
        Self::Truncated {
            file: file.to_owned(),
            what: what.into(),
            needed,
            available,
        }
    }
}
