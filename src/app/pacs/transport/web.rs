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

/// Runs `work` with a client for `base` as a `fetch` task (`work` gets the inbox for events
/// it sends as it goes); its answer, or the client's failure (a bad address, at once), is the
/// event `event` makes of it.
fn run<T, F: std::future::Future<Output = Result<T, DicomWebError>> + 'static>(
    (base, auth): (Base, Auth),
    task: u64,
    inbox: Inbox,
    work: impl FnOnce(Rc<WebClient>, Inbox) -> F,
    event: impl FnOnce(Result<T, DicomWebError>) -> Event + 'static,
) -> Task {
    match WebClient::new(base, auth) {
        Err(e) => {
            inbox.push(task, event(Err(e)));
            Task(None)
        }
        Ok(client) => {
            let client = Rc::new(client);
            let answer = work(client.clone(), inbox.clone());
            wasm_bindgen_futures::spawn_local(async move {
                let result = answer.await;
                inbox.push(task, event(result));
            });
            Task(Some(client))
        }
    }
}

pub(in crate::app) fn search(
    base: Base,
    auth: Auth,
    search: StudySearch,
    task: u64,
    inbox: Inbox,
) -> Task {
    let work = |c: Rc<WebClient>, _| async move { c.search_studies(&search).await };
    run((base, auth), task, inbox, work, Event::Studies)
}

pub(in crate::app) fn study(
    base: Base,
    auth: Auth,
    target: PacsTarget,
    task: u64,
    inbox: Inbox,
) -> Task {
    let study = target.study.clone();
    let work = |c: Rc<WebClient>, _| async move {
        Ok((c.find_study(&study).await?, c.list_series(&study).await?))
    };
    let event = move |result| Event::Study { target, result };
    run((base, auth), task, inbox, work, event)
}

pub(in crate::app) fn retrieve(
    base: Base,
    auth: Auth,
    target: PacsTarget,
    task: u64,
    inbox: Inbox,
) -> Task {
    let (study, series) = (
        target.study.clone(),
        target.series.clone().unwrap_or_default(),
    );
    let work = move |c: Rc<WebClient>, progress: Inbox| async move {
        c.retrieve(&study, &series, &mut |p| {
            progress.push(
                task,
                Event::Progress {
                    done: p.retrieval.instances_done,
                    total: p.retrieval.instances_total,
                    bytes: p.streamed_bytes.max(p.retrieval.bytes),
                    estimate: p.retrieval.bytes_estimate,
                },
            );
        })
        .await
    };
    let event = move |result| Event::Retrieved {
        target,
        result: Box::new(result),
    };
    run((base, auth), task, inbox, work, event)
}

/// Stores a rotation into its study (the source series' metadata, then STOW-RS).
pub(in crate::app) fn store(
    base: Base,
    auth: Auth,
    job: StoreJob,
    task: u64,
    inbox: Inbox,
) -> Task {
    let work = |c: Rc<WebClient>, _| async move {
        let mut job = job;
        let source = c.source_series(&job.study, &job.series).await?;
        let (instances, skipped) = job.instances(&source)?;
        let stored = c.store(&job.study, &instances).await?;
        let mut done = job.done(&instances, skipped);
        done.warnings = stored.warnings;
        Ok(done)
    };
    run((base, auth), task, inbox, work, Event::Stored)
}
