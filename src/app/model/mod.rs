//! Parts of the reader's state that the panes and panels share and change, apart from the
//! volume, its features and the loads: where the reader is and how the panes are laid out
//! ([`Reading`]), and the app's own windows and feedback ([`Windows`]); which voxel axes each
//! pane shows and how ([`axes`]).

pub mod axes;

use super::{Layout, Window, WindowPreset};

/// Where the reader is in the volume shown, and the layout.
pub(super) struct Reading {
    /// The slice panes' grey window (physical units).
    pub window: Window,
    /// The shared crosshair, a voxel of the volume shown.
    pub crosshair: [usize; 3],
    /// The voxel under the pointer, if any.
    pub hover: Option<[usize; 3]>,
    pub layout: Layout,
    /// The layout to go back to from a maximised pane.
    pub multi_layout: Layout,
    /// The volume generation the MIP window was set for.
    pub mip_window_for: Option<u64>,
}

impl Default for Reading {
    fn default() -> Self {
        Self {
            window: WindowPreset::Abdomen.window(),
            crosshair: [0; 3],
            hover: None,
            layout: Layout::MipAndSlices,
            multi_layout: Layout::MipAndSlices,
            mip_window_for: None,
        }
    }
}

/// The app's own windows and feedback.
#[derive(Default)]
pub(super) struct Windows {
    /// "About & data".
    pub show_about: bool,
    /// The keyboard help ("?").
    pub show_keys: bool,
    /// Files are being dragged over the window.
    pub drop_hover: bool,
    /// When "Copy link" was last clicked (egui time), for its "copied" feedback.
    pub link_copied_at: Option<f64>,
}
