//! What reaches the app from outside its frames ([`Event`]s from the platform, taken once per
//! frame): files dropped on the native window; on the web the page's events (files read by the
//! file inputs, downloads of `?url=` links and PETs, progress, a link pasted into the address
//! bar).

use super::error::AppError;
use super::platform::{Event, Platform as _};
use super::{LoadSource, ShapecastApp};

impl ShapecastApp {
    /// Files dropped on the window (native) or read by the page (web), and the page's events.
    pub(super) fn take_external_files(&mut self, ctx: &egui::Context) {
        for event in self.platform.take_events(ctx) {
            match event {
                Event::Hover(on) => self.windows.drop_hover = on,
                Event::Open(source) => self.open(source),
                Event::Progress {
                    verb,
                    label,
                    done,
                    total,
                } => {
                    // Files being read or downloaded: a newer load than one uploading.
                    self.cancel_upload();
                    let f = if total > 0.0 {
                        (done / total) as f32
                    } else {
                        0.0
                    };
                    let what = if total > 0.0 {
                        format!(
                            "{verb} {label} ({:.1} of {:.1} MB)",
                            done / 1e6,
                            total / 1e6
                        )
                    } else if done > 0.0 {
                        format!("{verb} {label} ({:.1} MB)", done / 1e6)
                    } else {
                        format!("{verb} {label}")
                    };
                    self.load_progress = Some((0.5 * f, what));
                }
                Event::Files {
                    label,
                    files,
                    origin,
                } => {
                    self.open_from(LoadSource::Files { label, files }, Some(origin));
                }
                Event::Loaded {
                    loaded,
                    series,
                    origin,
                } => {
                    self.load_progress = None;
                    self.series.loading = None;
                    // Another series of the files shown came from where they did.
                    self.loading_origin =
                        origin.or_else(|| self.scene.as_ref().and_then(|s| s.origin.clone()));
                    self.install(*loaded, series);
                }
                Event::PetLoaded { loaded, generation } => {
                    let ct = self.scene.as_ref().map(|s| s.volume.as_ref());
                    if let Some(message) =
                        self.pet
                            .install(loaded.volume, ct, generation, self.gpu.as_ref())
                    {
                        self.error(message);
                    }
                    self.pet_arrived();
                }
                Event::PetFiles {
                    label,
                    files,
                    generation,
                } => {
                    // Only for the CT it was asked for (a newer CT drops it unread).
                    if self.pet.awaits(generation) {
                        self.pet
                            .start_source(LoadSource::Files { label, files }, generation);
                    }
                }
                Event::PetFailed { error, generation } => {
                    if self.pet.failed(generation) {
                        self.error(AppError::Pet(Box::new(error)));
                    }
                }
                Event::Failed { error } => {
                    self.load_progress = None;
                    self.series.loading = None;
                    self.load_failed(error);
                }
                Event::Cancelled { label } => {
                    self.load_progress = None;
                    self.notes.push(format!("{label}: download cancelled"));
                }
                Event::Link { fragment } => self.open_link(&fragment),
            }
        }
    }
}
