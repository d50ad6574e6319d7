//! Measurements on the slice panes: a distance ruler (mm) and an ellipse region (mean, SD, min
//! and max of the values, HU for CT, and its area in mm²). A measurement keeps its two points in
//! patient space (LPS mm), so it does not depend on the file's voxel order and travels in a link
//! (`ViewState::measurements`, one `m=` field each).
//!
//! A ruler may also join two points in space: with the ruler tool, a click in the MIP measures
//! from the crosshair point (or the point the last such click picked, while the crosshair stays
//! there) to the 3D point the clicked pixel's maximum came from (`MipViewOutput::pick`), and
//! the crosshair moves there, so clicks in a row measure a path. Such a ruler has no pane
//! (`3d` in a link); the MIP draws it, and a slice pane marks each end on the slice it lies on.
//!
//! Which pixels an ellipse holds: those of the slice whose centres lie inside or on the ellipse
//! (centre-in-ellipse), in the pane's voxel plane: pixel `(u, v)` (index across, index up the
//! pane's vertical voxel axis) is inside when `((u - cu) / ru)² + ((v - cv) / rv)² <= 1`, with
//! `(cu, cv)` the centre and `(ru, rv)` the half-axes of the drawn box in continuous voxel
//! coordinates (a voxel's centre at its integer index). The SD is the population one (divided by
//! n, as numpy's default). The area is the ellipse's own, `π ru rv` times the pixel's area in mm²,
//! not the pixel count (which the readout gives beside it).

use glam::DVec3;

use super::model::axes::{SliceKind, pane_axes};
use crate::volume::Volume;

/// What a left drag in a slice pane does.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Tool {
    /// Moves the crosshair.
    #[default]
    Navigate,
    /// Draws a distance ruler.
    Ruler,
    /// Draws an ellipse region (its bounding box, corner to corner).
    Ellipse,
}

impl Tool {
    pub const ALL: [Self; 3] = [Self::Navigate, Self::Ruler, Self::Ellipse];

    pub fn label(self) -> &'static str {
        match self {
            Self::Navigate => "crosshair",
            Self::Ruler => "ruler",
            Self::Ellipse => "ellipse",
        }
    }

    /// The measurement this tool draws.
    pub fn kind(self) -> Option<MeasureKind> {
        match self {
            Self::Navigate => None,
            Self::Ruler => Some(MeasureKind::Ruler),
            Self::Ellipse => Some(MeasureKind::Ellipse),
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MeasureKind {
    Ruler,
    Ellipse,
}

impl MeasureKind {
    pub fn name(self) -> &'static str {
        match self {
            Self::Ruler => "ruler",
            Self::Ellipse => "ellipse",
        }
    }
}

/// One measurement: a ruler from `a_mm` to `b_mm`, or the ellipse inscribed in the box with
/// opposite corners `a_mm` and `b_mm` in the plane of a `pane`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Measurement {
    pub kind: MeasureKind,
    /// The slice pane it was drawn on; `None` for a ruler in 3D (an end picked in the MIP).
    pub pane: Option<SliceKind>,
    pub a_mm: DVec3,
    pub b_mm: DVec3,
}

/// The pane name of a ruler in 3D in a link.
const PANE_3D: &str = "3d";

/// Where a measurement lies in its pane, in continuous voxel coordinates of the volume.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct InPane {
    /// The slice (index along the pane's fixed axis), rounded and clamped to the volume.
    pub slice: usize,
    /// The two points as (across, vertical) voxel coordinates.
    pub a: [f64; 2],
    pub b: [f64; 2],
}

impl Measurement {
    /// The ruler's length (for an ellipse, its box's diagonal), mm.
    pub fn length_mm(&self) -> f64 {
        (self.b_mm - self.a_mm).length()
    }

