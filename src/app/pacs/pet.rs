//! A PET/CT study's PET from the archive: retrieved after its CT is shown and fused over it,
//! as a dropped folder's PET is.

use super::*;
use crate::app::error::AppError;

/// The tag of a PET retrieval's task ids: their own range, apart from the dialog's tasks
/// (`Pacs::task`), so that neither replaces nor receives the other's answers.
pub(super) const PET_TASK: u64 = 1 << 63;

/// A PET/CT study's PET on its way: its task, the generation of the CT it goes over, and the
/// retrieval (cancelled when another CT is shown).
pub(super) struct PetRetrieval {
    pub task: u64,
    pub generation: u64,
    pub running: backend::Task,
}

impl ShapecastApp {
    /// A CT just shown from an archive's PET/CT study (the CT of `generation`): the study's
    /// PET series is retrieved next and fused over it, as a dropped folder's PET is.
    pub(in crate::app) fn pacs_retrieve_pet(&mut self, generation: u64) {
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
            Err(source) => {
                return self.error(AppError::Archive {
                    action: "PET",
                    source,
                });
            }
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
    pub(super) fn pacs_pet_event(&mut self, event: Event) {
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
                    self.error(AppError::Archive {
                        action: "PET",
                        source: e,
                    });
                }
            }
        }
    }
}
