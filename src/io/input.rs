//! What the loaders read: a file's bytes in memory (the browser's reads, the demo, DICOMweb
//! parts), or a file read on demand through a [`FileSource`] (natively, a file on disk: see
//! `src/files.rs`). On demand, an uncompressed payload goes from the file straight into the
//! voxel buffer and a DICOM series is read one file at a time, so that reading never holds the
//! whole file and the voxels together.

use std::borrow::Cow;
use std::sync::Arc;

use super::LoadError;

/// A file's content, read on demand. `src/io` never opens a file itself: the native code gives
/// it this (`crate::files`), and tests give it bytes.
pub trait FileSource: Send + Sync + std::fmt::Debug {
    /// The file's length in bytes.
    fn len(&self) -> u64;

    /// Whether the file is empty.
    fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Fills `buf` with the bytes at `offset`; an error when the file holds fewer (it changed
    /// since it was listed) or cannot be read.
    fn read_exact_at(&self, offset: u64, buf: &mut [u8]) -> std::io::Result<()>;
}

/// Bytes of a file read on demand that stay in memory for sniffing (`io::sniff`): enough for
/// every format's magic, a NIfTI-2 header and the first kilobyte of a gzip stream.
pub const HEAD_BYTES: usize = 4096;

/// One file as the user gave it: its name (a path or just a file name; only the last component
/// is used to pair headers with data files) and its content.
#[derive(Clone)]
pub struct InputFile {
    pub name: String,
    /// The whole content, or, for a file read on demand ([`InputFile::on_demand`]), its first
    /// [`HEAD_BYTES`] bytes.
    pub bytes: Vec<u8>,
    source: Option<Arc<dyn FileSource>>,
}

impl std::fmt::Debug for InputFile {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("InputFile")
            .field("name", &self.name)
            .field("len", &self.len())
            .field("on_demand", &self.source.is_some())
            .finish()
    }
}

impl InputFile {
    pub fn new(name: impl Into<String>, bytes: Vec<u8>) -> Self {
        Self {
            name: name.into(),
            bytes,
            source: None,
        }
    }

    /// A file read when the loader needs it: only its first [`HEAD_BYTES`] bytes are read now.
    pub fn on_demand(
        name: impl Into<String>,
        source: Arc<dyn FileSource>,
    ) -> std::io::Result<Self> {
        let head_len = source.len().min(HEAD_BYTES as u64) as usize;
        let mut bytes = vec![0u8; head_len];
        source.read_exact_at(0, &mut bytes)?;
        Ok(Self {
            name: name.into(),
            bytes,
            source: Some(source),
        })
    }

    /// The file's length in bytes.
    pub fn len(&self) -> u64 {
        match &self.source {
            Some(s) => s.len(),
            None => self.bytes.len() as u64,
        }
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Whether the content is read on demand (else `bytes` is all of it).
    pub fn is_on_demand(&self) -> bool {
        self.source.is_some()
    }

    /// The whole content: borrowed when in memory, else read now (the caller drops it as soon
    /// as it can).
    pub fn contents(&self) -> Result<Cow<'_, [u8]>, LoadError> {
        self.prefix(usize::MAX)
    }

    /// The first `max` bytes (all of them when the file is shorter).
    pub(crate) fn prefix(&self, max: usize) -> Result<Cow<'_, [u8]>, LoadError> {
        match &self.source {
            None => Ok(Cow::Borrowed(&self.bytes[..self.bytes.len().min(max)])),
            Some(s) => {
                let n = usize::try_from(s.len()).unwrap_or(usize::MAX).min(max);
                let mut v = super::raw::try_vec::<u8>(&self.name, "the file's bytes", n)?;
                s.read_exact_at(0, &mut v)
                    .map_err(|e| read_error(&self.name, 0, &e))?;
                Ok(Cow::Owned(v))
            }
        }
    }

    /// All of the content as a [`Data`] range.
    pub(crate) fn data(&self) -> Data<'_> {
        match &self.source {
            None => Data::Memory(&self.bytes),
            Some(s) => Data::Source {
                source: s.as_ref(),
                start: 0,
                len: s.len(),
            },
        }
    }
}

