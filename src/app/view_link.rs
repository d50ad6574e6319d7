//! The view as a link: everything needed to see again exactly what a user sees (the source, the
//! display mode, the preset and edited parameters, channels and gains, camera, slab, crosshair,
//! windows, layout), written into a URL fragment (`#v=1&url=...&mode=li&...`, which browsers
//! never send to a server) and as the same fields in JSON (`window.shapecastStatus.view`).
//!
//! Pure code, no browser: the app captures and applies a [`ViewState`] (`share.rs`), the page
//! reads the fragment and the query (`web_files.rs`). A link carries a version (`v`); unknown
//! fields are ignored, and a field that cannot be read is named in a message while the rest
//! applies. Numbers are written in their shortest exact form, so a view read back from its link
//! is bit for bit the view that wrote it.

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

/// One field's value, written the same way into the fragment and the JSON.
#[derive(Clone, Debug, PartialEq)]
enum Value {
    Text(String),
    /// Repeated in the fragment (`url=a&url=b`), an array in JSON.
    Texts(Vec<String>),
    /// A number already in its shortest exact decimal form.
    Num(String),
    Nums(Vec<String>),
    Bool(bool),
    Bools(Vec<bool>),
}

fn num64(x: f64) -> String {
    // Rust prints the shortest decimal that reads back to the same f64 (JSON-valid for finite
    // values; the callers never pass others).
    format!("{}", if x.is_finite() { x } else { 0.0 })
}

fn num32(x: f32) -> String {
    format!("{}", if x.is_finite() { x } else { 0.0 })
}

fn map_name(m: FeatureMap) -> &'static str {
    match m {
        FeatureMap::Simple => "eq1",
        FeatureMap::Li => "li",
    }
}

fn projection_name(p: Projection) -> &'static str {
    match p {
        Projection::Mip => "mip",
        Projection::MinIp => "minip",
    }
}

