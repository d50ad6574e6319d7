//! The page's transport: `fetch` tasks.

use std::rc::Rc;

use super::super::{Event, Inbox, PacsTarget, StoreJob};
use crate::io::dicomweb::web::WebClient;
use crate::io::dicomweb::{Auth, Base, DicomWebError, StudySearch};

/// A running task: cancelling aborts its requests.
pub(in crate::app) struct Task(Option<Rc<WebClient>>);

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

/// Runs `work` on a client for `base` as a `fetch` task; a client that cannot be made (a bad
/// address) is `fail`'s event at once.
fn run<F: std::future::Future<Output = ()> + 'static>(
    (base, auth): (Base, Auth),
    task: u64,
    inbox: &Inbox,
    fail: impl FnOnce(DicomWebError) -> Event,
    work: impl FnOnce(Rc<WebClient>) -> F,
) -> Task {
    let Some(c) = client(base, auth, task, inbox, fail) else {
        return Task(None);
    };
    wasm_bindgen_futures::spawn_local(work(c.clone()));
    Task(Some(c))
}

pub(in crate::app) fn search(
    base: Base,
    auth: Auth,
    search: StudySearch,
    task: u64,
    inbox: Inbox,
) -> Task {
    let fail = |e| Event::Studies(Err(e));
    run(
        (base, auth),
        task,
        &inbox.clone(),
        fail,
        move |client| async move {
            let r = client.search_studies(&search).await;
            inbox.push(task, Event::Studies(r));
        },
    )
}

pub(in crate::app) fn study(
    base: Base,
    auth: Auth,
    target: PacsTarget,
    task: u64,
    inbox: Inbox,
) -> Task {
    let t = target.clone();
    let fail = |e| Event::Study {
        target: t,
        result: Err(e),
    };
    run(
        (base, auth),
        task,
        &inbox.clone(),
        fail,
        move |client| async move {
            let result = async {
                let info = client.find_study(&target.study).await?;
                let series = client.list_series(&target.study).await?;
                Ok((info, series))
            }
            .await;
            inbox.push(task, Event::Study { target, result });
        },
    )
}

pub(in crate::app) fn retrieve(
    base: Base,
    auth: Auth,
    target: PacsTarget,
    task: u64,
    inbox: Inbox,
) -> Task {
    let t = target.clone();
    let fail = |e| Event::Retrieved {
        target: t,
        result: Box::new(Err(e)),
    };
    run(
        (base, auth),
        task,
        &inbox.clone(),
        fail,
        move |client| async move {
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
        },
    )
}

/// Stores a rotation into its study (the source series' metadata, then STOW-RS).
pub(in crate::app) fn store(
    base: Base,
    auth: Auth,
    job: StoreJob,
    task: u64,
    inbox: Inbox,
) -> Task {
    let fail = |e| Event::Stored(Err(e));
    run(
        (base, auth),
        task,
        &inbox.clone(),
        fail,
        move |client| async move {
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
        },
    )
}
