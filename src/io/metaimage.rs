//! MetaImage reader (ITK's .mha with the data attached, .mhd with the data in a .raw/.zraw given
//! beside it): ElementSpacing, Offset, TransformMatrix, CompressedData (zlib), byte order.
//! MetaImage's world is ITK's, which is LPS, so no axis is flipped.

use glam::DVec3;

use super::geometry::checked_grid;
use super::input::Data;
use super::raw::{self, Endian, SampleLayout, SampleType};
use super::{HeaderInput, LoadError};
use crate::volume::{Modality, Volume};

/// Keys that may open a MetaImage header (ITK writes ObjectType first; others are seen too).
const FIRST_KEYS: &[&str] = &[
    "ObjectType",
    "NDims",
    "ObjectSubType",
    "Comment",
    "TransformType",
    "DimSize",
    "ElementType",
];
const MAX_HEADER_BYTES: usize = 1 << 20;

/// Whether the bytes begin with a "Key = value" line whose key is a MetaImage key.
pub(crate) fn looks_like_header(bytes: &[u8]) -> bool {
    let head = &bytes[..bytes.len().min(256)];
    let line_end = head.iter().position(|&b| b == b'\n').unwrap_or(head.len());
    let Ok(line) = std::str::from_utf8(&head[..line_end]) else {
        return false;
    };
    line.split_once('=')
        .is_some_and(|(k, _)| FIRST_KEYS.iter().any(|f| k.trim().eq_ignore_ascii_case(f)))
}

/// Header lines up to and including ElementDataFile (which must be last), and the offset of the
/// byte after that line (where LOCAL data start).
fn parse_header(file: &str, bytes: &[u8]) -> Result<(Vec<(String, String)>, usize), LoadError> {
    let mut fields = Vec::new();
    let mut pos = 0;
    let limit = bytes.len().min(MAX_HEADER_BYTES);
    while pos < limit {
        let line_end = bytes[pos..]
            .iter()
            .position(|&b| b == b'\n')
            .map_or(bytes.len(), |e| pos + e);
        let line = String::from_utf8_lossy(&bytes[pos..line_end]);
        pos = (line_end + 1).min(bytes.len());
        let line = line.trim();
        if line.is_empty() {
            continue;
        }
        let Some((k, v)) = line.split_once('=') else {
            return Err(LoadError::header_line(file, line, "Key = value"));
        };
        let key = k.trim().to_owned();
        let last = key.eq_ignore_ascii_case("ElementDataFile");
        fields.push((key, v.trim().to_owned()));
        if last {
            return Ok((fields, pos));
        }
    }
    Err(LoadError::header(
        file,
        "ElementDataFile",
        "missing (it must end the header)",
    ))
}

fn get<'a>(fields: &'a [(String, String)], key: &str) -> Option<&'a str> {
    fields
        .iter()
        .find(|(k, _)| k.eq_ignore_ascii_case(key))
        .map(|(_, v)| v.as_str())
}

fn numbers(file: &str, key: &str, value: &str) -> Result<Vec<f64>, LoadError> {
    value
        .split_whitespace()
        .map(|x| {
            x.parse::<f64>()
                .map_err(|_| LoadError::header(file, key, format!("\"{x}\" is not a number")))
        })
        .collect()
}

fn sample_type(file: &str, name: &str) -> Result<SampleType, LoadError> {
    Ok(match name {
        "MET_UCHAR" => SampleType::U8,
        "MET_CHAR" => SampleType::I8,
        "MET_USHORT" => SampleType::U16,
        "MET_SHORT" => SampleType::I16,
        "MET_UINT" | "MET_ULONG" => SampleType::U32,
        "MET_INT" | "MET_LONG" => SampleType::I32,
        "MET_ULONG_LONG" => SampleType::U64,
        "MET_LONG_LONG" => SampleType::I64,
        "MET_FLOAT" => SampleType::F32,
        "MET_DOUBLE" => SampleType::F64,
        other => {
            return Err(LoadError::unsupported(
                file,
                "MetaImage ElementType",
                other.to_owned(),
            ));
        }
    })
}

fn is_true(v: Option<&str>) -> bool {
    v.is_some_and(|v| v.eq_ignore_ascii_case("true") || v == "1")
}

