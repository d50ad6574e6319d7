//! DICOMweb: finding a study in an archive (QIDO-RS) and retrieving a series (WADO-RS) into a
//! `Volume`. Everything here but `client` is pure and platform-neutral (bytes and strings in,
//! requests and typed results out), so the native client and the page's `fetch` share it:
//!
//! - this file: the archive's base URL, UIDs, credentials, the requests (URL, Accept,
//!   Authorization) and what an HTTP status means;
//! - `error`: [`DicomWebError`] and the retry policy (which failures pass, [`backoff`]);
//! - `qido`: the QIDO-RS JSON of studies, series and instances, and the series chooser;
//! - `listing`: a series' instance list checked against its count and completed from the
//!   series metadata or QIDO pages where the archive caps its answers;
//! - `multipart`: a push parser of WADO-RS `multipart/related; type="application/dicom"`
//!   bodies, fed in chunks as they arrive;
//! - `retrieve`: one series' retrieval as a state machine (which instance to ask for next,
//!   one retry of a failed instance, progress), decoding each instance as it arrives into
//!   [`crate::io::SeriesBuilder`], the file loader's own series code;
//! - `client` (native only): the blocking HTTP transport (ureq) behind the [`client::Transport`]
//!   trait and the driver that keeps several instance requests in flight;
//! - `web` (wasm only): the page's transport, the browser's `fetch` with streamed bodies,
//!   driving the same `Retrieval` from one async task;
//! - `stow`: results back into the archive (STOW-RS): the source series from its metadata, the
//!   Secondary Capture of a shape MIP rotation, the request body and the archive's answer;
//! - `sr`: a reading's measurements and findings as a DICOM Structured Report (TID 1500).

#[cfg(not(target_arch = "wasm32"))]
pub mod client;
mod error;
pub mod listing;
pub mod multipart;
pub mod qido;
pub mod retrieve;
mod search;
pub mod sr;
pub mod stow;
#[cfg(target_arch = "wasm32")]
pub mod web;

pub use listing::InstanceListing;
pub use multipart::{MultipartParser, Part};
pub use qido::{InstanceInfo, SeriesInfo, StudyInfo, choose_series, pet_series};

pub use retrieve::{Fetch, InstanceResponse, Progress, Retrieval};
pub use search::{SeriesSearch, StudySearch};

pub use error::{BUSY_ATTEMPTS, DicomWebError, MAX_RETRY_AFTER, backoff, max_attempts};

/// Largest QIDO-RS answer read, bytes.
pub const MAX_JSON_BYTES: u64 = 64 << 20;

/// Instance requests in flight at once by default (both transports).
pub const DEFAULT_PARALLEL: usize = 4;

/// The archive's DICOMweb root: absolute (`http://host:8042/dicom-web`) or, for a page served
/// by the archive itself, relative to the page's origin (`/dicom-web`). No trailing slash.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Base {
    url: String,
}

impl Base {
    pub fn parse(base: &str) -> Result<Self, DicomWebError> {
        let invalid = |reason: &str| DicomWebError::InvalidBase {
            base: base.to_owned(),
            reason: reason.to_owned(),
        };
        let s = base.trim();
        if s.is_empty() {
            return Err(invalid("empty"));
        }
        if s.len() > 2048 {
            return Err(invalid("longer than 2048 characters"));
        }
        if s.chars()
            .any(|c| c.is_whitespace() || c.is_control() || "?#\"<>\\{}|^`".contains(c))
        {
            return Err(invalid(
                "has a space, a control character, a query (?) or a fragment (#); give the archive's DICOMweb root, e.g. http://127.0.0.1:8042/dicom-web",
            ));
        }
        let lower = s.to_ascii_lowercase();
        let rest = if lower.starts_with("http://") {
            &s[7..]
        } else if lower.starts_with("https://") {
            &s[8..]
        } else if s.starts_with('/') && !s.starts_with("//") {
            return Ok(Self {
                url: s.trim_end_matches('/').to_owned(),
            });
        } else {
            return Err(invalid(
                "must start with http://, https:// or / (e.g. http://127.0.0.1:8042/dicom-web, or /dicom-web on the archive's own origin)",
            ));
        };
        let authority = rest.split('/').next().unwrap_or("");
        if authority.is_empty() {
            return Err(invalid("has no host"));
        }
        if authority.contains('@') {
            return Err(invalid(
                "holds credentials (user@host); give them as a token instead, so they stay out of URLs and messages",
            ));
        }
        Ok(Self {
            url: s.trim_end_matches('/').to_owned(),
        })
    }

