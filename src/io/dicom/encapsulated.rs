//! Encapsulated (compressed) pixel data: our own RLE Lossless decoder, and a check of each JPEG
//! and JPEG 2000 frame's declared size against Rows/Columns before dicom-rs decodes it. Both
//! exist because dicom-rs 0.10's adapters index out of bounds (a panic, which on wasm32 ends
//! the page) on a truncated RLE segment or a codestream larger than Rows x Columns.

use dicom_core::DicomValue;
use dicom_dictionary_std::tags;
use dicom_object::DefaultDicomObject;

use super::FileHeader;
use crate::io::{DicomProblem, LoadError};

pub(super) const RLE_LOSSLESS: &str = "1.2.840.10008.1.2.5";

/// The fragments of encapsulated pixel data, or `None` for native pixel data.
pub(super) fn fragments(obj: &DefaultDicomObject) -> Option<Vec<&[u8]>> {
    let element = obj.get(tags::PIXEL_DATA)?;
    match element.value() {
        DicomValue::PixelSequence(seq) => Some(seq.fragments().iter().map(Vec::as_slice).collect()),
        _ => None,
    }
}

/// The Basic Offset Table of encapsulated pixel data (empty when absent or native).
pub(super) fn offset_table(obj: &DefaultDicomObject) -> &[u32] {
    match obj.get(tags::PIXEL_DATA).map(|e| e.value()) {
        Some(DicomValue::PixelSequence(seq)) => seq.offset_table(),
        _ => &[],
    }
}

/// Which fragments make each frame (PS3.5 A.4), as ranges of fragment indices, so that frames
/// are decoded one at a time: RLE has one fragment per frame; otherwise one fragment per frame
/// when the counts agree, all of them for a single frame, else the Basic Offset Table, else a
/// new frame at each fragment that starts a codestream (JPEG SOI, JPEG 2000 SOC or the JP2
/// signature). `None` when none of these gives `n_frames` frames.
pub(super) fn frame_fragments(
    transfer_syntax: &str,
    n_frames: usize,
    frags: &[&[u8]],
    offset_table: &[u32],
) -> Option<Vec<std::ops::Range<usize>>> {
    let lens: Vec<u64> = frags.iter().map(|f| f.len() as u64).collect();
    frames_of_fragments(transfer_syntax, n_frames, &lens, offset_table, |i| {
        starts_codestream(frags[i])
    })
}

/// [`frame_fragments`] from the fragments' lengths and whether each starts a codestream
/// (`starts(i)`, asked only when the counts and the offset table do not settle it).
pub(super) fn frames_of_fragments(
    transfer_syntax: &str,
    n_frames: usize,
    lens: &[u64],
    offset_table: &[u32],
    mut starts: impl FnMut(usize) -> bool,
) -> Option<Vec<std::ops::Range<usize>>> {
    let n_frags = lens.len();
    let one_each = || Some((0..n_frames).map(|k| k..k + 1).collect());
    if transfer_syntax == RLE_LOSSLESS {
        return if n_frags >= n_frames {
            one_each()
        } else {
            None
        };
    }
    if n_frames == 0 || n_frags == 0 {
        return None;
    }
    if n_frags == n_frames {
        return one_each();
    }
    if n_frames == 1 {
        return Some(std::iter::once(0..n_frags).collect());
    }
    if offset_table.len() == n_frames && offset_table[0] == 0 {
        // Offsets are from the first fragment's item header; each item header is 8 bytes.
        let mut firsts = Vec::with_capacity(n_frames);
        let mut at = 0u64;
        let mut next = 0;
        for (i, len) in lens.iter().enumerate() {
            if next < n_frames && u64::from(offset_table[next]) == at {
                firsts.push(i);
                next += 1;
            }
            at += len + 8;
        }
        if firsts.len() == n_frames {
            return Some(ranges_from_starts(&firsts, n_frags));
        }
    }
    let firsts: Vec<usize> = (0..n_frags).filter(|&i| starts(i)).collect();
    (firsts.len() == n_frames && firsts.first() == Some(&0))
        .then(|| ranges_from_starts(&firsts, n_frags))
}

