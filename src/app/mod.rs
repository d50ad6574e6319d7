//! The viewer app (eframe, wgpu renderer): the same code runs in the browser and in a native
//! window. It owns the loaded volume and its GPU textures, the features computed for it, the
//! shared crosshair and window, and the panes.
//!
//! Nothing blocks: each frame advances the load (read, decode, upload) and the feature job by
//! one bounded step (`advance`), then draws. A failed load shows a dismissable message and keeps
//! the previous volume.

pub mod demo;
pub mod export;
mod external;
pub mod features;
pub mod findings;
mod install;
#[cfg(target_arch = "wasm32")]
mod js_bytes;
mod keys;
pub mod load;
pub mod measure;
pub mod mip_view;
mod model;
mod options;
mod pacs;
mod panels;
mod panes;
mod pet;
mod probe;
mod publish;
pub mod report;
mod series_list;
mod share;
pub mod slices;
pub mod view_link;
#[cfg(target_arch = "wasm32")]
mod web_fetch;
#[cfg(target_arch = "wasm32")]
mod web_files;
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
pub use install::preset_for;
pub use load::{LoadSource, SeriesSet};
pub use options::{AppOptions, StartWith};
pub use pacs::PacsTarget;
pub use panes::{Layout, PaneId};
pub use slices::SliceKind;
pub use view_link::{ViewSource, ViewState};
pub use window_level::{Window, WindowPreset};

use features::{FeatureManager, JobEvent};
use load::{LoadJob, LoadStep};
use mip_view::{MipScene, MipView};
use slices::{PaneInputs, SlicePane};

/// The eframe/egui wgpu configuration both targets use: the adapter's own limits and features
/// (wgpu's defaults are far too small for volumes), WebGPU only on the web.
pub fn wgpu_options() -> eframe::egui_wgpu::WgpuConfiguration {
    use eframe::egui_wgpu::{WgpuConfiguration, WgpuSetup, WgpuSetupCreateNew};
    let mut create = WgpuSetupCreateNew::without_display_handle();
    create.device_descriptor = Arc::new(crate::gpu::context::device_descriptor);
    #[cfg(target_arch = "wasm32")]
    {
        create.instance_descriptor.backends = wgpu::Backends::BROWSER_WEBGPU;
    }
    #[cfg(not(target_arch = "wasm32"))]
    {
        create.instance_descriptor.backends =
            wgpu::Backends::from_env().unwrap_or(wgpu::Backends::PRIMARY);
    }
    WgpuConfiguration {
        wgpu_setup: WgpuSetup::CreateNew(create),
        ..Default::default()
    }
}

/// Opens the viewer in a native window.
#[cfg(not(target_arch = "wasm32"))]
pub fn run_native(options: AppOptions) -> anyhow::Result<()> {
    let native = eframe::NativeOptions {
        renderer: eframe::Renderer::Wgpu,
        wgpu_options: wgpu_options(),
        viewport: egui::ViewportBuilder::default()
            .with_title("Shapecast")
            .with_inner_size([1440.0, 900.0])
            .with_drag_and_drop(true),
        ..Default::default()
    };
    eframe::run_native(
        "Shapecast",
        native,
        Box::new(move |cc| Ok(Box::new(ShapecastApp::with_options(cc, options)))),
    )
    .map_err(|e| anyhow::anyhow!("could not open the viewer window: {e}"))
}

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

/// A loaded volume whose intensity texture is being written, slab by slab over frames (a
/// whole-body CT is 1 GB: seconds of uploading in one frame would stop the viewer); it is
/// installed, and the volume shown replaced, once the last slab is in.
struct Uploading {
    patient: Option<crate::io::Patient>,
    notes: Vec<String>,
    volume: Volume,
    series: Option<load::SeriesSet>,
    origin: Option<ViewSource>,
    render: RenderVolume,
    upload: IntensityUpload,
}