    /// Its place in its pane for `volume`; `None` for a ruler in 3D, an empty volume or
    /// non-finite points.
    pub fn in_pane(&self, volume: &Volume) -> Option<InPane> {
        let axes = pane_axes(volume, self.pane?);
        let n = volume.dims[axes.fixed];
        if n == 0 || !self.a_mm.is_finite() || !self.b_mm.is_finite() {
            return None;
        }
        let to_voxel = volume.voxel_from_world();
        let (a, b) = (
            to_voxel.transform_point3(self.a_mm),
            to_voxel.transform_point3(self.b_mm),
        );
        let mid = 0.5 * (a[axes.fixed] + b[axes.fixed]);
        Some(InPane {
            slice: mid.round().clamp(0.0, (n - 1) as f64) as usize,
            a: [a[axes.across], a[axes.vertical]],
            b: [b[axes.across], b[axes.vertical]],
        })
    }

    /// The link's text form: `kind,pane,ax,ay,az,bx,by,bz` (LPS mm, shortest exact decimals;
    /// the pane `3d` for a ruler in 3D).
    pub fn to_text(&self) -> String {
        let n = |x: f64| format!("{}", if x.is_finite() { x } else { 0.0 });
        format!(
            "{},{},{},{},{},{},{},{}",
            self.kind.name(),
            self.pane.map_or(PANE_3D, SliceKind::name),
            n(self.a_mm.x),
            n(self.a_mm.y),
            n(self.a_mm.z),
            n(self.b_mm.x),
            n(self.b_mm.y),
            n(self.b_mm.z)
        )
    }

    /// Reads [`Self::to_text`]'s form; `None` when anything in it is not as written there.
    pub fn from_text(s: &str) -> Option<Self> {
        let parts: Vec<&str> = s.split(',').map(str::trim).collect();
        if parts.len() != 8 {
            return None;
        }
        let kind = match parts[0] {
            "ruler" => MeasureKind::Ruler,
            "ellipse" => MeasureKind::Ellipse,
            _ => return None,
        };
        let pane = match parts[1] {
            // Only a ruler joins two points in space; an ellipse lies in a slice.
            PANE_3D if kind == MeasureKind::Ruler => None,
            name => Some(SliceKind::ALL.into_iter().find(|k| k.name() == name)?),
        };
        let mut x = [0.0f64; 6];
        for (slot, p) in x.iter_mut().zip(&parts[2..]) {
            *slot = p.parse::<f64>().ok().filter(|v| v.is_finite())?;
        }
        Some(Self {
            kind,
            pane,
            a_mm: DVec3::new(x[0], x[1], x[2]),
            b_mm: DVec3::new(x[3], x[4], x[5]),
        })
    }
}

/// The voxel nearest to a point (LPS mm), clamped into the volume; `None` for an empty volume
/// or a non-finite point.
pub fn nearest_voxel(volume: &Volume, p_mm: DVec3) -> Option<[usize; 3]> {
    let v = volume.voxel_from_world().transform_point3(p_mm);
    if !v.is_finite() || volume.dims.contains(&0) {
        return None;
    }
    Some(std::array::from_fn(|a| {
        v[a].round().clamp(0.0, (volume.dims[a] - 1) as f64) as usize
    }))
}

/// Statistics of the pixels of an ellipse region.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RegionStats {
    /// Pixels whose centres are inside.
    pub pixels: usize,
    pub mean: f64,
    /// Population standard deviation (divided by n).
    pub sd: f64,
    pub min: f32,
    pub max: f32,
    /// The ellipse's area, mm².
    pub area_mm2: f64,
}

/// Whether pixel `(u, v)`'s centre lies inside or on the ellipse of `centre` and half-axes
/// `radii` (voxel coordinates; a zero half-axis holds only the pixels on that line).
pub fn inside_ellipse(u: usize, v: usize, centre: [f64; 2], radii: [f64; 2]) -> bool {
    let term = |x: f64, c: f64, r: f64| {
        let d = x - c;
        if r > 0.0 {
            (d / r) * (d / r)
        } else if d == 0.0 {
            0.0
        } else {
            f64::INFINITY
        }
    };
    term(u as f64, centre[0], radii[0]) + term(v as f64, centre[1], radii[1]) <= 1.0
}

