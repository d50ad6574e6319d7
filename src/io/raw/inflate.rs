//! Decompressing a volume's voxels straight into their final buffer, the stream checked to its
//! end (gzip CRC-32 and ISIZE), and reading capped uncompressed streams.

use super::compress::*;
use super::*;

/// Decompresses the voxels of one volume straight into their final buffer, with a small
/// constant of scratch besides (peak memory ~ the voxel bytes): `skip` bytes of the stream are
/// dropped (a NIfTI header, an NRRD byte skip), then `layout` is decoded (offset 0 = the first
/// byte after `skip`). The stream is then read to its end, at most to `declared_bytes` (all the
/// header declares, other volumes included) plus a little slack, so that every gzip member's
/// CRC-32 and ISIZE (the zlib Adler-32) is checked: a corrupt file is refused, never loaded
/// with garbage. Wide integer types, whose compact type depends on their range, are inflated
/// twice: once for the range, once into the voxels. Returns the voxels and how many bytes the
/// whole stream held.
pub(crate) fn inflate_voxels(
    file: &str,
    kind: Compression,
    compressed: Data<'_>,
    skip: u64,
    layout: SampleLayout,
    declared_bytes: u64,
    limits: &Limits,
) -> Result<(Voxels, u64), LoadError> {
    let span = layout.span_bytes().unwrap_or(u64::MAX);
    let needed = skip.saturating_add(span);
    if needed > limits.max_decompressed_bytes {
        return Err(LoadError::TooLarge {
            file: file.to_owned(),
            what: format!("decompressed {} data", kind.name()),
            bytes: needed,
            limit: limits.max_decompressed_bytes,
        });
    }
    layout.check_voxel_budget(file, limits)?;
    check_expansion(
        file,
        &format!("{} data", kind.name()),
        compressed.len(),
        needed,
    )?;
    if kind == Compression::Gzip {
        check_gzip_trailer(file, compressed, needed, declared_bytes)?;
    }
    let stream = Stream {
        file,
        kind,
        layout,
        skip,
        needed,
    };
    let err = |e: std::io::Error| stream.error(e);
    let truncated = |got: u64| stream.truncated(got);
    let wide = matches!(
        layout.ty,
        SampleType::U32 | SampleType::I32 | SampleType::U64 | SampleType::I64
    );
    // The last pass over the stream lets the compressed bytes go as it reads them.
    let mut reader =
        std::io::BufReader::with_capacity(64 << 10, Members::new(file, kind, compressed, !wide));
    if !skip_bytes(&mut reader, skip).map_err(err)? {
        return Err(truncated(skip));
    }
    // Wide integers become i16, u16 or f32 by their range: a first pass finds the range (and
    // reads the stream to its end for its checksums), a second inflates again and converts,
    // so that no buffer of the stored bytes is ever held.
    let (voxels, range) = if wide {
        let mut samples = SampleReader::new(stream, &mut reader);
        let range = value_range(layout.count, |i| samples.value(i))?;
        (None, Some(range))
    } else {
        (Some(stream_samples(stream, &mut reader)?), None)
    };
    // The rest of the stream, so that the checksums at its end are read and checked.
    let allowed = declared_bytes
        .saturating_sub(needed)
        .saturating_add(STREAM_SLACK_BYTES);
    let rest =
        std::io::copy(&mut (&mut reader).take(allowed), &mut std::io::sink()).map_err(err)?;
    if rest == allowed {
        let mut probe = [0u8; 1];
        if reader.read(&mut probe).map_err(err)? > 0 {
            return Err(LoadError::decompress(
                file,
                kind.name(),
                Corruption::LongerThanDeclared {
                    declared: declared_bytes,
                    slack: STREAM_SLACK_BYTES,
                },
                None,
            ));
        }
    }
    let voxels = match (voxels, range) {
        (Some(v), _) => v,
        (None, range) => {
            let mut again = std::io::BufReader::with_capacity(
                64 << 10,
                Members::new(file, kind, compressed, true),
            );
            if !skip_bytes(&mut again, skip).map_err(err)? {
                return Err(truncated(skip));
            }
            let mut samples = SampleReader::new(stream, &mut again);
            let range = range.unwrap_or((0.0, 0.0));
            compact_wide(file, layout.count, range, |i| samples.value(i))?
        }
    };
    compressed.release_before(compressed.len());
    Ok((voxels, needed + rest))
}

