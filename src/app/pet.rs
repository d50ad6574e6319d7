//! The PET of a PET/CT study, read with its CT (the paper's Fig. 21): the CT stays the primary
//! volume (features are computed on it); the PET keeps its own grid and is read in patient
//! coordinates, never resampled into a CT-sized copy. Its part of the app: loading the PET
//! series that came with the CT, the fused overlay of each slice pane (hot iron over the CT's
//! grey), the SUV readout and the panel's window and opacity.
//!
//! The overlay of a pane is computed on the CPU, one pixel per CT voxel of the slice shown
//! (a 512 x 512 slice is 262,144 trilinear reads, a few milliseconds), and only when the
//! slice, the window or the opacity change.

use std::sync::Arc;

mod mip;
mod panel;

pub use mip::{MipArea, PetMip};

use glam::{DAffine3, DVec3};

use super::load::{LoadJob, LoadSource, LoadStep, SeriesSet};
use super::mip_view::{MipScene, MipView};
use super::model::axes::PaneAxes;
use super::platform::Platform;
use super::view_link::PetView;
use crate::gpu::GpuContext;
use crate::gpu::alloc::{AllocCheck, Allocation};
use crate::gpu::volume_texture::RenderVolume;
use crate::render::camera::Camera;
use crate::render::fusion::{hot_iron, pet_alpha};
use crate::volume::{Modality, Volume};

/// The PET shown over the CT.
pub struct PetLayer {
    pub volume: Arc<Volume>,
    /// The PET's window in its display unit (SUV when known).
    pub window: (f32, f32),
    /// How much the PET covers the CT where it is hot, 0..1.
    pub opacity: f32,
    pub visible: bool,
    /// The slice panes show the PET alone (inverted grey, as its MIP) instead of fused.
    pub alone: bool,
    /// What the user should know (a frame of reference that differs, no SUV).
    pub notes: Vec<String>,
    /// The PET's own 3D texture, for its MIP (`None` where the GPU refused it).
    pub render: Option<RenderVolume>,
    /// The device's answer to that texture while a browser has not given it.
    render_alloc: Option<AllocCheck>,
}

impl PetLayer {
    pub fn new(volume: Volume, ct: &Volume) -> Self {
        let mut notes = volume.warnings.clone();
        notes.extend(crate::io::frame_of_reference_note(ct, &volume));
        if volume.modality != Modality::Pt {
            notes.push(format!(
                "{} does not say it is a PET: fused over the CT as given, in its own values",
                volume.source
            ));
        }
        let window = if volume.unit() == "SUV" {
            (0.0, 10.0)
        } else {
            volume.value_range().unwrap_or((0.0, 1.0))
        };
        Self {
            volume: Arc::new(volume),
            window,
            opacity: 0.5,
            visible: true,
            alone: false,
            notes,
            render: None,
            render_alloc: None,
        }
    }

    /// A link's window, opacity and visibility.
    pub fn apply_view(&mut self, view: &PetView) {
        if let Some(w) = view.window {
            self.window = w;
        }
        if let Some(o) = view.opacity {
            self.opacity = o;
        }
        if let Some(v) = view.visible {
            self.visible = v;
        }
        if let Some(a) = view.alone {
            self.alone = a;
        }
    }

    /// The PET's unit ("SUV", else its own).
    pub fn unit(&self) -> &str {
        self.volume.unit()
    }

    /// The PET's value at a CT voxel (read on the PET's grid), `None` outside the PET.
    pub fn value_at_ct_voxel(&self, ct: &Volume, voxel: [usize; 3]) -> Option<f32> {
        let p = ct
            .world_from_voxel()
            .transform_point3(DVec3::from(voxel.map(|v| v as f64)));
        self.volume.value_at_world(p)
    }

    /// What the overlay of a pane depends on besides the slice.
    pub fn key(&self) -> OverlayKey {
        OverlayKey {
            window: self.window,
            opacity: self.opacity,
            alone: self.alone,
            volume: Arc::as_ptr(&self.volume) as usize,
        }
    }

