//! Shared low-level pieces of the loaders: capped decompression, fallible allocation, and the
//! conversion of raw sample bytes (any type, either endianness) into compact `Voxels`.

use std::io::{BufRead as _, Read};

use super::input::Data;
use super::{Corruption, Limits, LoadError};
use crate::volume::Voxels;

mod compress;
mod inflate;

pub(crate) use compress::{Compression, gunzip_prefix, gunzip_prefix_data, is_gzip};
pub(crate) use inflate::inflate_voxels;

/// Byte order of stored samples.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Endian {
    Little,
    Big,
}

/// The stored type of one sample, as the file declares it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum SampleType {
    U8,
    I8,
    U16,
    I16,
    U32,
    I32,
    U64,
    I64,
    F32,
    F64,
}

impl SampleType {
    pub(crate) fn size(self) -> usize {
        match self {
            Self::U8 | Self::I8 => 1,
            Self::U16 | Self::I16 => 2,
            Self::U32 | Self::I32 | Self::F32 => 4,
            Self::U64 | Self::I64 | Self::F64 => 8,
        }
    }

    /// Bytes per voxel once converted by [`decode_samples`] (an upper bound for the wider types,
    /// which may still fit in 16 bits).
    pub(crate) fn output_size(self) -> usize {
        match self {
            Self::U8 => 1,
            Self::I8 | Self::U16 | Self::I16 => 2,
            _ => 4,
        }
    }
}

/// `a * b * ...` without overflow, as u64.
pub(crate) fn checked_product(factors: &[u64]) -> Option<u64> {
    factors.iter().try_fold(1u64, |acc, &f| acc.checked_mul(f))
}

/// Refuses a voxel buffer larger than the limit before anything is allocated.
pub(crate) fn check_voxel_budget(
    file: &str,
    voxel_count: u64,
    bytes_per_voxel: u64,
    limits: &Limits,
) -> Result<(), LoadError> {
    let bytes = voxel_count.saturating_mul(bytes_per_voxel);
    if bytes > limits.max_voxel_bytes {
        return Err(LoadError::TooLarge {
            file: file.to_owned(),
            what: format!("{voxel_count} voxels"),
            bytes,
            limit: limits.max_voxel_bytes,
        });
    }
    Ok(())
}

/// Output a compressed file may expand to before [`check_expansion`] asks how much it grows
/// (1.25 GiB, 1.34 GB: a sparse label map of a whole-body CT, 0.5 GB at any ratio, stays
/// below).
pub(crate) const BOMB_MIN_BYTES: u64 = 1280 << 20;
/// How many times its compressed bytes a compressed file's output of more than
/// [`BOMB_MIN_BYTES`] may be. Real scans compress 2-5x losslessly (sparse label maps a few
/// hundred times, at a few hundred MB); a file of a few MB declaring gigabytes is a
/// decompression bomb, and reading it would cost the gigabytes before anything is seen. With
/// both, no input under 10 MB expands to more than 1.34 GB, so with the input and the process
/// it stays under the 1.5 GB issue 14 allows such inputs (the floor was 1.5 GiB = 1.61 GB).
pub(crate) const BOMB_RATIO: u64 = 128;

/// Refuses `out_bytes` of output (voxels, inflated bytes) from `compressed` bytes of `what`
/// when that is more than [`BOMB_MIN_BYTES`] and more than [`BOMB_RATIO`] times the compressed
/// bytes, before anything is allocated or inflated.
pub(crate) fn check_expansion(
    file: &str,
    what: &str,
    compressed: u64,
    out_bytes: u64,
) -> Result<(), LoadError> {
    if out_bytes > BOMB_MIN_BYTES && out_bytes / BOMB_RATIO > compressed {
        return Err(LoadError::decompress(
            file,
            what,
            Corruption::Bomb {
                compressed,
                declared: out_bytes,
                ratio: BOMB_RATIO,
            },
            None,
        ));
    }
    Ok(())
}

/// A vector of `len` default values, or an error instead of an abort when memory is short
/// (on wasm32 an allocation failure would otherwise end the page).
pub(crate) fn try_vec<T: Clone + Default>(
    file: &str,
    what: &str,
    len: usize,
) -> Result<Vec<T>, LoadError> {
    let mut v = reserve(file, what, len)?;
    v.resize(len, T::default());
    Ok(v)
}

