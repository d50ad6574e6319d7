//! A DICOM Structured Report of a reading: the measurements and findings as a TID 1500
//! "Imaging Measurement Report" (PS3.16), in a Comprehensive 3D SR (its regions are 3D
//! coordinates in the series' frame of reference, SCOORD3D), in the study of the series the
//! reading was made on, which it lists as evidence. Stored with STOW-RS as the Secondary
//! Capture is (`stow`).
//!
//! - a ruler: a measurement group (TID 1501) with its Length, inferred from the 3D line;
//! - an ellipse: a planar ROI group (TID 1410) with its 3D ellipse and the CT's mean, standard
//!   deviation, minimum and maximum (HU) and area; on a fused PET, SUVbw max, mean and peak
//!   (TID 1419's "Derivation" modifiers);
//! - a finding: a measurement group (TID 1501) with the finding's kind, its diameter and volume
//!   at its 3D point, its HU and its blobness score.

use dicom_core::value::DataSetSequence;
use dicom_core::{DataElement, PrimitiveValue, VR};
use dicom_dictionary_std::{tags, uids};
use dicom_object::InMemDicomObject;

use super::DicomWebError;
use super::stow::{self, DicomNow, Instance, SourceSeries};

/// A coded concept (code value, coding scheme, meaning).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Code {
    pub value: &'static str,
    pub scheme: &'static str,
    pub meaning: &'static str,
}

const fn code(value: &'static str, scheme: &'static str, meaning: &'static str) -> Code {
    Code {
        value,
        scheme,
        meaning,
    }
}

/// The codes a report uses (DCM: PS3.16; SCT: SNOMED CT; UCUM units; 99SHAPECAST: ours).
pub mod codes {
    use super::{Code, code};
    pub const REPORT: Code = code("126000", "DCM", "Imaging Measurement Report");
    pub const LANGUAGE: Code = code("121049", "DCM", "Language of Content Item and Descendants");
    pub const ENGLISH: Code = code("en-US", "RFC5646", "English (United States)");
    pub const OBSERVER_TYPE: Code = code("121005", "DCM", "Observer Type");
    pub const DEVICE: Code = code("121007", "DCM", "Device");
    pub const DEVICE_UID: Code = code("121012", "DCM", "Device Observer UID");
    pub const DEVICE_NAME: Code = code("121013", "DCM", "Device Observer Name");
    pub const PROCEDURE: Code = code("121058", "DCM", "Procedure reported");
    pub const IMAGING_PROCEDURE: Code = code("363679005", "SCT", "Imaging procedure");
    pub const MEASUREMENTS: Code = code("126010", "DCM", "Imaging Measurements");
    pub const GROUP: Code = code("125007", "DCM", "Measurement Group");
    pub const TRACKING_ID: Code = code("112039", "DCM", "Tracking Identifier");
    pub const TRACKING_UID: Code = code("112040", "DCM", "Tracking Unique Identifier");
    pub const FINDING: Code = code("121071", "DCM", "Finding");
    pub const IMAGE_REGION: Code = code("111030", "DCM", "Image Region");
    pub const DERIVATION: Code = code("121401", "DCM", "Derivation");
    pub const LENGTH: Code = code("410668003", "SCT", "Length");
    pub const DIAMETER: Code = code("81827009", "SCT", "Diameter");
    pub const VOLUME: Code = code("118565006", "SCT", "Volume");
    pub const AREA: Code = code("42798000", "SCT", "Area");
    pub const ATTENUATION: Code = code("112031", "DCM", "Attenuation Coefficient");
    pub const SUVBW: Code = code("126401", "DCM", "SUVbw");
    pub const MEAN: Code = code("373098007", "SCT", "Mean");
    pub const SD: Code = code("386136009", "SCT", "Standard Deviation");
    pub const MINIMUM: Code = code("255605001", "SCT", "Minimum");
    pub const MAXIMUM: Code = code("56851009", "SCT", "Maximum");
    pub const PEAK: Code = code("126031", "DCM", "Peak Value Within ROI");
    pub const INFERRED: &str = "INFERRED FROM";
    pub const NODULE: Code = code("27925004", "SCT", "Nodule");
    pub const LYMPH_NODE: Code = code("59441001", "SCT", "Lymph node");
    pub const LESION: Code = code("52988006", "SCT", "Lesion");
    pub const BLOBNESS_SCORE: Code = code("BLOBSCORE", "99SHAPECAST", "Blobness score");
    pub const MM: Code = code("mm", "UCUM", "millimeter");
    pub const MM2: Code = code("mm2", "UCUM", "square millimeter");
    pub const ML: Code = code("ml", "UCUM", "milliliter");
    pub const HU: Code = code("[hnsf'U]", "UCUM", "Hounsfield unit");
    pub const SUV: Code = code(
        "{SUVbw}g/ml",
        "UCUM",
        "Standardized Uptake Value body weight",
    );
    pub const NO_UNITS: Code = code("1", "UCUM", "no units");
}

