//! Sharing the view: the app's state as a [`ViewState`] (published as
//! `window.shapecastStatus.link` / `.view`, copied by the "Copy link" button) and a link's state
//! applied to the app. A link's view waits for its volume: it is applied when the volume it names
//! is installed (downloaded from its URLs, or dropped by the user: a link to a file from its
//! author's computer says which file to drop), after the defaults a new volume gets.

use super::model::axes::SliceKind;
use super::platform::Platform as _;
use super::view_link::{ViewSource, ViewState, human_bytes};
use super::{Layout, ShapecastApp};

/// A link's view that waits for its volume.
pub(super) struct PendingView {
    pub view: ViewState,
    /// The series the link names has been asked for once already (it is not asked again if
    /// its load fails or gives another).
    pub series_asked: bool,
}

impl PendingView {
    pub fn new(view: ViewState) -> Self {
        Self {
            view,
            series_asked: false,
        }
    }
}

impl ShapecastApp {
    /// Everything a link carries, as the app shows it now.
    pub fn view_state(&self) -> ViewState {
        let scene = self.scene.as_ref();
        let camera = match &self.pending_camera {
            Some((generation, camera)) if scene.is_some_and(|s| s.generation == *generation) => {
                *camera
            }
            _ => self.mip_view.camera,
        };
        ViewState {
            source: scene.and_then(|s| s.origin.clone()),
            mode: Some(self.mode),
            params: Some(self.applied.clone()),
            display: Some(self.display.clone()),
            camera: scene.map(|_| camera),
            slab_mm: Some(self.mip_view.slab_mm),
            crosshair_mm: self.crosshair_lps_mm().map(|p| p.to_array()),
            mip_window: scene.map(|_| self.mip_view.settings.window),
            projection: Some(self.mip_view.settings.projection),
            grey: Some(self.mip_view.settings.show_intensity),
            window: scene.map(|_| self.reading.window),
            layout: Some(self.reading.layout),
            measurements: scene
                .filter(|_| !self.measure.list.is_empty())
                .map(|_| self.measure.measurements()),
            choice: self
                .series
                .set
                .as_ref()
                .filter(|_| {
                    !matches!(
                        scene.and_then(|s| s.origin.as_ref()),
                        Some(ViewSource::DicomWeb { .. })
                    )
                })
                .and_then(|set| set.list.entries().get(set.chosen))
                .map(super::series_list::entry_key),
            pet: self.pet.view(),
            findings: scene
                .map(|s| self.findings.link_marks(s.generation))
                .filter(|m| !m.is_empty()),
        }
    }

    /// When `pending` names another series of the files shown than the one loaded: asks for
    /// it (once) and keeps the view pending until it is installed. Returns the view when it
    /// is to be applied now. A series the files do not hold is said in a note.
    fn series_first(&mut self, mut pending: PendingView) -> Option<PendingView> {
        let Some(key) = pending.view.choice.clone() else {
            return Some(pending);
        };
        let Some(set) = self.series.set.clone() else {
            return Some(pending);
        };
        match super::series_list::find_entry(&set, &key) {
            Some(i) if i == set.chosen => Some(pending),
            Some(i) if !pending.series_asked => {
                pending.series_asked = true;
                self.pending_view = Some(pending);
                self.open_series(&set, i);
                None
            }
            Some(_) => Some(pending),
            None => {
                self.notes.push(format!(
                    "the link's series {key} is not among these files: its view is shown on the series loaded"
                ));
                Some(pending)
            }
        }
    }

    /// The camera the MIP pane draws with now (`view_state` gives a link's camera already
    /// while it waits for the MIP pane to frame the volume).
    pub fn mip_camera(&self) -> crate::render::camera::Camera {
        self.mip_view.camera
    }

    /// The link to this view: the page's address (on the web) with the view as its fragment.
    pub fn link(&self) -> String {
        format!(
            "{}#{}",
            self.platform.page_address(),
            self.view_state().fragment()
        )
    }

