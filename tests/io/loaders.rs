//! Every volume and DICOM series in ../shared/data opens with the geometry and voxel values that
//! independent tools read from the same files (nibabel 5.4.2, pydicom 3.0.2 and SimpleITK 2.5.7,
//! run by hand; each expectation says which). Files in an encoding Shapecast cannot decode must
//! fail with a message that names it. Reads ../shared/data through `common::shared_data`.

use crate::common;

use std::path::Path;

use glam::{DMat3, DVec3};
use shapecast::io::{self, InputFile, LoadError, Loaded};

/// What a loaded volume must look like. `direction` is row-major, LPS (SimpleITK's
/// GetDirection() order); `values` are physical values (after rescale) at the voxels
/// (0,0,0), (nx/2,ny/2,nz/2), (nx-1,ny-1,nz-1) and (nx/3,ny/4,nz/5).
struct Expect {
    dims: [usize; 3],
    spacing_mm: [f64; 3],
    origin_mm: [f64; 3],
    direction: [f64; 9],
    values: [f32; 4],
    range: (f32, f32),
    voxel_type: &'static str,
    /// Tolerance for spacing and origin (mm) and direction cosines.
    tol: f64,
}

fn probe_points(d: [usize; 3]) -> [(usize, usize, usize); 4] {
    [
        (0, 0, 0),
        (d[0] / 2, d[1] / 2, d[2] / 2),
        (d[0] - 1, d[1] - 1, d[2] - 1),
        (d[0] / 3, d[1] / 4, d[2] / 5),
    ]
}

fn check(label: &str, loaded: &Loaded, e: &Expect) {
    let v = &loaded.volume;
    assert_eq!(v.dims, e.dims, "{label}: dims");
    assert_eq!(v.voxels.type_name(), e.voxel_type, "{label}: voxel type");
    for a in 0..3 {
        assert!(
            (v.spacing_mm[a] - e.spacing_mm[a]).abs() <= e.tol,
            "{label}: spacing {:?} vs {:?}",
            v.spacing_mm,
            e.spacing_mm
        );
        assert!(
            (v.origin_mm[a] - e.origin_mm[a]).abs() <= e.tol * 10.0,
            "{label}: origin {:?} vs {:?}",
            v.origin_mm,
            e.origin_mm
        );
    }
    let got = v.direction.transpose().to_cols_array();
    for (g, w) in got.iter().zip(&e.direction) {
        assert!(
            (g - w).abs() <= e.tol,
            "{label}: direction {got:?} vs {:?}",
            e.direction
        );
    }
    for (p, want) in probe_points(e.dims).iter().zip(&e.values) {
        let got = v.value_at(p.0, p.1, p.2);
        assert!(
            (got - want).abs() <= 1e-3 * want.abs().max(1.0),
            "{label}: value at {p:?} is {got}, expected {want}"
        );
    }
    let (lo, hi) = v.value_range().expect("non-empty");
    assert!(
        (lo - e.range.0).abs() <= 1e-3 * e.range.0.abs().max(1.0)
            && (hi - e.range.1).abs() <= 1e-3 * e.range.1.abs().max(1.0),
        "{label}: range ({lo}, {hi}) vs {:?}",
        e.range
    );
}

fn load_shared(rels: &[&str]) -> Option<Result<Loaded, LoadError>> {
    let mut files = Vec::new();
    for r in rels {
        let p = common::shared_data(r)?;
        if p.is_dir() {
            files.extend(common::inputs_in(&p));
        } else {
            files.push(common::input(&p));
        }
    }
    Some(io::load(&files))
}

fn expect_ok(rels: &[&str], e: &Expect) -> Option<Loaded> {
    let loaded = load_shared(rels)?.unwrap_or_else(|err| panic!("{rels:?}: {err}"));
    check(rels[0], &loaded, e);
    Some(loaded)
}

const IDENTITY: [f64; 9] = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0];
const RAS_IDENTITY_IN_LPS: [f64; 9] = [-1.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, 1.0];

// ---------------------------------------------------------------- NIfTI

