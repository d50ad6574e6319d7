//! QIDO-RS answers (the DICOM JSON model, PS3.18 annex F) read into studies, series and
//! instances, and the series chooser. Values are read as the standard writes them and as
//! archives do: IS/DS as JSON numbers or strings, PN as `{"Alphabetic": ...}` or a string, tags
//! in upper or lower case hex. Every UID is checked before it can reach a URL.

use serde_json::{Map, Value};

use super::{DicomWebError, check_uid};

/// Most entries read from one answer (a study with more series, or a series with more
/// instances, is refused rather than read without bound).
pub const MAX_ENTRIES: usize = 100_000;

/// A study as QIDO-RS lists it. Patient data are for the user's own screen only.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct StudyInfo {
    pub study_uid: String,
    pub patient_name: Option<String>,
    pub patient_id: Option<String>,
    /// PatientBirthDate as written (YYYYMMDD).
    pub patient_birth_date: Option<String>,
    /// StudyDate as written (YYYYMMDD).
    pub study_date: Option<String>,
    pub description: Option<String>,
    pub accession_number: Option<String>,
    pub modalities: Vec<String>,
    pub series_count: Option<u64>,
    pub instance_count: Option<u64>,
}

/// A series as QIDO-RS lists it.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SeriesInfo {
    pub series_uid: String,
    pub modality: Option<String>,
    pub description: Option<String>,
    pub number: Option<i64>,
    /// NumberOfSeriesRelatedInstances.
    pub instances: Option<u64>,
    /// SliceThickness, where the archive gives it at series level.
    pub slice_thickness_mm: Option<f64>,
}

impl SeriesInfo {
    /// One line for a list: modality, instances, thickness, description, UID.
    pub fn summary(&self) -> String {
        let mut s = format!(
            "{:<3} {:>5} instances",
            self.modality.as_deref().unwrap_or("?"),
            self.instances.map_or("?".to_owned(), |n| n.to_string())
        );
        if let Some(t) = self.slice_thickness_mm {
            s.push_str(&format!(", {t} mm"));
        }
        if let Some(n) = self.number {
            s.push_str(&format!(", #{n}"));
        }
        if let Some(d) = &self.description {
            s.push_str(&format!(", \"{d}\""));
        }
        s.push_str(&format!("  {}", self.series_uid));
        s
    }
}

/// An instance as QIDO-RS lists it.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct InstanceInfo {
    pub sop_uid: String,
    pub number: Option<i64>,
    pub frames: Option<u64>,
}

/// The studies of a QIDO-RS study query.
pub fn parse_studies(url: &str, body: &[u8]) -> Result<Vec<StudyInfo>, DicomWebError> {
    entries(url, body)?
        .iter()
        .map(|o| {
            Ok(StudyInfo {
                study_uid: uid(url, o, "0020000D", "StudyInstanceUID")?,
                patient_name: string(o, "00100010"),
                patient_id: string(o, "00100020"),
                patient_birth_date: string(o, "00100030"),
                study_date: string(o, "00080020"),
                description: string(o, "00081030"),
                accession_number: string(o, "00080050"),
                modalities: strings(o, "00080061"),
                series_count: count(o, "00201206"),
                instance_count: count(o, "00201208"),
            })
        })
        .collect()
}

/// The series of a QIDO-RS series query.
pub fn parse_series(url: &str, body: &[u8]) -> Result<Vec<SeriesInfo>, DicomWebError> {
    entries(url, body)?
        .iter()
        .map(|o| {
            Ok(SeriesInfo {
                series_uid: uid(url, o, "0020000E", "SeriesInstanceUID")?,
                modality: string(o, "00080060"),
                description: string(o, "0008103E"),
                number: number(o, "00200011")
                    .filter(|n| n.fract() == 0.0 && n.abs() < 1e15)
                    .map(|n| n as i64),
                instances: count(o, "00201209"),
                slice_thickness_mm: number(o, "00180050").filter(|t| *t > 0.0),
            })
        })
        .collect()
}

/// The series of an all-studies series query (`{base}/series?...`), each with its study.
pub fn parse_series_in_studies(
    url: &str,
    body: &[u8],
) -> Result<Vec<(String, SeriesInfo)>, DicomWebError> {
    let study_uids: Vec<String> = entries(url, body)?
        .iter()
        .map(|o| uid(url, o, "0020000D", "StudyInstanceUID"))
        .collect::<Result<_, _>>()?;
    Ok(study_uids
        .into_iter()
        .zip(parse_series(url, body)?)
        .collect())
}