/// Encapsulated pixel data located in a file rather than parsed into memory: each fragment's
/// offset and length in the file (the Basic Offset Table's item excluded), and that table.
#[derive(Debug)]
pub(super) struct FragmentsInFile {
    pub fragments: Vec<(u64, u64)>,
    pub offset_table: Vec<u32>,
}

/// Items (fragments and the offset table) walked at most: four per frame of the largest frame
/// count accepted, 64 MiB of table.
const MAX_ITEMS: usize = 4 * super::MAX_FRAMES as usize;

/// Walks the items of encapsulated pixel data from `at` (where [`super::FileHeader`] says they
/// start) to the sequence delimiter (or the end of the file, where dicom-rs ends it too),
/// reading only the 8-byte item headers (and the offset table's item). A tag that is not an
/// item, a length past the end of the file or more than [`MAX_ITEMS`] items is an error
/// naming the file.
pub(super) fn locate_fragments(
    file: &crate::io::InputFile,
    at: u64,
) -> Result<FragmentsInFile, LoadError> {
    let bad = |message: String| LoadError::Dicom {
        file: file.name.clone(),
        problem: DicomProblem::Encapsulated(message),
    };
    let len = file.len();
    let mut pos = at;
    let mut items: Vec<(u64, u64)> = Vec::new();
    loop {
        let mut head = [0u8; 8];
        if pos.saturating_add(8) > len {
            // Items running to the end of the file without the sequence delimiter: dicom-rs
            // ends the sequence there too (and loads the file from memory), so do the same.
            break;
        }
        if items.len() >= MAX_ITEMS {
            return Err(bad(format!(
                "more than {MAX_ITEMS} items (fragments); the file is corrupt or crafted"
            )));
        }
        items.try_reserve(1).map_err(|_| LoadError::OutOfMemory {
            file: file.name.clone(),
            what: "the table of compressed fragments".to_owned(),
            bytes: (items.len() as u64 + 1) * 16,
        })?;
        file.data().read_at(&file.name, pos, &mut head)?;
        let group = u16::from_le_bytes([head[0], head[1]]);
        let element = u16::from_le_bytes([head[2], head[3]]);
        let item_len = u64::from(u32::from_le_bytes([head[4], head[5], head[6], head[7]]));
        match (group, element) {
            (0xFFFE, 0xE0DD) => break,
            (0xFFFE, 0xE000) => {
                let start = pos + 8;
                if item_len == 0xFFFF_FFFF || start.saturating_add(item_len) > len {
                    return Err(bad(format!(
                        "item {} at byte {pos} declares {item_len} bytes; the file has {}",
                        items.len(),
                        len.saturating_sub(start)
                    )));
                }
                items.push((start, item_len));
                pos = start + item_len;
            }
            _ => {
                return Err(bad(format!(
                    "({group:04X},{element:04X}) at byte {pos} where an item or the sequence delimiter belongs"
                )));
            }
        }
    }
    let Some(&(bot_at, bot_len)) = items.first() else {
        return Err(bad("no Basic Offset Table item".to_owned()));
    };
    // The offset table holds one 32-bit offset per frame: a longer one is not read.
    let offset_table = if bot_len % 4 == 0 && bot_len <= 4 * (super::MAX_FRAMES as u64) {
        let mut bytes = vec![0u8; bot_len as usize];
        file.data().read_at(&file.name, bot_at, &mut bytes)?;
        bytes
            .chunks_exact(4)
            .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .collect()
    } else {
        Vec::new()
    };
    items.remove(0);
    Ok(FragmentsInFile {
        fragments: items,
        offset_table,
    })
}

/// Reads `len` bytes of a file at `at` into a new buffer (an error, never a panic, when memory
/// or the file runs out).
pub(super) fn read_range(
    file: &crate::io::InputFile,
    at: u64,
    len: u64,
) -> Result<Vec<u8>, LoadError> {
    let n = usize::try_from(len).unwrap_or(usize::MAX);
    let mut buf = crate::io::raw::try_vec(&file.name, "a compressed frame", n)?;
    file.data().read_at(&file.name, at, &mut buf)?;
    Ok(buf)
}

fn ranges_from_starts(starts: &[usize], n_frags: usize) -> Vec<std::ops::Range<usize>> {
    starts
        .iter()
        .enumerate()
        .map(|(k, &s)| s..starts.get(k + 1).copied().unwrap_or(n_frags))
        .collect()
}

