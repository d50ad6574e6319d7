//! `shapecast info` end to end: text and JSON output for a DICOM folder, and a one-line error
//! with a non-zero exit status for a file that is not a volume. Uses tests/data only.

use crate::common;

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

#[test]
fn info_finds_the_data_file_beside_a_header() {
    // Only the header is named: its same-stem data file is read too, as `features` does.
    let out = shapecast()
        .arg("info")
        .arg(common::test_data("analyze/ras.hdr"))
        .output()
        .expect("run shapecast");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(String::from_utf8_lossy(&out.stdout).contains("62 x 41 x 34"));
}

/// A series folder with a FIFO (which blocked `info` forever), a link to /dev/zero (read until
/// memory ran out) and a link back to the folder (a loop that failed the whole folder).
#[cfg(unix)]
#[test]
fn info_of_a_folder_skips_fifos_device_links_and_loops() {
    let dir = std::env::temp_dir().join(format!("shapecast-info-hostile-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("temp folder");
    let series = common::test_data("dicom/ct-head-64px");
    for e in std::fs::read_dir(&series).expect("series") {
        let p = e.expect("entry").path();
        std::fs::copy(&p, dir.join(p.file_name().expect("name"))).expect("copy");
    }
    let have_fifo = Command::new("mkfifo")
        .arg(dir.join("pipe"))
        .status()
        .is_ok_and(|s| s.success());
    std::os::unix::fs::symlink("/dev/zero", dir.join("zero")).expect("symlink");
    std::os::unix::fs::symlink(&dir, dir.join("loop")).expect("symlink");
    let mut child = shapecast()
        .arg("info")
        .arg(&dir)
        .arg("--json")
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("run shapecast");
    let started = std::time::Instant::now();
    while child.try_wait().expect("wait").is_none() {
        if started.elapsed().as_secs() > 30 {
            let _ = child.kill();
            panic!("shapecast info hung on the folder");
        }
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
    let out = child.wait_with_output().expect("output");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).expect("one JSON object");
    assert_eq!(json["dims"], serde_json::json!([64, 64, 6]));
    assert!(err.contains("zero") && err.contains("loop"), "{err}");
    if have_fifo {
        assert!(err.contains("FIFO"), "{err}");
    } else {
        eprintln!("SKIPPED: the FIFO case (mkfifo not available)");
    }
    std::fs::remove_dir_all(&dir).expect("clean up");
}

/// A zipped DICOM folder (what a PACS export or a web server hands out) reads in every
/// subcommand as the viewer reads it: `info` of the zip says what `info` of the folder says.
#[test]
fn info_of_a_zipped_folder_is_info_of_the_folder() {
    use std::io::Write as _;
    let dir = common::test_data("dicom/ct-head-64px");
    let zip_path = std::env::temp_dir().join(format!("shapecast-info-{}.zip", std::process::id()));
    let mut names: Vec<_> = std::fs::read_dir(&dir)
        .expect("the folder")
        .map(|e| e.expect("an entry").path())
        .collect();
    names.sort();
    let mut zip = zip::ZipWriter::new(std::fs::File::create(&zip_path).expect("a temp file"));
    for p in &names {
        let name = format!("ct/{}", p.file_name().expect("a name").to_string_lossy());
        zip.start_file(
            name,
            zip::write::SimpleFileOptions::default()
                .compression_method(zip::CompressionMethod::Deflated),
        )
        .expect("an entry");
        zip.write_all(&std::fs::read(p).expect("the file"))
            .expect("written");
    }
    zip.finish().expect("the archive");
    let json_of = |path: &std::path::Path| {
        let out = shapecast()
            .arg("info")
            .arg(path)
            .arg("--json")
            .output()
            .expect("run shapecast");
        assert!(
            out.status.success(),
            "{}: {}",
            path.display(),
            String::from_utf8_lossy(&out.stderr)
        );
        let mut json: serde_json::Value =
            serde_json::from_slice(&out.stdout).expect("one JSON object");
        json["source"] = serde_json::Value::Null;
        json
    };
    let (folder, zipped) = (json_of(&dir), json_of(&zip_path));
    let _ = std::fs::remove_file(&zip_path);
    assert_eq!(folder["dims"], serde_json::json!([64, 64, 6]));
    assert_eq!(folder, zipped);
}
