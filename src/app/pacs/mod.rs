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

mod backend;
mod store;
mod ui;

pub(super) use store::StoreJob;
use store::{STORE_TASK, StoreDone};

use super::{ShapecastApp, ViewSource};
use crate::io::dicomweb::{
    self, Auth, Base, DicomWebError, SeriesInfo, StudyInfo, StudySearch, pick_series,
};
use crate::io::{Loaded, Patient};

/// A study to open: the archive's DICOMweb root (absolute, or relative to the page's origin),
/// the study, and the series (`None`: the chooser's pick).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct PacsTarget {
    pub base: String,
    pub study: String,
    pub series: Option<String>,
}

/// What the archive's work reports back.
enum Event {
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
struct Inbox {
    queue: Arc<Mutex<VecDeque<(u64, Event)>>>,
    ctx: Arc<Mutex<Option<egui::Context>>>,
}

impl Inbox {
    fn push(&self, task: u64, event: Event) {
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

/// The tag of a PET retrieval's task ids: their own range, apart from the dialog's tasks
/// (`Pacs::task`), so that neither replaces nor receives the other's answers.
const PET_TASK: u64 = 1 << 63;

/// A PET/CT study's PET on its way: its task, the generation of the CT it goes over, and the
/// retrieval (cancelled when another CT is shown).
struct PetRetrieval {
    task: u64,
    generation: u64,
    running: backend::Task,
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
    busy: Option<String>,
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
    /// The window title set last (native).
    #[cfg(not(target_arch = "wasm32"))]
    title: Option<String>,
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

/// "DOE, JANE · ID P-7 · born 1970-01-01 · study 2024-01-02 · Thorax 1.0 B70f": the patient
/// line, from what is known (`None` when nothing is).
pub fn patient_line(p: &Patient) -> Option<String> {
    let date = |d: &str| {
        if d.len() == 8 && d.bytes().all(|b| b.is_ascii_digit()) {
            format!("{}-{}-{}", &d[..4], &d[4..6], &d[6..])
        } else {
            d.to_owned()
        }
    };
    let name = p.name.as_ref().map(|n| {
        n.split('^')
            .map(str::trim)
            .filter(|s| !s.is_empty())
            .collect::<Vec<_>>()
            .join(", ")
    });
    let parts: Vec<String> = [
        name.filter(|n| !n.is_empty()),
        p.id.as_ref().map(|i| format!("ID {i}")),
        p.birth_date.as_deref().map(|d| format!("born {}", date(d))),
        p.study_date
            .as_deref()
            .map(|d| format!("study {}", date(d))),
        p.series_description.clone(),
    ]
    .into_iter()
    .flatten()
    .collect();
    (!parts.is_empty()).then(|| parts.join(" · "))
}

/// The patient of a retrieved series: what its images say, completed by the archive's listing.
fn merge_patient(
    images: Option<Patient>,
    study: &StudyInfo,
    series: Option<&SeriesInfo>,
) -> Patient {
    let mut p = images.unwrap_or_default();
    p.name = p.name.or_else(|| study.patient_name.clone());
    p.id = p.id.or_else(|| study.patient_id.clone());
    p.birth_date = p.birth_date.or_else(|| study.patient_birth_date.clone());
    p.study_date = p.study_date.or_else(|| study.study_date.clone());
    p.series_description = p
        .series_description
        .or_else(|| series.and_then(|s| s.description.clone()));
    p
}

/// One line of the study list.
fn study_summary(s: &StudyInfo) -> String {
    let mut parts: Vec<String> = Vec::new();
    if let Some(d) = &s.study_date {
        parts.push(d.clone());
    }
    if let Some(n) = &s.patient_name {
        parts.push(n.replace('^', ", "));
    }
    if let Some(i) = &s.patient_id {
        parts.push(format!("ID {i}"));
    }
    if let Some(a) = &s.accession_number {
        parts.push(format!("acc. {a}"));
    }
    if !s.modalities.is_empty() {
        parts.push(s.modalities.join("/"));
    }
    if let Some(d) = &s.description {
        parts.push(format!("\"{d}\""));
    }
    if let Some(n) = s.series_count {
        parts.push(format!("{n} series"));
    }
    if parts.is_empty() {
        parts.push(s.study_uid.clone());
    }
    parts.join("  ")
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
        #[cfg(target_arch = "wasm32")]
        {
            if let Some(token) = backend::take_fragment_token() {
                self.pacs.token = token;
            }
            if backend::query_has_token() {
                self.error(
                    "a token in the address's query (?token=) is sent to servers and kept in their logs, so it was not used: give it after # (#token=...), or type it under \"Open from PACS…\"".to_owned(),
                );
            }
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
                "{e}. Paste a bearer token below (or give it in the link after #, as #token=...), then open the study again."
            ));
        } else {
            self.pacs.message = Some(e.to_string());
        }
        self.pacs.error_shown = Some(e.to_string());
        self.error(e.to_string());
    }