/// Whether a fragment begins a JPEG (SOI), JPEG 2000 (SOC + SIZ) or JP2 codestream.
pub(super) fn starts_codestream(frag: &[u8]) -> bool {
    frag.starts_with(&[0xFF, 0xD8])
        || frag.starts_with(&[0xFF, 0x4F, 0xFF, 0x51])
        || frag.starts_with(&[0, 0, 0, 0x0C, b'j', b'P', b' ', b' '])
}

/// One frame's codestream as dicom-rs's decoders read a DICOM object: a single frame in a
/// single fragment. Handing the codec only this frame (rather than the whole object, whose
/// `raw_pixel_data` clones every fragment on each call) is what lets frames be decoded one at a
/// time.
struct OneFrame<'a> {
    header: &'a FileHeader,
    codestream: &'a [u8],
}

impl dicom_encoding::adapters::PixelDataObject for OneFrame<'_> {
    fn transfer_syntax_uid(&self) -> &str {
        self.header.transfer_syntax.trim_end_matches(['\0', ' '])
    }
    fn rows(&self) -> Option<u16> {
        u16::try_from(self.header.rows).ok()
    }
    fn cols(&self) -> Option<u16> {
        u16::try_from(self.header.cols).ok()
    }
    fn samples_per_pixel(&self) -> Option<u16> {
        Some(self.header.samples_per_pixel)
    }
    fn bits_allocated(&self) -> Option<u16> {
        Some(self.header.bits_allocated)
    }
    fn bits_stored(&self) -> Option<u16> {
        Some(self.header.bits_stored)
    }
    fn photometric_interpretation(&self) -> Option<&str> {
        Some(self.header.photometric.as_str())
    }
    fn number_of_frames(&self) -> Option<u32> {
        Some(1)
    }
    fn number_of_fragments(&self) -> Option<u32> {
        Some(1)
    }
    fn fragment(&self, fragment: usize) -> Option<std::borrow::Cow<'_, [u8]>> {
        (fragment == 0).then_some(std::borrow::Cow::Borrowed(self.codestream))
    }
    fn offset_table(&self) -> Option<std::borrow::Cow<'_, [u32]>> {
        None
    }
    fn raw_pixel_data(&self) -> Option<dicom_encoding::adapters::RawPixelData> {
        Some(dicom_encoding::adapters::RawPixelData {
            fragments: vec![self.codestream.to_vec()].into(),
            offset_table: Vec::new().into(),
        })
    }
}

/// Decodes one JPEG or JPEG 2000 frame (its codestream, the frame's fragments joined) with the
/// transfer syntax's decoder into `out` (little-endian samples).
pub(super) fn decode_codestream_frame(
    h: &FileHeader,
    codestream: &[u8],
    out: &mut Vec<u8>,
) -> Result<(), String> {
    use dicom_encoding::transfer_syntax::{Codec, TransferSyntaxIndex as _};
    let ts = h.transfer_syntax.trim_end_matches(['\0', ' ']);
    let decoder = match dicom_transfer_syntax_registry::TransferSyntaxRegistry
        .get(ts)
        .map(|t| t.codec())
    {
        Some(Codec::EncapsulatedPixelData(Some(decoder), _)) => decoder,
        _ => return Err(format!("no decoder for transfer syntax {ts}")),
    };
    out.clear();
    decoder
        .decode_frame(
            &OneFrame {
                header: h,
                codestream,
            },
            0,
            out,
        )
        .map_err(|e| format!("cannot decode ({ts}): {}", crate::error::chain(&e)))
}

/// Decodes RLE Lossless frames (DICOM PS3.5 annex G) into little-endian samples, one frame
/// per fragment.
pub(super) fn decode_rle(
    file: &str,
    h: &FileHeader,
    frags: &[&[u8]],
) -> Result<Vec<u8>, LoadError> {
    let err = |message: String| LoadError::Dicom {
        file: file.to_owned(),
        problem: DicomProblem::Rle(message),
    };
    let n_frames = h.frames.len();
    if frags.len() < n_frames {
        return Err(err(format!(
            "{} fragments for {n_frames} frames",
            frags.len()
        )));
    }
    let compressed: usize = frags.iter().map(|f| f.len()).sum();
    let total = check_rle_size(file, h, compressed)?;
    let mut out = crate::io::raw::try_vec::<u8>(file, "RLE pixel data", total)?;
    let frame_bytes = total / n_frames.max(1);
    let mut segment = Vec::new();
    for (f, frag) in frags.iter().take(n_frames).enumerate() {
        let dst = &mut out[f * frame_bytes..(f + 1) * frame_bytes];
        decode_rle_frame(h, frag, dst, &mut segment).map_err(|m| err(format!("frame {f}: {m}")))?;
    }
    Ok(out)
}