impl ViewState {
    /// The fields in link order.
    fn fields(&self) -> Vec<(&'static str, Value)> {
        let mut f = vec![("v", Value::Num(VERSION.to_string()))];
        match &self.source {
            Some(ViewSource::Demo) => f.push(("demo", Value::Bool(true))),
            Some(ViewSource::Phantom(name)) => f.push(("phantom", Value::Text(name.clone()))),
            Some(ViewSource::Urls(urls)) => f.push(("url", Value::Texts(urls.clone()))),
            Some(ViewSource::Dropped { name, bytes }) => {
                f.push(("file", Value::Text(name.clone())));
                f.push(("bytes", Value::Num(bytes.to_string())));
            }
            Some(ViewSource::DicomWeb {
                base,
                study,
                series,
            }) => {
                f.push(("dicomweb", Value::Text(base.clone())));
                f.push(("study", Value::Text(study.clone())));
                f.push(("series", Value::Text(series.clone())));
            }
            None => {}
        }
        if let Some(c) = &self.choice {
            f.push(("choice", Value::Text(c.clone())));
        }
        if let Some(m) = self.mode {
            f.push(("mode", Value::Text(m.name().to_owned())));
        }
        if let Some(p) = &self.params {
            f.push(("preset", Value::Text(p.preset.name().to_owned())));
            // Only what differs from the preset: short links, and a preset's defaults may
            // improve without old links pinning the old values.
            let d = FeatureParams::from_preset(p.preset);
            if (p.sigma_min_mm, p.sigma_max_mm, p.sigma_count)
                != (d.sigma_min_mm, d.sigma_max_mm, d.sigma_count)
            {
                f.push((
                    "sigma",
                    Value::Nums(vec![
                        num64(p.sigma_min_mm),
                        num64(p.sigma_max_mm),
                        p.sigma_count.to_string(),
                    ]),
                ));
            }
            if p.rays != d.rays {
                f.push(("rays", Value::Num(p.rays.to_string())));
            }
            if p.radius_mm != d.radius_mm {
                f.push(("radius", Value::Num(num64(p.radius_mm))));
            }
            if p.step_mm != d.step_mm {
                f.push(("step", Value::Num(num64(p.step_mm))));
            }
            if p.tf != d.tf {
                f.push((
                    "tf",
                    match p.tf {
                        None => Value::Text("auto".to_owned()),
                        Some(tf) => Value::Nums(vec![num64(tf.d_min), num64(tf.d_max)]),
                    },
                ));
            }
            if p.map != d.map {
                f.push(("map", Value::Text(map_name(p.map).to_owned())));
            }
        }
        if let Some(d) = &self.display {
            f.push(("on", Value::Bools(d.enabled.to_vec())));
            f.push((
                "gain",
                Value::Nums(d.gain.iter().map(|&g| num32(g)).collect()),
            ));
            f.push(("overlay", Value::Bool(d.overlay_on_slices)));
            f.push(("opacity", Value::Num(num32(d.opacity))));
        }
        if let Some(c) = &self.camera {
            let q = c.rotation;
            f.push(("rot", Value::Nums([q.x, q.y, q.z, q.w].map(num64).to_vec())));
            f.push(("zoom", Value::Num(num64(c.zoom))));
            f.push((
                "centre",
                Value::Nums(c.centre_mm.to_array().map(num64).to_vec()),
            ));
            f.push(("fov", Value::Num(num64(c.fov_mm))));
        }
        if let Some(slab) = self.slab_mm {
            f.push((
                "slab",
                match slab {
                    None => Value::Text("off".to_owned()),
                    Some(t) => Value::Num(num64(t)),
                },
            ));
        }
        if let Some(p) = self.crosshair_mm {
            f.push(("cross", Value::Nums(p.map(num64).to_vec())));
        }
        if let Some((lo, hi)) = self.mip_window {
            f.push(("mipwin", Value::Nums(vec![num32(lo), num32(hi)])));
        }
        if let Some(p) = self.projection {
            f.push(("proj", Value::Text(projection_name(p).to_owned())));
        }
        if let Some(g) = self.grey {
            f.push(("grey", Value::Bool(g)));
        }
        if let Some(w) = self.window {
            f.push(("wl", Value::Nums(vec![num32(w.width), num32(w.level)])));
        }
        if let Some(l) = self.layout {
            f.push(("layout", Value::Text(l.name().to_owned())));
        }
        if let Some(m) = &self.measurements {
            f.push((
                "m",
                Value::Texts(m.iter().map(Measurement::to_text).collect()),
            ));
        }
        if let Some(list) = &self.findings {
            f.push((
                "find",
                Value::Texts(list.iter().map(FindingMark::to_text).collect()),
            ));
        }
        if let Some(p) = &self.pet {
            if !p.urls.is_empty() {
                f.push(("pet", Value::Texts(p.urls.clone())));
            }
            if let Some((lo, hi)) = p.window {
                f.push(("petwin", Value::Nums(vec![num32(lo), num32(hi)])));
            }
            if let Some(o) = p.opacity {
                f.push(("petop", Value::Num(num32(o))));
            }
            if let Some(on) = p.visible {
                f.push(("peton", Value::Bool(on)));
            }
            if let Some(alone) = p.alone {
                f.push(("petalone", Value::Bool(alone)));
            }
        }
        f
    }

    /// The URL fragment, without the `#`.
    pub fn fragment(&self) -> String {
        let mut parts = Vec::new();
        for (key, value) in self.fields() {
            match value {
                Value::Text(s) => parts.push(format!("{key}={}", encode(&s))),
                Value::Texts(v) => {
                    parts.extend(v.iter().map(|s| format!("{key}={}", encode(s))));
                }
                Value::Num(n) => parts.push(format!("{key}={n}")),
                Value::Nums(v) => parts.push(format!("{key}={}", v.join(","))),
                Value::Bool(b) => parts.push(format!("{key}={}", u8::from(b))),
                Value::Bools(v) => parts.push(format!(
                    "{key}={}",
                    v.iter()
                        .map(|&b| if b { "1" } else { "0" })
                        .collect::<Vec<_>>()
                        .join(",")
                )),
            }
        }
        parts.join("&")
    }

