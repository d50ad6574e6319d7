//! Checks every length a DICOM file declares against the bytes that are present, before
//! dicom-rs parses it: dicom-rs allocates and zero-fills a value's declared length before reading
//! it, so a corrupt length of 0xFFFFFFF0 would cost 4 GiB. The file meta group is walked by hand,
//! then read by dicom-rs to find the data set, which is walked through dicom-rs's own token reader.
//!
//! The same walk refuses sequences nested deeper than [`MAX_SEQUENCE_DEPTH`] (dicom-rs builds
//! objects recursively: ~7,500 levels overflow a native stack, ~900 the browser's) and a native
//! PixelData far longer than Rows x Columns x frames x bits needs. A deflated data set
//! (1.2.840.10008.1.2.1.99) is inflated as the walk goes, capped by
//! [`Limits::max_decompressed_bytes`], and walked like any other.

use std::cell::{Cell, RefCell};
use std::io::Read;
use std::rc::Rc;

use dicom_core::Tag;
use dicom_encoding::transfer_syntax::{TransferSyntax, TransferSyntaxIndex as _};
use dicom_object::meta::FileMetaTable;
use dicom_parser::dataset::{DataSetReader, DataToken, read::DataSetReaderOptions};
use dicom_transfer_syntax_registry::TransferSyntaxRegistry;

use crate::io::{Limits, LoadError};

mod meta;

use meta::Walker;

const PIXEL_DATA: (u16, u16) = (0x7FE0, 0x0010);
/// Deflated Explicit VR Little Endian: the whole data set deflated.
pub(super) const DEFLATED_EXPLICIT_LE: &str = "1.2.840.10008.1.2.1.99";
const EXPLICIT_LE: &str = "1.2.840.10008.1.2.1";

/// Deepest nesting of sequences accepted. Real files stay under 10 levels; dicom-rs builds each
/// level with a recursive call, and 64 of them are far from any stack's end.
pub(crate) const MAX_SEQUENCE_DEPTH: usize = 64;

/// How much longer than Rows x Columns x frames x samples x bits / 8 a native PixelData may be
/// (padding, a miscounted frame or two) before it is refused as a lie: twice that, plus this.
const PIXEL_DATA_SLACK_BYTES: u64 = 1 << 20;

/// Bytes inflated at a time from a deflated data set.
const INFLATE_CHUNK: usize = 64 << 10;

/// Checks the file meta group and the data set. `body` starts at the "DICM" magic (the preamble
/// is already skipped). With `until_pixel_data` the walk stops where dicom-rs's header-only read
/// stops (the first top-level tag at or after PixelData), after checking PixelData's length.
///
/// Returns where a top-level PixelData of defined length starts in `body` and how long it is
/// declared (not checked to be present when `until_pixel_data`), for a data set that is not
/// deflated: its native samples can then be read where they lie. For encapsulated pixel data
/// the length is [`UNDEFINED_LENGTH`] and the offset is where its items start.
///
/// Also says whether a walk `until_pixel_data` stopped at PixelData (or the first top-level tag
/// after it) in a data set that is not deflated: then `body` holds every element a header-only
/// read needs, so a file's first bytes can stand for it.
pub(super) fn check_lengths(
    file: &str,
    body: &[u8],
    limits: &Limits,
    until_pixel_data: bool,
) -> Result<(Option<(u64, u64)>, bool), LoadError> {
    let found = walk_lengths(file, body, limits, until_pixel_data)?;
    Ok((
        found.pixel_data.filter(|_| found.deflated_from.is_none()),
        found.stopped,
    ))
}

/// Where a deflated data set's native PixelData lies: the deflate stream's start in `body`,
/// then the PixelData value's offset and declared length in the inflated data set (the walk
/// of [`check_lengths`], up to PixelData, every check included). `None` when the data set is
/// not deflated or holds no PixelData of defined length before its end.
pub(super) fn deflated_pixel_data(
    file: &str,
    body: &[u8],
    limits: &Limits,
) -> Result<Option<(u64, u64, u64)>, LoadError> {
    let found = walk_lengths(file, body, limits, true)?;
    Ok(found
        .deflated_from
        .zip(found.pixel_data)
        .filter(|(_, (_, len))| *len != UNDEFINED_LENGTH)
        .map(|(from, (at, len))| (from, at, len)))
}

