//! The app's state as a plain object for automation: on the web it is published as
//! `window.shapecastStatus` (tests and anyone's scripts read it instead of guessing from pixels).

/// What the app is doing.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Phase {
    #[default]
    Starting,
    Loading,
    Computing,
    Ready,
    Error,
}

impl Phase {
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Starting => "starting",
            Self::Loading => "loading",
            Self::Computing => "computing",
            Self::Ready => "ready",
            Self::Error => "error",
        }
    }
}

#[derive(Clone, Debug, Default, PartialEq)]
pub struct AdapterStatus {
    pub name: String,
    pub backend: String,
}

#[derive(Clone, Debug, Default, PartialEq)]
pub struct VolumeStatus {
    pub dims: [usize; 3],
    pub spacing_mm: [f64; 3],
    /// LPS position of voxel (0, 0, 0), mm.
    pub origin_mm: [f64; 3],
    /// Direction cosines, column by column (column `c`: the LPS direction of voxel axis `c`).
    pub direction: [f64; 9],
    pub source: String,
    /// "CT", "MR", "phantom" or "unknown".
    pub modality: String,
}

/// The features of the displayed method.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FeatureStatus {
    /// "intensity", "hessian", "rst", "li", "frangi" or "gst".
    pub method: String,
    /// The preset of the parameters ("vessels", ...).
    pub preset: String,
    /// "none" (not computed), "running", "done", "cancelled" or "failed".
    pub state: String,
    /// 0..1 of the running computation (1 when done).
    pub fraction: f32,
    /// How many methods are computed and kept on the GPU.
    pub cached: usize,
    /// The displayed features' level: 0 full resolution, L kept max-pooled by 2^L per axis
    /// within the GPU budget.
    pub level: u32,
    /// The GPU budget of the volume textures, MiB.
    pub gpu_budget_mib: u64,
}

/// The shared crosshair (the MIP's slab centre).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CrosshairStatus {
    pub voxel: [usize; 3],
    /// Position in patient space, LPS, mm.
    pub lps_mm: [f64; 3],
}

/// One row of the series list (the files given hold several DICOM series). No patient data.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SeriesStatus {
    /// "CT", "MR", ... as written (empty when missing).
    pub modality: String,
    /// SeriesDescription (empty when missing).
    pub description: String,
    /// SeriesNumber.
    pub number: Option<i64>,
    /// Images (frames) in the series (or in this orientation of it).
    pub images: usize,
    pub rows: u32,
    pub cols: u32,
    /// SliceThickness, else SpacingBetweenSlices.
    pub thickness_mm: Option<f64>,
    /// "axial", "coronal", "sagittal", "oblique" or "unknown".
    pub orientation: String,
    /// The series shown.
    pub chosen: bool,
    /// Being loaded.
    pub loading: bool,
}

/// The PET fused over the CT (`window.shapecastStatus.pet`).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PetStatus {
    pub dims: [usize; 3],
    pub spacing_mm: [f64; 3],
    /// "SUV", or the PET's own unit when its SUV factor is not known.
    pub unit: String,
    /// SUVbw per unit of the rescaled stored value, when known.
    pub suv_factor: Option<f64>,
    /// The PET's value (SUV) at the crosshair, `None` outside the PET.
    pub at_crosshair: Option<f32>,
    pub window: (f32, f32),
    pub opacity: f32,
    pub visible: bool,
}

/// The findings of the displayed blobness (`window.shapecastStatus.findings`).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FindingsStatus {
    /// "not asked" (no list until the reader asks: the panel's "List findings", N, a link's
    /// marks), "none", "reading" (the features being read back), "linked" (a link's list,
    /// waiting for the features) or "done".
    pub state: String,
    /// Findings made (the list shows the first 30 until "more").
    pub total: usize,
    /// The row the crosshair was last sent to.
    pub current: Option<usize>,
    pub listed: Vec<FindingStatus>,
    /// With a PET fused: its hot spots (strongest SUVpeak first) and the SUV they were cut at.
    pub hot_spots: Vec<HotSpotStatus>,
    pub pet_threshold: Option<f64>,
}

/// One PET hot spot with its CT shape.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct HotSpotStatus {
    pub lps_mm: [f64; 3],
    pub suv_peak: f64,
    /// "round on CT" (true), "not round" (false), outside the CT (`None`).
    pub ct_round: Option<bool>,
}

/// One listed finding.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FindingStatus {
    pub lps_mm: [f64; 3],
    /// The peak voxel and the score, once the list is made (a link's rows have neither).
    pub voxel: Option<[usize; 3]>,
    pub score: Option<f64>,
    /// "open", "confirmed" or "dismissed".
    pub mark: String,
}