    pub fn as_str(&self) -> &str {
        &self.url
    }

    /// Relative to the page's origin (`/dicom-web`): usable only from a page.
    pub fn is_relative(&self) -> bool {
        self.url.starts_with('/')
    }

    /// `host:port` of an absolute base, for messages.
    pub fn host(&self) -> Option<&str> {
        crate::io::url::host_part(&self.url)
    }

    /// `{base}/studies?StudyInstanceUID={study}`: the study's patient and date (an empty list
    /// when the archive does not hold it).
    pub fn study_query(&self, study: &str) -> Result<String, DicomWebError> {
        let study = check_uid("StudyInstanceUID", study)?;
        Ok(format!("{}/studies?StudyInstanceUID={study}", self.url))
    }

    /// `{base}/studies?PatientID=..&AccessionNumber=..&StudyDate=..&limit=N`: the studies
    /// that match every criterion given (none given: the archive's first studies).
    pub fn study_search(&self, search: &StudySearch) -> Result<String, DicomWebError> {
        let mut url = format!("{}/studies?", self.url);
        for (key, value) in search.criteria()? {
            url.push_str(key);
            url.push('=');
            url.push_str(&crate::io::url::percent_encode(&value, b"*"));
            url.push('&');
        }
        url.push_str(&format!("limit={}", StudySearch::LIMIT));
        if search.offset > 0 {
            url.push_str(&format!("&offset={}", search.offset));
        }
        Ok(url)
    }

    /// `{base}/studies/{study}/series`, asking for SliceThickness too where the archive has it.
    pub fn series_query(&self, study: &str) -> Result<String, DicomWebError> {
        let study = check_uid("StudyInstanceUID", study)?;
        Ok(format!(
            "{}/studies/{study}/series?includefield=00180050",
            self.url
        ))
    }

    /// `{base}/studies/{study}/series/{series}/instances`.
    pub fn instances_query(&self, study: &str, series: &str) -> Result<String, DicomWebError> {
        let study = check_uid("StudyInstanceUID", study)?;
        let series = check_uid("SeriesInstanceUID", series)?;
        Ok(format!(
            "{}/studies/{study}/series/{series}/instances",
            self.url
        ))
    }

    /// `{base}/studies/{study}/series/{series}`: WADO-RS retrieve of a whole series.
    pub fn series_url(&self, study: &str, series: &str) -> Result<String, DicomWebError> {
        let study = check_uid("StudyInstanceUID", study)?;
        let series = check_uid("SeriesInstanceUID", series)?;
        Ok(format!("{}/studies/{study}/series/{series}", self.url))
    }

    /// `{base}/studies/{study}/series/{series}/instances/{instance}` (WADO-RS).
    pub fn instance_url(
        &self,
        study: &str,
        series: &str,
        instance: &str,
    ) -> Result<String, DicomWebError> {
        let study = check_uid("StudyInstanceUID", study)?;
        let series = check_uid("SeriesInstanceUID", series)?;
        let instance = check_uid("SOPInstanceUID", instance)?;
        Ok(format!(
            "{}/studies/{study}/series/{series}/instances/{instance}",
            self.url
        ))
    }
}

/// A DICOMweb URL as viewers link it (VolView's `?dicomweb=`, a copied WADO-RS path): the root
/// with the study and series it points into, `.../studies/UID[/series/UID[/...]]` split into
/// (root, study, series). A URL that points into no study is the root as it is.
pub fn split_target(url: &str) -> (String, Option<String>, Option<String>) {
    let url = url.trim().trim_end_matches('/');
    let is_uid = |s: &str| check_uid("UID", s).is_ok();
    if let Some(i) = url.rfind("/studies/") {
        let (root, rest) = (&url[..i], &url[i + "/studies/".len()..]);
        let mut parts = rest.split('/');
        if let Some(study) = parts.next().filter(|s| is_uid(s)) {
            let series = match (parts.next(), parts.next()) {
                (Some("series"), Some(s)) if is_uid(s) => Some(s.to_owned()),
                _ => None,
            };
            return (root.to_owned(), Some(study.to_owned()), series);
        }
    }
    (url.to_owned(), None, None)
}

