//! The NIfTI-1 writer: float32 scalar or vector volumes with the geometry of an input volume
//! (LPS turned back into RAS for sform and qform), gzip-compressed when the name ends in ".gz".

use std::io::Write;

use glam::{DMat3, DVec3};

use crate::io::LoadError;
use crate::volume::Volume;

/// What the written values mean (NIfTI intent codes).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum WriteIntent {
    /// Plain values (NIFTI_INTENT_NONE).
    None,
    /// A vector per voxel (NIFTI_INTENT_VECTOR, 1007).
    Vector,
    /// An RGB triple per voxel stored as floats (NIFTI_INTENT_RGB_VECTOR, 2003).
    RgbVector,
}

impl WriteIntent {
    fn code(self) -> i16 {
        match self {
            Self::None => 0,
            Self::Vector => 1007,
            Self::RgbVector => 2003,
        }
    }
}

/// Writes a NIfTI-1 file of float32 values on the grid of `geometry` (its dims, spacing, origin
/// and direction; its voxels are not written). `channels` holds one slice of `voxel_count`
/// values per component: one channel gives a 3D scalar file, several give dim[5] = n components
/// (the NIfTI layout for vectors). The result is gzip-compressed when `name` ends in ".gz".
pub fn write(
    name: &str,
    geometry: &Volume,
    channels: &[&[f32]],
    intent: WriteIntent,
) -> Result<Vec<u8>, LoadError> {
    let err = |message: String| LoadError::Write {
        file: name.to_owned(),
        message,
    };
    let n = geometry.voxel_count();
    if channels.is_empty() {
        return Err(err("no channels to write".to_owned()));
    }
    if let Some((c, ch)) = channels.iter().enumerate().find(|(_, ch)| ch.len() != n) {
        return Err(err(format!(
            "channel {c} has {} values; the grid has {n}",
            ch.len()
        )));
    }
    if geometry
        .dims
        .iter()
        .any(|&d| d == 0 || d > i16::MAX as usize)
        || channels.len() > i16::MAX as usize
    {
        return Err(err(format!(
            "dimensions {:?} do not fit NIfTI-1's 16-bit dim[]",
            geometry.dims
        )));
    }
    let mut out = header(geometry, channels.len(), intent);
    out.reserve(n * 4 * channels.len());
    for ch in channels {
        for v in ch.iter() {
            out.extend_from_slice(&v.to_le_bytes());
        }
    }
    if name.ends_with(".gz") {
        let mut enc = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::default());
        enc.write_all(&out).map_err(|e| err(e.to_string()))?;
        return enc.finish().map_err(|e| err(e.to_string()));
    }
    Ok(out)
}

/// Writes a volume's physical values (raw * slope + intercept) as a float32 NIfTI-1 file, NaN
/// and infinities as stored (not replaced as the features see them).
pub fn write_volume(name: &str, volume: &Volume) -> Result<Vec<u8>, LoadError> {
    let values: Vec<f32> = (0..volume.voxel_count()).map(|i| volume.value(i)).collect();
    write(name, volume, &[&values], WriteIntent::None)
}

