//! Which voxel axes a pane shows and how (the radiological convention from the direction
//! cosines), the mapping between the pane's screen, its slice coordinates and the patient, and
//! the pane's zoom and pan.

use glam::DVec3;

use crate::volume::Volume;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SliceKind {
    Axial,
    Coronal,
    Sagittal,
}

impl SliceKind {
    pub const ALL: [Self; 3] = [Self::Axial, Self::Coronal, Self::Sagittal];

    pub fn name(self) -> &'static str {
        match self {
            Self::Axial => "axial",
            Self::Coronal => "coronal",
            Self::Sagittal => "sagittal",
        }
    }

    pub fn title(self) -> &'static str {
        match self {
            Self::Axial => "Axial",
            Self::Coronal => "Coronal",
            Self::Sagittal => "Sagittal",
        }
    }
}

/// How a pane maps voxel axes to the screen.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PaneAxes {
    /// The voxel axis held fixed (the slice index runs along it).
    pub fixed: usize,
    /// The voxel axis across the screen, and whether its index grows to the right.
    pub across: usize,
    pub right_positive: bool,
    /// The voxel axis up the screen, and whether its index grows upwards.
    pub vertical: usize,
    pub up_positive: bool,
    /// Whether the slice index grows towards superior (axial), anterior (coronal) or the
    /// patient's left (sagittal): the way wheel-up and arrow-up go.
    pub forward_positive: bool,
}

/// For each patient axis (x = L, y = P, z = S in LPS), the voxel axis closest to it.
fn voxel_axis_of_patient_axes(volume: &Volume) -> [usize; 3] {
    // Greedy on the largest direction-cosine component: an oblique volume still gets a
    // permutation.
    let d = volume.direction;
    let mut pairs: Vec<(f64, usize, usize)> = Vec::with_capacity(9);
    for voxel_axis in 0..3 {
        let col = d.col(voxel_axis);
        for (patient_axis, c) in [col.x, col.y, col.z].into_iter().enumerate() {
            pairs.push((c.abs(), voxel_axis, patient_axis));
        }
    }
    pairs.sort_by(|a, b| b.0.total_cmp(&a.0));
    let mut of_patient = [usize::MAX; 3];
    let mut used = [false; 3];
    for (_, v, p) in pairs {
        if of_patient[p] == usize::MAX && !used[v] {
            of_patient[p] = v;
            used[v] = true;
        }
    }
    // Degenerate directions (all zero): fall back to i, j, k.
    if of_patient.contains(&usize::MAX) {
        return [0, 1, 2];
    }
    of_patient
}

/// The axes of a pane for a volume.
pub fn pane_axes(volume: &Volume, kind: SliceKind) -> PaneAxes {
    let of_patient = voxel_axis_of_patient_axes(volume);
    let comp = |voxel_axis: usize, patient_axis: usize| -> f64 {
        volume.direction.col(voxel_axis)[patient_axis]
    };
    let (fixed, across, vertical, up_is_plus) = kind.patient_axes();
    let up = comp(of_patient[vertical], vertical);
    // Forward: +z (superior), -y (anterior), +x (left).
    let forward = comp(of_patient[fixed], fixed)
        * if kind == SliceKind::Coronal {
            -1.0
        } else {
            1.0
        };
    PaneAxes {
        fixed: of_patient[fixed],
        across: of_patient[across],
        right_positive: comp(of_patient[across], across) >= 0.0,
        vertical: of_patient[vertical],
        up_positive: if up_is_plus { up >= 0.0 } else { up < 0.0 },
        forward_positive: forward >= 0.0,
    }
}

impl SliceKind {
    /// The patient axes (x, y, z = 0, 1, 2) fixed, across (its + direction on the right) and
    /// vertical, and whether up is the vertical axis's + direction.
    fn patient_axes(self) -> (usize, usize, usize, bool) {
        match self {
            // Patient left (+x) on the right, anterior (-y) up.
            SliceKind::Axial => (2, 0, 1, false),
            // Patient left on the right, superior (+z) up.
            SliceKind::Coronal => (1, 0, 2, true),
            // Posterior (+y) on the right (the patient faces left), superior up.
            SliceKind::Sagittal => (0, 1, 2, true),
        }
    }
}

