//! The user's paths read natively (the CLI's subcommands and the viewer's folder drops share
//! this): files and folders walked recursively in name order, taking only regular files. Inside
//! a folder a symlink is followed only to a regular file (never into a directory, so no loop and
//! no walk outside the folder); FIFOs, sockets and devices are skipped (a FIFO would block the
//! read forever, /dev/zero never ends); each file's size is checked against [`MAX_FILE_BYTES`]
//! before it is read. What is skipped is reported, never silently dropped. `src/io` never sees
//! a path: it gets the bytes.

use std::io::Read as _;
use std::path::{Path, PathBuf};

/// Largest single file read (the voxel cap of `io::Limits` plus room for headers and any
/// stored type wider than the voxels' own; larger files are refused before reading).
pub const MAX_FILE_BYTES: u64 = 8 << 30;

/// Nesting of folders walked at most (real series are a few levels deep).
const MAX_FOLDER_DEPTH: usize = 32;

/// The regular files found under the given paths, with their sizes, and what was skipped.
#[derive(Debug, Default)]
pub struct Listing {
    pub files: Vec<(PathBuf, u64)>,
    pub skipped: Vec<String>,
}

/// Why the given paths could not be listed.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum FilesError {
    #[error("{path}: cannot open")]
    Open {
        path: String,
        #[source]
        source: std::io::Error,
    },
    #[error("{path}: not a regular file or folder ({kind})")]
    NotAFile { path: String, kind: &'static str },
    #[error("{path}: cannot list the folder")]
    List {
        path: String,
        #[source]
        source: std::io::Error,
    },
    #[error("{path}: the folder holds no files{detail}")]
    EmptyFolder { path: String, detail: String },
    #[error("{path}: {bytes} bytes is more than the {limit} bytes a file may have")]
    TooLarge {
        path: String,
        bytes: u64,
        limit: u64,
    },
    #[error("{path}: cannot read")]
    Read {
        path: String,
        #[source]
        source: std::io::Error,
    },
}

fn kind_of(t: std::fs::FileType) -> &'static str {
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt as _;
        if t.is_fifo() {
            return "a FIFO";
        }
        if t.is_socket() {
            return "a socket";
        }
        if t.is_char_device() || t.is_block_device() {
            return "a device";
        }
    }
    if t.is_symlink() {
        "a symbolic link"
    } else if t.is_dir() {
        "a folder"
    } else if t.is_file() {
        "a regular file"
    } else {
        "not a regular file"
    }
}

/// Lists the given paths: a given file is taken as it is (it must be a regular file, possibly
/// through a symlink the user named); a given folder is walked. A header given as a file
/// (.hdr, .nhdr, .mhd) brings the files beside it that share its stem (ras.hdr + ras.img,
/// x.nhdr + x.raw.gz), as the loader needs its data file.
pub fn list(paths: &[PathBuf]) -> Result<Listing, FilesError> {
    let mut listing = Listing::default();
    for p in paths {
        let meta = std::fs::metadata(p).map_err(|e| FilesError::Open {
            path: p.display().to_string(),
            source: e,
        })?;
        if meta.is_dir() {
            let before = listing.files.len();
            walk(p, 0, &mut listing)?;
            if listing.files.len() == before {
                let detail = if listing.skipped.is_empty() {
                    String::new()
                } else {
                    format!(" it can read ({})", listing.skipped.join("; "))
                };
                return Err(FilesError::EmptyFolder {
                    path: p.display().to_string(),
                    detail,
                });
            }
        } else if meta.is_file() {
            check_size(p, meta.len())?;
            listing.files.push((p.clone(), meta.len()));
            add_companions(p, &mut listing);
        } else {
            return Err(FilesError::NotAFile {
                path: p.display().to_string(),
                kind: kind_of(meta.file_type()),
            });
        }
    }
    // A companion may also have been given or found in a folder: keep the first of each.
    let mut seen = std::collections::HashSet::new();
    listing.files.retain(|(p, _)| seen.insert(p.clone()));
    Ok(listing)
}

