//! The app's bars and panels: the top bar (open, demo and phantom menu, mode, layout, about),
//! the side panel (features and their parameters, display gains, window), the status bar
//! (mouse and crosshair readouts, progress), the error messages, the about window and the drop
//! overlay.

mod side;

use super::export::buttons::{
    ExportEvent, StoreShown, copy_link_button, movie_progress, save_movie_button,
    save_picture_menu, store_button,
};
use super::features::{self, DisplayMode};
use super::pacs::ui::{self as pacs_ui, BarEvent};
use super::platform::Platform as _;
use super::{Layout, LoadSource, PaneId, ShapecastApp, SliceKind, WindowPreset, demo};

const FEATURE_NAMES: [&str; 3] = ["vesselness", "airwayness", "blobness"];

/// What the user asked for in the top bar, applied after it is drawn.
#[derive(Clone, Debug)]
pub(in crate::app) enum TopEvent {
    Open(LoadSource),
    OpenDemo,
    Mode(DisplayMode),
    Layout(Layout),
    ToggleAbout,
    Export(ExportEvent),
}

/// The "Demo" menu: the demo CT and the paper's phantoms.
fn demo_menu(ui: &mut egui::Ui) -> Option<TopEvent> {
    let mut event = None;
    ui.menu_button("Demo", |ui| {
        if ui.button("Demo CT (chest CTA, 1.5 mm)").clicked() {
            event = Some(TopEvent::OpenDemo);
            ui.close();
        }
        ui.separator();
        ui.label("Phantoms of the paper (0.5 mm, HU):");
        for name in crate::phantom::NAMES
            .iter()
            .chain(crate::phantom::EXTRA_NAMES.iter())
        {
            if ui.button(*name).clicked() {
                event = Some(TopEvent::Open(LoadSource::Phantom((*name).to_owned())));
                ui.close();
            }
        }
    });
    event
}

/// The display modes, `mode` selected; `computed` says whether a method's features with the
/// current parameters are kept. Returns the mode clicked and the buttons as named controls.
fn mode_bar(
    ui: &mut egui::Ui,
    mode: DisplayMode,
    computed: impl Fn(crate::cpu::pipeline::Method) -> bool,
) -> (Option<TopEvent>, Vec<(String, egui::Rect)>) {
    let mut event = None;
    let mut controls = Vec::new();
    ui.label("Mode:");
    for m in DisplayMode::ALL {
        let r = ui.selectable_label(mode == m, m.label());
        let r = match m.method() {
            Some(method) => r.on_hover_text(if computed(method) {
                "computed: switches at once"
            } else if method == crate::cpu::pipeline::Method::Rst {
                "computes the RST features with the current parameters: rays from every voxel, several times the Hessian's time (the status says how long)"
            } else {
                "computes the features with the current parameters"
            }),
            None => r.on_hover_text("grey values only"),
        };
        controls.push((format!("mode:{}", m.name()), r.rect));
        if r.clicked() && mode != m {
            event = Some(TopEvent::Mode(m));
        }
    }
    (event, controls)
}

/// The layouts, `layout` selected. Returns the layout clicked and the buttons as named controls.
fn layout_bar(ui: &mut egui::Ui, layout: Layout) -> (Option<TopEvent>, Vec<(String, egui::Rect)>) {
    let mut event = None;
    let mut controls = Vec::new();
    ui.label("Layout:");
    for (l, label) in [
        (Layout::MipAndSlices, "MIP + slices"),
        (Layout::Grid, "2×2"),
        (Layout::Single(PaneId::Mip), "MIP"),
        (Layout::Single(PaneId::Slice(SliceKind::Axial)), "Axial"),
        (Layout::Single(PaneId::Slice(SliceKind::Coronal)), "Coronal"),
        (
            Layout::Single(PaneId::Slice(SliceKind::Sagittal)),
            "Sagittal",
        ),
    ] {
        let r = ui.selectable_label(layout == l, label);
        controls.push((format!("layout:{}", l.name()), r.rect));
        if r.clicked() {
            event = Some(TopEvent::Layout(l));
        }
    }
    (event, controls)
}

