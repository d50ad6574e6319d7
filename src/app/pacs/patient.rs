//! The patient line (name, ID, birth and study dates, series) from the images and the
//! archive's answers, and a study's one-line summary in the dialog.

use crate::io::Patient;
use crate::io::dicomweb::{SeriesInfo, StudyInfo};

/// "DOE, JANE · ID P-7 · born 1970-01-01 · study 2024-01-02 · Thorax 1.0 B70f": the patient
/// line, from what is known (`None` when nothing is).
pub fn patient_line(p: &Patient) -> Option<String> {
    let date = |d: &str| {
        if d.len() == 8 && d.bytes().all(|b| b.is_ascii_digit()) {
            format!("{}-{}-{}", &d[..4], &d[4..6], &d[6..])
        } else {
            d.to_owned()
        }
    };
    let name = p.name.as_ref().map(|n| {
        n.split('^')
            .map(str::trim)
            .filter(|s| !s.is_empty())
            .collect::<Vec<_>>()
            .join(", ")
    });
    let parts: Vec<String> = [
        name.filter(|n| !n.is_empty()),
        p.id.as_ref().map(|i| format!("ID {i}")),
        p.birth_date.as_deref().map(|d| format!("born {}", date(d))),
        p.study_date
            .as_deref()
            .map(|d| format!("study {}", date(d))),
        p.series_description.clone(),
    ]
    .into_iter()
    .flatten()
    .collect();
    (!parts.is_empty()).then(|| parts.join(" · "))
}

/// The patient of a retrieved series: what its images say, completed by the archive's listing.
pub(super) fn merge_patient(
    images: Option<Patient>,
    study: &StudyInfo,
    series: Option<&SeriesInfo>,
) -> Patient {
    let mut p = images.unwrap_or_default();
    p.name = p.name.or_else(|| study.patient_name.clone());
    p.id = p.id.or_else(|| study.patient_id.clone());
    p.birth_date = p.birth_date.or_else(|| study.patient_birth_date.clone());
    p.study_date = p.study_date.or_else(|| study.study_date.clone());
    p.series_description = p
        .series_description
        .or_else(|| series.and_then(|s| s.description.clone()));
    p
}

/// One line of the study list.
pub(super) fn study_summary(s: &StudyInfo) -> String {
    let mut parts: Vec<String> = Vec::new();
    if let Some(d) = &s.study_date {
        parts.push(d.clone());
    }
    if let Some(n) = &s.patient_name {
        parts.push(n.replace('^', ", "));
    }
    if let Some(i) = &s.patient_id {
        parts.push(format!("ID {i}"));
    }
    if let Some(a) = &s.accession_number {
        parts.push(format!("acc. {a}"));
    }
    if !s.modalities.is_empty() {
        parts.push(s.modalities.join("/"));
    }
    if let Some(d) = &s.description {
        parts.push(format!("\"{d}\""));
    }
    if let Some(n) = s.series_count {
        parts.push(format!("{n} series"));
    }
    if parts.is_empty() {
        parts.push(s.study_uid.clone());
    }
    parts.join("  ")
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // a failed unwrap is a failed test
mod tests {
    use super::*;

    #[test]
    fn the_patient_line_says_what_is_known() {
        assert_eq!(patient_line(&Patient::default()), None);
        let p = Patient {
            name: Some("DOE^JANE^^".to_owned()),
            id: Some("P-7".to_owned()),
            birth_date: Some("19700101".to_owned()),
            study_date: Some("2024-1-2".to_owned()),
            series_description: Some("Thorax 1.0 B70f".to_owned()),
        };
        assert_eq!(
            patient_line(&p).unwrap(),
            "DOE, JANE · ID P-7 · born 1970-01-01 · study 2024-1-2 · Thorax 1.0 B70f"
        );
        assert_eq!(format!("{p:?}"), "Patient(..)");
    }

    #[test]
    fn the_archive_fills_what_the_images_lack() {
        let study = StudyInfo {
            study_uid: "1.2".to_owned(),
            patient_name: Some("ROE^RICHARD".to_owned()),
            patient_id: Some("Q".to_owned()),
            study_date: Some("20200202".to_owned()),
            ..StudyInfo::default()
        };
        let series = SeriesInfo {
            series_uid: "1.2.3".to_owned(),
            description: Some("lung".to_owned()),
            ..SeriesInfo::default()
        };
        let images = Patient {
            id: Some("from-header".to_owned()),
            ..Patient::default()
        };
        let p = merge_patient(Some(images), &study, Some(&series));
        assert_eq!(p.id.as_deref(), Some("from-header"));
        assert_eq!(p.name.as_deref(), Some("ROE^RICHARD"));
        assert_eq!(p.study_date.as_deref(), Some("20200202"));
        assert_eq!(p.series_description.as_deref(), Some("lung"));
        assert!(study_summary(&study).starts_with("20200202  ROE, RICHARD  ID Q"));
    }
}
