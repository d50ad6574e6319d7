//! From a loaded volume to the displayed one: its texture written over frames (`Uploading`),
//! the scene, the panes and the features reset for it, a failed load reported with the previous
//! volume kept.

use super::platform::Platform as _;
use super::*;
use crate::gpu::volume_texture::RenderVolumeError;

/// A loaded volume whose intensity texture is being written, slab by slab over frames (a
/// whole-body CT is 1 GB: seconds of uploading in one frame would stop the viewer); it is
/// installed, and the volume shown replaced, once the last slab is in.
pub(super) struct Uploading {
    patient: Option<crate::io::Patient>,
    notes: Vec<String>,
    volume: Volume,
    series: Option<load::SeriesSet>,
    origin: Option<ViewSource>,
    render: RenderVolume,
    upload: IntensityUpload,
}

/// Upload slabs a frame may write, in seconds (at least one slab per frame).
const UPLOAD_SECONDS_PER_FRAME: f64 = 0.05;

/// Voxels from this size on are kept packed natively (`Voxels::packed`: lossless, about half a
/// CT's bytes, any voxel still read directly; `Platform::packs_voxels` says why not in the
/// page): a 512 x 512 x 128 CT and larger. Below it the saving is small and the dense copy is
/// read faster (a PET read every frame for its overlay).
pub const PACK_FROM_BYTES: usize = 64 << 20;

/// Keeps `volume`'s voxels packed when they are [`PACK_FROM_BYTES`] or more (the viewer natively;
/// `bench --whole-body` as the viewer does).
pub fn pack_if_large(volume: &mut Volume) {
    if volume.voxels.byte_len() >= PACK_FROM_BYTES {
        let dense = std::mem::replace(&mut volume.voxels, crate::volume::Voxels::U8(Vec::new()));
        volume.voxels = dense.packed(volume.dims);
    }
}

impl ShapecastApp {
    /// Makes a loaded volume the displayed one (or says why it cannot be shown), with the
    /// series list of the files it came from (`None`: files of one series, another format, a
    /// phantom, an archive's retrieval). A volume the GPU cannot show changes nothing; one it
    /// has no memory for is shown halved (`upload_refused`). Its texture is written over frames
    /// (`Uploading`); natively a small volume is installed in this frame (a browser answers for
    /// the texture's memory a frame or more later).
    pub(super) fn install(&mut self, loaded: crate::io::Loaded, series: Option<load::SeriesSet>) {
        let Some(gpu) = &self.gpu else { return };
        let patient = loaded.patient;
        let mut volume = loaded.volume;
        let mut notes = loaded.notes;
        // Larger than one 3D texture of this device: a reduced copy, said so (the file is
        // unchanged; features are computed on what is shown).
        let max = gpu.limits.max_texture_dimension_3d as usize;
        if max > 0 && volume.dims.iter().any(|&d| d > max) {
            let factors = volume.dims.map(|d| d.div_ceil(max));
            let before = volume.dims;
            volume = volume.reduced(factors);
            notes.push(format!(
                "{before:?} voxels exceed this GPU's largest 3D texture ({max} per side): shown and computed as {:?} voxels, averaged {factors:?}",
                volume.dims
            ));
        }
        if self.platform.packs_voxels() {
            pack_if_large(&mut volume);
        }
        let (render, upload) = match RenderVolume::create(gpu, &volume) {
            Ok(r) => r,
            Err(e) => return self.upload_refused(volume, notes, patient, series, e),
        };
        self.uploading = Some(Uploading {
            patient,
            notes,
            volume,
            series,
            origin: self.loading_origin.take(),
            render,
            upload,
        });
        self.advance_upload();
    }

    /// The device refused `volume`'s texture: when it had no memory for it, a copy half as
    /// large along its longest axis is installed instead, said so (again, until it fits or is
    /// too small to be worth showing); any other refusal fails the load.
    fn upload_refused(
        &mut self,
        volume: Volume,
        mut notes: Vec<String>,
        patient: Option<crate::io::Patient>,
        series: Option<load::SeriesSet>,
        error: RenderVolumeError,
    ) {
        if let RenderVolumeError::OutOfMemory { bytes, .. } = &error
            && let Some((reduced, factors)) = halved(&volume)
        {
            notes.push(format!(
                "the GPU had no memory for the {:?} voxels' texture ({:.0} MB): shown and computed as {:?} voxels, averaged {factors:?}",
                volume.dims,
                *bytes as f64 / 1e6,
                reduced.dims
            ));
            drop(volume);
            let loaded = crate::io::Loaded {
                volume: reduced,
                notes,
                patient,
            };
            return self.install(loaded, series);
        }
        self.loading_origin = None;
        self.load_failed(super::error::AppError::Upload {
            volume: volume.source.clone(),
            source: error,
        });
    }

