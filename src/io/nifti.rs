//! NIfTI-1, NIfTI-2 and Analyze 7.5 reader (.nii, .nii.gz, .hdr/.img pairs) and the NIfTI-1
//! writer (see `write`). Headers are parsed by hand from bytes so that this builds for wasm32.
//!
//! Geometry follows the NIfTI-1 standard (nifti1.h): sform when sform_code > 0 (preferred, as
//! the brief and nibabel do), else qform when qform_code > 0, else "method 1" (pixdim scaling
//! with no orientation, reported as a warning). NIfTI's world is RAS; it is turned into LPS.

mod write;

pub use write::{WriteIntent, write, write_volume};

use glam::{DMat3, DVec3};

use super::geometry::{checked_grid, ras_to_lps};
use super::raw::{self, Endian, FieldReader, SampleLayout, SampleType};
use super::{Companions, HeaderInput, InputFile, LoadError, base_name};
use crate::volume::Volume;

const NIFTI1_HEADER_BYTES: usize = 348;
const NIFTI2_HEADER_BYTES: usize = 540;

/// Whether the bytes begin with a NIfTI-1/Analyze (sizeof_hdr 348, either byte order) or a
/// NIfTI-2 (540 and the "n+2"/"ni2" magic) header.
pub(crate) fn looks_like_header(bytes: &[u8]) -> bool {
    let Some(first) = bytes.get(0..4) else {
        return false;
    };
    let le = i32::from_le_bytes([first[0], first[1], first[2], first[3]]);
    let be = i32::from_be_bytes([first[0], first[1], first[2], first[3]]);
    if (le == 348 || be == 348) && bytes.len() >= NIFTI1_HEADER_BYTES {
        return true;
    }
    if le == 540 || be == 540 {
        return bytes
            .get(4..8)
            .is_some_and(|m| m == b"n+2\0" || m == b"ni2\0");
    }
    false
}

/// Which kind of file the header belongs to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Kind {
    /// "n+1" / "n+2": header and data in one file.
    Single,
    /// "ni1" / "ni2": a .hdr whose data is in the .img beside it.
    Pair,
    /// No magic: an Analyze 7.5 .hdr (data in .img, no orientation).
    Analyze,
}

/// The kind a NIfTI-`version` magic names ("n+1", "ni2", ...), `None` for any other bytes.
fn kind_of_magic(magic: &[u8], version: u8) -> Option<Kind> {
    match magic {
        [b'n', b'+', v, 0] if *v == version => Some(Kind::Single),
        [b'n', b'i', v, 0] if *v == version => Some(Kind::Pair),
        _ => None,
    }
}

/// The fields of a NIfTI-1 or NIfTI-2 header that loading needs, widened to 64 bits.
#[derive(Clone, Debug)]
pub(crate) struct Header {
    version: u8,
    kind: Kind,
    endian: Endian,
    dim: [i64; 8],
    datatype: i16,
    pixdim: [f64; 8],
    vox_offset: f64,
    scl_slope: f64,
    scl_inter: f64,
    qform_code: i32,
    sform_code: i32,
    quatern: [f64; 3],
    qoffset: [f64; 3],
    srow: [[f64; 4]; 3],
    intent_code: i32,
}

