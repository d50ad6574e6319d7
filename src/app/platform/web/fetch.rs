//! Volumes by URL in the browser (wasm only): `?url=` and shared links. Each URL is fetched
//! and its body streamed into memory with progress (bytes of the total where the server gives a
//! Content-Length), cancellable (an `AbortController`: the "Cancel" button, a drop or a file
//! chosen meanwhile), and the files then take the same path as a drop (`WebEvent::Files`).
//!
//! Every failure is a message that names the URL and says what to do: an HTTP status (not found,
//! a login needed), a refusal the browser gives no detail about (the server does not allow this
//! site's origin, or does not answer; this page's Content-Security-Policy; plain http from an
//! https page), a web page where a volume was expected (a login page), or a size this tab cannot
//! hold. The volume on screen stays.

use crate::app::error::{AppError, DownloadProblem, PageError};
use std::cell::RefCell;

use wasm_bindgen::JsCast as _;
use wasm_bindgen::closure::Closure;
use wasm_bindgen_futures::JsFuture;

use crate::app::platform::web::events::{WebEvent, push};
use crate::app::platform::web::js_bytes::{self, Gathered, JsBytes};
use crate::app::view_link::ViewSource;
use crate::io::InputFile;
use crate::io::js::error_text as js_error;
use crate::io::url::host_of;

thread_local! {
    /// The running download's controller.
    static ACTIVE: RefCell<Option<web_sys::AbortController>> = const { RefCell::new(None) };
    /// Addresses this page's Content-Security-Policy blocked (to explain a failed fetch).
    static BLOCKED: RefCell<Vec<String>> = const { RefCell::new(Vec::new()) };
}

/// The most a download may hold: what one volume may take in this tab (`io::Limits`).
fn max_download_bytes() -> u64 {
    crate::io::Limits::default().max_voxel_bytes
}

/// Records what the page's Content-Security-Policy blocks (once, at start).
pub fn install() {
    let Some(window) = web_sys::window() else {
        return;
    };
    let on_violation = Closure::<dyn FnMut(web_sys::SecurityPolicyViolationEvent)>::new(
        |e: web_sys::SecurityPolicyViolationEvent| {
            let uri = e.blocked_uri();
            log::warn!(
                "Content-Security-Policy blocked {uri} ({})",
                e.violated_directive()
            );
            BLOCKED.with(|b| b.borrow_mut().push(uri));
        },
    );
    let _ = window.add_event_listener_with_callback(
        "securitypolicyviolation",
        on_violation.as_ref().unchecked_ref(),
    );
    on_violation.forget();
}

/// Whether a download is running.
pub fn active() -> bool {
    ACTIVE.with(|a| a.borrow().is_some())
}

/// Stops the running download, if any (it reports `WebEvent::Cancelled`).
pub fn cancel() {
    if let Some(c) = ACTIVE.with(|a| a.borrow_mut().take()) {
        c.abort();
    }
}

/// Downloads `urls` (absolute) one after the other, then queues them as one load.
pub fn fetch_urls(urls: Vec<String>) {
    cancel();
    let controller = match web_sys::AbortController::new() {
        Ok(c) => c,
        Err(e) => {
            push(WebEvent::Failed {
                error: PageError::DownloadNotStarted {
                    words: js_error(&e),
                }
                .into(),
            });
            return;
        }
    };
    ACTIVE.with(|a| *a.borrow_mut() = Some(controller.clone()));
    wasm_bindgen_futures::spawn_local(async move {
        let label = match urls.as_slice() {
            [one] => file_name(one),
            many => format!("{} files from {}", many.len(), host_of(&many[0])),
        };
        let result = download_all(&urls, &controller, true).await;
        let mine = ACTIVE.with(|a| {
            let mut a = a.borrow_mut();
            let same = a.as_ref() == Some(&controller);
            if same {
                *a = None;
            }
            same
        });
        match result {
            Ok(files) if mine => push(WebEvent::Files {
                label,
                files,
                origin: ViewSource::Urls(urls),
            }),
            // Replaced by a newer download or drop: that one reports.
            Ok(_) => {}
            Err(Failure::Cancelled) => push(WebEvent::Cancelled { label }),
            Err(Failure::Error(error)) => push(WebEvent::Failed { error }),
        }
    });
}

