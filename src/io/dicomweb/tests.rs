use super::*;

#[test]
fn bases_absolute_and_relative() {
    let b = Base::parse("http://127.0.0.1:8042/dicom-web/").unwrap();
    assert_eq!(b.as_str(), "http://127.0.0.1:8042/dicom-web");
    assert_eq!(b.host(), Some("127.0.0.1:8042"));
    assert!(!b.is_relative());
    assert_eq!(
        b.instance_url("1.2", "1.2.3", "4.5").unwrap(),
        "http://127.0.0.1:8042/dicom-web/studies/1.2/series/1.2.3/instances/4.5"
    );
    assert_eq!(
        b.study_query("1.2").unwrap(),
        "http://127.0.0.1:8042/dicom-web/studies?StudyInstanceUID=1.2"
    );
    assert_eq!(
        b.series_query("1.2").unwrap(),
        "http://127.0.0.1:8042/dicom-web/studies/1.2/series?includefield=00180050"
    );
    let r = Base::parse("/dicom-web").unwrap();
    assert!(r.is_relative());
    assert_eq!(r.host(), None);
    assert_eq!(
        r.instances_query("1.2", "3").unwrap(),
        "/dicom-web/studies/1.2/series/3/instances"
    );
    assert_eq!(
        Base::parse("HTTPS://pacs.example/wado").unwrap().host(),
        Some("pacs.example")
    );
    for bad in [
        "",
        "dicom-web",
        "//host/x",
        "ftp://x",
        "http://",
        "http://u:p@host/x",
        "http://host/x?y=1",
        "http://host/a b",
        "http://host/#x",
    ] {
        let e = Base::parse(bad).unwrap_err();
        assert!(matches!(e, DicomWebError::InvalidBase { .. }), "{bad}: {e}");
    }
}

#[test]
fn a_url_into_a_study_or_series_is_split_into_root_study_and_series() {
    let s = |u: &str| split_target(u);
    assert_eq!(
        s("http://h:8042/dicom-web"),
        ("http://h:8042/dicom-web".to_owned(), None, None)
    );
    assert_eq!(
        s("https://h/dw/studies/1.2.3/"),
        ("https://h/dw".to_owned(), Some("1.2.3".to_owned()), None)
    );
    assert_eq!(
        s("https://h/dw/studies/1.2.3/series/4.5/instances/6.7"),
        (
            "https://h/dw".to_owned(),
            Some("1.2.3".to_owned()),
            Some("4.5".to_owned())
        )
    );
    assert_eq!(
        s("/dicom-web/studies/1.2.3/series/4.5"),
        (
            "/dicom-web".to_owned(),
            Some("1.2.3".to_owned()),
            Some("4.5".to_owned())
        )
    );
    // Not a UID after /studies/: left as it is (Base::parse says what is wrong).
    assert_eq!(
        s("https://h/studies/x"),
        ("https://h/studies/x".to_owned(), None, None)
    );
}

#[test]
fn study_searches_are_checked_and_encoded() {
    let b = Base::parse("/dicom-web").unwrap();
    assert_eq!(
        b.study_search(&StudySearch::default()).unwrap(),
        "/dicom-web/studies?limit=100"
    );
    assert_eq!(
        b.study_search(&StudySearch {
            offset: 200,
            ..Default::default()
        })
        .unwrap(),
        "/dicom-web/studies?limit=100&offset=200"
    );
    let s = StudySearch {
        patient_id: " Lung_Dx A0002* ".to_owned(),
        patient_name: "DOE^J*".to_owned(),
        accession_number: "a&b=c?".to_owned(),
        modality: " pt ".to_owned(),
        study_date: "20070101-".to_owned(),
        offset: 0,
    };
    assert_eq!(
        b.study_search(&s).unwrap(),
        "/dicom-web/studies?PatientID=Lung_Dx%20A0002*&PatientName=DOE%5EJ*&AccessionNumber=a%26b%3Dc%3F&ModalitiesInStudy=PT&StudyDate=20070101-&limit=100"
    );
    let e = b
        .study_search(&StudySearch {
            modality: "CT&MR".to_owned(),
            ..StudySearch::default()
        })
        .unwrap_err()
        .to_string();
    assert!(e.contains("modality"), "{e}");
    for (date, ok) in [
        ("20070425", true),
        ("-20070425", true),
        ("20070101-20071231", true),
        ("2007-04-25", false),
        ("-", false),
        ("2007042", false),
        ("yesterday", false),
    ] {
        let s = StudySearch {
            study_date: date.to_owned(),
            ..StudySearch::default()
        };
        assert_eq!(b.study_search(&s).is_ok(), ok, "{date}");
    }
    let e = b
        .study_search(&StudySearch {
            patient_id: "a\nb".to_owned(),
            ..StudySearch::default()
        })
        .unwrap_err()
        .to_string();
    assert!(e.contains("patient ID") && e.contains("control"), "{e}");
    let long = StudySearch {
        accession_number: "x".repeat(65),
        ..StudySearch::default()
    };
    assert!(
        b.study_search(&long)
            .unwrap_err()
            .to_string()
            .contains("accession number")
    );
}