fn parse_header(file: &str, bytes: &[u8]) -> Result<Header, LoadError> {
    let first = bytes
        .get(0..4)
        .ok_or_else(|| LoadError::truncated(file, "NIfTI header", 4, bytes.len() as u64))?;
    let le = i32::from_le_bytes([first[0], first[1], first[2], first[3]]);
    let be = i32::from_be_bytes([first[0], first[1], first[2], first[3]]);
    let (size, endian) = match (le, be) {
        (348, _) => (348, Endian::Little),
        (_, 348) => (348, Endian::Big),
        (540, _) => (540, Endian::Little),
        (_, 540) => (540, Endian::Big),
        _ => {
            return Err(LoadError::header(
                file,
                "sizeof_hdr",
                format!("is {le}; expected 348 (NIfTI-1) or 540 (NIfTI-2)"),
            ));
        }
    };
    if bytes.len() < size {
        return Err(LoadError::truncated(
            file,
            "NIfTI header",
            size as u64,
            bytes.len() as u64,
        ));
    }
    let r = FieldReader { bytes, endian };
    let h = if size == 348 {
        // No NIfTI-1 magic: an Analyze 7.5 header.
        let kind = kind_of_magic(&bytes[344..348], b'1').unwrap_or(Kind::Analyze);
        let dim = std::array::from_fn(|i| i64::from(r.i16(40 + 2 * i)));
        let pixdim = std::array::from_fn(|i| f64::from(r.f32(76 + 4 * i)));
        let srow = std::array::from_fn(|row| {
            std::array::from_fn(|c| f64::from(r.f32(280 + 16 * row + 4 * c)))
        });
        let is_nifti = kind != Kind::Analyze;
        Header {
            version: 1,
            kind,
            endian,
            dim,
            datatype: r.i16(70),
            pixdim,
            vox_offset: f64::from(r.f32(108)),
            // Analyze 7.5 keeps other things at these offsets (funused1 is a scale in SPM's
            // variant); only NIfTI's meaning is trusted.
            scl_slope: if is_nifti { f64::from(r.f32(112)) } else { 0.0 },
            scl_inter: if is_nifti { f64::from(r.f32(116)) } else { 0.0 },
            qform_code: if is_nifti { i32::from(r.i16(252)) } else { 0 },
            sform_code: if is_nifti { i32::from(r.i16(254)) } else { 0 },
            quatern: std::array::from_fn(|i| f64::from(r.f32(256 + 4 * i))),
            qoffset: std::array::from_fn(|i| f64::from(r.f32(268 + 4 * i))),
            srow,
            intent_code: if is_nifti { i32::from(r.i16(68)) } else { 0 },
        }
    } else {
        let Some(kind) = kind_of_magic(&bytes[4..8], b'2') else {
            return Err(LoadError::header(
                file,
                "magic",
                "sizeof_hdr is 540 but the magic is not n+2 or ni2",
            ));
        };
        Header {
            version: 2,
            kind,
            endian,
            dim: std::array::from_fn(|i| r.i64(16 + 8 * i)),
            datatype: r.i16(12),
            pixdim: std::array::from_fn(|i| r.f64(104 + 8 * i)),
            vox_offset: r.i64(168) as f64,
            scl_slope: r.f64(176),
            scl_inter: r.f64(184),
            qform_code: r.i32(344),
            sform_code: r.i32(348),
            quatern: std::array::from_fn(|i| r.f64(352 + 8 * i)),
            qoffset: std::array::from_fn(|i| r.f64(376 + 8 * i)),
            srow: std::array::from_fn(|row| std::array::from_fn(|c| r.f64(400 + 32 * row + 8 * c))),
            intent_code: r.i32(504),
        }
    };
    Ok(h)
}

fn sample_type(file: &str, datatype: i16) -> Result<SampleType, LoadError> {
    Ok(match datatype {
        2 => SampleType::U8,
        4 => SampleType::I16,
        8 => SampleType::I32,
        16 => SampleType::F32,
        64 => SampleType::F64,
        256 => SampleType::I8,
        512 => SampleType::U16,
        768 => SampleType::U32,
        1024 => SampleType::I64,
        1280 => SampleType::U64,
        32 | 1792 | 2048 => {
            return Err(LoadError::unsupported(
                file,
                "NIfTI datatype",
                format!("{datatype} (complex)"),
            ));
        }
        128 | 2304 => {
            return Err(LoadError::unsupported(
                file,
                "NIfTI datatype",
                format!("{datatype} (RGB colour)"),
            ));
        }
        1 => {
            return Err(LoadError::unsupported(
                file,
                "NIfTI datatype",
                "1 (binary, 1 bit per voxel)",
            ));
        }
        other => {
            return Err(LoadError::header(
                file,
                "datatype",
                format!("{other} is not a NIfTI datatype"),
            ));
        }
    })
}