    /// The same fields as a JSON object.
    pub fn json(&self) -> String {
        // Each value written by serde_json (numbers as the link writes them: their shortest
        // exact form), the object assembled in the link's field order.
        let number = |n: &str| -> serde_json::Value {
            n.parse::<serde_json::Number>()
                .map_or(serde_json::Value::Null, serde_json::Value::Number)
        };
        let fields: Vec<String> = self
            .fields()
            .into_iter()
            .map(|(key, value)| {
                let value = match value {
                    Value::Text(s) => serde_json::Value::String(s),
                    Value::Texts(v) => v.into_iter().map(serde_json::Value::String).collect(),
                    Value::Num(n) => number(&n),
                    Value::Nums(v) => v.iter().map(|n| number(n)).collect(),
                    Value::Bool(b) => serde_json::Value::Bool(b),
                    Value::Bools(v) => v.into_iter().map(serde_json::Value::Bool).collect(),
                };
                format!("{}:{value}", serde_json::Value::from(key))
            })
            .collect();
        format!("{{{}}}", fields.join(","))
    }

    /// Reads a fragment (with or without its `#`). Returns what could be read and a message per
    /// field that could not (naming it); unknown fields are ignored.
    pub fn from_fragment(fragment: &str) -> (Self, Vec<String>) {
        let params = parse_params(fragment.trim_start_matches('#'));
        let mut v = Self::default();
        let mut f = Fields {
            params: &params,
            problems: Vec::new(),
        };
        if params.is_empty() {
            return (v, f.problems);
        }

        match f.get("v") {
            None => {}
            Some(s) => match s.parse::<u32>() {
                Ok(VERSION) => {}
                Ok(n) if n > VERSION => f.problems.push(format!(
                    "this link was made by a newer Shapecast (link version {n}, this page reads {VERSION}): what this version knows is applied"
                )),
                Ok(_) => {}
                Err(_) => bad(&mut f.problems, "v", s, "a version number"),
            },
        }

        // The source.
        let urls: Vec<String> = params
            .iter()
            .filter(|(k, _)| k == "url")
            .map(|(_, u)| u.trim().to_owned())
            .filter(|u| !u.is_empty())
            .collect();
        if !urls.is_empty() {
            v.source = Some(ViewSource::Urls(urls));
        } else if let Some(base) = f.get("dicomweb") {
            match (f.get("study"), f.get("series")) {
                (Some(study), Some(series)) if !base.trim().is_empty() => {
                    v.source = Some(ViewSource::DicomWeb {
                        base: base.trim().to_owned(),
                        study: study.trim().to_owned(),
                        series: series.trim().to_owned(),
                    });
                }
                _ => bad(
                    &mut f.problems,
                    "dicomweb",
                    base,
                    "an archive's DICOMweb root with study=UID and series=UID beside it",
                ),
            }
        } else if let Some(name) = f.get("file") {
            match f.get("bytes").map(|b| b.parse::<u64>()) {
                Some(Ok(bytes)) if !name.is_empty() => {
                    v.source = Some(ViewSource::Dropped {
                        name: name.to_owned(),
                        bytes,
                    });
                }
                Some(Ok(_)) => bad(&mut f.problems, "file", name, "a file name"),
                Some(Err(_)) => {
                    let bytes = f.get("bytes").unwrap_or("");
                    bad(&mut f.problems, "bytes", bytes, "a size in bytes");
                }
                None => bad(
                    &mut f.problems,
                    "file",
                    name,
                    "a size in bytes beside it (bytes=...)",
                ),
            }
        } else if let Some(name) = f.get("phantom") {
            v.source = Some(ViewSource::Phantom(name.to_owned()));
        } else if f.get("demo").is_some() {
            v.source = f.read("demo", "1", |d| {
                matches!(d, "1" | "true" | "ct").then_some(ViewSource::Demo)
            });
        }

        v.choice = f
            .get("choice")
            .map(str::trim)
            .filter(|c| !c.is_empty())
            .map(str::to_owned);

        v.mode = f.read(
            "mode",
            "intensity, hessian, rst, li, frangi or gst",
            DisplayMode::from_name,
        );

        // Parameters: the preset's, then each edited one.
        let preset = f.read(
            "preset",
            "lymph-nodes, lung-nodules, airways or vessels",
            Preset::from_name,
        );
        let edits = ["sigma", "rays", "radius", "step", "tf", "map"];
        if preset.is_some() || edits.iter().any(|k| f.get(k).is_some()) {
            let mut p = FeatureParams::from_preset(preset.unwrap_or_default());
            let sigma = f.read("sigma", "min,max,count in mm (0.3-30, count 1-12)", |s| {
                numbers::<f64>(s, 3).filter(|n| {
                    (0.3..=30.0).contains(&n[0])
                        && (0.3..=30.0).contains(&n[1])
                        && n[1] >= n[0]
                        && n[2].fract() == 0.0
                        && (1.0..=12.0).contains(&n[2])
                })
            });
            if let Some(n) = sigma {
                p.sigma_min_mm = n[0];
                p.sigma_max_mm = n[1];
                p.sigma_count = n[2] as usize;
            }
            if let Some(n) = f.read("rays", "26, 42, 98, 218 or 386", |s| {
                s.parse::<usize>().ok().filter(|n| RAY_COUNTS.contains(n))
            }) {
                p.rays = n;
            }
            if let Some(r) = f.read("radius", "a ray length of 1-100 mm", |s| {
                number_in(s, 1.0..=100.0)
            }) {
                p.radius_mm = r;
            }
            if let Some(r) = f.read("step", "a step of 0.05-5 mm", |s| number_in(s, 0.05..=5.0)) {
                p.step_mm = r;
            }
            let tf = f.read(
                "tf",
                "auto, or d_min,d_max with d_max > d_min >= 0",
                |s| match s {
                    "auto" => Some(None),
                    _ => numbers(s, 2)
                        .filter(|n| n[0] >= 0.0 && n[1] > n[0])
                        .map(|n| {
                            Some(TransferFunction {
                                d_min: n[0],
                                d_max: n[1],
                            })
                        }),
                },
            );
            if let Some(tf) = tf {
                p.tf = tf;
            }
            if let Some(m) = f.read("map", "li or eq1", |s| match s {
                "li" => Some(FeatureMap::Li),
                "eq1" => Some(FeatureMap::Simple),
                _ => None,
            }) {
                p.map = m;
            }
            v.params = Some(p);
        }

        // Channels and gains.
        let display_keys = ["on", "gain", "overlay", "opacity"];
        if display_keys.iter().any(|k| f.get(k).is_some()) {
            let mut d = FeatureDisplay::default();
            if let Some(b) = f.read("on", "three of 0 or 1 (vessels, airways, blobs)", |s| {
                bools(s, 3)
            }) {
                d.enabled = [b[0], b[1], b[2]];
            }
            if let Some(g) = f.read("gain", "three gains of 0.01-100", |s| {
                numbers::<f32>(s, 3).filter(|g| g.iter().all(|&x| (0.01..=100.0).contains(&x)))
            }) {
                d.gain = [g[0], g[1], g[2]];
            }
            if let Some(b) = f.read("overlay", "0 or 1", |s| bools(s, 1)) {
                d.overlay_on_slices = b[0];
            }
            if let Some(o) = f.read("opacity", "an opacity of 0-1", |s| {
                numbers::<f32>(s, 1).filter(|o| (0.0..=1.0).contains(&o[0]))
            }) {
                d.opacity = o[0];
            }
            v.display = Some(d);
        }

        // The camera: all four or none (a partial camera is not the view that was shared).
        let camera_keys = ["rot", "zoom", "centre", "fov"];
        if camera_keys.iter().any(|k| f.get(k).is_some()) {
            let text = |k: &str| f.get(k).unwrap_or("");
            let rotation = numbers(text("rot"), 4).and_then(|q| {
                let q = DQuat::from_xyzw(q[0], q[1], q[2], q[3]);
                let len = q.length();
                if len.is_nan() || len <= 1e-6 {
                    None
                } else if (len - 1.0).abs() < 1e-9 {
                    // Kept as written: the shared view bit for bit.
                    Some(q)
                } else {
                    Some(q / len)
                }
            });
            let zoom = number_in(text("zoom"), MIN_ZOOM..=MAX_ZOOM);
            let centre = numbers(text("centre"), 3);
            let fov = number_in(text("fov"), 1e-3..=1e7);
            let (rot_text, zoom_text) = (text("rot"), text("zoom"));
            let (centre_text, fov_text) = (text("centre"), text("fov"));
            if rotation.is_none() {
                let expected = "a rotation quaternion x,y,z,w";
                bad(&mut f.problems, "rot", rot_text, expected);
            }
            if zoom.is_none() {
                bad(&mut f.problems, "zoom", zoom_text, "a zoom of 0.05-200");
            }
            if centre.is_none() {
                bad(&mut f.problems, "centre", centre_text, "x,y,z in mm");
            }
            if fov.is_none() {
                bad(&mut f.problems, "fov", fov_text, "a field of view in mm");
            }
            if let (Some(rotation), Some(zoom), Some(c), Some(fov)) = (rotation, zoom, centre, fov)
            {
                v.camera = Some(Camera {
                    centre_mm: DVec3::new(c[0], c[1], c[2]),
                    rotation,
                    fov_mm: fov,
                    zoom,
                });
            }
        }

        v.slab_mm = f.read("slab", "off, or a thickness of 0.5-2000 mm", |s| match s {
            "off" => Some(None),
            _ => number_in(s, 0.5..=2000.0).map(Some),
        });
        v.crosshair_mm = f.read("cross", "x,y,z in mm (LPS)", |s| {
            numbers(s, 3).map(|p| [p[0], p[1], p[2]])
        });
        v.mip_window = f.read("mipwin", "lo,hi with hi > lo", |s| {
            numbers::<f32>(s, 2)
                .filter(|w| w[1] > w[0])
                .map(|w| (w[0], w[1]))
        });
        v.projection = f.read("proj", "mip or minip", |s| match s {
            "mip" => Some(Projection::Mip),
            "minip" => Some(Projection::MinIp),
            _ => None,
        });
        v.grey = f.read("grey", "0 or 1", |s| bools(s, 1).map(|b| b[0]));
        v.window = f.read("wl", "width,level with a width of 1-1000000", |s| {
            numbers::<f32>(s, 2)
                .filter(|w| (1.0..=1.0e6).contains(&w[0]))
                .map(|w| Window::new(w[0], w[1]))
        });
        v.layout = f.read(
            "layout",
            "mip+slices, grid, mip, axial, coronal or sagittal",
            Layout::from_name,
        );
        // Measurements: one `m` field each; a bad one is named and the others kept.
        let mut measurements = Vec::new();
        for (_, text) in params.iter().filter(|(k, _)| k == "m") {
            match Measurement::from_text(text) {
                Some(m) => measurements.push(m),
                None => bad(
                    &mut f.problems,
                    "m",
                    text,
                    "ruler|ellipse,axial|coronal|sagittal and two points x,y,z in mm",
                ),
            }
        }
        if !measurements.is_empty() {
            v.measurements = Some(measurements);
        }
        // Findings: one `find` field each, `x,y,z,mark`; a bad one is named, the others kept.
        let mut findings = Vec::new();
        for (_, text) in params.iter().filter(|(k, _)| k == "find") {
            match FindingMark::from_text(text) {
                Some(m) => findings.push(m),
                None => bad(
                    &mut f.problems,
                    "find",
                    text,
                    "x,y,z in mm and open, confirmed or dismissed",
                ),
            }
        }
        if !findings.is_empty() {
            v.findings = Some(findings);
        }
        let pet = PetView {
            urls: params
                .iter()
                .filter(|(k, _)| k == "pet")
                .map(|(_, u)| u.trim().to_owned())
                .filter(|u| !u.is_empty())
                .collect(),
            window: f.read("petwin", "lo,hi with hi > lo", |s| {
                numbers::<f32>(s, 2)
                    .filter(|w| w[1] > w[0])
                    .map(|w| (w[0], w[1]))
            }),
            opacity: f.read("petop", "an opacity of 0-1", |s| {
                numbers::<f32>(s, 1)
                    .map(|o| o[0])
                    .filter(|o| (0.0..=1.0).contains(o))
            }),
            visible: f.read("peton", "0 or 1", |s| bools(s, 1).map(|b| b[0])),
            alone: f.read("petalone", "0 or 1", |s| bools(s, 1).map(|b| b[0])),
        };
        if pet != PetView::default() {
            v.pet = Some(pet);
        }
        (v, f.problems)
    }
}

