//! The native transport: a thread per task over the blocking client.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use super::super::{Event, Inbox, PacsTarget, StoreJob};
use crate::io::dicomweb::client::Client;
use crate::io::dicomweb::{Auth, Base, StudySearch};

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

pub(in crate::app) fn search(
    base: Base,
    auth: Auth,
    search: StudySearch,
    task: u64,
    inbox: Inbox,
) -> Task {
    spawn(task, inbox, move |send| {
        let r = Client::new(base, auth).and_then(|c| c.search_studies(&search));
        send(Event::Studies(r));
    })
}

pub(in crate::app) fn study(
    base: Base,
    auth: Auth,
    target: PacsTarget,
    task: u64,
    inbox: Inbox,
) -> Task {
    spawn(task, inbox, move |send| {
        let result = Client::new(base, auth)
            .and_then(|c| Ok((c.find_study(&target.study)?, c.list_series(&target.study)?)));
        send(Event::Study { target, result });
    })
}

pub(in crate::app) fn retrieve(
    base: Base,
    auth: Auth,
    target: PacsTarget,
    task: u64,
    inbox: Inbox,
) -> Task {
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
pub(in crate::app) fn store(
    base: Base,
    auth: Auth,
    job: StoreJob,
    task: u64,
    inbox: Inbox,
) -> Task {
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