/// The 3D grid size and how many 3D volumes the file holds, from dim[].
fn grid(
    file: &str,
    h: &Header,
    warnings: &mut Vec<String>,
) -> Result<([usize; 3], u64), LoadError> {
    let ndim = h.dim[0];
    if !(1..=7).contains(&ndim) {
        return Err(LoadError::header(
            file,
            "dim[0]",
            format!("is {ndim}; expected 1 to 7"),
        ));
    }
    let ndim = ndim as usize;
    let mut dims = [1usize; 3];
    let mut extra: u64 = 1;
    for d in 1..=ndim {
        let n = h.dim[d];
        if n < 1 {
            return Err(LoadError::header(
                file,
                &format!("dim[{d}]"),
                format!("is {n}; expected at least 1"),
            ));
        }
        if d <= 3 {
            dims[d - 1] = usize::try_from(n)
                .map_err(|_| LoadError::header(file, &format!("dim[{d}]"), "too large"))?;
        } else {
            extra = extra.saturating_mul(n as u64);
        }
    }
    if ndim >= 4 && h.dim[4] > 1 {
        warnings.push(format!(
            "4D file with {} volumes: the first volume is shown",
            h.dim[4]
        ));
    }
    if ndim >= 5 && h.dim[5] > 1 {
        warnings.push(format!(
            "{} components per voxel (intent code {}): the first component is shown",
            h.dim[5], h.intent_code
        ));
    }
    if ndim >= 6 && h.dim[6..=ndim].iter().any(|&n| n > 1) {
        warnings.push(
            "dimensions 6 and 7 are larger than 1: only the first 3D volume is shown".to_owned(),
        );
    }
    Ok((dims, extra))
}

/// The 3x3 columns (axis steps) and origin in RAS, and a note on where they came from.
fn ras_geometry(h: &Header, warnings: &mut Vec<String>) -> ([DVec3; 3], DVec3) {
    if h.sform_code > 0 {
        let axes = [0, 1, 2].map(|c| DVec3::new(h.srow[0][c], h.srow[1][c], h.srow[2][c]));
        let origin = DVec3::new(h.srow[0][3], h.srow[1][3], h.srow[2][3]);
        let m = DMat3::from_cols(axes[0], axes[1], axes[2]);
        if m.determinant().is_finite() && m.determinant().abs() > 1e-12 && origin.is_finite() {
            return (axes, origin);
        }
        warnings.push("the sform is degenerate; the qform or pixdim is used instead".to_owned());
    }
    if h.qform_code > 0 {
        return qform_geometry(h, warnings);
    }
    let pix = [1, 2, 3].map(|a| pixdim_mm(h, a, false, warnings));
    warnings.push(match h.kind {
        Kind::Analyze => "Analyze 7.5 header: no orientation is stored; axes are assumed to be RAS with the origin at voxel 0".to_owned(),
        _ => "no qform or sform: no orientation is stored; axes are assumed to be RAS with the origin at voxel 0 (NIfTI method 1)".to_owned(),
    });
    (
        [DVec3::X * pix[0], DVec3::Y * pix[1], DVec3::Z * pix[2]],
        DVec3::ZERO,
    )
}

/// pixdim[a] as a voxel size in mm, with a warning that names the field when it is not one:
/// 0, NaN or infinity becomes 1 mm; a negative value becomes its magnitude for method 1 and
/// 1 mm for the qform (as nifti1_io's quaternion conversion does).
fn pixdim_mm(h: &Header, a: usize, qform: bool, warnings: &mut Vec<String>) -> f64 {
    let p = h.pixdim[a];
    if p.is_finite() && p > 0.0 {
        return p;
    }
    if a as i64 > h.dim[0] {
        return 1.0; // an axis the image does not have (a 2D image's pixdim[3])
    }
    let used = if p.is_finite() && p < 0.0 && !qform {
        -p
    } else {
        1.0
    };
    warnings.push(format!(
        "header field pixdim[{a}] is {p}, not a voxel size; {used} mm is used"
    ));
    used
}