/// Downloads the PET of a PET/CT link (`&pet=URL`, absolute) for the CT of `generation`, beside
/// any other download (it is not the page's cancellable one): its files are decoded as the
/// PET over that CT.
pub fn fetch_pet_urls(urls: Vec<String>, generation: u64) {
    let controller = match web_sys::AbortController::new() {
        Ok(c) => c,
        Err(e) => {
            push(WebEvent::PetFailed {
                error: PageError::DownloadNotStarted {
                    words: js_error(&e),
                }
                .into(),
                generation,
            });
            return;
        }
    };
    wasm_bindgen_futures::spawn_local(async move {
        let label = match urls.as_slice() {
            [one] => file_name(one),
            many => format!("{} files from {}", many.len(), host_of(&many[0])),
        };
        match download_all(&urls, &controller, false).await {
            Ok(files) => push(WebEvent::PetFiles {
                label,
                files,
                generation,
            }),
            Err(Failure::Cancelled) => push(WebEvent::PetFailed {
                error: PageError::DownloadCancelled { label }.into(),
                generation,
            }),
            Err(Failure::Error(error)) => push(WebEvent::PetFailed { error, generation }),
        }
    });
}

enum Failure {
    Cancelled,
    Error(AppError),
}

impl From<PageError> for Failure {
    fn from(e: PageError) -> Self {
        Self::Error(e.into())
    }
}

/// The file name a URL's path ends in (decoded), as loaders pair headers with data files.
fn file_name(url: &str) -> String {
    let path = url.split(['?', '#']).next().unwrap_or(url);
    let last = path
        .trim_end_matches('/')
        .rsplit('/')
        .next()
        .filter(|s| !s.is_empty() && !s.contains(':'))
        .unwrap_or("download");
    crate::io::url::decode(last)
}

/// Downloads `urls` in turn; `report`: the page's progress bar follows them (not for a PET
/// downloaded beside the volume shown, which must not take the bar of another load).
async fn download_all(
    urls: &[String],
    controller: &web_sys::AbortController,
    report: bool,
) -> Result<Vec<InputFile>, Failure> {
    let mut files: Vec<InputFile> = Vec::with_capacity(urls.len());
    let mut total_bytes: u64 = 0;
    for (n, url) in urls.iter().enumerate() {
        let mut name = file_name(url);
        if files.iter().any(|f| f.name == name) {
            name = format!("{n}-{name}");
        }
        let label = if urls.len() > 1 {
            format!("{name} ({} of {})", n + 1, urls.len())
        } else {
            name.clone()
        };
        let limit = max_download_bytes() - total_bytes;
        let bytes = download(url, &label, controller, limit, report).await?;
        total_bytes += bytes.len();
        files.push(js_bytes::into_input(bytes, name).map_err(Failure::Error)?);
    }
    Ok(files)
}

fn origin_of_page() -> String {
    web_sys::window()
        .and_then(|w| w.location().origin().ok())
        .unwrap_or_default()
}

/// Why the browser refused a fetch without saying why.
fn refusal(url: &str) -> DownloadProblem {
    let page = origin_of_page();
    let host = host_of(url);
    let blocked = BLOCKED.with(|b| {
        b.borrow()
            .iter()
            .any(|u| !u.is_empty() && (url.starts_with(u.as_str()) || u.contains(&host)))
    });
    if blocked {
        DownloadProblem::Policy { host }
    } else if url.starts_with("http:") && page.starts_with("https:") {
        DownloadProblem::PlainHttp
    } else if url.starts_with(&format!("{page}/")) {
        DownloadProblem::NoAnswer
    } else {
        DownloadProblem::Refused { host, page }
    }
}

/// What an HTTP status other than success means to the reader.
fn status_problem(url: &str, status: u16, text: &str) -> DownloadProblem {
    let host = host_of(url);
    match status {
        404 | 410 => DownloadProblem::NotFound { status },
        401 | 403 => DownloadProblem::Forbidden { host, status },
        _ => DownloadProblem::Status {
            host,
            answer: format!(
                "HTTP {status}{}{text}",
                if text.is_empty() { "" } else { " " }
            ),
        },
    }
}

fn too_large(bytes: u64) -> DownloadProblem {
    DownloadProblem::TooLarge {
        bytes,
        most: max_download_bytes(),
    }
}

/// Whether bytes look like an HTML page (after whitespace and a byte order mark).
fn looks_like_html(bytes: &[u8]) -> bool {
    let start = bytes
        .strip_prefix(b"\xEF\xBB\xBF".as_slice())
        .unwrap_or(bytes);
    let head: Vec<u8> = start
        .iter()
        .skip_while(|b| b.is_ascii_whitespace())
        .take(15)
        .map(u8::to_ascii_lowercase)
        .collect();
    head.starts_with(b"<!doctype html") || head.starts_with(b"<html") || head.starts_with(b"<head")
}

