//! Searches an archive answers with QIDO-RS: series across studies (a batch paging through an
//! archive) and studies by patient, accession, date, name and modality.

use super::*;

/// A series search across studies (QIDO-RS `{base}/series?...`), as a batch pages through an
/// archive: a modality, more matching keys (`StudyDate=20240101-20240131`, a keyword or an
/// 8-digit tag each), and a page.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct SeriesSearch {
    pub modality: String,
    pub keys: Vec<(String, String)>,
    pub offset: usize,
    pub limit: usize,
}

impl SeriesSearch {
    /// A `KEY=VALUE` matching key, checked.
    pub fn parse_key(kv: &str) -> Result<(String, String), DicomWebError> {
        let bad = |reason| DicomWebError::InvalidSearch {
            field: "query",
            value: kv.chars().take(80).collect(),
            reason,
        };
        let (k, v) = kv.split_once('=').ok_or(bad("expected KEY=VALUE"))?;
        let (k, v) = (k.trim(), v.trim());
        if k.is_empty()
            || k.len() > 64
            || !k.bytes().all(|b| b.is_ascii_alphanumeric())
            || k.eq_ignore_ascii_case("limit")
            || k.eq_ignore_ascii_case("offset")
        {
            return Err(bad(
                "KEY must be a DICOM keyword or an 8-digit tag (and not limit or offset)",
            ));
        }
        if v.is_empty() || v.chars().count() > 64 || v.chars().any(char::is_control) {
            return Err(bad("VALUE must be 1 to 64 printable characters"));
        }
        Ok((k.to_owned(), v.to_owned()))
    }
}

impl Base {
    /// `{base}/series?Modality=M&KEY=VALUE...&includefield=0020000D&limit=N&offset=K`.
    pub fn series_search(&self, search: &SeriesSearch) -> Result<String, DicomWebError> {
        let mut url = format!("{}/series?", self.url);
        let modality = SeriesSearch::parse_key(&format!("Modality={}", search.modality))?;
        for (k, v) in std::iter::once(&modality).chain(&search.keys) {
            let (k, v) = SeriesSearch::parse_key(&format!("{k}={v}"))?;
            url.push_str(&k);
            url.push('=');
            url.push_str(&crate::io::url::percent_encode(&v, b"*"));
            url.push('&');
        }
        url.push_str(&format!(
            "includefield=0020000D&limit={}&offset={}",
            search.limit.max(1),
            search.offset
        ));
        Ok(url)
    }

    /// `{base}/studies/{study}/series?SeriesInstanceUID={series}`: whether the archive holds it.
    pub fn series_exists_query(&self, study: &str, series: &str) -> Result<String, DicomWebError> {
        let study = check_uid("StudyInstanceUID", study)?;
        let series = check_uid("SeriesInstanceUID", series)?;
        Ok(format!(
            "{}/studies/{study}/series?SeriesInstanceUID={series}",
            self.url
        ))
    }
}

/// What a study search asks for: a patient ID, an accession number and a study date (or a date
/// range), each optional. `*` and `?` are wildcards, as QIDO-RS matches strings.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct StudySearch {
    pub patient_id: String,
    /// PatientName as DICOM writes it (`DOE^JANE`), `*` and `?` as wildcards (`DOE*`).
    pub patient_name: String,
    pub accession_number: String,
    /// ModalitiesInStudy: one modality (`CT`, `MR`, `PT`).
    pub modality: String,
    /// `YYYYMMDD`, or a range `YYYYMMDD-YYYYMMDD` (either end may be left open).
    pub study_date: String,
    /// The page: matches skipped before the first listed (a multiple of [`Self::LIMIT`]).
    pub offset: usize,
}

impl StudySearch {
    /// Most studies one search lists.
    pub const LIMIT: usize = 100;

    /// The query's (key, value) pairs, each checked.
    pub(super) fn criteria(&self) -> Result<Vec<(&'static str, String)>, DicomWebError> {
        let mut out = Vec::new();
        for (field, key, value) in [
            ("patient ID", "PatientID", &self.patient_id),
            ("patient name", "PatientName", &self.patient_name),
            (
                "accession number",
                "AccessionNumber",
                &self.accession_number,
            ),
        ] {
            let v = value.trim();
            if v.is_empty() {
                continue;
            }
            let bad = |reason| DicomWebError::InvalidSearch {
                field,
                value: v.chars().take(80).collect(),
                reason,
            };
            if v.chars().count() > 64 {
                return Err(bad("longer than 64 characters"));
            }
            if v.chars().any(|c| c.is_control() || c == '\\') {
                return Err(bad("holds a control character or a backslash"));
            }
            out.push((key, v.to_owned()));
        }
        let m = self.modality.trim().to_ascii_uppercase();
        if !m.is_empty() {
            if m.len() > 16 || !m.bytes().all(|b| b.is_ascii_alphanumeric() || b == b'_') {
                return Err(DicomWebError::InvalidSearch {
                    field: "modality",
                    value: m.chars().take(80).collect(),
                    reason: "expected a modality code such as CT, MR or PT",
                });
            }
            out.push(("ModalitiesInStudy", m));
        }
        let d = self.study_date.trim();
        if !d.is_empty() {
            let date =
                |s: &str| s.is_empty() || (s.len() == 8 && s.bytes().all(|b| b.is_ascii_digit()));
            let ok = match d.split_once('-') {
                Some((a, b)) => date(a) && date(b) && !(a.is_empty() && b.is_empty()),
                None => d.len() == 8 && date(d),
            };
            if !ok {
                return Err(DicomWebError::InvalidSearch {
                    field: "study date",
                    value: d.chars().take(80).collect(),
                    reason: "expected YYYYMMDD or a range YYYYMMDD-YYYYMMDD (an end may be left open)",
                });
            }
            out.push(("StudyDate", d.to_owned()));
        }
        Ok(out)
    }
}
