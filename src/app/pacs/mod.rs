//! "Open from PACS…" and the page's `?dicomweb=BASE&study=UID[&series=UID]`: a study found in
//! an archive over DICOMweb (QIDO-RS by patient ID, accession number and date), its series
//! listed (the CT or MR series with the most instances preselected), one retrieved (WADO-RS,
//! decoded as instances arrive) and installed like a drop. A PET/CT study opens its CT and then
//! retrieves its PET series (the largest PT) to fuse over it, as a dropped PET/CT folder does. The archive's work runs outside the
//! frame: `fetch` tasks on the web (`io::dicomweb::web`), a thread natively
//! (`io::dicomweb::client`); their answers come back as [`Event`]s taken once per frame.
//!
//! Credentials: an optional bearer token, typed here or given as `#token=` in the page's
//! fragment, which is then removed from the address bar. A token in the query string (sent to
//! servers, written to their logs) is refused. It never goes into a link (`ViewSource::DicomWeb`
//! has no place for it). A 401/403 opens this dialog asking for one.
//!
//! The loaded study's patient (name, ID, birth date), study date and series description, from a
//! DICOMweb retrieval or a dropped DICOM series, are shown in a line above the panes (and
//! natively in the window title) and nowhere else: not in links, `window.shapecastStatus` or
//! logs.

use std::collections::VecDeque;
use std::sync::{Arc, Mutex};

mod patient;
mod pet;
mod store;
pub(super) mod ui;

pub use patient::patient_line;
use patient::{merge_patient, study_summary};
use pet::{PET_TASK, PetRetrieval};
use store::STORE_TASK;
pub(in crate::app) use store::StoreDone;
pub(super) use store::StoreJob;

mod transport;

use super::platform::Platform as _;
use super::{ShapecastApp, ViewSource};
use crate::io::dicomweb::{
    self, Auth, Base, DicomWebError, SeriesInfo, StudyInfo, StudySearch, pick_series,
};
use crate::io::{Loaded, Patient};
use transport as backend;

/// A study to open: the archive's DICOMweb root (absolute, or relative to the page's origin),
/// the study, and the series (`None`: the chooser's pick).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct PacsTarget {
    pub base: String,
    pub study: String,
    pub series: Option<String>,
}

/// What the archive's work reports back.
pub(in crate::app) enum Event {
    Studies(Result<Vec<StudyInfo>, DicomWebError>),
    Study {
        target: PacsTarget,
        result: Result<(StudyInfo, Vec<SeriesInfo>), DicomWebError>,
    },
    Progress {
        done: usize,
        total: usize,
        bytes: u64,
        estimate: Option<u64>,
    },
    Retrieved {
        target: PacsTarget,
        result: Box<Result<Loaded, DicomWebError>>,
    },
    /// A result stored into the archive ("Store to PACS").
    Stored(Result<StoreDone, DicomWebError>),
}

/// Where answers go: each is tagged with the task it belongs to, so a cancelled or replaced
/// task's late answers are dropped.
#[derive(Clone, Default)]
pub(in crate::app) struct Inbox {
    queue: Arc<Mutex<VecDeque<(u64, Event)>>>,
    ctx: Arc<Mutex<Option<egui::Context>>>,
}

impl Inbox {
    pub(in crate::app) fn push(&self, task: u64, event: Event) {
        if let Ok(mut q) = self.queue.lock() {
            q.push_back((task, event));
        }
        if let Ok(c) = self.ctx.lock()
            && let Some(ctx) = c.as_ref()
        {
            ctx.request_repaint();
        }
    }

    fn take(&self) -> Vec<(u64, Event)> {
        self.queue
            .lock()
            .map(|mut q| q.drain(..).collect())
            .unwrap_or_default()
    }
}