/// Reads a .mha, or a .mhd whose data file is looked up among `companions`.
pub(crate) fn read(input: HeaderInput<'_>) -> Result<Volume, LoadError> {
    let name = input.file.name.as_str();
    // A file read on demand is parsed from its first 64 KiB, or up to the header cap when the
    // header is longer.
    let (fields, data_start) = {
        let on_demand = input.file.is_on_demand();
        let mut parsed = parse_header(
            name,
            &input
                .file
                .prefix(if on_demand { 64 << 10 } else { usize::MAX })?,
        );
        // The prefix's end may cut a line: its parse counts only if the header ended before it.
        let whole = !on_demand || input.file.len() <= 64 << 10;
        if !whole && !matches!(parsed, Ok((_, start)) if start < 64 << 10) {
            parsed = parse_header(name, &input.file.prefix(MAX_HEADER_BYTES + 1)?);
        }
        parsed?
    };
    let mut warnings = Vec::new();
    let need = |key: &str| {
        get(&fields, key)
            .ok_or_else(|| LoadError::header(name, key, "missing (a required MetaImage field)"))
    };

    let ndims: usize = LoadError::parse_field(name, "NDims", need("NDims")?, "not an integer")?;
    if !(1..=4).contains(&ndims) {
        return Err(LoadError::unsupported(
            name,
            "MetaImage NDims",
            ndims.to_string(),
        ));
    }
    let dim_size = numbers(name, "DimSize", need("DimSize")?)?;
    if dim_size.len() != ndims
        || dim_size
            .iter()
            .any(|&d| d < 1.0 || d.fract() != 0.0 || d > 1e12)
    {
        return Err(LoadError::header(
            name,
            "DimSize",
            format!("{dim_size:?} does not give {ndims} positive integers"),
        ));
    }
    let sizes: Vec<u64> = dim_size.iter().map(|&d| d as u64).collect();
    let ty = sample_type(name, need("ElementType")?)?;
    let channels: u64 = match get(&fields, "ElementNumberOfChannels") {
        Some(c) => LoadError::parse_field(name, "ElementNumberOfChannels", c, "not an integer")?,
        None => 1,
    };
    if channels == 0 {
        return Err(LoadError::header(name, "ElementNumberOfChannels", "is 0"));
    }
    if channels > 1 {
        warnings.push(format!(
            "{channels} channels per voxel: the first channel is shown"
        ));
    }
    if ndims == 4 && sizes[3] > 1 {
        warnings.push(format!(
            "4D image with {} volumes: the first volume is shown",
            sizes[3]
        ));
    }
    let mut dims = [1usize; 3];
    for a in 0..ndims.min(3) {
        dims[a] = usize::try_from(sizes[a])
            .map_err(|_| LoadError::header(name, "DimSize", "too large"))?;
    }
    let count = input.voxel_count(dims, ty)?;
    let total_samples = raw::checked_product(&sizes)
        .and_then(|n| n.checked_mul(channels))
        .unwrap_or(u64::MAX);
    let total_bytes = total_samples.saturating_mul(ty.size() as u64);

    // Geometry: spacing per axis, offset, and TransformMatrix whose consecutive triples are the
    // directions of the i, j, k axes (ITK's MetaImageIO reads it so).
    let spacing = match get(&fields, "ElementSpacing").or_else(|| get(&fields, "ElementSize")) {
        Some(s) => numbers(name, "ElementSpacing", s)?,
        None => {
            warnings.push("no ElementSpacing: 1 mm assumed".to_owned());
            vec![1.0; ndims]
        }
    };
    let origin = match get(&fields, "Offset")
        .or_else(|| get(&fields, "Origin"))
        .or_else(|| get(&fields, "Position"))
    {
        Some(s) => numbers(name, "Offset", s)?,
        None => vec![0.0; ndims],
    };
    let matrix = match get(&fields, "TransformMatrix")
        .or_else(|| get(&fields, "Rotation"))
        .or_else(|| get(&fields, "Orientation"))
    {
        Some(s) => Some(numbers(name, "TransformMatrix", s)?),
        None => None,
    };
    let mut steps = [DVec3::X, DVec3::Y, DVec3::Z];
    let n3 = ndims.min(3);
    for (a, step) in steps.iter_mut().enumerate().take(n3) {
        let mut dir = DVec3::ZERO;
        dir[a] = 1.0;
        if let Some(m) = &matrix
            && m.len() == ndims * ndims
        {
            dir = DVec3::ZERO;
            for c in 0..n3 {
                dir[c] = m[a * ndims + c];
            }
        }
        let s = match spacing.get(a).copied() {
            Some(s) => {
                if s < 0.0 {
                    // ITK keeps a negative spacing (with a warning): the axis points the other
                    // way. Said here too, as it flips the image.
                    warnings.push(format!(
                        "header field ElementSpacing: axis {a} is {s} (negative): the axis is taken to point the other way, as ITK reads it"
                    ));
                }
                s
            }
            None => {
                warnings.push(format!(
                    "header field ElementSpacing: no value for axis {a}; 1 mm is assumed"
                ));
                1.0
            }
        };
        *step = dir * s;
    }
    if matches!(&matrix, Some(m) if m.len() != ndims * ndims) {
        warnings.push("TransformMatrix does not have NDims x NDims values: ignored".to_owned());
    }
    let origin = DVec3::new(
        origin.first().copied().unwrap_or(0.0),
        origin.get(1).copied().unwrap_or(0.0),
        origin.get(2).copied().unwrap_or(0.0),
    );

    let endian = if is_true(
        get(&fields, "BinaryDataByteOrderMSB").or_else(|| get(&fields, "ElementByteOrderMSB")),
    ) {
        Endian::Big
    } else {
        Endian::Little
    };
    if get(&fields, "BinaryData").is_some_and(|v| v.eq_ignore_ascii_case("false")) {
        return Err(LoadError::unsupported(
            name,
            "MetaImage data",
            "BinaryData = False (ASCII data)",
        ));
    }
    let data_file = need("ElementDataFile")?;
    let (data_name, data): (String, Data<'_>) = if data_file.eq_ignore_ascii_case("LOCAL") {
        let data = input
            .file
            .data()
            .after(data_start as u64)
            .unwrap_or(Data::Memory(&[]));
        (name.to_owned(), data)
    } else {
        let f = input.companions.data_file(
            name,
            "ElementDataFile",
            data_file,
            ("MetaImage ElementDataFile", "one file per slice"),
            &mut warnings,
        )?;
        (f.name.clone(), f.data())
    };
    let header_size: i64 = get(&fields, "HeaderSize")
        .and_then(|s| s.parse().ok())
        .unwrap_or(0);
    let compressed = is_true(get(&fields, "CompressedData"));
    let layout = SampleLayout {
        ty,
        endian,
        offset: 0,
        count: count as usize,
        stride_samples: usize::try_from(channels).unwrap_or(usize::MAX),
    };
    let voxels = if compressed {
        // Straight from the stream into the voxels (the Adler-32 is checked at its end).
        raw::inflate_voxels(
            &data_name,
            raw::Compression::Zlib,
            data,
            0,
            layout,
            total_bytes,
            input.limits,
        )?
        .0
    } else {
        let skip = if header_size == -1 {
            // -1: the data are the last bytes of the file.
            data.len().saturating_sub(total_bytes)
        } else {
            u64::try_from(header_size).unwrap_or(0)
        };
        let data = data.after(skip.min(data.len())).unwrap_or(data);
        raw::decode_present(
            &data_name,
            "MetaImage data",
            data,
            total_bytes,
            layout,
            input.limits,
        )?
    };
    let grid = checked_grid(
        name,
        ("ElementSpacing/TransformMatrix", steps),
        ("Offset", origin),
        &mut warnings,
    )?;
    let modality = match get(&fields, "Modality") {
        Some("MET_MOD_CT") => Modality::Ct,
        Some("MET_MOD_MR") => Modality::Mr,
        _ => Modality::Unknown,
    };
    let source = raw::source_name(name, &data_name);
    Ok(Volume {
        modality,
        ..grid.volume(dims, voxels, source, warnings)
    })
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // a failed unwrap is a failed test
mod tests {
    use super::*;
    use crate::io::{InputFile, read_header};

    #[test]
    fn detached_big_endian_with_matrix() {
        let hdr = InputFile::new(
            "a.mhd",
            b"ObjectType = Image\nNDims = 3\nDimSize = 2 1 1\nElementType = MET_SHORT\nElementSpacing = 0.5 2 3\nOffset = 1 2 3\nTransformMatrix = 0 1 0 -1 0 0 0 0 1\nBinaryDataByteOrderMSB = True\nElementDataFile = a.raw\n".to_vec(),
        );
        assert!(looks_like_header(&hdr.bytes));
        let raw_file = [InputFile::new("a.raw", vec![0xff, 0xfe, 0x00, 0x05])];
        let v = read_header(read, &hdr, &raw_file).unwrap();
        assert_eq!(v.to_f32(), vec![-2.0, 5.0]);
        assert_eq!(v.direction.x_axis, DVec3::Y);
        assert_eq!(v.direction.y_axis, -DVec3::X);
        assert_eq!(v.spacing_mm, [0.5, 2.0, 3.0]);
        assert_eq!(v.origin_mm, [1.0, 2.0, 3.0]);
        let r = read_header(read, &hdr, &[]);
        assert!(matches!(r, Err(LoadError::MissingDataFile { .. })));
    }
}
