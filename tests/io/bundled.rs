//! Loader tests on the small copies in tests/data, so that they run on a fresh clone without
//! ../shared. Expected values as in tests/io/loaders.rs (SimpleITK 2.5.7, nibabel 5.4.2, pydicom 3.0.2).

use crate::common;

use shapecast::io::{self, InputFile};

fn load(rels: &[&str]) -> io::Loaded {
    let files: Vec<InputFile> = rels
        .iter()
        .map(|r| common::input(&common::test_data(r)))
        .collect();
    io::load(&files).unwrap_or_else(|e| panic!("{rels:?}: {e}"))
}

#[test]
fn bundled_nifti_pair_and_metaimage() {
    // SimpleITK ReadImage of ras.hdr.
    let v = load(&["analyze/ras.hdr", "analyze/ras.img"]).volume;
    assert_eq!(v.dims, [62, 41, 34]);
    assert!((v.origin_mm[0] - 73.37730407714844).abs() < 1e-6);
    assert_eq!(v.value_at(31, 20, 17), 124.0);
    // SimpleITK ReadImage of mha.mha.
    let v = load(&["metaimage/mha.mha"]).volume;
    assert_eq!(v.dims, [64, 64, 37]);
    assert_eq!(v.direction.y_axis.y, -1.0);
    assert_eq!(v.value_at(32, 32, 18), 4369.0);
    // nibabel: 7x5x3 uint8.
    let v = load(&["nifti/low_res.nii.gz"]).volume;
    assert_eq!(v.dims, [7, 5, 3]);
    let v = load(&["nifti/minimal.nii.gz"]).volume;
    assert_eq!(v.value_at(63, 63, 9), 63.0);
}

#[test]
fn bundled_dicom() {
    // pydicom pixel_array.
    let v = load(&["dicom/emri_small_RLE.dcm"]).volume;
    assert_eq!(v.dims, [64, 64, 10]);
    assert_eq!(v.value_at(32, 32, 5), 66.0);
    assert_eq!(v.value_at(63, 63, 9), 147.0);
    let v = load(&["dicom/enh.dcm"]).volume;
    assert_eq!(v.dims, [64, 64, 6]);
    assert_eq!(v.value_at(32, 32, 3), 560.0);
    // Six slices of the head series, given in reverse order: positions z = 58.5 .. 66.0
    // (pydicom), 1.5 mm apart.
    let dir = common::test_data("dicom/ct-head-64px");
    let mut files = common::inputs_in(&dir);
    files.reverse();
    let l = io::load(&files).expect("head slices");
    assert_eq!(l.volume.dims, [64, 64, 6]);
    assert!((l.volume.spacing_mm[2] - 1.5).abs() < 1e-9);
    assert!(
        (l.volume.origin_mm[2] - 58.5).abs() < 1e-9,
        "{:?}",
        l.volume.origin_mm
    );
}
