//! Helpers shared by the io tests: finding ../shared/data and reading files as `InputFile`s.
#![allow(dead_code)]

use std::path::{Path, PathBuf};

use shapecast::io::InputFile;

/// `<CARGO_MANIFEST_DIR>/../shared/data/<rel>` when it exists. When it does not, a developer's
/// clone skips with a visible message; under CI=true (where ../shared is always present) a
/// missing file is a failure, so a broken checkout cannot pass as green.
pub fn shared_data(rel: &str) -> Option<PathBuf> {
    let p = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/data")
        .join(rel);
    if p.exists() {
        return Some(p);
    }
    if std::env::var("CI").is_ok_and(|v| v == "true") {
        panic!("CI=true but {} is not present", p.display());
    }
    eprintln!("SKIPPED: ../shared/data not present ({rel})");
    None
}

/// A file inside this repository's tests/data.
pub fn test_data(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data")
        .join(rel)
}

/// Reads one file as an `InputFile` named by its file name.
pub fn input(path: &Path) -> InputFile {
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let name = path
        .file_name()
        .map_or_else(String::new, |n| n.to_string_lossy().into_owned());
    InputFile::new(name, bytes)
}

/// Every file under a directory, recursively, named by its path relative to `dir`, sorted.
pub fn inputs_in(dir: &Path) -> Vec<InputFile> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for entry in std::fs::read_dir(&d).unwrap_or_else(|e| panic!("{}: {e}", d.display())) {
            let path = entry.expect("directory entry").path();
            if path.is_dir() {
                stack.push(path);
            } else {
                let rel = path
                    .strip_prefix(dir)
                    .unwrap_or(&path)
                    .to_string_lossy()
                    .into_owned();
                let bytes =
                    std::fs::read(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
                out.push(InputFile::new(rel, bytes));
            }
        }
    }
    out.sort_by(|a, b| a.name.cmp(&b.name));
    out
}
