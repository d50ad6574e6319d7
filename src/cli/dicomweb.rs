//! `--dicomweb BASE --study UID [--series UID] [--token T | --user USER:PASS]`: the input of
//! `info`, `features` and `render` retrieved from an archive over DICOMweb
//! (`crate::io::dicomweb`) instead of read from files. Without `--series` the study's series are
//! listed on stderr and the chooser's pick (the CT or MR series with the most instances) is
//! opened. Patient names are not printed (batch logs travel); the patient ID and study date are.

use std::io::IsTerminal as _;

use anyhow::Context as _;

use crate::io::Loaded;
use crate::io::dicomweb::client::Client;
use crate::io::dicomweb::{Auth, Base, DicomWebError};

/// Environment variables read when the flags are not given (a command line is visible to
/// other users of the machine; the environment is not).
pub const TOKEN_ENV: &str = "SHAPECAST_DICOMWEB_TOKEN";
pub const USER_ENV: &str = "SHAPECAST_DICOMWEB_USER";
pub const CA_ENV: &str = "SHAPECAST_DICOMWEB_CA";

#[derive(clap::Args, Debug, Default, Clone)]
pub struct DicomWebArgs {
    /// Read the volume from a DICOMweb archive instead of files: its root URL, e.g.
    /// http://127.0.0.1:8042/dicom-web (Orthanc's DICOMweb plugin), with --study; or a URL into
    /// the study or series (BASE/studies/UID[/series/UID], as VolView links them). http:// or
    /// https:// (see --ca).
    #[arg(long, value_name = "BASE")]
    pub dicomweb: Option<String>,
    /// StudyInstanceUID of the study to open from --dicomweb.
    #[arg(long, value_name = "UID", requires = "dicomweb")]
    pub study: Option<String>,
    /// SeriesInstanceUID to open (default: the CT or MR series with the most instances; the
    /// study's series are then listed on stderr).
    #[arg(long, value_name = "UID", requires = "dicomweb")]
    pub series: Option<String>,
    /// Bearer token for the archive (Authorization: Bearer). Better in the environment
    /// variable SHAPECAST_DICOMWEB_TOKEN, out of the process list.
    #[arg(long, value_name = "T", requires = "dicomweb", conflicts_with = "user")]
    pub token: Option<String>,
    /// USER:PASSWORD for an archive with HTTP Basic authentication (e.g. Orthanc's
    /// RegisteredUsers); also SHAPECAST_DICOMWEB_USER.
    #[arg(long, value_name = "USER:PASS", requires = "dicomweb")]
    pub user: Option<String>,
    /// For an https archive whose certificate a site's own CA signed: that CA's certificate(s)
    /// as a PEM file, trusted instead of the public roots; also SHAPECAST_DICOMWEB_CA.
    #[arg(long, value_name = "PEM", requires = "dicomweb")]
    pub ca: Option<std::path::PathBuf>,
}

fn env(name: &str) -> Option<String> {
    std::env::var(name).ok().filter(|v| !v.trim().is_empty())
}

impl DicomWebArgs {
    pub fn is_set(&self) -> bool {
        self.dicomweb.is_some()
    }

    /// The credentials from the flags, else from the environment.
    fn auth(&self) -> anyhow::Result<Auth> {
        let token = self.token.clone().or_else(|| env(TOKEN_ENV));
        let user = self.user.clone().or_else(|| env(USER_ENV));
        Ok(match (token, user) {
            (Some(_), Some(_)) => anyhow::bail!(
                "both a token and a user name are set (--token/{TOKEN_ENV}, --user/{USER_ENV}); give one"
            ),
            (Some(t), None) => Auth::bearer(&t)?,
            (None, Some(u)) => Auth::basic(&u)?,
            (None, None) => Auth::None,
        })
    }

