//! The native transport: a thread per task over the blocking client.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use super::super::{Event, Inbox, PacsTarget, StoreJob};
use crate::io::dicomweb::client::Client;
use crate::io::dicomweb::{Auth, Base, DicomWebError, StudySearch};

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
fn run<T>(
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

pub(in crate::app) fn search(
    base: Base,
    auth: Auth,
    search: StudySearch,
    task: u64,
    inbox: Inbox,
) -> Task {
    let work = move |c: &Client, _: &dyn Fn(Event)| c.search_studies(&search);
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
    let work =
        move |c: &Client, _: &dyn Fn(Event)| Ok((c.find_study(&study)?, c.list_series(&study)?));
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
    let work = move |c: &Client, send: &dyn Fn(Event)| {
        c.retrieve(&study, &series, &mut |p| {
            send(Event::Progress {
                done: p.instances_done,
                total: p.instances_total,
                bytes: p.bytes,
                estimate: p.bytes_estimate,
            });
        })
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
    let work = move |c: &Client, _: &dyn Fn(Event)| {
        let mut job = job;
        let source = c.source_series(&job.study, &job.series)?;
        let (instances, skipped) = job.instances(&source)?;
        let stored = c.store(&job.study, &instances)?;
        let mut done = job.done(&instances, skipped);
        done.warnings = stored.warnings;
        Ok(done)
    };
    run((base, auth), task, inbox, work, Event::Stored)
}
