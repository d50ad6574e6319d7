//! A deflated data set (Deflated Explicit VR Little Endian) read as its inflated bytes, on
//! demand: the native samples of its PixelData are read frame by frame from a deflate stream
//! inflated as they are asked for, so neither the inflated data set nor the file is ever held
//! whole beside the voxels (dicom-rs inflates the whole data set into its object: ~2x).

use std::sync::{Arc, Mutex};

use flate2::{Decompress, FlushDecompress, Status};

use super::validate;
use crate::io::{Corruption, FileSource, InputFile, Limits, LoadError};

/// Compressed bytes read from the file at a time.
const READ_CHUNK: usize = 64 << 10;

/// The inflated data set of a deflated DICOM file, as a file read on demand: reads move
/// forward through the stream (a read behind the last one starts again from the beginning).
pub(super) struct InflatedSource {
    compressed: Arc<dyn FileSource>,
    /// Where the deflate stream starts in the file.
    start: u64,
    /// Inflated bytes that may be read: up to the end of PixelData.
    len: u64,
    state: Mutex<State>,
}

impl std::fmt::Debug for InflatedSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("InflatedSource")
            .field("start", &self.start)
            .field("len", &self.len)
            .finish()
    }
}

struct State {
    inflate: Decompress,
    /// The next compressed byte to read from the file.
    in_at: u64,
    /// Inflated bytes handed out so far.
    out_at: u64,
    input: Vec<u8>,
    input_used: usize,
    ended: bool,
}

impl State {
    fn new(start: u64) -> Self {
        Self {
            // DICOM's deflated syntax is raw deflate (RFC 1951), without a zlib header.
            inflate: Decompress::new(false),
            in_at: start,
            out_at: 0,
            input: Vec::new(),
            input_used: 0,
            ended: false,
        }
    }

    /// Fills `out` with the next inflated bytes.
    fn inflate_into(&mut self, src: &dyn FileSource, out: &mut [u8]) -> std::io::Result<()> {
        let mut filled = 0;
        while filled < out.len() {
            if self.ended {
                return Err(std::io::ErrorKind::UnexpectedEof.into());
            }
            if self.input_used == self.input.len() {
                let n = (src.len().saturating_sub(self.in_at)).min(READ_CHUNK as u64) as usize;
                // Emptied first: a failed read leaves no stale window behind.
                self.input.clear();
                self.input_used = 0;
                self.input.resize(n, 0);
                if let Err(e) = src.read_exact_at(self.in_at, &mut self.input) {
                    self.input.clear();
                    self.ended = true;
                    return Err(e);
                }
                self.in_at += n as u64;
            }
            let (before_in, before_out) = (self.inflate.total_in(), self.inflate.total_out());
            let status = self
                .inflate
                .decompress(
                    &self.input[self.input_used..],
                    &mut out[filled..],
                    FlushDecompress::None,
                )
                .map_err(std::io::Error::other)?;
            let used = (self.inflate.total_in() - before_in) as usize;
            let made = (self.inflate.total_out() - before_out) as usize;
            self.input_used += used;
            filled += made;
            self.out_at += made as u64;
            if status == Status::StreamEnd || (used == 0 && made == 0 && self.input.is_empty()) {
                self.ended = true;
            } else if used == 0 && made == 0 {
                // No progress with input left: a stream the inflater cannot go on with.
                self.ended = true;
                return Err(std::io::Error::other("the deflate stream does not go on"));
            }
        }
        Ok(())
    }
}

impl FileSource for InflatedSource {
    fn len(&self) -> u64 {
        self.len
    }

    fn read_exact_at(&self, offset: u64, buf: &mut [u8]) -> std::io::Result<()> {
        if offset.saturating_add(buf.len() as u64) > self.len {
            return Err(std::io::ErrorKind::UnexpectedEof.into());
        }
        let mut st = self
            .state
            .lock()
            .map_err(|_| std::io::Error::other("an earlier read failed"))?;
        if offset < st.out_at {
            *st = State::new(self.start);
        }
        let mut scratch = Vec::new();
        if st.out_at < offset {
            scratch.resize(READ_CHUNK, 0);
        }
        while st.out_at < offset {
            let n = ((offset - st.out_at) as usize).min(scratch.len());
            st.inflate_into(self.compressed.as_ref(), &mut scratch[..n])?;
        }
        st.inflate_into(self.compressed.as_ref(), buf)
    }
}

/// A deflated data set's inflated bytes as a file read on demand, with where its native
/// PixelData lies in them (offset, declared length), for a file read on demand; `None` when
/// the file is not one (or its PixelData is not native). The compressed file is read whole
/// once, for the header walk (every check of the in-memory read up to PixelData), and dropped
/// before its frames are read. The rest of the stream after the last frame is not read, so
/// a stream corrupt only there loads on demand where the in-memory parse refuses it.
pub(super) fn open(
    file: &InputFile,
    limits: &Limits,
) -> Result<Option<(InputFile, u64, u64)>, LoadError> {
    let Some(source) = file.source() else {
        return Ok(None);
    };
    let located = {
        let contents = file.contents()?;
        let preamble = if contents.len() >= 132 && &contents[128..132] == b"DICM" {
            128
        } else {
            0
        };
        validate::deflated_pixel_data(&file.name, &contents[preamble..], limits)?
            .map(|(from, at, len)| (from + preamble as u64, at, len))
    };
    let Some((from, at, len)) = located else {
        return Ok(None);
    };
    let end = at.saturating_add(len);
    if end > limits.max_decompressed_bytes {
        return Err(LoadError::TooLarge {
            file: file.name.clone(),
            what: "the inflated data set".to_owned(),
            bytes: end,
            limit: limits.max_decompressed_bytes,
        });
    }
    let inflated = InflatedSource {
        compressed: source,
        start: from,
        len: end,
        state: Mutex::new(State::new(from)),
    };
    // In the browser the compressed source holds JavaScript objects (not `Send`); it has one
    // thread.
    #[allow(clippy::arc_with_non_send_sync)]
    let inflated = Arc::new(inflated);
    let inflated = InputFile::on_demand(file.name.clone(), inflated).map_err(|e| {
        let problem = if e.kind() == std::io::ErrorKind::UnexpectedEof {
            Corruption::Truncated
        } else {
            Corruption::Corrupt
        };
        LoadError::decompress(&file.name, "the deflated data set", problem, Some(e.into()))
    })?;
    Ok(Some((inflated, at, len)))
}
