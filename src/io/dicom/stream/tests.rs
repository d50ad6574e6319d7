use super::*;
use crate::io::dicom::synth::Slice;

fn bundled(rel: &str) -> Vec<InputFile> {
    let p = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/dicom")
        .join(rel);
    let paths: Vec<std::path::PathBuf> = if p.is_dir() {
        let mut v: Vec<_> = std::fs::read_dir(&p)
            .unwrap()
            .map(|e| e.unwrap().path())
            .collect();
        v.sort();
        v
    } else {
        vec![p]
    };
    paths
        .iter()
        .map(|p| {
            let name = p.file_name().unwrap().to_string_lossy().into_owned();
            InputFile::new(name, std::fs::read(p).unwrap())
        })
        .collect()
}

/// Streams `files` in several orders (with and without an expected count) and checks that
/// the volume equals the file loader's, field by field.
fn assert_streams_like_files(files: &[InputFile]) -> Loaded {
    let want = crate::io::load(files).unwrap();
    let n = files.len();
    let orders: Vec<Vec<usize>> = vec![
        (0..n).collect(),
        (0..n).rev().collect(),
        (0..n).step_by(2).chain((1..n).step_by(2)).collect(),
    ];
    for (i, order) in orders.iter().enumerate() {
        let mut b = SeriesBuilder::new(Limits::default());
        if i == 1 {
            b.expect_images(n);
        }
        for &o in order {
            b.push(files[o].clone()).unwrap();
        }
        let got = b.finish().unwrap();
        assert_eq!(got.volume, want.volume, "order {order:?}");
        let mut got_notes = got.notes.clone();
        let mut want_notes = want.notes.clone();
        got_notes.sort();
        want_notes.sort();
        assert_eq!(got_notes, want_notes, "order {order:?}");
    }
    want
}

#[test]
fn bundled_dicom_streams_to_the_file_loaders_volume() {
    let head = assert_streams_like_files(&bundled("ct-head-64px"));
    assert_eq!(head.volume.dims, [64, 64, 6]);
    // Multi-frame (enhanced MR, RLE) objects.
    assert_streams_like_files(&bundled("enh.dcm"));
    assert_streams_like_files(&bundled("emri_small_RLE.dcm"));
    // Two series of different sizes: the larger is loaded, the other noted.
    let mut mixed = bundled("ct-head-64px");
    mixed.extend(bundled("enh.dcm"));
    let m = assert_streams_like_files(&mixed);
    assert!(
        m.notes.iter().any(|n| n.contains("another series")),
        "{:?}",
        m.notes
    );
}

#[test]
fn localizers_duplicates_and_rescales_stream_like_files() {
    let series = "1.2.826.0.1.3680043.10.1";
    let mut files: Vec<InputFile> = (0..5)
        .map(|k| {
            let s = Slice::axial(series, k, 3, 4);
            InputFile::new(format!("s{k}.dcm"), s.bytes())
        })
        .collect();
    // A localizer of another size and a coronal slice of the same size in the same series,
    // and a duplicate position.
    let mut loc = Slice::axial(series, 9, 5, 5);
    loc.orientation = [1.0, 0.0, 0.0, 0.0, 0.0, -1.0];
    files.push(InputFile::new("loc.dcm", loc.bytes()));
    let mut cor = Slice::axial(series, 10, 3, 4);
    cor.orientation = [1.0, 0.0, 0.0, 0.0, 0.0, -1.0];
    files.push(InputFile::new("cor.dcm", cor.bytes()));
    let mut dup = Slice::axial(series, 2, 3, 4);
    dup.sop_uid = format!("{series}.dup");
    files.push(InputFile::new("dup.dcm", dup.bytes()));
    let same = assert_streams_like_files(&files);
    assert_eq!(same.volume.dims, [4, 3, 5]);
    assert!(matches!(same.volume.voxels, Voxels::I16(_)));

    // Differing rescales: physical f32 values.
    let mut varied = files.clone();
    let mut s = Slice::axial(series, 3, 3, 4);
    s.slope = 2.0;
    s.intercept = 5.0;
    varied[3] = InputFile::new("s3.dcm", s.bytes());
    let v = assert_streams_like_files(&varied);
    assert!(matches!(v.volume.voxels, Voxels::F32(_)));
    assert_eq!(v.volume.value_at(1, 0, 3), ((300 + 1) * 2 + 5) as f32);
}

#[test]
fn undecodable_and_oversized_images_are_refused_when_pushed() {
    let mut s = Slice::axial("1.2.3", 0, 2, 2);
    s.transfer_syntax = "1.2.840.10008.1.2.4.80".to_owned();
    let mut b = SeriesBuilder::new(Limits::default());
    let e = b
        .push(InputFile::new("ls.dcm", s.bytes()))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("1.2.840.10008.1.2.4.80") && e.contains("JPEG-LS"),
        "{e}"
    );

    let limits = Limits {
        max_voxel_bytes: 2 * 2 * 2 * 3,
        ..Limits::default()
    };
    let mut b = SeriesBuilder::new(limits);
    for k in 0..3 {
        let f = InputFile::new(format!("{k}.dcm"), Slice::axial("1.2.3", k, 2, 2).bytes());
        b.push(f).unwrap();
    }
    let f = InputFile::new("3.dcm", Slice::axial("1.2.3", 3, 2, 2).bytes());
    let e = b.push(f).unwrap_err().to_string();
    assert!(e.contains("3.dcm") && e.contains("limit"), "{e}");

    let mut b = SeriesBuilder::new(Limits::default());
    b.push(InputFile::new("junk", b"DICMjunk".to_vec()))
        .unwrap();
    assert!(b.finish().is_err());
    assert!(matches!(
        SeriesBuilder::new(Limits::default()).finish(),
        Err(LoadError::NoFiles)
    ));
}

#[test]
fn permutation_in_place_matches_a_copy() {
    let frame_len = 3;
    let staged: Vec<u16> = (0..7 * frame_len as u16).collect();
    for order in [
        vec![0, 1, 2, 3, 4, 5, 6],
        vec![6, 5, 4, 3, 2, 1, 0],
        vec![3, 0, 6, 1],
        vec![2],
        vec![],
        vec![1, 2, 0, 4, 3, 6, 5],
    ] {
        let mut v = staged.clone();
        permute_frames(&mut v, &order, frame_len);
        let want: Vec<u16> = order
            .iter()
            .flat_map(|&o| staged[o * frame_len..(o + 1) * frame_len].iter().copied())
            .collect();
        assert_eq!(v, want, "{order:?}");
    }
}
