//! The native DICOMweb client: a blocking HTTP(S) transport (ureq with rustls) behind the
//! [`Transport`] trait, and the driver that runs a [`Retrieval`] (the whole series in one
//! request, then what it lacked with several instance requests in flight) on a few threads
//! while the calling thread decodes what arrives. This is the only
//! code of `src/io` that does I/O; the page drives the same `Retrieval` with `fetch`.

use std::io::Read;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Mutex, mpsc};
use std::time::Duration;

use super::multipart::{MultipartLimits, Part};
use super::qido::{self, InstanceInfo, SeriesInfo, StudyInfo};
use super::retrieve::{Fetch, InstanceResponse, Progress, Retrieval, SERIES_FETCH};
use super::{Auth, Base, DicomWebError, InstanceListing, Request, StudySearch, check_status};
use crate::io::{Limits, Loaded};

pub use super::MAX_JSON_BYTES;

pub use super::DEFAULT_PARALLEL;

/// An answer: status, Content-Type and the body, read as it arrives.
pub struct HttpResponse {
    pub status: u16,
    pub content_type: Option<String>,
    /// The Retry-After header of a busy answer.
    pub retry_after: Option<String>,
    pub body: Box<dyn Read>,
}

/// Blocking HTTP: GET, and POST for STOW-RS. The native client uses [`UreqTransport`]; tests
/// plug in their own.
pub trait Transport: Sync {
    fn get(&self, request: &Request) -> Result<HttpResponse, DicomWebError>;

    /// A POST of `body` (its Content-Type among the request's headers).
    fn post(&self, request: &Request, body: &[u8]) -> Result<HttpResponse, DicomWebError> {
        let _ = body;
        Err(DicomWebError::Transport {
            url: request.url.clone(),
            message: "this transport does not send (POST)".to_owned(),
            source: None,
        })
    }
}

/// HTTP and HTTPS with ureq: one agent, its connections kept alive and shared by the threads.
/// TLS (rustls) trusts Mozilla's roots, or only the CA certificates given.
pub struct UreqTransport {
    agent: ureq::Agent,
}

impl UreqTransport {
    pub fn new(parallel: usize) -> Self {
        Self::with_roots(parallel, ureq::tls::RootCerts::WebPki)
    }

    /// Trusting only the certificates of `ca_pem` (PEM, one or more: a site's own CA).
    pub fn with_ca(parallel: usize, ca_pem: &[u8]) -> Result<Self, DicomWebError> {
        let mut certs = Vec::new();
        for item in ureq::tls::parse_pem(ca_pem) {
            match item {
                Ok(ureq::tls::PemItem::Certificate(c)) => certs.push(c),
                Ok(_) => {}
                Err(e) => return Err(DicomWebError::InvalidCa(format!("not PEM: {e}"))),
            }
        }
        if certs.is_empty() {
            return Err(DicomWebError::InvalidCa(
                "no CERTIFICATE in the PEM given".to_owned(),
            ));
        }
        Ok(Self::with_roots(
            parallel,
            ureq::tls::RootCerts::Specific(std::sync::Arc::new(certs)),
        ))
    }

    fn with_roots(parallel: usize, roots: ureq::tls::RootCerts) -> Self {
        let config = ureq::Agent::config_builder()
            .tls_config(ureq::tls::TlsConfig::builder().root_certs(roots).build())
            .http_status_as_error(false)
            .timeout_connect(Some(Duration::from_secs(10)))
            // An archive may transcode before it answers; once it sends, reads must progress.
            .timeout_recv_response(Some(Duration::from_secs(300)))
            .timeout_per_read(Some(Duration::from_secs(60)))
            .max_idle_connections_per_host(parallel.max(1) + 2)
            .user_agent(concat!("shapecast/", env!("CARGO_PKG_VERSION")))
            .build();
        Self {
            agent: ureq::Agent::new_with_config(config),
        }
    }
}

impl Transport for UreqTransport {
    fn get(&self, request: &Request) -> Result<HttpResponse, DicomWebError> {
        let mut req = self.agent.get(&request.url);
        for (name, value) in &request.headers {
            req = req.header(*name, value);
        }
        answer(&request.url, req.call())
    }