/// A buffer reserved for `n` values, not filled (so not yet touched).
fn reserve<T>(file: &str, what: &str, n: usize) -> Result<Vec<T>, LoadError> {
    let mut v = Vec::new();
    v.try_reserve_exact(n).map_err(|_| LoadError::OutOfMemory {
        file: file.to_owned(),
        what: what.to_owned(),
        bytes: (n as u64).saturating_mul(std::mem::size_of::<T>() as u64),
    })?;
    Ok(v)
}

/// `n` voxel values, `value(i)` called in order, in a buffer reserved once.
fn collect<T>(
    file: &str,
    n: usize,
    mut value: impl FnMut(usize) -> Result<T, LoadError>,
) -> Result<Vec<T>, LoadError> {
    let mut v = reserve::<T>(file, "voxels", n)?;
    for i in 0..n {
        v.push(value(i)?);
    }
    Ok(v)
}

/// The smallest and largest of `n` values (`value(i)` called in order).
fn value_range(
    n: usize,
    mut value: impl FnMut(usize) -> Result<f64, LoadError>,
) -> Result<(f64, f64), LoadError> {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for i in 0..n {
        let x = value(i)?;
        lo = lo.min(x);
        hi = hi.max(x);
    }
    Ok((lo, hi))
}

/// `n` wide integers (`value(i)`, called in order, all within `range`) as the most compact
/// voxels that hold them exactly: i16 when they fit, else u16, else f32.
fn compact_wide(
    file: &str,
    n: usize,
    range: (f64, f64),
    mut value: impl FnMut(usize) -> Result<f64, LoadError>,
) -> Result<Voxels, LoadError> {
    let (lo, hi) = range;
    Ok(
        if n == 0 || (lo >= f64::from(i16::MIN) && hi <= f64::from(i16::MAX)) {
            Voxels::I16(collect(file, n, |i| Ok(value(i)? as i16))?)
        } else if lo >= 0.0 && hi <= f64::from(u16::MAX) {
            Voxels::U16(collect(file, n, |i| Ok(value(i)? as u16))?)
        } else {
            Voxels::F32(collect(file, n, |i| Ok(value(i)? as f32))?)
        },
    )
}

/// Reads fixed-size little/big endian numbers at offsets of a header that is known to be long
/// enough (callers check the length once; out-of-range reads give 0 rather than panicking).
#[derive(Clone, Copy)]
pub(crate) struct FieldReader<'a> {
    pub bytes: &'a [u8],
    pub endian: Endian,
}

impl FieldReader<'_> {
    fn array<const N: usize>(&self, offset: usize) -> [u8; N] {
        let mut a = [0u8; N];
        if let Some(src) = self.bytes.get(offset..offset + N) {
            a.copy_from_slice(src);
        }
        if self.endian == Endian::Big {
            a.reverse();
        }
        a
    }
    pub fn i16(&self, offset: usize) -> i16 {
        i16::from_le_bytes(self.array(offset))
    }
    pub fn i32(&self, offset: usize) -> i32 {
        i32::from_le_bytes(self.array(offset))
    }
    pub fn i64(&self, offset: usize) -> i64 {
        i64::from_le_bytes(self.array(offset))
    }
    pub fn f32(&self, offset: usize) -> f32 {
        f32::from_le_bytes(self.array(offset))
    }
    pub fn f64(&self, offset: usize) -> f64 {
        f64::from_le_bytes(self.array(offset))
    }
}

/// Reads sample `n` (0-based) of type `ty` as f64, `None` when it lies outside `bytes`.
#[inline]
fn sample_f64(bytes: &[u8], ty: SampleType, endian: Endian, offset: usize) -> Option<f64> {
    let size = ty.size();
    let src = bytes.get(offset..offset + size)?;
    let mut a = [0u8; 8];
    a[..size].copy_from_slice(src);
    if endian == Endian::Big {
        a[..size].reverse();
    }
    Some(match ty {
        SampleType::U8 => f64::from(a[0]),
        SampleType::I8 => f64::from(a[0] as i8),
        SampleType::U16 => f64::from(u16::from_le_bytes([a[0], a[1]])),
        SampleType::I16 => f64::from(i16::from_le_bytes([a[0], a[1]])),
        SampleType::U32 => f64::from(u32::from_le_bytes([a[0], a[1], a[2], a[3]])),
        SampleType::I32 => f64::from(i32::from_le_bytes([a[0], a[1], a[2], a[3]])),
        SampleType::F32 => f64::from(f32::from_le_bytes([a[0], a[1], a[2], a[3]])),
        SampleType::U64 => u64::from_le_bytes(a) as f64,
        SampleType::I64 => i64::from_le_bytes(a) as f64,
        SampleType::F64 => f64::from_le_bytes(a),
    })
}