/// A value measured over a region: what (and how it was derived from the region's values),
/// the number and its unit.
#[derive(Clone, Debug, PartialEq)]
pub struct Quantity {
    pub concept: Code,
    pub derivation: Option<Code>,
    pub value: f64,
    pub unit: Code,
}

/// One measurement group, in patient coordinates (LPS, mm) of the series' frame of reference.
#[derive(Clone, Debug, PartialEq)]
pub enum Group {
    /// A ruler from one point to another.
    Length {
        id: String,
        ends: [[f64; 3]; 2],
        mm: f64,
    },
    /// An ellipse on a slice: its major axis' two ends, then its minor axis' two ends.
    Ellipse {
        id: String,
        axes: [[f64; 3]; 4],
        quantities: Vec<Quantity>,
    },
    /// A finding at a point, of a kind.
    Finding {
        id: String,
        kind: Code,
        at: [f64; 3],
        quantities: Vec<Quantity>,
    },
}

/// A reading's report: its groups, and what it is of (after "Shapecast" in SeriesDescription).
#[derive(Clone, Debug, PartialEq)]
pub struct Report {
    pub groups: Vec<Group>,
    pub description: String,
    /// A key that makes the UIDs the same on every run (see `stow::Rotation::stable_key`).
    pub stable_key: Option<String>,
}

/// Shapecast's device observer UID.
const DEVICE_UID: &str = "2.25.261476391845279371164128926470127445163";

fn encode_error(message: String) -> DicomWebError {
    DicomWebError::Encode {
        what: "the measurement report".to_owned(),
        message,
    }
}

fn put(obj: &mut InMemDicomObject, tag: dicom_core::Tag, vr: VR, value: &str) {
    obj.put(DataElement::new(tag, vr, PrimitiveValue::from(value)));
}

fn seq(obj: &mut InMemDicomObject, tag: dicom_core::Tag, items: Vec<InMemDicomObject>) {
    obj.put(DataElement::new(tag, VR::SQ, DataSetSequence::from(items)));
}

fn code_item(c: &Code) -> InMemDicomObject {
    let mut o = InMemDicomObject::new_empty();
    put(&mut o, tags::CODE_VALUE, VR::SH, c.value);
    put(&mut o, tags::CODING_SCHEME_DESIGNATOR, VR::SH, c.scheme);
    put(&mut o, tags::CODE_MEANING, VR::LO, c.meaning);
    o
}

/// A content item: its relationship to its parent, value type and concept name.
fn item(relationship: &str, value_type: &str, concept: &Code) -> InMemDicomObject {
    let mut o = InMemDicomObject::new_empty();
    put(&mut o, tags::RELATIONSHIP_TYPE, VR::CS, relationship);
    put(&mut o, tags::VALUE_TYPE, VR::CS, value_type);
    seq(
        &mut o,
        tags::CONCEPT_NAME_CODE_SEQUENCE,
        vec![code_item(concept)],
    );
    o
}

