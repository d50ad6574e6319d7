//! One series' WADO-RS retrieval as a state machine, free of I/O so that the native client's
//! threads and the page's `fetch` drive the same logic: [`Retrieval::next`] says which
//! instance to ask for, [`InstanceResponse`] turns one answer (status, Content-Type, body
//! chunks) into its DICOM parts, [`Retrieval::received`] decodes them into the series as they
//! arrive, [`Retrieval::failed`] asks again once for an instance whose request failed in a way
//! that may pass (a dropped connection, a body cut short, a busy server), and
//! [`Retrieval::finish`] gives the volume.
//!
//! With [`Retrieval::series_first`] the whole series is asked for in one request first
//! (WADO-RS `.../studies/UID/series/UID`): its parts are decoded as they stream in
//! ([`Retrieval::received_part`], each matched to its instance by the SOPInstanceUID of its file
//! meta group), and whatever it did not bring (an archive that refuses series retrieves, an
//! answer cut short, a part that names no listed instance) is then asked for instance by
//! instance. One request instead of one per instance: in the page each request costs the one
//! thread tens of milliseconds of its own.

use std::collections::{HashMap, VecDeque};

use super::multipart::{MultipartLimits, MultipartParser, Part};
use super::qido::InstanceInfo;
use super::{Auth, Base, DicomWebError, Request, check_status, check_uid};
use crate::io::{InputFile, Limits, Loaded, SeriesBuilder};

/// Attempts per instance: the first and one retry (an archive that answers busy gets
/// [`super::BUSY_ATTEMPTS`], each after the wait it asked for).
pub const MAX_ATTEMPTS: u32 = 2;

/// The [`Fetch::id`] of the request for the whole series ([`Retrieval::series_first`]).
pub const SERIES_FETCH: usize = usize::MAX;

/// Where the request for the whole series is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum SeriesRequest {
    /// Not to be made (instance by instance only), or made and ended.
    NotAsked,
    /// To be made before any instance is asked for.
    Waiting,
    /// Made; instance requests wait until it ends.
    InFlight,
}

/// One request to make: `id` goes back with its answer.
#[derive(Clone, Debug)]
pub struct Fetch {
    pub id: usize,
    pub request: Request,
    /// "instance 3 of 30 (1.2.3...)" or "series 1.2.3... (30 instances)", for messages.
    pub label: String,
    /// Wait this long before asking (a retry's backoff; zero the first time).
    pub delay: std::time::Duration,
}

/// How far a retrieval has come.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Progress {
    pub instances_done: usize,
    pub instances_total: usize,
    /// Bytes of DICOM received.
    pub bytes: u64,
    /// The total bytes expected, estimated from the instances received so far.
    pub bytes_estimate: Option<u64>,
}

/// The retrieval of one series (see the module documentation).
pub struct Retrieval {
    base: Base,
    study: String,
    series: String,
    auth: Auth,
    instances: Vec<InstanceInfo>,
    queue: VecDeque<usize>,
    attempts: Vec<u32>,
    /// The backoff before each instance's next attempt.
    delays: Vec<std::time::Duration>,
    done: Vec<bool>,
    done_count: usize,
    bytes: u64,
    builder: SeriesBuilder,
    multipart: MultipartLimits,
    series_request: SeriesRequest,
    /// Requests for the whole series made, and the wait before the next (a busy archive's).
    series_attempts: u32,
    series_delay: std::time::Duration,
    /// Instance index by SOPInstanceUID (the parts of the series' answer).
    by_uid: HashMap<String, usize>,
}

