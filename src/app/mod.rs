//! The viewer app (eframe, wgpu renderer): the same code runs in the browser and in a native
//! window. It owns the loaded volume and its GPU textures, the features computed for it, the
//! shared crosshair and window, and the panes.
//!
//! Nothing blocks: each frame advances the load (read, decode, upload) and the feature job by
//! one bounded step (`advance`), then draws. A failed load shows a dismissable message and keeps
//! the previous volume.

mod api;
pub mod demo;
pub mod error;
pub mod export;
mod external;
pub mod features;
pub mod findings;
mod install;
mod keys;
pub mod load;
pub mod measure;
pub mod mip_view;
mod model;
mod options;
mod pacs;
mod paint;
mod panels;
mod panes;
mod pet;
pub mod platform;
mod probe;
mod publish;
pub mod report;
mod series_list;
mod share;
pub mod slices;
mod startup;
pub mod view_link;
pub mod window_level;

use std::sync::Arc;

use crate::gpu::volume_texture::FeatureTexture;

use crate::cpu::pipeline::Request;
use crate::cpu::tf::Preset;
use crate::gpu::GpuContext;
use crate::gpu::volume_texture::{IntensityUpload, RenderVolume};
use crate::render::slice::{Overlay, SliceRenderer};
use crate::status::{AdapterStatus, AppStatus, Phase};
use crate::volume::Volume;

pub use export::movie::MOVIE_FRAMES;
pub use features::{DisplayMode, FeatureDisplay, FeatureEntry, FeatureParams, JobOutcome};
pub use install::{PACK_FROM_BYTES, pack_if_large, preset_for};
pub use load::{LoadSource, SeriesSet};
pub use model::axes::SliceKind;
pub use options::{AppOptions, StartWith};
pub use pacs::PacsTarget;
pub use panes::{Layout, PaneId};
pub use view_link::{ViewSource, ViewState};
pub use window_level::{Window, WindowPreset};

use features::{FeatureManager, JobEvent};
use install::Uploading;
use load::{LoadJob, LoadStep};
use mip_view::{MipScene, MipView};
use slices::{PaneInputs, SlicePane};
pub use startup::wgpu_options;

/// The loaded volume and its intensity texture.
struct Scene {
    volume: Arc<Volume>,
    render: RenderVolume,
    /// Unique per loaded volume.
    generation: u64,
    /// Whether values are shown as HU.
    is_ct: bool,
    /// Where it came from, as a link names it.
    origin: Option<ViewSource>,
}

impl Scene {
    /// The unit values are shown in: HU for what looks like a CT, a PET's own ("SUV" with its
    /// factor), none otherwise (MR, phantoms, volumes of unknown modality).
    fn unit(&self) -> &str {
        if self.is_ct {
            "HU"
        } else if self.volume.modality == crate::volume::Modality::Pt {
            self.volume.unit()
        } else {
            ""
        }
    }
}

pub struct ShapecastApp {
    gpu: Option<GpuContext>,
    /// What differs between the page and the native window.
    platform: platform::Current,
    options: AppOptions,
    status: AppStatus,
    published: Option<AppStatus>,
    started: bool,

    load: Option<LoadJob>,
    uploading: Option<Uploading>,
    /// (fraction, what) of the load in progress, including the browser's file reads.
    load_progress: Option<(f32, String)>,
    scene: Option<Scene>,
    generation: u64,
    /// Errors for the user, newest last; each can be dismissed.
    errors: Vec<String>,
    /// Things the loader and the feature computation want the user to know.
    notes: Vec<String>,

    features: FeatureManager,
    /// The parameters the panel edits.
    params: FeatureParams,
    /// The parameters the displayed features were (or are being) computed with.
    applied: FeatureParams,
    mode: DisplayMode,
    display: FeatureDisplay,

    /// Grey window, crosshair, hover and layout.
    reading: model::Reading,
    panes: [SlicePane; 3],
    slice_renderer: Option<SliceRenderer>,
    mip_view: MipView,
    /// The measuring tool and the measurements on the volume shown.
    measure: measure::Measurements,
    probe: probe::ProbeState,

    /// "About & data", the keys' help, the drop hint, the "Open" path, "copied".
    windows: model::Windows,
    /// "Save picture" and "Save movie": what is being made and the last of each.
    export: export::Export,