/// Refuses, before anything is inflated, a single-member gzip stream whose trailer (ISIZE, the
/// uncompressed size mod 2^32) cannot be the size of data that hold the `needed` bytes and no
/// more than `declared` plus the slack: the checks the full read makes at the end, made first.
///
/// Safe only for a single member, whose ISIZE is the whole stream's: a stream in which the
/// bytes 1F 8B 08 (a member's start) occur anywhere after the first header might hold several
/// members (the last one's ISIZE says nothing about the others), so it is left to the full read.
/// Zero padding after the member is allowed (as gzip does): every place the trailer could end,
/// from the last byte back over the trailing zeros, is tried, and one that fits is enough.
pub(super) fn check_gzip_trailer(
    file: &str,
    compressed: Data<'_>,
    needed: u64,
    declared: u64,
) -> Result<(), LoadError> {
    const HEADER: u64 = 10;
    let len = compressed.len();
    if len < HEADER + 8 {
        return Ok(()); // the full read reports the truncated stream
    }
    // Another member's start anywhere after the first header? (Read in chunks that overlap by
    // two bytes, so that no place is missed.)
    let mut at = HEADER;
    let mut chunk = Vec::new();
    while at < len {
        let n = (len - at).min(1 << 20) as usize;
        chunk.resize(n, 0);
        compressed.read_at(file, at, &mut chunk)?;
        if chunk.windows(3).any(|w| w == [0x1f, 0x8b, 0x08]) {
            return Ok(());
        }
        if at + n as u64 >= len {
            break;
        }
        at += (n as u64).saturating_sub(2).max(1);
    }
    // The last bytes: the trailer, behind at most 64 KiB of zero padding.
    let tail_len = len.min((1 << 16) + 16);
    let tail_start = len - tail_len;
    let mut tail = vec![0u8; tail_len as usize];
    compressed.read_at(file, tail_start, &mut tail)?;
    let max = declared.saturating_add(STREAM_SLACK_BYTES);
    // A size s fits when needed <= s <= max and s = isize (mod 2^32).
    let fits = |isize: u32| {
        let isize = u64::from(isize);
        let k = needed.saturating_sub(isize).div_ceil(1 << 32);
        isize
            .checked_add(k.saturating_mul(1 << 32))
            .is_some_and(|s| s >= needed && s <= max)
    };
    let zeros = tail.iter().rev().take_while(|&&b| b == 0).count();
    if zeros > 1 << 16 {
        return Ok(()); // that much padding is rare: left to the full read
    }
    let mut seen = None;
    for pad in 0..=zeros {
        // The ISIZE field ends `pad` bytes before the end; the CRC-32 and a header precede it.
        let Some(end) = tail.len().checked_sub(pad) else {
            break;
        };
        let Some(t) = end.checked_sub(4) else {
            break;
        };
        if tail_start + (t as u64) < HEADER + 4 {
            break;
        }
        let isize = u32::from_le_bytes([tail[t], tail[t + 1], tail[t + 2], tail[t + 3]]);
        if fits(isize) {
            return Ok(());
        }
        seen.get_or_insert(isize);
    }
    match seen {
        Some(isize) if u64::from(isize) < needed => Err(LoadError::truncated(
            file,
            format!("gzip data (its trailer says {isize} bytes, mod 2^32; nothing was inflated)"),
            needed,
            u64::from(isize),
        )),
        Some(isize) => Err(LoadError::decompress(
            file,
            "gzip",
            Corruption::TrailerTooLarge {
                trailer: isize,
                max,
            },
            None,
        )),
        None => Ok(()),
    }
}

/// A layout's samples (offset 0) in a decompressing stream, after `skip` bytes: `needed` bytes
/// in all.
#[derive(Clone, Copy)]
pub(super) struct Stream<'f> {
    file: &'f str,
    kind: Compression,
    layout: SampleLayout,
    skip: u64,
    needed: u64,
}

impl Stream<'_> {
    /// The stream ended after `got` of the `needed` bytes.
    fn truncated(&self, got: u64) -> LoadError {
        LoadError::truncated(
            self.file,
            format!("decompressed {} data", self.kind.name()),
            self.needed,
            got,
        )
    }

    fn error(&self, e: std::io::Error) -> LoadError {
        decompress_error(self.file, self.kind, e)
    }
}

/// Reads the samples of a [`Stream`] one by one.
pub(super) struct SampleReader<'r, 'a> {
    stream: Stream<'r>,
    reader: &'r mut std::io::BufReader<Members<'a>>,
    /// Bytes read since the skip.
    done: u64,
}

impl<'r, 'a> SampleReader<'r, 'a> {
    fn new(stream: Stream<'r>, reader: &'r mut std::io::BufReader<Members<'a>>) -> Self {
        Self {
            stream,
            reader,
            done: 0,
        }
    }