/// The instances of a QIDO-RS instance query.
pub fn parse_instances(url: &str, body: &[u8]) -> Result<Vec<InstanceInfo>, DicomWebError> {
    entries(url, body)?
        .iter()
        .map(|o| {
            Ok(InstanceInfo {
                sop_uid: uid(url, o, "00080018", "SOPInstanceUID")?,
                number: number(o, "00200013")
                    .filter(|n| n.fract() == 0.0 && n.abs() < 1e15)
                    .map(|n| n as i64),
                frames: count(o, "00280008"),
            })
        })
        .collect()
}

/// The series to open when none is named: the CT or MR series with the most instances (the
/// first listed of equals); without CT or MR, the PET series with the most, then any series.
pub fn choose_series(series: &[SeriesInfo]) -> Option<usize> {
    let key = |s: &SeriesInfo| {
        // CT and MR first (the features are computed on them; a PET/CT study opens its CT),
        // then PET, then anything else.
        let rank = match s.modality.as_deref() {
            Some("CT" | "MR") => 2,
            Some("PT") => 1,
            _ => 0,
        };
        (rank, s.instances.unwrap_or(0))
    };
    let mut best: Option<usize> = None;
    for (i, s) in series.iter().enumerate() {
        if best.is_none_or(|b| key(s) > key(&series[b])) {
            best = Some(i);
        }
    }
    best
}

/// The PET series of a PET/CT study, fused over its CT: the PT series with the most instances
/// (the first of equals), if the study has one.
pub fn pet_series(series: &[SeriesInfo]) -> Option<usize> {
    let mut best: Option<usize> = None;
    for (i, s) in series.iter().enumerate() {
        if s.modality.as_deref() == Some("PT")
            && best.is_none_or(|b| s.instances.unwrap_or(0) > series[b].instances.unwrap_or(0))
        {
            best = Some(i);
        }
    }
    best
}

/// The objects of a QIDO-RS answer. An empty body (204 No Content) is no match.
pub(super) fn entries(url: &str, body: &[u8]) -> Result<Vec<Map<String, Value>>, DicomWebError> {
    let json_error = |message: String| DicomWebError::Json {
        url: url.to_owned(),
        message,
    };
    if body.iter().all(u8::is_ascii_whitespace) {
        return Ok(Vec::new());
    }
    let value: Value = serde_json::from_slice(body).map_err(|e| json_error(e.to_string()))?;
    let Value::Array(items) = value else {
        return Err(json_error("expected a JSON array".to_owned()));
    };
    if items.len() > MAX_ENTRIES {
        return Err(DicomWebError::TooLarge {
            what: format!("{url}: the answer's entries"),
            size: items.len() as u64,
            limit: MAX_ENTRIES as u64,
        });
    }
    items
        .into_iter()
        .map(|v| match v {
            Value::Object(o) => Ok(o),
            other => Err(json_error(format!(
                "expected an object per entry, found {}",
                kind(&other)
            ))),
        })
        .collect()
}

fn kind(v: &Value) -> &'static str {
    match v {
        Value::Null => "null",
        Value::Bool(_) => "a boolean",
        Value::Number(_) => "a number",
        Value::String(_) => "a string",
        Value::Array(_) => "an array",
        Value::Object(_) => "an object",
    }
}

/// The "Value" array of an attribute (tag as 8 hex digits, either case).
fn values<'a>(o: &'a Map<String, Value>, tag: &str) -> Option<&'a Vec<Value>> {
    let attr = o.get(tag).or_else(|| o.get(&tag.to_ascii_lowercase()))?;
    attr.get("Value")?.as_array()
}

/// A value as text: strings as they are, numbers written out, a person name's alphabetic form.
fn text(v: &Value) -> Option<String> {
    let s = match v {
        Value::String(s) => s.clone(),
        Value::Number(n) => n.to_string(),
        Value::Object(pn) => pn.get("Alphabetic")?.as_str()?.to_owned(),
        _ => return None,
    };
    let s = s.trim_matches(['\0', ' ']).to_owned();
    (!s.is_empty()).then_some(s)
}