    /// Where the volume being loaded comes from (becomes the scene's `origin`).
    loading_origin: Option<ViewSource>,
    /// A link's view waiting for its volume.
    pending_view: Option<share::PendingView>,
    /// A link's camera for the volume of this generation, set once the MIP has framed it.
    pending_camera: Option<(u64, crate::render::camera::Camera)>,
    /// Controls drawn this frame and where (for automation).
    controls: Vec<(String, egui::Rect)>,
    /// "Open from PACS…", DICOMweb retrievals and the patient line.
    pacs: pacs::Pacs,
    /// The series of the files given, when they hold several.
    series: series_list::SeriesState,
    /// The PET of a PET/CT study, fused over the CT.
    pet: pet::PetState,
    pet_mip: pet::PetMip,
    /// The ranked findings of the displayed blobness.
    findings: findings::FindingsState,
}

impl ShapecastApp {
    // ---- Per-frame work ------------------------------------------------------------------

    fn displayed_request(&self) -> Option<Request> {
        self.mode.method().map(|m| self.applied.request(m))
    }

    fn displayed_entry(&self) -> Option<&FeatureEntry> {
        self.features.find(&self.displayed_request()?)
    }

    /// Shows an error in the list (the newest five), with its sources.
    fn error(&mut self, error: impl Into<error::AppError>) {
        let message = error.into().message();
        log::error!("{message}");
        if self.errors.last() != Some(&message) {
            self.errors.push(message);
        }
        // Keep the list short: the newest matter.
        if self.errors.len() > 5 {
            self.errors.remove(0);
        }
    }

    /// Starts computing the displayed method if its features are neither kept nor running.
    fn ensure_features(&mut self) {
        let Some(request) = self.displayed_request() else {
            return;
        };
        if self.features.find(&request).is_some()
            || self.features.running_request() == Some(&request)
        {
            return;
        }
        let (Some(gpu), Some(scene)) = (&self.gpu, &self.scene) else {
            return;
        };
        if let Err(e) = self.features.start(gpu, &scene.volume, request) {
            self.error(e);
        }
    }

    /// Advances loading, uploading and computing by one step each.
    fn advance(&mut self, frame_s: f64) {
        if self.uploading.is_some() {
            self.advance_upload();
        }
        if let Some(job) = &mut self.load {
            match job.step() {
                LoadStep::Working { fraction, what } => {
                    self.load_progress = Some((fraction, what));
                }
                LoadStep::Done(loaded) => {
                    let series = job.take_series();
                    self.series.loading = None;
                    self.load = None;
                    self.load_progress = None;
                    self.install(*loaded, series);
                }
                LoadStep::Failed(message) => {
                    self.series.loading = None;
                    self.load = None;
                    self.load_progress = None;
                    self.loading_origin = None;
                    self.load_failed(message);
                }
            }
        }
        let had_pet = self.pet.layer.is_some();
        if let Some(message) = self.pet.step(
            self.scene.as_ref().map(|s| s.volume.as_ref()),
            self.generation,
            self.gpu.as_ref(),
        ) {
            self.error(message);
        }
        if !had_pet {
            self.pet_arrived();
        }
        if let Some(gpu) = &self.gpu {
            match self.features.step(gpu, frame_s) {
                Some(JobEvent::Finished { method, notes }) => {
                    for n in notes {
                        self.notes
                            .push(format!("{}: {n}", features::method_name(method)));
                    }
                }
                Some(JobEvent::Failed(message)) => self.error(message),
                None => {}
            }
        }
        if let Some(request) = self.displayed_request() {
            self.features.touch(&request);
        }
        if let (Some(gpu), Some(scene)) = (&self.gpu, &self.scene) {
            // The phantoms are modelled in HU (air -1000 where they have it, tissue 0 to 200).
            let reads_hu = scene.is_ct || scene.volume.modality == crate::volume::Modality::Phantom;
            let entry = self
                .displayed_request()
                .and_then(|r| self.features.find(&r));
            if let Some(message) = self.findings.update(
                gpu,
                self.generation,
                &scene.volume,
                reads_hu,
                entry,
                self.pet.layer.as_ref().map(|l| &l.volume),
            ) {
                self.error(message);
            }
        }
    }