    fn post(&self, request: &Request, body: &[u8]) -> Result<HttpResponse, DicomWebError> {
        let mut req = self.agent.post(&request.url);
        for (name, value) in &request.headers {
            req = req.header(*name, value);
        }
        answer(&request.url, req.send(body))
    }
}

/// An answer, or the failure as a [`DicomWebError`] that names the host or URL.
fn answer(
    url: &str,
    result: Result<ureq::http::Response<ureq::Body>, ureq::Error>,
) -> Result<HttpResponse, DicomWebError> {
    let connect = |message: String| DicomWebError::Connect {
        host: crate::io::url::host_of(url),
        message,
    };
    let response = result.map_err(|e| match e {
        ureq::Error::Io(io) if is_connect_error(io.kind()) => connect(io.to_string()),
        // rustls reports a certificate it does not trust as invalid data on the socket.
        ureq::Error::Io(io)
            if io.kind() == std::io::ErrorKind::InvalidData
                && url.to_ascii_lowercase().starts_with("https://") =>
        {
            connect(format!("TLS: {io}{CA_HINT}"))
        }
        ureq::Error::ConnectionFailed => connect("the connection failed".to_owned()),
        ureq::Error::HostNotFound => connect("host not found".to_owned()),
        // A certificate not trusted (or TLS refused) does not change by asking again.
        ureq::Error::Rustls(tls) => connect(format!("TLS: {tls}{CA_HINT}")),
        ureq::Error::Tls(tls) => connect(format!("TLS: {tls}")),
        other => DicomWebError::Transport {
            url: url.to_owned(),
            message: "the request failed".to_owned(),
            source: Some(other.into()),
        },
    })?;
    let status = response.status().as_u16();
    let header = |name: &str| {
        response
            .headers()
            .get(name)
            .and_then(|v| v.to_str().ok())
            .map(str::to_owned)
    };
    let (content_type, retry_after) = (header("content-type"), header("retry-after"));
    Ok(HttpResponse {
        status,
        content_type,
        retry_after,
        body: Box::new(response.into_body().into_reader()),
    })
}

/// What a TLS failure message adds.
const CA_HINT: &str = " (an archive whose certificate a site's own CA signed needs that CA: --ca FILE or SHAPECAST_DICOMWEB_CA)";

fn is_connect_error(kind: std::io::ErrorKind) -> bool {
    use std::io::ErrorKind as K;
    matches!(
        kind,
        K::ConnectionRefused
            | K::HostUnreachable
            | K::NetworkUnreachable
            | K::AddrNotAvailable
            | K::NetworkDown
    )
}

/// A study resolved to the series to open: the study, its series, and the one chosen.
#[derive(Clone, Debug)]
pub struct Resolved {
    pub study: StudyInfo,
    pub series: Vec<SeriesInfo>,
    pub chosen: usize,
    /// Whether the chooser picked it (no series was named).
    pub by_chooser: bool,
}

/// A DICOMweb client of one archive.
pub struct Client<T: Transport = UreqTransport> {
    transport: T,
    base: Base,
    auth: Auth,
    limits: Limits,
    parallel: usize,
}

impl Client<UreqTransport> {
    /// A client over HTTP or HTTPS (Mozilla's roots). The base must be absolute.
    pub fn new(base: Base, auth: Auth) -> Result<Self, DicomWebError> {
        Self::with_ca(base, auth, None)
    }

    /// ... trusting only the CA certificates of `ca_pem` where given (a site's own CA).
    pub fn with_ca(base: Base, auth: Auth, ca_pem: Option<&[u8]>) -> Result<Self, DicomWebError> {
        if base.is_relative() {
            return Err(DicomWebError::InvalidBase {
                base: base.as_str().to_owned(),
                reason: "a relative base works only from a page served by the archive; give http(s)://host:port/path".to_owned(),
            });
        }
        let transport = match ca_pem {
            Some(pem) => UreqTransport::with_ca(DEFAULT_PARALLEL, pem)?,
            None => UreqTransport::new(DEFAULT_PARALLEL),
        };
        Ok(Self::with_transport(transport, base, auth))
    }
}

impl<T: Transport> Client<T> {
    pub fn with_transport(transport: T, base: Base, auth: Auth) -> Self {
        Self {
            transport,
            base,
            auth,
            limits: Limits::default(),
            parallel: DEFAULT_PARALLEL,
        }
    }