/// What the walk of [`check_lengths`] found.
struct Found {
    /// The top-level PixelData's value (offset, declared length): in `body`, or for a deflated
    /// data set in the inflated data set.
    pixel_data: Option<(u64, u64)>,
    stopped: bool,
    /// Where a deflated data set's deflate stream starts in `body`.
    deflated_from: Option<u64>,
}

fn walk_lengths(
    file: &str,
    body: &[u8],
    limits: &Limits,
    until_pixel_data: bool,
) -> Result<Found, LoadError> {
    let nothing = Found {
        pixel_data: None,
        stopped: false,
        deflated_from: None,
    };
    let Some(rest) = body.strip_prefix(b"DICM") else {
        return Ok(nothing); // dicom-rs reports the missing magic itself
    };
    // The meta group is always explicit VR little endian. dicom-rs reads elements while fewer
    // bytes than its (0002,0000) declares have been read, whatever tags it meets (and reserves
    // what each declares, read whole even past the declared end), so the walk does the same,
    // each length checked against the bytes present, and the declared length must be present
    // (a fuzzed file declared 33 MB of group in 841 bytes and then a 3.2 GB element). Without
    // a group length (which dicom-rs refuses) the group ends where group 0002 ends.
    let group_len = (rest.len() >= 12 && rest[..6] == [2, 0, 0, 0, b'U', b'L'])
        .then(|| u32::from_le_bytes([rest[8], rest[9], rest[10], rest[11]]) as usize);
    if let Some(g) = group_len
        && g > rest.len() - 12
    {
        return Err(LoadError::truncated(
            file,
            "the DICOM file meta group",
            g as u64,
            (rest.len() - 12) as u64,
        ));
    }
    let mut walker = Walker {
        file,
        bytes: rest,
        pos: 0,
        end: group_len.map_or(usize::MAX, |g| 12 + g),
        explicit: true,
        big_endian: false,
        stop_after_group2: group_len.is_none(),
        transfer_syntax: None,
    };
    walker.walk()?;
    // Where the data set starts and how it is encoded, exactly as dicom-rs will see it: its own
    // meta reader on the same bytes (it trusts the group length where a hand walk would stop at
    // a mutated tag). A meta group it cannot read is reported by the parse proper.
    let pos = Rc::new(Cell::new(0));
    let mut source = CountingReader {
        bytes: body,
        pos: Rc::clone(&pos),
    };
    let Ok(meta) = FileMetaTable::from_reader(&mut source) else {
        return Ok(nothing);
    };
    let ts = meta.transfer_syntax().trim_end_matches(['\0', ' ']);
    let data = body.get(pos.get()..).unwrap_or_default();
    let data_start = pos.get() as u64;
    let walk = Walk {
        file,
        limits,
        until_pixel_data,
        pixel_data: Cell::new(None),
        stopped: Cell::new(false),
    };
    if ts == DEFLATED_EXPLICIT_LE {
        // dicom-rs inflates the data set and reads it as explicit VR little endian; so does the
        // walk, holding only a window of the inflated bytes.
        let Some(syntax) = TransferSyntaxRegistry.get(EXPLICIT_LE) else {
            return Ok(nothing);
        };
        let inflater = Rc::new(RefCell::new(Inflater::new(
            file,
            data,
            limits.max_decompressed_bytes,
        )));
        let reader = InflatingReader {
            inflater: Rc::clone(&inflater),
        };
        let pos = Rc::clone(&inflater.borrow().pos);
        let result = walk.tokens(reader, syntax, &pos, |at, len| {
            inflater.borrow_mut().available(at, len)
        });
        // A cap reached inside a read shows as a read error; name the cap instead.
        if let Some(e) = inflater.borrow_mut().failure.take() {
            return Err(e);
        }
        result?;
        return Ok(Found {
            pixel_data: walk.pixel_data.get().map(|(at, len)| (at as u64, len)),
            stopped: false,
            deflated_from: Some(data_start),
        });
    }
    let Some(syntax) = TransferSyntaxRegistry.get(ts) else {
        return Ok(nothing); // dicom-rs names the unknown transfer syntax itself
    };
    let pos = Rc::new(Cell::new(0));
    let source = CountingReader {
        bytes: data,
        pos: Rc::clone(&pos),
    };
    let total = data.len() as u64;
    walk.tokens(source, syntax, &pos, |at, _| {
        Ok(total.saturating_sub(at as u64))
    })?;
    let pixel_data = walk
        .pixel_data
        .get()
        .map(|(at, len)| (data_start + at as u64, len));
    Ok(Found {
        pixel_data,
        stopped: walk.stopped.get(),
        deflated_from: None,
    })
}