#[test]
fn nifti_aorta_ct() {
    // SimpleITK ReadImage; nibabel agrees (sform_code 2, affine diag(-1.5, -1.5, 1.5)).
    expect_ok(
        &["ct/aorta_ct_cropped.nii.gz"],
        &Expect {
            dims: [120, 126, 164],
            spacing_mm: [1.5; 3],
            origin_mm: [-71.658203125, -255.658203125, 540.2000122070312],
            direction: IDENTITY,
            values: [-108.0, 422.0, 66.0, 75.0],
            range: (-1078.0, 3343.0),
            voxel_type: "i16",
            tol: 1e-5,
        },
    );
}

#[test]
fn nifti_abdomen_ct_and_segmentation() {
    // SimpleITK ReadImage.
    expect_ok(
        &["ct/example_ct_sm.nii.gz"],
        &Expect {
            dims: [122, 101, 30],
            spacing_mm: [3.0; 3],
            origin_mm: [177.95632934570312, -11.319000244140625, 94.3017578125],
            direction: RAS_IDENTITY_IN_LPS,
            values: [-1024.0, 0.0, -997.0, 26.0],
            range: (-1100.0, 1207.0),
            voxel_type: "i16",
            tol: 1e-5,
        },
    );
    expect_ok(
        &["ct/aorta_seg.nii.gz"],
        &Expect {
            dims: [120, 126, 164],
            spacing_mm: [1.5; 3],
            origin_mm: [-71.658203125, -255.658203125, 540.2000122070312],
            direction: IDENTITY,
            values: [0.0; 4],
            range: (0.0, 1.0),
            voxel_type: "u8",
            tol: 1e-5,
        },
    );
}

#[test]
fn nifti_u8_with_scl_slope() {
    // SimpleITK ReadImage (float32 after scaling, max 563.2); nibabel: scl_slope 2.208627462387085.
    let l = expect_ok(
        &["ct/CT_AVM.nii.gz"],
        &Expect {
            dims: [256, 242, 154],
            spacing_mm: [0.719942569732666, 0.7209135890007019, 1.0],
            origin_mm: [73.39768981933594, 69.69419860839844, -64.11000061035156],
            direction: RAS_IDENTITY_IN_LPS,
            values: [0.0; 4],
            range: (0.0, 563.2),
            voxel_type: "u8",
            tol: 1e-5,
        },
    );
    if let Some(l) = l {
        assert!((l.volume.value_slope - 2.208_627_5).abs() < 1e-6);
    }
}

#[test]
fn nifti_sheared_gantry_tilt_keeps_the_sform() {
    // nibabel's affine (sform, which Shapecast prefers; SimpleITK squares it up from the qform):
    // [[0.482421875, 0, 0, -94.3793563843], [0, 0.4574920535, 0, -117.1060180664],
    //  [0, 0.1530747414, 2.3708093166, -102.2035522461]] in RAS; scl 7.109804153442383, -1024.
    let col_j_ras = DVec3::new(0.0, 0.4574920535, 0.1530747414);
    let sj = col_j_ras.length();
    let j_lps = DVec3::new(0.0, -col_j_ras.y, col_j_ras.z) / sj;
    let d = DMat3::from_cols(DVec3::new(-1.0, 0.0, 0.0), j_lps, DVec3::Z);
    let l = expect_ok(
        &["formats/shear.nii.gz"],
        &Expect {
            dims: [306, 422, 54],
            spacing_mm: [0.482421875, sj, 2.3708093166],
            origin_mm: [94.3793563843, 117.1060180664, -102.2035522461],
            direction: d.transpose().to_cols_array(),
            // SimpleITK values (it applies the same scl_slope/scl_inter).
            values: [-1024.0, 92.23925, -1024.0, -768.04706],
            range: (-1024.0, 789.00006),
            voxel_type: "u8",
            tol: 1e-6,
        },
    );
    if let Some(l) = l {
        assert!(
            l.volume
                .warnings
                .iter()
                .any(|w| w.contains("not orthogonal")),
            "{:?}",
            l.volume.warnings
        );
    }
}