    /// Stops uploading a volume when another load begins: the newer one is what the user asked
    /// for last, and a link's view waits for it, not for the older one.
    pub(super) fn cancel_upload(&mut self) {
        if self.uploading.take().is_some() {
            self.load_progress = None;
        }
    }

    /// A load failed: a link's view that waited for the series it named (asked for once
    /// already) is dropped with a note rather than applied later to another series.
    pub(super) fn load_failed(&mut self, error: impl Into<super::error::AppError>) {
        if self.pending_view.as_ref().is_some_and(|p| p.series_asked) {
            self.pending_view = None;
            self.notes
                .push("the link's series did not load, so its view was not applied".to_owned());
        }
        self.error(error);
    }

    /// Writes the next slabs of the volume being uploaded (about `UPLOAD_SECONDS_PER_FRAME`),
    /// and installs it after the last.
    pub(super) fn advance_upload(&mut self) {
        let (Some(gpu), Some(up)) = (&self.gpu, &mut self.uploading) else {
            return;
        };
        // Natively the queue's callbacks (which count the slabs in flight) run only when the
        // device is polled or something is submitted: poll, so that a frame that ended with
        // every slab in flight does not wait for ever (in the browser they run by themselves).
        gpu.poll_callbacks();
        let started = web_time::Instant::now();
        // Slabs while the frame's time lasts and the GPU keeps up (`ready`: a bounded number
        // in flight, so a slow device does not queue the whole volume in shared memory).
        // Nothing is written before the device has answered for the texture (the next frames).
        while up.upload.ready() && !up.upload.waiting() {
            match up.upload.step(gpu, &up.volume, &up.render) {
                Ok(false) => {}
                Ok(true) => {
                    if let Some(up) = self.uploading.take() {
                        self.load_progress = None;
                        self.finish_install(up);
                    }
                    return;
                }
                // A browser answers a refused texture a frame or more after it was made.
                Err(e) => {
                    if let Some(up) = self.uploading.take() {
                        self.load_progress = None;
                        self.loading_origin = up.origin;
                        self.upload_refused(up.volume, up.notes, up.patient, up.series, e);
                    }
                    return;
                }
            }
            if started.elapsed().as_secs_f64() >= UPLOAD_SECONDS_PER_FRAME {
                break;
            }
        }
        let fraction = up.upload.fraction(&up.render);
        self.load_progress = Some((
            fraction,
            format!(
                "uploading {} to the GPU ({:.0}%)",
                up.volume.source,
                100.0 * fraction
            ),
        ));
    }

    /// Makes an uploaded volume the displayed one.
    pub(super) fn finish_install(&mut self, up: Uploading) {
        let Uploading {
            patient,
            notes,
            volume,
            series,
            origin,
            render,
            upload: _,
        } = up;
        self.generation += 1;
        self.reading.window = window_level::default_window(&volume);
        self.reading.crosshair = volume.dims.map(|d| d / 2);
        self.reading.hover = None;
        self.features.clear();
        self.findings.clear();
        self.measure.list.clear();
        self.measure.last_pick = None;
        self.probe = probe::ProbeState::default();
        self.notes = notes;
        self.notes.extend(volume.warnings.iter().cloned());
        let range = volume.value_range();
        let is_ct = volume.looks_like_ct(range);
        // Without a preset asked for (URL, command line), open on the one that fits what was
        // loaded, and say which (the demo CTA keeps the vessels preset it starts with).
        if self.options.preset.is_none()
            && volume.modality != crate::volume::Modality::Phantom
            && !volume.source.contains(demo::DEMO_FILE)
        {
            let (preset, why) = preset_for(&volume, is_ct);
            if preset != self.applied.preset {
                self.params = FeatureParams::from_preset(preset);
                self.applied = self.params.clone();
            }
            self.notes.push(why);
        }
        self.scene = Some(Scene {
            is_ct,
            volume: Arc::new(volume),
            render,
            generation: self.generation,
            origin,
        });
        self.pacs.patient = patient;
        self.pending_camera = None;
        // The list goes with the volume shown.
        self.series.set = series;
        // The PET that came with a CT (a PET/CT study's folder) is read next, over it.
        self.pet.clear();
        if let (Some(set), Some(scene)) = (&self.series.set, &self.scene) {
            self.pet
                .start_with(set, &scene.volume, self.generation, &self.platform);
        }
        // ... and an archive's PET/CT study's PET series, retrieved over its CT.
        self.pacs_retrieve_pet(self.generation);
        if let Some(paths) = self.options.pet.take()
            && let Some(scene) = &self.scene
            && scene.volume.modality != crate::volume::Modality::Pt
        {
            self.pet
                .start_source(LoadSource::Paths(paths), self.generation);
        }
        // A PET/CT link's PET (`&pet=URL`): downloaded once the CT it goes over is shown.
        if !self.options.pet_urls.is_empty()
            && let Some(scene) = &self.scene
            && scene.volume.modality != crate::volume::Modality::Pt
        {
            let urls = std::mem::take(&mut self.options.pet_urls);
            self.pet.urls = urls.clone();
            self.pet.awaiting(self.generation);
            if let Err(why) = self.platform.fetch_pet(urls, self.generation) {
                self.error(why);
            }
        }
        // A link's view for this volume replaces the defaults it just got (after loading the
        // series it names, when that is another of these files).
        self.apply_pending_view();
        if self.options.compute_on_load {
            self.ensure_features();
        }
    }
}