    /// Sample `i` (called in order) as 8 little-endian bytes, zero-extended.
    fn next(&mut self, i: usize) -> Result<[u8; 8], LoadError> {
        let layout = self.stream.layout;
        let size = layout.ty.size();
        let truncated = |done: u64| self.stream.truncated(self.stream.skip + done);
        if i > 0 && layout.stride_samples > 1 {
            let gap = ((layout.stride_samples - 1) * size) as u64;
            match skip_bytes(self.reader, gap) {
                Ok(true) => self.done += gap,
                Ok(false) => return Err(truncated(self.done)),
                Err(e) => return Err(self.stream.error(e)),
            }
        }
        let mut a = [0u8; 8];
        if let Err(e) = self.reader.read_exact(&mut a[..size]) {
            return Err(if e.kind() == std::io::ErrorKind::UnexpectedEof {
                truncated(self.done)
            } else {
                self.stream.error(e)
            });
        }
        self.done += size as u64;
        if layout.endian == Endian::Big {
            a[..size].reverse();
        }
        Ok(a)
    }

    /// Sample `i` (called in order) as its value.
    fn value(&mut self, i: usize) -> Result<f64, LoadError> {
        let a = self.next(i)?;
        Ok(sample_f64(&a, self.stream.layout.ty, Endian::Little, 0).unwrap_or(0.0))
    }
}

/// Decodes `layout` (offset 0) from a stream into a buffer of the final type that grows as the
/// samples arrive (reserved once, never zero-filled ahead of the data).
pub(super) fn stream_samples(
    stream: Stream<'_>,
    reader: &mut std::io::BufReader<Members<'_>>,
) -> Result<Voxels, LoadError> {
    let (file, layout) = (stream.file, stream.layout);
    let n = layout.count;
    if layout.ty == SampleType::U8 && layout.stride_samples == 1 {
        // The common case in bulk: read straight into the buffer's spare capacity.
        let mut v = reserve::<u8>(file, "voxels", n)?;
        (&mut *reader)
            .take(n as u64)
            .read_to_end(&mut v)
            .map_err(|e| stream.error(e))?;
        if v.len() < n {
            return Err(stream.truncated(stream.skip + v.len() as u64));
        }
        return Ok(Voxels::U8(v));
    }
    let mut samples = SampleReader::new(stream, reader);
    let mut next = |i| samples.next(i);
    Ok(match layout.ty {
        SampleType::U8 => Voxels::U8(collect(file, n, |i| Ok(next(i)?[0]))?),
        SampleType::I8 => Voxels::I16(collect(file, n, |i| Ok(i16::from(next(i)?[0] as i8)))?),
        SampleType::U16 => Voxels::U16(collect(file, n, |i| {
            next(i).map(|a| u16::from_le_bytes([a[0], a[1]]))
        })?),
        SampleType::I16 => Voxels::I16(collect(file, n, |i| {
            next(i).map(|a| i16::from_le_bytes([a[0], a[1]]))
        })?),
        SampleType::F32 => Voxels::F32(collect(file, n, |i| {
            next(i).map(|a| f32::from_le_bytes([a[0], a[1], a[2], a[3]]))
        })?),
        SampleType::F64 => Voxels::F32(collect(file, n, |i| {
            next(i).map(|a| f64::from_le_bytes(a) as f32)
        })?),
        SampleType::U32 | SampleType::I32 | SampleType::U64 | SampleType::I64 => {
            return Err(LoadError::unsupported(
                file,
                "streamed sample type",
                format!("{:?} (internal: converted in two passes)", layout.ty),
            ));
        }
    })
}

pub(super) fn read_capped(
    file: &str,
    reader: impl Read,
    max_out: u64,
    kind: &str,
) -> Result<(Vec<u8>, bool), LoadError> {
    // One byte more than the cap tells whether the stream goes on past it.
    let mut limited = reader.take(max_out.saturating_add(1));
    let mut out = Vec::new();
    // Reserve modestly; the buffer grows as data arrive and the cap bounds the growth.
    let _ = out.try_reserve(max_out.min(1 << 26) as usize);
    let mut chunk = [0u8; 8192];
    loop {
        match limited.read(&mut chunk) {
            Ok(0) => break,
            Ok(n) => out.extend_from_slice(&chunk[..n]),
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(_) if !out.is_empty() => break,
            Err(e) => {
                let e = match LoadError::carried_by(e) {
                    Ok(read_failed) => return Err(read_failed),
                    Err(e) => e,
                };
                let problem = if e.kind() == std::io::ErrorKind::UnexpectedEof {
                    Corruption::Truncated
                } else {
                    Corruption::Corrupt
                };
                return Err(LoadError::decompress(file, kind, problem, Some(e.into())));
            }
        }
    }
    let more = out.len() as u64 > max_out;
    if more {
        out.truncate(max_out as usize);
    }
    Ok((out, more))
}