#[test]
fn nifti_small_files() {
    // low_res: SimpleITK and nibabel agree (sform_code 2, diag(2)).
    expect_ok(
        &["formats/low_res.nii.gz"],
        &Expect {
            dims: [7, 5, 3],
            spacing_mm: [2.0; 3],
            origin_mm: [0.0; 3],
            direction: RAS_IDENTITY_IN_LPS,
            values: [1.0, 1.0, 1.0, 0.0],
            range: (0.0, 1.0),
            voxel_type: "u8",
            tol: 1e-6,
        },
    );
    // minimal.nii.gz is big-endian with qform_code = sform_code = 0. Dims, spacing and values
    // from nibabel. Its geometry is the NIfTI-1 standard's method 1 (x = pixdim[1] * i in RAS,
    // origin 0); the tools disagree here (nibabel centres an Analyze-style flipped affine,
    // SimpleITK returns identity LPS), so the standard is the reference.
    let l = expect_ok(
        &["formats/minimal.nii.gz"],
        &Expect {
            dims: [64, 64, 10],
            spacing_mm: [3.0; 3],
            origin_mm: [0.0; 3],
            direction: RAS_IDENTITY_IN_LPS,
            values: [0.0, 32.0, 63.0, 16.0],
            range: (0.0, 63.0),
            voxel_type: "u8",
            tol: 1e-6,
        },
    );
    if let Some(l) = l {
        assert!(l.volume.warnings.iter().any(|w| w.contains("method 1")));
    }
}

#[test]
fn nifti_hdr_img_pair() {
    // SimpleITK ReadImage of ras.hdr; nibabel: Nifti1Pair, qform/sform code 1.
    let e = Expect {
        dims: [62, 41, 34],
        spacing_mm: [2.3852322101593018, 2.389753818511963, 2.3664863109588623],
        origin_mm: [73.37730407714844, 65.35720825195312, -31.532268524169922],
        direction: RAS_IDENTITY_IN_LPS,
        values: [0.0, 124.0, 0.0, 168.0],
        range: (0.0, 255.0),
        voxel_type: "u8",
        tol: 1e-6,
    };
    expect_ok(&["formats/ras.hdr", "formats/ras.img"], &e);
    // The order of the pair does not matter.
    expect_ok(&["formats/ras.img", "formats/ras.hdr"], &e);
    // The header alone names the missing data file.
    if let Some(r) = load_shared(&["formats/ras.hdr"]) {
        let err = r.expect_err("no .img").to_string();
        assert!(err.contains("ras.img"), "{err}");
    }
}

// ---------------------------------------------------------------- NRRD and MetaImage

#[test]
fn nrrd_oblique_flair() {
    // SimpleITK ReadImage.
    expect_ok(
        &["formats/FLAIR.nrrd"],
        &Expect {
            dims: [124, 160, 140],
            spacing_mm: [1.0, 1.0, 1.0],
            origin_mm: [64.8982391357422, 110.4311447143555, -27.92553901672364],
            direction: [
                -0.9935920092120875,
                -0.016005020190061215,
                -0.11188725988575329,
                0.04970492721885441,
                -0.9509366513904121,
                -0.30536684015685994,
                -0.10151029228632795,
                -0.3089713973349404,
                0.9456385852998346,
            ],
            values: [0.0, 170.0, 0.0, 125.0],
            range: (0.0, 255.0),
            voxel_type: "u8",
            tol: 1e-9,
        },
    );
}

#[test]
fn nrrd_lung_ct_and_label() {
    // SimpleITK ReadImage.
    let mut e = Expect {
        dims: [512, 512, 61],
        spacing_mm: [0.6269531, 0.6269531, 5.0],
        origin_mm: [-170.5, -324.5, -360.0],
        direction: IDENTITY,
        values: [-999.0, 39.0, -906.0, 40.0],
        range: (-1024.0, 1671.0),
        voxel_type: "i16",
        tol: 1e-9,
    };
    expect_ok(&["ct/lung2_image.nrrd"], &e);
    e.values = [0.0; 4];
    e.range = (0.0, 1.0);
    expect_ok(&["ct/lung2_label.nrrd"], &e);
}

