//! The viewer app (eframe, wgpu renderer): the same code runs in the browser and in a native
//! window. It owns the loaded volume, the GPU context it takes from eframe, and the panes.

pub mod mip_view;
mod slices;

use std::sync::Arc;

use crate::gpu::axis_mip::{AxisMip, AxisMipOutput};
use crate::gpu::{GpuContext, GpuVolume};
use crate::status::{AdapterStatus, AppStatus, Phase, VolumeStatus};
use crate::volume::Volume;
use slices::{SliceAxis, SlicePane};

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
pub fn run_native() -> anyhow::Result<()> {
    let options = eframe::NativeOptions {
        renderer: eframe::Renderer::Wgpu,
        wgpu_options: wgpu_options(),
        viewport: egui::ViewportBuilder::default()
            .with_title("Shapecast")
            .with_inner_size([1280.0, 800.0]),
        ..Default::default()
    };
    eframe::run_native(
        "Shapecast",
        options,
        Box::new(|cc| Ok(Box::new(ShapecastApp::new(cc)))),
    )
    .map_err(|e| anyhow::anyhow!("could not open the viewer window: {e}"))
}

/// The MIP on the GPU and the id egui draws it with.
struct MipView {
    output: AxisMipOutput,
    texture_id: egui::TextureId,
    axis: usize,
}

/// Where the app is in getting from nothing to a displayed volume. Each step runs in one frame,
/// so the browser's event loop is never blocked for long.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Step {
    LoadDemo,
    Upload,
    Project,
    Idle,
}

pub struct ShapecastApp {
    gpu: Option<GpuContext>,
    status: AppStatus,
    published: Option<AppStatus>,
    step: Step,
    volume: Option<Arc<Volume>>,
    gpu_volume: Option<GpuVolume>,
    axis_mip: Option<AxisMip>,
    mip: Option<MipView>,
    mip_axis: usize,
    /// Display window (lo, hi) in physical units.
    window: (f32, f32),
    /// The shared crosshair, voxel index.
    crosshair: [usize; 3],
    panes: [SlicePane; 3],
}