/// The series of `list` to open: the one named, else the chooser's (`qido::choose_series`);
/// and whether the chooser picked it.
pub fn pick_series(
    base: &Base,
    study: &str,
    list: &[SeriesInfo],
    series: Option<&str>,
) -> Result<(usize, bool), DicomWebError> {
    match series {
        Some(uid) => {
            let uid = check_uid("SeriesInstanceUID", uid)?;
            let i = list
                .iter()
                .position(|s| s.series_uid == uid)
                .ok_or_else(|| DicomWebError::SeriesNotInStudy {
                    study: study.to_owned(),
                    series: uid.to_owned(),
                    available: list
                        .iter()
                        .map(|s| s.series_uid.as_str())
                        .collect::<Vec<_>>()
                        .join(", "),
                })?;
            Ok((i, false))
        }
        None => Ok((
            choose_series(list).ok_or_else(|| DicomWebError::NotFound {
                what: format!("a series of study {study}"),
                url: base.series_query(study).unwrap_or_default(),
            })?,
            true,
        )),
    }
}

/// Checks that a UID is digits and dots (1 to 64 characters), so that it can go into a URL
/// path as it is; a UID from the user or from an archive's answer is never trusted.
pub fn check_uid<'a>(what: &str, uid: &'a str) -> Result<&'a str, DicomWebError> {
    let u = uid.trim_end_matches(['\0', ' ']);
    if u.is_empty()
        || u.len() > 64
        || !u.bytes().all(|b| b.is_ascii_digit() || b == b'.')
        || u.starts_with('.')
        || u.ends_with('.')
        || u.contains("..")
    {
        return Err(DicomWebError::InvalidUid {
            what: what.to_owned(),
            uid: uid.chars().take(80).collect(),
        });
    }
    Ok(u)
}

/// Credentials for the archive. `Debug` never shows them.
#[derive(Clone, Default, PartialEq, Eq)]
pub enum Auth {
    #[default]
    None,
    /// `Authorization: Bearer <token>` (OAuth, cloud archives, a proxy in front of a PACS).
    Bearer(String),
    /// `Authorization: Basic` (Orthanc's RegisteredUsers, many plain archives).
    Basic { user: String, password: String },
}

impl std::fmt::Debug for Auth {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::None => "Auth::None",
            Self::Bearer(_) => "Auth::Bearer(..)",
            Self::Basic { .. } => "Auth::Basic(..)",
        })
    }
}

impl Auth {
    /// A bearer token; refused if it holds characters that cannot go into a header.
    pub fn bearer(token: &str) -> Result<Self, DicomWebError> {
        let t = token.trim();
        if t.is_empty() {
            return Err(DicomWebError::InvalidAuth("the token is empty".to_owned()));
        }
        if !t.chars().all(|c| c.is_ascii_graphic()) {
            return Err(DicomWebError::InvalidAuth(
                "the token holds spaces, control or non-ASCII characters".to_owned(),
            ));
        }
        Ok(Self::Bearer(t.to_owned()))
    }

    /// `user:password` for HTTP Basic authentication.
    pub fn basic(user_password: &str) -> Result<Self, DicomWebError> {
        let (user, password) = user_password
            .split_once(':')
            .ok_or_else(|| DicomWebError::InvalidAuth("expected user:password".to_owned()))?;
        if user.is_empty() || user_password.chars().any(|c| c.is_control()) {
            return Err(DicomWebError::InvalidAuth(
                "expected user:password with a non-empty user and no control characters".to_owned(),
            ));
        }
        Ok(Self::Basic {
            user: user.to_owned(),
            password: password.to_owned(),
        })
    }

    /// The Authorization header's value, if any.
    pub fn header(&self) -> Option<String> {
        match self {
            Self::None => None,
            Self::Bearer(t) => Some(format!("Bearer {t}")),
            Self::Basic { user, password } => Some(format!(
                "Basic {}",
                base64(format!("{user}:{password}").as_bytes())
            )),
        }
    }

    /// What was sent, for messages (never the secret itself).
    pub fn describe(&self) -> Option<&'static str> {
        match self {
            Self::None => None,
            Self::Bearer(_) => Some("bearer token"),
            Self::Basic { .. } => Some("user name and password"),
        }
    }
}