/// The statistics of an ellipse measurement on `volume` (values as [`Volume::value_at`] gives
/// them: HU for CT); `None` for a ruler, or when no pixel centre is inside.
pub fn region_stats(volume: &Volume, m: &Measurement) -> Option<RegionStats> {
    let (voxels, radii, axes) = ellipse_voxels(volume, m)?;
    let (mut n, mut sum, mut sum2) = (0usize, 0.0f64, 0.0f64);
    let (mut min, mut max) = (f32::INFINITY, f32::NEG_INFINITY);
    for ijk in voxels {
        let x = volume.value_at(ijk[0], ijk[1], ijk[2]);
        if !x.is_finite() {
            continue;
        }
        n += 1;
        sum += f64::from(x);
        sum2 += f64::from(x) * f64::from(x);
        min = min.min(x);
        max = max.max(x);
    }
    if n == 0 {
        return None;
    }
    let mean = sum / n as f64;
    let var = (sum2 / n as f64 - mean * mean).max(0.0);
    let pixel_mm2 = volume.spacing_mm[axes.across] * volume.spacing_mm[axes.vertical];
    Some(RegionStats {
        pixels: n,
        mean,
        sd: var.sqrt(),
        min,
        max,
        area_mm2: std::f64::consts::PI * radii[0] * radii[1] * pixel_mm2,
    })
}

/// The voxels of `volume` inside an ellipse measurement (centre-in-ellipse, on its slice), its
/// half-axes in voxels and its pane's axes; `None` for a ruler or an ellipse off the volume.
fn ellipse_voxels(
    volume: &Volume,
    m: &Measurement,
) -> Option<(Vec<[usize; 3]>, [f64; 2], super::model::axes::PaneAxes)> {
    if m.kind != MeasureKind::Ellipse {
        return None;
    }
    let p = m.in_pane(volume)?;
    let axes = pane_axes(volume, m.pane?);
    let (w, h) = (volume.dims[axes.across], volume.dims[axes.vertical]);
    let centre = [0.5 * (p.a[0] + p.b[0]), 0.5 * (p.a[1] + p.b[1])];
    let radii = [0.5 * (p.a[0] - p.b[0]).abs(), 0.5 * (p.a[1] - p.b[1]).abs()];
    // Only the box's pixels can be inside.
    let range = |c: f64, r: f64, n: usize| {
        let lo = (c - r).ceil().max(0.0);
        let hi = (c + r).floor().min(n as f64 - 1.0);
        (lo <= hi).then_some(lo as usize..=hi as usize)
    };
    let (us, vs) = (
        range(centre[0], radii[0], w)?,
        range(centre[1], radii[1], h)?,
    );
    let mut out = Vec::new();
    for v in vs {
        for u in us.clone() {
            if inside_ellipse(u, v, centre, radii) {
                let mut ijk = [0usize; 3];
                ijk[axes.fixed] = p.slice;
                ijk[axes.across] = u;
                ijk[axes.vertical] = v;
                out.push(ijk);
            }
        }
    }
    Some((out, radii, axes))
}

/// An ellipse's two axes in patient coordinates (LPS mm) on the slice its statistics are read
/// on: the longer axis' two ends, then the shorter's (a DICOM SR ELLIPSE's four points).
pub fn ellipse_axes_mm(volume: &Volume, m: &Measurement) -> Option<[DVec3; 4]> {
    if m.kind != MeasureKind::Ellipse {
        return None;
    }
    let p = m.in_pane(volume)?;
    let axes = pane_axes(volume, m.pane?);
    let centre = [0.5 * (p.a[0] + p.b[0]), 0.5 * (p.a[1] + p.b[1])];
    let radii = [0.5 * (p.a[0] - p.b[0]).abs(), 0.5 * (p.a[1] - p.b[1]).abs()];
    let world = volume.world_from_voxel();
    let point = |du: f64, dv: f64| {
        let mut v = DVec3::ZERO;
        v[axes.fixed] = p.slice as f64;
        v[axes.across] = centre[0] + du;
        v[axes.vertical] = centre[1] + dv;
        world.transform_point3(v)
    };
    let across = [point(-radii[0], 0.0), point(radii[0], 0.0)];
    let vertical = [point(0.0, -radii[1]), point(0.0, radii[1])];
    let length = |e: &[DVec3; 2]| (e[1] - e[0]).length();
    let (major, minor) = if length(&across) >= length(&vertical) {
        (across, vertical)
    } else {
        (vertical, across)
    };
    Some([major[0], major[1], minor[0], minor[1]])
}