/// nifti1.h's quaternion to rotation, with qfac = pixdim[0] flipping the k axis.
fn qform_geometry(h: &Header, warnings: &mut Vec<String>) -> ([DVec3; 3], DVec3) {
    let [mut b, mut c, mut d] = h.quatern;
    let mut a2 = 1.0 - (b * b + c * c + d * d);
    if !(a2.is_finite()) || a2 < 1e-7 {
        // Not a unit quaternion: renormalise (b, c, d) and take a = 0, as nifti1_io does.
        let n = (b * b + c * c + d * d).sqrt();
        if n.is_finite() && n > 0.0 {
            b /= n;
            c /= n;
            d /= n;
        }
        a2 = 0.0;
    }
    let a = a2.sqrt();
    let r = DMat3::from_cols(
        DVec3::new(
            a * a + b * b - c * c - d * d,
            2.0 * (b * c + a * d),
            2.0 * (b * d - a * c),
        ),
        DVec3::new(
            2.0 * (b * c - a * d),
            a * a + c * c - b * b - d * d,
            2.0 * (c * d + a * b),
        ),
        DVec3::new(
            2.0 * (b * d + a * c),
            2.0 * (c * d - a * b),
            a * a + d * d - c * c - b * b,
        ),
    );
    let qfac = if h.pixdim[0] < 0.0 { -1.0 } else { 1.0 };
    let axes = [
        r.x_axis * pixdim_mm(h, 1, true, warnings),
        r.y_axis * pixdim_mm(h, 2, true, warnings),
        r.z_axis * pixdim_mm(h, 3, true, warnings) * qfac,
    ];
    (axes, DVec3::from(h.qoffset))
}

/// Reads a .nii, .nii.gz or the .hdr of a pair (whose .img is looked up among `companions`).
pub(crate) fn read(input: HeaderInput<'_>) -> Result<Volume, LoadError> {
    let name = input.file.name.as_str();
    let gz = raw::is_gzip(&input.file.bytes);
    // The header first: from a gzip stream only its first bytes are inflated at this point.
    let header_bytes;
    let head: &[u8] = if gz {
        header_bytes =
            raw::gunzip_prefix_data(name, input.file.data(), NIFTI2_HEADER_BYTES as u64)?.0;
        &header_bytes
    } else {
        &input.file.bytes
    };
    let h = parse_header(name, head)?;
    let mut warnings = Vec::new();
    let ty = sample_type(name, h.datatype)?;
    let (dims, volumes) = grid(name, &h, &mut warnings)?;
    let count = input.voxel_count(dims, ty)?;
    let data_bytes = count.saturating_mul(ty.size() as u64);
    let header_size = if h.version == 1 {
        NIFTI1_HEADER_BYTES
    } else {
        NIFTI2_HEADER_BYTES
    };

    if !h.vox_offset.is_finite() || h.vox_offset < 0.0 || h.vox_offset > 1e15 {
        return Err(LoadError::header(
            name,
            "vox_offset",
            format!("is {}", h.vox_offset),
        ));
    }
    let mut vox_offset = h.vox_offset as u64;
    if h.kind == Kind::Single && vox_offset < header_size as u64 {
        // Some writers leave vox_offset at 0 in a single file; the data then follow the
        // header and its 4-byte extension flag.
        vox_offset = header_size as u64 + 4;
        warnings.push(format!(
            "vox_offset was {}; {} assumed",
            h.vox_offset, vox_offset
        ));
    }

    // Where the voxels are: in this file after the header, or in the .img beside the .hdr.
    let data_file: &InputFile = match h.kind {
        Kind::Single => input.file,
        Kind::Pair | Kind::Analyze => pair_data_file(name, input.companions)?,
    };
    let data_name = data_file.name.clone();
    let layout = SampleLayout {
        ty,
        endian: h.endian,
        offset: 0,
        count: count as usize,
        stride_samples: 1,
    };
    let (voxels, present_bytes) = if raw::is_gzip(&data_file.bytes) {
        // Straight from the stream into the voxels; the whole stream (every volume of a 4D
        // file) is read so that its CRC-32 is checked.
        let declared = vox_offset.saturating_add(data_bytes.saturating_mul(volumes));
        raw::inflate_voxels(
            &data_name,
            raw::Compression::Gzip,
            data_file.data(),
            vox_offset,
            layout,
            declared,
            input.limits,
        )?
    } else {
        // From memory, or straight from the file into the voxels.
        let layout = SampleLayout {
            offset: usize::try_from(vox_offset).unwrap_or(usize::MAX),
            ..layout
        };
        (
            raw::decode_present(
                &data_name,
                "NIfTI voxel data",
                data_file.data(),
                vox_offset.saturating_add(data_bytes),
                layout,
                input.limits,
            )?,
            data_file.len(),
        )
    };
    if volumes > 1 && data_bytes > 0 {
        // Only the first volume is shown, but a file that lacks the others is worth a word.
        let complete = present_bytes.saturating_sub(vox_offset) / data_bytes;
        if complete < volumes {
            warnings.push(format!(
                "dim[4..7] declare {volumes} volumes but {data_name} holds only {complete} complete one(s)"
            ));
        }
    }

    let (axes_ras, origin_ras) = ras_geometry(&h, &mut warnings);
    let grid = checked_grid(
        name,
        ("sform/qform", axes_ras.map(ras_to_lps)),
        ("sform/qform offset", ras_to_lps(origin_ras)),
        &mut warnings,
    )?;

    // scl_slope = 0 (or NaN) means "no scaling" (nifti1.h).
    let (value_slope, value_intercept) = if h.scl_slope.is_finite() && h.scl_slope != 0.0 {
        let inter = if h.scl_inter.is_finite() {
            h.scl_inter
        } else {
            0.0
        };
        (h.scl_slope as f32, inter as f32)
    } else {
        (1.0, 0.0)
    };
    let source = if h.kind == Kind::Single {
        name.to_owned()
    } else {
        format!("{name} + {data_name}")
    };
    Ok(Volume {
        value_slope,
        value_intercept,
        ..grid.volume(dims, voxels, source, warnings)
    })
}