/// The dialog's state, the running task and the patient line.
#[derive(Default)]
pub(super) struct Pacs {
    /// The dialog is shown.
    pub dialog: bool,
    server: String,
    /// The bearer token typed or taken from the fragment (never logged, never in a link).
    token: String,
    search: StudySearch,
    studies: Vec<StudyInfo>,
    /// The archive may hold more matches than the page listed.
    more: bool,
    /// The study whose series are listed, with its archive.
    study: Option<(String, StudyInfo)>,
    series: Vec<SeriesInfo>,
    selected: Option<usize>,
    /// The chooser's pick of `series`.
    preselected: Option<usize>,
    /// A problem to show in the dialog (e.g. that a token is needed).
    message: Option<String>,
    needs_token: bool,
    /// The study last asked for and whether it was to be opened, for "Open again" once a token
    /// is given.
    last: Option<(PacsTarget, bool)>,
    /// The error this dialog last put in the app's list (taken away once a study opens).
    error_shown: Option<String>,
    /// What the running task does, if one runs.
    pub busy: Option<String>,
    retrieving: bool,
    task: u64,
    running: Option<backend::Task>,
    inbox: Inbox,
    /// The PET of a PET/CT study, retrieved after its CT is shown.
    pet: Option<PetRetrieval>,
    /// PET retrievals started (their task ids are `PET_TASK | n`).
    pet_tasks: u64,
    /// "Store to PACS" on its way: its task (`STORE_TASK | n`) and the work.
    store: Option<(u64, backend::Task)>,
    store_tasks: u64,
    /// Series stored this session.
    stored: Vec<String>,
    /// When the last store ended well (egui time), for its "stored" feedback.
    pub stored_at: Option<f64>,
    /// The loaded study's patient (the line above the panes).
    pub patient: Option<Patient>,
}

impl Pacs {
    fn auth(&self) -> Result<Auth, DicomWebError> {
        if self.token.trim().is_empty() {
            Ok(Auth::None)
        } else {
            Auth::bearer(&self.token)
        }
    }

    /// Stops the running task (its late answers are dropped) and starts numbering a new one.
    fn next_task(&mut self) -> u64 {
        if let Some(t) = self.running.take() {
            t.cancel();
        }
        self.task += 1;
        self.task
    }
}

impl ShapecastApp {
    /// Opens a study from an archive: its series are listed, and the one named (or the
    /// chooser's pick) is retrieved and shown. An empty study opens the search dialog.
    pub fn open_dicomweb(&mut self, target: PacsTarget) {
        self.pacs.server = target.base.clone();
        if target.study.trim().is_empty() {
            self.pacs.dialog = true;
            return;
        }
        self.pacs_open_study(target, true);
    }

    /// The patient line shown above the panes, if the loaded study has one.
    pub fn patient_line(&self) -> Option<String> {
        self.pacs.patient.as_ref().and_then(patient_line)
    }

    /// Whether the "Open from PACS" dialog is shown, and the message it shows.
    pub fn pacs_dialog(&self) -> (bool, Option<&str>) {
        (self.pacs.dialog, self.pacs.message.as_deref())
    }

    /// Reads the token from the page's address (`#token=`), then removes it there.
    pub(super) fn pacs_start(&mut self, ctx: &egui::Context) {
        if let Ok(mut c) = self.pacs.inbox.ctx.lock() {
            *c = Some(ctx.clone());
        }
        if let Some(token) = super::platform::take_fragment_token() {
            self.pacs.token = token;
        }
        if super::platform::query_has_token() {
            self.error(
                "a token in the address's query (?token=) is sent to servers and kept in their logs, so it was not used: give it after # (#token=...), or type it under \"Open from PACS…\"".to_owned(),
            );
        }
    }

    fn pacs_fail(&mut self, e: DicomWebError) {
        self.pacs.busy = None;
        self.pacs.retrieving = false;
        self.pacs.running = None;
        self.load_progress = None;
        if matches!(e, DicomWebError::Cancelled) {
            self.notes.push("DICOMweb retrieval cancelled".to_owned());
            return;
        }
        if matches!(e, DicomWebError::Unauthorized { .. }) {
            self.pacs.needs_token = true;
            self.pacs.dialog = true;
            self.pacs.message = Some(format!(
                "{}. Paste a bearer token below (or give it in the link after #, as #token=...), then open the study again.",
                crate::error::chain(&e)
            ));
        } else {
            self.pacs.message = Some(crate::error::chain(&e));
        }
        self.pacs.error_shown = Some(crate::error::chain(&e));
        self.error(crate::error::chain(&e));
    }

