//! Stand-in for the MIP viewport until the ray caster's widget (`src/app/mip_view.rs`, branch
//! `render`) lands: the axis-aligned intensity MIP of `gpu::axis_mip` along one of three
//! directions (anterior, lateral, superior), at its true aspect. A click moves the crosshair in
//! the projection's plane. It takes the same [`MipInputs`] the widget will.

use eframe::egui_wgpu::RenderState;

use crate::gpu::axis_mip::{AxisMip, AxisMipOutput};
use crate::gpu::{GpuContext, GpuVolume};
use crate::volume::Volume;

use super::MipInputs;

struct Drawn {
    output: AxisMipOutput,
    texture_id: egui::TextureId,
    key: (u64, usize, (f32, f32)),
}

/// The placeholder's state: its kernel, the volume as the f32 buffer that kernel reads, and the
/// last projection.
#[derive(Default)]
pub struct AxisMipPane {
    kernel: Option<AxisMip>,
    volume: Option<(u64, GpuVolume)>,
    drawn: Option<Drawn>,
    /// 1: anterior (along j), 0: lateral (along i), 2: superior (along k).
    pub axis: usize,
    error: Option<(u64, String)>,
}

impl AxisMipPane {
    pub fn new() -> Self {
        Self {
            axis: 1,
            ..Default::default()
        }
    }

    fn prepare(
        &mut self,
        gpu: &GpuContext,
        render_state: &RenderState,
        volume: &Volume,
        generation: u64,
        window: (f32, f32),
    ) -> Result<(), String> {
        if let Some((g, e)) = &self.error
            && *g == generation
        {
            return Err(e.clone());
        }
        if self.kernel.is_none() {
            self.kernel = Some(AxisMip::new(gpu).map_err(|e| e.to_string())?);
        }
        if self.volume.as_ref().map(|(g, _)| *g) != Some(generation) {
            self.volume = None;
            let v = GpuVolume::upload(gpu, volume).map_err(|e| format!("MIP: {e}"))?;
            self.volume = Some((generation, v));
        }
        let key = (generation, self.axis, window);
        if self.drawn.as_ref().map(|d| d.key) == Some(key) {
            return Ok(());
        }
        let (Some(kernel), Some((_, gv))) = (&self.kernel, &self.volume) else {
            return Ok(());
        };
        let output = kernel.run(gpu, gv, self.axis, window);
        let mut renderer = render_state.renderer.write();
        let texture_id = match self.drawn.take() {
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
        self.drawn = Some(Drawn {
            output,
            texture_id,
            key,
        });
        Ok(())
    }

    /// Draws the pane; returns true when its maximise/restore button was clicked.
    pub fn ui(&mut self, ui: &mut egui::Ui, inputs: MipInputs<'_>, maximised: bool) -> bool {
        let mut toggle = false;
        ui.horizontal(|ui| {
            ui.strong("MIP");
            ui.selectable_value(&mut self.axis, 1, "anterior");
            ui.selectable_value(&mut self.axis, 0, "lateral");
            ui.selectable_value(&mut self.axis, 2, "superior");
            ui.label(
                egui::RichText::new("axis-aligned intensity (stand-in for the shape MIP)").small(),
            );
            ui.with_layout(egui::Layout::right_to_left(egui::Align::Center), |ui| {
                let (text, tip) = if maximised {
                    ("restore", "back to all panes")
                } else {
                    ("maximise", "show this pane alone")
                };
                if ui.small_button(text).on_hover_text(tip).clicked() {
                    toggle = true;
                }
            });
        });
        let volume = inputs.volume;
        // A MIP collects the brightest values: the slice window's upper end raised by one width
        // keeps contrast-filled vessels and bone apart instead of all white.
        let (lo, hi) = inputs.window;
        let window = (lo, hi + (hi - lo));
        if let Err(e) = self.prepare(
            inputs.gpu,
            inputs.render_state,
            volume,
            inputs.generation,
            window,
        ) {
            self.error = Some((inputs.generation, e.clone()));
            ui.colored_label(ui.visuals().warn_fg_color, e);
            return toggle;
        }
        let Some(drawn) = &self.drawn else {
            return toggle;
        };
        let [w, h] = drawn.output.size;
        // The image's u and v run along the two remaining axes (see axis_mip::out_size).
        let (au, av) = match self.axis {
            0 => (1, 2),
            1 => (0, 2),
            _ => (0, 1),
        };
        let size_mm = egui::vec2(
            (f64::from(w) * volume.spacing_mm[au]) as f32,
            (f64::from(h) * volume.spacing_mm[av]) as f32,
        );
        let area = ui.available_rect_before_wrap();
        let response = ui.allocate_rect(area, egui::Sense::click_and_drag());
        let scale = (area.width() / size_mm.x)
            .min(area.height() / size_mm.y)
            .max(0.01);
        let rect = egui::Rect::from_center_size(area.center(), size_mm * scale);
        // k (superior) up for the anterior and lateral views.
        let up = self.axis != 2;
        let uv = if up {
            egui::Rect::from_min_max(egui::pos2(0.0, 1.0), egui::pos2(1.0, 0.0))
        } else {
            egui::Rect::from_min_max(egui::pos2(0.0, 0.0), egui::pos2(1.0, 1.0))
        };
        let painter = ui.painter_at(area);
        painter.rect_filled(area, 0.0, egui::Color32::BLACK);
        painter.image(drawn.texture_id, rect, uv, egui::Color32::WHITE);
        if (response.clicked() || response.dragged_by(egui::PointerButton::Primary))
            && let Some(pos) = response.interact_pointer_pos()
            && rect.contains(pos)
        {
            let fu = ((pos.x - rect.left()) / rect.width()).clamp(0.0, 0.999_999);
            let fv = ((pos.y - rect.top()) / rect.height()).clamp(0.0, 0.999_999);
            let u = (fu * w as f32) as usize;
            let row = (fv * h as f32) as usize;
            let v = if up { h as usize - 1 - row } else { row };
            inputs.crosshair[au] = u;
            inputs.crosshair[av] = v;
        }
        // The crosshair's position in the projection.
        let cu = (inputs.crosshair[au] as f32 + 0.5) / w.max(1) as f32;
        let cv = (inputs.crosshair[av] as f32 + 0.5) / h.max(1) as f32;
        let p = egui::pos2(
            rect.left() + cu * rect.width(),
            if up {
                rect.bottom() - cv * rect.height()
            } else {
                rect.top() + cv * rect.height()
            },
        );
        painter.circle_stroke(
            p,
            6.0,
            egui::Stroke::new(1.0, egui::Color32::from_rgb(90, 220, 90)),
        );
        toggle
    }
}