/// Upload slabs a frame may write, in seconds (at least one slab per frame).
const UPLOAD_SECONDS_PER_FRAME: f64 = 0.05;

pub struct ShapecastApp {
    gpu: Option<GpuContext>,
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
    /// The app as the page and the native window start it (URL parameters on the web).
    pub fn new(cc: &eframe::CreationContext<'_>) -> Self {
        Self::with_options(cc, AppOptions::from_environment())
    }

    pub fn with_options(cc: &eframe::CreationContext<'_>, options: AppOptions) -> Self {
        // Radiologists read in a dark room: dark theme regardless of the system's.
        cc.egui_ctx.set_theme(egui::Theme::Dark);
        let gpu = cc
            .wgpu_render_state
            .as_ref()
            .map(GpuContext::from_render_state);
        let mut status = AppStatus::default();
        // Asked now, so that the answer is in before the first volume (a link's) is uploaded.
        #[cfg(target_arch = "wasm32")]
        if let Some(g) = &gpu {
            crate::gpu::volume_texture::ask_render_attachment_3d(g);
        }
        match &gpu {
            Some(g) => {
                #[cfg(target_arch = "wasm32")]
                let name = crate::gpu::context::browser_adapter_name()
                    .unwrap_or_else(|| g.adapter_info.name.clone());
                #[cfg(not(target_arch = "wasm32"))]
                let name = g.adapter_info.name.clone();
                status.adapter = Some(AdapterStatus {
                    name,
                    backend: format!("{:?}", g.adapter_info.backend),
                });
                log::info!("GPU context:\n{}", g.describe());
            }
            None => {
                status.phase = Phase::Error;
                status.error = Some("eframe started without a wgpu renderer".to_owned());
            }
        }
        let mut errors = options.link_problems.clone();
        errors.truncate(5);
        let pending_view = options.view.clone().map(share::PendingView::new);
        let preset = options.preset.unwrap_or(match options.start {
            StartWith::DemoCt => Preset::Vessels,
            _ => Preset::default(),
        });
        let params = FeatureParams::from_preset(preset);
        let slice_renderer = gpu.as_ref().and_then(|g| match SliceRenderer::new(g) {
            Ok(r) => Some(r),
            Err(e) => {
                log::error!("slice kernel: {e}");
                None
            }
        });
        Self {
            gpu,
            mode: options.mode,
            options,
            status,
            published: None,
            started: false,
            load: None,
            uploading: None,
            load_progress: None,
            scene: None,
            generation: 0,
            errors,
            notes: Vec::new(),
            features: FeatureManager::default(),
            applied: params.clone(),
            params,
            display: FeatureDisplay::default(),
            reading: model::Reading::default(),
            panes: SliceKind::ALL.map(SlicePane::new),
            slice_renderer,
            mip_view: MipView::new(),
            measure: measure::Measurements::default(),
            probe: probe::ProbeState::default(),
            windows: model::Windows::default(),
            export: export::Export::default(),
            loading_origin: None,
            pending_view,
            pending_camera: None,
            controls: Vec::new(),
            pacs: pacs::Pacs::default(),
            pet: pet::PetState::default(),
            pet_mip: pet::PetMip::default(),
            findings: findings::FindingsState::default(),
            series: series_list::SeriesState::default(),
        }
    }

    // ---- State for tests and automation -------------------------------------------------

    /// The shared crosshair, voxel index.
    pub fn crosshair(&self) -> [usize; 3] {
        self.reading.crosshair
    }

    pub fn set_crosshair(&mut self, voxel: [usize; 3]) {
        if let Some(s) = &self.scene {
            self.reading.crosshair =
                std::array::from_fn(|a| voxel[a].min(s.volume.dims[a].saturating_sub(1)));
        }
    }

    /// The crosshair in patient space (LPS, mm): the MIP's slab centre and marker.
    pub fn crosshair_lps_mm(&self) -> Option<glam::DVec3> {
        let v = self.volume()?;
        let [i, j, k] = self.reading.crosshair;
        Some(
            v.world_from_voxel()
                .transform_point3(glam::DVec3::new(i as f64, j as f64, k as f64)),
        )
    }