impl Retrieval {
    /// A retrieval of the listed instances of one series.
    pub fn new(
        base: Base,
        study: &str,
        series: &str,
        instances: Vec<InstanceInfo>,
        auth: Auth,
        limits: Limits,
    ) -> Result<Self, DicomWebError> {
        let study = check_uid("StudyInstanceUID", study)?.to_owned();
        let series = check_uid("SeriesInstanceUID", series)?.to_owned();
        if instances.is_empty() {
            return Err(DicomWebError::NoInstances { study, series });
        }
        for i in &instances {
            check_uid("SOPInstanceUID", &i.sop_uid)?;
        }
        let n = instances.len();
        let mut builder = SeriesBuilder::new(limits);
        builder.expect_images(n);
        Ok(Self {
            base,
            study,
            series,
            auth,
            instances,
            queue: (0..n).collect(),
            attempts: vec![0; n],
            delays: vec![std::time::Duration::ZERO; n],
            done: vec![false; n],
            done_count: 0,
            bytes: 0,
            builder,
            multipart: MultipartLimits {
                max_part_bytes: limits.max_voxel_bytes.saturating_add(64 << 20),
                ..MultipartLimits::default()
            },
            series_request: SeriesRequest::NotAsked,
            series_attempts: 0,
            series_delay: std::time::Duration::ZERO,
            by_uid: HashMap::new(),
        })
    }

    /// Asks for the whole series in one request before any instance (see the module's
    /// documentation); the instances it does not bring are asked for one by one after it.
    pub fn series_first(mut self) -> Self {
        self.series_request = SeriesRequest::Waiting;
        self.by_uid = self
            .instances
            .iter()
            .enumerate()
            .map(|(k, i)| (i.sop_uid.clone(), k))
            .collect();
        self
    }

    /// The caps a response's multipart parser gets.
    pub fn multipart_limits(&self) -> MultipartLimits {
        self.multipart
    }

    pub fn auth(&self) -> &Auth {
        &self.auth
    }

    fn label(&self, id: usize) -> String {
        if id >= self.instances.len() {
            return format!(
                "series {} ({} instances)",
                self.series,
                self.instances.len()
            );
        }
        format!(
            "instance {} of {} ({})",
            id + 1,
            self.instances.len(),
            self.instances[id].sop_uid
        )
    }

    /// The next request to make: the whole series first ([`Self::series_first`]), then the
    /// instances waiting (first attempts, then retries).
    pub fn next_fetch(&mut self) -> Option<Fetch> {
        match self.series_request {
            SeriesRequest::Waiting => {
                self.series_request = SeriesRequest::InFlight;
                self.series_attempts += 1;
                // Every UID was checked when this retrieval was made.
                let url = self
                    .base
                    .series_url(&self.study, &self.series)
                    .unwrap_or_default();
                return Some(Fetch {
                    id: SERIES_FETCH,
                    request: Request::wado(url, &self.auth),
                    label: self.label(SERIES_FETCH),
                    delay: self.series_delay,
                });
            }
            SeriesRequest::InFlight => return None,
            SeriesRequest::NotAsked => {}
        }
        // Instances the series' answer brought are not asked for again.
        let id = loop {
            let id = self.queue.pop_front()?;
            if !self.done[id] {
                break id;
            }
        };
        self.attempts[id] += 1;
        let label = self.label(id);
        // Every UID was checked when this retrieval was made, so the URL is well formed.
        let url = self
            .base
            .instance_url(&self.study, &self.series, &self.instances[id].sop_uid)
            .unwrap_or_default();
        Some(Fetch {
            id,
            request: Request::wado(url, &self.auth),
            label,
            delay: self.delays[id],
        })
    }

    /// One part of the series' answer arrived ([`Self::series_first`]): decoded now into the
    /// series when it is a listed instance not yet received; otherwise let go (the instance is
    /// asked for on its own once the series' answer ends).
    pub fn received_part(&mut self, part: Part) -> Result<(), DicomWebError> {
        let Some(id) = part_sop_uid(&part.bytes).and_then(|uid| self.by_uid.get(&uid).copied())
        else {
            log::warn!(
                "{}: part {} names no listed instance; let go",
                self.label(SERIES_FETCH),
                part.index
            );
            return Ok(());
        };
        if self.done[id] {
            return Ok(());
        }
        self.attempts[id] += 1;
        self.received(id, vec![part])
    }

    /// The series' answer ended ([`Self::series_first`]): the instances it did not bring are
    /// asked for one by one.
    fn series_ended(&mut self) {
        self.series_request = SeriesRequest::NotAsked;
        let missing = self.instances.len() - self.done_count;
        if missing > 0 {
            log::info!(
                "{}: {missing} instances to ask for one by one",
                self.label(SERIES_FETCH)
            );
        }
    }