/// The .img (or .img.gz) beside a .hdr.
fn pair_data_file<'a>(
    hdr_name: &str,
    companions: Companions<'a>,
) -> Result<&'a InputFile, LoadError> {
    let base = base_name(hdr_name);
    let stem = base
        .strip_suffix(".hdr")
        .or_else(|| base.strip_suffix(".HDR"))
        .or_else(|| base.strip_suffix(".hdr.gz"))
        .unwrap_or(base);
    let candidates = [
        format!("{stem}.img"),
        format!("{stem}.img.gz"),
        format!("{stem}.IMG"),
    ];
    candidates
        .iter()
        .find_map(|c| companions.find(c))
        .ok_or_else(|| LoadError::MissingDataFile {
            file: hdr_name.to_owned(),
            data_file: format!("{stem}.img"),
        })
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // a failed unwrap is a failed test
mod tests {
    use super::*;
    use crate::io::{Limits, read_header};

    /// A minimal single-file NIfTI-1 header + data, for unit tests.
    pub(crate) fn tiny_nifti(datatype: i16, dims: [i16; 3], data: &[u8]) -> Vec<u8> {
        let mut b = vec![0u8; 352];
        b[0..4].copy_from_slice(&348i32.to_le_bytes());
        b[40..42].copy_from_slice(&3i16.to_le_bytes());
        for (i, d) in dims.iter().enumerate() {
            b[42 + 2 * i..44 + 2 * i].copy_from_slice(&d.to_le_bytes());
        }
        b[70..72].copy_from_slice(&datatype.to_le_bytes());
        for i in 0..4 {
            b[76 + 4 * i..80 + 4 * i].copy_from_slice(&1f32.to_le_bytes());
        }
        b[108..112].copy_from_slice(&352f32.to_le_bytes());
        b[344..348].copy_from_slice(b"n+1\0");
        b.extend_from_slice(data);
        b
    }

    #[test]
    fn reads_tiny_and_refuses_huge() {
        let bytes = tiny_nifti(2, [2, 2, 1], &[1, 2, 3, 4]);
        assert!(looks_like_header(&bytes));
        let f = InputFile::new("t.nii", bytes.clone());
        let v = read_header(read, &f, &[]).unwrap();
        assert_eq!(v.dims, [2, 2, 1]);
        assert_eq!(v.value_at(1, 1, 0), 4.0);
        // Method 1 (no qform/sform): RAS axes, which are -x, -y in LPS.
        assert_eq!(v.direction.x_axis, DVec3::new(-1.0, 0.0, 0.0));

        let huge = tiny_nifti(4, [i16::MAX, i16::MAX, i16::MAX], &[]);
        let limits = Limits {
            max_voxel_bytes: 1 << 20,
            ..Limits::default()
        };
        let file = InputFile::new("h.nii", huge);
        let r = read(HeaderInput::new(&file, Companions::new(&[]), &limits));
        assert!(matches!(r, Err(LoadError::TooLarge { .. })), "{r:?}");
        let short = tiny_nifti(4, [4, 4, 4], &[0; 10]);
        let file = InputFile::new("s.nii", short);
        let r = read_header(read, &file, &[]);
        assert!(matches!(r, Err(LoadError::Truncated { .. })), "{r:?}");
    }
}