    /// Makes `view` the one to show: at once for what does not depend on the volume, and for
    /// the rest when its volume is installed (now, if it is the one shown).
    pub fn apply_view(&mut self, view: ViewState) {
        let shown = self.scene.as_ref().and_then(|s| s.origin.clone());
        if self.scene.is_some() && (view.source.is_none() || view.source == shown) {
            if let Some(pending) = self.series_first(PendingView::new(view)) {
                self.apply_view_to_scene(&pending.view);
                self.ensure_features();
            }
        } else {
            self.pending_view = Some(PendingView::new(view));
        }
    }

    /// Opens a link in the running app (its fragment, e.g. pasted into the address bar): the
    /// link's volume is loaded unless it is the one shown (the volume shown stays until the new
    /// one arrives, and if it cannot be loaded), and its view applied.
    pub fn open_link(&mut self, fragment: &str) {
        let (view, problems) = ViewState::from_fragment(fragment);
        for p in problems {
            self.error(p);
        }
        let shown = self.scene.as_ref().and_then(|s| s.origin.clone());
        match view.source.clone() {
            Some(source) if Some(&source) != shown.as_ref() => {
                self.pending_view = Some(PendingView::new(view));
                match source {
                    ViewSource::Urls(urls) => self.open_urls(urls),
                    ViewSource::Phantom(name) => self.open(super::LoadSource::Phantom(name)),
                    ViewSource::Demo => self.open_demo_ct(),
                    ViewSource::DicomWeb {
                        base,
                        study,
                        series,
                    } => self.open_dicomweb(super::PacsTarget {
                        base,
                        study,
                        series: Some(series).filter(|s| !s.is_empty()),
                    }),
                    // The link's file is on its author's computer: wait for the user's drop.
                    ViewSource::Dropped { .. } => {}
                }
            }
            _ => self.apply_view(view),
        }
    }

    /// At install: the pending view, if it is for this volume. A view for a file that has to
    /// be dropped stays pending when another one arrives, with a note.
    pub(super) fn apply_pending_view(&mut self) {
        let Some(pending) = self.pending_view.take() else {
            return;
        };
        let shown = self.scene.as_ref().and_then(|s| s.origin.clone());
        match (&pending.view.source, &shown) {
            (None, _) => {
                if let Some(pending) = self.series_first(pending) {
                    self.apply_view_to_scene(&pending.view);
                }
            }
            (Some(wanted), Some(got)) if wanted == got => {
                if let Some(pending) = self.series_first(pending) {
                    self.apply_view_to_scene(&pending.view);
                }
            }
            (Some(ViewSource::Dropped { name, bytes }), got) => {
                self.notes.push(format!(
                    "the link's view is for {name} ({}); {} is another volume, so its view was not applied",
                    human_bytes(*bytes),
                    got.as_ref().map_or("this".to_owned(), ViewSource::describe)
                ));
                self.pending_view = Some(pending);
            }
            // Another volume was opened instead of the link's: the link is done with.
            _ => {}
        }
    }