impl ShapecastApp {
    /// Draws the top bar, then applies what the user asked for in it.
    pub(super) fn top_bar_ui(&mut self, ui: &mut egui::Ui) {
        let mut events = Vec::new();
        // Wrapped: on a narrow window (1280 px with the side panel) the bar takes a second row
        // rather than cutting off its last entries ("About & data" holds the demo's licence).
        egui::MenuBar::new().ui(ui, |ui| {
            ui.horizontal_wrapped(|ui| {
                ui.heading("Shapecast");
                ui.separator();
                events.extend(self.platform.open_menu_ui(ui).map(TopEvent::Open));
                events.extend(demo_menu(ui));
                ui.separator();
                let (features, applied) = (&self.features, &self.applied);
                let (mode, controls) = mode_bar(ui, self.mode, |method| {
                    features.find(&applied.request(method)).is_some()
                });
                events.extend(mode);
                self.controls.extend(controls);
                ui.separator();
                let (layout, controls) = layout_bar(ui, self.reading.layout);
                events.extend(layout);
                self.controls.extend(controls);
                ui.separator();
                let mut controls = Vec::new();
                let copied_at = &mut self.windows.link_copied_at;
                events.extend(copy_link_button(ui, copied_at, &mut controls).map(TopEvent::Export));
                let has_volume = self.scene.is_some();
                let picture = save_picture_menu(ui, self.reading.layout, has_volume);
                events.extend(picture.map(TopEvent::Export));
                let movie = has_volume && self.movie_progress().is_none();
                events.extend(save_movie_button(ui, movie, &mut controls).map(TopEvent::Export));
                self.controls.extend(controls);
                ui.separator();
                if ui.button("About & data").clicked() {
                    events.push(TopEvent::ToggleAbout);
                }
            });
        });
        for e in events {
            match e {
                TopEvent::Open(source) => self.open(source),
                TopEvent::OpenDemo => self.open_demo_ct(),
                TopEvent::Mode(m) => {
                    if self.mode != m {
                        self.set_mode(m);
                    }
                }
                TopEvent::Layout(l) => self.set_layout(l),
                TopEvent::ToggleAbout => self.windows.show_about = !self.windows.show_about,
                TopEvent::Export(e) => self.apply_export(ui.ctx(), e),
            }
        }
    }

    /// The bar above the panes: the PACS bar's buttons, "Store to PACS" for a volume from an
    /// archive, the patient line; then applies what was asked.
    pub(super) fn pacs_bar_ui(&mut self, ui: &mut egui::Ui) {
        let mut controls = Vec::new();
        let store = self.shows_archive_series().then(|| {
            let enabled = self.movie_progress().is_none() && !self.storing_to_pacs();
            (enabled, self.storing_to_pacs())
        });
        let busy = self.pacs.busy.is_some();
        let patient = self.patient_line();
        let stored_at = &mut self.pacs.stored_at;
        let (asked, export) = ui
            .horizontal(|ui| {
                let asked = pacs_ui::bar_buttons(ui, busy, &mut controls);
                let export = store.and_then(|(enabled, storing)| {
                    let shown = StoreShown {
                        enabled,
                        storing,
                        stored_at,
                    };
                    store_button(ui, shown, &mut controls)
                });
                pacs_ui::patient_label(ui, patient);
                (asked, export)
            })
            .inner;
        self.controls.extend(controls);
        match asked {
            Some(BarEvent::OpenDialog) => self.pacs.dialog = true,
            Some(BarEvent::Cancel) => self.cancel_dicomweb(),
            None => {}
        }
        if let Some(e) = export {
            self.apply_export(ui.ctx(), e);
        }
    }

    pub(super) fn open_demo_ct(&mut self) {
        match self.platform.demo() {
            Some(source) => self.open_from(source, Some(super::ViewSource::Demo)),
            None => {
                self.cancel_upload();
                self.load_progress = Some((0.0, "fetching the demo CT".to_owned()));
            }
        }
    }

    pub(super) fn status_bar_ui(&mut self, ui: &mut egui::Ui) {
        ui.horizontal(|ui| {
            ui.label(self.status.phase.as_str());
            if let Some((f, what)) = &self.load_progress {
                ui.add(
                    egui::ProgressBar::new(*f)
                        .desired_width(260.0)
                        .text(what.as_str()),
                );
                if self.platform.downloading() {
                    let r = ui
                        .small_button("Cancel")
                        .on_hover_text("stop the download; the volume shown stays");
                    self.control("cancel-download", r.rect);
                    if r.clicked() {
                        self.platform.cancel_download();
                    }
                }
            } else if let Some(bar) = self.feature_progress_bar(260.0) {
                ui.add(bar);
                if ui.small_button("Cancel").clicked() {
                    self.features.cancel();
                }
            }
            let mut controls = Vec::new();
            let movie = movie_progress(ui, self.movie_shown(), &mut controls);
            self.controls.extend(controls);
            if let Some(e) = movie {
                self.apply_export(ui.ctx(), e);
            }
            if let Some(a) = &self.status.adapter {
                ui.separator();
                ui.label(egui::RichText::new(format!("GPU: {} ({})", a.name, a.backend)).small());
            }
            ui.separator();
            ui.label(format!(
                "W {:.0} L {:.0}",
                self.reading.window.width, self.reading.window.level
            ));
        });
        let mono = egui::TextStyle::Monospace;
        ui.horizontal(|ui| {
            ui.label(egui::RichText::new("mouse     ").text_style(mono.clone()));
            if let Some(h) = self.reading.hover {
                ui.label(egui::RichText::new(self.readout(h)).text_style(mono.clone()));
            }
        });
        ui.horizontal(|ui| {
            ui.label(egui::RichText::new("crosshair ").text_style(mono.clone()));
            if self.scene.is_some() {
                ui.label(
                    egui::RichText::new(self.readout(self.reading.crosshair)).text_style(mono),
                );
            }
        });
    }