    /// Instance requests in flight at once (at least 1).
    pub fn with_parallel(mut self, parallel: usize) -> Self {
        self.parallel = parallel.clamp(1, 32);
        self
    }

    pub fn with_limits(mut self, limits: Limits) -> Self {
        self.limits = limits;
        self
    }

    pub fn base(&self) -> &Base {
        &self.base
    }

    /// A QIDO-RS answer's bytes (at most [`MAX_JSON_BYTES`]), asked for again after a dropped
    /// connection (once) or a busy answer (after the wait it asks for, [`super::backoff`]).
    fn get_json(&self, url: String, what: &str) -> Result<Vec<u8>, DicomWebError> {
        let mut attempt = 0;
        loop {
            attempt += 1;
            match self.get_json_once(&url, what) {
                Err(e) if e.is_retryable() && attempt < super::max_attempts(&e) => {
                    let wait = super::backoff(attempt, &e);
                    let e = crate::error::chain(&e);
                    log::warn!("{e}; asking again in {:.1} s", wait.as_secs_f64());
                    std::thread::sleep(wait);
                }
                other => return other,
            }
        }
    }

    fn get_json_once(&self, url: &str, what: &str) -> Result<Vec<u8>, DicomWebError> {
        let request = Request::qido(url.to_owned(), &self.auth);
        let response = self.transport.get(&request)?;
        check_status(response.status, &request.url, what, &self.auth)
            .map_err(|e| e.with_retry_after(response.retry_after.as_deref()))?;
        let mut body = Vec::new();
        response
            .body
            .take(MAX_JSON_BYTES + 1)
            .read_to_end(&mut body)
            .map_err(|e| DicomWebError::Transport {
                url: request.url.clone(),
                message: "reading the answer".to_owned(),
                source: Some(e.into()),
            })?;
        if body.len() as u64 > MAX_JSON_BYTES {
            return Err(DicomWebError::TooLarge {
                what: request.url,
                size: body.len() as u64,
                limit: MAX_JSON_BYTES,
            });
        }
        Ok(body)
    }

    /// The studies matching a search.
    pub fn search_studies(&self, search: &StudySearch) -> Result<Vec<StudyInfo>, DicomWebError> {
        let url = self.base.study_search(search)?;
        let body = self.get_json(url.clone(), "the study search")?;
        qido::parse_studies(&url, &body)
    }

    /// The study's patient, date and description; `NotFound` when the archive lacks it.
    pub fn find_study(&self, study: &str) -> Result<StudyInfo, DicomWebError> {
        let url = self.base.study_query(study)?;
        let what = format!("study {study}");
        let body = self.get_json(url.clone(), &what)?;
        qido::parse_studies(&url, &body)?
            .into_iter()
            .find(|s| s.study_uid == study.trim())
            .ok_or(DicomWebError::NotFound { what, url })
    }

    pub fn list_series(&self, study: &str) -> Result<Vec<SeriesInfo>, DicomWebError> {
        let url = self.base.series_query(study)?;
        let body = self.get_json(url.clone(), &format!("study {study}"))?;
        qido::parse_series(&url, &body)
    }

    /// Every instance of the series, checked against its count and completed where the
    /// archive caps its answers ([`InstanceListing`]); a series that stays short is refused.
    pub fn list_instances(
        &self,
        study: &str,
        series: &str,
    ) -> Result<Vec<InstanceInfo>, DicomWebError> {
        // The series' own count (NumberOfSeriesRelatedInstances); without it, the list as given.
        let expected = (self.list_series(study).ok())
            .and_then(|list| super::listing::expected_count(&list, series));
        let mut listing = InstanceListing::new(&self.base, study, series, expected)?;
        let what = listing.what();
        while let Some(url) = listing.next_url() {
            let answer = self.get_json(url.clone(), &what);
            match answer {
                Ok(body) => listing.take(&url, Ok(&body))?,
                Err(e) => listing.take(&url, Err(e))?,
            }
        }
        listing.finish()
    }