impl ShapecastApp {
    /// Reads `source` as the PET of the CT shown and fuses it over it, replacing a PET shown
    /// (what `view CT --pet PET` does once the CT is shown). Nothing without a volume shown.
    pub fn open_pet(&mut self, source: LoadSource) {
        if self.scene.is_some() {
            self.pet.clear();
            self.pet.start_source(source, self.generation);
        }
    }
}

/// The preset that fits a loaded volume, and a sentence saying why: lung nodules when a CT holds
/// lung (more than 5% of its voxels between -950 and -600 HU), lymph nodes / soft tissue for
/// other CT; for a volume without Hounsfield units, the default with a warning that the presets'
/// transfer functions are in HU.
pub fn preset_for(volume: &crate::volume::Volume, is_ct: bool) -> (Preset, String) {
    if !is_ct {
        return (
            Preset::default(),
            format!(
                "preset: {} (the presets' transfer functions and thresholds are CT Hounsfield units; this volume has none, so set the transfer function to its contrast)",
                features::preset_label(Preset::default())
            ),
        );
    }
    let n = volume.voxel_count();
    let stride = (n / 200_000).max(1);
    let (mut lung, mut seen) = (0usize, 0usize);
    for i in (0..n).step_by(stride) {
        let v = volume.value(i);
        seen += 1;
        lung += usize::from((-950.0..=-600.0).contains(&v));
    }
    let fraction = lung as f64 / seen.max(1) as f64;
    let preset = if fraction > 0.05 {
        Preset::LungNodules
    } else {
        Preset::LymphNodes
    };
    (
        preset,
        format!(
            "preset: {} ({:.0}% of the voxels are lung, -950..-600 HU); change it under Features",
            features::preset_label(preset),
            100.0 * fraction
        ),
    )
}

/// `volume` averaged by 2 along its longest axis (in voxels), and the factors; `None` once that
/// axis is 32 voxels or fewer (a copy that small shows nothing worth reading).
fn halved(volume: &Volume) -> Option<(Volume, [usize; 3])> {
    let longest = (0..3).max_by_key(|&a| volume.dims[a])?;
    if volume.dims[longest] <= 32 {
        return None;
    }
    let mut factors = [1; 3];
    factors[longest] = 2;
    Some((volume.reduced(factors), factors))
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::expect_used)] // a failed expect is a failed test
mod tests {
    use super::*;

    #[test]
    fn a_refused_volume_is_halved_along_its_longest_axis_until_small() {
        let volume = Volume::from_f32([40, 30, 70], [0.8, 0.8, 0.8], vec![7.0; 40 * 30 * 70]);
        let (half, factors) = halved(&volume).expect("70 slices halve");
        assert_eq!(factors, [1, 1, 2]);
        assert_eq!(half.dims, [40, 30, 35]);
        assert_eq!(half.spacing_mm, [0.8, 0.8, 1.6]);
        let (quarter, factors) = halved(&half).expect("40 columns halve");
        assert_eq!(factors, [2, 1, 1]);
        assert_eq!(quarter.dims, [20, 30, 35]);
        let small = Volume::from_f32([32, 16, 8], [1.0; 3], vec![0.0; 32 * 16 * 8]);
        assert!(halved(&small).is_none(), "32 voxels is as small as it gets");
    }
}