    fn pacs_search(&mut self) {
        let (base, auth) =
            match Base::parse(&self.pacs.server).and_then(|b| Ok((b, self.pacs.auth()?))) {
                Ok(x) => x,
                Err(e) => {
                    self.pacs.message = Some(crate::error::chain(&e));
                    return;
                }
            };
        if let Err(e) = base.study_search(&self.pacs.search) {
            self.pacs.message = Some(crate::error::chain(&e));
            return;
        }
        let task = self.pacs.next_task();
        self.pacs.message = None;
        self.pacs.busy = Some(format!("searching {}", base.as_str()));
        self.pacs.running = Some(backend::search(
            base,
            auth,
            self.pacs.search.clone(),
            task,
            self.pacs.inbox.clone(),
        ));
    }

    fn pacs_open_study(&mut self, target: PacsTarget, auto_open: bool) {
        let parsed = Base::parse(&target.base).and_then(|b| {
            dicomweb::check_uid("StudyInstanceUID", &target.study)?;
            if let Some(s) = &target.series {
                dicomweb::check_uid("SeriesInstanceUID", s)?;
            }
            Ok((b, self.pacs.auth()?))
        });
        let (base, auth) = match parsed {
            Ok(x) => x,
            Err(e) => return self.pacs_fail(e),
        };
        self.pacs.last = Some((target.clone(), auto_open));
        let task = self.pacs.next_task();
        self.pacs.message = None;
        self.pacs.series.clear();
        self.pacs.selected = None;
        let what = format!("asking {} for study {}", base.as_str(), target.study);
        self.pacs.busy = Some(what.clone());
        if auto_open {
            self.cancel_upload();
            self.load_progress = Some((0.0, what));
        }
        self.pacs.retrieving = auto_open;
        self.pacs.running = Some(backend::study(
            base,
            auth,
            target,
            task,
            self.pacs.inbox.clone(),
        ));
    }

    fn pacs_retrieve(&mut self, target: PacsTarget) {
        let Some(series) = target.series.clone() else {
            return;
        };
        let parsed = Base::parse(&target.base).and_then(|b| Ok((b, self.pacs.auth()?)));
        let (base, auth) = match parsed {
            Ok(x) => x,
            Err(e) => return self.pacs_fail(e),
        };
        self.pacs.last = Some((target.clone(), true));
        let task = self.pacs.next_task();
        let what = format!("retrieving series {series} from {}", base.as_str());
        self.pacs.busy = Some(what.clone());
        self.pacs.retrieving = true;
        self.cancel_upload();
        self.load_progress = Some((0.0, what));
        self.pacs.running = Some(backend::retrieve(
            base,
            auth,
            target,
            task,
            self.pacs.inbox.clone(),
        ));
    }

    /// Stops the running search or retrieval; the volume shown stays.
    pub fn cancel_dicomweb(&mut self) {
        if self.pacs.running.is_some() || self.pacs.busy.is_some() {
            self.pacs.next_task();
            self.pacs_fail(DicomWebError::Cancelled);
        }
    }