#[test]
fn nrrd_detached_4d_dwi() {
    // SimpleITK ReadImage (a 451-component vector image; its first component is compared).
    let l = expect_ok(
        &[
            "formats/multishell-DWI-451dir.nhdr",
            "formats/multishell-DWI-451dir.raw.gz",
        ],
        &Expect {
            dims: [7, 7, 2],
            spacing_mm: [2.499999999999999, 2.499999999999999, 2.5000009536743164],
            origin_mm: [-9.190097570916366, -98.09805317400576, 9.87501599984839],
            direction: [
                0.9961949571817105,
                -1.0571639073091968e-08,
                -0.08715277331654601,
                -0.0006107499494255613,
                0.9999754441667866,
                -0.0069812641842669785,
                0.08715064124967463,
                0.007007928612474695,
                0.9961704954743562,
            ],
            values: [45.0, 521.0, 28.0, 320.0],
            // Range of the first component only (from the same SimpleITK array).
            range: (7.0, 609.0),
            voxel_type: "i16",
            tol: 1e-9,
        },
    );
    if let Some(l) = l {
        assert!(l.volume.warnings.iter().any(|w| w.contains("451")));
    }
    if let Some(r) = load_shared(&["formats/multishell-DWI-451dir.nhdr"]) {
        assert!(matches!(r, Err(LoadError::MissingDataFile { .. })), "{r:?}");
    }
}

#[test]
fn metaimage_compressed() {
    // SimpleITK ReadImage.
    expect_ok(
        &["formats/mha.mha"],
        &Expect {
            dims: [64, 64, 37],
            spacing_mm: [3.4375, 3.4375, 3.8],
            origin_mm: [-108.281, 82.3795, -47.8356],
            direction: [1.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, 1.0],
            values: [0.0, 4369.0, 0.0, 2123.0],
            range: (0.0, 6690.0),
            voxel_type: "i16",
            tol: 1e-9,
        },
    );
}

// ---------------------------------------------------------------- DICOM series

#[test]
fn dicom_series_liver_slice_thickness_disagrees() {
    // SimpleITK ImageSeriesReader (GDCM), which also orders by position along the normal.
    let l = expect_ok(
        &["series/ct-3slice-liver"],
        &Expect {
            dims: [512, 512, 3],
            spacing_mm: [0.810547, 0.810547, 1.0],
            origin_mm: [-235.199997, -226.800003, -128.690002],
            direction: IDENTITY,
            values: [-3024.0, -92.0, -3024.0, 135.0],
            range: (-3024.0, 1381.0),
            voxel_type: "i16",
            tol: 1e-6,
        },
    );
    if let Some(l) = l {
        let w = &l.volume.warnings;
        assert!(
            w.iter().any(|w| w.contains("SliceThickness is 1.25")),
            "{w:?}"
        );
        assert_eq!(l.volume.modality, shapecast::Modality::Ct);
        assert_eq!(l.volume.value_intercept, -1024.0);
    }
}

#[test]
fn dicom_series_oblique_mr() {
    // SimpleITK ImageSeriesReader. Its k column is the slice normal; Shapecast's comes from the
    // positions, which differ from the normal by ~2e-5 here, hence the tolerance.
    expect_ok(
        &["series/mr-prostate-adc-oblique"],
        &Expect {
            dims: [256, 256, 20],
            spacing_mm: [0.7031, 0.7031, 2.9999917150116437],
            origin_mm: [-90.0225, -108.462, -43.9748],
            direction: [
                0.999980959458906,
                -0.005401652065676619,
                -0.002983768524384604,
                0.004800583524540405,
                0.9847553765859284,
                -0.17387870106177564,
                0.003877514341643107,
                0.17386106648720348,
                0.9847625573926249,
            ],
            values: [0.0, 1804.0, 0.0, 0.0],
            range: (0.0, 4095.0),
            voxel_type: "i16",
            tol: 5e-5,
        },
    );
}

#[test]
fn dicom_series_chest_ct() {
    // SimpleITK ImageSeriesReader; stored unsigned 12-bit with RescaleIntercept -1024.
    let l = expect_ok(
        &["series/ct-chest-lung-kernel"],
        &Expect {
            dims: [512, 512, 30],
            spacing_mm: [0.646484375, 0.646484375, 8.0],
            origin_mm: [-173.1767578125, -294.1767578125, 80.0],
            direction: IDENTITY,
            values: [-996.0, 20.0, -1003.0, 12.0],
            range: (-1024.0, 1904.0),
            voxel_type: "u16",
            tol: 1e-9,
        },
    );
    if let Some(l) = l {
        assert!(l.volume.warnings.is_empty(), "{:?}", l.volume.warnings);
    }
}