/// Where the samples of one volume lie in a byte buffer: `count` samples, sample `n` at byte
/// `offset + n * stride_samples * ty.size()` (a stride above 1 picks one component out of
/// interleaved vectors).
#[derive(Clone, Copy, Debug)]
pub(crate) struct SampleLayout {
    pub ty: SampleType,
    pub endian: Endian,
    pub offset: usize,
    pub count: usize,
    pub stride_samples: usize,
}

impl SampleLayout {
    /// Bytes from `offset` to the end of the last sample read, or `None` on overflow.
    pub(crate) fn span_bytes(&self) -> Option<u64> {
        if self.count == 0 {
            return Some(0);
        }
        let last = (self.count as u64 - 1).checked_mul(self.stride_samples as u64)?;
        last.checked_add(1)?.checked_mul(self.ty.size() as u64)
    }

    /// Refuses the layout when its samples run past the `len` bytes given (the file is
    /// truncated) or its voxels would exceed the voxel budget.
    fn check_present(&self, file: &str, len: u64, limits: &Limits) -> Result<(), LoadError> {
        let span = self
            .span_bytes()
            .and_then(|s| s.checked_add(self.offset as u64))
            .unwrap_or(u64::MAX);
        if span > len {
            return Err(LoadError::truncated(file, "voxel data", span, len));
        }
        self.check_voxel_budget(file, limits)
    }

    /// Refuses the voxels of this layout when they would exceed the voxel budget.
    fn check_voxel_budget(&self, file: &str, limits: &Limits) -> Result<(), LoadError> {
        check_voxel_budget(
            file,
            self.count as u64,
            self.ty.output_size() as u64,
            limits,
        )
    }
}

/// Checks that `needed` bytes of `what` are present in `data`, then decodes `layout` (its
/// offset counted from the start of `data`): from memory, or read from the file straight into
/// the voxel buffer ([`decode_source`]).
pub(crate) fn decode_present(
    file: &str,
    what: &str,
    data: Data<'_>,
    needed: u64,
    layout: SampleLayout,
    limits: &Limits,
) -> Result<Voxels, LoadError> {
    if data.len() < needed {
        return Err(LoadError::truncated(file, what, needed, data.len()));
    }
    match data {
        Data::Memory(bytes) => decode_samples(file, bytes, layout, limits),
        Data::Source { .. } => decode_source(file, data, layout, limits),
    }
}

/// Bytes read at a time when samples are converted from a file read on demand.
const SOURCE_CHUNK_BYTES: usize = 1 << 20;