/// A byte source that tells how far it has been read.
struct CountingReader<'a> {
    bytes: &'a [u8],
    pos: Rc<Cell<usize>>,
}

impl Read for CountingReader<'_> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let start = self.pos.get().min(self.bytes.len());
        let n = buf.len().min(self.bytes.len() - start);
        buf[..n].copy_from_slice(&self.bytes[start..start + n]);
        self.pos.set(start + n);
        Ok(n)
    }
}

/// A deflated data set inflated on demand into a window that holds the bytes from the reader's
/// position to as far as a length check needed to look.
struct Inflater<'a> {
    file: &'a str,
    decoder: flate2::read::DeflateDecoder<&'a [u8]>,
    /// Inflated bytes from `window_start` on.
    window: Vec<u8>,
    window_start: usize,
    /// Where the token reader is, in inflated bytes.
    pos: Rc<Cell<usize>>,
    ended: bool,
    cap: u64,
    failure: Option<LoadError>,
}

impl<'a> Inflater<'a> {
    fn new(file: &'a str, deflated: &'a [u8], cap: u64) -> Self {
        Self {
            file,
            decoder: flate2::read::DeflateDecoder::new(deflated),
            window: Vec::new(),
            window_start: 0,
            pos: Rc::new(Cell::new(0)),
            ended: false,
            cap,
            failure: None,
        }
    }

    fn window_end(&self) -> usize {
        self.window_start + self.window.len()
    }

    /// Inflates one more chunk; false at the end of the stream, on a corrupt stream (dicom-rs
    /// reports it) or at the cap.
    fn pull(&mut self) -> bool {
        if self.ended {
            return false;
        }
        if self.window_end() as u64 >= self.cap {
            self.ended = true;
            self.failure = Some(LoadError::TooLarge {
                file: self.file.to_owned(),
                what: "the inflated DICOM data set (deflated transfer syntax)".to_owned(),
                bytes: self.window_end() as u64 + 1,
                limit: self.cap,
            });
            return false;
        }
        // Drop what the reader has consumed before growing the window.
        let consumed = self.pos.get().saturating_sub(self.window_start);
        if consumed > (1 << 20) && consumed * 2 > self.window.len() {
            self.window.drain(..consumed);
            self.window_start += consumed;
        }
        let old = self.window.len();
        let room = (self.cap - self.window_end() as u64).min(INFLATE_CHUNK as u64) as usize;
        if self.window.try_reserve(room).is_err() {
            self.ended = true;
            self.failure = Some(LoadError::OutOfMemory {
                file: self.file.to_owned(),
                what: "inflating the DICOM data set".to_owned(),
                bytes: (self.window.len() + room) as u64,
            });
            return false;
        }
        self.window.resize(old + room, 0);
        match self.decoder.read(&mut self.window[old..]) {
            Ok(n) if n > 0 => {
                self.window.truncate(old + n);
                true
            }
            _ => {
                self.window.truncate(old);
                self.ended = true;
                false
            }
        }
    }

    /// How many bytes are present from `at` on, looking no further than `len` of them.
    fn available(&mut self, at: usize, len: u64) -> Result<u64, LoadError> {
        let wanted = (at as u64).saturating_add(len);
        while (self.window_end() as u64) < wanted && self.pull() {}
        if let Some(e) = self.failure.take() {
            return Err(e);
        }
        Ok((self.window_end() as u64).saturating_sub(at as u64))
    }
}