/// What an ellipse reads on the PET fused over its CT (PERCIST's measures), in the PET's unit.
#[derive(Clone, Debug, PartialEq)]
pub struct PetRegionStats {
    /// The largest PET value at the ROI's CT pixel centres (the PET read there trilinearly).
    pub max: f32,
    /// The mean of the PET at the ROI's CT pixel centres.
    pub mean: f64,
    /// SUVpeak: the mean of the PET voxels whose centres lie within the 1 cm³ sphere (radius
    /// 6.2 mm) centred on the ROI's hottest point; the hottest value itself when no voxel
    /// centre is that close (PET voxels coarser than the sphere).
    pub peak: f64,
    pub unit: String,
}

pub use crate::cpu::hot_spots::PEAK_SPHERE_RADIUS_MM;
use crate::cpu::hot_spots::sphere_mean;

/// An ellipse's PET measures, the PET read on its own grid at the CT pixels' patient points.
pub fn pet_region_stats(ct: &Volume, pet: &Volume, m: &Measurement) -> Option<PetRegionStats> {
    let (voxels, _, _) = ellipse_voxels(ct, m)?;
    let world = ct.world_from_voxel();
    let (mut n, mut sum) = (0usize, 0.0f64);
    let mut hottest: Option<(f32, DVec3)> = None;
    for ijk in voxels {
        let p = world.transform_point3(DVec3::from(ijk.map(|x| x as f64)));
        let Some(x) = pet.value_at_world(p).filter(|x| x.is_finite()) else {
            continue;
        };
        n += 1;
        sum += f64::from(x);
        if hottest.is_none_or(|(h, _)| x > h) {
            hottest = Some((x, p));
        }
    }
    let (max, at) = hottest?;
    Some(PetRegionStats {
        max,
        mean: sum / n as f64,
        peak: sphere_mean(pet, at, PEAK_SPHERE_RADIUS_MM).unwrap_or(f64::from(max)),
        unit: pet.unit().to_owned(),
    })
}

/// A measurement with what it reads on the volume it was made on.
#[derive(Clone, Debug, PartialEq)]
pub struct Entry {
    pub measurement: Measurement,
    pub stats: Option<RegionStats>,
    /// An ellipse's PET measures, when a PET is fused over the volume.
    pub pet: Option<PetRegionStats>,
}

impl Entry {
    pub fn new(volume: &Volume, measurement: Measurement) -> Self {
        Self {
            stats: region_stats(volume, &measurement),
            measurement,
            pet: None,
        }
    }

    /// The same with its PET measures on `pet` (fused over `volume`).
    pub fn with_pet(mut self, volume: &Volume, pet: Option<&Volume>) -> Self {
        self.pet = pet.and_then(|p| pet_region_stats(volume, p, &self.measurement));
        self
    }

    /// What it reads, e.g. "12.3 mm" or "mean 40.2 SD 3.1 HU (20..61), 78.5 mm², 310 px".
    pub fn reading(&self, unit: &str) -> String {
        let unit = if unit.is_empty() {
            String::new()
        } else {
            format!(" {unit}")
        };
        match self.measurement.kind {
            MeasureKind::Ruler => format!("{:.1} mm", self.measurement.length_mm()),
            MeasureKind::Ellipse => match &self.stats {
                Some(s) => {
                    // SUV in hundredths, HU and scanner units in whole numbers.
                    let d = if unit == " SUV" { 2 } else { 0 };
                    let mut text = format!(
                        "mean {:.1} SD {:.1}{unit} ({:.d$}..{:.d$}), {:.1} mm², {} px",
                        s.mean, s.sd, s.min, s.max, s.area_mm2, s.pixels
                    );
                    if let Some(p) = &self.pet {
                        let (max, mean, peak) = if p.unit == "SUV" {
                            ("SUVmax", "SUVmean", "SUVpeak")
                        } else {
                            ("PET max", "mean", "peak")
                        };
                        text.push_str(&format!(
                            "; {max} {:.2}, {mean} {:.2}, {peak} {:.2}",
                            p.max, p.mean, p.peak
                        ));
                    }
                    text
                }
                None => "no pixel centre inside".to_owned(),
            },
        }
    }
}