/// [`decode_samples`] for data read on demand, with the same result: samples whose stored type
/// is the voxels' own are read straight into the voxel buffer (then byte-swapped in place if
/// need be), others are converted from chunks of [`SOURCE_CHUNK_BYTES`]. Peak memory is the
/// voxels plus one chunk.
fn decode_source(
    file: &str,
    data: Data<'_>,
    layout: SampleLayout,
    limits: &Limits,
) -> Result<Voxels, LoadError> {
    layout.check_present(file, data.len(), limits)?;
    let n = layout.count;
    let offset = layout.offset as u64;
    let swap = (layout.endian == Endian::Little) != cfg!(target_endian = "little");
    if layout.stride_samples == 1 || n <= 1 {
        match layout.ty {
            SampleType::U8 => {
                let v = read_pieces::<u8>(file, data, offset, n)?;
                return Ok(Voxels::U8(v));
            }
            SampleType::I16 => {
                let mut v = read_pieces::<i16>(file, data, offset, n)?;
                if swap {
                    v.iter_mut().for_each(|x| *x = x.swap_bytes());
                }
                return Ok(Voxels::I16(v));
            }
            SampleType::U16 => {
                let mut v = read_pieces::<u16>(file, data, offset, n)?;
                if swap {
                    v.iter_mut().for_each(|x| *x = x.swap_bytes());
                }
                return Ok(Voxels::U16(v));
            }
            SampleType::F32 => {
                let mut v = read_pieces::<f32>(file, data, offset, n)?;
                if swap {
                    v.iter_mut()
                        .for_each(|x| *x = f32::from_bits(x.to_bits().swap_bytes()));
                }
                return Ok(Voxels::F32(v));
            }
            _ => {}
        }
    }
    // Read in order, each chunk let go once passed; wide integers are read twice (range, then
    // values), so only the second pass lets go.
    let wide = matches!(
        layout.ty,
        SampleType::U32 | SampleType::I32 | SampleType::U64 | SampleType::I64
    );
    let mut chunks = SourceChunks {
        file,
        data,
        layout,
        buf: Vec::new(),
        first: 0,
        held: 0,
        release: !wide,
    };
    let voxels = match layout.ty {
        SampleType::U8 => Voxels::U8(collect(file, n, |i| Ok(chunks.value(i)? as u8))?),
        SampleType::I8 | SampleType::I16 => {
            Voxels::I16(collect(file, n, |i| Ok(chunks.value(i)? as i16))?)
        }
        SampleType::U16 => Voxels::U16(collect(file, n, |i| Ok(chunks.value(i)? as u16))?),
        SampleType::F32 | SampleType::F64 => {
            Voxels::F32(collect(file, n, |i| Ok(chunks.value(i)? as f32))?)
        }
        SampleType::U32 | SampleType::I32 | SampleType::U64 | SampleType::I64 => {
            // One pass for the range decides the compact type; a second reads again and converts.
            let range = value_range(n, |i| chunks.value(i))?;
            chunks.release = true;
            compact_wide(file, n, range, |i| chunks.value(i))?
        }
    };
    data.release_before(data.len());
    Ok(voxels)
}

/// Values read at a time by [`read_pieces`] (16 MiB).
const PIECE_BYTES: usize = 16 << 20;

/// `n` values of `T` stored as they lie at `offset` of `data` (the payload's last read): the
/// buffer is reserved once and filled a piece at a time, each piece's bytes then let go
/// ([`Data::release_before`]; the rest of `data` at the end), so a
/// source that frees them (the browser's chunks) shrinks as the voxels grow, and the voxels'
/// memory is touched only as it is filled.
fn read_pieces<T: bytemuck::Pod>(
    file: &str,
    data: Data<'_>,
    offset: u64,
    n: usize,
) -> Result<Vec<T>, LoadError> {
    let mut v = reserve::<T>(file, "voxels", n)?;
    let per = (PIECE_BYTES / std::mem::size_of::<T>().max(1)).max(1);
    let mut at = offset;
    while v.len() < n {
        let from = v.len();
        v.resize(from + per.min(n - from), T::zeroed());
        let piece: &mut [u8] = bytemuck::cast_slice_mut(&mut v[from..]);
        data.read_at(file, at, piece)?;
        at += piece.len() as u64;
        data.release_before(at);
    }
    // The payload's last pass: whatever follows it (another volume of a 4D file) goes too.
    data.release_before(data.len());
    Ok(v)
}

/// The samples of a layout in data read on demand, a chunk at a time.
struct SourceChunks<'a> {
    file: &'a str,
    data: Data<'a>,
    layout: SampleLayout,
    buf: Vec<u8>,
    /// Index of the first sample in `buf`, and how many it holds.
    first: usize,
    held: usize,
    /// Whether the bytes before each new chunk are let go ([`Data::release_before`]).
    release: bool,
}

impl SourceChunks<'_> {
    /// Sample `i` as its value (any order; in order reads each chunk once).
    fn value(&mut self, i: usize) -> Result<f64, LoadError> {
        let size = self.layout.ty.size();
        let step = self.layout.stride_samples.saturating_mul(size).max(1);
        if !(self.first..self.first + self.held).contains(&i) {
            let per_chunk = (SOURCE_CHUNK_BYTES / step).max(1);
            let c = per_chunk.min(self.layout.count.saturating_sub(i)).max(1);
            let bytes = (c - 1).saturating_mul(step).saturating_add(size);
            let at =
                (self.layout.offset as u64).saturating_add((i as u64).saturating_mul(step as u64));
            if self.release {
                self.data.release_before(at);
            }
            self.buf.resize(bytes, 0);
            self.data.read_at(self.file, at, &mut self.buf)?;
            (self.first, self.held) = (i, c);
        }
        Ok(sample_f64(
            &self.buf,
            self.layout.ty,
            self.layout.endian,
            (i - self.first) * step,
        )
        .unwrap_or(0.0))
    }
}

