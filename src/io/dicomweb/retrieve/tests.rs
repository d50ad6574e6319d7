use super::*;
use crate::io::dicom::synth::Slice;

const SERIES: &str = "1.2.826.0.1.3680043.10.7";

fn instances(n: i32) -> Vec<InstanceInfo> {
    (0..n)
        .map(|k| InstanceInfo {
            sop_uid: format!("{SERIES}.{k}"),
            ..InstanceInfo::default()
        })
        .collect()
}

fn retrieval(n: i32) -> Retrieval {
    Retrieval::new(
        Base::parse("http://127.0.0.1:1/dicom-web").unwrap(),
        "1.2.3",
        SERIES,
        instances(n),
        Auth::None,
        Limits::default(),
    )
    .unwrap()
}

/// A 401 without credentials: a final answer, never retried.
fn unauthorized() -> DicomWebError {
    DicomWebError::Unauthorized {
        status: 401,
        url: "u".to_owned(),
        credentials: None,
    }
}

fn part(bytes: Vec<u8>) -> Part {
    Part {
        index: 1,
        content_type: None,
        transfer_syntax: None,
        content_location: None,
        bytes,
    }
}

#[test]
fn instances_arrive_in_any_order_and_one_failure_is_retried() {
    let n = 4;
    let mut r = retrieval(n);
    let mut fetches: Vec<Fetch> = std::iter::from_fn(|| r.next_fetch()).collect();
    assert_eq!(fetches.len(), 4);
    assert!(
        fetches[2]
            .request
            .url
            .ends_with(&format!("/series/{SERIES}/instances/{SERIES}.2"))
    );
    assert!(fetches[2].label.starts_with("instance 3 of 4"));
    fetches.reverse();
    for f in &fetches {
        if f.id == 1 {
            let cut = DicomWebError::Multipart {
                what: f.label.clone(),
                message: "part 1 was cut short".to_owned(),
            };
            r.failed(f.id, cut).unwrap();
        } else {
            let s = Slice::axial(SERIES, f.id as i32, 2, 3);
            r.received(f.id, vec![part(s.bytes())]).unwrap();
        }
    }
    assert!(!r.is_complete());
    assert_eq!(r.progress().instances_done, 3);
    let again = r.next_fetch().unwrap();
    assert_eq!(again.id, 1);
    assert!(r.next_fetch().is_none());
    r.received(1, vec![part(Slice::axial(SERIES, 1, 2, 3).bytes())])
        .unwrap();
    assert!(r.is_complete());
    let p = r.progress();
    assert_eq!((p.instances_done, p.instances_total), (4, 4));
    assert_eq!(p.bytes_estimate, Some(p.bytes));
    let loaded = r.finish().unwrap();
    assert_eq!(loaded.volume.dims, [3, 2, 4]);
    assert_eq!(loaded.volume.value_at(0, 0, 1), 100.0 - 1024.0);
    assert!(
        loaded
            .volume
            .source
            .starts_with("DICOMweb http://127.0.0.1:1/dicom-web series")
    );
}

#[test]
fn a_second_failure_or_a_final_answer_ends_the_retrieval() {
    let mut r = retrieval(2);
    let f = r.next_fetch().unwrap();
    let busy = || DicomWebError::Http {
        url: "u".to_owned(),
        status: 503,
        reason: "Service Unavailable".to_owned(),
    };
    r.failed(f.id, busy()).unwrap();
    let _second = r.next_fetch().unwrap();
    let again = r.next_fetch().unwrap();
    assert_eq!(again.id, f.id);
    let e = r.failed(again.id, busy()).unwrap_err().to_string();
    assert!(
        e.starts_with(&format!("instance 1 of 2 ({SERIES}.0) failed 2 times")),
        "{e}"
    );

    let mut r = retrieval(2);
    let f = r.next_fetch().unwrap();
    let e = r.failed(f.id, unauthorized()).unwrap_err();
    assert!(matches!(e, DicomWebError::Unauthorized { .. }));
    assert!(
        r.next_fetch().is_some(),
        "the other instance is still queued"
    );
    assert!(r.finish().is_err(), "an incomplete retrieval has no volume");
}

#[test]
fn undecodable_instances_are_named_with_their_syntax() {
    let mut r = retrieval(1);
    let f = r.next_fetch().unwrap();
    let mut s = Slice::axial(SERIES, 0, 2, 2);
    s.transfer_syntax = "1.2.840.10008.1.2.4.80".to_owned();
    let e = crate::error::chain(&r.received(f.id, vec![part(s.bytes())]).unwrap_err());
    assert!(
        e.starts_with(&format!("instance 1 of 1 ({SERIES}.0): "))
            && e.contains("1.2.840.10008.1.2.4.80")
            && e.contains("JPEG-LS"),
        "{e}"
    );
    assert!(
        Retrieval::new(
            Base::parse("/x").unwrap(),
            "1.2",
            "3.4",
            Vec::new(),
            Auth::None,
            Limits::default()
        )
        .is_err()
    );
}

#[test]
fn instance_responses_check_status_then_parse() {
    let mut r = retrieval(1);
    let f = r.next_fetch().unwrap();
    let lim = r.multipart_limits();
    let e = InstanceResponse::start(&f, 404, None, &Auth::None, lim)
        .err()
        .unwrap();
    assert!(e.to_string().starts_with("instance 1 of 1"), "{e}");
    let ct = "multipart/related; type=\"application/dicom\"; boundary=BB";
    let mut resp = InstanceResponse::start(&f, 200, Some(ct), &Auth::None, lim).unwrap();
    resp.feed(b"--BB\r\n\r\nDICM").unwrap();
    resp.feed(b"\r\n--BB--").unwrap();
    let parts = resp.finish().unwrap();
    assert_eq!(parts[0].bytes, b"DICM");
    let mut cut = InstanceResponse::start(&f, 200, Some(ct), &Auth::None, lim).unwrap();
    cut.feed(b"--BB\r\n\r\nDIC").unwrap();
    let e = cut.finish().err().unwrap();
    assert!(e.is_retryable());
    assert!(e.to_string().contains("instance 1 of 1") && e.to_string().contains("cut short"));
}

