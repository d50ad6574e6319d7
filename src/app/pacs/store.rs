//! "Store to PACS": the MIP's turn (made by `export::movie`) and the reading's report
//! (`app::report`) sent into the study the volume came from, as a Secondary Capture series and a
//! TID 1500 Structured Report (`io::dicomweb::stow`, `io::dicomweb::sr`), on a task of its own.

use super::transport as backend;
use super::{ShapecastApp, ViewSource};
use crate::app::error::{AppError, ExportError};
use crate::io::dicomweb::{self, Base, DicomWebError, stow};

/// What the error list calls the action.
const STORE: &str = "Store to PACS";

/// A rotation of the MIP to store into the study its series came from.
pub(in crate::app) struct StoreJob {
    pub study: String,
    pub series: String,
    /// RGBA frames of `size`.
    pub frames: Vec<Vec<u8>>,
    /// How many frames (kept after the frames are let go).
    pub frame_count: usize,
    pub size: [u32; 2],
    pub description: String,
    pub derivation: String,
    /// The reading's measurements and confirmed findings, if it has any.
    pub report: Option<dicomweb::sr::Report>,
}

impl StoreJob {
    /// What goes into the study: the rotation's Secondary Capture, and the report (when the
    /// reading has one and the series allows it: else why not, beside).
    /// The frames are let go once in the instance (a large pane's frames are hundreds of MB:
    /// the page must not hold them beside the request).
    pub(in crate::app) fn instances(
        &mut self,
        source: &stow::SourceSeries,
    ) -> Result<(Vec<stow::Instance>, Option<String>), DicomWebError> {
        let mut out = vec![self.instance(source)?];
        self.frames = Vec::new();
        let mut skipped = None;
        if let Some(report) = &self.report {
            match dicomweb::sr::measurement_report(
                source,
                report,
                &stow::DicomNow::now(),
                stow::REPORT_SERIES_NUMBER,
            ) {
                Ok(sr) => out.push(sr),
                Err(e) => skipped = Some(crate::error::chain(&e)),
            }
        }
        Ok((out, skipped))
    }

    /// The Secondary Capture of the rotation, in the source's study.
    fn instance(&self, source: &stow::SourceSeries) -> Result<stow::Instance, DicomWebError> {
        let rotation = stow::Rotation {
            width: self.size[0],
            height: self.size[1],
            frames: &self.frames,
            description: self.description.clone(),
            derivation: self.derivation.clone(),
            step_deg: 360.0 / self.frame_count.max(1) as f64,
            stable_key: None,
        };
        stow::secondary_capture(
            source,
            &rotation,
            &stow::DicomNow::now(),
            stow::ROTATION_SERIES_NUMBER,
        )
    }

    pub(in crate::app) fn done(
        &self,
        instances: &[stow::Instance],
        skipped: Option<String>,
    ) -> StoreDone {
        StoreDone {
            series: instances.iter().map(|i| i.series_uid.clone()).collect(),
            frames: self.frame_count,
            bytes: instances.iter().map(|i| i.bytes.len()).sum(),
            description: self.description.clone(),
            report: self
                .report
                .as_ref()
                .filter(|_| instances.len() > 1)
                .map(|r| r.description.clone()),
            skipped,
            warnings: Vec::new(),
        }
    }
}

/// What "Store to PACS" stored.
pub(in crate::app) struct StoreDone {
    /// The series made: the rotation's, then the report's.
    series: Vec<String>,
    frames: usize,
    bytes: usize,
    description: String,
    /// The report's description, when one was stored.
    report: Option<String>,
    /// Why the reading's report was not stored.
    skipped: Option<String>,
    /// What the archive said of what it stored.
    pub warnings: Vec<String>,
}

/// The tag of "Store to PACS" task ids (see [`PET_TASK`]).
pub(super) const STORE_TASK: u64 = 1 << 62;

impl ShapecastApp {
    /// Whether the volume shown came from an archive (what "Store to PACS" needs; checked
    /// every frame, so without copying the UIDs).
    pub(in crate::app) fn shows_archive_series(&self) -> bool {
        matches!(
            self.scene.as_ref().and_then(|s| s.origin.as_ref()),
            Some(ViewSource::DicomWeb { series, .. }) if !series.is_empty()
        )
    }

    /// The study and series the volume shown came from, when an archive it was.
    pub(in crate::app) fn pacs_source(&self) -> Option<(String, String, String)> {
        match &self.scene.as_ref()?.origin {
            Some(ViewSource::DicomWeb {
                base,
                study,
                series,
            }) if !series.is_empty() => Some((base.clone(), study.clone(), series.clone())),
            _ => None,
        }
    }

    /// The series stored into the archive this session.
    pub fn pacs_stored_series(&self) -> &[String] {
        &self.pacs.stored
    }

    /// Whether a store into the archive is on its way.
    pub fn storing_to_pacs(&self) -> bool {
        self.pacs.store.is_some()
    }

    /// Sends a rotation of the MIP into the study the volume came from (STOW-RS), with the
    /// token the study was opened with.
    pub(in crate::app) fn pacs_store(&mut self, job: StoreJob) {
        let Some((base, study, series)) = self.pacs_source() else {
            return self.error(AppError::export(STORE, ExportError::NotFromArchive));
        };
        if (study.as_str(), series.as_str()) != (job.study.as_str(), job.series.as_str()) {
            return self.error(AppError::export(STORE, ExportError::SeriesChanged));
        }
        let parsed = Base::parse(&base).and_then(|b| Ok((b, self.pacs.auth()?)));
        let (base, auth) = match parsed {
            Ok(x) => x,
            Err(source) => {
                return self.error(AppError::Archive {
                    action: STORE,
                    source,
                });
            }
        };
        if let Some((_, old)) = self.pacs.store.take() {
            old.cancel();
        }
        self.pacs.store_tasks += 1;
        let task = STORE_TASK | self.pacs.store_tasks;
        let running = backend::store(base, auth, job, task, self.pacs.inbox.clone());
        self.pacs.store = Some((task, running));
    }

    pub(super) fn pacs_stored(&mut self, result: Result<StoreDone, DicomWebError>, now: f64) {
        match result {
            Ok(done) => {
                self.notes.push(format!(
                    "stored in the archive: \"{} {}\", {} frames{} ({:.1} MB), series {}",
                    stow::DESCRIPTION_PREFIX,
                    done.description,
                    done.frames,
                    done.report
                        .as_ref()
                        .map(|r| format!(", and the report of the {r}"))
                        .unwrap_or_default(),
                    done.bytes as f64 / 1e6,
                    done.series.join(", ")
                ));
                if let Some(why) = done.skipped {
                    self.error(format!(
                        "Store to PACS: the rotation was stored, the measurements were not: {why}"
                    ));
                }
                for w in &done.warnings {
                    self.notes
                        .push(format!("Store to PACS: the archive says: {w}"));
                }
                self.pacs.stored.extend(done.series);
                self.pacs.stored_at = Some(now);
            }
            Err(DicomWebError::Cancelled) => {}
            Err(e) => {
                if matches!(e, DicomWebError::Unauthorized { .. }) {
                    self.pacs.needs_token = true;
                    self.pacs.dialog = true;
                    self.pacs.message = Some(format!(
                        "{}. Storing needs a token the archive accepts for writing: paste it below, then Store to PACS again.",
                        crate::error::chain(&e)
                    ));
                }
                self.error(AppError::Archive {
                    action: STORE,
                    source: e,
                });
            }
        }
    }
}
