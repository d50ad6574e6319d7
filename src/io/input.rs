//! What the loaders read: a file's bytes in memory (the browser's reads, the demo, DICOMweb
//! parts), or a file read on demand through a [`FileSource`] (natively, a file on disk: see
//! `src/files.rs`). On demand, an uncompressed payload goes from the file straight into the
//! voxel buffer and a DICOM series is read one file at a time, so that reading never holds the
//! whole file and the voxels together.

use std::borrow::Cow;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

use super::LoadError;

/// What a [`FileSource`] must be besides: `Send + Sync` natively, where a loader runs on a thread
/// of its own; nothing in the browser, which has one thread and whose sources hold JavaScript
/// objects (the page's file bytes, kept out of the wasm memory: `app::web_files`).
#[cfg(not(target_arch = "wasm32"))]
pub trait SourceBounds: Send + Sync {}
#[cfg(not(target_arch = "wasm32"))]
impl<T: Send + Sync + ?Sized> SourceBounds for T {}
/// What a [`FileSource`] must be besides: nothing in the browser (see the native definition).
#[cfg(target_arch = "wasm32")]
pub trait SourceBounds {}
#[cfg(target_arch = "wasm32")]
impl<T: ?Sized> SourceBounds for T {}

/// A file's content, read on demand. `src/io` never opens a file itself: the native code gives
/// it this (`crate::files`), the browser its files' bytes held by JavaScript, and tests give it
/// bytes.
pub trait FileSource: SourceBounds + std::fmt::Debug {
    /// The file's length in bytes.
    fn len(&self) -> u64;

    /// Whether the file is empty.
    fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Fills `buf` with the bytes at `offset`; an error when the file holds fewer (it changed
    /// since it was listed) or cannot be read.
    fn read_exact_at(&self, offset: u64, buf: &mut [u8]) -> std::io::Result<()>;

    /// Says that the loader has read what lies before `offset` for the last time: a source may
    /// let those bytes go (the browser's chunks, so that a file's bytes shrink as its voxels
    /// grow). Reading them again is then an error. Only the final pass over a payload says so
    /// (`raw::read_pieces`, the on-demand converter in `raw::decode_source`,
    /// `raw::inflate_voxels`); a file on disk ignores it.
    fn release_before(&self, _offset: u64) {}
}

/// Bytes of a file read on demand that a DICOM header listing reads first
/// (`dicom::open_located`); a zip entry inflates only its start for reads within them
/// (`zip::EntrySource`), so listing a zipped series inflates each entry's start, not all of it.
pub(crate) const LISTING_PREFIX_BYTES: usize = 64 << 10;

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

    /// The source a file read on demand is read from (shared, not copied).
    pub(crate) fn source(&self) -> Option<Arc<dyn FileSource>> {
        self.source.clone()
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
                    .map_err(|e| read_error(&self.name, 0, e))?;
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
pub(crate) fn read_error(file: &str, offset: u64, e: std::io::Error) -> LoadError {
    LoadError::Read {
        file: file.to_owned(),
        offset,
        source: e,
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
                    .map_err(|e| read_error(file, start + offset, e))
            }
        }
    }

