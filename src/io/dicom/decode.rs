//! Opening a file's pixel data for decoding: encapsulated frames decoded one at a time, native
//! samples read where they lie, and what can be refused from the header alone.

use dicom_pixeldata::PixelDecoder;

use super::pixels::Pixels;
use super::{FileHeader, NATIVE_SYNTAXES, check_transfer_syntax, encapsulated, open};
use crate::io::{InputFile, Limits, LoadError};

/// Decodes frame `frame` of encapsulated pixel data (RLE with our decoder, JPEG and JPEG 2000
/// with dicom-rs's) into its little-endian samples.
pub(super) fn decode_frame(
    h: &FileHeader,
    fragments: &[&[u8]],
    frames: &[std::ops::Range<usize>],
    frame: usize,
    frame_len: usize,
) -> Result<Vec<u8>, String> {
    let parts = frames
        .get(frame)
        .and_then(|r| fragments.get(r.clone()))
        .ok_or_else(|| format!("no fragment holds frame {frame}"))?;
    let frame_bytes = frame_len * usize::from(h.bits_allocated.div_ceil(8).max(1));
    if h.transfer_syntax.trim_end_matches(['\0', ' ']) == encapsulated::RLE_LOSSLESS {
        let mut out = Vec::new();
        out.try_reserve_exact(frame_bytes)
            .map_err(|_| format!("out of memory for a frame of {frame_bytes} bytes"))?;
        out.resize(frame_bytes, 0);
        let mut segment = Vec::new();
        encapsulated::decode_rle_frame(
            h,
            parts.first().copied().unwrap_or_default(),
            &mut out,
            &mut segment,
        )
        .map_err(|m| format!("RLE Lossless: {m}"))?;
        return Ok(out);
    }
    // A frame in several fragments is one codestream cut in pieces.
    let joined: Vec<u8>;
    let codestream: &[u8] = match parts {
        [one] => one,
        many => {
            joined = many.concat();
            &joined
        }
    };
    let mut out = Vec::new();
    encapsulated::decode_codestream_frame(h, codestream, &mut out)?;
    if out.len() < frame_bytes {
        return Err(format!(
            "frame {frame} decodes to {} bytes; {}x{} pixels at {} bits need {frame_bytes}",
            out.len(),
            h.cols,
            h.rows,
            h.bits_allocated
        ));
    }
    Ok(out)
}

