use super::*;

const META: &str = r#"[
      {"00080016":{"vr":"UI","Value":["1.2.840.10008.5.1.4.1.1.2"]},
       "00080018":{"vr":"UI","Value":["1.2.3.1"]},
       "00080060":{"vr":"CS","Value":["CT"]},
       "00100010":{"vr":"PN","Value":[{"Alphabetic":"Doe^Jane"}]},
       "00100020":{"vr":"LO","Value":["P-7"]},
       "00080020":{"vr":"DA","Value":["20240102"]},
       "0020000D":{"vr":"UI","Value":["1.2.3"]},
       "0020000E":{"vr":"UI","Value":["1.2.3.4"]}},
      {"00080016":{"vr":"UI","Value":["1.2.840.10008.5.1.4.1.1.2"]},
       "00080018":{"vr":"UI","Value":["1.2.3.2"]},
       "0020000D":{"vr":"UI","Value":["1.2.3"]},
       "0020000E":{"vr":"UI","Value":["1.2.3.4"]}}
    ]"#;

fn source() -> SourceSeries {
    SourceSeries::from_metadata("u", META.as_bytes()).unwrap()
}

#[test]
fn the_source_series_from_its_metadata() {
    let s = source();
    assert_eq!(s.study_uid, "1.2.3");
    assert_eq!(s.series_uid, "1.2.3.4");
    assert_eq!(s.modality.as_deref(), Some("CT"));
    assert_eq!(s.attribute(tags::PATIENT_NAME), Some("Doe^Jane"));
    assert_eq!(s.attribute(tags::ACCESSION_NUMBER), None);
    assert_eq!(s.instances.len(), 2);
    assert_eq!(s.instances[1].1, "1.2.3.2");
    let mixed = META.replacen("\"1.2.3.4\"]}}\n    ]", "\"1.2.3.5\"]}}\n    ]", 1);
    let e = SourceSeries::from_metadata("u", mixed.as_bytes()).unwrap_err();
    assert!(e.to_string().contains("mixes series"), "{e}");
    assert!(SourceSeries::from_metadata("u", b"[]").is_err());
}

#[test]
fn dates_and_uids() {
    let t = DicomNow::from_unix(1_732_838_400 + 3600 + 61, 5);
    assert_eq!(t.date, "20241129");
    assert_eq!(t.time, "010101.000005");
    assert_eq!(DicomNow::from_unix(951_782_400, 0).date, "20000229");
    let a = uid_for("a");
    assert!(a.starts_with("2.25.") && a.len() <= 64, "{a}");
    assert!(check_uid("u", &a).is_ok());
    assert_ne!(a, uid_for("b"));
    assert_eq!(a, uid_for("a"));
    assert!(check_uid("u", IMPLEMENTATION_CLASS_UID).is_ok());
}

fn frames(n: usize, w: u32, h: u32) -> Vec<Vec<u8>> {
    (0..n)
        .map(|f| {
            (0..w * h)
                .flat_map(|p| [f as u8, (p % 251) as u8, 7, 255])
                .collect()
        })
        .collect()
}

/// A turn of `frames` of `width` x `height` pixels.
fn rotation(frames: &[Vec<u8>], width: u32, height: u32) -> Rotation<'_> {
    Rotation {
        width,
        height,
        frames,
        description: "shape MIP, RST".to_owned(),
        derivation: "test".to_owned(),
        step_deg: 360.0 / frames.len().max(1) as f64,
        stable_key: None,
    }
}

