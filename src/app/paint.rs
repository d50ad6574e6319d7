//! Drawing both image panes share: a GPU texture shown in egui, and the scale bar (a round
//! length in mm near a fifth of the pane's width).

use crate::gpu::GpuContext;

/// A round length (1, 2 or 5 times a power of ten) in mm close to `target_mm`.
pub fn round_length_mm(target_mm: f64) -> f64 {
    if !(target_mm.is_finite() && target_mm > 0.0) {
        return 1.0;
    }
    let power = 10f64.powf(target_mm.log10().floor());
    let m = target_mm / power;
    let step = if m < 1.5 {
        1.0
    } else if m < 3.5 {
        2.0
    } else if m < 7.5 {
        5.0
    } else {
        10.0
    };
    step * power
}

/// A scale bar in the bottom-right corner of `area` for `points_per_mm` on screen: a round
/// length near a fifth of the width, with end ticks and its length written above.
pub fn draw_scale_bar(painter: &egui::Painter, area: egui::Rect, points_per_mm: f32) {
    if !(points_per_mm.is_finite() && points_per_mm > 0.0) || area.width() < 60.0 {
        return;
    }
    let mm = round_length_mm(f64::from(area.width() / points_per_mm) / 5.0);
    let length = mm as f32 * points_per_mm;
    let right = area.right_bottom() + egui::vec2(-10.0, -10.0);
    let left = right - egui::vec2(length, 0.0);
    // Light on a dark outline: readable on a CT's black and on a PET MIP's white alike.
    let outline = egui::Stroke::new(4.0, egui::Color32::from_black_alpha(170));
    let stroke = egui::Stroke::new(2.0, egui::Color32::from_gray(235));
    for s in [outline, stroke] {
        painter.line_segment([left, right], s);
        for p in [left, right] {
            painter.line_segment([p - egui::vec2(0.0, 5.0), p], s);
        }
    }
    let label = if mm >= 1.0 {
        format!("{mm:.0} mm")
    } else {
        format!("{mm} mm")
    };
    let at = left + egui::vec2(0.5 * length, -4.0);
    let font = egui::FontId::proportional(12.0);
    for (offset, colour) in [
        (egui::vec2(1.0, 1.0), egui::Color32::from_black_alpha(200)),
        (egui::Vec2::ZERO, egui::Color32::from_gray(235)),
    ] {
        let (label, font) = (label.clone(), font.clone());
        painter.text(
            at + offset,
            egui::Align2::CENTER_BOTTOM,
            label,
            font,
            colour,
        );
    }
}

/// Shows a GPU texture in egui under `id`: registered the first time, pointed at the new view
/// after (a texture made again at another size). Both image panes go through here.
pub fn show_texture(
    render_state: &eframe::egui_wgpu::RenderState,
    gpu: &GpuContext,
    view: &wgpu::TextureView,
    id: &mut Option<egui::TextureId>,
) {
    let mut renderer = render_state.renderer.write();
    match *id {
        Some(id) => renderer.update_egui_texture_from_wgpu_texture(
            &gpu.device,
            view,
            wgpu::FilterMode::Linear,
            id,
        ),
        None => {
            *id =
                Some(renderer.register_native_texture(&gpu.device, view, wgpu::FilterMode::Linear));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_lengths() {
        for (target, want) in [
            (0.9, 1.0),
            (1.6, 2.0),
            (4.0, 5.0),
            (8.0, 10.0),
            (23.0, 20.0),
            (0.3, 0.2),
        ] {
            let got = round_length_mm(target);
            assert!((got - want).abs() < 1e-9, "{target}: {got}");
        }
        assert_eq!(round_length_mm(f64::NAN), 1.0);
        assert_eq!(round_length_mm(-3.0), 1.0);
    }
}