fn head_expect() -> Expect {
    // SimpleITK ImageSeriesReader.
    Expect {
        dims: [64, 64, 93],
        spacing_mm: [3.2, 3.2, 1.5],
        origin_mm: [0.0; 3],
        direction: IDENTITY,
        values: [0.0, 122.0, 0.0, 107.0],
        range: (0.0, 3926.0),
        voxel_type: "i16",
        tol: 1e-9,
    }
}

/// A fixed pseudo-random permutation (no rand dependency; the test must be reproducible).
fn shuffled<T>(mut v: Vec<T>, seed: u64) -> Vec<T> {
    let mut s = seed;
    for i in (1..v.len()).rev() {
        s = s
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        v.swap(i, (s >> 33) as usize % (i + 1));
    }
    v
}

#[test]
fn dicom_series_in_any_order_or_folder_is_identical() {
    let Some(dir) = common::shared_data("series/ct-head-64px") else {
        return;
    };
    let files = common::inputs_in(&dir);
    let reference = io::load(&files).expect("head series");
    check("ct-head-64px", &reference, &head_expect());

    let reversed: Vec<InputFile> = files.iter().rev().cloned().collect();
    let shuffled_files = shuffled(files.clone(), 42);
    // Nested folders, as a dropped directory tree arrives.
    let nested: Vec<InputFile> = shuffled(files.clone(), 7)
        .into_iter()
        .enumerate()
        .map(|(i, f)| InputFile::new(format!("study/{}/sub/{}", i % 3, f.name), f.bytes))
        .collect();
    for (label, set) in [
        ("reversed", reversed),
        ("shuffled", shuffled_files),
        ("nested", nested),
    ] {
        let l = io::load(&set).unwrap_or_else(|e| panic!("{label}: {e}"));
        assert!(l.volume == reference.volume, "{label}: volume differs");
    }
}

#[test]
fn dicom_largest_series_is_chosen_and_others_listed() {
    let (Some(head), Some(liver), Some(licence)) = (
        common::shared_data("series/ct-head-64px"),
        common::shared_data("series/ct-3slice-liver"),
        common::shared_data("series/LICENSE-dcmqi.txt"),
    ) else {
        return;
    };
    let mut files = common::inputs_in(&liver);
    files.extend(common::inputs_in(&head));
    files.push(common::input(&licence));
    let l = io::load(&files).expect("mixed series");
    check("mixed", &l, &head_expect());
    assert!(
        l.notes
            .iter()
            .any(|n| n.contains("another series") && n.contains("3 images")),
        "{:?}",
        l.notes
    );
    assert!(
        l.notes.iter().any(|n| n.contains("LICENSE-dcmqi.txt")),
        "{:?}",
        l.notes
    );
}

/// The files of several series dirs, each named under its dir ("head/...", "liver/...").
fn series_inputs(dirs: &[(&str, &std::path::Path)]) -> Vec<InputFile> {
    let mut files = Vec::new();
    for (label, dir) in dirs {
        files.extend(
            common::inputs_in(dir)
                .into_iter()
                .map(|f| InputFile::new(format!("{label}/{}", f.name), f.bytes)),
        );
    }
    files
}

