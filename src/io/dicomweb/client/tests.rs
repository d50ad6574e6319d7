use super::*;
use crate::io::dicom::synth::Slice;
use std::collections::HashMap;
use std::sync::atomic::AtomicUsize;

const STUDY: &str = "1.2.826.0.1.3680043.10.9";
const SERIES: &str = "1.2.826.0.1.3680043.10.9.1";

/// An archive in memory: QIDO answers and instances by URL; the first request of each
/// URL in `flaky` is cut short.
struct FakeArchive {
    answers: HashMap<String, (u16, String, Vec<u8>)>,
    flaky: Vec<String>,
    /// URLs whose first request is answered 429 with Retry-After: 1.
    busy: Vec<String>,
    seen: Mutex<Vec<String>>,
    in_flight: AtomicUsize,
    most_in_flight: AtomicUsize,
}

impl Transport for FakeArchive {
    fn get(&self, request: &Request) -> Result<HttpResponse, DicomWebError> {
        let now = self.in_flight.fetch_add(1, Ordering::SeqCst) + 1;
        self.most_in_flight.fetch_max(now, Ordering::SeqCst);
        std::thread::sleep(Duration::from_millis(5));
        self.in_flight.fetch_sub(1, Ordering::SeqCst);
        let first_time = {
            let mut seen = self.seen.lock().unwrap();
            let first = !seen.contains(&request.url);
            seen.push(request.url.clone());
            first
        };
        let Some((status, ct, body)) = self.answers.get(&request.url) else {
            return Ok(HttpResponse {
                status: 404,
                content_type: None,
                retry_after: None,
                body: Box::new(std::io::empty()),
            });
        };
        let mut body = body.clone();
        if first_time && self.flaky.contains(&request.url) {
            body.truncate(body.len() / 2);
        }
        if first_time && self.busy.contains(&request.url) {
            return Ok(HttpResponse {
                status: 429,
                content_type: None,
                retry_after: Some("1".to_owned()),
                body: Box::new(std::io::empty()),
            });
        }
        Ok(HttpResponse {
            status: *status,
            content_type: Some(ct.clone()),
            retry_after: None,
            body: Box::new(std::io::Cursor::new(body)),
        })
    }
}

fn archive(n: i32) -> FakeArchive {
    let base = "http://archive/dw";
    let mut answers = HashMap::new();
    let json = |v: serde_json::Value| {
        (
            200,
            "application/dicom+json".to_owned(),
            serde_json::to_vec(&v).unwrap(),
        )
    };
    answers.insert(
        format!("{base}/studies?StudyInstanceUID={STUDY}"),
        json(serde_json::json!([{"0020000D": {"vr": "UI", "Value": [STUDY]}}])),
    );
    answers.insert(
            format!("{base}/studies/{STUDY}/series?includefield=00180050"),
            json(serde_json::json!([
                {"0020000E": {"vr": "UI", "Value": ["1.2.3"]}, "00080060": {"vr": "CS", "Value": ["SR"]}, "00201209": {"vr": "IS", "Value": [1]}},
                {"0020000E": {"vr": "UI", "Value": [SERIES]}, "00080060": {"vr": "CS", "Value": ["CT"]}, "00201209": {"vr": "IS", "Value": [n]}}
            ])),
        );
    let list: Vec<serde_json::Value> = (0..n)
        .map(|k| serde_json::json!({"00080018": {"vr": "UI", "Value": [format!("{SERIES}.{k}")]}}))
        .collect();
    answers.insert(
        format!("{base}/studies/{STUDY}/series/{SERIES}/instances"),
        json(serde_json::Value::Array(list)),
    );
    for k in 0..n {
        let dicom = Slice::axial(SERIES, k, 4, 5).bytes();
        let mut body = b"--XX\r\nContent-Type: application/dicom\r\n\r\n".to_vec();
        body.extend_from_slice(&dicom);
        body.extend_from_slice(b"\r\n--XX--");
        answers.insert(
            format!("{base}/studies/{STUDY}/series/{SERIES}/instances/{SERIES}.{k}"),
            (
                200,
                "multipart/related; type=\"application/dicom\"; boundary=XX".to_owned(),
                body,
            ),
        );
    }
    FakeArchive {
        answers,
        flaky: Vec::new(),
        busy: Vec::new(),
        seen: Mutex::new(Vec::new()),
        in_flight: AtomicUsize::new(0),
        most_in_flight: AtomicUsize::new(0),
    }
}