    /// The fused overlay of one CT slice: RGBA, one pixel per CT voxel of the slice, laid out as
    /// the slice kernel lays out its image (row `y` is `vertical`, column `x` is `across`), so
    /// that it is drawn with the slice's own rectangle and texture coordinates. Transparent
    /// where the PET is cold or absent. With [`PetLayer::alone`] the PET's slice instead, in
    /// inverted grey as its MIP (opaque; white where it is cold or outside the PET's field),
    /// read at the CT's points so that crosshair, rulers and ROIs stay where they are.
    pub fn overlay(&self, ct: &Volume, axes: PaneAxes, slice: usize) -> egui::ColorImage {
        let (w, h) = (ct.dims[axes.across], ct.dims[axes.vertical]);
        // PET continuous voxel index from CT voxel index: one affine map for the whole slice.
        let pet_from_ct: DAffine3 = self.volume.voxel_from_world() * ct.world_from_voxel();
        let (lo, hi) = self.window;
        let span = (hi - lo).max(1e-6);
        let mut pixels = Vec::with_capacity(w * h);
        for y in 0..h {
            for x in 0..w {
                let mut p = [0.0f64; 3];
                p[axes.fixed] = slice as f64;
                p[axes.across] = x as f64;
                p[axes.vertical] = y as f64;
                let value = self
                    .volume
                    .value_at_continuous(pet_from_ct.transform_point3(DVec3::from(p)));
                pixels.push(match value {
                    _ if self.alone => {
                        let t = value.map_or(0.0, |v| (v - lo) / span);
                        let t = if t.is_finite() {
                            t.clamp(0.0, 1.0)
                        } else {
                            0.0
                        };
                        let g = ((1.0 - t) * 255.0).round() as u8;
                        egui::Color32::from_gray(g)
                    }
                    Some(v) => {
                        let t = (v - lo) / span;
                        let [r, g, b] = hot_iron(t);
                        let a = pet_alpha(t, self.opacity);
                        let u8c = |c: f32| (c.clamp(0.0, 1.0) * 255.0).round() as u8;
                        egui::Color32::from_rgba_unmultiplied(u8c(r), u8c(g), u8c(b), u8c(a))
                    }
                    None => egui::Color32::TRANSPARENT,
                });
            }
        }
        egui::ColorImage::new([w, h], pixels)
    }
}

/// What a pane's overlay was made with (it is made again when this or the slice changes).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OverlayKey {
    window: (f32, f32),
    opacity: f32,
    alone: bool,
    /// The PET volume (its allocation): a new PET makes a new overlay.
    volume: usize,
}

/// A pane's overlay texture and what it shows.
#[derive(Default)]
pub struct PaneOverlay {
    texture: Option<egui::TextureHandle>,
    drawn: Option<(OverlayKey, [usize; 3], usize, u64)>,
}

impl PaneOverlay {
    /// The overlay texture of `slice` in this pane, made when anything it shows changed.
    /// `generation` is the CT's (a new CT, even of the same shape, makes a new overlay).
    pub fn texture(
        &mut self,
        ctx: &egui::Context,
        pet: &PetLayer,
        ct: &Volume,
        axes: PaneAxes,
        slice: usize,
        generation: u64,
    ) -> egui::TextureId {
        let key = (
            pet.key(),
            [axes.fixed, axes.across, axes.vertical],
            slice,
            generation,
        );
        match &mut self.texture {
            Some(t) if self.drawn == Some(key) => t.id(),
            slot => {
                let image = pet.overlay(ct, axes, slice);
                let options = egui::TextureOptions::LINEAR;
                let id = match slot {
                    Some(t) => {
                        t.set(image, options);
                        t.id()
                    }
                    None => {
                        let t =
                            ctx.load_texture(format!("pet overlay {}", axes.fixed), image, options);
                        let id = t.id();
                        *slot = Some(t);
                        id
                    }
                };
                self.drawn = Some(key);
                id
            }
        }
    }
}