/// A read that failed, naming the file and where.
pub(crate) fn read_error(file: &str, offset: u64, e: &std::io::Error) -> LoadError {
    LoadError::Read {
        file: file.to_owned(),
        message: format!("at byte {offset}: {e}"),
    }
}

/// A range of a file's bytes: in memory, or read on demand.
#[derive(Clone, Copy, Debug)]
pub(crate) enum Data<'a> {
    Memory(&'a [u8]),
    Source {
        source: &'a dyn FileSource,
        start: u64,
        len: u64,
    },
}

impl<'a> Data<'a> {
    pub(crate) fn len(&self) -> u64 {
        match self {
            Self::Memory(b) => b.len() as u64,
            Self::Source { len, .. } => *len,
        }
    }

    /// The bytes from `skip` on, `None` when there are fewer than `skip`.
    pub(crate) fn after(self, skip: u64) -> Option<Self> {
        match self {
            Self::Memory(b) => b.get(usize::try_from(skip).ok()?..).map(Self::Memory),
            Self::Source { source, start, len } => (skip <= len).then(|| Self::Source {
                source,
                start: start + skip,
                len: len - skip,
            }),
        }
    }

    /// Reads `buf.len()` bytes at `offset` within the range (the caller checks the length).
    pub(crate) fn read_at(&self, file: &str, offset: u64, buf: &mut [u8]) -> Result<(), LoadError> {
        match *self {
            Self::Memory(b) => {
                let src = usize::try_from(offset)
                    .ok()
                    .and_then(|o| b.get(o..o.checked_add(buf.len())?))
                    .ok_or_else(|| {
                        LoadError::truncated(
                            file,
                            "data",
                            offset.saturating_add(buf.len() as u64),
                            b.len() as u64,
                        )
                    })?;
                buf.copy_from_slice(src);
                Ok(())
            }
            Self::Source { source, start, len } => {
                let end = offset.saturating_add(buf.len() as u64);
                if end > len {
                    return Err(LoadError::truncated(file, "data", end, len));
                }
                source
                    .read_exact_at(start + offset, buf)
                    .map_err(|e| read_error(file, start + offset, &e))
            }
        }
    }

    /// The bytes after the first `lines` line ends (NRRD "line skip"), `None` when the data
    /// hold fewer lines.
    pub(crate) fn skip_lines(self, file: &str, lines: usize) -> Result<Option<Self>, LoadError> {
        let mut data = self;
        let mut chunk = Vec::new();
        for _ in 0..lines {
            let mut at = 0u64;
            let found = loop {
                if at >= data.len() {
                    break None;
                }
                let n = (data.len() - at).min(64 << 10) as usize;
                chunk.resize(n, 0);
                data.read_at(file, at, &mut chunk)?;
                if let Some(p) = chunk.iter().position(|&b| b == b'\n') {
                    break Some(at + p as u64 + 1);
                }
                at += n as u64;
            };
            match found.and_then(|p| data.after(p)) {
                Some(d) => data = d,
                None => return Ok(None),
            }
        }
        Ok(Some(data))
    }
}

/// A file's bytes in memory as a [`FileSource`] (tests, and the same code path as a file).
#[derive(Debug)]
pub struct MemorySource(pub Vec<u8>);

impl FileSource for MemorySource {
    fn len(&self) -> u64 {
        self.0.len() as u64
    }

    fn read_exact_at(&self, offset: u64, buf: &mut [u8]) -> std::io::Result<()> {
        let src = usize::try_from(offset)
            .ok()
            .and_then(|o| self.0.get(o..o.checked_add(buf.len())?))
            .ok_or_else(|| {
                std::io::Error::new(
                    std::io::ErrorKind::UnexpectedEof,
                    "read past the end of the file",
                )
            })?;
        buf.copy_from_slice(src);
        Ok(())
    }
}