    /// Applies every field of `view` to the loaded volume's display.
    fn apply_view_to_scene(&mut self, view: &ViewState) {
        let Some(scene) = &self.scene else { return };
        let generation = scene.generation;
        let volume = scene.volume.clone();
        if let Some(m) = view.mode {
            self.mode = m;
        }
        if let Some(p) = &view.params {
            self.params = p.clone();
            self.applied = p.clone();
        }
        if let Some(d) = &view.display {
            self.display = d.clone();
        }
        if let Some(w) = view.window {
            self.reading.window = w;
        }
        if let Some(p) = view.crosshair_mm {
            let v = volume
                .voxel_from_world()
                .transform_point3(glam::DVec3::from_array(p));
            let voxel = [v.x, v.y, v.z];
            self.reading.crosshair = std::array::from_fn(|a| {
                let max = volume.dims[a].saturating_sub(1) as f64;
                voxel[a].round().clamp(0.0, max) as usize
            });
        }
        if let Some(w) = view.mip_window {
            self.mip_view.settings.window = w;
            // The MIP keeps this window rather than setting its default for the volume.
            self.reading.mip_window_for = Some(generation);
        }
        if let Some(p) = view.projection {
            self.mip_view.settings.projection = p;
        }
        if let Some(g) = view.grey {
            self.mip_view.settings.show_intensity = g;
        }
        if let Some(s) = view.slab_mm {
            self.mip_view.slab_mm = s;
        }
        if let Some(c) = view.camera {
            // The MIP widget frames a new volume when it first draws it; the camera is set
            // after that (`restore_camera`).
            self.pending_camera = Some((generation, c));
        }
        if let Some(l) = view.layout {
            self.set_layout(l);
        }
        if let Some(m) = &view.measurements {
            self.measure.set(&volume, m);
        }
        if let Some(f) = &view.findings {
            self.findings.set_linked(generation, f.clone());
        }
        if let Some(p) = &view.pet {
            self.pet.apply_view(p);
            // A PET the link names by URL and that is not here yet comes with this CT (in
            // the page; natively the error says how to give it).
            if self.pet.layer.is_none() && !self.pet.loading() && !p.urls.is_empty() {
                match self.platform.fetch_pet(p.urls.clone(), generation) {
                    Ok(()) => {
                        self.pet.urls = p.urls.clone();
                        self.pet.awaiting(generation);
                    }
                    Err(why) => self.error(why),
                }
            }
        }
        self.measure
            .read_pet(&volume, self.pet.layer.as_ref().map(|l| l.volume.as_ref()));
    }

    /// Right after the MIP pane drew the current volume (the widget framed it then): the
    /// link's camera replaces that framing.
    pub(super) fn restore_camera(&mut self, ctx: &egui::Context) {
        let Some(scene) = &self.scene else { return };
        if let Some((generation, camera)) = self.pending_camera
            && generation == scene.generation
        {
            self.mip_view.camera = camera;
            self.pending_camera = None;
            ctx.request_repaint();
        }
    }

    /// What the user is asked to do for a link's view, if anything.
    pub(super) fn link_notice(&self) -> Option<String> {
        match &self.pending_view.as_ref()?.view.source {
            Some(ViewSource::Dropped { name, bytes }) => Some(format!(
                "This link shows a view of {name} ({}), a file from its author's computer: it is not on any server. Drop that file (or folder) here, or open it with \"Open files…\", and the view is restored.",
                human_bytes(*bytes)
            )),
            _ => None,
        }
    }

    /// The link notice, above the panes.
    pub(super) fn link_notice_ui(&mut self, ui: &mut egui::Ui) {
        let Some(notice) = self.link_notice() else {
            return;
        };
        let fill = egui::Color32::from_rgb(25, 45, 70);
        let title = ("Link:", egui::Color32::from_rgb(160, 200, 255));
        if super::panels::notice_ui(ui, fill, title, notice) {
            self.pending_view = None;
        }
    }

    /// Remembers where a control was drawn (published for automation as
    /// `window.shapecastStatus.controls`, in CSS pixels).
    pub(super) fn control(&mut self, name: &str, rect: egui::Rect) {
        self.controls.push((name.to_owned(), rect));
    }
}

/// The name of a pane in `controls`.
pub(super) fn pane_control(kind: Option<SliceKind>) -> String {
    match kind {
        None => "pane:mip".to_owned(),
        Some(k) => format!("pane:{}", k.name()),
    }
}

impl Layout {
    /// The layout of a name as [`Layout::name`] writes it.
    pub fn from_name(name: &str) -> Option<Self> {
        use super::PaneId;
        [
            Self::MipAndSlices,
            Self::Grid,
            Self::Single(PaneId::Mip),
            Self::Single(PaneId::Slice(SliceKind::Axial)),
            Self::Single(PaneId::Slice(SliceKind::Coronal)),
            Self::Single(PaneId::Slice(SliceKind::Sagittal)),
        ]
        .into_iter()
        .find(|l| l.name() == name)
    }
}
