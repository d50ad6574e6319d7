//! The native transport: a thread per task over the blocking client.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use super::super::{Event, Inbox, StoreDone, StoreJob};
use crate::io::Loaded;
use crate::io::dicomweb::client::Client;
use crate::io::dicomweb::{Auth, Base, DicomWebError, SeriesInfo, StudyInfo, StudySearch};

/// A running task: cancelling drops its answers (a blocking request in flight ends on its
/// own).
pub(in crate::app) struct Task(Arc<AtomicBool>);

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

/// Runs `work` with a client for `base` on its own thread (`work` may send events as it goes);
/// its answer, or the client's failure (a bad address), is the event `event` makes of it.
pub(super) fn run<T>(
    (base, auth): (Base, Auth),
    task: u64,
    inbox: Inbox,
    work: impl FnOnce(&Client, &dyn Fn(Event)) -> Result<T, DicomWebError> + Send + 'static,
    event: impl FnOnce(Result<T, DicomWebError>) -> Event + Send + 'static,
) -> Task {
    spawn(task, inbox, move |send| {
        let result = Client::new(base, auth).and_then(|c| work(&c, send));
        send(event(result));
    })
}

/// Blocking work on a client; it may send events (progress) as it goes.
pub(super) trait Work<T>:
    FnOnce(&Client, &dyn Fn(Event)) -> Result<T, DicomWebError> + Send + 'static
{
}

impl<T, F> Work<T> for F where
    F: FnOnce(&Client, &dyn Fn(Event)) -> Result<T, DicomWebError> + Send + 'static
{
}

pub(super) fn search(search: StudySearch) -> impl Work<Vec<StudyInfo>> {
    move |c: &Client, _: &dyn Fn(Event)| c.search_studies(&search)
}

pub(super) fn study(study: String) -> impl Work<(StudyInfo, Vec<SeriesInfo>)> {
    move |c: &Client, _: &dyn Fn(Event)| Ok((c.find_study(&study)?, c.list_series(&study)?))
}

pub(super) fn retrieve(study: String, series: String, _task: u64) -> impl Work<Loaded> {
    move |c: &Client, send: &dyn Fn(Event)| {
        c.retrieve(&study, &series, &mut |p| {
            send(Event::Progress {
                done: p.instances_done,
                total: p.instances_total,
                bytes: p.bytes,
                estimate: p.bytes_estimate,
            });
        })
    }
}

pub(super) fn store(job: StoreJob) -> impl Work<StoreDone> {
    move |c: &Client, _: &dyn Fn(Event)| {
        let mut job = job;
        let source = c.source_series(&job.study, &job.series)?;
        let (instances, skipped) = job.instances(&source)?;
        let stored = c.store(&job.study, &instances)?;
        let mut done = job.done(&instances, skipped);
        done.warnings = stored.warnings;
        Ok(done)
    }
}