#[test]
fn a_secondary_capture_reads_back_frame_by_frame() {
    let frames = frames(3, 5, 4);
    let turn = rotation(&frames, 5, 4);
    let now = DicomNow::from_unix(1_732_838_400, 0);
    let made = secondary_capture(&source(), &turn, &now, 9001).unwrap();
    let obj = dicom_object::from_reader(&made.bytes[128..]).unwrap();
    let get = |t: Tag| obj.element(t).unwrap().to_str().unwrap().trim().to_owned();
    assert_eq!(get(tags::SOP_CLASS_UID), made.sop_class_uid);
    assert_eq!(get(tags::STUDY_INSTANCE_UID), "1.2.3");
    assert_eq!(get(tags::PATIENT_NAME), "Doe^Jane");
    assert_eq!(get(tags::SERIES_INSTANCE_UID), made.series_uid);
    assert!(get(tags::SERIES_DESCRIPTION).starts_with("Shapecast "));
    assert_eq!(get(tags::NUMBER_OF_FRAMES), "3");
    assert_eq!(obj.element(tags::ROWS).unwrap().to_int::<u16>().unwrap(), 4);
    let px = obj.element(tags::PIXEL_DATA).unwrap().to_bytes().unwrap();
    assert_eq!(px.len(), 3 * 5 * 4 * 3);
    // Frame 2, pixel 6: [2, 6, 7].
    let at = 2 * 60 + 6 * 3;
    assert_eq!(&px[at..at + 3], &[2, 6, 7]);
    let refs = obj.element(tags::REFERENCED_SERIES_SEQUENCE).unwrap();
    let items = refs.items().unwrap();
    assert_eq!(
        items[0]
            .element(tags::SERIES_INSTANCE_UID)
            .unwrap()
            .to_str()
            .unwrap()
            .trim_end_matches('\0'),
        "1.2.3.4"
    );
    // Another picture, another UID.
    let other = frames.iter().rev().cloned().collect::<Vec<_>>();
    let again = secondary_capture(
        &source(),
        &Rotation {
            frames: &other,
            ..turn
        },
        &now,
        9001,
    )
    .unwrap();
    assert_ne!(again.sop_instance_uid, made.sop_instance_uid);
    // Frames that are not width x height pixels.
    assert!(secondary_capture(&source(), &rotation(&frames, 6, 4), &now, 1).is_err());
}

#[test]
fn the_body_and_the_answers() {
    let frames = frames(1, 2, 2);
    let rotation = rotation(&frames, 2, 2);
    let made = secondary_capture(&source(), &rotation, &DicomNow::from_unix(0, 0), 1).unwrap();
    let (ct, body) = request_body(std::slice::from_ref(&made));
    let boundary = ct.split("boundary=").nth(1).unwrap();
    assert!(ct.starts_with("multipart/related; type=\"application/dicom\""));
    let mut parser = super::super::MultipartParser::new(
        Some(&ct),
        "stow",
        super::super::multipart::MultipartLimits::default(),
    )
    .unwrap();
    let mut parts = Vec::new();
    parser
        .feed(&body, &mut |p| {
            parts.push(p);
            Ok(())
        })
        .unwrap();
    parser
        .finish(&mut |p| {
            parts.push(p);
            Ok(())
        })
        .unwrap();
    assert_eq!(parts.len(), 1, "{boundary}");
    assert_eq!(parts[0].bytes, made.bytes);

    let ok = format!(
        r#"{{"00081199":{{"vr":"SQ","Value":[{{"00081155":{{"vr":"UI","Value":["{}"]}}}}]}}}}"#,
        made.sop_instance_uid
    );
    let asked = std::slice::from_ref(&made);
    let stored = read_answer("u", 200, ok.as_bytes(), asked, &Auth::None).unwrap();
    assert_eq!(stored.instances, vec![made.sop_instance_uid.clone()]);
    let refused = format!(
        r#"{{"00081198":{{"vr":"SQ","Value":[{{"00081155":{{"vr":"UI","Value":["{}"]}},"00081197":{{"vr":"US","Value":[43264]}}}}]}}}}"#,
        made.sop_instance_uid
    );
    let e = read_answer("u", 409, refused.as_bytes(), asked, &Auth::None).unwrap_err();
    let m = e.to_string();
    assert!(m.contains("refused") && m.contains("0xA900"), "{m}");
    let e = read_answer("u", 401, b"", asked, &Auth::None).unwrap_err();
    assert!(matches!(e, DicomWebError::Unauthorized { .. }), "{e}");
    let e = read_answer(
        "u",
        200,
        b"{\"00081199\":{\"vr\":\"SQ\"}}",
        asked,
        &Auth::None,
    )
    .unwrap_err();
    assert!(e.to_string().contains("not in the archive's answer"), "{e}");
    // A login page, an empty 202: not a success.
    let e = read_answer("u", 200, b"<html>log in</html>", asked, &Auth::None).unwrap_err();
    assert!(e.to_string().contains("is not DICOM JSON"), "{e}");
    assert!(read_answer("u", 202, b"", asked, &Auth::None).is_err());
    assert!(read_answer("u", 200, b"", asked, &Auth::None).is_ok());
    // A duplicate of our own instance (a rerun): already stored, said as a warning.
    let duplicate = refused.replace("43264", "273");
    let stored = read_answer("u", 409, duplicate.as_bytes(), asked, &Auth::None).unwrap();
    assert_eq!(stored.instances, vec![made.sop_instance_uid.clone()]);
    assert!(stored.warnings[0].contains("in the archive already"));
}
