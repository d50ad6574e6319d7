//! The page's DICOMweb transport (wasm only): the browser's `fetch` drives the same pure code as
//! the native client (`client.rs`). QIDO-RS answers are read whole (at most
//! [`MAX_JSON_BYTES`]); a WADO-RS retrieval asks for the whole series in one request first,
//! its parts decoded into the [`Retrieval`]'s series as they complete, then keeps
//! [`DEFAULT_PARALLEL`] requests in flight from one async task for the instances that answer
//! lacked, each body streamed from its reader into an [`InstanceResponse`] chunk by chunk and
//! decoded as it completes (so the voxels are held once), a failed instance asked for again. One `AbortController`
//! cancels every request of a client. Nothing here blocks: every wait is a promise.

use std::cell::RefCell;
use std::collections::VecDeque;
use std::future::Future;
use std::pin::Pin;
use std::rc::Rc;
use std::task::{Context, Poll, Waker};

use wasm_bindgen::JsCast as _;
use wasm_bindgen::JsValue;
use wasm_bindgen_futures::JsFuture;

use super::multipart::{MultipartLimits, Part};
use super::qido::{self, InstanceInfo, SeriesInfo, StudyInfo};
use super::retrieve::{Fetch, InstanceResponse, Progress, Retrieval, SERIES_FETCH};
use super::{
    Auth, Base, DEFAULT_PARALLEL, DicomWebError, InstanceListing, MAX_JSON_BYTES, Request,
    StudySearch, check_status,
};
use crate::io::js::error_text;
use crate::io::{Limits, Loaded};

/// A progress report is sent at least every this many streamed bytes.
const PROGRESS_BYTES: u64 = 256 << 10;

/// A DICOMweb client of one archive in the page; dropping it does not cancel, [`cancel`] does.
///
/// [`cancel`]: WebClient::cancel
pub struct WebClient {
    base: Base,
    auth: Auth,
    limits: Limits,
    parallel: usize,
    controller: web_sys::AbortController,
}

/// How a retrieval is going: the instances and bytes decoded, and the bytes streamed so far
/// (those of instances still arriving included).
#[derive(Clone, Copy, Debug, Default)]
pub struct WebProgress {
    pub retrieval: Progress,
    pub streamed_bytes: u64,
}

impl WebClient {
    pub fn new(base: Base, auth: Auth) -> Result<Self, DicomWebError> {
        let controller = web_sys::AbortController::new().map_err(|e| DicomWebError::Transport {
            url: base.as_str().to_owned(),
            message: format!("cannot make an AbortController: {}", error_text(&e)),
            source: None,
        })?;
        Ok(Self {
            base,
            auth,
            limits: Limits::default(),
            parallel: DEFAULT_PARALLEL,
            controller,
        })
    }

    pub fn base(&self) -> &Base {
        &self.base
    }

    /// Stops every request of this client; a retrieval running ends with `Cancelled`.
    pub fn cancel(&self) {
        self.controller.abort();
    }

    pub fn cancelled(&self) -> bool {
        self.controller.signal().aborted()
    }

    /// The studies matching a search.
    pub async fn search_studies(
        &self,
        search: &StudySearch,
    ) -> Result<Vec<StudyInfo>, DicomWebError> {
        let url = self.base.study_search(search)?;
        let body = self.get_json(&url, "the study search").await?;
        qido::parse_studies(&url, &body)
    }

    /// The study's patient, date and description; `NotFound` when the archive lacks it.
    pub async fn find_study(&self, study: &str) -> Result<StudyInfo, DicomWebError> {
        let url = self.base.study_query(study)?;
        let what = format!("study {study}");
        let body = self.get_json(&url, &what).await?;
        qido::parse_studies(&url, &body)?
            .into_iter()
            .find(|s| s.study_uid == study.trim())
            .ok_or(DicomWebError::NotFound { what, url })
    }

    pub async fn list_series(&self, study: &str) -> Result<Vec<SeriesInfo>, DicomWebError> {
        let url = self.base.series_query(study)?;
        let body = self.get_json(&url, &format!("study {study}")).await?;
        qido::parse_series(&url, &body)
    }

    /// Every instance of the series, checked against its count and completed where the
    /// archive caps its answers ([`InstanceListing`]); a series that stays short is refused.
    pub async fn list_instances(
        &self,
        study: &str,
        series: &str,
    ) -> Result<Vec<InstanceInfo>, DicomWebError> {
        // The series' own count (NumberOfSeriesRelatedInstances); without it, the list as given.
        let expected = (self.list_series(study).await.ok())
            .and_then(|list| super::listing::expected_count(&list, series));
        let mut listing = InstanceListing::new(&self.base, study, series, expected)?;
        let what = listing.what();
        while let Some(url) = listing.next_url() {
            match self.get_json(&url, &what).await {
                Ok(body) => listing.take(&url, Ok(&body))?,
                Err(e) => listing.take(&url, Err(e))?,
            }
        }
        listing.finish()
    }

