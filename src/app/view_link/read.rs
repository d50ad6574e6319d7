//! Reading a view back from a fragment: each field checked, a message naming each that cannot
//! be read while the rest applies.

use super::*;

impl ViewState {
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
pub(super) struct Fields<'a> {
    params: &'a [(String, String)],
    problems: Vec<String>,
}

impl<'a> Fields<'a> {
    pub(super) fn get(&self, key: &str) -> Option<&'a str> {
        self.params
            .iter()
            .rev()
            .find(|(k, _)| k == key)
            .map(|(_, v)| v.as_str())
    }

    /// The field `key` as `parse` reads it; a field that is there but `parse` refuses is named
    /// in the problems with what was `expected`.
    pub(super) fn read<T>(
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

pub(super) fn bad(problems: &mut Vec<String>, key: &str, value: &str, expected: &str) {
    problems.push(format!(
        "link field {key}={value:?}: expected {expected}; ignored"
    ));
}

/// `n` comma-separated finite numbers (f64 or f32).
pub(super) fn numbers<T: std::str::FromStr + Copy + Into<f64>>(
    s: &str,
    n: usize,
) -> Option<Vec<T>> {
    let v: Vec<T> = s
        .split(',')
        .map(|x| x.trim().parse::<T>().ok().filter(|&x| x.into().is_finite()))
        .collect::<Option<_>>()?;
    (v.len() == n).then_some(v)
}

pub(super) fn number_in(s: &str, range: std::ops::RangeInclusive<f64>) -> Option<f64> {
    numbers(s, 1).map(|v| v[0]).filter(|x| range.contains(x))
}

pub(super) fn bools(s: &str, n: usize) -> Option<Vec<bool>> {
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