/// Everything `window.shapecastStatus` holds.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct AppStatus {
    pub phase: Phase,
    pub adapter: Option<AdapterStatus>,
    pub volume: Option<VolumeStatus>,
    /// 0..1 of the current loading or computing step.
    pub progress: f32,
    /// The last error, for the user, or `None`.
    pub error: Option<String>,
    /// Frames drawn since start.
    pub frames: u64,
    /// What is being loaded or computed now, for the user ("decoding x.nii.gz").
    pub task: Option<String>,
    pub features: Option<FeatureStatus>,
    pub crosshair: Option<CrosshairStatus>,
    /// "mip+slices", "grid", "mip", "axial", "coronal" or "sagittal".
    pub layout: String,
    /// A link to the current view (`app::view_link`): the page's address and the view as its
    /// fragment.
    pub link: String,
    /// The same view as a JSON object's text (published as the object `view`).
    pub view_json: String,
    /// Something the user is asked to do (a link's file to drop), or `None`.
    pub notice: Option<String>,
    /// Where some controls were drawn last frame, `[x, y, width, height]` in CSS pixels, by
    /// name ("mode:li", "gain:0", "copy-link", "cancel-download", "pane:mip", "pane:axial",
    /// "series:0"...).
    pub controls: Vec<(String, [f32; 4])>,
    /// The series list (empty unless the files given hold several series); row `i` is the
    /// control "series:i".
    pub series: Vec<SeriesStatus>,
    /// The PET over the CT, once loaded; `pet_loading` while it is read.
    pub pet: Option<PetStatus>,
    pub pet_loading: bool,
    /// The MIP's picture: "none" (nothing drawn yet), "coarse" (a reduced frame, the view
    /// moving), "refining" (the full frame being drawn in bands over a coarse one) or "done"
    /// (the full-resolution frame of the current view is drawn): automation compares finished
    /// pictures instead of sleeping.
    pub mip: String,
    /// The same for the PET's MIP ("none" without a PET).
    pub pet_mip: String,
    pub findings: FindingsStatus,
    /// "Store to PACS" is rendering or sending.
    pub storing: bool,
    /// SeriesInstanceUIDs stored into the archive since the app started, oldest first.
    pub stored: Vec<String>,
}

impl AppStatus {
    /// Makes the status visible outside the app (wasm: `window.shapecastStatus`; native: nothing,
    /// the CLI and tests read the struct directly).
    pub fn publish(&self) {
        #[cfg(target_arch = "wasm32")]
        web::publish(self);
    }
}

#[cfg(target_arch = "wasm32")]
mod web {
    use super::AppStatus;
    use js_sys::{Array, Object, Reflect};
    use wasm_bindgen::JsValue;

    fn set(obj: &Object, key: &str, value: impl Into<JsValue>) {
        // Reflect::set only fails on frozen objects or proxies, which ours are not.
        let _ = Reflect::set(obj, &JsValue::from_str(key), &value.into());
    }

    fn array_f64(values: impl IntoIterator<Item = f64>) -> Array {
        values.into_iter().map(JsValue::from_f64).collect()
    }

    /// `null` for `None`, else a new object that `fill` fills from the value.
    fn object<T>(value: Option<&T>, fill: impl FnOnce(&Object, &T)) -> JsValue {
        match value {
            Some(v) => {
                let o = Object::new();
                fill(&o, v);
                o.into()
            }
            None => JsValue::NULL,
        }
    }

    /// `null` for `None`, else the string.
    fn string(value: Option<&String>) -> JsValue {
        value.map_or(JsValue::NULL, |s| JsValue::from_str(s))
    }