fn client(a: FakeArchive) -> Client<FakeArchive> {
    Client::with_transport(a, Base::parse("http://archive/dw").unwrap(), Auth::None)
}

#[test]
fn resolves_and_retrieves_with_requests_in_flight_and_a_retry() {
    let mut a = archive(12);
    a.flaky = vec![format!(
        "http://archive/dw/studies/{STUDY}/series/{SERIES}/instances/{SERIES}.5"
    )];
    let c = client(a).with_parallel(3);
    let r = c.resolve(STUDY, None).unwrap();
    assert_eq!(r.series[r.chosen].series_uid, SERIES);
    assert!(r.by_chooser);
    let mut reports = Vec::new();
    let loaded = c
        .retrieve(STUDY, SERIES, &mut |p| reports.push(*p))
        .unwrap();
    assert_eq!(loaded.volume.dims, [5, 4, 12]);
    assert_eq!(loaded.volume.value_at(2, 1, 7), (700 + 7) as f32 - 1024.0);
    assert_eq!(reports.last().unwrap().instances_done, 12);
    let most = c.transport.most_in_flight.load(Ordering::SeqCst);
    assert!((2..=3).contains(&most), "in flight at once: {most}");
    let seen = c.transport.seen.lock().unwrap();
    assert_eq!(
        seen.iter().filter(|u| u.ends_with(".5")).count(),
        2,
        "retried once"
    );
}

/// An archive that answers 429 with Retry-After: 1 to an instance and to the instance list
/// is asked again after the wait it asked for, and the series opens.
#[test]
fn a_busy_archive_is_asked_again_after_its_retry_after() {
    let mut a = archive(4);
    let list = format!("http://archive/dw/studies/{STUDY}/series/{SERIES}/instances");
    let instance = format!("{list}/{SERIES}.2");
    a.busy = vec![list.clone(), instance.clone()];
    let c = client(a);
    let started = std::time::Instant::now();
    let loaded = c.retrieve(STUDY, SERIES, &mut |_| {}).unwrap();
    assert_eq!(loaded.volume.dims, [5, 4, 4]);
    // Two waits of the 1 s asked for, one after the other (the list, then the instance).
    assert!(
        started.elapsed() >= Duration::from_secs(2),
        "{:?}",
        started.elapsed()
    );
    let seen = c.transport.seen.lock().unwrap();
    assert_eq!(seen.iter().filter(|u| **u == instance).count(), 2);
    assert_eq!(seen.iter().filter(|u| **u == list).count(), 2);
}

#[test]
fn named_series_missing_study_and_failures_are_messages() {
    let c = client(archive(2));
    let r = c.resolve(STUDY, Some("1.2.3")).unwrap();
    assert!(!r.by_chooser);
    let e = c.resolve(STUDY, Some("9.9")).unwrap_err().to_string();
    assert!(e.contains("has no series 9.9") && e.contains(SERIES), "{e}");
    let e = c.resolve("7.7.7", None).unwrap_err().to_string();
    assert!(e.starts_with("study 7.7.7 not found"), "{e}");

    // An instance cut short every time fails with its name after two attempts.
    let mut a = archive(3);
    let url = format!("http://archive/dw/studies/{STUDY}/series/{SERIES}/instances/{SERIES}.1");
    a.answers.get_mut(&url).unwrap().2.truncate(100);
    let e = crate::error::chain(&client(a).retrieve(STUDY, SERIES, &mut |_| {}).unwrap_err());
    assert!(
        e.starts_with(&format!("instance 2 of 3 ({SERIES}.1) failed 2 times"))
            && e.contains("cut short"),
        "{e}"
    );
}

