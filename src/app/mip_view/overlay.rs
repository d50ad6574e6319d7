//! What the MIP draws over its picture (orientation letters, the crosshair marker, errors).

use super::*;

impl MipView {
    /// Orientation letters on the four edges, the crosshair marker, errors.
    pub(super) fn draw_overlay(&self, painter: &egui::Painter, rect: egui::Rect) {
        let (right, up, _) = self.camera.basis();
        let font = egui::FontId::proportional(14.0);
        let colour = egui::Color32::from_rgb(230, 200, 80);
        let edge = 6.0;
        for (dir, anchor, pos) in [
            (
                right,
                egui::Align2::RIGHT_CENTER,
                egui::pos2(rect.right() - edge, rect.center().y),
            ),
            (
                -right,
                egui::Align2::LEFT_CENTER,
                egui::pos2(rect.left() + edge, rect.center().y),
            ),
            (
                up,
                egui::Align2::CENTER_TOP,
                egui::pos2(rect.center().x, rect.top() + edge),
            ),
            (
                -up,
                egui::Align2::CENTER_BOTTOM,
                egui::pos2(rect.center().x, rect.bottom() - edge),
            ),
        ] {
            painter.text(pos, anchor, orientation_label(dir), font.clone(), colour);
        }
        if let Some(c) = self.crosshair_mm
            && let Some(p) = self.screen_pos_of(c)
        {
            let stroke = egui::Stroke::new(1.5, egui::Color32::from_rgb(80, 220, 80));
            for (a, b) in [
                (egui::vec2(-10.0, 0.0), egui::vec2(-3.0, 0.0)),
                (egui::vec2(3.0, 0.0), egui::vec2(10.0, 0.0)),
                (egui::vec2(0.0, -10.0), egui::vec2(0.0, -3.0)),
                (egui::vec2(0.0, 3.0), egui::vec2(0.0, 10.0)),
            ] {
                painter.line_segment([p + a, p + b], stroke);
            }
        }
        for m in &self.markers {
            if let Some(p) = self.screen_pos_of(m.lps_mm) {
                crate::app::findings::draw_one(painter, m, p, 9.0);
            }
        }
        if let Some(t) = &self.hover_text {
            painter.text(
                rect.left_top() + egui::vec2(edge, edge),
                egui::Align2::LEFT_TOP,
                t,
                egui::FontId::proportional(13.0),
                egui::Color32::from_gray(200),
            );
        }
        if let Some(e) = &self.error {
            painter.text(
                rect.left_bottom() + egui::vec2(edge, -edge),
                egui::Align2::LEFT_BOTTOM,
                e,
                font,
                egui::Color32::from_rgb(255, 90, 90),
            );
        }
    }
}