    /// The series a result derives from: its patient, study and instances, from the series'
    /// WADO-RS metadata.
    pub fn source_series(
        &self,
        study: &str,
        series: &str,
    ) -> Result<super::stow::SourceSeries, DicomWebError> {
        let url = self.base.series_metadata_url(study, series)?;
        let body = self.get_json(url.clone(), &format!("series {series}"))?;
        super::stow::SourceSeries::from_metadata(&url, &body)
    }

    /// Stores instances into a study (STOW-RS), asking once more after a dropped connection
    /// or a busy archive.
    pub fn store(
        &self,
        study: &str,
        instances: &[super::stow::Instance],
    ) -> Result<super::stow::Stored, DicomWebError> {
        let url = self.base.store_url(study)?;
        let (content_type, body) = super::stow::request_body(instances);
        let request = Request::stow(url.clone(), content_type, &self.auth);
        let mut attempt = 0;
        loop {
            attempt += 1;
            let result = self.transport.post(&request, &body).and_then(|response| {
                let status = response.status;
                let retry_after = response.retry_after.clone();
                let mut answer = Vec::new();
                response
                    .body
                    .take(MAX_JSON_BYTES)
                    .read_to_end(&mut answer)
                    .map_err(|e| DicomWebError::Transport {
                        url: url.clone(),
                        message: "reading the answer".to_owned(),
                        source: Some(e.into()),
                    })?;
                super::stow::read_answer(&url, status, &answer, instances, &self.auth)
                    .map_err(|e| e.with_retry_after(retry_after.as_deref()))
            });
            match result {
                Err(e) if e.is_retryable() && attempt < super::max_attempts(&e) => {
                    std::thread::sleep(super::backoff(attempt, &e));
                }
                other => return other,
            }
        }
    }

    /// One page of a series search across studies: (study, series) pairs.
    pub fn search_series(
        &self,
        search: &super::SeriesSearch,
    ) -> Result<Vec<(String, SeriesInfo)>, DicomWebError> {
        let url = self.base.series_search(search)?;
        let body = self.get_json(url.clone(), "the series search")?;
        qido::parse_series_in_studies(&url, &body)
    }

    /// Whether the archive holds series `series` in study `study`.
    pub fn has_series(&self, study: &str, series: &str) -> Result<bool, DicomWebError> {
        let url = self.base.series_exists_query(study, series)?;
        let body = self.get_json(url.clone(), &format!("study {study}"));
        match body {
            Ok(body) => Ok(qido::parse_series(&url, &body)?
                .iter()
                .any(|s| s.series_uid == series)),
            // Some archives answer a query into an unknown study with 404.
            Err(DicomWebError::NotFound { .. }) => Ok(false),
            Err(e) => Err(e),
        }
    }

    /// The study and the series to open: the one named, else the chooser's.
    pub fn resolve(&self, study: &str, series: Option<&str>) -> Result<Resolved, DicomWebError> {
        let info = self.find_study(study)?;
        let list = self.list_series(study)?;
        let (chosen, by_chooser) = super::pick_series(&self.base, study, &list, series)?;
        Ok(Resolved {
            study: info,
            series: list,
            chosen,
            by_chooser,
        })
    }