    /// Takes the archive's answers (once per frame).
    pub(super) fn pacs_frame(&mut self, ctx: &egui::Context) {
        for (task, event) in self.pacs.inbox.take() {
            if task & STORE_TASK != 0 {
                if self.pacs.store.as_ref().is_some_and(|(t, _)| *t == task) {
                    self.pacs.store = None;
                    if let Event::Stored(result) = event {
                        self.pacs_stored(result, ctx.input(|i| i.time));
                    }
                }
                continue;
            }
            if task & PET_TASK != 0 {
                // The PET's answers; a cancelled one's late answers are dropped.
                if self.pacs.pet.as_ref().is_some_and(|p| p.task == task) {
                    self.pacs_pet_event(event);
                }
                continue;
            }
            if task != self.pacs.task {
                continue;
            }
            match event {
                Event::Studies(Ok(studies)) => {
                    self.pacs.busy = None;
                    self.pacs.running = None;
                    let first = self.pacs.search.offset;
                    self.pacs.message = studies.is_empty().then(|| {
                        if first == 0 {
                            "no study matches".to_owned()
                        } else {
                            format!("no more matches after the first {first}")
                        }
                    });
                    if studies.len() >= StudySearch::LIMIT || first > 0 {
                        self.pacs.message = Some(format!(
                            "matches {} to {} are listed: narrow the search, or page with Previous / Next",
                            first + 1,
                            first + studies.len()
                        ));
                    }
                    self.pacs.more = studies.len() >= StudySearch::LIMIT;
                    self.pacs.studies = studies;
                }
                Event::Studies(Err(e)) => {
                    self.pacs.busy = None;
                    self.pacs.running = None;
                    if matches!(e, DicomWebError::Unauthorized { .. }) {
                        self.pacs_fail(e);
                    } else {
                        self.pacs.message = Some(crate::error::chain(&e));
                    }
                }
                Event::Study { target, result } => match result {
                    Ok((info, series)) => {
                        let base = Base::parse(&target.base).ok();
                        let pick = base.as_ref().map(|b| {
                            pick_series(b, &target.study, &series, target.series.as_deref())
                        });
                        self.pacs.preselected =
                            base.as_ref().and_then(|_| dicomweb::choose_series(&series));
                        self.pacs.study = Some((target.base.clone(), info));
                        self.pacs.series = series;
                        match pick {
                            Some(Ok((i, _))) => {
                                self.pacs.selected = Some(i);
                                if self.pacs.retrieving {
                                    let uid = self.pacs.series[i].series_uid.clone();
                                    self.pacs_retrieve(PacsTarget {
                                        series: Some(uid),
                                        ..target
                                    });
                                } else {
                                    self.pacs.busy = None;
                                    self.pacs.running = None;
                                }
                            }
                            Some(Err(e)) => self.pacs_fail(e),
                            None => {}
                        }
                    }
                    Err(e) => self.pacs_fail(e),
                },
                Event::Progress {
                    done,
                    total,
                    bytes,
                    estimate,
                } => {
                    let fraction = done as f32 / total.max(1) as f32;
                    let mb = |b: u64| b as f64 / 1e6;
                    let what = match estimate {
                        Some(e) => format!(
                            "retrieving {done} of {total} instances ({:.1} of ~{:.1} MB)",
                            mb(bytes),
                            mb(e.max(bytes))
                        ),
                        None => format!(
                            "retrieving {done} of {total} instances ({:.1} MB)",
                            mb(bytes)
                        ),
                    };
                    self.load_progress = Some((fraction, what));
                }
                // Only store tasks report this (handled above).
                Event::Stored(_) => {}
                Event::Retrieved { target, result } => {
                    self.pacs.busy = None;
                    self.pacs.retrieving = false;
                    self.pacs.running = None;
                    self.load_progress = None;
                    match *result {
                        Ok(mut loaded) => {
                            let study = self.pacs.study.as_ref().map(|(_, s)| s.clone());
                            let series = self.pacs.selected.and_then(|i| self.pacs.series.get(i));
                            if let Some(study) = &study {
                                loaded.patient =
                                    Some(merge_patient(loaded.patient.take(), study, series));
                            }
                            self.pacs.dialog = false;
                            self.pacs.needs_token = false;
                            self.pacs.message = None;
                            // What the last attempt failed with is past now.
                            if let Some(old) = self.pacs.error_shown.take() {
                                self.errors.retain(|e| *e != old);
                            }
                            self.loading_origin = Some(ViewSource::DicomWeb {
                                base: target.base,
                                study: target.study,
                                series: target.series.unwrap_or_default(),
                            });
                            self.install(loaded, None);
                        }
                        Err(e) => self.pacs_fail(e),
                    }
                }
            }
        }
        self.pacs_title(ctx);
    }

    /// Natively the window title names the patient too (the page's title never does: it is
    /// the tab's name in a browser's history).
    fn pacs_title(&mut self, ctx: &egui::Context) {
        let title = match self.pacs.patient.as_ref().and_then(patient_line) {
            Some(line) => format!("Shapecast: {line}"),
            None => "Shapecast".to_owned(),
        };
        self.platform.set_title(ctx, title);
    }
}