async fn download(
    url: &str,
    label: &str,
    controller: &web_sys::AbortController,
    room: u64,
    report: bool,
) -> Result<JsBytes, Failure> {
    let fail = |problem| {
        Failure::from(PageError::Download {
            url: url.to_owned(),
            problem,
        })
    };
    let signal = controller.signal();
    let window = web_sys::window().ok_or(PageError::NoWindow)?;
    if report {
        push(WebEvent::Progress {
            verb: "downloading",
            label: label.to_owned(),
            done: 0.0,
            total: 0.0,
        });
    }
    let init = web_sys::RequestInit::new();
    init.set_signal(Some(&signal));
    let response = match JsFuture::from(window.fetch_with_str_and_init(url, &init)).await {
        Ok(r) => r,
        Err(_) if signal.aborted() => return Err(Failure::Cancelled),
        Err(e) => {
            log::warn!("fetch {url}: {}", js_error(&e));
            // The policy's violation event comes as a task of its own, after the rejection.
            sleep_ms(50).await;
            return Err(fail(refusal(url)));
        }
    };
    let response: web_sys::Response = response.unchecked_into();
    if !response.ok() {
        return Err(fail(status_problem(
            url,
            response.status(),
            &response.status_text(),
        )));
    }
    let headers = response.headers();
    let content_type = headers
        .get("content-type")
        .ok()
        .flatten()
        .unwrap_or_default()
        .to_ascii_lowercase();
    if content_type.starts_with("text/html") {
        controller.abort();
        return Err(fail(DownloadProblem::WebPage));
    }
    // The declared length; with a Content-Encoding it counts the compressed bytes, while the
    // body arrives decoded, so it is only a progress hint there.
    let encoded = headers
        .get("content-encoding")
        .ok()
        .flatten()
        .is_some_and(|e| !e.is_empty() && e != "identity");
    let length: Option<u64> = headers
        .get("content-length")
        .ok()
        .flatten()
        .and_then(|l| l.trim().parse().ok());
    if let Some(n) = length
        && !encoded
        && n > room
    {
        controller.abort();
        return Err(fail(too_large(n)));
    }
    // The chunks stay JavaScript's, gathered into 16 MiB buffers as they arrive: the loader
    // reads them on demand and lets each go once read, so the wasm memory never holds the file
    // besides its voxels and the page holds the file shrinking as the voxels grow.
    let mut bytes = Gathered::default();
    let Some(body) = response.body() else {
        return Ok(JsBytes::default());
    };
    let reader: web_sys::ReadableStreamDefaultReader = body.get_reader().unchecked_into();
    let total = length.map_or(0.0, |n| n as f64);
    let mut last_report = 0u64;
    loop {
        let array = match js_bytes::next_chunk(&reader).await {
            Ok(Some(array)) => array,
            Ok(None) => break,
            Err(_) if signal.aborted() => return Err(Failure::Cancelled),
            Err(e) => {
                return Err(fail(DownloadProblem::BrokeOff {
                    bytes: bytes.len(),
                    words: js_error(&e),
                }));
            }
        };
        let new_len = bytes.len() + u64::from(array.length());
        if new_len > room {
            controller.abort();
            return Err(fail(too_large(new_len)));
        }
        bytes.push(&array);
        // A progress event per ~256 KB is plenty (chunks are often 16-64 KB).
        if report && bytes.len() - last_report >= 256 << 10 {
            last_report = bytes.len();
            push(WebEvent::Progress {
                verb: "downloading",
                label: label.to_owned(),
                done: bytes.len() as f64,
                total: total.max(bytes.len() as f64),
            });
        }
    }
    let bytes = bytes.finish();
    if looks_like_html(&bytes.head(1024)) {
        return Err(fail(DownloadProblem::WebPage));
    }
    Ok(bytes)
}

/// Waits `ms` milliseconds without blocking (a timer promise).
async fn sleep_ms(ms: i32) {
    let promise = js_sys::Promise::new(&mut |resolve, _reject| {
        if let Some(w) = web_sys::window() {
            let _ = w.set_timeout_with_callback_and_timeout_and_arguments_0(&resolve, ms);
        }
    });
    let _ = JsFuture::from(promise).await;
}