    /// The status as `window.shapecastStatus` shows it.
    pub fn status(&self) -> &AppStatus {
        &self.status
    }

    pub fn window(&self) -> Window {
        self.reading.window
    }

    pub fn set_window(&mut self, window: Window) {
        self.reading.window = window;
    }

    /// Sets the fused PET's window (its display unit, SUV); nothing without a PET.
    pub fn set_pet_window(&mut self, window: (f32, f32)) {
        if let Some(layer) = &mut self.pet.layer
            && window.1 > window.0
        {
            layer.window = window;
        }
    }

    pub fn volume(&self) -> Option<&Volume> {
        self.scene.as_ref().map(|s| s.volume.as_ref())
    }

    /// The errors shown (not dismissed), oldest first.
    pub fn errors(&self) -> &[String] {
        &self.errors
    }

    pub fn mode(&self) -> DisplayMode {
        self.mode
    }

    pub fn layout(&self) -> Layout {
        self.reading.layout
    }

    pub fn set_layout(&mut self, layout: Layout) {
        self.reading.layout = layout;
        if !matches!(layout, Layout::Single(_)) {
            self.reading.multi_layout = layout;
        }
    }

    /// The slice a pane shows (its index along the pane's fixed voxel axis).
    pub fn pane_slice(&self, kind: SliceKind) -> Option<usize> {
        let v = self.volume()?;
        Some(self.reading.crosshair[slices::pane_axes(v, kind).fixed])
    }

    /// Where a pane's image was drawn in the last frame (screen points).
    pub fn pane_rect(&self, kind: SliceKind) -> Option<egui::Rect> {
        self.panes.iter().find(|p| p.kind == kind)?.image_rect
    }

    /// The voxel under a screen point of a pane's image, as the pane maps it.
    pub fn pane_voxel_at(&self, kind: SliceKind, pos: egui::Pos2) -> Option<[usize; 3]> {
        let v = self.volume()?;
        let rect = self.pane_rect(kind)?;
        let axes = slices::pane_axes(v, kind);
        let (u, w) = axes.voxel_at(rect, pos, v.dims[axes.across], v.dims[axes.vertical])?;
        let mut p = self.reading.crosshair;
        p[axes.across] = u;
        p[axes.vertical] = w;
        Some(p)
    }

    /// Feature values (V, A, B) at the crosshair as last read back from the GPU.
    pub fn features_at_crosshair(&self) -> Option<[f32; 3]> {
        let entry = self.displayed_entry()?;
        self.probe.value_at(entry.id, self.reading.crosshair)
    }

    /// Starts loading a volume (the current one stays until the new one is ready). A link to
    /// it names files by their label and size, phantoms by name.
    pub fn open(&mut self, source: LoadSource) {
        let origin = match &source {
            LoadSource::Files { label, files } => Some(ViewSource::Dropped {
                name: label.clone(),
                bytes: files.iter().map(crate::io::InputFile::len).sum(),
            }),
            LoadSource::Phantom(name) => Some(ViewSource::Phantom(name.clone())),
            #[cfg(not(target_arch = "wasm32"))]
            LoadSource::Paths(_) => None,
            // Another series of the files shown: they came from where the shown one did.
            LoadSource::Series(_) => self.scene.as_ref().and_then(|s| s.origin.clone()),
        };
        self.open_from(source, origin);
    }

    /// Starts loading a volume that a link names by `origin`.
    pub fn open_from(&mut self, source: LoadSource, origin: Option<ViewSource>) {
        self.cancel_upload();
        self.load_progress = Some((0.0, format!("opening {}", source.label())));
        self.loading_origin = origin;
        self.load = Some(LoadJob::new(source));
        self.series.loading = None;
    }

