//! What a slice pane draws over its picture: the crosshair, the orientation labels, the
//! position of the slice, and the measurements.

use super::*;

/// Where a slice's image lies on screen: its rectangle (larger than the pane when zoomed in),
/// the pane's axes, and the image's size in voxels across (`w`) and up (`h`).
#[derive(Clone, Copy)]
pub(super) struct Placed {
    pub rect: egui::Rect,
    pub axes: PaneAxes,
    pub w: usize,
    pub h: usize,
}

impl Placed {
    /// The screen point of the centre of voxel (u, v) of the image.
    pub fn screen_of(&self, u: usize, v: usize) -> egui::Pos2 {
        self.axes.screen_of(self.rect, u, v, self.w, self.h)
    }

    /// The screen point of continuous pane coordinates.
    pub fn screen_of_coord(&self, c: [f64; 2]) -> egui::Pos2 {
        self.axes.screen_of_coord(self.rect, c, self.w, self.h)
    }
}

impl SlicePane {
    pub(super) fn draw_overlay(
        &self,
        painter: &egui::Painter,
        area: egui::Rect,
        at: Placed,
        crosshair: &[usize; 3],
        volume: &Volume,
    ) {
        let axes = at.axes;
        // What of the image is on screen (zoomed in, the image is larger than the pane).
        let shown = at.rect.intersect(area);
        // Crosshair lines with a gap around the point, so they never hide what is there.
        let c = at.screen_of(crosshair[axes.across], crosshair[axes.vertical]);
        let gap = 10.0;
        let stroke =
            egui::Stroke::new(1.0, egui::Color32::from_rgba_unmultiplied(90, 220, 90, 200));
        for seg in [
            [egui::pos2(c.x, shown.top()), egui::pos2(c.x, c.y - gap)],
            [egui::pos2(c.x, c.y + gap), egui::pos2(c.x, shown.bottom())],
            [egui::pos2(shown.left(), c.y), egui::pos2(c.x - gap, c.y)],
            [egui::pos2(c.x + gap, c.y), egui::pos2(shown.right(), c.y)],
        ] {
            if seg[0].x <= seg[1].x && seg[0].y <= seg[1].y {
                painter.line_segment(seg, stroke);
            }
        }

        // Patient-direction labels on the four edges of what is shown.
        let dir = |a: usize, positive: bool| {
            let d = volume.direction.col(a);
            if positive { d } else { -d }
        };
        let right = dir(axes.across, axes.right_positive);
        let up = dir(axes.vertical, axes.up_positive);
        let colour = egui::Color32::from_rgb(240, 200, 80);
        let font = egui::FontId::proportional(14.0);
        for (pos, align, d) in [
            (
                shown.right_center() - egui::vec2(4.0, 0.0),
                egui::Align2::RIGHT_CENTER,
                right,
            ),
            (
                shown.left_center() + egui::vec2(4.0, 0.0),
                egui::Align2::LEFT_CENTER,
                -right,
            ),
            (
                shown.center_top() + egui::vec2(0.0, 4.0),
                egui::Align2::CENTER_TOP,
                up,
            ),
            (
                shown.center_bottom() - egui::vec2(0.0, 4.0),
                egui::Align2::CENTER_BOTTOM,
                -up,
            ),
        ] {
            painter.text(pos, align, orientation_label(d), font.clone(), colour);
        }
    }

    /// The measurements of this pane made on the slice shown.
    pub(super) fn draw_measurements(
        &self,
        painter: &egui::Painter,
        inputs: &PaneInputs<'_>,
        at: Placed,
        slice: usize,
    ) {
        for (n, entry) in inputs.measurements.iter().enumerate() {
            let m = &entry.measurement;
            if m.pane.is_none() {
                draw_ends_3d(painter, inputs, n, at, slice);
                continue;
            }
            if m.pane != Some(self.kind) {
                continue;
            }
            let Some(p) = m.in_pane(inputs.volume) else {
                continue;
            };
            if p.slice == slice {
                draw_measurement(painter, entry, inputs.unit, at, [p.a, p.b], false);
            }
        }
    }
}