    fn pacs_search(&mut self) {
        let (base, auth) =
            match Base::parse(&self.pacs.server).and_then(|b| Ok((b, self.pacs.auth()?))) {
                Ok(x) => x,
                Err(e) => {
                    self.pacs.message = Some(e.to_string());
                    return;
                }
            };
        if let Err(e) = base.study_search(&self.pacs.search) {
            self.pacs.message = Some(e.to_string());
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
                        self.pacs.message = Some(e.to_string());
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

    /// A CT just shown from an archive's PET/CT study (the CT of `generation`): the study's
    /// PET series is retrieved next and fused over it, as a dropped folder's PET is.
    pub(super) fn pacs_retrieve_pet(&mut self, generation: u64) {
        // A PET still on its way for an earlier CT is cancelled.
        if let Some(old) = self.pacs.pet.take() {
            old.running.cancel();
        }
        let Some(scene) = &self.scene else {
            return;
        };
        let Some(ViewSource::DicomWeb { base, study, .. }) = &scene.origin else {
            return;
        };
        if scene.volume.modality != crate::volume::Modality::Ct
            || self.pacs.study.as_ref().map(|(_, s)| &s.study_uid) != Some(study)
        {
            return;
        }
        let Some(pet) = dicomweb::pet_series(&self.pacs.series) else {
            return;
        };
        let target = PacsTarget {
            base: base.clone(),
            study: study.clone(),
            series: Some(self.pacs.series[pet].series_uid.clone()),
        };
        let parsed = Base::parse(&target.base).and_then(|b| Ok((b, self.pacs.auth()?)));
        let (base, auth) = match parsed {
            Ok(x) => x,
            Err(e) => return self.error(format!("PET: {e}")),
        };
        // Its own task: the dialog's next search or study does not cancel it, a new CT does.
        self.pacs.pet_tasks += 1;
        let task = PET_TASK | self.pacs.pet_tasks;
        self.pet.awaiting(generation);
        let running = backend::retrieve(base, auth, target, task, self.pacs.inbox.clone());
        self.pacs.pet = Some(PetRetrieval {
            task,
            generation,
            running,
        });
    }

    /// The archive's answer for a PET/CT study's PET: fused over its CT when that is still the
    /// one shown; its progress shows as the PET's own "loading".
    fn pacs_pet_event(&mut self, event: Event) {
        let Event::Retrieved { result, .. } = event else {
            return;
        };
        let Some(retrieval) = self.pacs.pet.take() else {
            return;
        };
        match *result {
            Ok(loaded) => {
                let ct = self.scene.as_ref().map(|s| s.volume.as_ref());
                if let Some(message) =
                    self.pet
                        .install(loaded.volume, ct, retrieval.generation, self.gpu.as_ref())
                {
                    self.error(message);
                }
                self.pet_arrived();
            }
            Err(e) => {
                if self.pet.failed(retrieval.generation) {
                    self.error(format!("PET: {e}"));
                }
            }
        }
    }

    /// Natively the window title names the patient too (the page's title never does: it is
    /// the tab's name in a browser's history).
    fn pacs_title(&mut self, ctx: &egui::Context) {
        #[cfg(not(target_arch = "wasm32"))]
        {
            let title = match self.pacs.patient.as_ref().and_then(patient_line) {
                Some(line) => format!("Shapecast: {line}"),
                None => "Shapecast".to_owned(),
            };
            if self.pacs.title.as_ref() != Some(&title) {
                ctx.send_viewport_cmd(egui::ViewportCommand::Title(title.clone()));
                self.pacs.title = Some(title);
            }
        }
        let _ = ctx;
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // a failed unwrap is a failed test
mod tests {
    use super::*;

    #[test]
    fn the_patient_line_says_what_is_known() {
        assert_eq!(patient_line(&Patient::default()), None);
        let p = Patient {
            name: Some("DOE^JANE^^".to_owned()),
            id: Some("P-7".to_owned()),
            birth_date: Some("19700101".to_owned()),
            study_date: Some("2024-1-2".to_owned()),
            series_description: Some("Thorax 1.0 B70f".to_owned()),
        };
        assert_eq!(
            patient_line(&p).unwrap(),
            "DOE, JANE · ID P-7 · born 1970-01-01 · study 2024-1-2 · Thorax 1.0 B70f"
        );
        assert_eq!(format!("{p:?}"), "Patient(..)");
    }

    #[test]
    fn the_archive_fills_what_the_images_lack() {
        let study = StudyInfo {
            study_uid: "1.2".to_owned(),
            patient_name: Some("ROE^RICHARD".to_owned()),
            patient_id: Some("Q".to_owned()),
            study_date: Some("20200202".to_owned()),
            ..StudyInfo::default()
        };
        let series = SeriesInfo {
            series_uid: "1.2.3".to_owned(),
            description: Some("lung".to_owned()),
            ..SeriesInfo::default()
        };
        let images = Patient {
            id: Some("from-header".to_owned()),
            ..Patient::default()
        };
        let p = merge_patient(Some(images), &study, Some(&series));
        assert_eq!(p.id.as_deref(), Some("from-header"));
        assert_eq!(p.name.as_deref(), Some("ROE^RICHARD"));
        assert_eq!(p.study_date.as_deref(), Some("20200202"));
        assert_eq!(p.series_description.as_deref(), Some("lung"));
        assert!(study_summary(&study).starts_with("20200202  ROE, RICHARD  ID Q"));
    }
}