    /// Retrieves one series (WADO-RS: the whole series in one request, decoded part by part as
    /// it streams in; what it did not bring instance by instance, several in flight, a failed
    /// one asked for again once); `progress` is told as bytes stream in and after each
    /// instance.
    pub async fn retrieve(
        &self,
        study: &str,
        series: &str,
        progress: &mut dyn FnMut(WebProgress),
    ) -> Result<Loaded, DicomWebError> {
        let instances = self.list_instances(study, series).await?;
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
        let inbox: Inbox<Message> = Inbox::default();
        let mut in_flight = 0;
        let mut streamed: u64 = 0;
        let result = async {
            loop {
                while in_flight < self.parallel
                    && let Some(fetch) = retrieval.next_fetch()
                {
                    let (inbox, auth, signal) =
                        (inbox.clone(), self.auth.clone(), self.controller.signal());
                    wasm_bindgen_futures::spawn_local(async move {
                        let id = fetch.id;
                        let result = fetch_instance(&fetch, &auth, limits, &signal, &inbox).await;
                        inbox.push(Message::Done(id, result));
                    });
                    in_flight += 1;
                }
                if retrieval.is_complete() {
                    return Ok(());
                }
                if in_flight == 0 {
                    return Err(DicomWebError::Transport {
                        url: self.base.as_str().to_owned(),
                        message: "internal: nothing in flight and nothing to ask for".to_owned(),
                        source: None,
                    });
                }
                match inbox.next().await {
                    Message::Bytes(n) => streamed += n,
                    Message::Part(part) => {
                        if self.cancelled() {
                            return Err(DicomWebError::Cancelled);
                        }
                        retrieval.received_part(part)?;
                    }
                    Message::Done(id, result) => {
                        in_flight -= 1;
                        if self.cancelled() {
                            return Err(DicomWebError::Cancelled);
                        }
                        match result {
                            Ok(parts) => retrieval.received(id, parts)?,
                            Err(e) => retrieval.failed(id, e)?,
                        }
                    }
                }
                progress(WebProgress {
                    retrieval: retrieval.progress(),
                    streamed_bytes: streamed,
                });
            }
        }
        .await;
        if result.is_err() {
            // The other requests are of no use any more.
            self.controller.abort();
        }
        result?;
        retrieval.finish()
    }

    /// The series a result derives from, from the series' WADO-RS metadata.
    pub async fn source_series(
        &self,
        study: &str,
        series: &str,
    ) -> Result<super::stow::SourceSeries, DicomWebError> {
        let url = self.base.series_metadata_url(study, series)?;
        let body = self.get_json(&url, &format!("series {series}")).await?;
        super::stow::SourceSeries::from_metadata(&url, &body)
    }

    /// Stores instances into a study (STOW-RS).
    pub async fn store(
        &self,
        study: &str,
        instances: &[super::stow::Instance],
    ) -> Result<super::stow::Stored, DicomWebError> {
        let url = self.base.store_url(study)?;
        let (content_type, body) = super::stow::request_body(instances);
        let request = Request::stow(url.clone(), content_type, &self.auth);
        let signal = self.controller.signal();
        let response = send(&request, Some(&body), &signal).await?;
        drop(body);
        let status = response.status();
        let mut answer = Vec::new();
        read_body(&response, &url, &signal, &mut |chunk| {
            if answer.len() as u64 + chunk.len() as u64 <= MAX_JSON_BYTES {
                answer.extend_from_slice(chunk);
            }
            Ok(())
        })
        .await?;
        super::stow::read_answer(&url, status, &answer, instances, &self.auth)
    }

    /// A QIDO-RS answer's bytes (at most [`MAX_JSON_BYTES`]), asked for again after a dropped
    /// connection (once) or a busy answer (after the wait it asks for, [`super::backoff`]).
    async fn get_json(&self, url: &str, what: &str) -> Result<Vec<u8>, DicomWebError> {
        let mut attempt = 0;
        loop {
            attempt += 1;
            match self.get_json_once(url, what).await {
                Err(e)
                    if e.is_retryable()
                        && attempt < super::max_attempts(&e)
                        && !self.cancelled() =>
                {
                    let wait = super::backoff(attempt, &e);
                    log::warn!("{e}; asking again in {:.1} s", wait.as_secs_f64());
                    sleep(wait).await;
                }
                other => return other,
            }
        }
    }

