//! Why a DICOMweb request failed ([`DicomWebError`]), and what to do about a failure that may
//! pass: whether to ask again, how many times, and after how long ([`backoff`]).

use super::retrieve;
use crate::io::LoadError;

/// Why a DICOMweb request or retrieval failed; each message names the URL, host or instance.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum DicomWebError {
    #[error("DICOMweb base URL {base:?}: {reason}")]
    InvalidBase { base: String, reason: String },

    #[error("{what} {uid:?} is not a DICOM UID (digits and dots, at most 64 characters)")]
    InvalidUid { what: String, uid: String },

    #[error("credentials: {0}")]
    InvalidAuth(String),

    #[error("CA certificates: {0}")]
    InvalidCa(String),

    #[error("study search: {field} {value:?}: {reason}")]
    InvalidSearch {
        field: &'static str,
        value: String,
        reason: &'static str,
    },

    #[error("{}", unauthorized_message(*status, url, *credentials))]
    Unauthorized {
        status: u16,
        url: String,
        /// What was sent: `None`, or a description of the credentials.
        credentials: Option<&'static str>,
    },

    #[error("{what} not found ({url})")]
    NotFound { what: String, url: String },

    #[error(
        "{url}: HTTP 406: the archive cannot send any transfer syntax this build decodes (asked for {asked})"
    )]
    NotAcceptable { url: String, asked: String },

    #[error("{url}: HTTP {status} {reason}")]
    Http {
        url: String,
        status: u16,
        reason: String,
    },

    #[error("{url}: HTTP {status}: the archive is busy{}", match retry_after_s {
        Some(s) => format!(" (it asked to wait {s} s)"),
        None => String::new(),
    })]
    Busy {
        url: String,
        /// 429 Too Many Requests or 503 Service Unavailable.
        status: u16,
        /// The answer's Retry-After, in seconds.
        retry_after_s: Option<u64>,
    },

    #[error(
        "cannot connect to {host}: {message} (is the archive running there, and is the base URL right?)"
    )]
    Connect { host: String, message: String },

    /// The request or its answer broke off; `message` says where, `source` (natively) why.
    #[error("{url}: {message}")]
    Transport {
        url: String,
        message: String,
        #[source]
        source: Option<Box<dyn std::error::Error + Send + Sync>>,
    },

    #[error("{url}: the answer is not QIDO-RS JSON: {message}")]
    Json { url: String, message: String },

    #[error("{what}: multipart body: {message}")]
    Multipart { what: String, message: String },

    #[error("{what}: {size} bytes is more than the limit of {limit} bytes")]
    TooLarge { what: String, size: u64, limit: u64 },

    #[error("series {series} of study {study}: the archive lists no instances")]
    NoInstances { study: String, series: String },

    #[error("study {study} has no series {series} (it has: {available})")]
    SeriesNotInStudy {
        study: String,
        series: String,
        available: String,
    },

    #[error("{instance}")]
    Load {
        instance: String,
        #[source]
        source: Box<LoadError>,
    },

    #[error("{instance} failed {attempts} times; the last time")]
    Failed {
        instance: String,
        attempts: u32,
        #[source]
        source: Box<DicomWebError>,
    },

    #[error(
        "series {series} of study {study}: the archive listed {listed} of its {expected} instances{}; not opened in part",
        also_tried(tried)
    )]
    Incomplete {
        study: String,
        series: String,
        listed: usize,
        /// NumberOfSeriesRelatedInstances.
        expected: u64,
        /// What else was asked, and what it answered.
        tried: String,
    },

    #[error("the retrieval was cancelled")]
    Cancelled,

    #[error("{what}: cannot be written as DICOM: {message}")]
    Encode { what: String, message: String },

    #[error("{url}: HTTP {status}: the archive refused to store {refused}")]
    StoreRefused {
        url: String,
        status: u16,
        /// The instances refused, with the archive's reasons.
        refused: String,
    },
}

fn also_tried(tried: &str) -> String {
    if tried.is_empty() {
        String::new()
    } else {
        format!(" (its answers are capped; also asked: {tried})")
    }
}

fn unauthorized_message(status: u16, url: &str, credentials: Option<&str>) -> String {
    let what = if status == 403 {
        "403 Forbidden"
    } else {
        "401 Unauthorized"
    };
    match credentials {
        None => format!(
            "{url}: HTTP {what}: the archive asks for credentials; give a bearer token (or, for an archive with HTTP Basic authentication such as Orthanc, a user name and password)"
        ),
        Some(c) => format!(
            "{url}: HTTP {what}: the archive did not accept the {c} given; give a valid token (or user name and password)"
        ),
    }
}

impl DicomWebError {
    /// Whether trying the same request again may help (a dropped connection, a body cut short,
    /// a busy server), as opposed to an answer that will not change (401, 404, 406, bad data).
    pub fn is_retryable(&self) -> bool {
        match self {
            Self::Transport { .. }
            | Self::Multipart { .. }
            | Self::Connect { .. }
            | Self::Busy { .. } => true,
            Self::Http { status, .. } => *status >= 500 || *status == 408 || *status == 429,
            _ => false,
        }
    }

    /// A busy answer with the answer's `Retry-After` header (seconds; an HTTP date is not
    /// read and leaves the default backoff).
    pub fn with_retry_after(self, header: Option<&str>) -> Self {
        match self {
            Self::Busy {
                url,
                status,
                retry_after_s: None,
            } => Self::Busy {
                url,
                status,
                retry_after_s: header.and_then(|h| h.trim().parse::<u64>().ok()),
            },
            other => other,
        }
    }
}

/// The longest wait a Retry-After is honoured for: an archive asking for more is asked again
/// after this (and the request fails if it is still busy then).
pub const MAX_RETRY_AFTER: std::time::Duration = std::time::Duration::from_secs(120);

/// How long to wait before attempt `attempt + 1` of a request that failed with `error`: the
/// archive's Retry-After where it gave one (at most [`MAX_RETRY_AFTER`]), else 0.5 s doubling
/// per attempt up to 8 s.
pub fn backoff(attempt: u32, error: &DicomWebError) -> std::time::Duration {
    use std::time::Duration;
    if let DicomWebError::Busy {
        retry_after_s: Some(s),
        ..
    } = error
    {
        return Duration::from_secs(*s).min(MAX_RETRY_AFTER);
    }
    let doublings = attempt.saturating_sub(1).min(4);
    Duration::from_millis(500 << doublings)
}

/// Attempts of a request the archive answered busy (429, 503): the first and three more.
pub const BUSY_ATTEMPTS: u32 = 4;

/// Attempts of a request that failed with `e` (a retryable failure): two, more for a busy
/// archive.
pub fn max_attempts(e: &DicomWebError) -> u32 {
    if matches!(e, DicomWebError::Busy { .. }) {
        BUSY_ATTEMPTS
    } else {
        retrieve::MAX_ATTEMPTS
    }
}