    /// An instance's parts arrived: each is decoded into the series now. For the series'
    /// request ([`SERIES_FETCH`]) the parts not yet given to [`Self::received_part`], and its
    /// end.
    pub fn received(&mut self, id: usize, parts: Vec<Part>) -> Result<(), DicomWebError> {
        if id == SERIES_FETCH {
            for part in parts {
                self.received_part(part)?;
            }
            self.series_ended();
            return Ok(());
        }
        if id >= self.done.len() || self.done[id] {
            return Ok(());
        }
        let label = self.label(id);
        if parts.is_empty() {
            return Err(DicomWebError::Multipart {
                what: label,
                message: "the body holds no part".to_owned(),
            });
        }
        let many = parts.len() > 1;
        for part in parts {
            self.bytes += part.bytes.len() as u64;
            let name = if many {
                format!("{}#{}", self.instances[id].sop_uid, part.index)
            } else {
                self.instances[id].sop_uid.clone()
            };
            self.builder
                .push(InputFile::new(name, part.bytes))
                .map_err(|source| DicomWebError::Load {
                    instance: label.clone(),
                    source: Box::new(source),
                })?;
        }
        self.done[id] = true;
        self.done_count += 1;
        Ok(())
    }

    /// An instance's request failed: it is asked for again once if the failure may pass,
    /// otherwise (or the second time) the retrieval fails with an error naming it.
    pub fn failed(&mut self, id: usize, error: DicomWebError) -> Result<(), DicomWebError> {
        if id == SERIES_FETCH {
            // Credentials refused (401) are refused for the instances too. A busy archive is
            // asked again after the wait it asks for, once. Anything else (an archive without
            // series retrieves, a gateway forbidding them with 403, an answer cut short)
            // leaves the rest to the instances, each with its own answer.
            if matches!(error, DicomWebError::Unauthorized { status: 401, .. }) {
                return Err(error);
            }
            if matches!(error, DicomWebError::Busy { .. }) && self.series_attempts < 2 {
                self.series_delay = super::backoff(self.series_attempts, &error);
                log::warn!(
                    "{}: {}; asking again in {:.1} s",
                    self.label(SERIES_FETCH),
                    crate::error::chain(&error),
                    self.series_delay.as_secs_f64()
                );
                self.series_request = SeriesRequest::Waiting;
                return Ok(());
            }
            log::warn!(
                "{}: {}; asking instance by instance",
                self.label(SERIES_FETCH),
                crate::error::chain(&error)
            );
            self.series_ended();
            return Ok(());
        }
        if id >= self.done.len() || self.done[id] {
            return Ok(());
        }
        let label = self.label(id);
        if !error.is_retryable() {
            return Err(match error {
                // Already specific; the instance adds nothing to "asks for credentials".
                e @ (DicomWebError::Unauthorized { .. } | DicomWebError::Load { .. }) => e,
                other => DicomWebError::Failed {
                    instance: label,
                    attempts: self.attempts[id],
                    source: Box::new(other),
                },
            });
        }
        if self.attempts[id] >= super::max_attempts(&error) {
            return Err(DicomWebError::Failed {
                instance: label,
                attempts: self.attempts[id],
                source: Box::new(error),
            });
        }
        self.delays[id] = super::backoff(self.attempts[id], &error);
        log::warn!(
            "{label}: {}; asking again in {:.1} s",
            crate::error::chain(&error),
            self.delays[id].as_secs_f64()
        );
        self.queue.push_back(id);
        Ok(())
    }

    pub fn is_complete(&self) -> bool {
        self.done_count == self.instances.len()
    }

    pub fn progress(&self) -> Progress {
        Progress {
            instances_done: self.done_count,
            instances_total: self.instances.len(),
            bytes: self.bytes,
            bytes_estimate: (self.done_count > 0).then(|| {
                (self.bytes as f64 / self.done_count as f64 * self.instances.len() as f64) as u64
            }),
        }
    }

