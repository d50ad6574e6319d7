//! Writing a view: its fields in link order, as a URL fragment and as JSON.

use super::*;

/// One field's value, written the same way into the fragment and the JSON.
#[derive(Clone, Debug, PartialEq)]
pub(super) enum Value {
    Text(String),
    /// Repeated in the fragment (`url=a&url=b`), an array in JSON.
    Texts(Vec<String>),
    /// A number already in its shortest exact decimal form.
    Num(String),
    Nums(Vec<String>),
    Bool(bool),
    Bools(Vec<bool>),
}

pub(super) fn num64(x: f64) -> String {
    // Rust prints the shortest decimal that reads back to the same f64 (JSON-valid for finite
    // values; the callers never pass others).
    format!("{}", if x.is_finite() { x } else { 0.0 })
}

pub(super) fn num32(x: f32) -> String {
    format!("{}", if x.is_finite() { x } else { 0.0 })
}

pub(super) fn map_name(m: FeatureMap) -> &'static str {
    match m {
        FeatureMap::Simple => "eq1",
        FeatureMap::Li => "li",
    }
}

pub(super) fn projection_name(p: Projection) -> &'static str {
    match p {
        Projection::Mip => "mip",
        Projection::MinIp => "minip",
    }
}

impl ViewState {
    /// The fields in link order.
    pub(super) fn fields(&self) -> Vec<(&'static str, Value)> {
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
}