/// The token reader's view of an [`Inflater`].
struct InflatingReader<'a> {
    inflater: Rc<RefCell<Inflater<'a>>>,
}

impl Read for InflatingReader<'_> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let mut inf = self.inflater.borrow_mut();
        let at = inf.pos.get();
        if at >= inf.window_end() && !inf.pull() {
            return if inf.failure.is_some() {
                Err(std::io::Error::other("inflation cap reached"))
            } else {
                Ok(0)
            };
        }
        let start = at - inf.window_start;
        let n = buf.len().min(inf.window.len() - start);
        buf[..n].copy_from_slice(&inf.window[start..start + n]);
        inf.pos.set(at + n);
        Ok(n)
    }
}

/// Top-level attributes the PixelData length is checked against.
#[derive(Default)]
struct ImageSize {
    rows: Option<u64>,
    cols: Option<u64>,
    frames: Option<u64>,
    bits: Option<u64>,
    samples: Option<u64>,
}

impl ImageSize {
    fn slot(&mut self, tag: Tag) -> Option<&mut Option<u64>> {
        match (tag.group(), tag.element()) {
            (0x0028, 0x0010) => Some(&mut self.rows),
            (0x0028, 0x0011) => Some(&mut self.cols),
            (0x0028, 0x0008) => Some(&mut self.frames),
            (0x0028, 0x0100) => Some(&mut self.bits),
            (0x0028, 0x0002) => Some(&mut self.samples),
            _ => None,
        }
    }

    /// Bytes of native pixel data the attributes call for, when Rows and Columns are known.
    fn pixel_bytes(&self) -> Option<u64> {
        let bits = self.bits.unwrap_or(16).max(1);
        let bits_total = self
            .rows?
            .checked_mul(self.cols?)?
            .checked_mul(self.frames.unwrap_or(1).max(1))?
            .checked_mul(self.samples.unwrap_or(1).max(1))?
            .checked_mul(bits)?;
        Some(bits_total.div_ceil(8))
    }
}

/// The declared length [`check_lengths`] gives an encapsulated PixelData, whose value is a
/// sequence of items (fragments) of undefined length in all.
pub(super) const UNDEFINED_LENGTH: u64 = u64::MAX;

struct Walk<'a> {
    file: &'a str,
    limits: &'a Limits,
    until_pixel_data: bool,
    /// Where the top-level PixelData's value starts (in the data set) and its declared length
    /// ([`UNDEFINED_LENGTH`] for encapsulated pixel data: where its first item starts).
    pixel_data: Cell<Option<(usize, u64)>>,
    /// Whether the walk stopped at the first top-level tag at or after PixelData (with
    /// `until_pixel_data`), rather than at the end of the bytes.
    stopped: Cell<bool>,
}