impl ShapecastApp {
    pub fn new(cc: &eframe::CreationContext<'_>) -> Self {
        // Radiologists read in a dark room: dark theme regardless of the system's.
        cc.egui_ctx.set_theme(egui::Theme::Dark);
        let gpu = cc
            .wgpu_render_state
            .as_ref()
            .map(GpuContext::from_render_state);
        let mut status = AppStatus::default();
        match &gpu {
            Some(g) => {
                #[cfg(target_arch = "wasm32")]
                let name = crate::web::browser_adapter_name()
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
        Self::with_gpu(gpu, status)
    }

    fn with_gpu(gpu: Option<GpuContext>, status: AppStatus) -> Self {
        Self {
            gpu,
            status,
            published: None,
            step: Step::LoadDemo,
            volume: None,
            gpu_volume: None,
            axis_mip: None,
            mip: None,
            mip_axis: 1,
            window: (-160.0, 240.0),
            crosshair: [0; 3],
            panes: [
                SlicePane::new(SliceAxis::Axial),
                SlicePane::new(SliceAxis::Coronal),
                SlicePane::new(SliceAxis::Sagittal),
            ],
        }
    }

    /// The shared crosshair, voxel index.
    pub fn crosshair(&self) -> [usize; 3] {
        self.crosshair
    }

    /// The status as `window.shapecastStatus` shows it.
    pub fn status(&self) -> &AppStatus {
        &self.status
    }

    fn fail(&mut self, message: String) {
        log::error!("{message}");
        self.status.phase = Phase::Error;
        self.status.error = Some(message);
        self.step = Step::Idle;
    }

    /// Advances loading and computing by one step.
    fn advance(&mut self, frame: &mut eframe::Frame) {
        if self.status.phase == Phase::Error && self.gpu.is_none() {
            return;
        }
        match self.step {
            Step::LoadDemo => {
                self.status.phase = Phase::Loading;
                self.set_volume(crate::phantom::demo());
                self.step = Step::Upload;
            }
            Step::Upload => {
                self.status.phase = Phase::Computing;
                self.status.progress = 0.0;
                let (Some(gpu), Some(volume)) = (&self.gpu, &self.volume) else {
                    return;
                };
                match GpuVolume::upload(gpu, volume) {
                    Ok(v) => {
                        self.gpu_volume = Some(v);
                        self.status.progress = 0.5;
                        self.step = Step::Project;
                    }
                    Err(e) => self.fail(format!("{e}")),
                }
            }
            Step::Project => self.project(frame),
            Step::Idle => {}
        }
    }

    fn project(&mut self, frame: &mut eframe::Frame) {
        let Some(gpu) = &self.gpu else { return };
        let Some(gpu_volume) = &self.gpu_volume else {
            return;
        };
        if self.axis_mip.is_none() {
            match AxisMip::new(gpu) {
                Ok(k) => self.axis_mip = Some(k),
                Err(e) => return self.fail(format!("{e}")),
            }
        }
        let Some(kernel) = &self.axis_mip else { return };
        let output = kernel.run(gpu, gpu_volume, self.mip_axis, self.window);
        let Some(render_state) = frame.wgpu_render_state() else {
            return self.fail("no wgpu render state to draw the projection with".to_owned());
        };
        let mut renderer = render_state.renderer.write();
        let texture_id = match self.mip.take() {
            Some(old) => {
                renderer.update_egui_texture_from_wgpu_texture(
                    &gpu.device,
                    &output.view,
                    wgpu::FilterMode::Linear,
                    old.texture_id,
                );
                old.texture_id
            }
            None => renderer.register_native_texture(
                &gpu.device,
                &output.view,
                wgpu::FilterMode::Linear,
            ),
        };
        self.mip = Some(MipView {
            output,
            texture_id,
            axis: self.mip_axis,
        });
        self.status.progress = 1.0;
        self.status.phase = Phase::Ready;
        self.step = Step::Idle;
    }

    fn set_volume(&mut self, volume: Volume) {
        self.crosshair = volume.dims.map(|d| d / 2);
        self.status.volume = Some(VolumeStatus {
            dims: volume.dims,
            spacing_mm: volume.spacing_mm,
            source: volume.source.clone(),
        });
        self.volume = Some(Arc::new(volume));
        self.gpu_volume = None;
        for pane in &mut self.panes {
            pane.invalidate();
        }
    }

    fn top_bar_ui(&mut self, ui: &mut egui::Ui) {
        ui.horizontal(|ui| {
            ui.heading("Shapecast");
            ui.separator();
            if let Some(v) = &self.status.volume {
                ui.label(&v.source);
            }
            ui.separator();
            ui.label("MIP view:");
            let before = self.mip_axis;
            ui.selectable_value(&mut self.mip_axis, 1, "anterior");
            ui.selectable_value(&mut self.mip_axis, 0, "lateral");
            ui.selectable_value(&mut self.mip_axis, 2, "superior");
            if before != self.mip_axis && self.gpu_volume.is_some() {
                self.step = Step::Project;
            }
        });
    }

    fn status_bar_ui(&self, ui: &mut egui::Ui) {
        ui.horizontal(|ui| {
            ui.label(self.status.phase.as_str());
            if let Some(a) = &self.status.adapter {
                ui.separator();
                ui.label(format!("GPU: {} ({})", a.name, a.backend));
            }
            if let Some(volume) = &self.volume {
                ui.separator();
                let [i, j, k] = self.crosshair;
                let p = volume
                    .world_from_voxel()
                    .transform_point3(glam::DVec3::new(i as f64, j as f64, k as f64));
                ui.label(format!(
                    "crosshair voxel ({i}, {j}, {k})  LPS ({:.1}, {:.1}, {:.1}) mm  value {:.0}",
                    p.x,
                    p.y,
                    p.z,
                    volume.value_at(i, j, k)
                ));
            }
            if let Some(e) = &self.status.error {
                ui.separator();
                ui.colored_label(ui.visuals().error_fg_color, e);
            }
        });
    }

    fn mip_ui(&mut self, ui: &mut egui::Ui) {
        let Some(mip) = &self.mip else {
            ui.centered_and_justified(|ui| {
                ui.spinner();
            });
            return;
        };
        let Some(volume) = &self.volume else { return };
        let [w, h] = mip.output.size;
        // The image's u and v run along the two remaining axes; show them at their true size in mm.
        let (su, sv) = match mip.axis {
            0 => (volume.spacing_mm[1], volume.spacing_mm[2]),
            1 => (volume.spacing_mm[0], volume.spacing_mm[2]),
            _ => (volume.spacing_mm[0], volume.spacing_mm[1]),
        };
        let size_mm = egui::vec2(w as f32 * su as f32, h as f32 * sv as f32);
        let avail = ui.available_size();
        let scale = (avail.x / size_mm.x).min(avail.y / size_mm.y).max(0.01);
        // k (superior) points up on screen for the anterior and lateral views.
        let uv = if mip.axis == 2 {
            egui::Rect::from_min_max(egui::pos2(0.0, 0.0), egui::pos2(1.0, 1.0))
        } else {
            egui::Rect::from_min_max(egui::pos2(0.0, 1.0), egui::pos2(1.0, 0.0))
        };
        ui.centered_and_justified(|ui| {
            ui.add(
                egui::Image::new((mip.texture_id, size_mm * scale))
                    .uv(uv)
                    .fit_to_exact_size(size_mm * scale),
            );
        });
    }
}

impl eframe::App for ShapecastApp {
    fn logic(&mut self, ctx: &egui::Context, _frame: &mut eframe::Frame) {
        if self.step != Step::Idle {
            ctx.request_repaint();
        }
    }

    fn ui(&mut self, ui: &mut egui::Ui, frame: &mut eframe::Frame) {
        self.advance(frame);
        self.status.frames += 1;

        egui::Panel::top("top").show(ui, |ui| self.top_bar_ui(ui));
        egui::Panel::bottom("status").show(ui, |ui| self.status_bar_ui(ui));
        egui::Panel::right("slices")
            .resizable(true)
            .default_size(ui.available_width() * 0.45)
            .show(ui, |ui| {
                if let Some(volume) = self.volume.clone() {
                    let h = ui.available_height() / 3.0 - 4.0;
                    for pane in &mut self.panes {
                        let size = egui::vec2(ui.available_width(), h);
                        ui.allocate_ui(size, |ui| {
                            pane.ui(ui, &volume, &mut self.crosshair, self.window);
                        });
                    }
                }
            });
        egui::CentralPanel::default().show(ui, |ui| self.mip_ui(ui));

        if self.published.as_ref() != Some(&self.status) {
            self.status.publish();
            self.published = Some(self.status.clone());
        }
        if self.status.phase != Phase::Ready && self.status.phase != Phase::Error {
            ui.ctx().request_repaint();
        }
    }
}
