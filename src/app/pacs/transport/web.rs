//! The page's transport: `fetch` tasks.

use std::future::Future;
use std::pin::Pin;
use std::rc::Rc;

use super::super::{Event, Inbox, StoreDone, StoreJob};
use crate::io::Loaded;
use crate::io::dicomweb::web::WebClient;
use crate::io::dicomweb::{Auth, Base, DicomWebError, SeriesInfo, StudyInfo, StudySearch};

/// A running task: cancelling aborts its requests.
pub(in crate::app) struct Task(Option<Rc<WebClient>>);

impl Task {
    pub fn cancel(&self) {
        if let Some(c) = &self.0 {
            c.cancel();
        }
    }
}

/// What a task's work answers, in time.
pub(super) type Answer<T> = Pin<Box<dyn Future<Output = Result<T, DicomWebError>>>>;

/// Runs `work` with a client for `base` as a `fetch` task (`work` gets the inbox for events
/// it sends as it goes); its answer, or the client's failure (a bad address, at once), is the
/// event `event` makes of it.
pub(super) fn run<T: 'static>(
    (base, auth): (Base, Auth),
    task: u64,
    inbox: Inbox,
    work: impl FnOnce(Rc<WebClient>, Inbox) -> Answer<T>,
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

pub(super) fn search(
    search: StudySearch,
) -> impl FnOnce(Rc<WebClient>, Inbox) -> Answer<Vec<StudyInfo>> {
    |c, _| Box::pin(async move { c.search_studies(&search).await })
}

pub(super) fn study(
    study: String,
) -> impl FnOnce(Rc<WebClient>, Inbox) -> Answer<(StudyInfo, Vec<SeriesInfo>)> {
    |c, _| Box::pin(async move { Ok((c.find_study(&study).await?, c.list_series(&study).await?)) })
}

pub(super) fn retrieve(
    study: String,
    series: String,
    task: u64,
) -> impl FnOnce(Rc<WebClient>, Inbox) -> Answer<Loaded> {
    move |c, progress| {
        Box::pin(async move {
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
        })
    }
}

pub(super) fn store(job: StoreJob) -> impl FnOnce(Rc<WebClient>, Inbox) -> Answer<StoreDone> {
    |c, _| {
        Box::pin(async move {
            let mut job = job;
            let source = c.source_series(&job.study, &job.series).await?;
            let (instances, skipped) = job.instances(&source)?;
            let stored = c.store(&job.study, &instances).await?;
            let mut done = job.done(&instances, skipped);
            done.warnings = stored.warnings;
            Ok(done)
        })
    }
}
