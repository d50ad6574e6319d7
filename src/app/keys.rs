//! Keyboard shortcuts of the viewer and the short help that "?" shows: window presets on the
//! number keys, measuring tools, fitting the slice panes. Keys act only while no text field has
//! the keyboard (a typed "1" in a parameter field is a digit, not a preset).

use super::measure::Tool;
use super::{ShapecastApp, WindowPreset};

/// The help's lines: keys (or gestures) and what they do.
pub const HELP: &[(&str, &str)] = &[
    (
        "1 … 5",
        "window presets: lung, mediastinum, abdomen, bone, brain (slices and MIP)",
    ),
    ("0", "the volume's default windows (slices and MIP)"),
    (
        "wheel, arrow up/down, PgUp PgDn",
        "next slice towards superior / anterior / left (over a slice pane)",
    ),
    (
        "ctrl + wheel, pinch",
        "zoom at the pointer (slice panes; the wheel alone in the MIP)",
    ),
    ("middle drag, shift + drag", "pan"),
    ("double-click, F", "fit the slices in their panes"),
    (
        "right drag, ctrl + drag",
        "window: sideways = width, down = darker",
    ),
    (
        "left click",
        "move the crosshair (in the MIP: to where the pixel's maximum is)",
    ),
    (
        "D, E, Esc",
        "draw a ruler, an ellipse; back to the crosshair",
    ),
    (
        "P",
        "save a picture (PNG) of the pane under the pointer, or of the MIP",
    ),
    (
        "M",
        "save a movie: a full turn of the MIP as an animated PNG",
    ),
    (
        "N, shift + N",
        "next / previous finding (the Findings list; dismissed ones are skipped)",
    ),
    ("?", "show or hide this help"),
];

impl ShapecastApp {
    /// Handles this frame's shortcut keys.
    pub(super) fn keys(&mut self, ctx: &egui::Context) {
        if ctx.egui_wants_keyboard_input() {
            return;
        }
        let events = ctx.input(|i| i.events.clone());
        for e in events {
            match e {
                egui::Event::Text(t) if t == "?" => {
                    self.windows.show_keys = !self.windows.show_keys
                }
                egui::Event::Key {
                    key,
                    pressed: true,
                    repeat: false,
                    modifiers,
                    ..
                } if !(modifiers.ctrl || modifiers.command || modifiers.alt) => {
                    if key == egui::Key::N {
                        self.next_finding(!modifiers.shift);
                    } else if key == egui::Key::P {
                        let pane = self.pane_under_pointer(ctx);
                        self.save_picture(ctx, pane);
                    } else if key == egui::Key::M {
                        if self.movie_progress().is_none() {
                            self.save_movie(ctx, super::export::movie::MOVIE_FRAMES);
                        }
                    } else {
                        self.key(key);
                    }
                }
                _ => {}
            }
        }
    }

    fn key(&mut self, key: egui::Key) {
        use egui::Key;
        let preset = match key {
            Key::Num1 => Some(0),
            Key::Num2 => Some(1),
            Key::Num3 => Some(2),
            Key::Num4 => Some(3),
            Key::Num5 => Some(4),
            _ => None,
        };
        if let Some(n) = preset {
            let w = WindowPreset::ALL[n].window();
            // The presets set the MIP's grey window too.
            self.reading.window = w;
            self.mip_view.settings.window = w.bounds();
            return;
        }
        match key {
            Key::Num0 => {
                if let Some(s) = &self.scene {
                    self.reading.window = super::window_level::default_window(&s.volume);
                    self.mip_view.settings.window =
                        super::default_mip_window(s, self.reading.window);
                }
            }
            Key::D => self.measure.tool = Tool::Ruler,
            Key::E => self.measure.tool = Tool::Ellipse,
            Key::Escape => self.measure.tool = Tool::Navigate,
            Key::F => {
                for p in &mut self.panes {
                    p.view = super::model::axes::PaneView::default();
                }
            }
            _ => {}
        }
    }

    /// The pane under the pointer (the MIP when there is none).
    fn pane_under_pointer(&self, ctx: &egui::Context) -> super::PaneId {
        use super::{PaneId, SliceKind};
        let Some(pos) = ctx.pointer_latest_pos() else {
            return PaneId::Mip;
        };
        SliceKind::ALL
            .into_iter()
            .find(|&k| {
                self.panes
                    .iter()
                    .any(|p| p.kind == k && p.area_rect.is_some_and(|r| r.contains(pos)))
            })
            .map_or(PaneId::Mip, PaneId::Slice)
    }

    /// The keyboard help window ("?").
    pub(super) fn keys_help_ui(&mut self, ctx: &egui::Context) {
        let mut open = self.windows.show_keys;
        egui::Window::new("Keys and mouse")
            .open(&mut open)
            .collapsible(false)
            .default_width(660.0)
            .show(ctx, |ui| {
                egui::Grid::new("keys help")
                    .num_columns(2)
                    .striped(true)
                    .show(ui, |ui| {
                        for (keys, what) in HELP {
                            ui.strong(*keys);
                            ui.label(*what);
                            ui.end_row();
                        }
                    });
            });
        self.windows.show_keys = open;
    }

    /// Whether the keyboard help is shown.
    pub fn keys_help_shown(&self) -> bool {
        self.windows.show_keys
    }
}