#[test]
fn dicom_series_list_names_each_series_and_loads_the_one_chosen() {
    use shapecast::io::{Limits, SliceOrientation};
    let (Some(head), Some(liver), Some(mr), Some(licence)) = (
        common::shared_data("series/ct-head-64px"),
        common::shared_data("series/ct-3slice-liver"),
        common::shared_data("series/mr-prostate-adc-oblique"),
        common::shared_data("series/LICENSE-dcmqi.txt"),
    ) else {
        return;
    };
    let dirs = [("liver", liver.as_path()), ("head", &head), ("mr", &mr)];
    let mut files = series_inputs(&dirs);
    files.push(common::input(&licence));
    let limits = Limits::default();
    let list = io::list_series(&files, &limits)
        .expect("listed")
        .expect("a DICOM set");
    let entries = list.entries();
    assert_eq!(entries.len(), 3, "{entries:?}");
    let find = |modality: &str, images: usize| {
        entries
            .iter()
            .position(|e| e.modality == modality && e.images == images)
            .unwrap_or_else(|| panic!("no {modality} series of {images} images: {entries:?}"))
    };
    let (i_head, i_liver, i_mr) = (find("CT", 93), find("CT", 3), find("MR", 20));
    // Headers alone: counts, sizes, thickness and plane as the files say.
    let (h, l, m) = (&entries[i_head], &entries[i_liver], &entries[i_mr]);
    assert_eq!((h.files, h.rows, h.cols), (93, 64, 64));
    assert_eq!((l.files, l.rows, l.cols), (3, 512, 512));
    assert_eq!((m.files, m.rows, m.cols), (20, 256, 256));
    assert_eq!(l.slice_thickness_mm, Some(1.25));
    assert_eq!(h.orientation, SliceOrientation::Axial);
    assert_eq!(l.orientation, SliceOrientation::Axial);
    // The ADC's normal is 10.02 degrees from S (see dicom_series_oblique_mr's direction).
    assert_eq!(m.orientation, SliceOrientation::Oblique);
    assert!(entries.iter().all(|e| e.part == (0, 1)), "{entries:?}");
    assert!(
        list.notes().iter().any(|n| n.contains("LICENSE-dcmqi.txt")),
        "{:?}",
        list.notes()
    );
    // The default is the CT or MR series with the most images.
    assert_eq!(list.default_choice(), i_head);
    // Each entry loads exactly the volume its folder loads alone.
    for (i, (label, dir)) in [(i_liver, dirs[0]), (i_head, dirs[1]), (i_mr, dirs[2])] {
        let chosen = list.load(&files, i, &limits).expect(label);
        let alone = io::load(&series_inputs(&[(label, dir)])).expect(label);
        assert!(chosen.volume == alone.volume, "{label}: volume differs");
        assert_eq!(chosen.volume.dims[2], entries[i].images, "{label}");
    }
    // Read file by file (the browser's folders): the same list in one pass, and each entry
    // loaded from its own files, decoded as they come, equals the list's load.
    let mut reader = io::FolderReader::new(limits);
    for f in &files {
        if f.name.ends_with(".txt") {
            reader.ignore(f.name.clone());
        } else {
            reader.push(f.clone()).expect("pushed");
        }
    }
    let io::FolderRead::List(streamed) = reader.finish().expect("read") else {
        panic!("three series read as one volume");
    };
    assert_eq!(streamed.entries(), entries);
    assert_eq!(streamed.default_choice(), i_head);
    for i in [i_liver, i_head, i_mr] {
        let want = list.load(&files, i, &limits).expect("loads");
        let got = io::load_entry(&streamed, i, &limits, |k| Ok(files[k].clone())).expect("loads");
        assert!(got.volume == want.volume, "entry {i}: volume differs");
        assert_eq!(got.patient, want.patient, "entry {i}");
        let sorted = |mut v: Vec<String>| {
            v.sort();
            v
        };
        assert_eq!(sorted(got.notes), sorted(want.notes), "entry {i}");
    }
    // One series read file by file is decoded in the same pass: the file loader's volume.
    let liver_files = series_inputs(&[dirs[0]]);
    let mut reader = io::FolderReader::new(limits);
    for f in &liver_files {
        reader.push(f.clone()).expect("pushed");
    }
    assert!(reader.decoding());
    let io::FolderRead::Loaded(one) = reader.finish().expect("read") else {
        panic!("one series listed");
    };
    let alone = io::load(&liver_files).expect("liver");
    assert!(one.volume == alone.volume, "liver: volume differs");
    assert_eq!(one.notes, alone.notes);
    // The list does not depend on the order the files came in.
    let reversed: Vec<InputFile> = files.iter().rev().cloned().collect();
    let again = io::list_series(&reversed, &limits)
        .expect("listed")
        .expect("a DICOM set");
    assert_eq!(again.entries(), entries);
    // Other files than those listed are refused, naming the problem.
    let e = list
        .load(&reversed, i_mr, &limits)
        .expect_err("other files");
    assert!(
        matches!(
            e,
            io::LoadError::DicomSeries {
                problem: io::SeriesProblem::FilesChanged {
                    given: 117,
                    listed: 117
                },
                ..
            }
        ),
        "{e}"
    );
    // One series, or another format, is no list of several.
    let one = io::list_series(&series_inputs(&[dirs[0]]), &limits)
        .expect("listed")
        .expect("a DICOM set");
    assert_eq!(one.entries().len(), 1);
    assert!(
        io::list_series(&[common::input(&licence)], &limits)
            .expect("listed")
            .is_none()
    );
}