    /// The volume, once every instance has arrived.
    pub fn finish(self) -> Result<Loaded, DicomWebError> {
        if !self.is_complete() {
            let missing = self.done.iter().position(|d| !d).unwrap_or(0);
            return Err(DicomWebError::Failed {
                instance: self.label(missing),
                attempts: self.attempts[missing],
                source: Box::new(DicomWebError::Cancelled),
            });
        }
        let n = self.instances.len();
        let what = format!("series {}", self.series);
        let mut loaded = self
            .builder
            .finish()
            .map_err(|source| DicomWebError::Load {
                instance: what,
                source: Box::new(source),
            })?;
        loaded.volume.source = format!(
            "DICOMweb {} series {} ({n} instance{})",
            self.base.as_str(),
            self.series,
            if n == 1 { "" } else { "s" }
        );
        Ok(loaded)
    }
}

/// The SOPInstanceUID of a Part 10 file, from its file meta group (MediaStorageSOPInstanceUID,
/// (0002,0003), explicit VR little endian as PS3.10 requires), without parsing the data set.
pub fn part_sop_uid(bytes: &[u8]) -> Option<String> {
    if bytes.get(128..132)? != b"DICM" {
        return None;
    }
    let mut at = 132;
    loop {
        let head = bytes.get(at..at + 8)?;
        let group = u16::from_le_bytes([head[0], head[1]]);
        let element = u16::from_le_bytes([head[2], head[3]]);
        if group != 0x0002 {
            return None;
        }
        let vr = &head[4..6];
        // OB, OW, OF, SQ, UT, UN and the like have a 4-byte length after 2 reserved bytes.
        let (len, value_at) = if matches!(
            vr,
            b"OB"
                | b"OD"
                | b"OF"
                | b"OL"
                | b"OV"
                | b"OW"
                | b"SQ"
                | b"SV"
                | b"UC"
                | b"UN"
                | b"UR"
                | b"UT"
                | b"UV"
        ) {
            let l = bytes.get(at + 8..at + 12)?;
            (
                u32::from_le_bytes([l[0], l[1], l[2], l[3]]) as usize,
                at + 12,
            )
        } else {
            (usize::from(u16::from_le_bytes([head[6], head[7]])), at + 8)
        };
        let value = bytes.get(value_at..value_at.checked_add(len)?)?;
        if element == 0x0003 {
            let uid = String::from_utf8_lossy(value);
            let uid = uid.trim_end_matches(['\0', ' ']);
            return (!uid.is_empty()).then(|| uid.to_owned());
        }
        at = value_at + len;
    }
}

/// One instance's answer being read: the status is checked first, then the body is fed in
/// chunks to a multipart parser, and `finish` gives its parts.
pub struct InstanceResponse {
    parser: MultipartParser,
    parts: Vec<Part>,
}

impl InstanceResponse {
    pub fn start(
        fetch: &Fetch,
        status: u16,
        content_type: Option<&str>,
        auth: &Auth,
        limits: MultipartLimits,
    ) -> Result<Self, DicomWebError> {
        check_status(status, &fetch.request.url, &fetch.label, auth)?;
        Ok(Self {
            parser: MultipartParser::new(content_type, &fetch.label, limits)?,
            parts: Vec::new(),
        })
    }

    pub fn feed(&mut self, chunk: &[u8]) -> Result<(), DicomWebError> {
        let parts = &mut self.parts;
        self.parser.feed(chunk, &mut |p| {
            parts.push(p);
            Ok(())
        })
    }

    /// Feeds a chunk, handing each part that completes to `each` at once (the series' answer:
    /// its parts are decoded while the rest streams in) instead of keeping it for `finish`.
    pub fn feed_each(
        &mut self,
        chunk: &[u8],
        each: &mut dyn FnMut(Part) -> Result<(), DicomWebError>,
    ) -> Result<(), DicomWebError> {
        self.parser.feed(chunk, each)
    }

    pub fn finish(mut self) -> Result<Vec<Part>, DicomWebError> {
        let parts = &mut self.parts;
        self.parser.finish(&mut |p| {
            parts.push(p);
            Ok(())
        })?;
        Ok(self.parts)
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // a failed unwrap is a failed test
mod tests;
