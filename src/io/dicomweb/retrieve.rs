//! One series' WADO-RS retrieval as a state machine, free of I/O so that the native client's
//! threads and the page's `fetch` drive the same logic: [`Retrieval::next`] says which
//! instance to ask for, [`InstanceResponse`] turns one answer (status, Content-Type, body
//! chunks) into its DICOM parts, [`Retrieval::received`] decodes them into the series as they
//! arrive, [`Retrieval::failed`] asks again once for an instance whose request failed in a way
//! that may pass (a dropped connection, a body cut short, a busy server), and
//! [`Retrieval::finish`] gives the volume.

use std::collections::VecDeque;

use super::multipart::{MultipartLimits, MultipartParser, Part};
use super::qido::InstanceInfo;
use super::{Auth, Base, DicomWebError, Request, check_status, check_uid};
use crate::io::{InputFile, Limits, Loaded, SeriesBuilder};

/// Attempts per instance: the first and one retry (an archive that answers busy gets
/// [`super::BUSY_ATTEMPTS`], each after the wait it asked for).
pub const MAX_ATTEMPTS: u32 = 2;

/// One request to make: `id` goes back with its answer.
#[derive(Clone, Debug)]
pub struct Fetch {
    pub id: usize,
    pub request: Request,
    /// "instance 3 of 30 (1.2.3...)", for messages.
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
        })
    }

    /// The caps a response's multipart parser gets.
    pub fn multipart_limits(&self) -> MultipartLimits {
        self.multipart
    }

    pub fn auth(&self) -> &Auth {
        &self.auth
    }

    fn label(&self, id: usize) -> String {
        format!(
            "instance {} of {} ({})",
            id + 1,
            self.instances.len(),
            self.instances[id].sop_uid
        )
    }

    /// The next instance to ask for, if any is waiting (first attempts, then retries).
    pub fn next_fetch(&mut self) -> Option<Fetch> {
        let id = self.queue.pop_front()?;
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

    /// An instance's parts arrived: each is decoded into the series now.
    pub fn received(&mut self, id: usize, parts: Vec<Part>) -> Result<(), DicomWebError> {
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
                    source,
                })?;
        }
        self.done[id] = true;
        self.done_count += 1;
        Ok(())
    }

    /// An instance's request failed: it is asked for again once if the failure may pass,
    /// otherwise (or the second time) the retrieval fails with an error naming it.
    pub fn failed(&mut self, id: usize, error: DicomWebError) -> Result<(), DicomWebError> {
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
            "{label}: {error}; asking again in {:.1} s",
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
                source,
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
mod tests {
    use super::*;
    use crate::io::dicom::synth::Slice;

    const SERIES: &str = "1.2.826.0.1.3680043.10.7";

    fn instances(n: i32) -> Vec<InstanceInfo> {
        (0..n)
            .map(|k| InstanceInfo {
                sop_uid: format!("{SERIES}.{k}"),
                ..InstanceInfo::default()
            })
            .collect()
    }

    fn retrieval(n: i32) -> Retrieval {
        Retrieval::new(
            Base::parse("http://127.0.0.1:1/dicom-web").unwrap(),
            "1.2.3",
            SERIES,
            instances(n),
            Auth::None,
            Limits::default(),
        )
        .unwrap()
    }

    fn part(bytes: Vec<u8>) -> Part {
        Part {
            index: 1,
            content_type: None,
            transfer_syntax: None,
            content_location: None,
            bytes,
        }
    }

    #[test]
    fn instances_arrive_in_any_order_and_one_failure_is_retried() {
        let n = 4;
        let mut r = retrieval(n);
        let mut fetches: Vec<Fetch> = std::iter::from_fn(|| r.next_fetch()).collect();
        assert_eq!(fetches.len(), 4);
        assert!(
            fetches[2]
                .request
                .url
                .ends_with(&format!("/series/{SERIES}/instances/{SERIES}.2"))
        );
        assert!(fetches[2].label.starts_with("instance 3 of 4"));
        fetches.reverse();
        for f in &fetches {
            if f.id == 1 {
                let cut = DicomWebError::Multipart {
                    what: f.label.clone(),
                    message: "part 1 was cut short".to_owned(),
                };
                r.failed(f.id, cut).unwrap();
            } else {
                let s = Slice::axial(SERIES, f.id as i32, 2, 3);
                r.received(f.id, vec![part(s.bytes())]).unwrap();
            }
        }
        assert!(!r.is_complete());
        assert_eq!(r.progress().instances_done, 3);
        let again = r.next_fetch().unwrap();
        assert_eq!(again.id, 1);
        assert!(r.next_fetch().is_none());
        r.received(1, vec![part(Slice::axial(SERIES, 1, 2, 3).bytes())])
            .unwrap();
        assert!(r.is_complete());
        let p = r.progress();
        assert_eq!((p.instances_done, p.instances_total), (4, 4));
        assert_eq!(p.bytes_estimate, Some(p.bytes));
        let loaded = r.finish().unwrap();
        assert_eq!(loaded.volume.dims, [3, 2, 4]);
        assert_eq!(loaded.volume.value_at(0, 0, 1), 100.0 - 1024.0);
        assert!(
            loaded
                .volume
                .source
                .starts_with("DICOMweb http://127.0.0.1:1/dicom-web series")
        );
    }

    #[test]
    fn a_second_failure_or_a_final_answer_ends_the_retrieval() {
        let mut r = retrieval(2);
        let f = r.next_fetch().unwrap();
        let busy = || DicomWebError::Http {
            url: "u".to_owned(),
            status: 503,
            reason: "Service Unavailable".to_owned(),
        };
        r.failed(f.id, busy()).unwrap();
        let _second = r.next_fetch().unwrap();
        let again = r.next_fetch().unwrap();
        assert_eq!(again.id, f.id);
        let e = r.failed(again.id, busy()).unwrap_err().to_string();
        assert!(
            e.starts_with(&format!("instance 1 of 2 ({SERIES}.0) failed 2 times")),
            "{e}"
        );

        let mut r = retrieval(2);
        let f = r.next_fetch().unwrap();
        let e = r
            .failed(
                f.id,
                DicomWebError::Unauthorized {
                    status: 401,
                    url: "u".to_owned(),
                    credentials: None,
                },
            )
            .unwrap_err();
        assert!(matches!(e, DicomWebError::Unauthorized { .. }));
        assert!(
            r.next_fetch().is_some(),
            "the other instance is still queued"
        );
        assert!(r.finish().is_err(), "an incomplete retrieval has no volume");
    }

    #[test]
    fn undecodable_instances_are_named_with_their_syntax() {
        let mut r = retrieval(1);
        let f = r.next_fetch().unwrap();
        let mut s = Slice::axial(SERIES, 0, 2, 2);
        s.transfer_syntax = "1.2.840.10008.1.2.4.80".to_owned();
        let e = r
            .received(f.id, vec![part(s.bytes())])
            .unwrap_err()
            .to_string();
        assert!(
            e.starts_with(&format!("instance 1 of 1 ({SERIES}.0): "))
                && e.contains("1.2.840.10008.1.2.4.80")
                && e.contains("JPEG-LS"),
            "{e}"
        );
        assert!(
            Retrieval::new(
                Base::parse("/x").unwrap(),
                "1.2",
                "3.4",
                Vec::new(),
                Auth::None,
                Limits::default()
            )
            .is_err()
        );
    }

    #[test]
    fn instance_responses_check_status_then_parse() {
        let mut r = retrieval(1);
        let f = r.next_fetch().unwrap();
        let lim = r.multipart_limits();
        let e = InstanceResponse::start(&f, 404, None, &Auth::None, lim)
            .err()
            .unwrap();
        assert!(e.to_string().starts_with("instance 1 of 1"), "{e}");
        let ct = "multipart/related; type=\"application/dicom\"; boundary=BB";
        let mut resp = InstanceResponse::start(&f, 200, Some(ct), &Auth::None, lim).unwrap();
        resp.feed(b"--BB\r\n\r\nDICM").unwrap();
        resp.feed(b"\r\n--BB--").unwrap();
        let parts = resp.finish().unwrap();
        assert_eq!(parts[0].bytes, b"DICM");
        let mut cut = InstanceResponse::start(&f, 200, Some(ct), &Auth::None, lim).unwrap();
        cut.feed(b"--BB\r\n\r\nDIC").unwrap();
        let e = cut.finish().err().unwrap();
        assert!(e.is_retryable());
        assert!(e.to_string().contains("instance 1 of 1") && e.to_string().contains("cut short"));
    }
}