    /// Switches the display mode; computes its features if they are not kept yet.
    pub fn set_mode(&mut self, mode: DisplayMode) {
        self.mode = mode;
        self.ensure_features();
    }

    /// Applies the edited parameters and computes the displayed method with them.
    pub fn recompute(&mut self) {
        self.applied = self.params.clone();
        self.ensure_features();
    }

    pub fn params_mut(&mut self) -> &mut FeatureParams {
        &mut self.params
    }

    /// Whether a feature computation is running.
    pub fn computing(&self) -> bool {
        self.features.running_request().is_some()
    }

    pub fn cancel_features(&mut self) {
        self.features.cancel();
    }

    // ---- Per-frame work ------------------------------------------------------------------

    fn displayed_request(&self) -> Option<Request> {
        self.mode.method().map(|m| self.applied.request(m))
    }

    fn displayed_entry(&self) -> Option<&FeatureEntry> {
        self.features.find(&self.displayed_request()?)
    }

    fn error(&mut self, message: String) {
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

    fn start_once(&mut self, ctx: &egui::Context) {
        if self.started {
            return;
        }
        self.started = true;
        // One frame when a job's step is done (`request_repaint` would ask for two).
        let wake = ctx.clone();
        self.features.set_waker(Arc::new(move || {
            wake.request_repaint_after(std::time::Duration::from_millis(1));
        }));
        #[cfg(target_arch = "wasm32")]
        if let Err(e) = web_files::install(ctx) {
            self.error(format!("drag and drop is unavailable: {e}"));
        }
        self.pacs_start(ctx);
        match self.options.start.clone() {
            StartWith::DemoCt => {
                #[cfg(target_arch = "wasm32")]
                {
                    self.cancel_upload();
                    self.load_progress = Some((0.0, "fetching the demo CT".to_owned()));
                    web_files::fetch_demo();
                }
                #[cfg(not(target_arch = "wasm32"))]
                self.open_from(demo::demo_source(), Some(ViewSource::Demo));
            }
            StartWith::Phantom(name) => self.open(LoadSource::Phantom(name)),
            #[cfg(not(target_arch = "wasm32"))]
            StartWith::Paths(paths) => self.open(LoadSource::Paths(paths)),
            StartWith::Urls(urls) => self.open_urls(urls),
            StartWith::DicomWeb(target) => self.open_dicomweb(target),
            StartWith::Nothing => {}
        }
    }

    /// Downloads volumes by URL (web; natively the command line opens paths instead).
    pub fn open_urls(&mut self, urls: Vec<String>) {
        #[cfg(target_arch = "wasm32")]
        {
            self.cancel_upload();
            self.load_progress = Some((0.0, format!("downloading {}", urls.join(", "))));
            web_fetch::fetch_urls(urls);
        }
        #[cfg(not(target_arch = "wasm32"))]
        self.error(format!(
            "{}: opening a volume by URL works in the browser; download it and open the file",
            urls.join(", ")
        ));
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

    /// N / Shift+N: the next or previous finding not dismissed.
    pub fn next_finding(&mut self, forward: bool) {
        if let Some(p) = self.findings.step(self.generation, forward) {
            self.go_to_lps(p);
        }
    }

    /// Asks for findings (as the panel's "List findings" does), for tests and automation.
    pub fn list_findings(&mut self) {
        self.findings.ask();
    }

    /// The findings of the shown volume, for tests and automation.
    pub fn findings_status(&self) -> crate::status::FindingsStatus {
        self.findings.status(self.generation)
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
    /// is done (its waker, from the queue's callback), so frames do not run back to back
    /// between steps: on a software adapter a frame costs ~0.25 s of the device, and three of
    /// them per step left the job a third of it. The progress line still moves four times a
    /// second. Natively the queue's callbacks run only when something polls: frames go on.
    fn repaint_for_job(&self, ctx: &egui::Context) {
        if self.features.running_request().is_none() {
            return;
        }
        if cfg!(target_arch = "wasm32") {
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
