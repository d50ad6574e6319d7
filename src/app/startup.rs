//! Starting the viewer: the wgpu configuration, the native window, the app's first state and
//! what it opens first (the demo, a phantom, paths, URLs, an archive's study).

use super::platform::Platform as _;
use super::*;

/// The eframe/egui wgpu configuration both targets use: the adapter's own limits and features
/// (wgpu's defaults are far too small for volumes), WebGPU only on the web.
pub fn wgpu_options() -> eframe::egui_wgpu::WgpuConfiguration {
    use eframe::egui_wgpu::{WgpuConfiguration, WgpuSetup, WgpuSetupCreateNew};
    let mut create = WgpuSetupCreateNew::without_display_handle();
    create.device_descriptor = Arc::new(crate::gpu::context::device_descriptor);
    create.instance_descriptor.backends = if platform::IN_PAGE {
        wgpu::Backends::BROWSER_WEBGPU
    } else {
        wgpu::Backends::from_env().unwrap_or(wgpu::Backends::PRIMARY)
    };
    WgpuConfiguration {
        wgpu_setup: WgpuSetup::CreateNew(create),
        ..Default::default()
    }
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
        if let Some(g) = &gpu {
            crate::gpu::volume_texture::ask_render_attachment_3d(g);
        }
        match &gpu {
            Some(g) => {
                status.adapter = Some(AdapterStatus {
                    name: g.adapter_name(),
                    backend: format!("{:?}", g.adapter_info.backend),
                });
                log::info!("GPU context:\n{}", g.describe());
            }
            None => {
                status.phase = Phase::Error;
                status.error = Some("eframe started without a wgpu renderer".to_owned());
            }
        }
        // The GPU budget for the volume textures: the user's, or the adapter's rule.
        let gpu_budget = gpu.as_ref().map_or_else(
            || crate::gpu::budget::GpuBudget::user_mib(options.gpu_budget_mib.unwrap_or(1536)),
            |g| crate::gpu::budget::GpuBudget::choose(&g.adapter_info, options.gpu_budget_mib),
        );
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
            features: FeatureManager::with_budget(gpu_budget),
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
            platform: Default::default(),
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

    pub(super) fn start_once(&mut self, ctx: &egui::Context) {
        if self.started {
            return;
        }
        self.started = true;
        // One frame when a job's step is done (`request_repaint` would ask for two).
        let wake = ctx.clone();
        self.features.set_waker(Arc::new(move || {
            wake.request_repaint_after(std::time::Duration::from_millis(1));
        }));
        if let Err(e) = self.platform.install(ctx) {
            self.error(e);
        }
        self.pacs_start(ctx);
        match self.options.start.clone() {
            StartWith::DemoCt => self.open_demo_ct(),
            StartWith::Phantom(name) => self.open(LoadSource::Phantom(name)),
            StartWith::Paths(paths) => self.open(LoadSource::Paths(paths)),
            StartWith::Urls(urls) => self.open_urls(urls),
            StartWith::DicomWeb(target) => self.open_dicomweb(target),
            StartWith::Nothing => {}
        }
    }

    /// Downloads volumes by URL (web; natively the command line opens paths instead).
    pub fn open_urls(&mut self, urls: Vec<String>) {
        let what = format!("downloading {}", urls.join(", "));
        match self.platform.fetch(urls) {
            Ok(()) => {
                self.cancel_upload();
                self.load_progress = Some((0.0, what));
            }
            Err(why) => self.error(why),
        }
    }
}
