//! The native window's side of [`Platform`]: paths typed into "Open", files written into the
//! pictures' folder, the demo CT embedded in the binary.

use super::{Event, LoadSource, Platform, PlatformError, SaveError, SeriesSet};

/// The native window.
pub type This = Native;

/// Opens the viewer in a native window (`shapecast view`).
pub fn run_native(options: crate::app::AppOptions) -> Result<(), eframe::Error> {
    let native = eframe::NativeOptions {
        renderer: eframe::Renderer::Wgpu,
        wgpu_options: crate::app::wgpu_options(),
        viewport: egui::ViewportBuilder::default()
            .with_title("Shapecast")
            .with_inner_size([1440.0, 900.0])
            .with_drag_and_drop(true),
        ..Default::default()
    };
    eframe::run_native(
        "Shapecast",
        native,
        Box::new(move |cc| {
            Ok(Box::new(crate::app::ShapecastApp::with_options(
                cc, options,
            )))
        }),
    )
}

/// The native window has no address: no query, no fragment.
pub fn page_query_and_fragment() -> (Vec<(String, String)>, String) {
    (Vec::new(), String::new())
}

/// Natively a URL stays as given.
pub fn absolute_url(url: &str) -> String {
    url.to_owned()
}

/// The native window has no address to carry a token.
pub fn take_fragment_token() -> Option<String> {
    None
}

/// The native window has no address to carry a token.
pub fn query_has_token() -> bool {
    false
}

/// The native window.
#[derive(Default)]
pub struct Native {
    /// The "Open" field's path.
    open_path: String,
    /// Where saved pictures and movies are written (`None`: the current folder).
    picture_dir: Option<std::path::PathBuf>,
    /// The window title set last.
    title: Option<String>,
}

impl Platform for Native {
    /// Files dropped on the window: paths when they have them, else their bytes.
    fn take_events(&mut self, ctx: &egui::Context) -> Vec<Event> {
        let (dropped, hovering) =
            ctx.input(|i| (i.raw.dropped_files.clone(), !i.raw.hovered_files.is_empty()));
        let mut events = vec![Event::Hover(hovering)];
        if dropped.is_empty() {
            return events;
        }
        let paths: Vec<std::path::PathBuf> = dropped
            .iter()
            .map(|f| f.path().to_path_buf())
            .filter(|p| !p.as_os_str().is_empty())
            .collect();
        if paths.len() == dropped.len() {
            events.push(Event::Open(LoadSource::Paths(paths)));
            return events;
        }
        let mut files = Vec::new();
        for f in &dropped {
            let name = f.path().display().to_string();
            match f.bytes() {
                Ok(bytes) => files.push(crate::io::InputFile::new(name, bytes)),
                Err(e) => {
                    // egui gives the reason as text.
                    let error = crate::app::error::PageError::CannotRead {
                        file: name,
                        words: e,
                    };
                    events.push(Event::Failed {
                        error: error.into(),
                    });
                    return events;
                }
            }
        }
        let label = format!("{} dropped files", files.len());
        events.push(Event::Open(LoadSource::Files { label, files }));
        events
    }

    fn open_menu_ui(&mut self, ui: &mut egui::Ui) -> Option<LoadSource> {
        let mut chosen = None;
        ui.menu_button("Open", |ui| {
            ui.label("A file or a folder (DICOM series), or drop them on the window:");
            let r = ui.add(
                egui::TextEdit::singleline(&mut self.open_path)
                    .hint_text("/path/to/volume.nii.gz or /path/to/dicom-folder")
                    .desired_width(360.0),
            );
            let enter = r.lost_focus() && ui.input(|i| i.key_pressed(egui::Key::Enter));
            if (ui.button("Open").clicked() || enter) && !self.open_path.trim().is_empty() {
                let path = std::path::PathBuf::from(self.open_path.trim());
                chosen = Some(LoadSource::Paths(vec![path]));
                ui.close();
            }
        });
        chosen
    }

    fn deliver(&self, name: &str, bytes: &[u8]) -> Result<String, SaveError> {
        let path = self
            .picture_dir
            .as_ref()
            .map_or_else(|| std::path::PathBuf::from(name), |d| d.join(name));
        std::fs::write(&path, bytes).map_err(|source| SaveError::Write {
            path: path.display().to_string(),
            source,
        })?;
        let shown = std::path::absolute(&path).unwrap_or(path);
        Ok(shown.display().to_string())
    }

    fn set_save_dir(&mut self, dir: std::path::PathBuf) {
        self.picture_dir = Some(dir);
    }

    fn install(&self, _ctx: &egui::Context) -> Result<(), PlatformError> {
        Ok(())
    }

    /// The demo CT, embedded in the binary (the page fetches it instead of carrying 3.6 MB in
    /// the wasm).
    fn demo(&self) -> Option<LoadSource> {
        let bytes = include_bytes!("../../../../web/demo/aorta_ct_cropped.nii.gz");
        Some(LoadSource::Files {
            label: "demo CT".to_owned(),
            files: vec![crate::io::InputFile::new(
                crate::app::demo::DEMO_FILE,
                bytes.to_vec(),
            )],
        })
    }

    fn fetch(&self, urls: Vec<String>) -> Result<(), PlatformError> {
        Err(PlatformError::UrlsNatively {
            urls: urls.join(", "),
        })
    }

    fn downloading(&self) -> bool {
        false
    }

    fn cancel_download(&self) {}

    fn fetch_pet(&self, urls: Vec<String>, _generation: u64) -> Result<(), PlatformError> {
        Err(PlatformError::PetUrlsNatively {
            urls: urls.join(", "),
        })
    }

    fn page_address(&self) -> String {
        String::new()
    }

    fn set_title(&mut self, ctx: &egui::Context, title: String) {
        if self.title.as_ref() != Some(&title) {
            ctx.send_viewport_cmd(egui::ViewportCommand::Title(title.clone()));
            self.title = Some(title);
        }
    }

    fn read_page_series(&self, set: SeriesSet, _pet_for: Option<u64>) -> Option<SeriesSet> {
        Some(set)
    }

    fn packs_voxels(&self) -> bool {
        true
    }
}