    /// [`FileSource::release_before`] at `offset` within the range (nothing for bytes in memory).
    pub(crate) fn release_before(&self, offset: u64) {
        if let Self::Source { source, start, len } = *self {
            source.release_before(start.saturating_add(offset.min(len)));
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

/// One piece of a [`Chunked`] file: in the browser a JavaScript `Uint8Array` (a file's
/// `ArrayBuffer`, a download's chunk), in tests a `Vec<u8>`.
pub trait Chunk {
    /// Its length in bytes.
    fn len(&self) -> u64;

    fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Copies its bytes from `from` on into `out` (the caller keeps within the chunk).
    fn copy_to(&self, from: u64, out: &mut [u8]);

    /// Lets its bytes go, if it can (the browser detaches the `ArrayBuffer`, freeing it
    /// before the garbage collector would); it is never read again.
    fn release(&self) {}
}

impl Chunk for Vec<u8> {
    fn len(&self) -> u64 {
        self.as_slice().len() as u64
    }

    fn copy_to(&self, from: u64, out: &mut [u8]) {
        let from = from as usize;
        out.copy_from_slice(&self[from..from + out.len()]);
    }
}

/// A file as chunks in order, read on demand across them: the browser keeps a file's bytes
/// (or a download's chunks as they came) in JavaScript's memory this way and the loaders read
/// them into the voxels, so the wasm memory does not hold the file too.
pub struct Chunked<C> {
    /// Each chunk with its offset in the file; none is empty, so the offsets increase.
    chunks: Vec<(u64, C)>,
    len: u64,
    /// The bytes before this were let go ([`FileSource::release_before`]).
    released: AtomicU64,
}

impl<C> Default for Chunked<C> {
    fn default() -> Self {
        Self {
            chunks: Vec::new(),
            len: 0,
            released: AtomicU64::new(0),
        }
    }
}

impl<C> std::fmt::Debug for Chunked<C> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Chunked")
            .field("chunks", &self.chunks.len())
            .field("len", &self.len)
            .field("released", &self.released.load(Ordering::Relaxed))
            .finish()
    }
}

impl<C: Chunk> Chunked<C> {
    /// One chunk: a whole file.
    pub fn whole(bytes: C) -> Self {
        let mut c = Self::default();
        c.push(bytes);
        c
    }

    /// Appends the next chunk (kept, not copied).
    pub fn push(&mut self, chunk: C) {
        let n = chunk.len();
        if n > 0 {
            self.chunks.push((self.len, chunk));
            self.len += n;
        }
    }

    /// The bytes so far.
    pub fn len(&self) -> u64 {
        self.len
    }

    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// How many bytes from the start have been let go.
    pub fn released(&self) -> u64 {
        self.released.load(Ordering::Relaxed)
    }

    /// The first `n` bytes (all of them when there are fewer), copied.
    pub fn head(&self, n: usize) -> Vec<u8> {
        let mut v = vec![0u8; n.min(usize::try_from(self.len).unwrap_or(usize::MAX))];
        match self.read_at(0, &mut v) {
            Ok(()) => v,
            Err(_) => Vec::new(),
        }
    }