    pub fn publish(status: &AppStatus) {
        let Some(window) = web_sys::window() else {
            return;
        };
        let obj = Object::new();
        set(&obj, "phase", status.phase.as_str());
        let adapter = object(status.adapter.as_ref(), |o, a| {
            set(o, "name", a.name.as_str());
            set(o, "backend", a.backend.as_str());
        });
        set(&obj, "adapter", adapter);
        let volume = object(status.volume.as_ref(), |o, v| {
            set(o, "dims", array_f64(v.dims.iter().map(|&d| d as f64)));
            set(o, "spacing_mm", array_f64(v.spacing_mm));
            set(o, "origin_mm", array_f64(v.origin_mm));
            set(o, "direction", array_f64(v.direction));
            set(o, "source", v.source.as_str());
            set(o, "modality", v.modality.as_str());
        });
        set(&obj, "volume", volume);
        set(&obj, "progress", f64::from(status.progress));
        set(&obj, "error", string(status.error.as_ref()));
        set(&obj, "frames", status.frames as f64);
        set(&obj, "task", string(status.task.as_ref()));
        let features = object(status.features.as_ref(), |o, f| {
            set(o, "method", f.method.as_str());
            set(o, "preset", f.preset.as_str());
            set(o, "state", f.state.as_str());
            set(o, "fraction", f64::from(f.fraction));
            set(o, "cached", f.cached as f64);
            set(o, "level", f64::from(f.level));
            set(o, "gpuBudgetMib", f.gpu_budget_mib as f64);
        });
        set(&obj, "features", features);
        let crosshair = object(status.crosshair.as_ref(), |o, c| {
            set(o, "voxel", array_f64(c.voxel.iter().map(|&d| d as f64)));
            set(o, "lps_mm", array_f64(c.lps_mm));
        });
        set(&obj, "crosshair", crosshair);
        set(&obj, "layout", status.layout.as_str());
        set(&obj, "link", status.link.as_str());
        let view = js_sys::JSON::parse(&status.view_json).unwrap_or(JsValue::NULL);
        set(&obj, "view", view);
        set(&obj, "notice", string(status.notice.as_ref()));
        let controls = Object::new();
        for (name, r) in &status.controls {
            set(&controls, name, array_f64(r.iter().map(|&x| f64::from(x))));
        }
        set(&obj, "controls", controls);
        let series: Array = status
            .series
            .iter()
            .map(|r| {
                let o = Object::new();
                set(&o, "modality", r.modality.as_str());
                set(&o, "description", r.description.as_str());
                set(
                    &o,
                    "number",
                    r.number
                        .map_or(JsValue::NULL, |n| JsValue::from_f64(n as f64)),
                );
                set(&o, "images", r.images as f64);
                set(&o, "rows", f64::from(r.rows));
                set(&o, "cols", f64::from(r.cols));
                set(
                    &o,
                    "thickness_mm",
                    r.thickness_mm.map_or(JsValue::NULL, JsValue::from_f64),
                );
                set(&o, "orientation", r.orientation.as_str());
                set(&o, "chosen", r.chosen);
                set(&o, "loading", r.loading);
                JsValue::from(o)
            })
            .collect();
        set(&obj, "series", series);
        let pet = object(status.pet.as_ref(), |o, p| {
            set(o, "dims", array_f64(p.dims.iter().map(|&d| d as f64)));
            set(o, "spacing_mm", array_f64(p.spacing_mm));
            set(o, "unit", p.unit.as_str());
            set(
                o,
                "suv_factor",
                p.suv_factor.map_or(JsValue::NULL, JsValue::from_f64),
            );
            set(
                o,
                "at_crosshair",
                p.at_crosshair
                    .map_or(JsValue::NULL, |v| JsValue::from_f64(f64::from(v))),
            );
            set(
                o,
                "window",
                array_f64([f64::from(p.window.0), f64::from(p.window.1)]),
            );
            set(o, "opacity", f64::from(p.opacity));
            set(o, "visible", p.visible);
        });
        set(&obj, "pet", pet);
        set(&obj, "pet_loading", status.pet_loading);
        set(&obj, "mip", status.mip.as_str());
        set(&obj, "pet_mip", status.pet_mip.as_str());
        set(&obj, "storing", status.storing);
        let stored: Array = status.stored.iter().map(|s| JsValue::from_str(s)).collect();
        set(&obj, "stored", stored);
        let f = &status.findings;
        let findings = Object::new();
        set(&findings, "state", f.state.as_str());
        set(&findings, "total", f.total as f64);
        set(
            &findings,
            "current",
            f.current
                .map_or(JsValue::NULL, |c| JsValue::from_f64(c as f64)),
        );
        let listed: Array = f
            .listed
            .iter()
            .map(|r| {
                let o = Object::new();
                set(&o, "lps_mm", array_f64(r.lps_mm));
                set(
                    &o,
                    "voxel",
                    r.voxel.map_or(JsValue::NULL, |v| {
                        array_f64(v.iter().map(|&d| d as f64)).into()
                    }),
                );
                set(
                    &o,
                    "score",
                    r.score.map_or(JsValue::NULL, JsValue::from_f64),
                );
                set(&o, "mark", r.mark.as_str());
                JsValue::from(o)
            })
            .collect();
        set(&findings, "listed", listed);
        let spots: Array = f
            .hot_spots
            .iter()
            .map(|h| {
                let o = Object::new();
                set(&o, "lps_mm", array_f64(h.lps_mm));
                set(&o, "suv_peak", h.suv_peak);
                set(
                    &o,
                    "ct_round",
                    h.ct_round.map_or(JsValue::NULL, JsValue::from_bool),
                );
                JsValue::from(o)
            })
            .collect();
        set(&findings, "hot_spots", spots);
        set(
            &findings,
            "pet_threshold",
            f.pet_threshold.map_or(JsValue::NULL, JsValue::from_f64),
        );
        set(&obj, "findings", findings);
        let _ = Reflect::set(&window, &JsValue::from_str("shapecastStatus"), &obj);
    }
}