/// Decodes one RLE Lossless frame (one fragment) into `dst`, the frame's little-endian
/// samples (Rows x Columns x BitsAllocated / 8 bytes); `segment` is scratch.
pub(super) fn decode_rle_frame(
    h: &FileHeader,
    frag: &[u8],
    dst: &mut [u8],
    segment: &mut Vec<u8>,
) -> Result<(), String> {
    let bytes_per_sample = match h.bits_allocated {
        8 => 1,
        16 => 2,
        other => return Err(format!("BitsAllocated {other} is not supported")),
    };
    let pixels = h.rows as usize * h.cols as usize;
    if dst.len() != pixels * bytes_per_sample {
        return Err(format!(
            "internal: {} bytes for a frame of {pixels} pixels",
            dst.len()
        ));
    }
    if frag.len() < 64 {
        return Err(format!(
            "fragment of {} bytes has no RLE header",
            frag.len()
        ));
    }
    let word = |i: usize| {
        u32::from_le_bytes([
            frag[4 * i],
            frag[4 * i + 1],
            frag[4 * i + 2],
            frag[4 * i + 3],
        ]) as usize
    };
    let n_segments = word(0);
    if n_segments != bytes_per_sample {
        return Err(format!(
            "{n_segments} segments; expected {bytes_per_sample}"
        ));
    }
    for s in 0..n_segments {
        let start = word(1 + s);
        let end = if s + 1 < n_segments {
            word(2 + s)
        } else {
            frag.len()
        };
        let data = frag.get(start..end).ok_or_else(|| {
            format!(
                "segment {s} at {start}..{end} lies outside the {} byte fragment",
                frag.len()
            )
        })?;
        segment.clear();
        unpack_bits(data, pixels, segment);
        if segment.len() < pixels {
            return Err(format!(
                "segment {s} decodes to {} of {pixels} bytes",
                segment.len()
            ));
        }
        // Segment 0 holds the most significant bytes; output is little endian.
        let byte_in_sample = bytes_per_sample - 1 - s;
        for (p, &b) in segment.iter().enumerate() {
            dst[p * bytes_per_sample + byte_in_sample] = b;
        }
    }
    Ok(())
}

/// The decoded size of a file's RLE frames, refused when `compressed` bytes cannot hold them:
/// even the best RLE needs 2 bytes per 128 output bytes.
pub(super) fn check_rle_size(
    file: &str,
    h: &FileHeader,
    compressed: usize,
) -> Result<usize, LoadError> {
    let bytes_per_sample = usize::from(h.bits_allocated.div_ceil(8).max(1));
    let total = (h.rows as usize)
        .checked_mul(h.cols as usize)
        .and_then(|p| p.checked_mul(bytes_per_sample))
        .and_then(|b| b.checked_mul(h.frames.len()))
        .ok_or_else(|| LoadError::Dicom {
            file: file.to_owned(),
            problem: DicomProblem::Rle("frame size overflows".to_owned()),
        })?;
    if total / 64 > compressed.saturating_add(1 << 16) {
        return Err(LoadError::Dicom {
            file: file.to_owned(),
            problem: DicomProblem::RleTooSmall { compressed, total },
        });
    }
    Ok(total)
}

/// PackBits, stopping once `limit` bytes are out.
fn unpack_bits(data: &[u8], limit: usize, out: &mut Vec<u8>) {
    let mut i = 0;
    while i < data.len() && out.len() < limit {
        let n = data[i] as i8;
        i += 1;
        if n >= 0 {
            let count = n as usize + 1;
            let end = (i + count).min(data.len());
            let take = (end - i).min(limit - out.len());
            out.extend_from_slice(&data[i..i + take]);
            i = end;
        } else if n != -128 {
            let count = (1 - n as isize) as usize;
            let Some(&b) = data.get(i) else {
                break;
            };
            i += 1;
            let take = count.min(limit - out.len());
            out.extend(std::iter::repeat_n(b, take));
        }
    }
}