/// The fields of a fragment (the last of a repeated key counts) and a message per field that
/// could not be read.
struct Fields<'a> {
    params: &'a [(String, String)],
    problems: Vec<String>,
}

impl<'a> Fields<'a> {
    fn get(&self, key: &str) -> Option<&'a str> {
        self.params
            .iter()
            .rev()
            .find(|(k, _)| k == key)
            .map(|(_, v)| v.as_str())
    }

    /// The field `key` as `parse` reads it; a field that is there but `parse` refuses is named
    /// in the problems with what was `expected`.
    fn read<T>(
        &mut self,
        key: &str,
        expected: &str,
        parse: impl FnOnce(&str) -> Option<T>,
    ) -> Option<T> {
        let s = self.get(key)?;
        let value = parse(s);
        if value.is_none() {
            bad(&mut self.problems, key, s, expected);
        }
        value
    }
}

fn bad(problems: &mut Vec<String>, key: &str, value: &str, expected: &str) {
    problems.push(format!(
        "link field {key}={value:?}: expected {expected}; ignored"
    ));
}

/// `n` comma-separated finite numbers (f64 or f32).
fn numbers<T: std::str::FromStr + Copy + Into<f64>>(s: &str, n: usize) -> Option<Vec<T>> {
    let v: Vec<T> = s
        .split(',')
        .map(|x| x.trim().parse::<T>().ok().filter(|&x| x.into().is_finite()))
        .collect::<Option<_>>()?;
    (v.len() == n).then_some(v)
}

