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

    #[error("{file}: cannot read at byte {offset}")]
    Read {
        file: String,
        offset: u64,
        #[source]
        source: std::io::Error,
    },

    /// A compressed stream (`stream`: "gzip", "zip archive", "DICOM pixel data", ...) that
    /// cannot be, or must not be, inflated; `source` is the decompressor's own complaint.
    #[error("{file}: decompression failed: {stream}: {problem}")]
    Decompress {
        file: String,
        stream: String,
        problem: Corruption,
        #[source]
        source: Option<Box<dyn std::error::Error + Send + Sync>>,
    },

    #[error(
        "{file}: the data file \"{data_file}\" named in the header was not given (drop it together with the header)"
    )]
    MissingDataFile { file: String, data_file: String },

    #[error("{file}: DICOM: {problem}")]
    Dicom { file: String, problem: DicomProblem },

    /// dicom-rs refused the file (`what` it was doing); `source` is its error.
    #[error("{file}: DICOM: {what}")]
    DicomRead {
        file: String,
        what: String,
        #[source]
        source: Box<dyn std::error::Error + Send + Sync>,
    },

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

    #[error("DICOM series {series}: {problem}")]
    DicomSeries {
        series: String,
        problem: SeriesProblem,
    },

    #[error("{file}: out of memory allocating {bytes} bytes for {what}")]
    OutOfMemory {
        file: String,
        what: String,
        bytes: u64,
    },

    #[error("{file}: cannot write: {message}")]
    Write { file: String, message: String },
}

/// What is wrong with one DICOM file.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum DicomProblem {
    #[error("holds no image (no Rows and Columns)")]
    NoImage,
    /// Sequences nested deeper than `limit` at element (`group`,`element`), byte `at`.
    #[error(
        "sequences nested more than {limit} deep (at ({group:04X},{element:04X}), byte {at} of the data set); real files stay under 10, so the file is corrupt or crafted"
    )]
    NestedTooDeep {
        limit: usize,
        group: u16,
        element: u16,
        at: u64,
    },
    /// A delimitation item (FFFE,`element`) at byte `at` with a length other than 0.
    #[error(
        "delimitation item (FFFE,{element:04X}) at byte {at} has length {len}; the standard requires 0 (the file is corrupt)"
    )]
    DelimiterLength { element: u16, at: usize, len: u64 },
    /// The items of encapsulated (compressed) pixel data, in the decoder's words.
    #[error("encapsulated pixel data: {0}")]
    Encapsulated(String),
    /// RLE Lossless pixel data, in the decoder's words.
    #[error("RLE Lossless: {0}")]
    Rle(String),
    #[error("RLE Lossless: {compressed} compressed bytes cannot hold {total} bytes of pixels")]
    RleTooSmall { compressed: usize, total: usize },
    /// A compressed fragment's own image size against the header's.
    #[error("fragment {fragment}: the compressed image is {found}, but the header says {declared}")]
    FragmentSize {
        fragment: usize,
        found: String,
        declared: String,
    },
    /// Frame `frame`'s samples could not be stored, in the decoder's words.
    #[error("frame {frame}: {message}")]
    Frame { frame: usize, message: String },
    /// A state the code should never reach.
    #[error("internal: {0}")]
    Internal(&'static str),
}

/// What is wrong with a DICOM series as a whole (its files each read).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum SeriesProblem {
    /// None of `files` DICOM files holds an image; `names`: the first few.
    #[error("none of the {files} DICOM files holds an image ({names})")]
    NoImage { files: usize, names: String },
    /// `file` stores its pixels unlike the series' first file.
    #[error("{file} stores pixels differently from {first} (BitsAllocated/PixelRepresentation)")]
    MixedPixels { file: String, first: String },
    #[error("no series")]
    NoSeries,
    /// Entry `number` (from 1) of a list of `count` series.
    #[error("no series {number} in a list of {count}")]
    NotListed { number: usize, count: usize },
    /// The files given to load a listed series are not those that were listed.
    #[error("the {given} files given are not the {listed} files listed; list them again")]
    FilesChanged { given: usize, listed: usize },
    #[error("no image in this series")]
    NoImageInSeries,
    /// A state the code should never reach.
    #[error("internal: {0}")]
    Internal(&'static str),
}

/// What is wrong with a compressed stream ([`LoadError::Decompress`]).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum Corruption {
    #[error("the stream ends early (the file is truncated)")]
    Truncated,

    /// The decompressor refused the stream: bad codes, or a failed CRC-32 / Adler-32 check.
    #[error("the stream is corrupt")]
    Corrupt,

    #[error(
        "{compressed} compressed bytes declare {declared} bytes ({}:1); scans compress far less than {ratio}:1, so this is refused as a decompression bomb",
        declared / compressed.max(&1)
    )]
    Bomb {
        compressed: u64,
        declared: u64,
        ratio: u64,
    },

    #[error(
        "the stream holds more than the {declared} bytes its header declares (with {slack} bytes of slack)"
    )]
    LongerThanDeclared { declared: u64, slack: u64 },

    #[error(
        "the trailer says the data are {trailer} bytes (mod 2^32), more than the {max} the header allows: the file is corrupt or has bytes after its end (nothing was inflated)"
    )]
    TrailerTooLarge { trailer: u32, max: u64 },
}

impl LoadError {
    /// The `LoadError` an `io::Error` carries (a read of the file that failed inside a
    /// decompressor, which only passes `io::Error`s on), or the `io::Error` itself.
    pub(crate) fn carried_by(e: std::io::Error) -> Result<Self, std::io::Error> {
        if !e.get_ref().is_some_and(|inner| inner.is::<Self>()) {
            return Err(e);
        }
        let kind = e.kind();
        match e.into_inner().map(|inner| inner.downcast::<Self>()) {
            Some(Ok(load)) => Ok(*load),
            Some(Err(other)) => Err(std::io::Error::new(kind, other)),
            None => Err(std::io::Error::from(kind)),
        }
    }

    /// A compressed stream that cannot be inflated.
    pub(crate) fn decompress(
        file: &str,
        stream: impl Into<String>,
        problem: Corruption,
        source: Option<Box<dyn std::error::Error + Send + Sync>>,
    ) -> Self {
        Self::Decompress {
            file: file.to_owned(),
            stream: stream.into(),
            problem,
            source,
        }
    }

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
