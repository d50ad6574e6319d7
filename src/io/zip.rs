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
//!
//! The archive is read where it lies (on demand natively, JavaScript's bytes in the browser)
//! and its entries are on-demand files: their first 4 KiB are inflated when listed, the whole of
//! one when the loader reads it, and only the last entry read whole is kept. So a zipped DICOM
//! series costs the voxels and one slice, not every slice as well.

// In the browser an archive's bytes are JavaScript's, which are not `Send`; it has one thread.
#![cfg_attr(target_arch = "wasm32", allow(clippy::arc_with_non_send_sync))]

use std::io::Read as _;
use std::sync::{Arc, Mutex};

use super::{FileSource, InputFile, Limits, LoadError, base_name};

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
            unpack(file, &mut budget, &mut out, &mut notes)?;
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
        ZipError::Io(e) => match LoadError::carried_by(e) {
            Ok(read_failed) => read_failed,
            Err(e) => LoadError::decompress(
                &file,
                "zip archive",
                crate::io::Corruption::Corrupt,
                Some(e.into()),
            ),
        },
        other => LoadError::decompress(
            &file,
            "zip archive",
            crate::io::Corruption::Corrupt,
            Some(other.into()),
        ),
    }
}

/// Whether an entry is metadata a desktop added (macOS resource forks, hidden files).
fn is_clutter(path: &str) -> bool {
    path.split('/')
        .any(|part| part == "__MACOSX" || part.starts_with('.'))
}

/// Reads an archive where it lies (in memory, or on demand from the file), for `ZipArchive`.
struct ArchiveReader {
    file: Arc<InputFile>,
    pos: u64,
}

impl std::io::Read for ArchiveReader {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let data = self.file.data();
        let n = data.len().saturating_sub(self.pos).min(buf.len() as u64) as usize;
        data.read_at(&self.file.name, self.pos, &mut buf[..n])
            .map_err(std::io::Error::other)?;
        self.pos += n as u64;
        Ok(n)
    }
}

impl std::io::Seek for ArchiveReader {
    fn seek(&mut self, to: std::io::SeekFrom) -> std::io::Result<u64> {
        let len = self.file.len();
        let pos = match to {
            std::io::SeekFrom::Start(p) => Some(p),
            std::io::SeekFrom::End(d) => len.checked_add_signed(d),
            std::io::SeekFrom::Current(d) => self.pos.checked_add_signed(d),
        };
        self.pos = pos.ok_or_else(|| {
            std::io::Error::new(std::io::ErrorKind::InvalidInput, "seek before the start")
        })?;
        Ok(self.pos)
    }
}

type Archive = ::zip::ZipArchive<std::io::BufReader<ArchiveReader>>;

/// One archive's state that its entries share: the archive, and the one entry last inflated
/// whole (a loader reads an entry's head, then all of it once; keeping one entry bounds the
/// memory whatever the archive holds).
struct Shared {
    archive: Archive,
    last: Option<(usize, Vec<u8>)>,
}

/// An entry of an archive, inflated when read: reads within its first [`PREFIX_READ`] bytes
/// inflate only that far; a longer read inflates it whole (its size and CRC-32 checked) and
/// keeps it until another entry is read whole.
struct EntrySource {
    shared: Arc<Mutex<Shared>>,
    index: usize,
    size: u64,
}

/// Reads ending within this many bytes of an entry inflate only its start (sniffing reads 4 KiB
/// of every file, a DICOM header listing 64 KiB).
const PREFIX_READ: u64 = super::input::LISTING_PREFIX_BYTES as u64;

impl std::fmt::Debug for EntrySource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("EntrySource")
            .field("index", &self.index)
            .field("size", &self.size)
            .finish()
    }
}

impl FileSource for EntrySource {
    fn len(&self) -> u64 {
        self.size
    }

