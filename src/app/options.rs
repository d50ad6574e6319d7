//! How the app starts: what it opens on and its options, from the command line, the page's URL
//! or a link (`AppOptions::from_environment`, `AppOptions::apply_link`).

use super::{DisplayMode, PacsTarget, ViewSource, ViewState, features};
use crate::cpu::tf::Preset;

use super::platform;

/// What the app opens on.
#[derive(Clone, Debug, PartialEq)]
pub enum StartWith {
    /// The demo CT (web/demo/): embedded natively, fetched by the page.
    DemoCt,
    /// A phantom by name (`crate::phantom::NAMES`, "fig8-sphere", "demo").
    Phantom(String),
    /// Files and folders on this machine (`shapecast view PATH...`; natively).
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
    /// A PET to fuse over the CT that opens (`shapecast view CT --pet PET`; natively).
    pub pet: Option<Vec<std::path::PathBuf>>,
    /// A PET to fuse over the CT that opens, by URL (the page's `&pet=URL`).
    pub pet_urls: Vec<String>,
    /// The GPU memory budget for the volume textures, MiB (`--gpu-budget-mib`, the page's
    /// `?gpu_budget_mib=`); `None`: the adapter's rule (`gpu::budget::GpuBudget`).
    pub gpu_budget_mib: Option<u64>,
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
            pet: None,
            pet_urls: Vec::new(),
            gpu_budget_mib: None,
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
        let (query, fragment) = platform::page_query_and_fragment();
        Self::from_address(&query, &fragment, platform::absolute_url)
    }

    /// The defaults changed by a page address's query parameters and fragment
    /// ([`Self::from_environment`]); `absolute` resolves a URL against the page.
    pub fn from_address(
        query: &[(String, String)],
        fragment: &str,
        absolute: impl Fn(&str) -> String,
    ) -> Self {
        let mut o = Self::default();
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
            .map(|(_, v)| absolute(v.trim()))
            .collect();
        if !urls.is_empty() {
            o.start = StartWith::Urls(urls);
        }
        o.pet_urls = query
            .iter()
            .filter(|(k, v)| k == "pet" && !v.trim().is_empty())
            .map(|(_, v)| absolute(v.trim()))
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
        match param("gpu_budget_mib").map(|v| v.trim().parse::<u64>()) {
            Some(Ok(mib)) if mib > 0 => o.gpu_budget_mib = Some(mib),
            Some(_) => o.link_problems.push(
                "gpu_budget_mib: not a whole number of MiB above 0; the adapter's budget is used"
                    .to_owned(),
            ),
            None => {}
        }
        let (view, problems) = ViewState::from_fragment(fragment);
        o.link_problems.extend(problems);
        if view != ViewState::default() {
            o.apply_link(view);
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cpu::pipeline::Method;

    fn query(pairs: &[(&str, &str)]) -> Vec<(String, String)> {
        pairs
            .iter()
            .map(|(k, v)| ((*k).to_owned(), (*v).to_owned()))
            .collect()
    }

    fn absolute(url: &str) -> String {
        format!("https://viewer.example/{url}")
    }

    #[test]
    fn an_address_without_query_or_fragment_starts_as_the_defaults() {
        assert_eq!(
            AppOptions::from_address(&[], "", absolute),
            AppOptions::default()
        );
    }

    #[test]
    fn the_query_names_the_volumes_the_method_the_preset_and_the_wait() {
        let o = AppOptions::from_address(
            &query(&[
                ("url", "ct.nii.gz"),
                ("url", " "),
                ("url", "https://data.example/mask.nii.gz"),
                ("pet", "pet.zip"),
                ("method", "rst"),
                ("preset", "airways"),
                ("compute", "0"),
            ]),
            "",
            absolute,
        );
        assert_eq!(
            o.start,
            StartWith::Urls(vec![
                "https://viewer.example/ct.nii.gz".to_owned(),
                "https://viewer.example/https://data.example/mask.nii.gz".to_owned(),
            ])
        );
        assert_eq!(
            o.pet_urls,
            vec!["https://viewer.example/pet.zip".to_owned()]
        );
        assert_eq!(o.mode, DisplayMode::Features(Method::Rst));
        assert_eq!(o.preset, Some(Preset::Airways));
        assert!(!o.compute_on_load);
        assert!(o.link_problems.is_empty());
    }

    #[test]
    fn a_dicomweb_url_into_a_study_keeps_its_series_unless_another_study_is_named() {
        let url = "https://pacs.example/dicom-web/studies/1.2.3/series/1.2.3.4";
        let o = AppOptions::from_address(&query(&[("dicomweb", url)]), "", absolute);
        assert_eq!(
            o.start,
            StartWith::DicomWeb(PacsTarget {
                base: "https://pacs.example/dicom-web".to_owned(),
                study: "1.2.3".to_owned(),
                series: Some("1.2.3.4".to_owned()),
            })
        );
        let o = AppOptions::from_address(
            &query(&[("dicomweb", url), ("study", "9.8.7")]),
            "",
            absolute,
        );
        assert_eq!(
            o.start,
            StartWith::DicomWeb(PacsTarget {
                base: "https://pacs.example/dicom-web".to_owned(),
                study: "9.8.7".to_owned(),
                series: None,
            })
        );
    }

    #[test]
    fn a_fragment_overrides_the_query_and_its_problems_are_kept() {
        let o = AppOptions::from_address(
            &query(&[("phantom", "fig8-sphere"), ("method", "rst")]),
            "#v=1&demo=1&mode=intensity&rays=7",
            absolute,
        );
        assert_eq!(o.start, StartWith::DemoCt);
        assert_eq!(o.mode, DisplayMode::Intensity);
        assert!(!o.link_problems.is_empty(), "{:?}", o.link_problems);
    }
}
