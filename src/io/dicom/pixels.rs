//! A series' samples into the volume's voxels: the type they are stored in, the rescale, and a
//! file's pixel data read frame by frame.

use super::decode::decode_frame;
use super::series::Frame;
use super::{FileHeader, encapsulated};
use crate::io::InputFile;
use crate::volume::Voxels;

/// How decoded samples are stored in the volume.
#[derive(Clone, Copy, PartialEq, Debug)]
pub(super) enum Target {
    U8,
    I16,
    U16,
    F32,
}

impl Target {
    /// The compact type that holds a stored sample of these bits without loss (32-bit samples
    /// go to f32).
    pub(super) fn raw(bits_allocated: u16, signed: bool) -> Self {
        match (bits_allocated, signed) {
            (1, _) | (8, false) => Self::U8,
            (8, true) => Self::I16,
            (16, false) => Self::U16,
            (16, true) => Self::I16,
            _ => Self::F32,
        }
    }

    pub(super) fn bytes(self) -> u64 {
        match self {
            Self::U8 => 1,
            Self::I16 | Self::U16 => 2,
            Self::F32 => 4,
        }
    }

    /// An empty voxel buffer of this type.
    pub(super) fn empty(self) -> Voxels {
        match self {
            Self::U8 => Voxels::U8(Vec::new()),
            Self::I16 => Voxels::I16(Vec::new()),
            Self::U16 => Voxels::U16(Vec::new()),
            Self::F32 => Voxels::F32(Vec::new()),
        }
    }
}

