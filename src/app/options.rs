//! How the app starts: what it opens on and its options, from the command line, the page's URL
//! or a link (`AppOptions::from_environment`, `AppOptions::apply_link`).

use super::{DisplayMode, PacsTarget, ViewSource, ViewState, features};
use crate::cpu::tf::Preset;

#[cfg(target_arch = "wasm32")]
use super::platform::web::files as web_files;

/// What the app opens on.
#[derive(Clone, Debug, PartialEq)]
pub enum StartWith {
    /// The demo CT (web/demo/): embedded natively, fetched by the page.
    DemoCt,
    /// A phantom by name (`crate::phantom::NAMES`, "fig8-sphere", "demo").
    Phantom(String),
    /// Files and folders on this machine (`shapecast view PATH...`).
    #[cfg(not(target_arch = "wasm32"))]
    Paths(Vec<std::path::PathBuf>),
    /// Files downloaded from these URLs (the page's `?url=`, a link; web only).
    Urls(Vec<String>),
    /// A study in a DICOMweb archive (the page's `?dicomweb=BASE&study=UID[&series=UID]`).
    DicomWeb(PacsTarget),
    /// Nothing: an empty app that asks for files.
    Nothing,
}

/// How the app starts.
#[derive(Clone, Debug, PartialEq)]
pub struct AppOptions {
    pub start: StartWith,
    /// The display mode it opens in.
    pub mode: DisplayMode,
    /// Compute the mode's features as soon as a volume is loaded.
    pub compute_on_load: bool,
    /// The feature preset; `None`: vessels for the demo CT (a CTA), lymph nodes otherwise.
    pub preset: Option<Preset>,
    /// A shared view (a link's fragment): applied when its volume is loaded.
    pub view: Option<ViewState>,
    /// What could not be read from the link, one message per field.
    pub link_problems: Vec<String>,
    /// A PET to fuse over the CT that opens (`shapecast view CT --pet PET`).
    #[cfg(not(target_arch = "wasm32"))]
    pub pet: Option<Vec<std::path::PathBuf>>,
    /// A PET to fuse over the CT that opens, by URL (the page's `&pet=URL`).
    pub pet_urls: Vec<String>,
}

impl Default for AppOptions {
    fn default() -> Self {
        Self {
            start: StartWith::DemoCt,
            mode: features::DEFAULT_MODE,
            compute_on_load: true,
            preset: None,
            view: None,
            link_problems: Vec::new(),
            #[cfg(not(target_arch = "wasm32"))]
            pet: None,
            pet_urls: Vec::new(),
        }
    }
}

impl AppOptions {
    /// The defaults, changed by the page's URL on the web: `?url=URL` (repeatable) downloads a
    /// volume instead of the demo CT, `?phantom=NAME` opens a phantom,
    /// `?method=intensity|hessian|rst|li|frangi|gst` the mode,
    /// `?preset=lymph-nodes|lung-nodules|airways|vessels` the preset, `?compute=0` waits for
    /// the Recompute button; a link's `#fragment` (a shared view, `view_link`) overrides them.
    pub fn from_environment() -> Self {
        #[allow(unused_mut)]
        let mut o = Self::default();
        #[cfg(target_arch = "wasm32")]
        {
            let query = web_files::query_params();
            let param = |name: &str| {
                query
                    .iter()
                    .rev()
                    .find(|(k, _)| k == name)
                    .map(|(_, v)| v.clone())
            };
            if let Some(name) = param("phantom") {
                o.start = StartWith::Phantom(name);
            }
            let urls: Vec<String> = query
                .iter()
                .filter(|(k, v)| k == "url" && !v.trim().is_empty())
                .map(|(_, v)| web_files::absolute_url(v.trim()))
                .collect();
            if !urls.is_empty() {
                o.start = StartWith::Urls(urls);
            }
            o.pet_urls = query
                .iter()
                .filter(|(k, v)| k == "pet" && !v.trim().is_empty())
                .map(|(_, v)| web_files::absolute_url(v.trim()))
                .collect();
            if let Some(base) = param("dicomweb").filter(|b| !b.trim().is_empty()) {
                // VolView's form too: a URL into the study or series (`.../studies/UID`).
                let (base, study, series) = crate::io::dicomweb::split_target(&base);
                let given = |k: &str| {
                    param(k)
                        .map(|s| s.trim().to_owned())
                        .filter(|s| !s.is_empty())
                };
                // The URL's series goes with the URL's study only.
                let (study, series) = match given("study") {
                    Some(s) if Some(&s) != study.as_ref() => (s, given("series")),
                    _ => (study.unwrap_or_default(), given("series").or(series)),
                };
                o.start = StartWith::DicomWeb(PacsTarget {
                    base,
                    study,
                    series,
                });
            }
            if let Some(m) = param("method").and_then(|m| DisplayMode::from_name(&m)) {
                o.mode = m;
            }
            if let Some(p) = param("preset").and_then(|p| Preset::from_name(&p)) {
                o.preset = Some(p);
            }
            if param("compute").as_deref() == Some("0") {
                o.compute_on_load = false;
            }
            let (view, problems) = ViewState::from_fragment(&web_files::fragment());
            o.link_problems = problems;
            if view != ViewState::default() {
                o.apply_link(view);
            }
        }
        o
    }

    /// A link's view: its source replaces the start, its mode and preset the URL's.
    pub fn apply_link(&mut self, view: ViewState) {
        match &view.source {
            Some(ViewSource::Demo) => self.start = StartWith::DemoCt,
            Some(ViewSource::Phantom(name)) => self.start = StartWith::Phantom(name.clone()),
            Some(ViewSource::Urls(urls)) => self.start = StartWith::Urls(urls.clone()),
            Some(ViewSource::DicomWeb {
                base,
                study,
                series,
            }) => {
                self.start = StartWith::DicomWeb(PacsTarget {
                    base: base.clone(),
                    study: study.clone(),
                    series: Some(series.clone()).filter(|s| !s.is_empty()),
                });
            }
            // The user has the file; the app waits for it to be dropped.
            Some(ViewSource::Dropped { .. }) => self.start = StartWith::Nothing,
            None => {}
        }
        if let Some(m) = view.mode {
            self.mode = m;
        }
        if let Some(p) = &view.params {
            self.preset = Some(p.preset);
        }
        self.view = Some(view);
    }
}