    async fn get_json_once(&self, url: &str, what: &str) -> Result<Vec<u8>, DicomWebError> {
        let request = Request::qido(url.to_owned(), &self.auth);
        let signal = self.controller.signal();
        let response = send(&request, None, &signal).await?;
        check_status(response.status(), url, what, &self.auth)
            .map_err(|e| e.with_retry_after(header(&response, "retry-after").as_deref()))?;
        if let Some(n) = content_length(&response)
            && n > MAX_JSON_BYTES
        {
            return Err(DicomWebError::TooLarge {
                what: url.to_owned(),
                size: n,
                limit: MAX_JSON_BYTES,
            });
        }
        let mut body = Vec::new();
        read_body(&response, url, &signal, &mut |chunk| {
            if body.len() as u64 + chunk.len() as u64 > MAX_JSON_BYTES {
                return Err(DicomWebError::TooLarge {
                    what: url.to_owned(),
                    size: body.len() as u64 + chunk.len() as u64,
                    limit: MAX_JSON_BYTES,
                });
            }
            body.extend_from_slice(chunk);
            Ok(())
        })
        .await?;
        Ok(body)
    }
}

enum Message {
    /// Bytes streamed by one of the requests since its last report.
    Bytes(u64),
    /// A part of the series' answer ([`SERIES_FETCH`]), decoded while the rest streams in.
    Part(Part),
    /// One instance's request (or the series') ended.
    Done(usize, Result<Vec<Part>, DicomWebError>),
}

/// One instance's request, its body streamed through the multipart parser.
async fn fetch_instance(
    fetch: &Fetch,
    auth: &Auth,
    limits: MultipartLimits,
    signal: &web_sys::AbortSignal,
    inbox: &Inbox<Message>,
) -> Result<Vec<Part>, DicomWebError> {
    if !fetch.delay.is_zero() {
        sleep(fetch.delay).await;
    }
    let response = send(&fetch.request, None, signal).await?;
    let content_type = header(&response, "content-type");
    let mut reader = InstanceResponse::start(
        fetch,
        response.status(),
        content_type.as_deref(),
        auth,
        limits,
    )
    .map_err(|e| e.with_retry_after(header(&response, "retry-after").as_deref()))?;
    let mut unreported: u64 = 0;
    let whole_series = fetch.id == SERIES_FETCH;
    read_body(&response, &fetch.request.url, signal, &mut |chunk| {
        unreported += chunk.len() as u64;
        if unreported >= PROGRESS_BYTES {
            inbox.push(Message::Bytes(std::mem::take(&mut unreported)));
        }
        if whole_series {
            reader.feed_each(chunk, &mut |part| {
                inbox.push(Message::Part(part));
                Ok(())
            })
        } else {
            reader.feed(chunk)
        }
    })
    .await?;
    if unreported > 0 {
        inbox.push(Message::Bytes(unreported));
    }
    reader.finish()
}

/// A header of an answer (one the page may read: same-origin, or exposed by CORS).
fn header(response: &web_sys::Response, name: &str) -> Option<String> {
    response.headers().get(name).ok().flatten()
}

/// Waits `d` without blocking the page (a `setTimeout` promise).
async fn sleep(d: std::time::Duration) {
    let ms = d.as_millis().min(i32::MAX as u128) as i32;
    let promise = js_sys::Promise::new(&mut |resolve, _| {
        let scheduled = web_sys::window().is_some_and(|w| {
            w.set_timeout_with_callback_and_timeout_and_arguments_0(&resolve, ms)
                .is_ok()
        });
        if !scheduled {
            let _ = resolve.call0(&JsValue::NULL);
        }
    });
    let _ = JsFuture::from(promise).await;
}

/// Sends a GET (or, with a body, a POST) with the request's headers; a refusal (no answer,
/// CORS, the page's Content-Security-Policy) is a message saying what may be wrong.
async fn send(
    request: &Request,
    body: Option<&[u8]>,
    signal: &web_sys::AbortSignal,
) -> Result<web_sys::Response, DicomWebError> {
    let url = request.url.as_str();
    let transport = |message: String| DicomWebError::Transport {
        url: url.to_owned(),
        message,
        source: None,
    };
    let window = web_sys::window().ok_or_else(|| transport("no window object".to_owned()))?;
    let headers = web_sys::Headers::new().map_err(|e| transport(error_text(&e)))?;
    for (name, value) in &request.headers {
        headers
            .set(name, value)
            .map_err(|_| transport(format!("the {name} header cannot be sent")))?;
    }
    let init = web_sys::RequestInit::new();
    match body {
        Some(bytes) => {
            init.set_method("POST");
            init.set_body(&js_sys::Uint8Array::from(bytes).into());
        }
        None => init.set_method("GET"),
    }
    init.set_headers(&headers);
    init.set_signal(Some(signal));
    match JsFuture::from(window.fetch_with_str_and_init(url, &init)).await {
        Ok(r) => Ok(r.unchecked_into()),
        Err(_) if signal.aborted() => Err(DicomWebError::Cancelled),
        Err(e) => {
            log::warn!("fetch {url}: {}", error_text(&e));
            Err(transport(refusal(url)))
        }
    }
}

