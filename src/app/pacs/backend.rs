//! The archive's work outside the frame: `fetch` tasks on the web (`io::dicomweb::web`), a
//! thread per task over the blocking client natively (`io::dicomweb::client`). Each reports
//! `Event`s into the dialog's inbox, tagged with its task.

#[cfg(not(target_arch = "wasm32"))]
pub use native::*;
#[cfg(target_arch = "wasm32")]
pub use web::*;

/// The page's transport: `fetch` tasks (wasm).
#[cfg(target_arch = "wasm32")]
mod web {
    use std::rc::Rc;

    use super::super::{Event, Inbox, PacsTarget, StoreJob};
    use crate::io::dicomweb::web::WebClient;
    use crate::io::dicomweb::{Auth, Base, DicomWebError, StudySearch};

    /// A running task: cancelling aborts its requests.
    pub struct Task(Option<Rc<WebClient>>);

    impl Task {
        pub fn cancel(&self) {
            if let Some(c) = &self.0 {
                c.cancel();
            }
        }
    }

    fn client(
        base: Base,
        auth: Auth,
        task: u64,
        inbox: &Inbox,
        fail: impl FnOnce(DicomWebError) -> Event,
    ) -> Option<Rc<WebClient>> {
        match WebClient::new(base, auth) {
            Ok(c) => Some(Rc::new(c)),
            Err(e) => {
                inbox.push(task, fail(e));
                None
            }
        }
    }

    pub fn search(base: Base, auth: Auth, search: StudySearch, task: u64, inbox: Inbox) -> Task {
        let Some(c) = client(base, auth, task, &inbox, |e| Event::Studies(Err(e))) else {
            return Task(None);
        };
        let client = c.clone();
        wasm_bindgen_futures::spawn_local(async move {
            let r = client.search_studies(&search).await;
            inbox.push(task, Event::Studies(r));
        });
        Task(Some(c))
    }

    pub fn study(base: Base, auth: Auth, target: PacsTarget, task: u64, inbox: Inbox) -> Task {
        let t = target.clone();
        let Some(c) = client(base, auth, task, &inbox, |e| Event::Study {
            target: t,
            result: Err(e),
        }) else {
            return Task(None);
        };
        let client = c.clone();
        wasm_bindgen_futures::spawn_local(async move {
            let result = async {
                let info = client.find_study(&target.study).await?;
                let series = client.list_series(&target.study).await?;
                Ok((info, series))
            }
            .await;
            inbox.push(task, Event::Study { target, result });
        });
        Task(Some(c))
    }

    pub fn retrieve(base: Base, auth: Auth, target: PacsTarget, task: u64, inbox: Inbox) -> Task {
        let t = target.clone();
        let Some(c) = client(base, auth, task, &inbox, |e| Event::Retrieved {
            target: t,
            result: Box::new(Err(e)),
        }) else {
            return Task(None);
        };
        let client = c.clone();
        wasm_bindgen_futures::spawn_local(async move {
            let series = target.series.clone().unwrap_or_default();
            let progress_inbox = inbox.clone();
            let result = client
                .retrieve(&target.study, &series, &mut |p| {
                    progress_inbox.push(
                        task,
                        Event::Progress {
                            done: p.retrieval.instances_done,
                            total: p.retrieval.instances_total,
                            bytes: p.streamed_bytes.max(p.retrieval.bytes),
                            estimate: p.retrieval.bytes_estimate,
                        },
                    );
                })
                .await;
            inbox.push(
                task,
                Event::Retrieved {
                    target,
                    result: Box::new(result),
                },
            );
        });
        Task(Some(c))
    }

    /// Stores a rotation into its study (the source series' metadata, then STOW-RS).
    pub fn store(base: Base, auth: Auth, job: StoreJob, task: u64, inbox: Inbox) -> Task {
        let Some(c) = client(base, auth, task, &inbox, |e| Event::Stored(Err(e))) else {
            return Task(None);
        };
        let client = c.clone();
        wasm_bindgen_futures::spawn_local(async move {
            let result = async {
                let mut job = job;
                let source = client.source_series(&job.study, &job.series).await?;
                let (instances, skipped) = job.instances(&source)?;
                let stored = client.store(&job.study, &instances).await?;
                let mut done = job.done(&instances, skipped);
                done.warnings = stored.warnings;
                Ok(done)
            }
            .await;
            inbox.push(task, Event::Stored(result));
        });
        Task(Some(c))
    }

