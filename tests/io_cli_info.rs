//! `shapecast info` end to end: text and JSON output for a DICOM folder, and a one-line error
//! with a non-zero exit status for a file that is not a volume. Uses tests/data only.

mod common;

use std::process::Command;

fn shapecast() -> Command {
    Command::new(env!("CARGO_BIN_EXE_shapecast"))
}

#[test]
fn info_json_of_a_dicom_folder() {
    let dir = common::test_data("dicom/ct-head-64px");
    let out = shapecast()
        .arg("info")
        .arg(&dir)
        .arg("--json")
        .output()
        .expect("run shapecast");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).expect("one JSON object");
    assert_eq!(json["dims"], serde_json::json!([64, 64, 6]));
    assert_eq!(json["spacing_mm"][2], 1.5);
    assert_eq!(json["origin_mm"][2], 58.5);
    assert_eq!(
        json["direction"],
        serde_json::json!([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    );
    assert_eq!(json["modality"], "CT");
    for key in ["min", "max", "warnings"] {
        assert!(json.get(key).is_some(), "{key} missing");
    }
}

#[test]
fn info_text_of_a_pair() {
    let out = shapecast()
        .arg("info")
        .arg(common::test_data("analyze/ras.hdr"))
        .arg(common::test_data("analyze/ras.img"))
        .output()
        .expect("run shapecast");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("62 x 41 x 34"), "{text}");
    assert!(text.contains("i -> R, j -> A, k -> S"), "{text}");
}

#[test]
fn info_fails_with_one_line() {
    let bogus = common::test_data("README.md");
    let out = shapecast()
        .arg("info")
        .arg(&bogus)
        .output()
        .expect("run shapecast");
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(err.contains("README.md"), "{err}");
}