/// How a volume read from `header` and, possibly, a separate data file is named to the user.
pub(crate) fn source_name(header: &str, data_file: &str) -> String {
    if data_file == header {
        header.to_owned()
    } else {
        format!("{header} + {data_file}")
    }
}

/// Converts raw samples into the most compact `Voxels` that holds them exactly: u8 stays u8,
/// i8/i16 become i16, u16 stays u16, wider integers become i16/u16 when every value fits and
/// f32 otherwise, and floats become f32. Checks that the bytes are present first.
pub(crate) fn decode_samples(
    file: &str,
    bytes: &[u8],
    layout: SampleLayout,
    limits: &Limits,
) -> Result<Voxels, LoadError> {
    layout.check_present(file, bytes.len() as u64, limits)?;
    let n = layout.count;
    let size = layout.ty.size();
    let step = layout.stride_samples * size;
    let at = |i: usize| layout.offset + i * step;
    let get = |i: usize| sample_f64(bytes, layout.ty, layout.endian, at(i)).unwrap_or(0.0);
    let read16 = |i: usize| {
        let p = at(i);
        let b = [bytes[p], bytes[p + 1]];
        match layout.endian {
            Endian::Little => u16::from_le_bytes(b),
            Endian::Big => u16::from_be_bytes(b),
        }
    };
    Ok(match layout.ty {
        SampleType::U8 => Voxels::U8(collect(file, n, |i| Ok(bytes[at(i)]))?),
        SampleType::I8 => Voxels::I16(collect(file, n, |i| Ok(i16::from(bytes[at(i)] as i8)))?),
        SampleType::U16 => Voxels::U16(collect(file, n, |i| Ok(read16(i)))?),
        SampleType::I16 => Voxels::I16(collect(file, n, |i| Ok(read16(i) as i16))?),
        SampleType::F32 | SampleType::F64 => Voxels::F32(collect(file, n, |i| Ok(get(i) as f32))?),
        SampleType::U32 | SampleType::I32 | SampleType::U64 | SampleType::I64 => {
            // One pass for the range decides the compact type; a second converts.
            let range = value_range(n, |i| Ok(get(i)))?;
            compact_wide(file, n, range, |i| Ok(get(i)))?
        }
    })
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // a failed unwrap is a failed test
mod tests {
    use super::*;

    #[test]
    fn wide_integers_are_compacted() {
        let limits = Limits::default();
        let bytes: Vec<u8> = [-5i32, 7, 1000]
            .iter()
            .flat_map(|v| v.to_le_bytes())
            .collect();
        let layout = SampleLayout {
            ty: SampleType::I32,
            endian: Endian::Little,
            offset: 0,
            count: 3,
            stride_samples: 1,
        };
        let v = decode_samples("t", &bytes, layout, &limits).unwrap();
        assert_eq!(v, Voxels::I16(vec![-5, 7, 1000]));
        let big: Vec<u8> = [70000u32, 1].iter().flat_map(|v| v.to_be_bytes()).collect();
        let layout = SampleLayout {
            ty: SampleType::U32,
            endian: Endian::Big,
            count: 2,
            ..layout
        };
        assert_eq!(
            decode_samples("t", &big, layout, &limits).unwrap(),
            Voxels::F32(vec![70000.0, 1.0])
        );
    }

    #[test]
    fn strided_and_truncated() {
        let limits = Limits::default();
        let bytes = [1u8, 2, 3, 4, 5, 6];
        let layout = SampleLayout {
            ty: SampleType::U8,
            endian: Endian::Little,
            offset: 0,
            count: 3,
            stride_samples: 2,
        };
        assert_eq!(
            decode_samples("t", &bytes, layout, &limits).unwrap(),
            Voxels::U8(vec![1, 3, 5])
        );
        let layout = SampleLayout { count: 4, ..layout };
        assert!(matches!(
            decode_samples("t", &bytes, layout, &limits),
            Err(LoadError::Truncated { .. })
        ));
    }

    #[test]
    fn gzip_output_is_capped() {
        use std::io::Write;
        let mut enc = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
        enc.write_all(&vec![0u8; 100_000]).unwrap();
        let gz = enc.finish().unwrap();
        let (out, more) = gunzip_prefix("t", &gz, 1000).unwrap();
        assert_eq!(out.len(), 1000);
        assert!(more);
    }
}