    fn read_exact_at(&self, offset: u64, buf: &mut [u8]) -> std::io::Result<()> {
        let end = offset
            .checked_add(buf.len() as u64)
            .filter(|&e| e <= self.size)
            .ok_or_else(|| {
                std::io::Error::new(
                    std::io::ErrorKind::UnexpectedEof,
                    format!("read past the entry's {} bytes", self.size),
                )
            })?;
        let mut shared = self
            .shared
            .lock()
            .map_err(|_| std::io::Error::other("the archive failed while being read"))?;
        let shared = &mut *shared;
        let from = offset as usize;
        if let Some((i, bytes)) = &shared.last
            && *i == self.index
        {
            buf.copy_from_slice(&bytes[from..from + buf.len()]);
            return Ok(());
        }
        let mut entry = shared
            .archive
            .by_index(self.index)
            .map_err(std::io::Error::other)?;
        if end <= PREFIX_READ.min(self.size.saturating_sub(1)) {
            // Only the start, not kept: the CRC is checked when the entry is read whole.
            let mut head = vec![0u8; end as usize];
            entry.read_exact(&mut head)?;
            buf.copy_from_slice(&head[from..]);
            return Ok(());
        }
        let size = self.size as usize;
        let mut bytes = Vec::new();
        bytes
            .try_reserve_exact(size)
            .map_err(|_| std::io::Error::other(format!("no memory for {size} bytes")))?;
        // One byte more than declared: an entry that inflates past its declared size is an
        // error; reading to the end checks the CRC-32.
        (&mut entry)
            .take(self.size.saturating_add(1))
            .read_to_end(&mut bytes)?;
        if bytes.len() != size {
            return Err(std::io::Error::new(
                std::io::ErrorKind::InvalidData,
                format!(
                    "the archive declares {size} bytes but the entry holds {}{}",
                    if bytes.len() > size { "more than " } else { "" },
                    bytes.len().min(size)
                ),
            ));
        }
        drop(entry);
        buf.copy_from_slice(&bytes[from..from + buf.len()]);
        shared.last = Some((self.index, bytes));
        Ok(())
    }
}

fn unpack(
    archive_file: InputFile,
    budget: &mut u64,
    out: &mut Vec<InputFile>,
    notes: &mut Vec<String>,
) -> Result<(), LoadError> {
    let archive_file = Arc::new(archive_file);
    let name = archive_file.name.clone();
    let name = name.as_str();
    // 64 KiB reads: in the browser each read of the archive crosses into JavaScript.
    let reader = std::io::BufReader::with_capacity(
        64 << 10,
        ArchiveReader {
            file: Arc::clone(&archive_file),
            pos: 0,
        },
    );
    let mut archive = ::zip::ZipArchive::new(reader).map_err(|e| zip_error(name, None, e))?;
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
    crate::io::raw::check_expansion(name, "zip archive", archive_file.len(), declared_total)?;
    // The entries to read: opened once each here (so that an unsupported codec or encryption
    // is refused now), inflated when the loader reads them.
    let mut entries = Vec::new();
    let mut skipped = 0usize;
    for i in 0..archive.len() {
        let entry = archive.by_index(i).map_err(|e| zip_error(name, None, e))?;
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
        entries.push((i, inner, entry.size()));
    }
    let shared = Arc::new(Mutex::new(Shared {
        archive,
        last: None,
    }));
    let before = out.len();
    for (index, inner, size) in entries {
        let file = format!("{name}/{inner}");
        let source = EntrySource {
            shared: Arc::clone(&shared),
            index,
            size,
        };
        let input = InputFile::on_demand(file.clone(), Arc::new(source))
            .map_err(|e| super::input::read_error(&file, 0, e))?;
        *budget -= size;
        if is_zip(&input.bytes) {
            notes.push(format!(
                "{file}: an archive inside the archive, not opened (unpack it first)"
            ));
            continue;
        }
        out.push(input);
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
        // Read on demand: the head now, the whole entry when asked.
        assert_eq!(out[2].bytes.len(), crate::io::HEAD_BYTES);
        assert_eq!(out[2].contents().unwrap().as_ref(), vec![7u8; 5000]);
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