    /// `#token=...` of the page's address, removed from the address bar (the rest of the
    /// fragment stays).
    pub fn take_fragment_token() -> Option<String> {
        let window = web_sys::window()?;
        let hash = window.location().hash().ok()?;
        let fragment = hash.trim_start_matches('#');
        let params = crate::io::url::parse_params(fragment);
        let token = params
            .iter()
            .rev()
            .find(|(k, _)| k == "token")
            .map(|(_, v)| v.clone())?;
        let rest: Vec<&str> = fragment
            .split('&')
            .filter(|kv| kv.split('=').next() != Some("token"))
            .collect();
        let location = window.location();
        let url = format!(
            "{}{}{}",
            location.pathname().unwrap_or_default(),
            location.search().unwrap_or_default(),
            if rest.is_empty() {
                String::new()
            } else {
                format!("#{}", rest.join("&"))
            }
        );
        if let Ok(history) = window.history() {
            let _ = history.replace_state_with_url(&wasm_bindgen::JsValue::NULL, "", Some(&url));
        }
        Some(token)
    }

    /// Whether the page's query names a token (refused).
    pub fn query_has_token() -> bool {
        crate::app::platform::web::files::query_params()
            .iter()
            .any(|(k, _)| k == "token")
    }
}

/// The native transport: a thread per task over the blocking client.
#[cfg(not(target_arch = "wasm32"))]
mod native {
    use std::sync::Arc;
    use std::sync::atomic::{AtomicBool, Ordering};

    use super::super::{Event, Inbox, PacsTarget, StoreJob};
    use crate::io::dicomweb::client::Client;
    use crate::io::dicomweb::{Auth, Base, StudySearch};

    /// A running task: cancelling drops its answers (a blocking request in flight ends on its
    /// own).
    pub struct Task(Arc<AtomicBool>);

    impl Task {
        pub fn cancel(&self) {
            self.0.store(true, Ordering::Relaxed);
        }
    }

    fn spawn(task: u64, inbox: Inbox, work: impl FnOnce(&dyn Fn(Event)) + Send + 'static) -> Task {
        let cancelled = Arc::new(AtomicBool::new(false));
        let flag = cancelled.clone();
        let spawned = std::thread::Builder::new()
            .name("dicomweb".to_owned())
            .spawn(move || {
                let send = |e: Event| {
                    if !flag.load(Ordering::Relaxed) {
                        inbox.push(task, e);
                    }
                };
                work(&send);
            });
        if let Err(e) = spawned {
            log::error!("cannot start a DICOMweb thread: {e}");
        }
        Task(cancelled)
    }

    pub fn search(base: Base, auth: Auth, search: StudySearch, task: u64, inbox: Inbox) -> Task {
        spawn(task, inbox, move |send| {
            let r = Client::new(base, auth).and_then(|c| c.search_studies(&search));
            send(Event::Studies(r));
        })
    }

    pub fn study(base: Base, auth: Auth, target: PacsTarget, task: u64, inbox: Inbox) -> Task {
        spawn(task, inbox, move |send| {
            let result = Client::new(base, auth)
                .and_then(|c| Ok((c.find_study(&target.study)?, c.list_series(&target.study)?)));
            send(Event::Study { target, result });
        })
    }

    pub fn retrieve(base: Base, auth: Auth, target: PacsTarget, task: u64, inbox: Inbox) -> Task {
        spawn(task, inbox, move |send| {
            let series = target.series.clone().unwrap_or_default();
            let result = Client::new(base, auth).and_then(|c| {
                c.retrieve(&target.study, &series, &mut |p| {
                    send(Event::Progress {
                        done: p.instances_done,
                        total: p.instances_total,
                        bytes: p.bytes,
                        estimate: p.bytes_estimate,
                    });
                })
            });
            send(Event::Retrieved {
                target,
                result: Box::new(result),
            });
        })
    }

    /// Stores a rotation into its study (the source series' metadata, then STOW-RS).
    pub fn store(base: Base, auth: Auth, job: StoreJob, task: u64, inbox: Inbox) -> Task {
        spawn(task, inbox, move |send| {
            let mut job = job;
            let result = Client::new(base, auth).and_then(|c| {
                let source = c.source_series(&job.study, &job.series)?;
                let (instances, skipped) = job.instances(&source)?;
                let stored = c.store(&job.study, &instances)?;
                let mut done = job.done(&instances, skipped);
                done.warnings = stored.warnings;
                Ok(done)
            });
            send(Event::Stored(result));
        })
    }
}