impl PaneAxes {
    /// The voxel (across, vertical) indices under a point of `rect` (the image), if inside.
    pub fn voxel_at(
        &self,
        rect: egui::Rect,
        pos: egui::Pos2,
        w: usize,
        h: usize,
    ) -> Option<(usize, usize)> {
        if !rect.contains(pos) || w == 0 || h == 0 {
            return None;
        }
        let fx = ((pos.x - rect.left()) / rect.width()).clamp(0.0, 0.999_999);
        let fy = ((pos.y - rect.top()) / rect.height()).clamp(0.0, 0.999_999);
        let col = (fx * w as f32) as usize;
        let row = (fy * h as f32) as usize;
        let u = if self.right_positive {
            col
        } else {
            w - 1 - col
        };
        let v = if self.up_positive { h - 1 - row } else { row };
        Some((u, v))
    }

    /// The continuous voxel coordinates (across, vertical; a voxel's centre at its integer
    /// index) of a screen point, for an image of `w` x `h` voxels drawn in `rect`.
    pub fn coord_at(&self, rect: egui::Rect, pos: egui::Pos2, w: usize, h: usize) -> [f64; 2] {
        let fx = f64::from((pos.x - rect.left()) / rect.width().max(1e-6)) * w as f64;
        let fy = f64::from((pos.y - rect.top()) / rect.height().max(1e-6)) * h as f64;
        let u = if self.right_positive {
            fx - 0.5
        } else {
            w as f64 - 0.5 - fx
        };
        let v = if self.up_positive {
            h as f64 - 0.5 - fy
        } else {
            fy - 0.5
        };
        [u, v]
    }

    /// The screen point of continuous voxel coordinates (the inverse of [`Self::coord_at`]).
    pub fn screen_of_coord(&self, rect: egui::Rect, c: [f64; 2], w: usize, h: usize) -> egui::Pos2 {
        let col = if self.right_positive {
            c[0] + 0.5
        } else {
            w as f64 - 0.5 - c[0]
        };
        let row = if self.up_positive {
            h as f64 - 0.5 - c[1]
        } else {
            c[1] + 0.5
        };
        egui::pos2(
            rect.left() + (col / w.max(1) as f64) as f32 * rect.width(),
            rect.top() + (row / h.max(1) as f64) as f32 * rect.height(),
        )
    }

    /// The world point (LPS mm) of continuous pane coordinates on slice `slice`.
    pub fn world_of(&self, volume: &Volume, slice: usize, c: [f64; 2]) -> DVec3 {
        let mut ijk = DVec3::ZERO;
        ijk[self.fixed] = slice as f64;
        ijk[self.across] = c[0];
        ijk[self.vertical] = c[1];
        volume.world_from_voxel().transform_point3(ijk)
    }

    /// The screen point of the centre of voxel (u, v) in `rect`.
    pub fn screen_of(
        &self,
        rect: egui::Rect,
        u: usize,
        v: usize,
        w: usize,
        h: usize,
    ) -> egui::Pos2 {
        let col = if self.right_positive {
            u
        } else {
            w.saturating_sub(1 + u)
        };
        let row = if self.up_positive {
            h.saturating_sub(1 + v)
        } else {
            v
        };
        egui::pos2(
            rect.left() + (col as f32 + 0.5) / w.max(1) as f32 * rect.width(),
            rect.top() + (row as f32 + 0.5) / h.max(1) as f32 * rect.height(),
        )
    }

    /// Texture coordinates that show the raw slice image (x = across, y = vertical) oriented.
    pub(in crate::app) fn uv(&self) -> egui::Rect {
        let (x0, x1) = if self.right_positive {
            (0.0, 1.0)
        } else {
            (1.0, 0.0)
        };
        let (y0, y1) = if self.up_positive {
            (1.0, 0.0)
        } else {
            (0.0, 1.0)
        };
        egui::Rect::from_min_max(egui::pos2(x0, y0), egui::pos2(x1, y1))
    }
}

/// Zoom and pan of a pane. Zoom 1 fits the whole slice in the pane; the pan is the offset of the
/// image's centre from the pane's centre, in mm of the image (so it survives a resize).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PaneView {
    pub zoom: f32,
    pub pan_mm: egui::Vec2,
}

impl Default for PaneView {
    fn default() -> Self {
        Self {
            zoom: 1.0,
            pan_mm: egui::Vec2::ZERO,
        }
    }
}

impl PaneView {
    pub const MIN_ZOOM: f32 = 0.25;
    pub const MAX_ZOOM: f32 = 64.0;

    /// Screen points per mm at zoom 1: the whole image fits `area`.
    fn fit_scale(area: egui::Rect, size_mm: egui::Vec2) -> f32 {
        (area.width() / size_mm.x.max(1e-6))
            .min(area.height() / size_mm.y.max(1e-6))
            .max(1e-3)
    }