    /// Retrieves one series (WADO-RS: the whole series in one request, decoded part by part as
    /// it streams in; what it did not bring instance by instance, several in flight, a failed
    /// one asked for again once); `progress` is told after each instance.
    pub fn retrieve(
        &self,
        study: &str,
        series: &str,
        progress: &mut dyn FnMut(&Progress),
    ) -> Result<Loaded, DicomWebError> {
        let instances = self.list_instances(study, series)?;
        let mut retrieval = Retrieval::new(
            self.base.clone(),
            study,
            series,
            instances,
            self.auth.clone(),
            self.limits,
        )?
        .series_first();
        let limits = retrieval.multipart_limits();
        let auth = &self.auth;
        let transport = &self.transport;
        let stop = AtomicBool::new(false);
        let (job_tx, job_rx) = mpsc::channel::<Fetch>();
        let job_rx = Mutex::new(job_rx);
        // Bounded: at most `parallel` answers wait to be decoded.
        let (done_tx, done_rx) = mpsc::sync_channel::<Answer>(self.parallel);
        std::thread::scope(|scope| {
            // Dropped when the loop below ends, so that a request thread blocked handing on a
            // part of the series' answer (the channel full) stops instead of waiting forever.
            let done_rx = done_rx;
            for _ in 0..self.parallel {
                let done_tx = done_tx.clone();
                let (job_rx, stop) = (&job_rx, &stop);
                scope.spawn(move || {
                    loop {
                        let job = match job_rx.lock() {
                            Ok(rx) => rx.recv(),
                            Err(_) => return,
                        };
                        let Ok(fetch) = job else { return };
                        if !fetch.delay.is_zero() {
                            std::thread::sleep(fetch.delay);
                        }
                        if stop.load(Ordering::Relaxed) {
                            return;
                        }
                        let mut each = |part: Part| {
                            if stop.load(Ordering::Relaxed) {
                                return Err(DicomWebError::Cancelled);
                            }
                            done_tx
                                .send(Answer::Part(part))
                                .map_err(|_| DicomWebError::Cancelled)
                        };
                        let each: Option<&mut dyn FnMut(Part) -> Result<(), DicomWebError>> =
                            (fetch.id == SERIES_FETCH).then_some(&mut each);
                        let result = fetch_instance(transport, &fetch, auth, limits, each);
                        if done_tx.send(Answer::Done(fetch.id, result)).is_err() {
                            return;
                        }
                    }
                });
            }
            drop(done_tx);
            let mut in_flight = 0;
            let result = (|| {
                loop {
                    while in_flight < self.parallel
                        && let Some(fetch) = retrieval.next_fetch()
                    {
                        job_tx
                            .send(fetch)
                            .map_err(|_| internal("the request threads stopped"))?;
                        in_flight += 1;
                    }
                    if retrieval.is_complete() {
                        return Ok(());
                    }
                    if in_flight == 0 {
                        return Err(internal("nothing in flight and nothing to ask for"));
                    }
                    let answer = done_rx
                        .recv()
                        .map_err(|_| internal("the request threads stopped"))?;
                    match answer {
                        Answer::Part(part) => retrieval.received_part(part)?,
                        Answer::Done(id, result) => {
                            in_flight -= 1;
                            match result {
                                Ok(parts) => retrieval.received(id, parts)?,
                                Err(e) => retrieval.failed(id, e)?,
                            }
                        }
                    }
                    progress(&retrieval.progress());
                }
            })();
            stop.store(true, Ordering::Relaxed);
            drop(job_tx);
            drop(done_rx);
            result
        })?;
        retrieval.finish()
    }
}

/// What a request thread hands the retrieval.
enum Answer {
    /// A part of the series' answer ([`SERIES_FETCH`]), decoded while the rest streams in.
    Part(Part),
    /// A request ended: its parts (those not handed on one by one), or why it failed.
    Done(usize, Result<Vec<Part>, DicomWebError>),
}

fn internal(message: &str) -> DicomWebError {
    DicomWebError::Transport {
        url: "-".to_owned(),
        message: format!("internal: {message}"),
        source: None,
    }
}

/// One instance's request (or the series'), read to its end through the multipart parser;
/// with `each`, parts are handed to it as they complete instead of kept for the end.
fn fetch_instance<T: Transport>(
    transport: &T,
    fetch: &Fetch,
    auth: &Auth,
    limits: MultipartLimits,
    mut each: Option<&mut dyn FnMut(Part) -> Result<(), DicomWebError>>,
) -> Result<Vec<Part>, DicomWebError> {
    let response = transport.get(&fetch.request)?;
    let mut reader = InstanceResponse::start(
        fetch,
        response.status,
        response.content_type.as_deref(),
        auth,
        limits,
    )
    .map_err(|e| e.with_retry_after(response.retry_after.as_deref()))?;
    let mut body = response.body;
    let mut buf = vec![0u8; 256 << 10];
    loop {
        let n = match body.read(&mut buf) {
            Ok(0) => break,
            Ok(n) => n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
            Err(e) => {
                return Err(DicomWebError::Transport {
                    url: fetch.request.url.clone(),
                    message: "the body broke off".to_owned(),
                    source: Some(e.into()),
                });
            }
        };
        match each.as_mut() {
            Some(each) => reader.feed_each(&buf[..n], &mut **each)?,
            None => reader.feed(&buf[..n])?,
        }
    }
    reader.finish()
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // a failed unwrap is a failed test
mod tests;