/// Standard base64 with padding (RFC 4648), for Basic authentication.
fn base64(bytes: &[u8]) -> String {
    const ALPHABET: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::with_capacity(bytes.len().div_ceil(3) * 4);
    for chunk in bytes.chunks(3) {
        let b = [
            chunk[0],
            chunk.get(1).copied().unwrap_or(0),
            chunk.get(2).copied().unwrap_or(0),
        ];
        let n = (u32::from(b[0]) << 16) | (u32::from(b[1]) << 8) | u32::from(b[2]);
        for i in 0..4 {
            if i <= chunk.len() {
                out.push(char::from(ALPHABET[((n >> (18 - 6 * i)) & 63) as usize]));
            } else {
                out.push('=');
            }
        }
    }
    out
}

/// One GET the client makes: its URL and headers.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Request {
    pub url: String,
    /// Header names and values; the Authorization value is a secret (never logged).
    pub headers: Vec<(&'static str, String)>,
}

impl Request {
    /// A QIDO-RS query (JSON).
    pub fn qido(url: String, auth: &Auth) -> Self {
        Self::with_accept(url, "application/dicom+json".to_owned(), auth)
    }

    /// A WADO-RS retrieval of DICOM instances in the transfer syntaxes this build decodes.
    pub fn wado(url: String, auth: &Auth) -> Self {
        Self::with_accept(url, wado_accept(), auth)
    }

    fn with_accept(url: String, accept: String, auth: &Auth) -> Self {
        let mut headers = vec![("Accept", accept)];
        if let Some(a) = auth.header() {
            headers.push(("Authorization", a));
        }
        Self { url, headers }
    }
}

/// The Accept header of WADO-RS retrievals: one `multipart/related; type="application/dicom"`
/// media range per transfer syntax this build decodes. Explicit VR little endian has the
/// highest quality and comes last: archives that follow RFC 9110 choose by quality (lossless
/// compressed next, lossy, which an archive only sends as it stored it, last), and some
/// (Orthanc's DICOMweb plugin 1.7) take the last range given.
pub fn wado_accept() -> String {
    let range = |uid: &str, q: Option<&str>| {
        let mut s = format!("multipart/related; type=\"application/dicom\"; transfer-syntax={uid}");
        if let Some(q) = q {
            s.push_str("; q=");
            s.push_str(q);
        }
        s
    };
    let syntaxes = crate::io::decodable_transfer_syntaxes();
    let mut ranges: Vec<String> = syntaxes
        .iter()
        .filter(|(uid, _)| *uid != EXPLICIT_LE)
        .map(|(uid, lossless)| range(uid, Some(if *lossless { "0.9" } else { "0.5" })))
        .collect();
    ranges.push(range(EXPLICIT_LE, None));
    ranges.join(", ")
}

/// The transfer syntaxes asked for, for messages.
pub fn asked_syntaxes() -> String {
    crate::io::decodable_transfer_syntaxes()
        .iter()
        .map(|(uid, _)| *uid)
        .collect::<Vec<_>>()
        .join(", ")
}

const EXPLICIT_LE: &str = "1.2.840.10008.1.2.1";

/// What an HTTP status means for a request of `what` (e.g. "study 1.2.3"): `Ok` for 2xx.
pub fn check_status(status: u16, url: &str, what: &str, auth: &Auth) -> Result<(), DicomWebError> {
    match status {
        200..=299 => Ok(()),
        401 | 403 => Err(DicomWebError::Unauthorized {
            status,
            url: url.to_owned(),
            credentials: auth.describe(),
        }),
        404 => Err(DicomWebError::NotFound {
            what: what.to_owned(),
            url: url.to_owned(),
        }),
        429 | 503 => Err(DicomWebError::Busy {
            url: url.to_owned(),
            status,
            retry_after_s: None,
        }),
        406 => Err(DicomWebError::NotAcceptable {
            url: url.to_owned(),
            asked: asked_syntaxes(),
        }),
        _ => Err(DicomWebError::Http {
            url: url.to_owned(),
            status,
            reason: reason_phrase(status).to_owned(),
        }),
    }
}

fn reason_phrase(status: u16) -> &'static str {
    match status {
        400 => "Bad Request",
        405 => "Method Not Allowed",
        408 => "Request Timeout",
        410 => "Gone",
        413 => "Content Too Large",
        415 => "Unsupported Media Type",
        429 => "Too Many Requests",
        500 => "Internal Server Error",
        501 => "Not Implemented",
        502 => "Bad Gateway",
        503 => "Service Unavailable",
        504 => "Gateway Timeout",
        300..=399 => "(a redirect that was not followed)",
        _ => "",
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // a failed unwrap is a failed test
mod tests;