    /// Where an image of `size_mm` is drawn in `area`.
    pub fn image_rect(&self, area: egui::Rect, size_mm: egui::Vec2) -> egui::Rect {
        let scale = Self::fit_scale(area, size_mm) * self.zoom;
        egui::Rect::from_center_size(area.center() + self.pan_mm * scale, size_mm * scale)
    }

    /// Zooms by `factor` keeping the image point under `pos` where it is.
    pub fn zoom_at(&mut self, area: egui::Rect, size_mm: egui::Vec2, pos: egui::Pos2, factor: f32) {
        if !factor.is_finite() || factor <= 0.0 {
            return;
        }
        let fit = Self::fit_scale(area, size_mm);
        let rect = self.image_rect(area, size_mm);
        let from_centre_mm = (pos - rect.center()) / (fit * self.zoom);
        self.zoom = (self.zoom * factor).clamp(Self::MIN_ZOOM, Self::MAX_ZOOM);
        let scale = fit * self.zoom;
        let centre = pos - from_centre_mm * scale;
        self.pan_mm = (centre - area.center()) / scale;
    }

    /// Moves the image by `delta` screen points.
    pub fn pan_by(&mut self, area: egui::Rect, size_mm: egui::Vec2, delta: egui::Vec2) {
        self.pan_mm += delta / (Self::fit_scale(area, size_mm) * self.zoom);
    }