/// Loading the PET that came with a CT, and the layer once loaded.
#[derive(Default)]
pub struct PetState {
    pub layer: Option<PetLayer>,
    job: Option<LoadJob>,
    /// The CT generation the PET is being loaded for (a newer CT drops it).
    loading_for: Option<u64>,
    /// Where the PET came from when it came by URL (a link names them).
    pub urls: Vec<String>,
    /// A link's fusion settings, waiting for the PET.
    pending_view: Option<PetView>,
}

impl PetState {
    /// Forgets the PET (a new CT was loaded).
    pub fn clear(&mut self) {
        *self = Self::default();
    }
}

impl PetState {
    /// Whether a PET is being loaded.
    pub fn loading(&self) -> bool {
        self.loading_for.is_some()
    }

    /// The PET series among the files a CT came from: the PT series with the most images.
    pub fn pet_entry(set: &SeriesSet) -> Option<usize> {
        let entries = set.list.entries();
        // The first of equals (`max_by_key` would take the last).
        (0..entries.len())
            .filter(|&i| entries[i].modality == "PT")
            .fold(None, |best: Option<usize>, i| match best {
                Some(b) if entries[b].images >= entries[i].images => Some(b),
                _ => Some(i),
            })
    }

    /// Starts loading the PET series of `set` (the files the CT of `generation` came from),
    /// when the CT is a CT and the files hold a PET. True when a load started.
    pub fn start_with(
        &mut self,
        set: &SeriesSet,
        ct: &Volume,
        generation: u64,
        platform: &impl Platform,
    ) -> bool {
        if ct.modality != Modality::Ct {
            return false;
        }
        let Some(index) = Self::pet_entry(set) else {
            return false;
        };
        let set = set.with_chosen(index);
        self.loading_for = Some(generation);
        // The page's files are read by the page; others by a job.
        let Some(set) = platform.read_page_series(set, Some(generation)) else {
            return true;
        };
        self.job = Some(LoadJob::new(LoadSource::Series(set)));
        true
    }

    /// Starts decoding a PET from other files than the CT's (`shapecast view CT --pet PET`,
    /// a link's `&pet=URL` once downloaded), for the CT of `generation`.
    pub fn start_source(&mut self, source: LoadSource, generation: u64) {
        if self.loading_for.is_some_and(|g| g != generation) {
            return;
        }
        self.loading_for = Some(generation);
        self.job = Some(LoadJob::new(source));
    }

    /// A PET for the CT of `generation` is on its way (being downloaded).
    pub fn awaiting(&mut self, generation: u64) {
        self.loading_for = Some(generation);
    }

    /// A link's fusion settings: applied now, or when the PET arrives.
    pub fn apply_view(&mut self, view: &PetView) {
        match &mut self.layer {
            Some(layer) => layer.apply_view(view),
            None => self.pending_view = Some(view.clone()),
        }
    }

    /// What a link says of the PET shown.
    pub fn view(&self) -> Option<PetView> {
        self.layer.as_ref().map(|l| PetView {
            urls: self.urls.clone(),
            window: Some(l.window),
            opacity: Some(l.opacity),
            visible: Some(l.visible),
            alone: Some(l.alone),
        })
    }

    /// Advances the load by one step; a finished load becomes the layer over `ct` (of
    /// `generation`). Returns a message for the user when it failed or what it loaded is not
    /// a PET.
    pub fn step(
        &mut self,
        ct: Option<&Volume>,
        generation: u64,
        gpu: Option<&GpuContext>,
    ) -> Option<String> {
        // A browser answers for the PET's texture a frame or more after it was made: refused,
        // the PET MIP goes (its slices stay).
        if let Some(layer) = &mut self.layer
            && let Some(check) = &mut layer.render_alloc
        {
            match check.poll() {
                Allocation::Waiting => {}
                Allocation::Granted => layer.render_alloc = None,
                Allocation::Refused(detail) => {
                    layer.render_alloc = None;
                    let e = layer.render.take().map(|r| r.out_of_memory("PET", detail));
                    return e.map(|e| format!("PET MIP: {e} (the fused slices still show it)"));
                }
            }
        }
        let job = self.job.as_mut()?;
        // The job is for the CT it was started for (`clear` drops it with a new CT).
        let Some(loading_for) = self.loading_for else {
            self.job = None;
            return None;
        };
        match job.step() {
            LoadStep::Working { .. } => None,
            LoadStep::Done(loaded) => {
                self.job = None;
                if loading_for != generation {
                    self.loading_for = None;
                    return None;
                }
                self.install(loaded.volume, ct, generation, gpu)
            }
            LoadStep::Failed(error) => {
                self.job = None;
                self.failed(loading_for)
                    .then(|| format!("PET: {}", error.message()))
            }
        }
    }

