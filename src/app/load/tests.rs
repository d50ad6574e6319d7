use super::*;

fn run(mut job: LoadJob) -> (Vec<String>, Result<Box<Loaded>, AppError>) {
    let mut said = Vec::new();
    for _ in 0..1000 {
        match job.step() {
            LoadStep::Working { what, fraction } => {
                assert!((0.0..=1.0).contains(&fraction));
                said.push(what);
            }
            LoadStep::Done(l) => return (said, Ok(l)),
            LoadStep::Failed(e) => return (said, Err(e)),
        }
    }
    panic!("the job never finished");
}

/// A small sphere phantom and its NIfTI file.
fn sphere_nii() -> (crate::volume::Volume, Vec<u8>) {
    let volume = crate::phantom::Phantom::by_name("sphere", None)
        .unwrap()
        .render([2.0; 3]);
    let bytes = crate::io::nifti::write_volume("s.nii", &volume).unwrap();
    (volume, bytes)
}

/// Runs the load of one file `name`.
fn run_file(name: &str, bytes: Vec<u8>) -> (Vec<String>, Result<Box<Loaded>, AppError>) {
    run(LoadJob::new(LoadSource::Files {
        label: name.into(),
        files: vec![InputFile::new(name, bytes)],
    }))
}

#[test]
fn decoding_is_announced_before_it_runs() {
    let (volume, bytes) = sphere_nii();
    let (said, r) = run_file("s.nii", bytes);
    assert_eq!(said, vec!["decoding s.nii".to_owned()]);
    assert_eq!(r.unwrap().volume.dims, volume.dims);
}

/// A zip archive holding `bytes` as `name`.
fn zip_of(name: &str, bytes: &[u8]) -> Vec<u8> {
    use std::io::Write as _;
    let mut w = ::zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
    w.start_file(name, ::zip::write::SimpleFileOptions::default())
        .unwrap();
    w.write_all(bytes).unwrap();
    w.finish().unwrap().into_inner()
}

/// The sphere of `sphere_nii`, loaded from `s.zip/scan/s.nii`.
fn the_sphere_from_the_zip(r: Result<Box<Loaded>, AppError>, volume: &Volume) {
    let loaded = r.unwrap();
    assert_eq!(loaded.volume.dims, volume.dims);
    let source = &loaded.volume.source;
    assert!(source.contains("s.zip/scan/s.nii"), "{source}");
}

#[test]
fn a_zip_archive_is_unpacked_and_loaded() {
    let (volume, nii) = sphere_nii();
    let zip = zip_of("scan/s.nii", &nii);
    let (_, r) = run_file("s.zip", zip);
    the_sphere_from_the_zip(r, &volume);
}

#[test]
fn a_zip_archive_on_disk_is_read_on_demand_and_unpacked() {
    let (volume, nii) = sphere_nii();
    let zip = zip_of("scan/s.nii", &nii);
    let dir = std::env::temp_dir().join(format!("shapecast-load-zip-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("s.zip");
    std::fs::write(&path, zip).unwrap();
    let (_, r) = run(LoadJob::new(LoadSource::Paths(vec![path])));
    the_sphere_from_the_zip(r, &volume);
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn errors_name_the_file() {
    let (_, r) = run(LoadJob::new(LoadSource::Files {
        label: "x".into(),
        files: vec![InputFile::new("broken.nii", vec![7; 400])],
    }));
    let e = r.unwrap_err();
    assert!(
        matches!(&e, AppError::Load(crate::io::LoadError::UnknownFormat { file, .. }) if file == "broken.nii"),
        "{e:?}"
    );
    let (_, r) = run(LoadJob::new(LoadSource::Phantom("no-such".into())));
    assert!(matches!(r.unwrap_err(), AppError::UnknownPhantom { name, .. } if name == "no-such"));
}

#[test]
fn folders_are_walked_and_missing_paths_named() {
    let dir = std::env::temp_dir().join(format!("shapecast-load-{}", std::process::id()));
    let sub = dir.join("sub");
    std::fs::create_dir_all(&sub).unwrap();
    let volume = crate::phantom::Phantom::by_name("sphere", None)
        .unwrap()
        .render([2.0; 3]);
    let bytes = crate::io::nifti::write_volume("a.nii", &volume).unwrap();
    std::fs::write(sub.join("a.nii"), bytes).unwrap();
    std::fs::write(dir.join(".hidden"), b"x").unwrap();
    #[cfg(unix)]
    std::os::unix::fs::symlink("/dev/zero", dir.join("zero")).unwrap();
    let (said, r) = run(LoadJob::new(LoadSource::Paths(vec![dir.clone()])));
    assert!(
        said.iter().any(|s| s.starts_with("reading 1 files")),
        "{said:?}"
    );
    let loaded = r.unwrap();
    assert_eq!(loaded.volume.dims, volume.dims);
    #[cfg(unix)]
    assert!(
        loaded
            .notes
            .iter()
            .any(|n| n.contains("zero") && n.contains("skipped")),
        "{:?}",
        loaded.notes
    );
    let missing = dir.join("missing.nii");
    let (_, r) = run(LoadJob::new(LoadSource::Paths(vec![missing])));
    let e = r.unwrap_err();
    assert!(
        matches!(&e, AppError::Files(crate::files::FilesError::Open { path, source })
            if path.ends_with("missing.nii") && source.kind() == std::io::ErrorKind::NotFound),
        "{e:?}"
    );
    assert!(e.message().contains("missing.nii"), "{}", e.message());
    std::fs::remove_dir_all(&dir).unwrap();
}