    /// The zoom at which one voxel across spans one screen pixel, centred where it was.
    pub fn one_to_one(
        &mut self,
        area: egui::Rect,
        size_mm: egui::Vec2,
        voxels_across: usize,
        pixels_per_point: f32,
    ) {
        let points_per_voxel = 1.0 / pixels_per_point.max(1e-3);
        let points_per_mm = points_per_voxel * voxels_across.max(1) as f32 / size_mm.x.max(1e-6);
        let zoom = points_per_mm / Self::fit_scale(area, size_mm);
        self.zoom_at(area, size_mm, area.center(), zoom / self.zoom);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::app::slices::slice_position;
    use glam::{DMat3, DVec3};

    fn vol(direction: DMat3) -> Volume {
        let mut v = Volume::from_f32([4, 5, 6], [1.0; 3], vec![0.0; 120]);
        v.direction = direction;
        v
    }

    #[test]
    fn lps_volume_follows_the_radiological_convention() {
        let v = vol(DMat3::IDENTITY);
        let a = pane_axes(&v, SliceKind::Axial);
        // i runs to patient left: on the right; j runs posterior: index grows downwards.
        assert_eq!((a.fixed, a.across, a.vertical), (2, 0, 1));
        assert!(a.right_positive && !a.up_positive);
        let c = pane_axes(&v, SliceKind::Coronal);
        assert_eq!((c.fixed, c.across, c.vertical), (1, 0, 2));
        assert!(c.right_positive && c.up_positive);
        let s = pane_axes(&v, SliceKind::Sagittal);
        assert_eq!((s.fixed, s.across, s.vertical), (0, 1, 2));
        assert!(s.right_positive && s.up_positive);
    }

    #[test]
    fn flipped_and_permuted_volumes_show_the_same_way() {
        // A sagittally stored MR: i along -y (anterior), j along -z (inferior), k along +x (left).
        let d = DMat3::from_cols(DVec3::NEG_Y, DVec3::NEG_Z, DVec3::X);
        let v = vol(d);
        let a = pane_axes(&v, SliceKind::Axial);
        assert_eq!((a.fixed, a.across, a.vertical), (1, 2, 0));
        // i runs anterior, so its index grows upwards in the axial pane.
        assert!(a.right_positive && a.up_positive);
        let c = pane_axes(&v, SliceKind::Coronal);
        assert_eq!((c.fixed, c.across, c.vertical), (0, 2, 1));
        assert!(c.right_positive && !c.up_positive);
    }

    #[test]
    fn screen_and_voxel_round_trip() {
        let rect = egui::Rect::from_min_size(egui::pos2(10.0, 20.0), egui::vec2(100.0, 50.0));
        for right_positive in [true, false] {
            for up_positive in [true, false] {
                let axes = PaneAxes {
                    fixed: 2,
                    across: 0,
                    right_positive,
                    vertical: 1,
                    up_positive,
                    forward_positive: true,
                };
                for (u, v) in [(0, 0), (9, 4), (3, 2)] {
                    let p = axes.screen_of(rect, u, v, 10, 5);
                    assert_eq!(axes.voxel_at(rect, p, 10, 5), Some((u, v)));
                    let c = axes.coord_at(rect, p, 10, 5);
                    assert!((c[0] - u as f64).abs() < 1e-4 && (c[1] - v as f64).abs() < 1e-4);
                    let q = axes.screen_of_coord(rect, [u as f64 + 0.3, v as f64 - 0.2], 10, 5);
                    let c = axes.coord_at(rect, q, 10, 5);
                    assert!((c[0] - u as f64 - 0.3).abs() < 1e-4, "{c:?}");
                    assert!((c[1] - v as f64 + 0.2).abs() < 1e-4, "{c:?}");
                }
                assert_eq!(axes.voxel_at(rect, egui::pos2(0.0, 0.0), 10, 5), None);
            }
        }
    }

    #[test]
    fn forward_is_superior_anterior_left_whatever_the_voxel_order() {
        let lps = vol(DMat3::IDENTITY);
        let flipped = vol(DMat3::from_cols(DVec3::NEG_X, DVec3::NEG_Y, DVec3::NEG_Z));
        for kind in SliceKind::ALL {
            let (a, b) = (pane_axes(&lps, kind), pane_axes(&flipped, kind));
            assert_eq!(a.fixed, b.fixed);
            assert_ne!(a.forward_positive, b.forward_positive, "{kind:?}");
        }
        // LPS: k runs superior, j posterior (so anterior is -j), i left.
        assert!(pane_axes(&lps, SliceKind::Axial).forward_positive);
        assert!(!pane_axes(&lps, SliceKind::Coronal).forward_positive);
        assert!(pane_axes(&lps, SliceKind::Sagittal).forward_positive);
        // The position reads the same patient coordinate in both orders.
        let mut v = Volume::from_f32([4, 5, 6], [1.0, 1.0, 2.5], vec![0.0; 120]);
        v.origin_mm = [0.0, 0.0, -5.0];
        assert_eq!(
            slice_position(&v, pane_axes(&v, SliceKind::Axial), [0, 0, 1]),
            "I 2.5 mm"
        );
        assert_eq!(
            slice_position(&v, pane_axes(&v, SliceKind::Axial), [0, 0, 5]),
            "S 7.5 mm"
        );
        assert_eq!(
            slice_position(&v, pane_axes(&v, SliceKind::Coronal), [0, 3, 0]),
            "P 3.0 mm"
        );
    }

    #[test]
    fn zoom_keeps_the_point_under_the_pointer_and_pan_moves_the_image() {
        let area = egui::Rect::from_min_size(egui::pos2(100.0, 50.0), egui::vec2(300.0, 200.0));
        let size_mm = egui::vec2(180.0, 240.0);
        let mut view = PaneView::default();
        let fitted = view.image_rect(area, size_mm);
        assert!((fitted.height() - 200.0).abs() < 1e-3 && area.contains_rect(fitted.shrink(0.01)));
        for (pos, factor) in [
            (egui::pos2(180.0, 90.0), 2.0),
            (egui::pos2(300.0, 220.0), 3.5),
            (egui::pos2(150.0, 60.0), 0.4),
        ] {
            let before = view.image_rect(area, size_mm);
            let f = (pos - before.min) / before.size();
            view.zoom_at(area, size_mm, pos, factor);
            let after = view.image_rect(area, size_mm);
            let g = (pos - after.min) / after.size();
            assert!((f - g).length() < 1e-4, "{f:?} vs {g:?}");
        }
        let before = view.image_rect(area, size_mm);
        view.pan_by(area, size_mm, egui::vec2(13.0, -7.0));
        let after = view.image_rect(area, size_mm);
        assert!((after.min - before.min - egui::vec2(13.0, -7.0)).length() < 1e-3);
        view.zoom_at(area, size_mm, area.center(), 1e9);
        assert_eq!(view.zoom, PaneView::MAX_ZOOM);
        view.zoom_at(area, size_mm, area.center(), f32::NAN);
        assert_eq!(view.zoom, PaneView::MAX_ZOOM);
        // 1:1: one voxel (here 180 across) per pixel at 2 pixels per point.
        view.one_to_one(area, size_mm, 180, 2.0);
        let r = view.image_rect(area, size_mm);
        assert!((r.width() - 90.0).abs() < 1e-3, "{r:?}");
    }
}