    pub(super) fn errors_ui(&mut self, ui: &mut egui::Ui) {
        let mut dismiss = None;
        for (n, e) in self.errors.iter().enumerate() {
            let fill = egui::Color32::from_rgb(70, 25, 25);
            let title = ("Error:", egui::Color32::from_rgb(255, 170, 160));
            if notice_ui(ui, fill, title, e) {
                dismiss = Some(n);
            }
        }
        if let Some(n) = dismiss {
            self.errors.remove(n);
        }
    }

    pub(super) fn about_ui(&mut self, ctx: &egui::Context) {
        let mut open = self.windows.show_about;
        egui::Window::new("About & data")
            .open(&mut open)
            .default_width(520.0)
            .show(ctx, |ui| {
                ui.label(
                    "Shapecast shows shape features of CT and MR volumes (Hessian and radial \
                     structure tensor, after Wiemker et al. 2013) as colour-coded maximum \
                     intensity projections beside linked slice panes. Everything runs on this \
                     machine's GPU; no data leaves it.",
                );
                ui.separator();
                ui.heading("Demo data");
                ui.label(demo::ATTRIBUTION);
                ui.hyperlink_to("Apache License 2.0", demo::LICENCE_URL);
                ui.hyperlink_to(
                    "TotalSegmentator on GitHub",
                    "https://github.com/wasserth/TotalSegmentator",
                );
                ui.separator();
                ui.label(demo::PHANTOM_NOTE);
                ui.separator();
                ui.label(
                    "Use: click a slice to move the crosshair; wheel to change slice; \
                     right-drag (or ctrl-drag) for window/level; 'maximise' shows one pane alone.",
                );
            });
        self.windows.show_about = open;
    }

    pub(super) fn drop_overlay(&self, ctx: &egui::Context) {
        if !self.windows.drop_hover {
            return;
        }
        let screen = ctx.content_rect();
        let painter = ctx.layer_painter(egui::LayerId::new(
            egui::Order::Foreground,
            egui::Id::unique("drop overlay"),
        ));
        painter.rect_filled(screen, 0.0, egui::Color32::from_black_alpha(170));
        painter.text(
            screen.center(),
            egui::Align2::CENTER_CENTER,
            "Drop files or a folder to open them",
            egui::FontId::proportional(24.0),
            egui::Color32::WHITE,
        );
    }

    /// The running feature computation's progress, `width` points wide: "method: stage".
    fn feature_progress_bar(&self, width: f32) -> Option<egui::ProgressBar> {
        let (fraction, stage) = self.features.progress()?;
        let name = self
            .features
            .running_request()
            .map_or("", |r| features::method_name(r.method));
        Some(
            egui::ProgressBar::new(fraction)
                .desired_width(width)
                .text(format!(
                    "{name}: {stage}{}",
                    time_left(self.features.timing())
                )),
        )
    }

    /// Keeps the status bar's feature readback going.
    pub(super) fn update_probe(&mut self) {
        let Some(gpu) = &self.gpu else { return };
        let entry = self
            .displayed_request()
            .and_then(|r| self.features.find(&r));
        let mut voxels = vec![self.reading.crosshair];
        if let Some(h) = self.reading.hover
            && h != self.reading.crosshair
        {
            voxels.push(h);
        }
        self.probe
            .update(gpu, entry.map(|e| (&e.texture, e.id)), voxels);
    }
}

/// ", about 12 s left" from a job's (elapsed, left) seconds; ", estimating the time" before it
/// has progress to go by.
pub(super) fn time_left(timing: Option<(f64, Option<f64>)>) -> String {
    match timing {
        None => String::new(),
        Some((_, None)) => ", estimating the time".to_owned(),
        Some((_, Some(left))) if left < 60.0 => format!(", about {:.0} s left", left.ceil()),
        Some((_, Some(left))) => format!(", about {:.0} min left", (left / 60.0).ceil()),
    }
}

/// A notice in a `fill` frame: a Dismiss button on the right, the title (text, colour), then
/// `text`, wrapped. True when Dismiss was clicked.
pub(super) fn notice_ui(
    ui: &mut egui::Ui,
    fill: egui::Color32,
    title: (&str, egui::Color32),
    text: impl Into<egui::WidgetText>,
) -> bool {
    let mut dismiss = false;
    egui::Frame::new()
        .fill(fill)
        .inner_margin(6.0)
        .corner_radius(4.0)
        .show(ui, |ui| {
            ui.with_layout(egui::Layout::right_to_left(egui::Align::TOP), |ui| {
                dismiss = ui.button("Dismiss").clicked();
                ui.with_layout(egui::Layout::left_to_right(egui::Align::TOP), |ui| {
                    ui.colored_label(title.1, title.0);
                    ui.add(egui::Label::new(text).wrap());
                });
            });
        });
    dismiss
}

/// A closed header `title` over `notes`, one small line each.
fn notes_ui(
    ui: &mut egui::Ui,
    title: impl Into<egui::WidgetText>,
    id_salt: &str,
    notes: &[String],
) {
    egui::CollapsingHeader::new(title)
        .id_salt(id_salt)
        .show(ui, |ui| {
            for n in notes {
                ui.label(egui::RichText::new(n).small());
            }
        });
}