fn header(geometry: &Volume, components: usize, intent: WriteIntent) -> Vec<u8> {
    let mut b = vec![0u8; 352];
    let mut put =
        |offset: usize, bytes: &[u8]| b[offset..offset + bytes.len()].copy_from_slice(bytes);
    put(0, &348i32.to_le_bytes());
    let mut dim = [1i16; 8];
    dim[0] = if components > 1 { 5 } else { 3 };
    for a in 0..3 {
        dim[a + 1] = geometry.dims[a] as i16;
    }
    dim[5] = components as i16;
    for (i, d) in dim.iter().enumerate() {
        put(40 + 2 * i, &d.to_le_bytes());
    }
    put(68, &intent.code().to_le_bytes());
    put(70, &16i16.to_le_bytes()); // NIFTI_TYPE_FLOAT32
    put(72, &32i16.to_le_bytes()); // bitpix

    // LPS -> RAS: negate the x and y rows of world_from_voxel.
    let flip = DMat3::from_diagonal(DVec3::new(-1.0, -1.0, 1.0));
    let m = flip * geometry.direction * DMat3::from_diagonal(DVec3::from(geometry.spacing_mm));
    let origin = flip * DVec3::from(geometry.origin_mm);

    // qform: only for a (nearly) orthonormal direction, squared up by Gram-Schmidt (a DICOM
    // stack's k axis from positions is off by ~1e-5); a sheared grid has no quaternion and gets
    // qform_code 0. The sform always carries the exact geometry.
    let rot = flip * geometry.direction;
    let orthonormal = (rot.transpose() * rot - DMat3::IDENTITY)
        .to_cols_array()
        .iter()
        .all(|x| x.abs() < 1e-3);
    let (quatern, qfac) = if orthonormal {
        quaternion(gram_schmidt(rot))
    } else {
        ([0.0; 3], 1.0)
    };
    let pixdim = [
        qfac,
        geometry.spacing_mm[0],
        geometry.spacing_mm[1],
        geometry.spacing_mm[2],
        1.0,
        1.0,
        1.0,
        1.0,
    ];
    for (i, p) in pixdim.iter().enumerate() {
        put(76 + 4 * i, &(*p as f32).to_le_bytes());
    }
    put(108, &352f32.to_le_bytes()); // vox_offset
    put(112, &1f32.to_le_bytes()); // scl_slope
    put(123, &[2u8]); // xyzt_units: mm
    let descrip = b"shapecast";
    put(148, descrip);
    put(252, &(if orthonormal { 1i16 } else { 0 }).to_le_bytes()); // qform_code: scanner
    put(254, &1i16.to_le_bytes()); // sform_code: scanner
    for (i, q) in quatern.iter().enumerate() {
        put(256 + 4 * i, &(*q as f32).to_le_bytes());
    }
    for i in 0..3 {
        put(268 + 4 * i, &(origin[i] as f32).to_le_bytes());
    }
    for row in 0..3 {
        let r = m.row(row);
        for (c, v) in [r.x, r.y, r.z, origin[row]].iter().enumerate() {
            put(280 + 16 * row + 4 * c, &(*v as f32).to_le_bytes());
        }
    }
    put(344, b"n+1\0");
    b
}

/// The nearest orthonormal frame with the same first axis and handedness.
fn gram_schmidt(m: DMat3) -> DMat3 {
    let x = m.x_axis.normalize();
    let y = (m.y_axis - x * x.dot(m.y_axis)).normalize();
    let z = x.cross(y);
    let z = if z.dot(m.z_axis) < 0.0 { -z } else { z };
    DMat3::from_cols(x, y, z)
}

