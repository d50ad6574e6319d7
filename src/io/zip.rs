//! .zip archives: a DICOM series, a header with its data file, or any file Shapecast reads,
//! packed into one archive (what a PACS export or a web server most often hands out). Each
//! archive among the given files is replaced by the files it holds, named
//! `archive.zip/path/inside`, and the result goes to [`super::load`] like any drop.
//!
//! Hostile archives are expected: only stored and deflated entries are read (no encryption, no
//! other codecs); the sizes the central directory declares are checked against [`Limits`]
//! before anything is allocated, and an entry is read at most to its declared size + 1 byte, so
//! a lying header is an error rather than an allocation. The CRC-32 of every entry is checked
//! (by the `zip` crate, at the end of each entry). Archives inside archives are not opened.

use std::io::Read as _;

use super::{InputFile, Limits, LoadError, base_name};

/// At most this many entries per archive (a whole-body CT series has a few thousand slices).
pub const MAX_ENTRIES: usize = 200_000;

/// Whether the bytes start like a zip archive (a local file header, or an empty archive's end
/// record).
pub fn is_zip(bytes: &[u8]) -> bool {
    bytes.starts_with(b"PK\x03\x04") || bytes.starts_with(b"PK\x05\x06")
}

/// Replaces every zip archive among `files` by the files inside it (in archive order), and says
/// what was skipped. Files that are not archives pass through unchanged. The decompressed bytes
/// of all archives together are capped by `limits.max_decompressed_bytes`.
pub fn expand(
    files: Vec<InputFile>,
    limits: &Limits,
) -> Result<(Vec<InputFile>, Vec<String>), LoadError> {
    if !files.iter().any(|f| is_zip(&f.bytes)) {
        return Ok((files, Vec::new()));
    }
    let mut out = Vec::with_capacity(files.len());
    let mut notes = Vec::new();
    let mut budget = limits.max_decompressed_bytes;
    for file in files {
        if is_zip(&file.bytes) {
            unpack(&file, &mut budget, &mut out, &mut notes)?;
        } else {
            out.push(file);
        }
    }
    if out.is_empty() {
        return Err(LoadError::NoFiles);
    }
    Ok((out, notes))
}

fn zip_error(archive: &str, entry: Option<&str>, e: ::zip::result::ZipError) -> LoadError {
    use ::zip::result::ZipError;
    let file = match entry {
        Some(entry) => format!("{archive}/{entry}"),
        None => archive.to_owned(),
    };
    match e {
        ZipError::CompressionMethodNotSupported(m) => LoadError::unsupported(
            &file,
            "zip compression",
            format!(
                "method {m} (only stored and deflated entries are read; re-pack the archive with plain zip)"
            ),
        ),
        ZipError::UnsupportedArchive(what)
            if what.contains("assword") || what.contains("ncrypt") =>
        {
            LoadError::unsupported(
                &file,
                "zip entry",
                "encrypted; unpack it and drop the files",
            )
        }
        ZipError::UnsupportedArchive(what) => LoadError::unsupported(&file, "zip archive", what),
        ZipError::InvalidPassword => LoadError::unsupported(
            &file,
            "zip entry",
            "encrypted; unpack it and drop the files",
        ),
        other => LoadError::Decompress {
            file,
            message: format!("not a readable zip archive: {other}"),
        },
    }
}

/// Whether an entry is metadata a desktop added (macOS resource forks, hidden files).
fn is_clutter(path: &str) -> bool {
    path.split('/')
        .any(|part| part == "__MACOSX" || part.starts_with('.'))
}