// ---------------------------------------------------------------- DICOM single files

fn emri_expect() -> Expect {
    // pydicom pixel_array (frames in file order: the file has no positions or orientation).
    Expect {
        dims: [64, 64, 10],
        spacing_mm: [1.0, 1.0, 1.2],
        origin_mm: [0.0; 3],
        direction: IDENTITY,
        values: [31.0, 66.0, 147.0, 134.0],
        range: (0.0, 467.0),
        voxel_type: "u16",
        tol: 1e-9,
    }
}

#[test]
fn dicom_multiframe_transfer_syntaxes() {
    for f in [
        "formats/emri_small.dcm",
        "formats/emri_small_big_endian.dcm",
        "formats/emri_small_RLE.dcm",
        "formats/emri_small_jpeg_2k_lossless.dcm",
    ] {
        if let Some(l) = expect_ok(&[f], &emri_expect()) {
            assert!(
                l.volume
                    .warnings
                    .iter()
                    .any(|w| w.contains("ImagePositionPatient")),
                "{f}"
            );
        }
    }
}

#[test]
fn compressed_multi_frame_files_decode_frame_by_frame_to_the_uncompressed_voxels() {
    // RLE and JPEG 2000 frames are decoded one at a time (straight into the voxel buffer): every
    // voxel must equal the uncompressed copy's, frame order included.
    let Some(plain) = load_shared(&["formats/emri_small.dcm"]) else {
        return;
    };
    let plain = plain.expect("uncompressed loads").volume;
    let mut compressed = vec!["formats/emri_small_RLE.dcm"];
    if cfg!(not(target_arch = "wasm32")) {
        compressed.push("formats/emri_small_jpeg_2k_lossless.dcm");
    }
    for f in compressed {
        let v = load_shared(&[f])
            .expect("shared data present")
            .unwrap_or_else(|e| panic!("{f}: {e}"))
            .volume;
        assert_eq!(v.voxels, plain.voxels, "{f}");
        assert_eq!(v.dims, plain.dims, "{f}");
    }
}

#[test]
fn dicom_jpeg_ls_is_named_as_unsupported() {
    let Some(r) = load_shared(&["formats/emri_small_jpeg_ls_lossless.dcm"]) else {
        return;
    };
    let err = r.expect_err("JPEG-LS has no pure-Rust decoder");
    assert!(
        matches!(err, LoadError::UnsupportedTransferSyntax { .. }),
        "{err:?}"
    );
    let msg = err.to_string();
    assert!(
        msg.contains("1.2.840.10008.1.2.4.80") && msg.contains("JPEG-LS"),
        "{msg}"
    );
}

#[test]
fn dicom_enhanced_ct_and_mr() {
    // pydicom: shared PlaneOrientation [-1,0,0, 0,1,0], PixelSpacing 0.388672, frames at
    // z = -159 and -149 (ordered along the normal (0,0,-1): -149 first), rescale -1024.
    expect_ok(
        &["formats/eCT_Supplemental.dcm"],
        &Expect {
            dims: [512, 512, 2],
            spacing_mm: [0.388672, 0.388672, 10.0],
            origin_mm: [99.5, -301.5, -149.0],
            direction: [-1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, -1.0],
            values: [-1024.0, 81.0, -1024.0, 73.0],
            range: (-1024.0, 172.0),
            voxel_type: "u16",
            tol: 1e-9,
        },
    );
    // pydicom: per-frame PlanePosition z = -5.40356 + 2.4 k, PixelSpacing 3.375, pixel_array.
    expect_ok(
        &["formats/enh.dcm"],
        &Expect {
            dims: [64, 64, 6],
            spacing_mm: [3.375, 3.375, 2.4],
            origin_mm: [-109.79, -58.4773, -5.40356],
            direction: IDENTITY,
            values: [0.0, 560.0, 11.0, 11.0],
            range: (0.0, 1195.0),
            voxel_type: "u16",
            tol: 2e-5,
        },
    );
}

