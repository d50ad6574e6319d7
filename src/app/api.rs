//! The app's state as tests, automation and the page's controls read and set it: the crosshair,
//! windows, layout, panes, opening volumes, the display mode, the features and findings.

use super::*;

impl ShapecastApp {
    /// The shared crosshair, voxel index.
    pub fn crosshair(&self) -> [usize; 3] {
        self.reading.crosshair
    }

    pub fn set_crosshair(&mut self, voxel: [usize; 3]) {
        if let Some(s) = &self.scene {
            self.reading.crosshair =
                std::array::from_fn(|a| voxel[a].min(s.volume.dims[a].saturating_sub(1)));
        }
    }

    /// The crosshair in patient space (LPS, mm): the MIP's slab centre and marker.
    pub fn crosshair_lps_mm(&self) -> Option<glam::DVec3> {
        let v = self.volume()?;
        let [i, j, k] = self.reading.crosshair;
        Some(
            v.world_from_voxel()
                .transform_point3(glam::DVec3::new(i as f64, j as f64, k as f64)),
        )
    }

    /// The status as `window.shapecastStatus` shows it.
    pub fn status(&self) -> &AppStatus {
        &self.status
    }

    pub fn window(&self) -> Window {
        self.reading.window
    }

    pub fn set_window(&mut self, window: Window) {
        self.reading.window = window;
    }

    /// Sets the fused PET's window (its display unit, SUV); nothing without a PET.
    pub fn set_pet_window(&mut self, window: (f32, f32)) {
        if let Some(layer) = &mut self.pet.layer
            && window.1 > window.0
        {
            layer.window = window;
        }
    }

    pub fn volume(&self) -> Option<&Volume> {
        self.scene.as_ref().map(|s| s.volume.as_ref())
    }

    /// The errors shown (not dismissed), oldest first.
    pub fn errors(&self) -> &[String] {
        &self.errors
    }

    pub fn mode(&self) -> DisplayMode {
        self.mode
    }

    pub fn layout(&self) -> Layout {
        self.reading.layout
    }

    pub fn set_layout(&mut self, layout: Layout) {
        self.reading.layout = layout;
        if !matches!(layout, Layout::Single(_)) {
            self.reading.multi_layout = layout;
        }
    }

    /// The slice a pane shows (its index along the pane's fixed voxel axis).
    pub fn pane_slice(&self, kind: SliceKind) -> Option<usize> {
        let v = self.volume()?;
        Some(self.reading.crosshair[model::axes::pane_axes(v, kind).fixed])
    }

    /// Where a pane's image was drawn in the last frame (screen points).
    pub fn pane_rect(&self, kind: SliceKind) -> Option<egui::Rect> {
        self.panes.iter().find(|p| p.kind == kind)?.image_rect
    }

    /// The voxel under a screen point of a pane's image, as the pane maps it.
    pub fn pane_voxel_at(&self, kind: SliceKind, pos: egui::Pos2) -> Option<[usize; 3]> {
        let v = self.volume()?;
        let rect = self.pane_rect(kind)?;
        let axes = model::axes::pane_axes(v, kind);
        let (u, w) = axes.voxel_at(rect, pos, v.dims[axes.across], v.dims[axes.vertical])?;
        let mut p = self.reading.crosshair;
        p[axes.across] = u;
        p[axes.vertical] = w;
        Some(p)
    }

    /// Feature values (V, A, B) at the crosshair as last read back from the GPU.
    pub fn features_at_crosshair(&self) -> Option<[f32; 3]> {
        let entry = self.displayed_entry()?;
        self.probe.value_at(entry.id, self.reading.crosshair)
    }

    /// Starts loading a volume (the current one stays until the new one is ready). A link to
    /// it names files by their label and size, phantoms by name.
    pub fn open(&mut self, source: LoadSource) {
        let origin = match &source {
            LoadSource::Files { label, files } => Some(ViewSource::Dropped {
                name: label.clone(),
                bytes: files.iter().map(crate::io::InputFile::len).sum(),
            }),
            LoadSource::Phantom(name) => Some(ViewSource::Phantom(name.clone())),
            LoadSource::Paths(_) => None,
            // Another series of the files shown: they came from where the shown one did.
            LoadSource::Series(_) => self.scene.as_ref().and_then(|s| s.origin.clone()),
        };
        self.open_from(source, origin);
    }

    /// Starts loading a volume that a link names by `origin`.
    pub fn open_from(&mut self, source: LoadSource, origin: Option<ViewSource>) {
        self.cancel_upload();
        self.load_progress = Some((0.0, format!("opening {}", source.label())));
        self.loading_origin = origin;
        self.load = Some(LoadJob::new(source));
        self.series.loading = None;
    }

    /// Switches the display mode; computes its features if they are not kept yet.
    pub fn set_mode(&mut self, mode: DisplayMode) {
        self.mode = mode;
        self.ensure_features();
    }

    /// Applies the edited parameters and computes the displayed method with them.
    pub fn recompute(&mut self) {
        self.applied = self.params.clone();
        self.ensure_features();
    }

    pub fn params_mut(&mut self) -> &mut FeatureParams {
        &mut self.params
    }

    /// Whether a feature computation is running.
    pub fn computing(&self) -> bool {
        self.features.running_request().is_some()
    }

    pub fn cancel_features(&mut self) {
        self.features.cancel();
    }

    /// N / Shift+N: the next or previous finding not dismissed.
    pub fn next_finding(&mut self, forward: bool) {
        if let Some(p) = self.findings.step(self.generation, forward) {
            self.go_to_lps(p);
        }
    }

    /// Asks for findings (as the panel's "List findings" does), for tests and automation.
    pub fn list_findings(&mut self) {
        self.findings.ask();
    }

    /// The findings of the shown volume, for tests and automation.
    pub fn findings_status(&self) -> crate::status::FindingsStatus {
        self.findings.status(self.generation)
    }
}