    /// A client of the archive at `base` with the credentials and CA given.
    pub fn client_for(&self, base: &str) -> anyhow::Result<Client> {
        let base = Base::parse(base)?;
        let ca = match self.ca.clone().or_else(|| env(CA_ENV).map(Into::into)) {
            Some(path) => Some(
                std::fs::read(&path)
                    .map_err(|e| anyhow::anyhow!("--ca {}: cannot read it: {e}", path.display()))?,
            ),
            None => None,
        };
        Ok(Client::with_ca(base, self.auth()?, ca.as_deref())?)
    }

    /// Resolves the study, lists its series when none is named, and retrieves the series.
    pub fn load(&self) -> anyhow::Result<Loaded> {
        self.open().map(|(loaded, _)| loaded)
    }

    /// [`Self::load`], and the archive with the study and series opened (to store results
    /// back into).
    pub fn open(&self) -> anyhow::Result<(Loaded, Archive)> {
        let Some(url) = &self.dicomweb else {
            anyhow::bail!("--dicomweb needs --study");
        };
        // A URL into the study or series (`.../studies/UID[/series/UID]`) names them too.
        let (base, url_study, url_series) = crate::io::dicomweb::split_target(url);
        // The URL's series goes with the URL's study only.
        let (study, series) = match (&self.study, url_study) {
            (Some(s), u) if Some(s) != u.as_ref() => (s.clone(), self.series.clone()),
            (_, Some(u)) => (u, self.series.clone().or(url_series)),
            (Some(s), None) => (s.clone(), self.series.clone()),
            (None, None) => anyhow::bail!(
                "--dicomweb needs --study (or a URL into the study: BASE/studies/UID)"
            ),
        };
        let study = &study;
        let client = self.client_for(&base)?;
        let base = client.base().clone();
        let hint = |e: DicomWebError| {
            let unauthorized = matches!(e, DicomWebError::Unauthorized { .. });
            let e = anyhow::Error::new(e);
            if unauthorized {
                e.context(format!(
                    "DICOMweb {}: give a token with --token T or {TOKEN_ENV}, or --user USER:PASS (or {USER_ENV}) for Basic authentication",
                    base.as_str()
                ))
            } else {
                e.context(format!("DICOMweb {}", base.as_str()))
            }
        };
        let resolved = client.resolve(study, series.as_deref()).map_err(hint)?;
        let s = &resolved.study;
        let about: Vec<String> = [
            s.study_date.as_ref().map(|d| format!("date {d}")),
            s.patient_id.as_ref().map(|p| format!("patient ID {p}")),
            s.description.as_ref().map(|d| format!("\"{d}\"")),
        ]
        .into_iter()
        .flatten()
        .collect();
        let chosen = &resolved.series[resolved.chosen];
        if resolved.by_chooser && resolved.series.len() > 1 {
            eprintln!(
                "DICOMweb {}: study {} ({}), {} series:",
                base.as_str(),
                s.study_uid,
                about.join(", "),
                resolved.series.len()
            );
            for (i, series) in resolved.series.iter().enumerate() {
                let mark = if i == resolved.chosen { "*" } else { " " };
                eprintln!("  {mark} {}", series.summary());
            }
            eprintln!(
                "opening * (the CT or MR series with the most instances; --series UID opens another)"
            );
        } else {
            eprintln!(
                "DICOMweb {}: study {} ({}), series {}",
                base.as_str(),
                s.study_uid,
                about.join(", "),
                chosen.summary()
            );
        }
        let started = web_time::Instant::now();
        let tty = std::io::stderr().is_terminal();
        let mut last = (0, 0);
        let loaded = client
            .retrieve(study, &chosen.series_uid, &mut |p| {
                if tty && (p.instances_done, p.instances_total) != last {
                    last = (p.instances_done, p.instances_total);
                    eprint!(
                        "\rretrieving: {}/{} instances, {:.1} MB",
                        p.instances_done,
                        p.instances_total,
                        p.bytes as f64 / 1e6
                    );
                }
            })
            .map_err(hint)
            .with_context(|| format!("retrieving series {}", chosen.series_uid))?;
        if tty {
            eprintln!();
        }
        eprintln!(
            "retrieved series {} in {:.2} s",
            chosen.series_uid,
            started.elapsed().as_secs_f64()
        );
        let series = chosen.series_uid.clone();
        Ok((
            loaded,
            Archive {
                client,
                study: study.clone(),
                series,
            },
        ))
    }
}