/// Whether every frame shares one rescale (then the volume keeps the raw type) and the type the
/// voxels are stored in; differing rescales need physical floats, which the user is told.
pub(super) fn pixel_target(
    first: &FileHeader,
    frames: &[Frame<'_>],
    warnings: &mut Vec<String>,
) -> (Target, bool) {
    let same_rescale = frames.iter().all(|f| {
        f.info.slope == frames[0].info.slope && f.info.intercept == frames[0].info.intercept
    });
    if same_rescale {
        (Target::raw(first.bits_allocated, first.signed), true)
    } else {
        warnings.push("RescaleSlope/RescaleIntercept differ between slices: values are stored as 32-bit floats".to_owned());
        (Target::F32, false)
    }
}

/// The volume's rescale: the frames' own when they share one, else identity (the voxels then
/// hold physical values).
pub(super) fn volume_rescale(frames: &[Frame<'_>], same_rescale: bool) -> (f32, f32) {
    if same_rescale {
        (frames[0].info.slope as f32, frames[0].info.intercept as f32)
    } else {
        (1.0, 0.0)
    }
}

/// Writes one frame's stored samples into `voxels[dst]`: as they are, or (into f32 voxels)
/// through `rescale` = (slope, intercept).
pub(super) fn store_frame(
    voxels: &mut Voxels,
    dst: std::ops::Range<usize>,
    samples: &[i64],
    rescale: (f64, f64),
) {
    match voxels {
        Voxels::U8(v) => v[dst]
            .iter_mut()
            .zip(samples)
            .for_each(|(o, s)| *o = *s as u8),
        Voxels::I16(v) => v[dst]
            .iter_mut()
            .zip(samples)
            .for_each(|(o, s)| *o = *s as i16),
        Voxels::U16(v) => v[dst]
            .iter_mut()
            .zip(samples)
            .for_each(|(o, s)| *o = *s as u16),
        Voxels::F32(v) => {
            let (a, b) = rescale;
            v[dst]
                .iter_mut()
                .zip(samples)
                .for_each(|(o, s)| *o = (*s as f64 * a + b) as f32)
        }
        // Loaders fill dense buffers; only the viewer packs a volume, after loading.
        Voxels::Packed(_) => {}
    }
}

/// A file's pixel data, ready for [`Pixels::frame_samples`]: decoded bytes of all frames,
/// native samples where they lie in the file (read a frame at a time), or encapsulated frames
/// decoded one at a time when stored.
pub(super) enum Pixels<'a> {
    Bytes(&'a [u8]),
    InFile {
        file: &'a InputFile,
        offset: u64,
        len: u64,
    },
    Encoded {
        fragments: &'a [&'a [u8]],
        /// The fragments of each frame ([`encapsulated::frame_fragments`]).
        frames: Vec<std::ops::Range<usize>>,
    },
    /// Encapsulated frames of a file read on demand, their fragments read from where they lie
    /// (offset, length) one frame at a time.
    EncodedInFile {
        file: &'a InputFile,
        fragments: &'a [(u64, u64)],
        frames: Vec<std::ops::Range<usize>>,
    },
}

/// Pixels converted at a time: a frame's samples go through an i64 scratch in pieces of at most
/// this many, so that the scratch stays small whatever the frame's size (a 20000 x 20000 frame
/// would otherwise need 3.2 GB of it).
pub(super) const PIECE_PIXELS: usize = 1 << 18;

impl Pixels<'_> {
    /// Stores frame `frame` of `n_frames` into `voxels` from `dst_start` on ([`store_frame`]),
    /// a piece at a time; `samples` is the scratch.
    #[allow(clippy::too_many_arguments)] // one frame's place: kept explicit rather than bundled
    pub(super) fn store(
        &self,
        h: &FileHeader,
        frame: usize,
        n_frames: usize,
        frame_len: usize,
        voxels: &mut Voxels,
        dst_start: usize,
        rescale: (f64, f64),
        samples: &mut Vec<i64>,
    ) -> Result<(), String> {
        if let Self::EncodedInFile {
            file,
            fragments,
            frames,
        } = self
        {
            let parts = frames
                .get(frame)
                .and_then(|r| fragments.get(r.clone()))
                .ok_or_else(|| format!("no fragment holds frame {frame}"))?;
            let read: Vec<Vec<u8>> = parts
                .iter()
                .map(|&(at, len)| encapsulated::read_range(file, at, len))
                .collect::<Result<_, _>>()
                .map_err(|e| crate::error::chain(&e))?;
            let refs: Vec<&[u8]> = read.iter().map(Vec::as_slice).collect();
            // The frame's fragments, read: frame 0 of them all.
            let whole = std::iter::once(0..refs.len()).collect::<Vec<_>>();
            let decoded = decode_frame(h, &refs, &whole, 0, frame_len)?;
            return Pixels::Bytes(&decoded)
                .store(h, 0, 1, frame_len, voxels, dst_start, rescale, samples);
        }
        if let Self::Encoded { fragments, frames } = self {
            // One frame decoded, stored, and dropped before the next.
            let decoded = decode_frame(h, fragments, frames, frame, frame_len)?;
            return Pixels::Bytes(&decoded)
                .store(h, 0, 1, frame_len, voxels, dst_start, rescale, samples);
        }
        let bytes = usize::from(h.bits_allocated / 8);
        if !matches!(h.bits_allocated, 8 | 16 | 32) {
            // 1-bit frames (packed or not) are taken whole; other sizes are refused whole.
            samples.clear();
            self.frame_samples(h, frame, n_frames, frame_len, 0, frame_len, samples)?;
            store_frame(voxels, dst_start..dst_start + frame_len, samples, rescale);
            return Ok(());
        }
        let frame_bytes = frame_len as u64 * bytes as u64;
        let len = match self {
            Self::Bytes(d) => d.len() as u64,
            Self::InFile { len, .. } => *len,
            Self::Encoded { .. } | Self::EncodedInFile { .. } => {
                return Err("internal: encoded frames are decoded first".into());
            }
        };
        if (frame as u64 + 1) * frame_bytes > len {
            return Err(format!(
                "pixel data has {len} bytes; frame {frame} of {}x{} pixels at {} bits needs {}",
                h.cols,
                h.rows,
                h.bits_allocated,
                (frame as u64 + 1) * frame_bytes
            ));
        }
        let mut at = 0;
        while at < frame_len {
            let n = PIECE_PIXELS.min(frame_len - at);
            samples.clear();
            self.frame_samples(h, frame, n_frames, frame_len, at, n, samples)?;
            store_frame(voxels, dst_start + at..dst_start + at + n, samples, rescale);
            at += n;
        }
        Ok(())
    }

    /// Lets go the bytes of native samples lying in the file before frame `frame` (frames
    /// are then read in increasing order, none below `frame` again); nothing for the others.
    pub(super) fn release_before_frame(&self, h: &FileHeader, frame: usize, frame_len: usize) {
        match self {
            Self::InFile { file, offset, .. } if matches!(h.bits_allocated, 8 | 16 | 32) => {
                let frame_bytes = frame_len as u64 * u64::from(h.bits_allocated / 8);
                let at = offset.saturating_add((frame as u64).saturating_mul(frame_bytes));
                file.data().release_before(at);
            }
            Self::EncodedInFile {
                file,
                fragments,
                frames,
            } => {
                // Up to the item header of the frame's first fragment.
                if let Some(&(at, _)) = frames.get(frame).and_then(|r| fragments.get(r.start)) {
                    file.data().release_before(at.saturating_sub(8));
                }
            }
            _ => {}
        }
    }

    /// [`frame_samples`] of pixels `first..first + count` of frame `frame` of `n_frames`
    /// (the whole frame for 1-bit data).
    #[allow(clippy::too_many_arguments)] // one piece's place: kept explicit rather than bundled
    fn frame_samples(
        &self,
        h: &FileHeader,
        frame: usize,
        n_frames: usize,
        frame_len: usize,
        first: usize,
        count: usize,
        out: &mut Vec<i64>,
    ) -> Result<(), String> {
        let bytes = u64::from(h.bits_allocated / 8);
        if !matches!(h.bits_allocated, 8 | 16 | 32) {
            return match self {
                Self::Bytes(data) => frame_samples(h, data, frame, n_frames, frame_len, out),
                Self::InFile { .. } | Self::Encoded { .. } | Self::EncodedInFile { .. } => {
                    Err(format!(
                        "BitsAllocated {} is not read from the file directly",
                        h.bits_allocated
                    ))
                }
            };
        }
        let start = (frame as u64 * frame_len as u64 + first as u64) * bytes;
        let piece = count as u64 * bytes;
        match self {
            Self::Bytes(data) => {
                let src = usize::try_from(start)
                    .ok()
                    .and_then(|s| data.get(s..s.checked_add(piece as usize)?))
                    .ok_or("pixel data too short")?;
                frame_samples(h, src, 0, 1, count, out)
            }
            Self::InFile { file, offset, len } => {
                if start + piece > *len {
                    return Err("pixel data too short".to_owned());
                }
                let mut buf = Vec::new();
                buf.try_reserve_exact(piece as usize)
                    .map_err(|_| format!("out of memory for {piece} bytes of a frame"))?;
                buf.resize(piece as usize, 0);
                file.data()
                    .read_at(&file.name, offset + start, &mut buf)
                    .map_err(|e| crate::error::chain(&e))?;
                frame_samples(h, &buf, 0, 1, count, out)
            }
            Self::Encoded { .. } | Self::EncodedInFile { .. } => {
                Err("internal: encoded frames are decoded first".to_owned())
            }
        }
    }
}