#[test]
fn dicom_jpeg_lossless_secondary_capture() {
    // pydicom pixel_array; the file has PixelSpacing 2.26 but no position or orientation.
    expect_ok(
        &["formats/JPEG-LL.dcm"],
        &Expect {
            dims: [256, 1024, 1],
            spacing_mm: [2.26, 2.26, 1.0],
            origin_mm: [0.0; 3],
            direction: IDENTITY,
            values: [0.0, 13.0, 0.0, 49.0],
            range: (0.0, 278.0),
            voxel_type: "i16",
            tol: 1e-9,
        },
    );
}

#[test]
fn dicom_one_bit_segmentations() {
    // pydicom pixel_array of liver.dcm: 1-bit SEG, frames at z = -128.69, -127.69, -126.69,
    // 36233 + 35645 + 35220 set pixels. The deflated copy must read the same.
    let e = Expect {
        dims: [512, 512, 3],
        spacing_mm: [0.810547, 0.810547, 1.0],
        origin_mm: [-235.2, -226.8, -128.69],
        direction: IDENTITY,
        values: [0.0, 1.0, 0.0, 0.0],
        range: (0.0, 1.0),
        voxel_type: "u8",
        tol: 1e-6,
    };
    for f in ["formats/liver.dcm", "formats/liver_deflate.dcm"] {
        if let Some(l) = expect_ok(&[f], &e) {
            let per_slice: Vec<usize> = (0..3)
                .map(|k| {
                    (0..512 * 512)
                        .filter(|&n| l.volume.value(k * 512 * 512 + n) > 0.5)
                        .count()
                })
                .collect();
            assert_eq!(per_slice, vec![36233, 35645, 35220], "{f}");
        }
    }
    // dicom-rs decodes RLE and JPEG 2000 only at 8 and 16 bits: a named error.
    for f in ["formats/liver_rle.dcm", "formats/liver_j2k.dcm"] {
        if let Some(r) = load_shared(&[f]) {
            let msg = r.expect_err("1-bit compressed").to_string();
            assert!(
                msg.contains("1.2.840.10008.1.2") && msg.contains("1-bit"),
                "{f}: {msg}"
            );
        }
    }
}

/// Every file and series directory under ../shared/data loads or fails with a named reason.
#[test]
fn everything_in_shared_data_opens_or_names_why_not() {
    let Some(root) = common::shared_data("") else {
        return;
    };
    let mut checked = 0;
    for sub in ["formats", "ct"] {
        for entry in std::fs::read_dir(root.join(sub)).expect("data dir") {
            let path = entry.expect("entry").path();
            let name = path
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default();
            // Data files of pairs and licences are not volumes on their own.
            if name.ends_with(".img")
                || name.ends_with(".raw.gz")
                || name.ends_with(".txt")
                || name.ends_with(".nhdr")
                || name.ends_with(".hdr")
            {
                continue;
            }
            match io::load(&[common::input(&path)]) {
                Ok(l) => assert!(l.volume.voxel_count() > 0, "{name}"),
                Err(e) => {
                    let msg = e.to_string();
                    assert!(
                        msg.contains("transfer syntax")
                            && (name.contains("jpeg_ls")
                                || name.contains("rle")
                                || name.contains("j2k")),
                        "{name} failed unexpectedly: {msg}"
                    );
                }
            }
            checked += 1;
        }
    }
    for series in [
        "ct-3slice-liver",
        "mr-prostate-adc-oblique",
        "ct-head-64px",
        "ct-chest-lung-kernel",
    ] {
        let files = common::inputs_in(&root.join("series").join(series));
        let l = io::load(&files).unwrap_or_else(|e| panic!("{series}: {e}"));
        assert!(l.volume.dims[2] > 1, "{series}");
        checked += 1;
    }
    assert!(
        checked >= 25,
        "only {checked} inputs found under {}",
        Path::new(&root).display()
    );
}
