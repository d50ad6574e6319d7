//! What the app publishes each frame for tests and anyone's scripts: `AppStatus`
//! (`window.shapecastStatus` in the browser), the link of the view shown and the controls'
//! rectangles.

use super::platform::Platform as _;
use super::{JobOutcome, ShapecastApp, features, panels, series_list};
use crate::status::{CrosshairStatus, FeatureStatus, PetStatus, Phase, VolumeStatus};

impl ShapecastApp {
    pub(super) fn update_status(&mut self) {
        let view = self.view_state();
        let link = format!("{}#{}", self.platform.page_address(), view.fragment());
        if self.status.link != link {
            self.status.link = link;
            self.status.view_json = view.json();
        }
        self.status.notice = self.link_notice();
        self.status.controls = self
            .controls
            .iter()
            .map(|(n, r)| (n.clone(), [r.left(), r.top(), r.width(), r.height()]))
            .collect();
        let movie = self.movie_progress();
        let pet_status = self.pet.layer.as_ref().map(|p| PetStatus {
            dims: p.volume.dims,
            spacing_mm: p.volume.spacing_mm,
            unit: p.unit().to_owned(),
            suv_factor: p.volume.pet.as_ref().and_then(|x| x.suv_factor),
            at_crosshair: self
                .scene
                .as_ref()
                .and_then(|sc| p.value_at_ct_voxel(&sc.volume, self.reading.crosshair)),
            window: p.window,
            opacity: p.opacity,
            visible: p.visible,
        });
        let mip_state = if self.scene.is_some() {
            self.mip_view.picture_state()
        } else {
            "none"
        };
        let pet_mip_state = if self.pet.layer.is_none() {
            "none"
        } else if self.pet_mip.lags(&self.mip_view.camera) {
            // Drawn with the shape MIP's camera of the frame before: the next frame redraws it.
            "refining"
        } else {
            self.pet_mip.picture_state()
        };
        let storing = self.storing_to_pacs() || self.movie_stores_to_pacs();
        let stored = self.pacs_stored_series().to_vec();
        let s = &mut self.status;
        s.pet = pet_status;
        s.pet_loading = self.pet.loading();
        s.mip = mip_state.to_owned();
        s.pet_mip = pet_mip_state.to_owned();
        s.findings = self.findings.status(self.generation);
        s.storing = storing;
        s.stored = stored;
        s.volume = self.scene.as_ref().map(|sc| VolumeStatus {
            dims: sc.volume.dims,
            spacing_mm: sc.volume.spacing_mm,
            origin_mm: sc.volume.origin_mm,
            direction: sc.volume.direction.to_cols_array(),
            source: sc.volume.source.clone(),
            modality: sc.volume.modality.as_str().to_owned(),
        });
        s.crosshair = self.scene.as_ref().map(|sc| {
            let [i, j, k] = self.reading.crosshair;
            let p = sc
                .volume
                .world_from_voxel()
                .transform_point3(glam::DVec3::new(i as f64, j as f64, k as f64));
            CrosshairStatus {
                voxel: self.reading.crosshair,
                lps_mm: [p.x, p.y, p.z],
            }
        });
        let request = self.mode.method().map(|m| self.applied.request(m));
        let (state, fraction) = match &request {
            None => ("none", 1.0),
            Some(r) if self.features.find(r).is_some() => ("done", 1.0),
            Some(r) if self.features.running_request() == Some(r) => {
                ("running", self.features.progress().map_or(0.0, |(f, _)| f))
            }
            Some(r) => match self.features.outcome(r) {
                Some(JobOutcome::Cancelled) => ("cancelled", 0.0),
                Some(JobOutcome::Failed(_)) => ("failed", 0.0),
                _ => ("none", 0.0),
            },
        };
        s.features = Some(FeatureStatus {
            method: self.mode.name().to_owned(),
            preset: self.applied.preset.name().to_owned(),
            state: state.to_owned(),
            fraction,
            cached: self.features.len(),
            level: request
                .as_ref()
                .and_then(|r| self.features.find(r))
                .map_or(0, |e| e.texture.level),
            gpu_budget_mib: self.features.gpu_budget().mib(),
        });
        s.layout = self.reading.layout.name().to_owned();
        s.error = self.errors.last().cloned();
        s.series = series_list::status_of(&self.series);

        let computing = self.features.running_request().is_some();
        if let Some((f, what)) = &self.load_progress {
            s.phase = Phase::Loading;
            s.progress = *f;
            s.task = Some(what.clone());
        } else if computing {
            s.phase = Phase::Computing;
            let (f, stage) = self.features.progress().unwrap_or((0.0, ""));
            s.progress = f;
            s.task = Some(format!(
                "computing {} features: {stage}{}",
                self.features
                    .running_request()
                    .map_or("", |r| features::method_name(r.method)),
                panels::time_left(self.features.timing())
            ));
        } else if let Some((done, frames)) = movie {
            // Saving a movie leaves the viewer ready; the task says how far it is.
            s.phase = Phase::Ready;
            s.progress = done as f32 / frames.max(1) as f32;
            s.task = Some(format!("saving the movie: frame {done} of {frames}"));
        } else {
            s.task = None;
            s.progress = 1.0;
            s.phase = if self.gpu.is_none() || (self.scene.is_none() && !self.errors.is_empty()) {
                Phase::Error
            } else {
                Phase::Ready
            };
        }
        if self.gpu.is_none() {
            s.phase = Phase::Error;
            s.error = Some("eframe started without a wgpu renderer".to_owned());
        }
    }
}
