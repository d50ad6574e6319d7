//! What reaches the app from outside its frames: files dropped on the native window, and on the
//! web the page's events (files read by the file inputs, downloads of `?url=` links and PETs,
//! progress, a link pasted into the address bar), taken once per frame.

#[cfg(target_arch = "wasm32")]
use super::platform::web::events as web_events;
use super::{LoadSource, ShapecastApp};

impl ShapecastApp {
    /// Files dropped on the window (native) or read by the page (web).
    pub(super) fn take_external_files(&mut self, ctx: &egui::Context) {
        #[cfg(not(target_arch = "wasm32"))]
        {
            let (dropped, hovering) =
                ctx.input(|i| (i.raw.dropped_files.clone(), !i.raw.hovered_files.is_empty()));
            self.windows.drop_hover = hovering;
            if !dropped.is_empty() {
                let paths: Vec<std::path::PathBuf> = dropped
                    .iter()
                    .map(|f| f.path().to_path_buf())
                    .filter(|p| !p.as_os_str().is_empty())
                    .collect();
                if paths.len() == dropped.len() {
                    self.open(LoadSource::Paths(paths));
                } else {
                    let mut files = Vec::new();
                    for f in &dropped {
                        let name = f.path().display().to_string();
                        match f.bytes() {
                            Ok(bytes) => files.push(crate::io::InputFile::new(name, bytes)),
                            Err(e) => return self.error(format!("{name}: cannot read: {e}")),
                        }
                    }
                    let label = format!("{} dropped files", files.len());
                    self.open(LoadSource::Files { label, files });
                }
            }
        }
        #[cfg(target_arch = "wasm32")]
        {
            let _ = ctx;
            for event in web_events::take_events() {
                match event {
                    web_events::WebEvent::Hover(on) => self.windows.drop_hover = on,
                    web_events::WebEvent::Progress {
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
                    web_events::WebEvent::Files {
                        label,
                        files,
                        origin,
                    } => {
                        self.open_from(LoadSource::Files { label, files }, Some(origin));
                    }
                    web_events::WebEvent::Loaded {
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
                    web_events::WebEvent::PetLoaded { loaded, generation } => {
                        let ct = self.scene.as_ref().map(|s| s.volume.as_ref());
                        if let Some(message) =
                            self.pet
                                .install(loaded.volume, ct, generation, self.gpu.as_ref())
                        {
                            self.error(message);
                        }
                        self.pet_arrived();
                    }
                    web_events::WebEvent::PetFiles {
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
                    web_events::WebEvent::PetFailed {
                        message,
                        generation,
                    } => {
                        if self.pet.failed(generation) {
                            self.error(format!("PET: {message}"));
                        }
                    }
                    web_events::WebEvent::Failed { message } => {
                        self.load_progress = None;
                        self.series.loading = None;
                        self.load_failed(message);
                    }
                    web_events::WebEvent::Cancelled { label } => {
                        self.load_progress = None;
                        self.notes.push(format!("{label}: download cancelled"));
                    }
                    web_events::WebEvent::Link { fragment } => self.open_link(&fragment),
                }
            }
        }
    }
}