fn unpack(
    archive_file: &InputFile,
    budget: &mut u64,
    out: &mut Vec<InputFile>,
    notes: &mut Vec<String>,
) -> Result<(), LoadError> {
    let name = archive_file.name.as_str();
    let mut archive = ::zip::ZipArchive::new(std::io::Cursor::new(archive_file.contents()?))
        .map_err(|e| zip_error(name, None, e))?;
    if archive.len() > MAX_ENTRIES {
        return Err(LoadError::TooLarge {
            file: name.to_owned(),
            what: "the archive's entry count".to_owned(),
            bytes: archive.len() as u64,
            limit: MAX_ENTRIES as u64,
        });
    }
    // Every declared size is checked before the first byte is inflated: a bomb is refused
    // whole, not after filling memory with its first entries.
    let mut declared_total: u64 = 0;
    for i in 0..archive.len() {
        let entry = archive
            .by_index_raw(i)
            .map_err(|e| zip_error(name, None, e))?;
        if entry.is_file() {
            declared_total = declared_total.saturating_add(entry.size());
        }
    }
    if declared_total > *budget {
        return Err(LoadError::TooLarge {
            file: name.to_owned(),
            what: "unpacking the archive".to_owned(),
            bytes: declared_total,
            limit: *budget,
        });
    }
    let before = out.len();
    let mut skipped = 0usize;
    for i in 0..archive.len() {
        let mut entry = archive.by_index(i).map_err(|e| zip_error(name, None, e))?;
        let inner = entry
            .name()
            .map(|n| n.replace('\\', "/"))
            .unwrap_or_else(|_| format!("entry {i}"));
        if !entry.is_file() {
            continue;
        }
        if is_clutter(&inner) {
            skipped += 1;
            continue;
        }
        if entry.encrypted() {
            return Err(LoadError::unsupported(
                &format!("{name}/{inner}"),
                "zip entry",
                "encrypted; unpack it and drop the files",
            ));
        }
        let declared = entry.size();
        if declared > *budget {
            return Err(LoadError::TooLarge {
                file: format!("{name}/{inner}"),
                what: "unpacking this entry".to_owned(),
                bytes: declared,
                limit: *budget,
            });
        }
        let capacity = usize::try_from(declared).map_err(|_| LoadError::TooLarge {
            file: format!("{name}/{inner}"),
            what: "unpacking this entry".to_owned(),
            bytes: declared,
            limit: usize::MAX as u64,
        })?;
        let mut bytes = Vec::new();
        bytes
            .try_reserve_exact(capacity)
            .map_err(|_| LoadError::OutOfMemory {
                file: format!("{name}/{inner}"),
                what: "the unpacked entry".to_owned(),
                bytes: declared,
            })?;
        // One byte more than declared: an entry that inflates past its declared size is an error.
        (&mut entry)
            .take(declared.saturating_add(1))
            .read_to_end(&mut bytes)
            .map_err(|e| LoadError::Decompress {
                file: format!("{name}/{inner}"),
                message: e.to_string(),
            })?;
        if bytes.len() as u64 != declared {
            return Err(LoadError::Decompress {
                file: format!("{name}/{inner}"),
                message: format!(
                    "the archive declares {declared} bytes but the entry holds {}{}",
                    if bytes.len() as u64 > declared {
                        "more than "
                    } else {
                        ""
                    },
                    bytes.len().min(capacity)
                ),
            });
        }
        *budget -= declared;
        if is_zip(&bytes) {
            notes.push(format!(
                "{name}/{inner}: an archive inside the archive, not opened (unpack it first)"
            ));
            continue;
        }
        out.push(InputFile::new(format!("{name}/{inner}"), bytes));
    }
    if skipped > 0 {
        notes.push(format!(
            "{name}: {skipped} hidden or __MACOSX entries skipped"
        ));
    }
    if out.len() == before {
        return Err(LoadError::UnknownFormat {
            file: base_name(name).to_owned(),
            reason: "the zip archive holds no files".to_owned(),
        });
    }
    Ok(())
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // a failed unwrap is a failed test
mod tests {
    use super::*;
    use std::io::Write as _;

    fn archive(entries: &[(&str, &[u8])], method: ::zip::CompressionMethod) -> Vec<u8> {
        let mut w = ::zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
        let options = ::zip::write::SimpleFileOptions::default().compression_method(method);
        for (name, bytes) in entries {
            w.start_file(*name, options).unwrap();
            w.write_all(bytes).unwrap();
        }
        w.finish().unwrap().into_inner()
    }

    #[test]
    fn entries_replace_the_archive_and_clutter_is_skipped() {
        let zip = archive(
            &[
                ("series/a.dcm", b"aaaa"),
                ("__MACOSX/series/._a.dcm", b"junk"),
                ("series/.DS_Store", b"junk"),
                ("series/b.dcm", &[7u8; 5000]),
            ],
            ::zip::CompressionMethod::Deflated,
        );
        let files = vec![
            InputFile::new("x.nhdr", b"NRRD0004\n".to_vec()),
            InputFile::new("s.zip", zip),
        ];
        let (out, notes) = expand(files, &Limits::default()).unwrap();
        let names: Vec<&str> = out.iter().map(|f| f.name.as_str()).collect();
        assert_eq!(
            names,
            ["x.nhdr", "s.zip/series/a.dcm", "s.zip/series/b.dcm"]
        );
        assert_eq!(out[2].bytes, vec![7u8; 5000]);
        assert!(notes.iter().any(|n| n.contains("2 hidden")), "{notes:?}");
    }

    #[test]
    fn sizes_over_the_limit_are_refused_before_inflating() {
        let zip = archive(
            &[("big.raw", &[0u8; 100_000])],
            ::zip::CompressionMethod::Deflated,
        );
        let limits = Limits {
            max_voxel_bytes: 1 << 20,
            max_decompressed_bytes: 50_000,
        };
        let e = expand(vec![InputFile::new("b.zip", zip)], &limits).unwrap_err();
        assert!(matches!(e, LoadError::TooLarge { .. }), "{e}");
        assert!(e.to_string().contains("b.zip"), "{e}");
    }

    #[test]
    fn a_lying_size_or_crc_is_an_error_not_a_panic() {
        let zip = archive(
            &[("v.raw", &[3u8; 4000])],
            ::zip::CompressionMethod::Deflated,
        );
        // Every copy of the uncompressed size (local header offset 22, central header 24)
        // claims 1000 bytes.
        let mut lie = zip.clone();
        let cd = lie.windows(4).position(|w| w == b"PK\x01\x02").unwrap();
        lie[22..26].copy_from_slice(&1000u32.to_le_bytes());
        lie[cd + 24..cd + 28].copy_from_slice(&1000u32.to_le_bytes());
        let e = expand(vec![InputFile::new("l.zip", lie)], &Limits::default()).unwrap_err();
        assert!(e.to_string().contains("l.zip/v.raw"), "{e}");
        // A flipped CRC.
        let mut bad = zip.clone();
        bad[cd + 16] ^= 0xff;
        bad[14] ^= 0xff;
        assert!(expand(vec![InputFile::new("c.zip", bad)], &Limits::default()).is_err());
        // Truncations and bit flips anywhere: errors or files, never a panic.
        for cut in (0..zip.len()).step_by(7) {
            let _ = expand(
                vec![InputFile::new("t.zip", zip[..cut].to_vec())],
                &Limits::default(),
            );
        }
        for at in 0..zip.len() {
            let mut flipped = zip.clone();
            flipped[at] ^= 0x5a;
            let _ = expand(vec![InputFile::new("f.zip", flipped)], &Limits::default());
        }
    }

    #[test]
    fn stored_entries_nested_archives_and_empty_archives() {
        let inner = archive(&[("a", b"a")], ::zip::CompressionMethod::Stored);
        let zip = archive(
            &[("plain.nii", b"hello"), ("inner.zip", &inner)],
            ::zip::CompressionMethod::Stored,
        );
        let (out, notes) = expand(vec![InputFile::new("o.zip", zip)], &Limits::default()).unwrap();
        assert_eq!(out.len(), 1);
        assert_eq!(out[0].bytes, b"hello");
        assert!(notes.iter().any(|n| n.contains("inner.zip")), "{notes:?}");
        let empty = archive(&[], ::zip::CompressionMethod::Stored);
        let e = expand(vec![InputFile::new("e.zip", empty)], &Limits::default()).unwrap_err();
        assert!(e.to_string().contains("no files"), "{e}");
    }
}