/// An archive that caps its QIDO answers (5 of 12 instances): the series metadata gives
/// the rest and the whole series opens; without metadata or pages it is refused, never
/// opened in part.
#[test]
fn a_capped_instance_list_is_completed_or_the_series_refused() {
    let mut a = archive(12);
    let instances = format!("http://archive/dw/studies/{STUDY}/series/{SERIES}/instances");
    let full = a.answers[&instances].clone();
    let all: serde_json::Value = serde_json::from_slice(&full.2).unwrap();
    let capped = serde_json::Value::Array(all.as_array().unwrap()[..5].to_vec());
    a.answers.get_mut(&instances).unwrap().2 = serde_json::to_vec(&capped).unwrap();
    a.answers.insert(
        format!("http://archive/dw/studies/{STUDY}/series/{SERIES}/metadata"),
        full,
    );
    let loaded = client(a).retrieve(STUDY, SERIES, &mut |_| {}).unwrap();
    assert_eq!(loaded.volume.dims, [5, 4, 12]);

    let mut a = archive(12);
    a.answers.get_mut(&instances).unwrap().2 = serde_json::to_vec(&capped).unwrap();
    let e = client(a).retrieve(STUDY, SERIES, &mut |_| {}).unwrap_err();
    assert!(
        matches!(
            e,
            DicomWebError::Incomplete {
                listed: 5,
                expected: 12,
                ..
            }
        ),
        "{e}"
    );
}

/// An archive that gives the whole series in one answer: one request for it, decoded as it
/// streams, and only the instance its answer lacked asked for on its own.
#[test]
fn a_series_answer_is_decoded_as_it_streams_and_only_its_gaps_are_asked_for() {
    let mut a = archive(6);
    let series_url = format!("http://archive/dw/studies/{STUDY}/series/{SERIES}");
    let mut body = Vec::new();
    for k in [0, 1, 2, 4, 5] {
        body.extend_from_slice(b"--XX\r\nContent-Type: application/dicom\r\n\r\n");
        body.extend_from_slice(&Slice::axial(SERIES, k, 4, 5).bytes());
        body.extend_from_slice(b"\r\n");
    }
    body.extend_from_slice(b"--XX--");
    a.answers.insert(
        series_url.clone(),
        (
            200,
            "multipart/related; type=\"application/dicom\"; boundary=XX".to_owned(),
            body,
        ),
    );
    let c = client(a);
    let mut reports = Vec::new();
    let loaded = c
        .retrieve(STUDY, SERIES, &mut |p| reports.push(*p))
        .unwrap();
    assert_eq!(loaded.volume.dims, [5, 4, 6]);
    assert_eq!(loaded.volume.value_at(2, 1, 3), (300 + 7) as f32 - 1024.0);
    // Progress came part by part while the one answer streamed (five parts, then the gap).
    assert!(reports.len() >= 6, "{} reports", reports.len());
    let seen = c.transport.seen.lock().unwrap();
    assert_eq!(seen.iter().filter(|u| **u == series_url).count(), 1);
    let instances: Vec<&String> = seen.iter().filter(|u| u.contains("/instances/")).collect();
    assert_eq!(instances, [&format!("{series_url}/instances/{SERIES}.3")]);
}

/// A part of the series' answer that cannot be decoded ends the retrieval with its error while
/// the rest of the answer is still streaming: the request thread blocked handing on parts is
/// let go, never left waiting (it was, with more parts behind than the channel holds).
#[test]
fn a_bad_part_mid_stream_ends_the_retrieval_without_hanging() {
    let mut a = archive(12);
    let series_url = format!("http://archive/dw/studies/{STUDY}/series/{SERIES}");
    let mut body = Vec::new();
    for k in 0..12 {
        let mut s = Slice::axial(SERIES, k, 4, 5);
        if k == 1 {
            s.transfer_syntax = "1.2.840.10008.1.2.4.80".to_owned();
        }
        body.extend_from_slice(b"--XX\r\nContent-Type: application/dicom\r\n\r\n");
        body.extend_from_slice(&s.bytes());
        body.extend_from_slice(b"\r\n");
    }
    body.extend_from_slice(b"--XX--");
    a.answers.insert(
        series_url,
        (
            200,
            "multipart/related; type=\"application/dicom\"; boundary=XX".to_owned(),
            body,
        ),
    );
    let c = client(a).with_parallel(2);
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let result = c.retrieve(STUDY, SERIES, &mut |_| {}).map(|_| ());
        let _ = tx.send(result.map_err(|e| crate::error::chain(&e)));
    });
    let result = rx
        .recv_timeout(Duration::from_secs(60))
        .expect("the retrieval hangs");
    let e = result.unwrap_err();
    assert!(e.contains("1.2.840.10008.1.2.4.80"), "{e}");
}