/// Opens a file, decodes its pixel data once and hands them to `f`. Native little-endian
/// samples are read where they lie: in memory without a copy, from a file read on demand a
/// frame at a time (no parsed object holds them); others where the parsed object holds them.
///
/// With `release` (the last read of this file: [`crate::io::FileSource::release_before`]),
/// pixel data parsed into memory lets the file's bytes go once parsed; native samples read
/// where they lie are let go frame by frame by the caller ([`Pixels::release_before_frame`]).
/// A deflated data set read on demand has its native samples inflated as they are read
/// ([`super::inflated`]).
pub(super) fn with_pixel_data<R>(
    file: &InputFile,
    header: &FileHeader,
    limits: &Limits,
    release: bool,
    f: impl FnOnce(&Pixels<'_>) -> Result<R, LoadError>,
) -> Result<R, LoadError> {
    if let Some((offset, len)) = header.native_pixels
        && offset.saturating_add(len) <= file.len()
    {
        if !file.is_on_demand() {
            let at = usize::try_from(offset).unwrap_or(usize::MAX);
            let end = usize::try_from(offset + len).unwrap_or(usize::MAX);
            if let Some(data) = file.bytes.get(at..end) {
                return f(&Pixels::Bytes(data));
            }
        } else {
            return f(&Pixels::InFile { file, offset, len });
        }
    }
    if file.is_on_demand()
        && header.transfer_syntax.trim_end_matches(['\0', ' '])
            == super::validate::DEFLATED_EXPLICIT_LE
        && matches!(header.bits_allocated, 8 | 16 | 32)
        && let Some((inflated, offset, len)) = super::inflated::open(file, limits)?
    {
        // A deflated data set read on demand: its frames are inflated as they are read.
        return f(&Pixels::InFile {
            file: &inflated,
            offset,
            len,
        });
    }
    if file.is_on_demand()
        && let Some(at) = header.encapsulated_pixels
        && matches!(header.bits_allocated, 8 | 16)
    {
        // Compressed frames of a file read on demand: located, checked and then read from the
        // file a frame at a time, so the fragments are never all in memory (parsed, they were
        // the file's size again beside the voxels).
        let ts = header.transfer_syntax.trim_end_matches(['\0', ' ']);
        let located = encapsulated::locate_fragments(file, at)?;
        let lens: Vec<u64> = located.fragments.iter().map(|f| f.1).collect();
        if ts == encapsulated::RLE_LOSSLESS {
            let total = usize::try_from(lens.iter().sum::<u64>()).unwrap_or(usize::MAX);
            encapsulated::check_rle_size(&file.name, header, total)?;
        } else {
            for (i, &(offset, len)) in located.fragments.iter().enumerate() {
                let head = encapsulated::read_range(
                    file,
                    offset,
                    len.min(encapsulated::CODESTREAM_HEAD_BYTES),
                )?;
                encapsulated::check_codestream(&file.name, header, i, &head)?;
            }
        }
        let mut failed = None;
        let frames = encapsulated::frames_of_fragments(
            ts,
            header.frames.len(),
            &lens,
            &located.offset_table,
            |i| {
                let (offset, len) = located.fragments[i];
                match encapsulated::read_range(file, offset, len.min(8)) {
                    Ok(head) => encapsulated::starts_codestream(&head),
                    Err(e) => {
                        failed.get_or_insert(e);
                        false
                    }
                }
            },
        );
        if let Some(e) = failed {
            return Err(e);
        }
        if let Some(frames) = frames {
            return f(&Pixels::EncodedInFile {
                file,
                fragments: &located.fragments,
                frames,
            });
        }
        // Frames that cannot be told apart are decoded whole, from the parsed file, below.
    }
    let obj = open(file, false, limits)?;
    if release {
        // The object holds its own copy of everything: the file's bytes are not read again.
        file.data().release_before(file.len());
    }
    let fragments = encapsulated::fragments(&obj);
    if let Some(frags) = &fragments {
        let ts = header.transfer_syntax.trim_end_matches(['\0', ' ']);
        // Checked for every frame before the first is decoded (and before the caller makes
        // the voxel buffer).
        if ts == encapsulated::RLE_LOSSLESS {
            encapsulated::check_rle_size(&file.name, header, frags.iter().map(|f| f.len()).sum())?;
        } else {
            encapsulated::check_codestreams(&file.name, header, frags)?;
        }
        // Frames decoded one at a time: the fragments, one decoded frame and the voxels are
        // what is held, not every frame decoded beside the voxels. RLE, JPEG and JPEG 2000 of
        // 8 or 16 bits; the rest (deflated image frames, 1-bit data) are decoded whole below.
        if !NATIVE_SYNTAXES.contains(&ts)
            && matches!(header.bits_allocated, 8 | 16)
            && let Some(frames) = encapsulated::frame_fragments(
                ts,
                header.frames.len(),
                frags,
                encapsulated::offset_table(&obj),
            )
        {
            return f(&Pixels::Encoded {
                fragments: frags,
                frames,
            });
        }
    }
    let rle_data;
    let decoded;
    let native;
    let data: &[u8] = match &fragments {
        Some(frags)
            if header.transfer_syntax.trim_end_matches(['\0', ' '])
                == encapsulated::RLE_LOSSLESS =>
        {
            rle_data = encapsulated::decode_rle(&file.name, header, frags)?;
            &rle_data
        }
        // Native samples are read where the object holds them: dicom-pixeldata would copy
        // them twice (to bytes, then to a vector), a third and fourth copy of the pixels.
        None if header.bits_allocated != 1
            && let Some(bytes) = native_pixel_bytes(&obj) =>
        {
            native = bytes;
            &native
        }
        _ => {
            if let Some(frags) = &fragments {
                encapsulated::check_codestreams(&file.name, header, frags)?;
            }
            decoded = obj.decode_pixel_data().map_err(|e| LoadError::DicomRead {
                file: file.name.clone(),
                what: format!("cannot decode pixel data ({})", header.transfer_syntax),
                source: Box::new(e),
            })?;
            decoded.data()
        }
    };
    f(&Pixels::Bytes(data))
}

/// The native PixelData's bytes as the object holds them (little endian), without a copy
/// where the value is bytes (OB) or, on a little-endian machine, 16-bit words (OW).
pub(super) fn native_pixel_bytes(
    obj: &dicom_object::DefaultDicomObject,
) -> Option<std::borrow::Cow<'_, [u8]>> {
    use dicom_core::value::PrimitiveValue;
    let dicom_core::DicomValue::Primitive(p) =
        obj.get(dicom_dictionary_std::tags::PIXEL_DATA)?.value()
    else {
        return None;
    };
    Some(match p {
        PrimitiveValue::U8(v) => std::borrow::Cow::Borrowed(v.as_slice()),
        PrimitiveValue::U16(v) if cfg!(target_endian = "little") => {
            std::borrow::Cow::Borrowed(bytemuck::cast_slice(v.as_slice()))
        }
        other => other.to_bytes(),
    })
}

/// What can be refused from a file's header and size alone: a transfer syntax without a
/// decoder, 1-bit data in a compressed syntax, RLE data too small to hold the frames.
pub(super) fn check_before_decoding(
    file: &InputFile,
    header: &FileHeader,
) -> Result<(), LoadError> {
    check_transfer_syntax(&file.name, &header.transfer_syntax)?;
    let ts = header.transfer_syntax.trim_end_matches(['\0', ' ']);
    if header.bits_allocated == 1 && !NATIVE_SYNTAXES.contains(&ts) {
        // dicom-rs's RLE and JPEG 2000 decoders handle 8 and 16 bits only.
        return Err(LoadError::UnsupportedTransferSyntax {
            file: file.name.clone(),
            uid: header.transfer_syntax.clone(),
            name: super::transfer_syntax_name(&header.transfer_syntax),
            reason:
                "1-bit (binary segmentation) pixel data can be read only uncompressed or deflated"
                    .to_owned(),
        });
    }
    if ts == encapsulated::RLE_LOSSLESS {
        // The whole file bounds the compressed size.
        encapsulated::check_rle_size(
            &file.name,
            header,
            usize::try_from(file.len()).unwrap_or(usize::MAX),
        )?;
    }
    Ok(())
}