/// The slice's position along the pane's normal through the crosshair, e.g. "S 12.5 mm": the
/// patient coordinate (LPS mm) along the normal of the slice plane, signed towards the pane's
/// forward direction (superior, anterior, left), written with the letter of the side it is on.
pub fn slice_position(volume: &Volume, axes: PaneAxes, crosshair: [usize; 3]) -> String {
    let d = volume.direction;
    let forward = d.col(axes.fixed) * if axes.forward_positive { 1.0 } else { -1.0 };
    let mut normal = d.col(axes.across).cross(d.col(axes.vertical));
    if normal.length_squared() < 1e-12 {
        normal = forward;
    }
    let mut normal = normal.normalize_or_zero();
    if normal.dot(forward) < 0.0 {
        normal = -normal;
    }
    let p = volume.world_from_voxel().transform_point3(DVec3::new(
        crosshair[0] as f64,
        crosshair[1] as f64,
        crosshair[2] as f64,
    ));
    let along = p.dot(normal);
    let side = if along >= 0.0 { normal } else { -normal };
    format!("{} {:.1} mm", orientation_label(side), along.abs())
}

/// The ends of ruler `n` in 3D that lie on the slice shown: a ring each, with its number and
/// length.
pub(super) fn draw_ends_3d(
    painter: &egui::Painter,
    inputs: &PaneInputs<'_>,
    n: usize,
    at: Placed,
    slice: usize,
) {
    let axes = at.axes;
    let Some(entry) = inputs.measurements.get(n) else {
        return;
    };
    let m = &entry.measurement;
    let volume = inputs.volume;
    let to_voxel = volume.voxel_from_world();
    let top = volume.dims[axes.fixed].saturating_sub(1) as f64;
    let colour = egui::Color32::from_rgb(90, 200, 255);
    for end in [m.a_mm, m.b_mm] {
        let v = to_voxel.transform_point3(end);
        // An end is on the slice whose voxels hold it (none outside the volume).
        let k = v[axes.fixed];
        if !v.is_finite()
            || !(-0.5..=top + 0.5).contains(&k)
            || k.round().max(0.0) as usize != slice
        {
            continue;
        }
        let p = at.screen_of_coord([v[axes.across], v[axes.vertical]]);
        painter.circle_stroke(p, 5.0, egui::Stroke::new(1.5, colour));
        painter.text(
            p + egui::vec2(7.0, -7.0),
            egui::Align2::LEFT_BOTTOM,
            format!("{} 3D {}", n + 1, entry.reading(inputs.unit)),
            egui::FontId::proportional(13.0),
            colour,
        );
    }
}

/// A ruler (line, end ticks, length) or an ellipse (outline and statistics) between pane
/// coordinates `a` and `b` (the one being drawn, `drawing`, in another colour).
pub(super) fn draw_measurement(
    painter: &egui::Painter,
    entry: &measure::Entry,
    unit: &str,
    at: Placed,
    [a, b]: [[f64; 2]; 2],
    drawing: bool,
) {
    let colour = if drawing {
        egui::Color32::from_rgb(255, 230, 120)
    } else {
        egui::Color32::from_rgb(90, 200, 255)
    };
    let stroke = egui::Stroke::new(1.5, colour);
    let (pa, pb) = (at.screen_of_coord(a), at.screen_of_coord(b));
    let font = egui::FontId::proportional(13.0);
    match entry.measurement.kind {
        MeasureKind::Ruler => {
            painter.line_segment([pa, pb], stroke);
            let along = (pb - pa).normalized();
            let tick = egui::vec2(-along.y, along.x) * 5.0;
            for p in [pa, pb] {
                painter.line_segment([p - tick, p + tick], stroke);
            }
            painter.text(
                pb + egui::vec2(6.0, -6.0),
                egui::Align2::LEFT_BOTTOM,
                entry.reading(unit),
                font,
                colour,
            );
        }
        MeasureKind::Ellipse => {
            let centre = pa + (pb - pa) * 0.5;
            let radius = ((pb - pa) * 0.5).abs();
            let points: Vec<egui::Pos2> = (0..64)
                .map(|n| {
                    let t = n as f32 / 64.0 * std::f32::consts::TAU;
                    centre + egui::vec2(radius.x * t.cos(), radius.y * t.sin())
                })
                .collect();
            painter.add(egui::Shape::closed_line(points, stroke));
            painter.text(
                egui::pos2(centre.x, centre.y + radius.y + 4.0),
                egui::Align2::CENTER_TOP,
                entry.reading(unit),
                font,
                colour,
            );
        }
    }
}