fn check_size(path: &Path, bytes: u64) -> Result<(), FilesError> {
    if bytes > MAX_FILE_BYTES {
        return Err(FilesError::TooLarge {
            path: path.display().to_string(),
            bytes,
            limit: MAX_FILE_BYTES,
        });
    }
    Ok(())
}

fn walk(dir: &Path, depth: usize, listing: &mut Listing) -> Result<(), FilesError> {
    if depth > MAX_FOLDER_DEPTH {
        listing.skipped.push(format!(
            "{}: skipped (folders nested more than {MAX_FOLDER_DEPTH} deep)",
            dir.display()
        ));
        return Ok(());
    }
    let mut entries: Vec<std::fs::DirEntry> = std::fs::read_dir(dir)
        .map_err(|e| FilesError::List {
            path: dir.display().to_string(),
            source: e,
        })?
        .filter_map(Result::ok)
        // Hidden files (.DS_Store, ._x) are never part of a series.
        .filter(|e| !e.file_name().to_string_lossy().starts_with('.'))
        .collect();
    entries.sort_by_key(std::fs::DirEntry::file_name);
    for e in entries {
        let path = e.path();
        // The entry's own type: a symlink is not followed by this call.
        let Ok(t) = e.file_type() else {
            listing.skipped.push(format!(
                "{}: skipped (cannot tell its type)",
                path.display()
            ));
            continue;
        };
        if t.is_dir() {
            walk(&path, depth + 1, listing)?;
        } else if t.is_file() {
            match e.metadata() {
                Ok(m) if m.len() > MAX_FILE_BYTES => listing.skipped.push(format!(
                    "{}: skipped ({} bytes, more than the {MAX_FILE_BYTES} a file may have)",
                    path.display(),
                    m.len()
                )),
                Ok(m) => listing.files.push((path, m.len())),
                Err(err) => listing
                    .skipped
                    .push(format!("{}: skipped ({err})", path.display())),
            }
        } else if t.is_symlink() {
            // Followed only to a regular file; a link to a folder (a loop, or a walk out of
            // the folder), to a device or to nothing is skipped.
            match std::fs::metadata(&path) {
                Ok(m) if m.is_file() && m.len() <= MAX_FILE_BYTES => {
                    listing.files.push((path, m.len()));
                }
                Ok(m) if m.is_file() => listing.skipped.push(format!(
                    "{}: skipped (links to a file of {} bytes, more than the {MAX_FILE_BYTES} a file may have)",
                    path.display(),
                    m.len()
                )),
                Ok(m) => listing.skipped.push(format!(
                    "{}: skipped (a symbolic link to {}; only links to regular files are followed)",
                    path.display(),
                    kind_of(m.file_type())
                )),
                Err(err) => listing.skipped.push(format!(
                    "{}: skipped (a symbolic link that cannot be followed: {err})",
                    path.display()
                )),
            }
        } else {
            listing.skipped.push(format!(
                "{}: skipped ({}, not a regular file)",
                path.display(),
                kind_of(t)
            ));
        }
    }
    Ok(())
}

/// Regular files beside a header file that share its stem.
fn add_companions(path: &Path, listing: &mut Listing) {
    let name = path.to_string_lossy().to_lowercase();
    if ![".hdr", ".nhdr", ".mhd"].iter().any(|e| name.ends_with(e)) {
        return;
    }
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    let (Some(stem), Some(own)) = (path.file_stem(), path.file_name()) else {
        return;
    };
    let prefix = format!("{}.", stem.to_string_lossy());
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    let mut found: Vec<(PathBuf, u64)> = entries
        .filter_map(Result::ok)
        .filter(|e| e.file_name() != own && e.file_name().to_string_lossy().starts_with(&prefix))
        .filter_map(|e| {
            let m = std::fs::metadata(e.path()).ok()?;
            (m.is_file() && m.len() <= MAX_FILE_BYTES).then(|| (e.path(), m.len()))
        })
        .collect();
    found.sort();
    listing.files.extend(found);
}

/// A listed file as the loaders read it: on demand, so that an uncompressed payload goes from
/// the disk straight into the voxel buffer and a DICOM series is read one file at a time. Each
/// read opens the file again (a series of thousands of files holds no descriptors), checks it
/// is still a regular file and reads from the offset asked.
#[derive(Debug)]
pub struct DiskFile {
    path: PathBuf,
    len: u64,
}