/// An archive and the series a command opened from it.
pub struct Archive {
    pub client: Client,
    pub study: String,
    pub series: String,
}

impl Archive {
    /// Stores a rotation of the shape MIP into the study as a Secondary Capture series
    /// (STOW-RS) and says so on stderr; returns the new series' UID.
    pub fn store_rotation(
        &self,
        rotation: &crate::io::dicomweb::stow::Rotation<'_>,
    ) -> anyhow::Result<String> {
        use crate::io::dicomweb::stow;
        let what = format!("{} frames of the shape MIP", rotation.frames.len());
        self.store(&what, |source, now| {
            stow::secondary_capture(source, rotation, now, stow::ROTATION_SERIES_NUMBER)
        })
    }

    /// Stores a measurement report into the study (STOW-RS) and says so on stderr; returns the
    /// new series' UID.
    pub fn store_report(&self, report: &crate::io::dicomweb::sr::Report) -> anyhow::Result<String> {
        use crate::io::dicomweb::{sr, stow};
        let what = format!("the report ({} groups)", report.groups.len());
        self.store(&what, |source, now| {
            sr::measurement_report(source, report, now, stow::REPORT_SERIES_NUMBER)
        })
    }

    /// Makes an instance from the source series' metadata and stores it into the study.
    fn store(
        &self,
        what: &str,
        make: impl FnOnce(
            &crate::io::dicomweb::stow::SourceSeries,
            &crate::io::dicomweb::stow::DicomNow,
        ) -> Result<crate::io::dicomweb::stow::Instance, DicomWebError>,
    ) -> anyhow::Result<String> {
        let base = self.client.base().as_str().to_owned();
        let source = self
            .client
            .source_series(&self.study, &self.series)
            .with_context(|| format!("DICOMweb {base}: the source series' metadata"))?;
        let instance = make(&source, &crate::io::dicomweb::stow::DicomNow::now())?;
        let started = web_time::Instant::now();
        let stored = self
            .client
            .store(&self.study, std::slice::from_ref(&instance))
            .with_context(|| format!("DICOMweb {base}: storing {what}"))?;
        for w in &stored.warnings {
            eprintln!("warning: the archive stored {what} with a warning: {w}");
        }
        eprintln!(
            "stored {what} ({:.1} MB) as series {} in study {} ({:.1} s)",
            instance.bytes.len() as f64 / 1e6,
            instance.series_uid,
            self.study,
            started.elapsed().as_secs_f64()
        );
        Ok(instance.series_uid)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Parser, Debug)]
    struct T {
        #[command(flatten)]
        d: DicomWebArgs,
    }

    #[test]
    fn flags_need_each_other() {
        let ok = T::try_parse_from(["t", "--dicomweb", "http://h/dw", "--study", "1.2"]);
        assert!(ok.is_ok_and(|t| t.d.is_set()));
        // The study may be in the URL (checked when loading: `load` says it is missing).
        assert!(T::try_parse_from(["t", "--dicomweb", "http://h/dw/studies/1.2"]).is_ok());
        let no_study = T::try_parse_from(["t", "--dicomweb", "http://h/dw"]).expect("parses");
        let e = no_study.d.load().expect_err("no study").to_string();
        assert!(e.contains("--dicomweb needs --study"), "{e}");
        assert!(T::try_parse_from(["t", "--study", "1.2"]).is_err());
        assert!(
            T::try_parse_from([
                "t",
                "--dicomweb",
                "x",
                "--study",
                "1",
                "--token",
                "a",
                "--user",
                "u:p"
            ])
            .is_err()
        );
    }
}
