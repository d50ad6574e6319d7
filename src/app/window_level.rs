//! Display window (width and level) of the grey values: the CT presets radiologists know, a
//! default per modality, and the change a right-button drag makes.

use crate::volume::Volume;

/// A display window in physical units (HU for CT).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Window {
    pub width: f32,
    pub level: f32,
}

/// Narrowest window a drag can make (physical units).
const MIN_WIDTH: f32 = 1.0;

impl Window {
    pub const fn new(width: f32, level: f32) -> Self {
        Self { width, level }
    }

    /// (lo, hi) as the kernels take it.
    pub fn range(self) -> (f32, f32) {
        (self.level - 0.5 * self.width, self.level + 0.5 * self.width)
    }

    pub fn from_range(lo: f32, hi: f32) -> Self {
        Self {
            width: (hi - lo).max(MIN_WIDTH),
            level: 0.5 * (lo + hi),
        }
    }

    /// The window of the grey range `(lo, hi)`.
    pub fn from_bounds((lo, hi): (f32, f32)) -> Self {
        Self {
            width: (hi - lo).max(MIN_WIDTH),
            level: 0.5 * (lo + hi),
        }
    }

    /// The grey range `(lo, hi)` of this window.
    pub fn bounds(self) -> (f32, f32) {
        (self.level - 0.5 * self.width, self.level + 0.5 * self.width)
    }

    /// The window after a drag of `delta` screen points: right widens, left narrows (by a factor,
    /// so it is as fine for brain as for bone); down raises the level (darker), up lowers it, by
    /// a fraction of the width.
    pub fn dragged(self, delta: egui::Vec2) -> Self {
        let width = (self.width * (delta.x * 0.005).exp()).clamp(MIN_WIDTH, 1.0e6);
        let level = self.level + delta.y * 0.0025 * self.width.max(10.0);
        Self { width, level }
    }
}

/// The usual CT windows.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum WindowPreset {
    Lung,
    Mediastinum,
    Abdomen,
    Bone,
    Brain,
}

impl WindowPreset {
    pub const ALL: [Self; 5] = [
        Self::Lung,
        Self::Mediastinum,
        Self::Abdomen,
        Self::Bone,
        Self::Brain,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Self::Lung => "lung",
            Self::Mediastinum => "mediastinum",
            Self::Abdomen => "abdomen",
            Self::Bone => "bone",
            Self::Brain => "brain",
        }
    }

    /// (width, level) in HU.
    pub fn window(self) -> Window {
        match self {
            Self::Lung => Window::new(1500.0, -600.0),
            Self::Mediastinum => Window::new(350.0, 50.0),
            Self::Abdomen => Window::new(400.0, 50.0),
            Self::Bone => Window::new(1800.0, 400.0),
            Self::Brain => Window::new(80.0, 40.0),
        }
    }
}

/// The window a volume opens with: the abdomen (soft-tissue) window for CT, 0-10 for a PET in
/// SUV, otherwise the 1st to 99.5th percentile of the values (MR has no units; phantoms have low contrast).
pub fn default_window(volume: &Volume) -> Window {
    let range = volume.value_range();
    if volume.looks_like_ct(range) {
        return WindowPreset::Abdomen.window();
    }
    // A PET in SUV opens on 0-10 SUV, as nuclear-medicine viewers do.
    if volume.unit() == "SUV" {
        return Window::from_range(0.0, 10.0);
    }
    match percentiles(volume, 0.01, 0.995) {
        Some((lo, hi)) if hi > lo => Window::from_range(lo, hi),
        _ => match range {
            Some((lo, hi)) => Window::from_range(lo, hi.max(lo + 1.0)),
            None => Window::new(400.0, 40.0),
        },
    }
}

/// Two percentiles of the values, from a subsample of at most about a million voxels.
fn percentiles(volume: &Volume, p_lo: f64, p_hi: f64) -> Option<(f32, f32)> {
    let n = volume.voxel_count();
    if n == 0 {
        return None;
    }
    let stride = n.div_ceil(1 << 20).max(1);
    let mut v: Vec<f32> = (0..n)
        .step_by(stride)
        .map(|i| volume.value(i))
        .filter(|x| x.is_finite())
        .collect();
    if v.is_empty() {
        return None;
    }
    v.sort_by(f32::total_cmp);
    let at = |p: f64| v[((v.len() - 1) as f64 * p).round() as usize];
    Some((at(p_lo), at(p_hi)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::volume::Modality;

    #[test]
    fn bounds_round_trip() {
        let w = WindowPreset::Lung.window();
        let (lo, hi) = w.bounds();
        assert_eq!(hi - lo, w.width);
        assert_eq!(Window::from_bounds((lo, hi)), w);
        // An inverted or empty range is the narrowest window at its centre.
        assert_eq!(Window::from_bounds((10.0, 10.0)).width, MIN_WIDTH);
    }

    #[test]
    fn drag_changes_width_and_level() {
        let w = WindowPreset::Abdomen.window();
        let wider = w.dragged(egui::vec2(100.0, 0.0));
        assert!(wider.width > w.width && wider.level == w.level);
        let darker = w.dragged(egui::vec2(0.0, 40.0));
        assert!(darker.level > w.level && darker.width == w.width);
        let narrow = w.dragged(egui::vec2(-1.0e5, 0.0));
        assert_eq!(narrow.width, MIN_WIDTH);
        let (lo, hi) = w.range();
        assert_eq!((lo, hi), (-150.0, 250.0));
        assert_eq!(Window::from_range(lo, hi), w);
    }

    #[test]
    fn defaults_per_modality() {
        let mut ct = Volume::from_f32(
            [4, 4, 4],
            [1.0; 3],
            (0..64).map(|i| -1000.0 + 30.0 * i as f32).collect(),
        );
        assert_eq!(default_window(&ct), WindowPreset::Abdomen.window());
        ct.modality = Modality::Mr;
        let w = default_window(&ct);
        assert!(
            w.range().0 >= -1000.0 && w.range().1 <= 890.0 && w.width > 1500.0,
            "{w:?}"
        );
    }
}