impl DiskFile {
    /// The file at `path`, refused when it is not a regular file or is over [`MAX_FILE_BYTES`].
    pub fn open(path: &Path) -> Result<Self, FilesError> {
        let meta = std::fs::metadata(path).map_err(|e| FilesError::Read {
            path: path.display().to_string(),
            source: e,
        })?;
        if !meta.is_file() {
            return Err(FilesError::NotAFile {
                path: path.display().to_string(),
                kind: kind_of(meta.file_type()),
            });
        }
        check_size(path, meta.len())?;
        Ok(Self {
            path: path.to_owned(),
            len: meta.len(),
        })
    }
}

impl crate::io::FileSource for DiskFile {
    fn len(&self) -> u64 {
        self.len
    }

    fn read_exact_at(&self, offset: u64, buf: &mut [u8]) -> std::io::Result<()> {
        use std::io::{Seek as _, SeekFrom};
        let end = offset.saturating_add(buf.len() as u64);
        if end > self.len {
            return Err(std::io::Error::new(
                std::io::ErrorKind::UnexpectedEof,
                format!(
                    "bytes {offset}..{end} asked of a file of {} bytes",
                    self.len
                ),
            ));
        }
        // Opened again for each read: the path is checked to be a regular file first, so a
        // file replaced by a FIFO since it was listed cannot block the open.
        let meta = std::fs::metadata(&self.path)?;
        if !meta.is_file() || meta.len() < end {
            return Err(std::io::Error::new(
                std::io::ErrorKind::UnexpectedEof,
                format!(
                    "the file changed since it was listed ({}, {} bytes)",
                    kind_of(meta.file_type()),
                    meta.len()
                ),
            ));
        }
        let mut f = std::fs::File::open(&self.path)?;
        f.seek(SeekFrom::Start(offset))?;
        f.read_exact(buf)
    }
}

/// Lists the given paths as loader inputs named by their paths, read on demand (see
/// [`DiskFile`]), with what was skipped.
pub fn read_all(paths: &[PathBuf]) -> Result<(Vec<crate::io::InputFile>, Vec<String>), FilesError> {
    let listing = list(paths)?;
    let mut files = Vec::with_capacity(listing.files.len());
    for (p, _) in &listing.files {
        let source = std::sync::Arc::new(DiskFile::open(p)?);
        let file =
            crate::io::InputFile::on_demand(p.display().to_string(), source).map_err(|e| {
                FilesError::Read {
                    path: p.display().to_string(),
                    source: e,
                }
            })?;
        files.push(file);
    }
    Ok((files, listing.skipped))
}

#[cfg(all(test, unix))]
#[allow(clippy::unwrap_used)] // a failed unwrap is a failed test
mod tests {
    use super::*;

