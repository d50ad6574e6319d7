use super::*;
use dicom_object::mem::InMemElement;

fn source(frame: bool) -> SourceSeries {
    let meta = format!(
        r#"[{{"00080016":{{"vr":"UI","Value":["1.2.840.10008.5.1.4.1.1.2"]}},
               "00080018":{{"vr":"UI","Value":["1.2.3.1"]}},
               "00100020":{{"vr":"LO","Value":["P-7"]}},
               {}
               "0020000D":{{"vr":"UI","Value":["1.2.3"]}},
               "0020000E":{{"vr":"UI","Value":["1.2.3.4"]}}}}]"#,
        if frame {
            r#""00200052":{"vr":"UI","Value":["1.2.3.9"]},"#
        } else {
            ""
        }
    );
    SourceSeries::from_metadata("u", meta.as_bytes()).unwrap()
}

fn report() -> Report {
    let q = |concept, derivation, value, unit| Quantity {
        concept,
        derivation,
        value,
        unit,
    };
    Report {
        stable_key: None,
        description: "measurements".to_owned(),
        groups: vec![
            Group::Length {
                id: "ruler 1".to_owned(),
                ends: [[0.0, 0.0, 0.0], [3.0, 4.0, 0.0]],
                mm: 5.0,
            },
            Group::Ellipse {
                id: "ellipse 1".to_owned(),
                axes: [
                    [-2.0, 0.0, 1.0],
                    [2.0, 0.0, 1.0],
                    [0.0, -1.0, 1.0],
                    [0.0, 1.0, 1.0],
                ],
                quantities: vec![
                    q(codes::ATTENUATION, Some(codes::MEAN), 42.25, codes::HU),
                    q(codes::SUVBW, Some(codes::PEAK), 7.5, codes::SUV),
                ],
            },
            Group::Finding {
                id: "finding 1".to_owned(),
                kind: codes::NODULE,
                at: [10.0, -20.5, 30.0],
                quantities: vec![q(codes::DIAMETER, None, 12.5, codes::MM)],
            },
        ],
    }
}

fn text_of(o: &InMemDicomObject, tag: dicom_core::Tag) -> String {
    o.element(tag)
        .unwrap()
        .to_str()
        .unwrap()
        .trim_end_matches(['\0', ' '])
        .to_owned()
}

fn items(e: &InMemElement) -> &[InMemDicomObject] {
    e.items().unwrap()
}

fn concept(o: &InMemDicomObject) -> String {
    text_of(
        &items(o.element(tags::CONCEPT_NAME_CODE_SEQUENCE).unwrap())[0],
        tags::CODE_MEANING,
    )
}

#[test]
fn a_report_reads_back_as_tid_1500() {
    let now = DicomNow::from_unix(1_732_838_400, 0);
    let made = measurement_report(&source(true), &report(), &now, 9002).unwrap();
    let obj = dicom_object::from_reader(&made.bytes[128..]).unwrap();
    assert_eq!(
        text_of(&obj, tags::SOP_CLASS_UID),
        uids::COMPREHENSIVE3_DSR_STORAGE
    );
    assert_eq!(text_of(&obj, tags::MODALITY), "SR");
    assert_eq!(text_of(&obj, tags::PATIENT_ID), "P-7");
    assert_eq!(concept(&obj), "Imaging Measurement Report");
    let template = &items(obj.element(tags::CONTENT_TEMPLATE_SEQUENCE).unwrap())[0];
    assert_eq!(text_of(template, tags::TEMPLATE_IDENTIFIER), "1500");
    let content = items(obj.element(tags::CONTENT_SEQUENCE).unwrap());
    let measurements = content
        .iter()
        .find(|i| concept(i) == "Imaging Measurements")
        .unwrap();
    let groups = items(measurements.element(tags::CONTENT_SEQUENCE).unwrap());
    assert_eq!(groups.len(), 3);
    // The ruler: its length, inferred from a 3D line in the series' frame of reference.
    let ruler = items(groups[0].element(tags::CONTENT_SEQUENCE).unwrap());
    assert_eq!(text_of(&ruler[0], tags::TEXT_VALUE), "ruler 1");
    let length = ruler.iter().find(|i| concept(i) == "Length").unwrap();
    let value = &items(length.element(tags::MEASURED_VALUE_SEQUENCE).unwrap())[0];
    assert_eq!(text_of(value, tags::NUMERIC_VALUE), "5");
    let line = &items(length.element(tags::CONTENT_SEQUENCE).unwrap())[0];
    assert_eq!(text_of(line, tags::VALUE_TYPE), "SCOORD3D");
    assert_eq!(
        text_of(line, tags::REFERENCED_FRAME_OF_REFERENCE_UID),
        "1.2.3.9"
    );
    let points = line
        .element(tags::GRAPHIC_DATA)
        .unwrap()
        .to_multi_float32()
        .unwrap();
    assert_eq!(points, vec![0.0, 0.0, 0.0, 3.0, 4.0, 0.0]);
    // The ellipse: its region and its values with their derivations.
    let ellipse = items(groups[1].element(tags::CONTENT_SEQUENCE).unwrap());
    let region = ellipse
        .iter()
        .find(|i| concept(i) == "Image Region")
        .unwrap();
    assert_eq!(text_of(region, tags::GRAPHIC_TYPE), "ELLIPSE");
    let suv = ellipse.iter().find(|i| concept(i) == "SUVbw").unwrap();
    let modifier = &items(suv.element(tags::CONTENT_SEQUENCE).unwrap())[0];
    assert_eq!(
        text_of(
            &items(modifier.element(tags::CONCEPT_CODE_SEQUENCE).unwrap())[0],
            tags::CODE_MEANING
        ),
        "Peak Value Within ROI"
    );
    // The finding: its kind and where.
    let finding = items(groups[2].element(tags::CONTENT_SEQUENCE).unwrap());
    assert!(finding.iter().any(|i| concept(i) == "Finding"));
    // The evidence: the source series.
    let evidence = &items(
        obj.element(tags::CURRENT_REQUESTED_PROCEDURE_EVIDENCE_SEQUENCE)
            .unwrap(),
    )[0];
    assert_eq!(text_of(evidence, tags::STUDY_INSTANCE_UID), "1.2.3");
}

#[test]
fn what_cannot_be_reported_is_said() {
    let now = DicomNow::from_unix(0, 0);
    let e = measurement_report(&source(false), &report(), &now, 1).unwrap_err();
    assert!(e.to_string().contains("FrameOfReferenceUID"), "{e}");
    let empty = Report {
        groups: Vec::new(),
        description: String::new(),
        stable_key: None,
    };
    let e = measurement_report(&source(true), &empty, &now, 1).unwrap_err();
    assert!(e.to_string().contains("nothing to report"), "{e}");
}

#[test]
fn decimals_fit_sixteen_characters() {
    assert_eq!(decimal(5.0).unwrap(), "5");
    assert_eq!(decimal(42.25).unwrap(), "42.25");
    assert_eq!(decimal(-0.0).unwrap(), "0");
    assert_eq!(decimal(1.0 / 3.0).unwrap(), "0.3333333333");
    assert!(decimal(123_456_789.123_456_78).unwrap().len() <= 16);
    assert!(decimal(1e300).unwrap().len() <= 16);
    assert!(decimal(f64::NAN).is_err());
}