fn number_in(s: &str, range: std::ops::RangeInclusive<f64>) -> Option<f64> {
    numbers(s, 1).map(|v| v[0]).filter(|x| range.contains(x))
}

fn bools(s: &str, n: usize) -> Option<Vec<bool>> {
    let v: Vec<bool> = s
        .split(',')
        .map(|x| match x.trim() {
            "1" | "true" => Some(true),
            "0" | "false" => Some(false),
            _ => None,
        })
        .collect::<Option<_>>()?;
    (v.len() == n).then_some(v)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // a failed unwrap is a failed test
mod tests {
    use super::*;
    use crate::app::measure::MeasureKind;
    use crate::cpu::pipeline::Method;

    fn full() -> ViewState {
        let mut params = FeatureParams::from_preset(Preset::Airways);
        params.sigma_count = 3;
        params.rays = 98;
        params.tf = Some(TransferFunction {
            d_min: 12.5,
            d_max: 40.0,
        });
        params.map = FeatureMap::Simple;
        ViewState {
            source: Some(ViewSource::Urls(vec![
                "https://example.org/a b/x.nhdr?token=1&y=2".to_owned(),
                "https://example.org/a b/x.raw.gz".to_owned(),
            ])),
            mode: Some(DisplayMode::Features(Method::Li)),
            params: Some(params),
            display: Some(FeatureDisplay {
                enabled: [true, false, true],
                gain: [1.0, 0.1, 2.345_678_9],
                overlay_on_slices: false,
                opacity: 0.3,
            }),
            camera: Some(Camera {
                centre_mm: DVec3::new(-12.25, 0.1 + 0.2, 1e-9),
                rotation: DQuat::from_rotation_y(0.7) * DQuat::from_rotation_x(-0.3),
                fov_mm: 231.123_456_789,
                zoom: 1.7,
            }),
            slab_mm: Some(Some(12.5)),
            crosshair_mm: Some([1.0 / 3.0, -250.0, 7.5]),
            mip_window: Some((-100.0, 900.5)),
            projection: Some(Projection::MinIp),
            grey: Some(false),
            window: Some(Window::new(1500.0, -600.0)),
            layout: Some(Layout::Single(super::super::PaneId::Slice(
                super::super::SliceKind::Coronal,
            ))),
            measurements: Some(vec![
                Measurement {
                    kind: MeasureKind::Ruler,
                    pane: Some(super::super::SliceKind::Axial),
                    a_mm: DVec3::new(-12.25, 1.0 / 3.0, 40.0),
                    b_mm: DVec3::new(3.5, 0.1, 40.0),
                },
                Measurement {
                    kind: MeasureKind::Ellipse,
                    pane: Some(super::super::SliceKind::Sagittal),
                    a_mm: DVec3::new(7.0, -20.0, 1e-3),
                    b_mm: DVec3::new(7.0, -5.5, 18.0),
                },
                // A ruler in 3D (an end picked in the MIP).
                Measurement {
                    kind: MeasureKind::Ruler,
                    pane: None,
                    a_mm: DVec3::new(1.5, -2.0, 30.25),
                    b_mm: DVec3::new(-8.0, 14.125, -3.0),
                },
            ]),
            choice: Some("1.2.840.113619.2.55.3.604688119:1".to_owned()),
            pet: Some(PetView {
                urls: vec!["https://example.org/pet/PT.zip".to_owned()],
                window: Some((0.0, 7.5)),
                opacity: Some(0.35),
                visible: Some(true),
                alone: Some(true),
            }),
            findings: Some(vec![
                FindingMark {
                    lps_mm: [-40.5, 12.0, 101.25],
                    mark: super::super::findings::Mark::Confirmed,
                },
                FindingMark {
                    lps_mm: [1.0 / 3.0, 0.0, -7.0],
                    mark: super::super::findings::Mark::Open,
                },
            ]),
        }
    }

    #[test]
    fn a_view_reads_back_bit_for_bit() {
        let v = full();
        let fragment = v.fragment();
        let (back, problems) = ViewState::from_fragment(&format!("#{fragment}"));
        assert!(problems.is_empty(), "{problems:?}");
        assert_eq!(back, v, "{fragment}");
        assert_eq!(back.fragment(), fragment);
        assert_eq!(back.json(), v.json());
        // Every layout and source kind too.
        for layout in [
            Layout::MipAndSlices,
            Layout::Grid,
            Layout::Single(super::super::PaneId::Mip),
        ] {
            for source in [
                ViewSource::Demo,
                ViewSource::Phantom("fig8-sphere".into()),
                ViewSource::Dropped {
                    name: "ct-head (93 files)".into(),
                    bytes: 1_234_567,
                },
                ViewSource::DicomWeb {
                    base: "/dicom-web".into(),
                    study: "1.2.3".into(),
                    series: "1.2.3.4".into(),
                },
            ] {
                let v = ViewState {
                    layout: Some(layout),
                    source: Some(source),
                    slab_mm: Some(None),
                    ..full()
                };
                let (back, problems) = ViewState::from_fragment(&v.fragment());
                assert!(problems.is_empty(), "{problems:?}");
                assert_eq!(back, v);
            }
        }
    }

    #[test]
    fn the_fragment_is_readable_and_the_json_valid() {
        let v = full();
        let f = v.fragment();
        assert!(
            f.starts_with("v=1&url=https://example.org/a%20b/x.nhdr%3Ftoken%3D1%26y%3D2&url="),
            "{f}"
        );
        assert!(f.contains("&mode=li&preset=airways&sigma="), "{f}");
        assert!(f.contains("&layout=coronal"), "{f}");
        let json: serde_json::Value = serde_json::from_str(&v.json()).unwrap();
        assert_eq!(json["v"], 1);
        assert_eq!(json["url"][1], "https://example.org/a b/x.raw.gz");
        assert_eq!(json["gain"][2].as_f64().unwrap() as f32, 2.345_678_9_f32);
        assert_eq!(json["on"][1], false);
        assert_eq!(json["tf"][0], 12.5);
        assert_eq!(json["layout"], "coronal");
        let mut mip = full();
        mip.layout = Some(Layout::MipAndSlices);
        assert!(mip.fragment().contains("layout=mip%2Bslices"));
    }

    #[test]
    fn preset_defaults_are_left_out() {
        let v = ViewState {
            params: Some(FeatureParams::from_preset(Preset::Vessels)),
            ..Default::default()
        };
        assert_eq!(v.fragment(), "v=1&preset=vessels");
        let (back, _) = ViewState::from_fragment("preset=vessels");
        assert_eq!(
            back.params,
            Some(FeatureParams::from_preset(Preset::Vessels))
        );
    }

    #[test]
    fn bad_fields_are_named_and_the_rest_applies() {
        let (v, problems) = ViewState::from_fragment(
            "#v=1&mode=li&gain=1,x,1&layout=grid&rays=7&future=42&rot=0,0,0,0&zoom=2&centre=1,2,3&fov=100&cross=1,2",
        );
        assert_eq!(v.mode, Some(DisplayMode::Features(Method::Li)));
        assert_eq!(v.layout, Some(Layout::Grid));
        assert_eq!(
            v.display.unwrap().gain,
            [1.0; 3],
            "a bad gain keeps the default"
        );
        assert_eq!(v.params.unwrap().rays, 42);
        assert_eq!(v.camera, None, "a bad rotation drops the whole camera");
        assert_eq!(v.crosshair_mm, None);
        let joined = problems.join("\n");
        for field in ["gain=\"1,x,1\"", "rays=\"7\"", "rot=", "cross="] {
            assert!(joined.contains(field), "{field} not named in {joined}");
        }
        assert!(
            !joined.contains("future"),
            "unknown fields are ignored: {joined}"
        );
        assert_eq!(problems.len(), 4, "{problems:?}");
        // A bad measurement is named; the good ones are kept.
        let (v, problems) = ViewState::from_fragment(
            "m=ruler,axial,1,2,3,4,5,6&m=ruler,axial,1,2&m=ellipse,coronal,0,0,0,1,1,1",
        );
        assert_eq!(v.measurements.map(|m| m.len()), Some(2));
        assert!(
            problems.len() == 1 && problems[0].contains("m=\"ruler,axial,1,2\""),
            "{problems:?}"
        );
        // A newer version is said, and still read.
        let (v, problems) = ViewState::from_fragment("v=9&mode=rst");
        assert_eq!(v.mode, Some(DisplayMode::Features(Method::Rst)));
        assert!(problems[0].contains("newer"), "{problems:?}");
        // Garbage never panics.
        for s in [
            "",
            "#",
            "&&&",
            "=",
            "v",
            "%",
            "%zz&%4",
            "url=",
            "file=x",
            "bytes=9&file=",
        ] {
            let _ = ViewState::from_fragment(s);
        }
    }
}
