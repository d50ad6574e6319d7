//! The view as a link: everything needed to see again exactly what a user sees (the source, the
//! display mode, the preset and edited parameters, channels and gains, camera, slab, crosshair,
//! windows, layout), written into a URL fragment (`#v=1&url=...&mode=li&...`, which browsers
//! never send to a server) and as the same fields in JSON (`window.shapecastStatus.view`).
//!
//! Pure code, no browser: the app captures and applies a [`ViewState`] (`share.rs`), the page
//! reads the fragment and the query (`web_files`). A link carries a version (`v`); unknown
//! fields are ignored, and a field that cannot be read is named in a message while the rest
//! applies. Numbers are written in their shortest exact form, so a view read back from its link
//! is bit for bit the view that wrote it.

mod read;
mod write;

use glam::{DQuat, DVec3};

use super::Layout;
use super::features::{DisplayMode, FeatureDisplay, FeatureParams};
use super::findings::FindingMark;
use super::measure::Measurement;
use super::window_level::Window;
use crate::cpu::features::FeatureMap;
use crate::cpu::rays::RAY_COUNTS;
use crate::cpu::tf::{Preset, TransferFunction};
use crate::io::url::{encode, host_of, parse_params};
use crate::render::camera::{Camera, MAX_ZOOM, MIN_ZOOM};
use crate::render::raycast::Projection;

/// The link format this build writes. Links of other versions are read field by field.
pub const VERSION: u32 = 1;

/// Where the viewed volume came from.
#[derive(Clone, Debug, PartialEq)]
pub enum ViewSource {
    /// The demo CT the page ships with.
    Demo,
    /// A phantom by name.
    Phantom(String),
    /// Files downloaded from these (absolute) URLs.
    Urls(Vec<String>),
    /// Files from the author's own computer (dropped or opened): what to drop to see the view
    /// (a file's name, or a folder's as the app labels it) and its size in bytes.
    Dropped { name: String, bytes: u64 },
    /// A series in a DICOMweb archive: its root (absolute, or relative to the page's origin),
    /// study and series UIDs. Credentials never go into a link.
    DicomWeb {
        base: String,
        study: String,
        series: String,
    },
}

impl ViewSource {
    /// What the user is told about it.
    pub fn describe(&self) -> String {
        match self {
            Self::Demo => "the demo CT".to_owned(),
            Self::Phantom(name) => format!("phantom {name}"),
            Self::Urls(urls) => match urls.as_slice() {
                [one] => one.clone(),
                many => format!("{} files from {}", many.len(), host_of(&many[0])),
            },
            Self::Dropped { name, bytes } => format!("{name} ({})", human_bytes(*bytes)),
            Self::DicomWeb { base, series, .. } => format!("series {series} from {base}"),
        }
    }
}

/// "12.3 MB" (or bytes for small files).
pub fn human_bytes(bytes: u64) -> String {
    if bytes < 10_000 {
        format!("{bytes} bytes")
    } else {
        format!("{:.1} MB", bytes as f64 / 1e6)
    }
}

/// Everything a link can carry. `None` fields are not in the link and leave the app as it is.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ViewState {
    pub source: Option<ViewSource>,
    pub mode: Option<DisplayMode>,
    /// The preset and the parameters the displayed features were computed with.
    pub params: Option<FeatureParams>,
    pub display: Option<FeatureDisplay>,
    /// The MIP's camera: rotation, zoom and pan (the orbit centre), and its field of view.
    pub camera: Option<Camera>,
    /// The MIP's slab thickness in mm; `Some(None)`: no slab.
    pub slab_mm: Option<Option<f64>>,
    /// The shared crosshair, LPS mm.
    pub crosshair_mm: Option<[f64; 3]>,
    /// The MIP's grey window (lo, hi).
    pub mip_window: Option<(f32, f32)>,
    pub projection: Option<Projection>,
    /// The MIP's grey on or off.
    pub grey: Option<bool>,
    /// The slice panes' window.
    pub window: Option<Window>,
    pub layout: Option<Layout>,
    /// The measurements on the slices (rulers and ellipses, points in LPS mm).
    pub measurements: Option<Vec<Measurement>>,
    /// Which series of the source's files is shown, when they hold several (a folder or an
    /// archive): its SeriesInstanceUID, with `:k` for stack k of a series split in several
    /// (`series_list::entry_key`). A DICOMweb source names its series itself.
    pub choice: Option<String>,
    /// The PET fused over the CT: its URLs when it came by link (`pet=`, repeated; a PET that
    /// came with the CT's own files needs none), its window, opacity and whether it is shown.
    pub pet: Option<PetView>,
    /// The findings listed, with the reader's marks (points in LPS mm).
    pub findings: Option<Vec<FindingMark>>,
}

/// The PET of a PET/CT link.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PetView {
    pub urls: Vec<String>,
    pub window: Option<(f32, f32)>,
    pub opacity: Option<f32>,
    pub visible: Option<bool>,
    /// The slice panes show the PET alone (inverted grey) instead of fused over the CT.
    pub alone: Option<bool>,
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // a failed unwrap is a failed test
mod tests;