#[test]
fn series_first_asks_once_then_only_for_what_its_answer_lacked() {
    let mut r = retrieval(4).series_first();
    let whole = r.next_fetch().unwrap();
    assert_eq!(whole.id, SERIES_FETCH);
    assert!(whole.request.url.ends_with(&format!("/series/{SERIES}")));
    assert!(
        whole
            .label
            .starts_with(&format!("series {SERIES} (4 instances)"))
    );
    assert!(
        r.next_fetch().is_none(),
        "instances wait for the series' answer"
    );
    // Instances 2 and 0 stream in; a part that names no listed instance is let go.
    for k in [2, 0] {
        r.received_part(part(Slice::axial(SERIES, k, 2, 3).bytes()))
            .unwrap();
    }
    let mut stranger = Slice::axial(SERIES, 9, 2, 3);
    stranger.sop_uid = "1.2.3.999".to_owned();
    r.received_part(part(stranger.bytes())).unwrap();
    r.received_part(part(b"not DICOM".to_vec())).unwrap();
    // A part given twice counts once.
    r.received_part(part(Slice::axial(SERIES, 0, 2, 3).bytes()))
        .unwrap();
    assert_eq!(r.progress().instances_done, 2);
    // The answer ends: what it lacked is asked for, one by one.
    r.received(SERIES_FETCH, Vec::new()).unwrap();
    let rest: Vec<Fetch> = std::iter::from_fn(|| r.next_fetch()).collect();
    assert_eq!(rest.iter().map(|f| f.id).collect::<Vec<_>>(), [1, 3]);
    for f in rest {
        r.received(
            f.id,
            vec![part(Slice::axial(SERIES, f.id as i32, 2, 3).bytes())],
        )
        .unwrap();
    }
    assert!(r.is_complete());
    let loaded = r.finish().unwrap();
    assert_eq!(loaded.volume.dims, [3, 2, 4]);
    assert_eq!(loaded.volume.value_at(0, 0, 3), 100.0 * 3.0 - 1024.0);
}

#[test]
fn a_refused_series_request_falls_back_to_instances_unless_unauthorized() {
    let mut r = retrieval(2).series_first();
    let whole = r.next_fetch().unwrap();
    let refused = DicomWebError::Http {
        url: whole.request.url.clone(),
        status: 406,
        reason: "Not Acceptable".to_owned(),
    };
    r.failed(whole.id, refused).unwrap();
    let ids: Vec<usize> = std::iter::from_fn(|| r.next_fetch())
        .map(|f| f.id)
        .collect();
    assert_eq!(ids, [0, 1]);

    let mut r = retrieval(2).series_first();
    let whole = r.next_fetch().unwrap();
    let e = r.failed(whole.id, unauthorized()).unwrap_err();
    assert!(matches!(e, DicomWebError::Unauthorized { .. }));
}

#[test]
fn a_part_is_named_by_its_file_meta_group() {
    let s = Slice::axial(SERIES, 5, 2, 2);
    assert_eq!(
        part_sop_uid(&s.bytes()).as_deref(),
        Some(&*format!("{SERIES}.5"))
    );
    let mut bytes = s.bytes();
    assert_eq!(
        part_sop_uid(&bytes[..140]),
        None,
        "cut inside the meta group"
    );
    bytes[128] = b'X';
    assert_eq!(part_sop_uid(&bytes), None, "no DICM magic");
    assert_eq!(part_sop_uid(b""), None);
    // A length running past the end is no UID, not a panic.
    let mut long = vec![0u8; 128];
    long.extend_from_slice(b"DICM\x02\x00\x03\x00UI\xff\xff1.2");
    assert_eq!(part_sop_uid(&long), None);
}

#[test]
fn a_busy_series_request_is_asked_again_once_and_a_403_falls_back() {
    let mut r = retrieval(2).series_first();
    let whole = r.next_fetch().unwrap();
    let busy = || DicomWebError::Busy {
        url: whole.request.url.clone(),
        status: 429,
        retry_after_s: Some(3),
    };
    r.failed(SERIES_FETCH, busy()).unwrap();
    let again = r.next_fetch().unwrap();
    assert_eq!(
        (again.id, again.delay),
        (SERIES_FETCH, std::time::Duration::from_secs(3))
    );
    assert!(
        r.next_fetch().is_none(),
        "instances wait for the series again"
    );
    // Busy a second time: the instances, each with its own answer.
    r.failed(SERIES_FETCH, busy()).unwrap();
    let ids: Vec<usize> = std::iter::from_fn(|| r.next_fetch())
        .map(|f| f.id)
        .collect();
    assert_eq!(ids, [0, 1]);

    // A gateway that forbids series retrieves (403) but serves instances.
    let mut r = retrieval(2).series_first();
    let whole = r.next_fetch().unwrap();
    let forbidden = DicomWebError::Unauthorized {
        status: 403,
        url: whole.request.url.clone(),
        credentials: None,
    };
    r.failed(SERIES_FETCH, forbidden).unwrap();
    let ids: Vec<usize> = std::iter::from_fn(|| r.next_fetch())
        .map(|f| f.id)
        .collect();
    assert_eq!(ids, [0, 1]);
}
