//! Shared low-level pieces of the loaders: capped decompression, fallible allocation, and the
//! conversion of raw sample bytes (any type, either endianness) into compact `Voxels`.

use std::io::Read;

use super::{Limits, LoadError};
use crate::volume::Voxels;

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

/// A vector of `len` default values, or an error instead of an abort when memory is short
/// (on wasm32 an allocation failure would otherwise end the page).
pub(crate) fn try_vec<T: Clone + Default>(
    file: &str,
    what: &str,
    len: usize,
) -> Result<Vec<T>, LoadError> {
    let mut v = Vec::new();
    v.try_reserve_exact(len)
        .map_err(|_| LoadError::OutOfMemory {
            file: file.to_owned(),
            what: what.to_owned(),
            bytes: (len as u64).saturating_mul(std::mem::size_of::<T>() as u64),
        })?;
    v.resize(len, T::default());
    Ok(v)
}

/// Whether the bytes start like a gzip stream.
pub(crate) fn is_gzip(bytes: &[u8]) -> bool {
    bytes.len() >= 2 && bytes[0] == 0x1f && bytes[1] == 0x8b
}

/// Decompresses gzip (possibly several members), stopping at `max_out` bytes of output.
/// Returns the bytes and whether the stream had more than `max_out` bytes.
pub(crate) fn gunzip_prefix(
    file: &str,
    bytes: &[u8],
    max_out: u64,
) -> Result<(Vec<u8>, bool), LoadError> {
    let decoder = flate2::read::MultiGzDecoder::new(bytes);
    read_capped(file, decoder, max_out, "gzip")
}

/// Decompresses a zlib stream (MetaImage CompressedData), stopping at `max_out` bytes.
pub(crate) fn inflate_zlib_prefix(
    file: &str,
    bytes: &[u8],
    max_out: u64,
) -> Result<(Vec<u8>, bool), LoadError> {
    let decoder = flate2::read::ZlibDecoder::new(bytes);
    read_capped(file, decoder, max_out, "zlib")
}

fn read_capped(
    file: &str,
    reader: impl Read,
    max_out: u64,
    kind: &str,
) -> Result<(Vec<u8>, bool), LoadError> {
    // One byte more than the cap tells whether the stream goes on past it.
    let mut limited = reader.take(max_out.saturating_add(1));
    let mut out = Vec::new();
    // Reserve modestly; read_to_end grows geometrically and the cap bounds the growth.
    let _ = out.try_reserve(max_out.min(1 << 26) as usize);
    limited
        .read_to_end(&mut out)
        .map_err(|e| LoadError::Decompress {
            file: file.to_owned(),
            message: format!("{kind}: {e}"),
        })?;
    let more = out.len() as u64 > max_out;
    if more {
        out.truncate(max_out as usize);
    }
    Ok((out, more))
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
}

/// Checks that `needed` bytes of `what` are present, then decodes them (NRRD and MetaImage data).
pub(crate) fn decode_present(
    file: &str,
    what: &str,
    bytes: &[u8],
    needed: u64,
    layout: SampleLayout,
    limits: &Limits,
) -> Result<Voxels, LoadError> {
    if (bytes.len() as u64) < needed {
        return Err(LoadError::truncated(file, what, needed, bytes.len() as u64));
    }
    decode_samples(file, bytes, layout, limits)
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
    let span = layout
        .span_bytes()
        .and_then(|s| s.checked_add(layout.offset as u64))
        .unwrap_or(u64::MAX);
    if span > bytes.len() as u64 {
        return Err(LoadError::truncated(
            file,
            "voxel data",
            span,
            bytes.len() as u64,
        ));
    }
    check_voxel_budget(
        file,
        layout.count as u64,
        layout.ty.output_size() as u64,
        limits,
    )?;
    let n = layout.count;
    let size = layout.ty.size();
    let step = layout.stride_samples * size;
    let at = |i: usize| layout.offset + i * step;
    let get = |i: usize| sample_f64(bytes, layout.ty, layout.endian, at(i)).unwrap_or(0.0);
    Ok(match layout.ty {
        SampleType::U8 => {
            let mut v = try_vec::<u8>(file, "voxels", n)?;
            for (i, o) in v.iter_mut().enumerate() {
                *o = bytes[at(i)];
            }
            Voxels::U8(v)
        }
        SampleType::I8 => {
            let mut v = try_vec::<i16>(file, "voxels", n)?;
            for (i, o) in v.iter_mut().enumerate() {
                *o = i16::from(bytes[at(i)] as i8);
            }
            Voxels::I16(v)
        }
        SampleType::U16 | SampleType::I16 => {
            let read = |i: usize| {
                let p = at(i);
                let b = [bytes[p], bytes[p + 1]];
                match layout.endian {
                    Endian::Little => u16::from_le_bytes(b),
                    Endian::Big => u16::from_be_bytes(b),
                }
            };
            if layout.ty == SampleType::U16 {
                let mut v = try_vec::<u16>(file, "voxels", n)?;
                for (i, o) in v.iter_mut().enumerate() {
                    *o = read(i);
                }
                Voxels::U16(v)
            } else {
                let mut v = try_vec::<i16>(file, "voxels", n)?;
                for (i, o) in v.iter_mut().enumerate() {
                    *o = read(i) as i16;
                }
                Voxels::I16(v)
            }
        }
        SampleType::F32 | SampleType::F64 => {
            let mut v = try_vec::<f32>(file, "voxels", n)?;
            for (i, o) in v.iter_mut().enumerate() {
                *o = get(i) as f32;
            }
            Voxels::F32(v)
        }
        SampleType::U32 | SampleType::I32 | SampleType::U64 | SampleType::I64 => {
            // One pass for the range decides the compact type; a second converts.
            let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
            for i in 0..n {
                let x = get(i);
                lo = lo.min(x);
                hi = hi.max(x);
            }
            if n == 0 || (lo >= f64::from(i16::MIN) && hi <= f64::from(i16::MAX)) {
                let mut v = try_vec::<i16>(file, "voxels", n)?;
                for (i, o) in v.iter_mut().enumerate() {
                    *o = get(i) as i16;
                }
                Voxels::I16(v)
            } else if lo >= 0.0 && hi <= f64::from(u16::MAX) {
                let mut v = try_vec::<u16>(file, "voxels", n)?;
                for (i, o) in v.iter_mut().enumerate() {
                    *o = get(i) as u16;
                }
                Voxels::U16(v)
            } else {
                let mut v = try_vec::<f32>(file, "voxels", n)?;
                for (i, o) in v.iter_mut().enumerate() {
                    *o = get(i) as f32;
                }
                Voxels::F32(v)
            }
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