    /// Sends the crosshair (and the MIP's marker) to a point in patient space (LPS mm).
    fn go_to_lps(&mut self, p: glam::DVec3) {
        let Some(volume) = self.volume() else { return };
        let v = volume.voxel_from_world().transform_point3(p);
        let dims = volume.dims;
        if !v.is_finite() {
            return;
        }
        self.reading.crosshair = std::array::from_fn(|a| {
            (v[a].round().max(0.0) as usize).min(dims[a].saturating_sub(1))
        });
        self.mip_view.set_crosshair(Some(p));
    }

    /// A PET just fused over the CT: the measurements made before it (a link's) read it too.
    fn pet_arrived(&mut self) {
        if let (Some(layer), Some(scene)) = (&self.pet.layer, &self.scene) {
            self.measure
                .read_pet(&scene.volume, Some(layer.volume.as_ref()));
        }
    }

    fn overlay(&self) -> Option<Overlay> {
        let entry = self.displayed_entry()?;
        self.display.overlay_on_slices.then(|| Overlay {
            scale: self.display.scales(entry.texture.reference()),
            opacity: self.display.opacity,
        })
    }
}

impl ShapecastApp {
    /// Frames for a running feature job. In the browser the job asks for a frame when its step
    /// is done (its waker, when the step's time is known), so frames do not run back to back
    /// between steps: on a software adapter a frame costs ~0.25 s of the device, and three of
    /// them per step left the job a third of it. The progress line still moves four times a
    /// second. Natively the queue's callbacks run only when something polls: frames go on.
    fn repaint_for_job(&self, ctx: &egui::Context) {
        if self.features.running_request().is_none() {
            return;
        }
        if platform::IN_PAGE {
            ctx.request_repaint_after(std::time::Duration::from_millis(250));
        } else {
            ctx.request_repaint();
        }
    }
}

impl eframe::App for ShapecastApp {
    fn logic(&mut self, ctx: &egui::Context, _frame: &mut eframe::Frame) {
        if self.load.is_some() || self.probe.busy() || self.pet.busy() {
            ctx.request_repaint();
        }
        self.repaint_for_job(ctx);
    }

    fn ui(&mut self, ui: &mut egui::Ui, frame: &mut eframe::Frame) {
        let ctx = ui.ctx().clone();
        self.controls.clear();
        self.start_once(&ctx);
        self.take_external_files(&ctx);
        self.pacs_frame(&ctx);
        // The time between the starts of the last two frames (the feature job's step follows it
        // where the device's own frames are slow).
        let frame_s = f64::from(ctx.input(|i| i.unstable_dt));
        self.advance(frame_s);
        self.status.frames += 1;

        egui::Panel::top("top").show(ui, |ui| self.top_bar_ui(ui));
        egui::Panel::top("pacs").show(ui, |ui| self.pacs_bar_ui(ui));
        egui::Panel::bottom("status").show(ui, |ui| self.status_bar_ui(ui));
        egui::Panel::left("controls")
            .resizable(true)
            .default_size(290.0)
            .show(ui, |ui| {
                egui::ScrollArea::vertical().show(ui, |ui| self.side_panel_ui(ui));
            });
        egui::CentralPanel::default().show(ui, |ui| {
            self.link_notice_ui(ui);
            self.errors_ui(ui);
            self.panes_ui(ui, frame);
        });
        self.about_ui(&ctx);
        self.pacs_window_ui(&ctx);
        self.keys(&ctx);
        self.keys_help_ui(&ctx);
        self.drop_overlay(&ctx);

        self.poll_picture(&ctx);
        self.advance_movie(&ctx);
        self.update_probe();
        self.update_status();
        if self.published.as_ref() != Some(&self.status) {
            self.status.publish();
            self.published = Some(self.status.clone());
        }
        // A job started in this frame (a mode, a recompute, a new volume) asks for its frames.
        self.repaint_for_job(&ctx);
        if self.load.is_some()
            || self.uploading.is_some()
            || self.load_progress.is_some()
            || self.probe.busy()
            || self.pet.busy()
        {
            ctx.request_repaint();
        }
    }
}

/// The MIP's own window for a new volume (and key 0): -100..900 HU for CT, where contrast,
/// vessels and bone stay apart (a soft-tissue window saturates a CT's MIP); for other volumes
/// the slices' `slice_window`.
fn default_mip_window(scene: &Scene, slice_window: Window) -> (f32, f32) {
    if scene.is_ct {
        (-100.0, 900.0)
    } else {
        slice_window.range()
    }
}