#[test]
fn uids_are_digits_and_dots_only() {
    assert_eq!(check_uid("x", "1.2.840.10008\0").unwrap(), "1.2.840.10008");
    for bad in [
        "",
        "1.2/../3",
        "1.2.3a",
        ".1",
        "1.",
        "1..2",
        &"1".repeat(65),
        "1 2",
    ] {
        assert!(check_uid("x", bad).is_err(), "{bad}");
    }
    let e = Base::parse("http://h")
        .unwrap()
        .instance_url("1.2", "../../x", "3")
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("SeriesInstanceUID") && e.contains("../../x"),
        "{e}"
    );
}

#[test]
fn credentials_headers_and_redaction() {
    assert_eq!(base64(b""), "");
    assert_eq!(base64(b"f"), "Zg==");
    assert_eq!(base64(b"fo"), "Zm8=");
    assert_eq!(base64(b"foo"), "Zm9v");
    assert_eq!(base64(b"foob"), "Zm9vYg==");
    assert_eq!(
        Auth::basic("Aladdin:open sesame")
            .unwrap()
            .header()
            .unwrap(),
        "Basic QWxhZGRpbjpvcGVuIHNlc2FtZQ=="
    );
    let t = Auth::bearer(" abc.def ").unwrap();
    assert_eq!(t.header().unwrap(), "Bearer abc.def");
    assert!(!format!("{t:?}").contains("abc"));
    assert!(Auth::bearer("a\r\nX-Evil: 1").is_err());
    assert!(Auth::bearer("").is_err());
    assert!(Auth::basic("nopassword").is_err());
    assert!(Auth::basic(":p").is_err());
    let r = Request::wado("http://h/x".to_owned(), &t);
    assert!(
        r.headers
            .iter()
            .any(|(k, v)| *k == "Authorization" && v == "Bearer abc.def")
    );
    assert!(
        Request::qido("u".to_owned(), &Auth::None)
            .headers
            .iter()
            .all(|(k, _)| *k != "Authorization")
    );
}

#[test]
fn accept_lists_what_this_build_decodes_explicit_le_last() {
    let a = wado_accept();
    let ranges: Vec<&str> = a.split(", ").collect();
    assert!(ranges.len() >= 5, "{a}");
    assert!(ranges.iter().all(|r| {
        r.starts_with("multipart/related; type=\"application/dicom\"; transfer-syntax=")
    }));
    assert!(
        ranges
            .last()
            .unwrap()
            .ends_with("transfer-syntax=1.2.840.10008.1.2.1")
    );
    assert!(a.contains("1.2.840.10008.1.2.5; q=0.9"), "{a}");
    assert!(
        !a.contains("1.2.840.10008.1.2.4.80"),
        "JPEG-LS is not decoded: {a}"
    );
    assert!(!a.contains('*'));
}

#[test]
fn statuses_become_messages() {
    let e = check_status(401, "http://h/x", "study 1", &Auth::None).unwrap_err();
    assert!(e.to_string().contains("asks for credentials"), "{e}");
    assert!(!e.is_retryable());
    let e = check_status(403, "u", "s", &Auth::Bearer("t".to_owned())).unwrap_err();
    let m = e.to_string();
    assert!(
        m.contains("403") && m.contains("did not accept the bearer token"),
        "{m}"
    );
    assert!(!m.contains(" t "), "{m}");
    let e = check_status(404, "u", "study 9.9", &Auth::None).unwrap_err();
    assert_eq!(e.to_string(), "study 9.9 not found (u)");
    assert!(
        check_status(406, "u", "s", &Auth::None)
            .unwrap_err()
            .to_string()
            .contains("1.2.840.10008.1.2.1")
    );
    assert!(
        check_status(503, "u", "s", &Auth::None)
            .unwrap_err()
            .is_retryable()
    );
    // A busy answer: its Retry-After is honoured up to a limit, else the wait doubles.
    let busy = check_status(429, "u", "s", &Auth::None)
        .unwrap_err()
        .with_retry_after(Some(" 5 "));
    assert!(busy.to_string().contains("asked to wait 5 s"), "{busy}");
    assert_eq!(backoff(1, &busy), std::time::Duration::from_secs(5));
    let long = check_status(503, "u", "s", &Auth::None)
        .unwrap_err()
        .with_retry_after(Some("86400"));
    assert_eq!(backoff(1, &long), MAX_RETRY_AFTER);
    let dated = check_status(503, "u", "s", &Auth::None)
        .unwrap_err()
        .with_retry_after(Some("Wed, 21 Oct 2026 07:28:00 GMT"));
    let ms = |a| backoff(a, &dated).as_millis();
    assert_eq!((ms(1), ms(2), ms(3), ms(9)), (500, 1000, 2000, 8000));
    assert!(
        !check_status(400, "u", "s", &Auth::None)
            .unwrap_err()
            .is_retryable()
    );
    assert!(check_status(204, "u", "s", &Auth::None).is_ok());
}