/// What a rejected fetch may mean, for the user.
fn refusal(url: &str) -> String {
    let page = web_sys::window()
        .and_then(|w| w.location().origin().ok())
        .unwrap_or_default();
    let same_origin = url.starts_with('/') || url.starts_with(&format!("{page}/"));
    if same_origin {
        "no answer from the archive (network error): is it running, and is the DICOMweb path right?"
            .to_owned()
    } else if url.starts_with("http:") && page.starts_with("https:") {
        format!(
            "a page served over HTTPS may not ask a plain http archive; use the archive's https:// address (this page is {page})"
        )
    } else {
        format!(
            "the archive refused this page or did not answer. An archive on another origin must allow this page ({page}) with CORS headers (Access-Control-Allow-Origin: {page}, Access-Control-Allow-Headers: Authorization, Accept; README, \"Open from a PACS\"), and the page's Content-Security-Policy must allow its address; or serve Shapecast from the archive itself"
        )
    }
}

fn content_length(response: &web_sys::Response) -> Option<u64> {
    let headers = response.headers();
    let encoded = headers
        .get("content-encoding")
        .ok()
        .flatten()
        .is_some_and(|e| !e.is_empty() && e != "identity");
    if encoded {
        return None;
    }
    headers
        .get("content-length")
        .ok()
        .flatten()
        .and_then(|l| l.trim().parse().ok())
}

/// Reads a response's body chunk by chunk as it arrives.
async fn read_body(
    response: &web_sys::Response,
    url: &str,
    signal: &web_sys::AbortSignal,
    each: &mut dyn FnMut(&[u8]) -> Result<(), DicomWebError>,
) -> Result<(), DicomWebError> {
    let Some(body) = response.body() else {
        return Ok(());
    };
    let reader: web_sys::ReadableStreamDefaultReader = body.get_reader().unchecked_into();
    let mut received: u64 = 0;
    let mut buf = Vec::new();
    loop {
        let chunk = match JsFuture::from(reader.read()).await {
            Ok(c) => c,
            Err(_) if signal.aborted() => return Err(DicomWebError::Cancelled),
            Err(e) => {
                return Err(DicomWebError::Transport {
                    url: url.to_owned(),
                    message: format!(
                        "the answer broke off after {received} bytes ({})",
                        error_text(&e)
                    ),
                    source: None,
                });
            }
        };
        let done = js_sys::Reflect::get(&chunk, &JsValue::from_str("done"))
            .ok()
            .and_then(|d| d.as_bool())
            .unwrap_or(true);
        if done {
            return Ok(());
        }
        let Ok(value) = js_sys::Reflect::get(&chunk, &JsValue::from_str("value")) else {
            continue;
        };
        let Ok(array) = value.dyn_into::<js_sys::Uint8Array>() else {
            continue;
        };
        buf.resize(array.length() as usize, 0);
        array.copy_to(&mut buf);
        received += buf.len() as u64;
        if let Err(e) = each(&buf) {
            // Stop the body: what follows cannot help.
            let _ = reader.cancel();
            return Err(e);
        }
    }
}

/// A queue that one task awaits and others push to (single-threaded: wasm).
struct Inbox<T> {
    state: Rc<RefCell<(VecDeque<T>, Option<Waker>)>>,
}

impl<T> Default for Inbox<T> {
    fn default() -> Self {
        Self {
            state: Rc::new(RefCell::new((VecDeque::new(), None))),
        }
    }
}

impl<T> Clone for Inbox<T> {
    fn clone(&self) -> Self {
        Self {
            state: self.state.clone(),
        }
    }
}

impl<T> Inbox<T> {
    fn push(&self, item: T) {
        let waker = {
            let mut s = self.state.borrow_mut();
            s.0.push_back(item);
            s.1.take()
        };
        if let Some(w) = waker {
            w.wake();
        }
    }

    fn next(&self) -> Next<'_, T> {
        Next { inbox: self }
    }
}

struct Next<'a, T> {
    inbox: &'a Inbox<T>,
}

impl<T> Future for Next<'_, T> {
    type Output = T;

    fn poll(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<T> {
        let mut s = self.inbox.state.borrow_mut();
        match s.0.pop_front() {
            Some(item) => Poll::Ready(item),
            None => {
                s.1 = Some(cx.waker().clone());
                Poll::Pending
            }
        }
    }
}