/// The stored values of one frame as i64 (sign-extended or masked to BitsStored), checking that
/// the decoded data hold the whole frame.
pub(super) fn frame_samples(
    h: &FileHeader,
    data: &[u8],
    frame: usize,
    n_frames: usize,
    frame_len: usize,
    out: &mut Vec<i64>,
) -> Result<(), String> {
    let total_pixels = frame_len.saturating_mul(n_frames);
    match h.bits_allocated {
        1 => {
            // Native 1-bit data are expanded to one byte per pixel by dicom-pixeldata; some
            // codecs keep them packed. Either way a pixel is 0 or 1.
            if data.len() >= total_pixels {
                let src = data
                    .get(frame * frame_len..(frame + 1) * frame_len)
                    .ok_or("pixel data too short")?;
                out.extend(src.iter().map(|&b| i64::from(b != 0)));
            } else {
                let start_bit = frame * frame_len;
                let needed = (start_bit + frame_len).div_ceil(8);
                if data.len() < needed {
                    return Err(format!(
                        "pixel data has {} bytes; {} frames of 1-bit pixels need {}",
                        data.len(),
                        n_frames,
                        total_pixels.div_ceil(8)
                    ));
                }
                out.extend(
                    (start_bit..start_bit + frame_len)
                        .map(|bit| i64::from((data[bit / 8] >> (bit % 8)) & 1)),
                );
            }
            Ok(())
        }
        8 | 16 | 32 => {
            let bytes = usize::from(h.bits_allocated / 8);
            let frame_bytes = frame_len * bytes;
            let src = data
                .get(frame * frame_bytes..(frame + 1) * frame_bytes)
                .ok_or_else(|| {
                    format!(
                        "pixel data has {} bytes; frame {} of {}x{} pixels at {} bits needs {}",
                        data.len(),
                        frame,
                        h.cols,
                        h.rows,
                        h.bits_allocated,
                        (frame + 1) * frame_bytes
                    )
                })?;
            let stored = u32::from(h.bits_stored.clamp(1, h.bits_allocated));
            let shift = 64 - stored;
            out.extend(src.chunks_exact(bytes).map(|c| {
                let raw = match bytes {
                    1 => u64::from(c[0]),
                    2 => u64::from(u16::from_le_bytes([c[0], c[1]])),
                    _ => u64::from(u32::from_le_bytes([c[0], c[1], c[2], c[3]])),
                };
                if h.signed {
                    ((raw << shift) as i64) >> shift
                } else {
                    ((raw << shift) >> shift) as i64
                }
            }));
            Ok(())
        }
        other => Err(format!("BitsAllocated {other} is not supported")),
    }
}