impl Walk<'_> {
    /// Reads the data set with dicom-rs's own token reader, and before each value is read
    /// (which is when dicom-rs allocates and zero-fills the declared length) checks that the
    /// declared length is present (`available(position, length)` says how many bytes are, up
    /// to `length`). Following dicom-rs's tokens, instead of a second parser that mimics it,
    /// means the check cannot disagree with dicom-rs about where an element starts.
    fn tokens<R: Read>(
        &self,
        source: R,
        syntax: &TransferSyntax,
        pos: &Cell<usize>,
        mut available: impl FnMut(usize, u64) -> Result<u64, LoadError>,
    ) -> Result<(), LoadError> {
        let file = self.file;
        let Ok(reader) =
            DataSetReader::new_with_ts_options(source, syntax, DataSetReaderOptions::default())
        else {
            return Ok(()); // dicom-rs reports the same failure when it parses the file
        };
        let mut depth = 0usize;
        let mut size = ImageSize::default();
        // The top-level attribute whose value comes next, if it is one of `size`'s.
        let mut pending: Option<Tag> = None;
        for token in reader {
            let Ok(token) = token else {
                return Ok(()); // the parse proper reports it
            };
            let declared = match token {
                DataToken::SequenceStart { tag, .. } => {
                    if depth == 0 && self.until_pixel_data && tag >= pixel_tag() {
                        self.stopped.set(true);
                        return Ok(());
                    }
                    depth += 1;
                    if depth > MAX_SEQUENCE_DEPTH {
                        return Err(LoadError::Dicom {
                            file: file.to_owned(),
                            problem: crate::io::DicomProblem::NestedTooDeep {
                                limit: MAX_SEQUENCE_DEPTH,
                                group: tag.group(),
                                element: tag.element(),
                                at: pos.get() as u64,
                            },
                        });
                    }
                    None
                }
                DataToken::PixelSequenceStart => {
                    if depth == 0 {
                        // Encapsulated: its items start here (the length is undefined).
                        self.pixel_data.set(Some((pos.get(), UNDEFINED_LENGTH)));
                    }
                    if depth == 0 && self.until_pixel_data {
                        self.stopped.set(true);
                        return Ok(());
                    }
                    depth += 1;
                    None
                }
                DataToken::SequenceEnd => {
                    depth = depth.saturating_sub(1);
                    None
                }
                DataToken::ElementHeader(header) => {
                    let tag = header.tag;
                    if depth == 0 {
                        pending = size.slot(tag).is_some().then_some(tag);
                        if (tag.group(), tag.element()) == PIXEL_DATA
                            && let Some(len) = header.len.get()
                        {
                            self.check_native_pixel_data(u64::from(len), &size)?;
                            self.pixel_data.set(Some((pos.get(), u64::from(len))));
                        }
                        if self.until_pixel_data && tag >= pixel_tag() {
                            self.stopped.set(true);
                            return Ok(());
                        }
                    }
                    Some((tag, header.len))
                }
                DataToken::ItemStart { len } => Some((Tag(0xFFFE, 0xE000), len)),
                DataToken::PrimitiveValue(value) => {
                    if let Some(tag) = pending.take()
                        && let Some(slot) = size.slot(tag)
                    {
                        *slot = value.to_int::<u64>().ok();
                    }
                    None
                }
                _ => None,
            };
            let Some((tag, len)) = declared else {
                continue;
            };
            let Some(len) = len.get() else {
                continue; // undefined length: a sequence or item, walked into
            };
            // The header has been read; its value has not.
            let present = available(pos.get(), u64::from(len))?;
            if u64::from(len) > present {
                return Err(LoadError::truncated(
                    file,
                    format!(
                        "DICOM element ({:04X},{:04X}) of {len} bytes",
                        tag.group(),
                        tag.element()
                    ),
                    u64::from(len),
                    present,
                ));
            }
        }
        Ok(())
    }

    /// Refuses a native PixelData far longer than the image attributes call for (a deflate
    /// bomb's 2.5 GB of zeros under a 512 x 512 header), or longer than the voxel cap.
    fn check_native_pixel_data(&self, len: u64, size: &ImageSize) -> Result<(), LoadError> {
        if len > self.limits.max_voxel_bytes {
            return Err(LoadError::TooLarge {
                file: self.file.to_owned(),
                what: "the native PixelData".to_owned(),
                bytes: len,
                limit: self.limits.max_voxel_bytes,
            });
        }
        if let Some(expected) = size.pixel_bytes()
            && len
                > expected
                    .saturating_mul(2)
                    .saturating_add(PIXEL_DATA_SLACK_BYTES)
        {
            return Err(LoadError::header(
                self.file,
                "PixelData",
                format!(
                    "holds {len} bytes, far more than the {expected} that Rows {} x Columns {} x {} frame(s) x {} sample(s) at {} bits need",
                    size.rows.unwrap_or(0),
                    size.cols.unwrap_or(0),
                    size.frames.unwrap_or(1),
                    size.samples.unwrap_or(1),
                    size.bits.unwrap_or(16)
                ),
            ));
        }
        Ok(())
    }
}

fn pixel_tag() -> Tag {
    Tag(PIXEL_DATA.0, PIXEL_DATA.1)
}