fn template(o: &mut InMemDicomObject, id: &str) {
    let mut t = InMemDicomObject::new_empty();
    put(&mut t, tags::MAPPING_RESOURCE, VR::CS, "DCMR");
    put(&mut t, tags::TEMPLATE_IDENTIFIER, VR::CS, id);
    seq(o, tags::CONTENT_TEMPLATE_SEQUENCE, vec![t]);
}

fn container(
    relationship: &str,
    concept: &Code,
    template_id: Option<&str>,
    children: Vec<InMemDicomObject>,
) -> InMemDicomObject {
    let mut o = item(relationship, "CONTAINER", concept);
    put(&mut o, tags::CONTINUITY_OF_CONTENT, VR::CS, "SEPARATE");
    if let Some(t) = template_id {
        template(&mut o, t);
    }
    seq(&mut o, tags::CONTENT_SEQUENCE, children);
    o
}

fn text(relationship: &str, concept: &Code, value: &str) -> InMemDicomObject {
    let mut o = item(relationship, "TEXT", concept);
    put(&mut o, tags::TEXT_VALUE, VR::UT, value);
    o
}

fn coded(relationship: &str, concept: &Code, value: &Code) -> InMemDicomObject {
    let mut o = item(relationship, "CODE", concept);
    seq(&mut o, tags::CONCEPT_CODE_SEQUENCE, vec![code_item(value)]);
    o
}

fn uidref(relationship: &str, concept: &Code, uid: &str) -> InMemDicomObject {
    let mut o = item(relationship, "UIDREF", concept);
    put(&mut o, tags::UID, VR::UI, uid);
    o
}

/// A decimal string of at most 16 characters (DS), as precise as fits.
pub fn decimal(v: f64) -> Result<String, DicomWebError> {
    if !v.is_finite() {
        return Err(encode_error(format!("{v} is not a number DICOM can hold")));
    }
    for precision in (0..=10).rev() {
        let s = format!("{v:.precision$}");
        let s = if s.contains('.') {
            s.trim_end_matches('0').trim_end_matches('.').to_owned()
        } else {
            s
        };
        if s.len() <= 16 {
            return Ok(if s == "-0" { "0".to_owned() } else { s });
        }
    }
    let s = format!("{v:.6E}");
    if s.len() <= 16 {
        Ok(s)
    } else {
        Err(encode_error(format!(
            "{v} does not fit a DICOM decimal string"
        )))
    }
}

fn num(
    relationship: &str,
    q: &Quantity,
    children: Vec<InMemDicomObject>,
) -> Result<InMemDicomObject, DicomWebError> {
    let mut o = item(relationship, "NUM", &q.concept);
    let mut value = InMemDicomObject::new_empty();
    seq(
        &mut value,
        tags::MEASUREMENT_UNITS_CODE_SEQUENCE,
        vec![code_item(&q.unit)],
    );
    put(&mut value, tags::NUMERIC_VALUE, VR::DS, &decimal(q.value)?);
    seq(&mut o, tags::MEASURED_VALUE_SEQUENCE, vec![value]);
    let mut children = children;
    if let Some(d) = &q.derivation {
        children.insert(0, coded("HAS CONCEPT MOD", &codes::DERIVATION, d));
    }
    if !children.is_empty() {
        seq(&mut o, tags::CONTENT_SEQUENCE, children);
    }
    Ok(o)
}