/// Rows, columns, bits and components a JPEG (SOF marker) or JPEG 2000 (SIZ marker) codestream
/// declares, if it can be found in its first bytes.
fn declared_size(codestream: &[u8]) -> Option<(u32, u32, u32, u32)> {
    let be16 = |at: usize| {
        codestream
            .get(at..at + 2)
            .map(|b| u32::from(u16::from_be_bytes([b[0], b[1]])))
    };
    let be32 = |at: usize| {
        codestream
            .get(at..at + 4)
            .map(|b| u32::from_be_bytes([b[0], b[1], b[2], b[3]]))
    };
    // JPEG 2000: SOC (FF4F) then SIZ (FF51), possibly inside a JP2 box structure.
    if let Some(at) = codestream
        .windows(4)
        .take(4096)
        .position(|w| w == [0xFF, 0x4F, 0xFF, 0x51])
    {
        let siz = at + 2; // the FF51 marker; offsets below are from ISO 15444-1 A.5.1
        let width = be32(siz + 6)?.checked_sub(be32(siz + 14)?)?;
        let height = be32(siz + 10)?.checked_sub(be32(siz + 18)?)?;
        let components = be16(siz + 38)?;
        let bits = u32::from(codestream.get(siz + 40)? & 0x7F) + 1;
        return Some((height, width, bits, components));
    }
    // JPEG: walk the markers after SOI to the first SOFn.
    if codestream.get(0..2) != Some(&[0xFF, 0xD8]) {
        return None;
    }
    let mut at = 2;
    while at + 4 <= codestream.len() && at < 1 << 20 {
        if codestream[at] != 0xFF {
            return None;
        }
        let marker = codestream[at + 1];
        if marker == 0xFF {
            at += 1;
            continue;
        }
        let len = be16(at + 2)? as usize;
        if (0xC0..=0xCF).contains(&marker) && !matches!(marker, 0xC4 | 0xC8 | 0xCC) {
            let bits = u32::from(*codestream.get(at + 4)?);
            let height = be16(at + 5)?;
            let width = be16(at + 7)?;
            let components = u32::from(*codestream.get(at + 9)?);
            return Some((height, width, bits, components));
        }
        at += 2 + len;
    }
    None
}

/// Refuses JPEG and JPEG 2000 frames whose codestream declares another size, more bits or more
/// components than the DICOM header (dicom-rs would write past its buffer).
pub(super) fn check_codestreams(
    file: &str,
    h: &FileHeader,
    frags: &[&[u8]],
) -> Result<(), LoadError> {
    for (f, frag) in frags.iter().enumerate() {
        check_codestream(file, h, f, frag)?;
    }
    Ok(())
}

/// Bytes of a fragment's start that [`check_codestream`] reads at most (the JPEG marker walk
/// stops within the first MiB).
pub(super) const CODESTREAM_HEAD_BYTES: u64 = (1 << 20) + 16;

/// [`check_codestreams`] of fragment `f` from its first [`CODESTREAM_HEAD_BYTES`].
pub(super) fn check_codestream(
    file: &str,
    h: &FileHeader,
    f: usize,
    frag: &[u8],
) -> Result<(), LoadError> {
    {
        let Some((rows, cols, bits, components)) = declared_size(frag) else {
            return Ok(());
        };
        // JPEG 2000 heights can come out as 0 for a zero-height image; treat as a mismatch.
        if rows != h.rows
            || cols != h.cols
            || bits > u32::from(h.bits_allocated)
            || components != u32::from(h.samples_per_pixel)
        {
            return Err(LoadError::Dicom {
                file: file.to_owned(),
                problem: DicomProblem::FragmentSize {
                    fragment: f,
                    found: format!("{cols}x{rows}, {bits} bits, {components} component(s)"),
                    declared: format!(
                        "{}x{}, {} bits allocated, {} sample(s) per pixel",
                        h.cols, h.rows, h.bits_allocated, h.samples_per_pixel
                    ),
                },
            });
        }
    }
    Ok(())
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // a failed unwrap is a failed test
mod tests;