    fn read_at(&self, offset: u64, buf: &mut [u8]) -> std::io::Result<()> {
        let want = buf.len();
        let short = || {
            std::io::Error::new(
                std::io::ErrorKind::UnexpectedEof,
                format!(
                    "{want} bytes at {offset} asked of a file of {} bytes",
                    self.len
                ),
            )
        };
        if offset.saturating_add(want as u64) > self.len {
            return Err(short());
        }
        if want > 0 && offset < self.released() {
            return Err(std::io::Error::other(format!(
                "bytes at {offset} were read before and let go (released up to {})",
                self.released()
            )));
        }
        // The chunk holding `offset`: the last one starting at or before it.
        let mut i = self
            .chunks
            .partition_point(|(start, _)| *start <= offset)
            .saturating_sub(1);
        let mut at = offset;
        let mut done = 0usize;
        while done < want {
            let (start, chunk) = self.chunks.get(i).ok_or_else(short)?;
            let from = at - start;
            let n = chunk.len().saturating_sub(from).min((want - done) as u64) as usize;
            if n == 0 {
                return Err(short());
            }
            chunk.copy_to(from, &mut buf[done..done + n]);
            done += n;
            at += n as u64;
            i += 1;
        }
        Ok(())
    }
}

impl<C: Chunk + std::fmt::Debug> FileSource for Chunked<C>
where
    Chunked<C>: SourceBounds,
{
    fn len(&self) -> u64 {
        self.len
    }

    fn read_exact_at(&self, offset: u64, buf: &mut [u8]) -> std::io::Result<()> {
        self.read_at(offset, buf)
    }

    /// Lets go every chunk that ends at or before `offset` (a chunk's end is the next one's start:
    /// a released chunk's own length means nothing any more).
    fn release_before(&self, offset: u64) {
        let offset = offset.min(self.len);
        let before = self.released.fetch_max(offset, Ordering::Relaxed);
        if offset <= before {
            return;
        }
        // From the chunk holding `before` (those ending earlier are released already).
        let first = self
            .chunks
            .partition_point(|(start, _)| *start <= before)
            .saturating_sub(1);
        for (i, (_, chunk)) in self.chunks.iter().enumerate().skip(first) {
            let end = self.chunks.get(i + 1).map_or(self.len, |(next, _)| *next);
            if end > offset {
                break;
            }
            if end > before {
                chunk.release();
            }
        }
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // a failed unwrap is a failed test
mod tests {
    use super::*;

    /// Every read of a file cut into chunks of uneven sizes gives the file's bytes, and a read
    /// past the end is an error, never a panic.
    #[test]
    fn chunked_reads_cross_chunks_as_the_file_reads() {
        let file: Vec<u8> = (0..1000u32).map(|i| (i * 7 + i / 3) as u8).collect();
        for cuts in [
            vec![1000],
            vec![1, 999],
            vec![300, 0, 1, 1, 698],
            vec![17; 58],
        ] {
            let mut c = Chunked::default();
            let mut at = 0;
            for n in cuts {
                let n = n.min(file.len() - at);
                c.push(file[at..at + n].to_vec());
                at += n;
            }
            c.push(file[at..].to_vec());
            assert_eq!(c.len(), 1000);
            for (offset, len) in [
                (0, 1000),
                (0, 0),
                (299, 3),
                (500, 17),
                (999, 1),
                (16, 35),
                (1000, 0),
            ] {
                let mut buf = vec![0u8; len];
                c.read_exact_at(offset as u64, &mut buf).unwrap();
                assert_eq!(buf, file[offset..offset + len]);
            }
            let mut buf = vec![0u8; 2];
            assert!(c.read_exact_at(999, &mut buf).is_err());
            assert!(c.read_exact_at(u64::MAX, &mut buf).is_err());
            assert_eq!(c.head(5), file[..5]);
        }
        let empty: Chunked<Vec<u8>> = Chunked::default();
        assert_eq!(empty.released(), 0);
        assert_eq!(empty.head(4), Vec::<u8>::new());
        let input = InputFile::on_demand("f", Arc::new(Chunked::whole(vec![1u8, 2, 3]))).unwrap();
        assert_eq!(input.contents().unwrap().as_ref(), &[1, 2, 3]);
    }

    /// A chunk that records whether it was let go.
    #[derive(Debug)]
    struct Recorded(Vec<u8>, std::sync::atomic::AtomicBool);

    impl Chunk for Recorded {
        fn len(&self) -> u64 {
            self.0.len() as u64
        }

        fn copy_to(&self, from: u64, out: &mut [u8]) {
            self.0.copy_to(from, out);
        }

        fn release(&self) {
            assert!(
                !self.1.swap(true, Ordering::Relaxed),
                "a chunk is let go once"
            );
        }
    }

    /// `release_before` lets go exactly the chunks that end at or before the mark, each once,
    /// and reads below the mark are errors while reads above it still work.
    #[test]
    fn chunks_are_let_go_once_they_end_before_the_mark() {
        let mut c = Chunked::default();
        for n in [300usize, 1, 699, 5] {
            c.push(Recorded(vec![n as u8; n], Default::default()));
        }
        let let_go = |c: &Chunked<Recorded>| -> Vec<bool> {
            c.chunks
                .iter()
                .map(|(_, r)| r.1.load(Ordering::Relaxed))
                .collect()
        };
        c.release_before(299);
        assert_eq!(let_go(&c), [false; 4]);
        c.release_before(300);
        assert_eq!(let_go(&c), [true, false, false, false]);
        c.release_before(100); // a lower mark changes nothing
        c.release_before(1000);
        assert_eq!(let_go(&c), [true, true, true, false]);
        assert_eq!(c.released(), 1000);
        let mut b = [0u8; 2];
        assert!(c.read_exact_at(999, &mut b).is_err());
        c.read_exact_at(1000, &mut b).unwrap();
        assert_eq!(b, [5, 5]);
        c.release_before(u64::MAX);
        assert_eq!(let_go(&c), [true; 4]);
        assert_eq!(c.released(), 1005);
    }
}