fn scoord3d(
    relationship: &str,
    concept: &Code,
    graphic_type: &str,
    points: &[[f64; 3]],
    frame: &str,
) -> Result<InMemDicomObject, DicomWebError> {
    if points.iter().flatten().any(|c| !c.is_finite()) {
        return Err(encode_error("a point is not finite".to_owned()));
    }
    let mut o = item(relationship, "SCOORD3D", concept);
    put(&mut o, tags::GRAPHIC_TYPE, VR::CS, graphic_type);
    let data: Vec<f32> = points.iter().flatten().map(|&c| c as f32).collect();
    o.put(DataElement::new(
        tags::GRAPHIC_DATA,
        VR::FL,
        PrimitiveValue::F32(data.into()),
    ));
    put(
        &mut o,
        tags::REFERENCED_FRAME_OF_REFERENCE_UID,
        VR::UI,
        frame,
    );
    Ok(o)
}

/// The group's tracking identifier and a UID unique to it within this report.
fn tracking(report_uid: &str, index: usize, id: &str) -> Vec<InMemDicomObject> {
    vec![
        text("HAS OBS CONTEXT", &codes::TRACKING_ID, id),
        uidref(
            "HAS OBS CONTEXT",
            &codes::TRACKING_UID,
            &stow::uid_for(&format!("{report_uid}|group|{index}")),
        ),
    ]
}

fn group_item(
    g: &Group,
    index: usize,
    report_uid: &str,
    frame: &str,
) -> Result<InMemDicomObject, DicomWebError> {
    Ok(match g {
        Group::Length { id, ends, mm } => {
            let line = scoord3d(
                codes::INFERRED,
                &codes::IMAGE_REGION,
                "POLYLINE",
                ends,
                frame,
            )?;
            let length = Quantity {
                concept: codes::LENGTH,
                derivation: None,
                value: *mm,
                unit: codes::MM,
            };
            let mut children = tracking(report_uid, index, id);
            children.push(num("CONTAINS", &length, vec![line])?);
            container("CONTAINS", &codes::GROUP, Some("1501"), children)
        }
        Group::Ellipse {
            id,
            axes,
            quantities,
        } => {
            let mut children = tracking(report_uid, index, id);
            children.push(scoord3d(
                "CONTAINS",
                &codes::IMAGE_REGION,
                "ELLIPSE",
                axes,
                frame,
            )?);
            for q in quantities {
                children.push(num("CONTAINS", q, Vec::new())?);
            }
            container("CONTAINS", &codes::GROUP, Some("1410"), children)
        }
        Group::Finding {
            id,
            kind,
            at,
            quantities,
        } => {
            let mut children = tracking(report_uid, index, id);
            children.push(coded("CONTAINS", &codes::FINDING, kind));
            for (i, q) in quantities.iter().enumerate() {
                // The first measurement carries where it was made.
                let point = if i == 0 {
                    vec![scoord3d(
                        codes::INFERRED,
                        &codes::IMAGE_REGION,
                        "POINT",
                        &[*at],
                        frame,
                    )?]
                } else {
                    Vec::new()
                };
                children.push(num("CONTAINS", q, point)?);
            }
            container("CONTAINS", &codes::GROUP, Some("1501"), children)
        }
    })
}