/// The measuring state of the app: the tool and the measurements made on the volume shown.
#[derive(Clone, Debug, Default)]
pub struct Measurements {
    pub tool: Tool,
    pub list: Vec<Entry>,
    /// The point the last MIP click picked (LPS mm) and the voxel the crosshair went to.
    pub last_pick: Option<([usize; 3], DVec3)>,
}

impl Measurements {
    /// A click in the MIP picked `pick_mm` (voxel `pick_voxel`) while the crosshair was at
    /// `crosshair`: with the ruler tool, the ruler in 3D from the crosshair's point (the last
    /// picked point itself while the crosshair is still on its voxel) to the picked one.
    pub fn mip_pick(
        &mut self,
        volume: &Volume,
        crosshair: [usize; 3],
        pick_voxel: [usize; 3],
        pick_mm: DVec3,
    ) -> Option<Measurement> {
        let from = match self.last_pick {
            Some((voxel, p)) if voxel == crosshair => p,
            _ => volume.world_from_voxel().transform_point3(DVec3::new(
                crosshair[0] as f64,
                crosshair[1] as f64,
                crosshair[2] as f64,
            )),
        };
        self.last_pick = Some((pick_voxel, pick_mm));
        (self.tool == Tool::Ruler && pick_mm.is_finite()).then_some(Measurement {
            kind: MeasureKind::Ruler,
            pane: None,
            a_mm: from,
            b_mm: pick_mm,
        })
    }

    /// Replaces the list (a link's, or none for a new volume), read on `volume`.
    pub fn set(&mut self, volume: &Volume, list: &[Measurement]) {
        self.list = list.iter().map(|m| Entry::new(volume, *m)).collect();
    }

    /// Adds a measurement, with its PET measures when a PET is fused over `volume`.
    pub fn add(&mut self, volume: &Volume, pet: Option<&Volume>, m: Measurement) {
        self.list.push(Entry::new(volume, m).with_pet(volume, pet));
    }

    /// Reads every measurement's PET measures again on `pet` (a PET loaded after them).
    pub fn read_pet(&mut self, volume: &Volume, pet: Option<&Volume>) {
        for e in &mut self.list {
            e.pet = pet.and_then(|p| pet_region_stats(volume, p, &e.measurement));
        }
    }

    pub fn measurements(&self) -> Vec<Measurement> {
        self.list.iter().map(|e| e.measurement).collect()
    }
}

/// The rulers in 3D of `list` drawn over the MIP (`screen_of`: a point's place on it), each
/// with its number and length.
pub fn draw_rulers_3d(
    painter: &egui::Painter,
    list: &[Entry],
    screen_of: impl Fn(DVec3) -> Option<egui::Pos2>,
) {
    let colour = egui::Color32::from_rgb(90, 200, 255);
    let stroke = egui::Stroke::new(1.5, colour);
    for (n, e) in list.iter().enumerate() {
        let m = &e.measurement;
        if m.pane.is_some() {
            continue;
        }
        let (Some(a), Some(b)) = (screen_of(m.a_mm), screen_of(m.b_mm)) else {
            continue;
        };
        painter.line_segment([a, b], stroke);
        for p in [a, b] {
            painter.circle_stroke(p, 4.0, stroke);
        }
        painter.text(
            b + egui::vec2(6.0, -6.0),
            egui::Align2::LEFT_BOTTOM,
            format!("{} {}", n + 1, e.reading("")),
            egui::FontId::proportional(13.0),
            colour,
        );
    }
}

impl super::ShapecastApp {
    /// The measurements on the volume shown, oldest first.
    pub fn measurements(&self) -> &[Entry] {
        &self.measure.list
    }

    /// What a left drag on a slice does.
    pub fn set_tool(&mut self, tool: Tool) {
        self.measure.tool = tool;
    }

    pub fn tool(&self) -> Tool {
        self.measure.tool
    }

    /// Where a point (LPS mm) is in the MIP pane as last drawn (screen points), if inside it.
    pub fn mip_screen_pos_of(&self, world_mm: DVec3) -> Option<egui::Pos2> {
        self.mip_view.screen_pos_of(world_mm)
    }
}

#[cfg(test)]
mod tests;