    /// Whether a PET is being decoded in the app's frames (they must keep coming).
    pub fn busy(&self) -> bool {
        self.job.is_some()
            || self
                .layer
                .as_ref()
                .is_some_and(|l| l.render_alloc.is_some())
    }

    /// Whether a PET for the CT of `generation` is awaited (its download may be decoded).
    pub fn awaits(&self, generation: u64) -> bool {
        self.loading_for == Some(generation) && self.job.is_none()
    }

    /// A PET load for the CT of `generation` failed: true when that is still the CT shown
    /// (the failure is then the user's to know).
    pub fn failed(&mut self, generation: u64) -> bool {
        if self.loading_for == Some(generation) {
            self.loading_for = None;
            true
        } else {
            false
        }
    }

    /// Makes a loaded PET the layer over `ct`, if it was loaded for that CT.
    pub fn install(
        &mut self,
        volume: Volume,
        ct: Option<&Volume>,
        generation: u64,
        gpu: Option<&GpuContext>,
    ) -> Option<String> {
        // A PET read for an older CT is dropped, and does not end the load of the current one.
        if self.loading_for != Some(generation) {
            return None;
        }
        self.loading_for = None;
        let ct = ct?;
        match volume.modality {
            // A NIfTI or NRRD PET says nothing of its modality: fused as given, said so.
            Modality::Pt | Modality::Unknown => {}
            other => {
                return Some(format!(
                    "{}: not a PET (modality {}); not fused",
                    volume.source,
                    other.as_str()
                ));
            }
        }
        let mut layer = PetLayer::new(volume, ct);
        let mut message = None;
        if let Some(gpu) = gpu {
            // The PET is small beside its CT (a whole-body PET of 200 x 200 x 700 is 56 MB
            // of texture): uploaded in one go.
            match RenderVolume::upload_checked(gpu, &layer.volume) {
                Ok((r, check)) => {
                    layer.render = Some(r);
                    layer.render_alloc = Some(check);
                }
                Err(e) => message = Some(format!("PET MIP: {e} (the fused slices still show it)")),
            }
        }
        if let Some(view) = self.pending_view.take() {
            layer.apply_view(&view);
        }
        self.layer = Some(layer);
        message
    }
}

#[cfg(test)]
mod tests {
    use super::panel::window_presets;
    use super::*;
    use crate::volume::PetScale;

    fn pet(
        dims: [usize; 3],
        spacing: [f64; 3],
        origin: [f64; 3],
        f: impl Fn(DVec3) -> f32,
    ) -> Volume {
        let mut values = Vec::new();
        for k in 0..dims[2] {
            for j in 0..dims[1] {
                for i in 0..dims[0] {
                    let p = DVec3::new(
                        origin[0] + i as f64 * spacing[0],
                        origin[1] + j as f64 * spacing[1],
                        origin[2] + k as f64 * spacing[2],
                    );
                    values.push(f(p));
                }
            }
        }
        let mut v = Volume::from_f32(dims, spacing, values);
        v.origin_mm = origin;
        v.modality = Modality::Pt;
        v.pet = Some(PetScale {
            units: "BQML".to_owned(),
            suv_factor: Some(1.0),
            rule: "test".to_owned(),
        });
        v
    }