/// nifti1_io's mat44_to_quatern for an orthonormal matrix: (b, c, d) and qfac.
fn quaternion(rot: DMat3) -> ([f64; 3], f64) {
    let mut r = rot;
    let qfac = if r.determinant() < 0.0 {
        r.z_axis = -r.z_axis;
        -1.0
    } else {
        1.0
    };
    // r(row, col) in nifti1_io's notation.
    let e = |row: usize, col: usize| r.col(col)[row];
    let (r11, r12, r13) = (e(0, 0), e(0, 1), e(0, 2));
    let (r21, r22, r23) = (e(1, 0), e(1, 1), e(1, 2));
    let (r31, r32, r33) = (e(2, 0), e(2, 1), e(2, 2));
    let trace = r11 + r22 + r33 + 1.0;
    let (mut a, mut b, mut c, mut d);
    if trace > 0.5 {
        a = 0.5 * trace.sqrt();
        b = 0.25 * (r32 - r23) / a;
        c = 0.25 * (r13 - r31) / a;
        d = 0.25 * (r21 - r12) / a;
    } else {
        let xd = 1.0 + r11 - (r22 + r33);
        let yd = 1.0 + r22 - (r11 + r33);
        let zd = 1.0 + r33 - (r11 + r22);
        if xd > 1.0 {
            b = 0.5 * xd.sqrt();
            c = 0.25 * (r12 + r21) / b;
            d = 0.25 * (r13 + r31) / b;
            a = 0.25 * (r32 - r23) / b;
        } else if yd > 1.0 {
            c = 0.5 * yd.sqrt();
            b = 0.25 * (r12 + r21) / c;
            d = 0.25 * (r23 + r32) / c;
            a = 0.25 * (r13 - r31) / c;
        } else {
            d = 0.5 * zd.sqrt();
            b = 0.25 * (r13 + r31) / d;
            c = 0.25 * (r23 + r32) / d;
            a = 0.25 * (r21 - r12) / d;
        }
    }
    if a < 0.0 {
        (b, c, d) = (-b, -c, -d);
        a = -a;
    }
    let _ = a;
    ([b, c, d], qfac)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // a failed unwrap is a failed test
mod tests {
    use super::*;
    use crate::io::{InputFile, load};

    fn oblique_volume() -> Volume {
        let mut v = Volume::from_f32(
            [3, 4, 5],
            [0.5, 0.75, 2.0],
            (0..60).map(|x| x as f32).collect(),
        );
        let a = 0.3f64;
        v.direction = DMat3::from_cols(
            DVec3::new(a.cos(), a.sin(), 0.0),
            DVec3::new(-a.sin(), a.cos(), 0.0),
            DVec3::new(0.0, 0.0, -1.0),
        );
        v.origin_mm = [10.0, -20.0, 30.0];
        v
    }

    #[test]
    fn roundtrip_keeps_geometry_and_values() {
        let v = oblique_volume();
        for name in ["o.nii", "o.nii.gz"] {
            let bytes = write_volume(name, &v).unwrap();
            let back = load(&[InputFile::new(name, bytes)]).unwrap().volume;
            assert_eq!(back.dims, v.dims);
            assert_eq!(back.to_f32(), v.to_f32());
            for a in 0..3 {
                assert!((back.spacing_mm[a] - v.spacing_mm[a]).abs() < 1e-5);
                assert!((back.origin_mm[a] - v.origin_mm[a]).abs() < 1e-4);
            }
            assert!(
                (back.direction - v.direction)
                    .to_cols_array()
                    .iter()
                    .all(|x| x.abs() < 1e-5)
            );
        }
    }

    #[test]
    fn qform_alone_gives_the_same_geometry() {
        let v = oblique_volume();
        let mut bytes = write_volume("o.nii", &v).unwrap();
        bytes[254..256].copy_from_slice(&0i16.to_le_bytes()); // sform_code = 0
        let back = load(&[InputFile::new("o.nii", bytes)]).unwrap().volume;
        assert!(
            (back.direction - v.direction)
                .to_cols_array()
                .iter()
                .all(|x| x.abs() < 1e-5)
        );
        for a in 0..3 {
            assert!((back.origin_mm[a] - v.origin_mm[a]).abs() < 1e-4);
        }
    }

    #[test]
    fn vector_file_reads_first_component() {
        let v = oblique_volume();
        let a: Vec<f32> = vec![1.0; 60];
        let b: Vec<f32> = vec![2.0; 60];
        let bytes = write("vec.nii", &v, &[&a, &b, &a], WriteIntent::Vector).unwrap();
        assert_eq!(bytes.len(), 352 + 60 * 3 * 4);
        let back = load(&[InputFile::new("vec.nii", bytes)]).unwrap().volume;
        assert_eq!(back.to_f32(), a);
        assert!(back.warnings.iter().any(|w| w.contains("components")));
        assert!(write("x.nii", &v, &[&a[..10]], WriteIntent::None).is_err());
    }
}