/// The report as a Comprehensive 3D SR instance (TID 1500) in the source's study.
pub fn measurement_report(
    source: &SourceSeries,
    report: &Report,
    now: &DicomNow,
    series_number: u32,
) -> Result<Instance, DicomWebError> {
    let Some(frame) = source.frame_of_reference.as_deref() else {
        return Err(encode_error(format!(
            "series {} has no FrameOfReferenceUID, which 3D coordinates need",
            source.series_uid
        )));
    };
    if report.groups.is_empty() {
        return Err(encode_error(
            "nothing to report: no measurement and no finding".to_owned(),
        ));
    }
    let name = match &report.stable_key {
        Some(key) => format!("shapecast|stable|{key}"),
        None => format!(
            "shapecast|measurement-report|{}|{}{}|{:?}",
            source.series_uid, now.date, now.time, report.groups
        ),
    };
    let series_uid = stow::uid_for(&format!("{name}|series"));
    let sop_instance_uid = stow::uid_for(&format!("{name}|instance"));
    let sop_class_uid = uids::COMPREHENSIVE3_DSR_STORAGE;
    let mut obj = stow::derived_object(
        source,
        &stow::Derived {
            sop_class_uid,
            sop_instance_uid: &sop_instance_uid,
            series_uid: &series_uid,
            modality: "SR",
            series_number,
            description: &report.description,
        },
        now,
    );
    // SR document general: complete, not verified by a person; the evidence is the series.
    put(&mut obj, tags::INSTANCE_NUMBER, VR::IS, "1");
    put(&mut obj, tags::CONTENT_DATE, VR::DA, &now.date);
    put(&mut obj, tags::CONTENT_TIME, VR::TM, &now.time);
    put(&mut obj, tags::COMPLETION_FLAG, VR::CS, "COMPLETE");
    put(&mut obj, tags::VERIFICATION_FLAG, VR::CS, "UNVERIFIED");
    seq(
        &mut obj,
        tags::REFERENCED_PERFORMED_PROCEDURE_STEP_SEQUENCE,
        Vec::new(),
    );
    seq(
        &mut obj,
        tags::PERFORMED_PROCEDURE_CODE_SEQUENCE,
        vec![code_item(&codes::IMAGING_PROCEDURE)],
    );
    let refs: Vec<InMemDicomObject> = source
        .instances
        .iter()
        .map(|(c, i)| {
            let mut r = InMemDicomObject::new_empty();
            put(&mut r, tags::REFERENCED_SOP_CLASS_UID, VR::UI, c);
            put(&mut r, tags::REFERENCED_SOP_INSTANCE_UID, VR::UI, i);
            r
        })
        .collect();
    let mut series = InMemDicomObject::new_empty();
    put(
        &mut series,
        tags::SERIES_INSTANCE_UID,
        VR::UI,
        &source.series_uid,
    );
    seq(&mut series, tags::REFERENCED_SOP_SEQUENCE, refs);
    let mut study = InMemDicomObject::new_empty();
    put(
        &mut study,
        tags::STUDY_INSTANCE_UID,
        VR::UI,
        &source.study_uid,
    );
    seq(&mut study, tags::REFERENCED_SERIES_SEQUENCE, vec![series]);
    seq(
        &mut obj,
        tags::CURRENT_REQUESTED_PROCEDURE_EVIDENCE_SEQUENCE,
        vec![study],
    );
    // The content tree: the root container and its items.
    put(&mut obj, tags::VALUE_TYPE, VR::CS, "CONTAINER");
    seq(
        &mut obj,
        tags::CONCEPT_NAME_CODE_SEQUENCE,
        vec![code_item(&codes::REPORT)],
    );
    put(&mut obj, tags::CONTINUITY_OF_CONTENT, VR::CS, "SEPARATE");
    template(&mut obj, "1500");
    let mut groups = Vec::with_capacity(report.groups.len());
    for (i, g) in report.groups.iter().enumerate() {
        groups.push(group_item(g, i, &sop_instance_uid, frame)?);
    }
    let content = vec![
        coded("HAS CONCEPT MOD", &codes::LANGUAGE, &codes::ENGLISH),
        coded("HAS OBS CONTEXT", &codes::OBSERVER_TYPE, &codes::DEVICE),
        uidref("HAS OBS CONTEXT", &codes::DEVICE_UID, DEVICE_UID),
        text("HAS OBS CONTEXT", &codes::DEVICE_NAME, "Shapecast"),
        coded(
            "HAS CONCEPT MOD",
            &codes::PROCEDURE,
            &codes::IMAGING_PROCEDURE,
        ),
        container("CONTAINS", &codes::MEASUREMENTS, None, groups),
    ];
    seq(&mut obj, tags::CONTENT_SEQUENCE, content);
    let bytes = stow::part10(obj, "the measurement report")?;
    Ok(Instance {
        bytes,
        series_uid,
        sop_instance_uid,
        sop_class_uid,
    })
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // a failed unwrap is a failed test
mod tests;