    /// The overlay samples the PET at each CT voxel's patient position, whatever the two grids:
    /// a PET of 4 mm voxels offset from a CT of 1 mm voxels lights up the CT pixels where the
    /// PET is hot, and is transparent outside the PET.
    #[test]
    fn the_suv_presets_are_the_reader_s_windows_and_full_covers_the_volume() {
        let suv = window_presets("SUV", (0.0, 37.5));
        let labels: Vec<&str> = suv.iter().map(|p| p.0).collect();
        assert_eq!(labels, ["0-5", "0-10", "0-20", "full"]);
        assert_eq!(suv[1].1, (0.0, 10.0));
        assert_eq!(suv[3].1, (0.0, 37.5));
        // Counts (no SUV): the whole range only, from 0 or below, never an empty window.
        assert_eq!(
            window_presets("counts", (-2.0, 129_176.0)),
            [("full", (-2.0, 129_176.0))]
        );
        assert_eq!(window_presets("counts", (5.0, 5.0)), [("full", (0.0, 5.0))]);
    }

    #[test]
    fn the_overlay_reads_the_pet_at_the_ct_s_points() {
        let mut ct = Volume::from_f32([40, 40, 5], [1.0, 1.0, 2.0], vec![0.0; 8000]);
        ct.modality = Modality::Ct;
        // Hot (SUV 10) for x > 20 mm, cold (0) elsewhere; the PET starts at x = 2 mm.
        let pet = pet([8, 12, 4], [4.0, 4.0, 4.0], [2.0, -2.0, -1.0], |p| {
            if p.x > 20.0 { 10.0 } else { 0.0 }
        });
        let layer = PetLayer::new(pet, &ct);
        assert_eq!(layer.window, (0.0, 10.0));
        let axes =
            crate::app::model::axes::pane_axes(&ct, crate::app::model::axes::SliceKind::Axial);
        let image = layer.overlay(&ct, axes, 2);
        assert_eq!(image.size, [40, 40]);
        let at = |x: usize, y: usize| image.pixels[x + 40 * y];
        // CT voxel x = 30 mm lies in the hot part: white-hot, half covered.
        let hot = at(30, 10);
        assert!(hot.a() > 100, "{hot:?}");
        // x = 10 mm: cold, transparent.
        assert_eq!(at(10, 10).a(), 0);
        // x = 0 lies before the PET's first voxel centre (2 mm): outside, transparent.
        assert_eq!(at(0, 10), egui::Color32::TRANSPARENT);
        assert_eq!(layer.value_at_ct_voxel(&ct, [30, 10, 2]), Some(10.0));
        assert_eq!(layer.value_at_ct_voxel(&ct, [0, 10, 2]), None);
        // The PET alone: opaque inverted grey, black where hot, white where cold or outside,
        // on the same CT pixels (the crosshair and ROIs stay put).
        let mut alone = layer;
        alone.alone = true;
        let image = alone.overlay(&ct, axes, 2);
        let at = |x: usize, y: usize| image.pixels[x + 40 * y];
        assert_eq!(at(30, 10), egui::Color32::from_gray(0));
        assert_eq!(at(10, 10), egui::Color32::from_gray(255));
        assert_eq!(at(0, 10), egui::Color32::from_gray(255));
    }

    #[test]
    fn a_pet_for_an_older_ct_is_dropped() {
        let mut ct = Volume::from_f32([4, 4, 4], [1.0; 3], vec![0.0; 64]);
        ct.modality = Modality::Ct;
        let p = pet([2, 2, 2], [2.0; 3], [0.0; 3], |_| 1.0);
        let mut state = PetState {
            loading_for: Some(1),
            ..Default::default()
        };
        assert_eq!(state.install(p.clone(), Some(&ct), 2, None), None);
        assert!(state.layer.is_none());
        state.loading_for = Some(2);
        let mut not_pet = p;
        not_pet.modality = Modality::Ct;
        assert!(
            state
                .install(not_pet, Some(&ct), 2, None)
                .is_some_and(|m| m.contains("not a PET"))
        );
    }
}