pub(super) fn string(o: &Map<String, Value>, tag: &str) -> Option<String> {
    values(o, tag)?.first().and_then(text)
}

fn strings(o: &Map<String, Value>, tag: &str) -> Vec<String> {
    values(o, tag)
        .map(|v| v.iter().filter_map(text).collect())
        .unwrap_or_default()
}

fn number(o: &Map<String, Value>, tag: &str) -> Option<f64> {
    let v = values(o, tag)?.first()?;
    let n = match v {
        Value::Number(n) => n.as_f64()?,
        Value::String(s) => s.trim().parse().ok()?,
        _ => return None,
    };
    n.is_finite().then_some(n)
}

pub(super) fn count(o: &Map<String, Value>, tag: &str) -> Option<u64> {
    number(o, tag)
        .filter(|n| *n >= 0.0 && n.fract() == 0.0 && *n < 1e15)
        .map(|n| n as u64)
}

pub(super) fn uid(
    url: &str,
    o: &Map<String, Value>,
    tag: &str,
    name: &str,
) -> Result<String, DicomWebError> {
    let s = string(o, tag).ok_or_else(|| DicomWebError::Json {
        url: url.to_owned(),
        message: format!("an entry has no {name} ({tag})"),
    })?;
    Ok(check_uid(name, &s)?.to_owned())
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // a failed unwrap is a failed test
mod tests {
    use super::*;

    /// Orthanc 1.10's answer to a series query (DICOMweb plugin 1.7), cut to two series.
    const ORTHANC_SERIES: &str = r#"[
      {"00080005":{"Value":["ISO_IR 100"],"vr":"CS"},"00080020":{"Value":["20070425"],"vr":"DA"},
       "00080060":{"Value":["CT"],"vr":"CS"},"0008103E":{"Value":["ThoraxRoutine  8.0.0  B70f"],"vr":"LO"},
       "00100010":{"Value":[{"Alphabetic":"Lung_Dx-A0002"}],"vr":"PN"},
       "00180050":{"Value":[8],"vr":"DS"},
       "0020000D":{"Value":["1.3.6.1.4.1.14519.5.2.1.6655.2359.104855313699639828167809534834"],"vr":"UI"},
       "0020000E":{"Value":["1.3.6.1.4.1.14519.5.2.1.6655.2359.241981550240354690198744362919"],"vr":"UI"},
       "00200010":{"vr":"SH"},"00200011":{"Value":[2],"vr":"IS"},"00201209":{"Value":[30],"vr":"IS"}},
      {"00080060":{"Value":["SR"],"vr":"CS"},"0020000e":{"Value":["1.2.3.4"],"vr":"UI"},
       "00201209":{"Value":["1"],"vr":"IS"},"00200011":{"Value":["901"],"vr":"IS"}}
    ]"#;

    #[test]
    fn orthanc_series_answer() {
        let s = parse_series("u", ORTHANC_SERIES.as_bytes()).unwrap();
        assert_eq!(s.len(), 2);
        assert_eq!(
            s[0].series_uid,
            "1.3.6.1.4.1.14519.5.2.1.6655.2359.241981550240354690198744362919"
        );
        assert_eq!(s[0].modality.as_deref(), Some("CT"));
        assert_eq!(s[0].instances, Some(30));
        assert_eq!(s[0].slice_thickness_mm, Some(8.0));
        assert_eq!(s[0].number, Some(2));
        assert_eq!(
            s[0].description.as_deref(),
            Some("ThoraxRoutine  8.0.0  B70f")
        );
        // Lower-case tags and numbers as strings (as some archives write them).
        assert_eq!(s[1].series_uid, "1.2.3.4");
        assert_eq!(s[1].instances, Some(1));
        assert_eq!(s[1].number, Some(901));
        assert_eq!(s[1].slice_thickness_mm, None);
        assert!(
            s[0].summary().contains("30 instances, 8 mm, #2"),
            "{}",
            s[0].summary()
        );
    }

    #[test]
    fn studies_with_patient_data() {
        let body = r#"[{"0020000D":{"vr":"UI","Value":["1.2.3"]},
            "00100010":{"vr":"PN","Value":[{"Alphabetic":"Doe^Jane"}]},
            "00100020":{"vr":"LO","Value":["P-7"]},"00080020":{"vr":"DA","Value":["20240102"]},
            "00100030":{"vr":"DA","Value":["19700101"]},
            "00080061":{"vr":"CS","Value":["CT","SR"]},"00201206":{"vr":"IS","Value":[3]},
            "00080050":{"vr":"SH"}}]"#;
        let s = parse_studies("u", body.as_bytes()).unwrap();
        assert_eq!(s[0].patient_name.as_deref(), Some("Doe^Jane"));
        assert_eq!(s[0].patient_id.as_deref(), Some("P-7"));
        assert_eq!(s[0].study_date.as_deref(), Some("20240102"));
        assert_eq!(s[0].patient_birth_date.as_deref(), Some("19700101"));
        assert_eq!(s[0].modalities, ["CT", "SR"]);
        assert_eq!(s[0].series_count, Some(3));
        assert_eq!(s[0].accession_number, None);
        // No match: an empty array, or 204's empty body.
        assert!(parse_studies("u", b"[]").unwrap().is_empty());
        assert!(parse_studies("u", b"").unwrap().is_empty());
    }

    #[test]
    fn instances() {
        let body = r#"[{"00080018":{"vr":"UI","Value":["1.2.3.1"]},"00200013":{"vr":"IS","Value":[5]}},
                       {"00080018":{"vr":"UI","Value":["1.2.3.2"]},"00280008":{"vr":"IS","Value":["12"]}}]"#;
        let i = parse_instances("u", body.as_bytes()).unwrap();
        assert_eq!(i[0].number, Some(5));
        assert_eq!(i[1].frames, Some(12));
    }

    #[test]
    fn hostile_answers_are_errors_not_panics() {
        let cases: &[&str] = &[
            "{",
            "{}",
            "[1]",
            "[{}]",
            r#"[{"0020000E":{"Value":[]}}]"#,
            r#"[{"0020000E":{"Value":["1.2/../../x"]}}]"#,
            r#"[{"0020000E":{"Value":[{"Alphabetic":7}]}}]"#,
            &"[".repeat(10_000),
        ];
        for c in cases {
            let e = parse_series("http://h/q", c.as_bytes()).unwrap_err();
            assert!(
                e.to_string().contains("http://h/q") || e.to_string().contains("UID"),
                "{e}"
            );
        }
        // Odd values are skipped, not trusted.
        let odd = r#"[{"0020000E":{"Value":["1.2"]},"00201209":{"Value":[-3]},
            "00180050":{"Value":["NaN"]},"00200011":{"Value":[1e300]}}]"#;
        let s = parse_series("u", odd.as_bytes()).unwrap();
        assert_eq!(
            (s[0].instances, s[0].slice_thickness_mm, s[0].number),
            (None, None, None)
        );
    }

    /// A series of modality `m` with `n` instances.
    fn series_of(m: &str, n: Option<u64>) -> SeriesInfo {
        SeriesInfo {
            series_uid: "1".to_owned(),
            modality: Some(m.to_owned()),
            instances: n,
            ..SeriesInfo::default()
        }
    }

    #[test]
    fn chooser_prefers_the_largest_ct_or_mr() {
        let s = series_of;
        assert_eq!(choose_series(&[]), None);
        assert_eq!(
            choose_series(&[
                s("SR", Some(500)),
                s("CT", Some(3)),
                s("MR", Some(30)),
                s("CT", Some(30))
            ]),
            Some(2)
        );
        assert_eq!(choose_series(&[s("CT", None), s("CT", Some(1))]), Some(1));
        assert_eq!(
            choose_series(&[s("SEG", Some(1)), s("PT", Some(200))]),
            Some(1)
        );
    }

    #[test]
    fn a_pet_ct_study_s_pet_is_its_largest_pt_series() {
        let s = series_of;
        assert_eq!(pet_series(&[s("CT", Some(300)), s("SR", Some(1))]), None);
        let study = [
            s("CT", Some(300)),
            s("PT", Some(59)),
            s("PT", Some(255)),
            s("PT", Some(255)),
        ];
        // The CT opens; the larger PET (the first of equals) goes over it.
        assert_eq!(choose_series(&study), Some(0));
        assert_eq!(pet_series(&study), Some(2));
        assert_eq!(pet_series(&[s("PT", None)]), Some(0));
    }
}