    fn temp_dir(tag: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("shapecast-files-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    #[test]
    fn fifos_devices_and_directory_links_are_skipped() {
        let d = temp_dir("walk");
        std::fs::write(d.join("a.dcm"), b"one").unwrap();
        std::fs::create_dir(d.join("sub")).unwrap();
        std::fs::write(d.join("sub/b.dcm"), b"two").unwrap();
        // A FIFO (reading it would block forever), made with mkfifo(1).
        let fifo = d.join("pipe");
        let made = std::process::Command::new("mkfifo").arg(&fifo).status();
        let have_fifo = made.is_ok_and(|s| s.success());
        std::os::unix::fs::symlink("/dev/zero", d.join("zero")).unwrap();
        std::os::unix::fs::symlink(&d, d.join("sub/loop")).unwrap();
        std::os::unix::fs::symlink(d.join("missing"), d.join("dangling")).unwrap();
        std::os::unix::fs::symlink(d.join("a.dcm"), d.join("c.dcm")).unwrap();

        let t = std::time::Instant::now();
        let (files, skipped) = read_all(std::slice::from_ref(&d)).unwrap();
        assert!(t.elapsed().as_secs() < 5);
        let names: Vec<String> = files
            .iter()
            .map(|f| crate::io::base_name(&f.name).to_owned())
            .collect();
        assert_eq!(names, ["a.dcm", "c.dcm", "b.dcm"]);
        assert_eq!(files[1].bytes, b"one");
        let said = skipped.join("\n");
        assert!(said.contains("zero") && said.contains("a device"), "{said}");
        assert!(said.contains("loop") && said.contains("a folder"), "{said}");
        assert!(said.contains("dangling"), "{said}");
        if have_fifo {
            assert!(said.contains("pipe") && said.contains("FIFO"), "{said}");
            // Given by name it is refused, not opened.
            let r = list(&[fifo]);
            assert!(matches!(r, Err(FilesError::NotAFile { .. })), "{r:?}");
        } else {
            eprintln!("SKIPPED: the FIFO case (mkfifo not available)");
        }
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn a_file_read_on_demand_that_shrinks_or_turns_into_a_fifo_is_an_error_naming_it() {
        use crate::io::FileSource as _;
        let d = temp_dir("shrink");
        // A NIfTI-1 header (u8, 64 x 64 x 2) and its voxels: over HEAD_BYTES, so read on demand.
        let mut nii = vec![0u8; 352];
        nii[0..4].copy_from_slice(&348i32.to_le_bytes());
        for (at, v) in [(40, 3i16), (42, 64), (44, 64), (46, 2), (70, 2), (72, 8)] {
            nii[at..at + 2].copy_from_slice(&v.to_le_bytes());
        }
        for i in 0..4 {
            nii[76 + 4 * i..80 + 4 * i].copy_from_slice(&1f32.to_le_bytes());
        }
        nii[108..112].copy_from_slice(&352f32.to_le_bytes());
        nii[344..348].copy_from_slice(b"n+1\0");
        nii.resize(352 + 64 * 64 * 2, 7);
        let p = d.join("a.nii");
        std::fs::write(&p, &nii).unwrap();
        let (files, _) = read_all(std::slice::from_ref(&p)).unwrap();
        assert!(files[0].is_on_demand());
        assert_eq!(crate::io::load(&files).unwrap().volume.dims, [64, 64, 2]);
        // Cut short after it was listed: the read fails, named.
        std::fs::write(&p, &nii[..1000]).unwrap();
        let e = crate::io::load(&files).unwrap_err();
        assert!(
            matches!(&e, crate::io::LoadError::Read { file, .. } if file.ends_with("a.nii")),
            "{e:?}"
        );
        // The cause (the file changed since it was listed) is said after the read that failed.
        let shown = crate::error::chain(&e);
        assert!(shown.contains("changed since it was listed"), "{shown}");
        // Replaced by a FIFO: refused without opening it (which would block).
        let made = std::process::Command::new("mkfifo")
            .arg(d.join("f.nii"))
            .status();
        if made.is_ok_and(|s| s.success()) {
            std::fs::write(d.join("g.nii"), &nii).unwrap();
            let g = DiskFile::open(&d.join("g.nii")).unwrap();
            std::fs::remove_file(d.join("g.nii")).unwrap();
            std::fs::rename(d.join("f.nii"), d.join("g.nii")).unwrap();
            let mut buf = [0u8; 4];
            let t = std::time::Instant::now();
            assert!(g.read_exact_at(0, &mut buf).is_err());
            assert!(t.elapsed().as_secs() < 5);
        } else {
            eprintln!("SKIPPED: the FIFO case (mkfifo not available)");
        }
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn a_header_brings_its_data_file() {
        let d = temp_dir("pair");
        std::fs::write(d.join("x.nhdr"), b"NRRD0004\n").unwrap();
        std::fs::write(d.join("x.raw.gz"), b"data").unwrap();
        std::fs::write(d.join("y.raw"), b"other").unwrap();
        let listing = list(&[d.join("x.nhdr")]).unwrap();
        let names: Vec<PathBuf> = listing.files.iter().map(|(p, _)| p.clone()).collect();
        assert_eq!(names, [d.join("x.nhdr"), d.join("x.raw.gz")]);
        std::fs::remove_dir_all(&d).unwrap();
    }
}
