//! Peak memory while reading, for every format (issue 14): at most 1.5x the final voxel bytes
//! plus a small constant. Natively files are read on demand (`shapecast::files::read_all`, as
//! the command line reads them): an uncompressed payload goes from the file straight into the
//! voxel buffer and a DICOM series is read one file at a time. In memory (the browser's reads,
//! whose bytes cannot be avoided) the loaders add at most the voxels to the input. Each file
//! is built here in a temporary folder; a counting allocator measures each load.

use crate::counting;

use std::io::Write;
use std::path::{Path, PathBuf};

use counting::peak_during;
use shapecast::io::{self, InputFile};
use shapecast::{Volume, Voxels};

const MIB: usize = 1 << 20;
/// The constant allowed above the voxels: a 1 MiB read chunk, 4 KiB heads, a DICOM slice or
/// two, names and headers.
const SLACK: usize = 3 * MIB;
const DIMS: [usize; 3] = [256, 256, 48];
const N: usize = DIMS[0] * DIMS[1] * DIMS[2];

fn temp_dir(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("shapecast-mem-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).expect("temp dir");
    d
}

/// A value per voxel that every stored type holds (0..=250, varied).
fn value(i: usize) -> f64 {
    ((i * 7 + i / 256) % 251) as f64
}

fn samples(ty: &str, big_endian: bool) -> Vec<u8> {
    let mut out = Vec::new();
    for i in 0..N {
        let v = value(i);
        let mut b: Vec<u8> = match ty {
            "u8" => vec![v as u8],
            "i16" => (v as i16).to_le_bytes().to_vec(),
            "u16" => (v as u16).to_le_bytes().to_vec(),
            "f32" => (v as f32).to_le_bytes().to_vec(),
            "f64" => v.to_le_bytes().to_vec(),
            "i32" => (v as i32).to_le_bytes().to_vec(),
            _ => unreachable!("{ty}"),
        };
        if big_endian {
            b.reverse();
        }
        out.extend_from_slice(&b);
    }
    out
}

/// NIfTI-1 single file (or, with `pair`, the 348-byte .hdr of a .hdr/.img pair).
fn nifti_header(datatype: i16, bitpix: i16, pair: bool) -> Vec<u8> {
    let mut b = vec![0u8; if pair { 348 } else { 352 }];
    b[0..4].copy_from_slice(&348i32.to_le_bytes());
    b[40..42].copy_from_slice(&3i16.to_le_bytes());
    for (i, d) in DIMS.iter().enumerate() {
        b[42 + 2 * i..44 + 2 * i].copy_from_slice(&(*d as i16).to_le_bytes());
    }
    b[70..72].copy_from_slice(&datatype.to_le_bytes());
    b[72..74].copy_from_slice(&bitpix.to_le_bytes());
    for i in 0..4 {
        b[76 + 4 * i..80 + 4 * i].copy_from_slice(&1f32.to_le_bytes());
    }
    let off: f32 = if pair { 0.0 } else { 352.0 };
    b[108..112].copy_from_slice(&off.to_le_bytes());
    b[344..348].copy_from_slice(if pair { b"ni1\0" } else { b"n+1\0" });
    b
}

fn gzip(bytes: &[u8]) -> Vec<u8> {
    let mut enc = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
    enc.write_all(bytes).expect("gzip");
    enc.finish().expect("gzip")
}

fn zlib(bytes: &[u8]) -> Vec<u8> {
    let mut enc = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::fast());
    enc.write_all(bytes).expect("zlib");
    enc.finish().expect("zlib")
}

fn nrrd_header(ty: &str, encoding: &str, endian: &str, data_file: Option<&str>) -> Vec<u8> {
    let mut h = format!(
        "NRRD0004\ntype: {ty}\ndimension: 3\nsizes: {} {} {}\nspacings: 1 1 1\nendian: {endian}\nencoding: {encoding}\n",
        DIMS[0], DIMS[1], DIMS[2]
    );
    match data_file {
        Some(f) => h.push_str(&format!("data file: {f}\n")),
        None => h.push('\n'),
    }
    h.into_bytes()
}

/// The voxel values as text, one per line, with varied separators.
fn ascii_text() -> Vec<u8> {
    let mut t = Vec::new();
    for i in 0..N {
        t.extend_from_slice(format!("{}", value(i)).as_bytes());
        t.extend_from_slice(match i % 3 {
            0 => b" ",
            1 => b",",
            _ => b"\n",
        });
    }
    t
}

fn mha_header(ty: &str, compressed: bool, data_file: &str) -> Vec<u8> {
    format!(
        "ObjectType = Image\nNDims = 3\nDimSize = {} {} {}\nElementType = {ty}\nElementSpacing = 1 1 1\nCompressedData = {}\nElementDataFile = {data_file}\n",
        DIMS[0],
        DIMS[1],
        DIMS[2],
        if compressed { "True" } else { "False" }
    )
    .into_bytes()
}

fn cat(a: Vec<u8>, b: &[u8]) -> Vec<u8> {
    let mut a = a;
    a.extend_from_slice(b);
    a
}

/// Files by name and content; the first is the one given, the others are found beside it.
type Files = Vec<(String, Vec<u8>)>;

/// The cases: a label, the files, the voxel type.
fn cases() -> Vec<(&'static str, Files, &'static str)> {
    let one = |n: &str, b: Vec<u8>| vec![(n.to_owned(), b)];
    vec![
        (
            "nii i16",
            one(
                "a.nii",
                cat(nifti_header(4, 16, false), &samples("i16", false)),
            ),
            "i16",
        ),
        (
            "nii u8",
            one(
                "a.nii",
                cat(nifti_header(2, 8, false), &samples("u8", false)),
            ),
            "u8",
        ),
        (
            "nii f32",
            one(
                "a.nii",
                cat(nifti_header(16, 32, false), &samples("f32", false)),
            ),
            "f32",
        ),
        (
            "nii f64 -> f32",
            one(
                "a.nii",
                cat(nifti_header(64, 64, false), &samples("f64", false)),
            ),
            "f32",
        ),
        (
            "nii i32 -> i16",
            one(
                "a.nii",
                cat(nifti_header(8, 32, false), &samples("i32", false)),
            ),
            "i16",
        ),
        (
            "hdr/img (ANALYZE-style pair)",
            vec![
                ("a.hdr".to_owned(), nifti_header(4, 16, true)),
                ("a.img".to_owned(), samples("i16", false)),
            ],
            "i16",
        ),
        (
            "nii.gz",
            one(
                "a.nii.gz",
                gzip(&cat(nifti_header(4, 16, false), &samples("i16", false))),
            ),
            "i16",
        ),
        (
            "nrrd raw",
            one(
                "a.nrrd",
                cat(
                    nrrd_header("short", "raw", "little", None),
                    &samples("i16", false),
                ),
            ),
            "i16",
        ),
        (
            "nrrd raw big endian",
            one(
                "a.nrrd",
                cat(
                    nrrd_header("ushort", "raw", "big", None),
                    &samples("u16", true),
                ),
            ),
            "u16",
        ),
        (
            "nhdr + raw (detached)",
            vec![
                (
                    "a.nhdr".to_owned(),
                    nrrd_header("float", "raw", "little", Some("a.raw")),
                ),
                ("a.raw".to_owned(), samples("f32", false)),
            ],
            "f32",
        ),
        (
            "nrrd gzip",
            one(
                "a.nrrd",
                cat(
                    nrrd_header("short", "gzip", "little", None),
                    &gzip(&samples("i16", false)),
                ),
            ),
            "i16",
        ),
        (
            "nrrd ascii",
            one(
                "a.nrrd",
                cat(nrrd_header("float", "ascii", "little", None), &ascii_text()),
            ),
            "f32",
        ),
        (
            "mha raw",
            one(
                "a.mha",
                cat(
                    mha_header("MET_SHORT", false, "LOCAL"),
                    &samples("i16", false),
                ),
            ),
            "i16",
        ),
        (
            "mhd + raw",
            vec![
                ("a.mhd".to_owned(), mha_header("MET_UCHAR", false, "a.raw")),
                ("a.raw".to_owned(), samples("u8", false)),
            ],
            "u8",
        ),
        (
            "mha zlib",
            one(
                "a.mha",
                cat(
                    mha_header("MET_SHORT", true, "LOCAL"),
                    &zlib(&samples("i16", false)),
                ),
            ),
            "i16",
        ),
    ]
}

fn check_values(label: &str, v: &Volume, ty: &str) {
    assert_eq!(v.dims, DIMS, "{label}");
    assert_eq!(v.voxels.type_name(), ty, "{label}");
    for i in [0, 1, 255, 256, 4097, N / 2, N - 1] {
        assert_eq!(
            f64::from(v.voxels.raw_f32(i)),
            value(i),
            "{label}: voxel {i}"
        );
    }
}

fn write_all(dir: &Path, files: &[(String, Vec<u8>)]) {
    for (n, b) in files {
        std::fs::write(dir.join(n), b).expect("write");
    }
}

#[test]
fn every_format_read_from_files_peaks_within_one_and_a_half_times_the_voxels() {
    let dir = temp_dir("formats");
    let mut report = Vec::new();
    for (label, files, ty) in cases() {
        let sub = dir.join(label.replace([' ', '/', '(', ')', '>'], "_"));
        std::fs::create_dir_all(&sub).expect("dir");
        write_all(&sub, &files);
        // The first file is given; the others are found beside it.
        let given = sub.join(&files[0].0);
        drop(files);
        let (r, peak) = peak_during(|| {
            let (inputs, _) = shapecast::files::read_all(&[given]).expect("lists the files");
            io::load(&inputs)
        });
        let v = r.unwrap_or_else(|e| panic!("{label}: {e}")).volume;
        check_values(label, &v, ty);
        let voxel_bytes = v.voxels.byte_len();
        report.push(format!(
            "{label}: peak {peak} bytes for {voxel_bytes} voxel bytes ({:.3}x)",
            peak as f64 / voxel_bytes as f64
        ));
        assert!(
            peak <= voxel_bytes * 3 / 2 + SLACK,
            "{label}: peak {peak} bytes for {voxel_bytes} voxel bytes"
        );
        std::fs::remove_dir_all(&sub).expect("clean up");
    }
    eprintln!("{}", report.join("\n"));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn every_format_in_memory_adds_at_most_the_voxels_to_its_input() {
    // The browser's path: the file bytes are already in memory (not counted: allocated before
    // the load); the load itself allocates the voxels and a constant.
    let mut report = Vec::new();
    for (label, files, ty) in cases() {
        let inputs: Vec<InputFile> = files
            .into_iter()
            .map(|(n, b)| InputFile::new(n, b))
            .collect();
        let (r, peak) = peak_during(|| io::load(&inputs));
        let v = r.unwrap_or_else(|e| panic!("{label}: {e}")).volume;
        check_values(label, &v, ty);
        let voxel_bytes = v.voxels.byte_len();
        report.push(format!(
            "{label}: input + {peak} bytes for {voxel_bytes} voxel bytes ({:.3}x)",
            peak as f64 / voxel_bytes as f64
        ));
        assert!(
            peak <= voxel_bytes + SLACK,
            "{label}: the load allocated {peak} bytes for {voxel_bytes} voxel bytes"
        );
    }
    eprintln!("{}", report.join("\n"));
}

#[test]
fn a_file_read_on_demand_loads_what_the_same_bytes_in_memory_load() {
    for (label, files, _) in cases() {
        let in_memory: Vec<InputFile> = files
            .iter()
            .map(|(n, b)| InputFile::new(n.clone(), b.clone()))
            .collect();
        let on_demand: Vec<InputFile> = files
            .into_iter()
            .map(|(n, b)| {
                InputFile::on_demand(n, std::sync::Arc::new(io::MemorySource(b)))
                    .expect("reads the head")
            })
            .collect();
        let a = io::load(&in_memory).unwrap_or_else(|e| panic!("{label}: {e}"));
        let b = io::load(&on_demand).unwrap_or_else(|e| panic!("{label}: {e}"));
        assert_eq!(a.volume, b.volume, "{label}");
        assert_eq!(a.notes, b.notes, "{label}");
    }
}

/// The browser's files are chunks (`io::Chunked`) that the loader lets go as it reads a
/// payload for the last time, so that the page holds the file's bytes or the voxels, not both.
/// Every format loads the same from chunks as from memory (a read of a chunk already let go
/// would be an error), and each file whose payload is decoded (not ascii) is let go whole.
#[test]
fn chunks_let_go_as_the_payload_is_read_load_what_memory_loads() {
    const CHUNK: usize = 100_003;
    for (label, files, _) in cases() {
        let in_memory: Vec<InputFile> = files
            .iter()
            .map(|(n, b)| InputFile::new(n.clone(), b.clone()))
            .collect();
        let sources: Vec<std::sync::Arc<io::Chunked<Vec<u8>>>> = files
            .iter()
            .map(|(_, b)| {
                let mut c = io::Chunked::default();
                b.chunks(CHUNK).for_each(|piece| c.push(piece.to_vec()));
                std::sync::Arc::new(c)
            })
            .collect();
        let chunked: Vec<InputFile> = files
            .iter()
            .zip(&sources)
            .map(|((n, _), c)| InputFile::on_demand(n.clone(), c.clone()).expect("head"))
            .collect();
        let a = io::load(&in_memory).unwrap_or_else(|e| panic!("{label}: {e}"));
        let b = io::load(&chunked).unwrap_or_else(|e| panic!("{label}: {e}"));
        assert_eq!(a.volume, b.volume, "{label}");
        assert_eq!(a.notes, b.notes, "{label}");
        // The payload's file: the largest.
        let Some(payload) = sources.iter().max_by_key(|c| c.len()) else {
            continue;
        };
        let released = payload.released();
        if label.contains("ascii") {
            assert_eq!(released, 0, "{label}: an ascii payload is not let go");
        } else {
            assert_eq!(released, payload.len(), "{label}: bytes let go");
        }
    }
}

#[test]
fn a_data_file_shorter_than_its_header_says_is_refused_by_name_on_demand_too() {
    let mut raw = samples("i16", false);
    raw.truncate(raw.len() - 2);
    let files = [
        InputFile::new(
            "a.nhdr",
            nrrd_header("short", "raw", "little", Some("a.raw")),
        ),
        InputFile::on_demand("a.raw", std::sync::Arc::new(io::MemorySource(raw)))
            .expect("reads the head"),
    ];
    let e = io::load(&files).expect_err("one sample short");
    let m = e.to_string();
    assert!(m.contains("a.raw") && m.contains("truncated"), "{m}");
    // A nii cut short, read on demand.
    let mut nii = cat(nifti_header(4, 16, false), &samples("i16", false));
    nii.truncate(nii.len() / 2);
    let f = InputFile::on_demand("cut.nii", std::sync::Arc::new(io::MemorySource(nii)))
        .expect("reads the head");
    let m = io::load(&[f]).expect_err("half the voxels").to_string();
    assert!(m.contains("cut.nii") && m.contains("truncated"), "{m}");
}

// ---------------------------------------------------------------------------------------------
// DICOM: a series of slices and one multi-frame file, written by hand (explicit VR little endian).

fn element(out: &mut Vec<u8>, tag: (u16, u16), vr: &[u8; 2], value: &[u8]) {
    let mut v = value.to_vec();
    if v.len() % 2 == 1 {
        v.push(if matches!(vr, b"UI" | b"OB") { 0 } else { b' ' });
    }
    out.extend_from_slice(&tag.0.to_le_bytes());
    out.extend_from_slice(&tag.1.to_le_bytes());
    out.extend_from_slice(vr);
    if matches!(vr, b"OB" | b"OW" | b"SQ" | b"UN" | b"UT") {
        out.extend_from_slice(&[0, 0]);
        out.extend_from_slice(&(v.len() as u32).to_le_bytes());
    } else {
        out.extend_from_slice(&(v.len() as u16).to_le_bytes());
    }
    out.extend_from_slice(&v);
}

/// A CT image of DIMS[0] x DIMS[1] with `frames` frames at z = `z` mm, pixels `value(first + i)`.
fn dicom(z: usize, frames: usize, first: usize) -> Vec<u8> {
    let mut group = Vec::new();
    element(&mut group, (0x0002, 0x0001), b"OB", &[0, 1]);
    element(
        &mut group,
        (0x0002, 0x0002),
        b"UI",
        b"1.2.840.10008.5.1.4.1.1.2",
    );
    element(
        &mut group,
        (0x0002, 0x0003),
        b"UI",
        format!("1.2.3.4.{z}").as_bytes(),
    );
    element(&mut group, (0x0002, 0x0010), b"UI", b"1.2.840.10008.1.2.1");
    let mut f = vec![0u8; 128];
    f.extend_from_slice(b"DICM");
    element(
        &mut f,
        (0x0002, 0x0000),
        b"UL",
        &(group.len() as u32).to_le_bytes(),
    );
    f.extend_from_slice(&group);
    let us = |v: u16| v.to_le_bytes().to_vec();
    element(
        &mut f,
        (0x0008, 0x0018),
        b"UI",
        format!("1.2.3.4.{z}").as_bytes(),
    );
    element(&mut f, (0x0008, 0x0060), b"CS", b"CT");
    element(&mut f, (0x0020, 0x000E), b"UI", b"1.2.3.99");
    if frames == 1 {
        // A multi-frame file without per-frame positions is stacked in frame order.
        element(
            &mut f,
            (0x0020, 0x0032),
            b"DS",
            format!("0\\0\\{z}").as_bytes(),
        );
        element(&mut f, (0x0020, 0x0037), b"DS", b"1\\0\\0\\0\\1\\0");
    }
    element(&mut f, (0x0028, 0x0002), b"US", &us(1));
    element(&mut f, (0x0028, 0x0004), b"CS", b"MONOCHROME2");
    if frames > 1 {
        element(
            &mut f,
            (0x0028, 0x0008),
            b"IS",
            frames.to_string().as_bytes(),
        );
    }
    element(&mut f, (0x0028, 0x0010), b"US", &us(DIMS[1] as u16));
    element(&mut f, (0x0028, 0x0011), b"US", &us(DIMS[0] as u16));
    element(&mut f, (0x0028, 0x0030), b"DS", b"1\\1");
    element(&mut f, (0x0028, 0x0100), b"US", &us(16));
    element(&mut f, (0x0028, 0x0101), b"US", &us(16));
    element(&mut f, (0x0028, 0x0102), b"US", &us(15));
    element(&mut f, (0x0028, 0x0103), b"US", &us(1));
    let n = DIMS[0] * DIMS[1] * frames;
    let pixels: Vec<u8> = (0..n)
        .flat_map(|i| (value(first + i) as i16).to_le_bytes())
        .collect();
    element(&mut f, (0x7FE0, 0x0010), b"OW", &pixels);
    f
}

#[test]
fn a_dicom_series_read_from_files_peaks_within_one_and_a_half_times_the_voxels() {
    let dir = temp_dir("dicom");
    let slice = DIMS[0] * DIMS[1];
    for z in 0..DIMS[2] {
        std::fs::write(dir.join(format!("s{z:03}.dcm")), dicom(z, 1, z * slice)).expect("write");
    }
    let (r, peak) = peak_during(|| {
        let (inputs, _) = shapecast::files::read_all(std::slice::from_ref(&dir)).expect("lists");
        io::load(&inputs)
    });
    let v = r.unwrap_or_else(|e| panic!("{e}")).volume;
    check_values("DICOM series", &v, "i16");
    let voxel_bytes = v.voxels.byte_len();
    check_disk_peak(
        &format!("DICOM series of {} files from disk", DIMS[2]),
        peak,
        voxel_bytes,
    );

    // The same files in memory: the load adds the voxels and a slice or two to the input.
    let inputs: Vec<InputFile> = (0..DIMS[2])
        .map(|z| InputFile::new(format!("s{z:03}.dcm"), dicom(z, 1, z * slice)))
        .collect();
    let (r, peak) = peak_during(|| io::load(&inputs));
    assert_eq!(r.expect("loads").volume.voxels, v.voxels);
    check_memory_peak("DICOM series", peak, voxel_bytes);
    std::fs::remove_dir_all(&dir).expect("clean up");
}

/// Prints a load's peak from disk and checks that it is within 1.5x the voxel bytes (+ a
/// constant).
fn check_disk_peak(label: &str, peak: usize, voxel_bytes: usize) {
    eprintln!(
        "{label}: peak {peak} bytes for {voxel_bytes} voxel bytes ({:.3}x)",
        peak as f64 / voxel_bytes as f64
    );
    assert!(
        peak <= voxel_bytes * 3 / 2 + SLACK,
        "{label}: peak {peak} bytes"
    );
}

/// Prints what a load from memory adds to its input and checks that it is at most the voxel
/// bytes (+ a constant).
fn check_memory_peak(label: &str, peak: usize, voxel_bytes: usize) {
    eprintln!("{label} in memory: input + {peak} bytes");
    assert!(
        peak <= voxel_bytes + SLACK,
        "{label} in memory: input + {peak} bytes"
    );
}

/// A zipped DICOM series (deflated, as a PACS export or a web server hands it out): the archive
/// is read where it lies and its entries inflated one at a time as the loader reads them, so the
/// peak is the voxels and a slice or two, not every slice as well (the entries were unpacked
/// whole before: about 2x). From disk (on demand) and from memory (the browser: the archive is
/// JavaScript's, the wasm side adds only this).
#[test]
fn a_zipped_dicom_series_peaks_within_one_and_a_half_times_the_voxels() {
    let slice = DIMS[0] * DIMS[1];
    let zip = {
        let mut w = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
        let options = zip::write::SimpleFileOptions::default()
            .compression_method(zip::CompressionMethod::Deflated);
        for z in 0..DIMS[2] {
            w.start_file(format!("study/series/s{z:03}.dcm"), options)
                .expect("entry");
            w.write_all(&dicom(z, 1, z * slice)).expect("write");
        }
        w.finish().expect("zip").into_inner()
    };
    let dir = temp_dir("zip");
    std::fs::write(dir.join("series.zip"), &zip).expect("write");
    let limits = io::Limits::default();
    let load = |inputs: Vec<InputFile>| {
        let (files, _) = io::zip::expand(inputs, &limits)?;
        io::load(&files)
    };
    let (r, peak) = peak_during(|| {
        let (inputs, _) = shapecast::files::read_all(std::slice::from_ref(&dir.join("series.zip")))
            .expect("lists");
        load(inputs)
    });
    let v = r.unwrap_or_else(|e| panic!("{e}")).volume;
    check_values("zipped DICOM series", &v, "i16");
    let voxel_bytes = v.voxels.byte_len();
    check_disk_peak(
        &format!("zipped DICOM series of {} files from disk", DIMS[2]),
        peak,
        voxel_bytes,
    );

    let input = InputFile::new("series.zip", zip);
    let (r, peak) = peak_during(|| load(vec![input]));
    assert_eq!(r.expect("loads").volume.voxels, v.voxels);
    check_memory_peak("zipped DICOM series", peak, voxel_bytes);
    std::fs::remove_dir_all(&dir).expect("clean up");
}

/// The browser's folders: each file is read whole (here: made) and handed to a
/// `FolderReader`, which decodes it at once and drops it, so the peak is the voxels and a
/// file, not all the files and the voxels (what reading them all first, then loading, costs).
#[test]
fn a_dicom_folder_read_file_by_file_peaks_within_one_and_a_half_times_the_voxels() {
    let slice = DIMS[0] * DIMS[1];
    let limits = io::Limits::default();
    let (r, peak) = peak_during(|| {
        let mut reader = io::FolderReader::new(limits);
        reader.expect_files(DIMS[2]);
        for z in 0..DIMS[2] {
            reader.push(InputFile::new(
                format!("s{z:03}.dcm"),
                dicom(z, 1, z * slice),
            ))?;
        }
        reader.finish()
    });
    let v = match r.unwrap_or_else(|e| panic!("{e}")) {
        io::FolderRead::Loaded(l) => l.volume,
        io::FolderRead::List(list) => panic!("one series listed as {:?}", list.entries()),
    };
    check_values("DICOM folder read file by file", &v, "i16");
    let voxel_bytes = v.voxels.byte_len();
    let files_bytes: usize = (0..DIMS[2]).map(|z| dicom(z, 1, z * slice).len()).sum();
    eprintln!(
        "DICOM folder read file by file: peak {peak} bytes for {voxel_bytes} voxel bytes ({:.3}x; the files are {files_bytes} bytes)",
        peak as f64 / voxel_bytes as f64
    );
    assert!(peak <= voxel_bytes * 3 / 2 + SLACK, "peak {peak} bytes");
    assert!(peak < voxel_bytes + files_bytes / 2, "peak {peak} bytes");
}

#[test]
fn a_multi_frame_dicom_peaks_within_one_and_a_half_times_the_voxels() {
    // One file of DIMS[2] frames: its native samples are read where they lie in the file, a
    // frame at a time (no parsed copy of the pixel data).
    let dir = temp_dir("multiframe");
    let path = dir.join("frames.dcm");
    std::fs::write(&path, dicom(0, DIMS[2], 0)).expect("write");
    let (r, peak) = peak_during(|| {
        let (inputs, _) = shapecast::files::read_all(std::slice::from_ref(&path)).expect("lists");
        io::load(&inputs)
    });
    let v = r.unwrap_or_else(|e| panic!("{e}")).volume;
    check_values("multi-frame DICOM", &v, "i16");
    let voxel_bytes = v.voxels.byte_len();
    check_disk_peak("multi-frame DICOM from disk", peak, voxel_bytes);
    let inputs = [InputFile::new("frames.dcm", dicom(0, DIMS[2], 0))];
    let (r, peak) = peak_during(|| io::load(&inputs));
    assert_eq!(r.expect("loads").volume.voxels, v.voxels);
    check_memory_peak("multi-frame DICOM", peak, voxel_bytes);
    std::fs::remove_dir_all(&dir).expect("clean up");
}

/// A file read on demand from chunks (as the browser holds a file's bytes) that records, at
/// every read, where it read and how many bytes were still held.
#[derive(Debug)]
struct Watched {
    chunks: std::sync::Arc<io::Chunked<Vec<u8>>>,
    /// (offset read, bytes not yet let go) of every read.
    reads: std::sync::Mutex<Vec<(u64, u64)>>,
}

impl Watched {
    fn new(bytes: &[u8]) -> std::sync::Arc<Self> {
        let mut c = io::Chunked::default();
        bytes.chunks(100_003).for_each(|p| c.push(p.to_vec()));
        std::sync::Arc::new(Self {
            chunks: std::sync::Arc::new(c),
            reads: std::sync::Mutex::new(Vec::new()),
        })
    }

    fn held(&self) -> u64 {
        self.chunks.len() - self.chunks.released()
    }

    /// The bytes still held at the last read (the last frame's).
    fn held_at_last_read(&self) -> u64 {
        let reads = self.reads.lock().expect("not poisoned");
        reads.last().map_or(u64::MAX, |r| r.1)
    }
}

impl io::FileSource for Watched {
    fn len(&self) -> u64 {
        self.chunks.len()
    }

    fn read_exact_at(&self, offset: u64, buf: &mut [u8]) -> std::io::Result<()> {
        let held = self.held();
        self.reads
            .lock()
            .expect("not poisoned")
            .push((offset, held));
        self.chunks.read_exact_at(offset, buf)
    }

    fn release_before(&self, offset: u64) {
        self.chunks.release_before(offset);
    }
}

/// The browser's single multi-frame file: its bytes are JavaScript's, read on demand, and the
/// load is their last read, so they are let go frame by frame as the voxels fill (before, the
/// whole file was held beside the voxels: 2x). A series list kept for choosing again keeps them.
#[test]
fn a_multi_frame_dicom_read_on_demand_lets_its_frames_go_as_they_are_decoded() {
    let bytes = dicom(0, DIMS[2], 0);
    let frame_bytes = (DIMS[0] * DIMS[1] * 2) as u64;
    let expected = io::load(&[InputFile::new("frames.dcm", bytes.clone())])
        .expect("loads from memory")
        .volume;

    let watched = Watched::new(&bytes);
    let file = InputFile::on_demand("frames.dcm", watched.clone()).expect("reads the head");
    let loaded = io::load(&[file]).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(loaded.volume, expected);
    assert_eq!(watched.held(), 0, "the whole file is let go");
    let held = watched.held_at_last_read();
    eprintln!(
        "multi-frame DICOM on demand: {held} of {} bytes held at the last frame's read",
        bytes.len()
    );
    assert!(
        held <= 2 * frame_bytes + 2 * 100_003,
        "{held} bytes held at the last frame's read (a frame is {frame_bytes})"
    );

    // Listed and loaded for a series set (another entry may be chosen later): nothing let go.
    let watched = Watched::new(&bytes);
    let files = [InputFile::on_demand("frames.dcm", watched.clone()).expect("reads the head")];
    let limits = io::Limits::default();
    let list = io::list_series(&files, &limits)
        .expect("lists")
        .expect("a DICOM list");
    let first = list.load(&files, 0, &limits).expect("loads");
    assert_eq!(watched.held(), bytes.len() as u64, "kept for another load");
    let again = list.load_last(&files, 0, &limits).expect("loads again");
    assert_eq!(first.volume, again.volume);
    assert_eq!(again.volume, expected);
    assert_eq!(watched.held(), 0, "the last load lets the file go");
}

/// PackBits (as RLE Lossless uses it): runs of 2 or more equal bytes as repeats, the rest as
/// literals of at most 128 bytes.
fn pack_bits(data: &[u8], out: &mut Vec<u8>) {
    let mut i = 0;
    while i < data.len() {
        let mut run = 1;
        while i + run < data.len() && run < 128 && data[i + run] == data[i] {
            run += 1;
        }
        if run >= 2 {
            out.push((1i16 - run as i16) as i8 as u8);
            out.push(data[i]);
            i += run;
        } else {
            let start = i;
            while i < data.len()
                && i - start < 128
                && !(i + 1 < data.len() && data[i + 1] == data[i])
            {
                i += 1;
            }
            let n = (i - start).max(1);
            i = start + n;
            out.push((n - 1) as u8);
            out.extend_from_slice(&data[start..start + n]);
        }
    }
}

/// [`dicom`] of `frames` frames re-encoded as RLE Lossless: one fragment per frame (an empty
/// Basic Offset Table), two segments each (high bytes, then low bytes).
fn dicom_rle(frames: usize) -> Vec<u8> {
    dicom_rle_with(frames, false)
}

/// [`dicom_rle`], with `noise` pixels that hardly compress (the file is about the voxels' size).
fn dicom_rle_with(frames: usize, noise: bool) -> Vec<u8> {
    let mut f = dicom(0, frames, 0);
    let at = f
        .windows(4)
        .rposition(|w| w == [0xE0, 0x7F, 0x10, 0x00])
        .expect("PixelData");
    let mut pixels = f.split_off(at)[12..].to_vec();
    if noise {
        let mut x = 0x9E37_79B9_7F4A_7C15u64;
        for b in &mut pixels {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            *b = (x >> 32) as u8;
        }
    }
    let ts = b"1.2.840.10008.1.2.1\0";
    let p = f.windows(ts.len()).position(|w| w == ts).expect("syntax");
    f[p..p + ts.len()].copy_from_slice(b"1.2.840.10008.1.2.5\0");
    f.extend_from_slice(&[
        0xE0, 0x7F, 0x10, 0x00, b'O', b'B', 0, 0, 0xFF, 0xFF, 0xFF, 0xFF,
    ]);
    let item = |out: &mut Vec<u8>, len: usize| {
        out.extend_from_slice(&[0xFE, 0xFF, 0x00, 0xE0]);
        out.extend_from_slice(&(len as u32).to_le_bytes());
    };
    item(&mut f, 0);
    let frame_bytes = DIMS[0] * DIMS[1] * 2;
    for frame in pixels.chunks_exact(frame_bytes) {
        let (mut high, mut low) = (Vec::new(), Vec::new());
        pack_bits(
            &frame.iter().skip(1).step_by(2).copied().collect::<Vec<_>>(),
            &mut high,
        );
        pack_bits(
            &frame.iter().step_by(2).copied().collect::<Vec<_>>(),
            &mut low,
        );
        let mut frag = vec![0u8; 64];
        frag[0..4].copy_from_slice(&2u32.to_le_bytes());
        frag[4..8].copy_from_slice(&64u32.to_le_bytes());
        frag[8..12].copy_from_slice(&(64 + high.len() as u32).to_le_bytes());
        frag.extend_from_slice(&high);
        frag.extend_from_slice(&low);
        if frag.len() % 2 == 1 {
            frag.push(0);
        }
        item(&mut f, frag.len());
        f.extend_from_slice(&frag);
    }
    f.extend_from_slice(&[0xFE, 0xFF, 0xDD, 0xE0, 0, 0, 0, 0]);
    f
}

#[test]
fn a_compressed_multi_frame_dicom_is_decoded_a_frame_at_a_time() {
    // One RLE file of DIMS[2] frames. Decoding every frame at once would hold the fragments,
    // all frames decoded and the voxels (~2.5x here); a frame at a time, the fragments, one
    // frame and the voxels.
    let rle = dicom_rle(DIMS[2]);
    let dir = temp_dir("rle");
    let path = dir.join("frames-rle.dcm");
    std::fs::write(&path, &rle).expect("write");
    let (r, peak) = peak_during(|| {
        let (inputs, _) = shapecast::files::read_all(std::slice::from_ref(&path)).expect("lists");
        io::load(&inputs)
    });
    let v = r.unwrap_or_else(|e| panic!("{e}")).volume;
    check_values("RLE multi-frame DICOM", &v, "i16");
    let voxel_bytes = v.voxels.byte_len();
    check_disk_peak(
        &format!("RLE multi-frame DICOM ({} bytes) from disk", rle.len()),
        peak,
        voxel_bytes,
    );
    // In memory: the parsed fragments, one frame and the voxels beside the input.
    let inputs = [InputFile::new("frames-rle.dcm", rle.clone())];
    let (r, peak) = peak_during(|| io::load(&inputs));
    assert_eq!(r.expect("loads").volume.voxels, v.voxels);
    eprintln!("RLE multi-frame DICOM in memory: input + {peak} bytes");
    assert!(
        peak <= voxel_bytes + rle.len() + SLACK,
        "input + {peak} bytes"
    );
    std::fs::remove_dir_all(&dir).expect("clean up");
}

/// Compressed frames that hardly compress, in one file read on demand: the fragments are read
/// from where they lie, a frame at a time, so the peak is the voxels and a frame, not the
/// parsed fragments (the file's size) beside the voxels (~2x here, before); and from chunks
/// (the browser's bytes) each frame's bytes are let go once decoded.
#[test]
fn an_incompressible_rle_multi_frame_dicom_is_read_a_frame_at_a_time_from_the_file() {
    let rle = dicom_rle_with(DIMS[2], true);
    let voxel_bytes = N * 2;
    assert!(rle.len() > voxel_bytes * 9 / 10, "{} bytes", rle.len());
    let expected = io::load(&[InputFile::new("noise-rle.dcm", rle.clone())])
        .expect("loads from memory")
        .volume;

    let dir = temp_dir("rle-noise");
    let path = dir.join("noise-rle.dcm");
    std::fs::write(&path, &rle).expect("write");
    let (r, peak) = peak_during(|| {
        let (inputs, _) = shapecast::files::read_all(std::slice::from_ref(&path)).expect("lists");
        io::load(&inputs)
    });
    let from_disk = r.unwrap_or_else(|e| panic!("{e}")).volume;
    assert!(
        from_disk.voxels == expected.voxels,
        "the same voxels from disk"
    );
    check_disk_peak(
        &format!(
            "incompressible RLE multi-frame DICOM ({} bytes) from disk",
            rle.len()
        ),
        peak,
        voxel_bytes,
    );
    std::fs::remove_dir_all(&dir).expect("clean up");

    let watched = Watched::new(&rle);
    let file = InputFile::on_demand("noise-rle.dcm", watched.clone()).expect("reads the head");
    let loaded = io::load(&[file]).unwrap_or_else(|e| panic!("{e}"));
    assert!(loaded.volume == expected, "the same volume from chunks");
    assert_eq!(watched.held(), 0, "the whole file is let go");
    let frame_bytes = (DIMS[0] * DIMS[1] * 2) as u64;
    let held = watched.held_at_last_read();
    assert!(
        held <= 3 * frame_bytes + 2 * 100_003,
        "{held} bytes held at the last frame's read"
    );
}

/// `dicom(..)` with its data set deflated (Deflated Explicit VR Little Endian): the transfer
/// syntax in the meta group changed (and the group's length), the rest raw-deflated.
fn deflated_data_set(plain: &[u8]) -> Vec<u8> {
    let old: &[u8] = b"\x10\x00UI\x14\x001.2.840.10008.1.2.1\0";
    let at = plain
        .windows(old.len())
        .position(|w| w == old)
        .expect("the transfer syntax");
    let group_len = u32::from_le_bytes([plain[140], plain[141], plain[142], plain[143]]) as usize;
    let data_start = 144 + group_len;
    let mut f = plain[..data_start].to_vec();
    f.splice(
        at..at + old.len(),
        b"\x10\x00UI\x16\x001.2.840.10008.1.2.1.99".iter().copied(),
    );
    f[140..144].copy_from_slice(&((group_len + 2) as u32).to_le_bytes());
    let mut enc = flate2::write::DeflateEncoder::new(f, flate2::Compression::fast());
    enc.write_all(&plain[data_start..]).expect("deflate");
    enc.finish().expect("deflate")
}

/// A deflated data set read on demand: its frames are inflated as they are read, so the peak
/// is the voxels and a window, not the inflated data set beside the voxels (dicom-rs inflates
/// it whole: about 2x, and that is still the path for one in memory).
#[test]
fn a_deflated_multi_frame_dicom_is_inflated_a_frame_at_a_time_from_the_file() {
    let deflated = deflated_data_set(&dicom(0, DIMS[2], 0));
    let expected = io::load(&[InputFile::new("deflated.dcm", deflated.clone())])
        .expect("loads from memory")
        .volume;
    check_values("deflated multi-frame DICOM", &expected, "i16");
    let voxel_bytes = expected.voxels.byte_len();
    let dir = temp_dir("deflated");
    let path = dir.join("deflated.dcm");
    std::fs::write(&path, &deflated).expect("write");
    let (r, peak) = peak_during(|| {
        let (inputs, _) = shapecast::files::read_all(std::slice::from_ref(&path)).expect("lists");
        io::load(&inputs)
    });
    let v = r.unwrap_or_else(|e| panic!("{e}")).volume;
    assert!(v.voxels == expected.voxels, "the same voxels from disk");
    check_disk_peak(
        &format!(
            "deflated multi-frame DICOM ({} bytes) from disk",
            deflated.len()
        ),
        peak,
        voxel_bytes,
    );
    std::fs::remove_dir_all(&dir).expect("clean up");
    // A stream cut short is refused by name, on demand as in memory.
    let cut = deflated[..deflated.len() / 2].to_vec();
    let f = InputFile::on_demand("cut.dcm", std::sync::Arc::new(io::MemorySource(cut)))
        .expect("reads the head");
    let e = io::load(&[f]).expect_err("cut short").to_string();
    assert!(e.contains("cut.dcm"), "{e}");
}

#[test]
fn ascii_numbers_cut_by_a_read_chunk_are_read_whole() {
    // The text is read in 1 MiB chunks: numbers straddling each chunk's end, and the last one
    // without a separator after it.
    let mut text = Vec::new();
    let mut expect = Vec::new();
    let mut k = 0u32;
    while text.len() < 3 << 20 {
        let v = 1000.0 + f64::from(k) * 0.25;
        text.extend_from_slice(format!("{v} ").as_bytes());
        expect.push(v as f32);
        k += 1;
    }
    text.pop();
    let header = format!(
        "NRRD0004\ntype: double\ndimension: 1\nsizes: {}\nencoding: ascii\n\n",
        expect.len()
    );
    for on_demand in [false, true] {
        let bytes = cat(header.clone().into_bytes(), &text);
        let f = if on_demand {
            InputFile::on_demand("t.nrrd", std::sync::Arc::new(io::MemorySource(bytes)))
                .expect("head")
        } else {
            InputFile::new("t.nrrd", bytes)
        };
        let v = io::load(&[f]).expect("loads").volume;
        assert_eq!(
            v.voxels,
            Voxels::F32(expect.clone()),
            "on demand: {on_demand}"
        );
    }
    // One number short: refused by name.
    let cut = text.iter().rposition(|&c| c == b' ').expect("a space");
    let f = InputFile::new("short.nrrd", cat(header.into_bytes(), &text[..cut]));
    let m = io::load(&[f]).expect_err("short").to_string();
    assert!(m.contains("short.nrrd") && m.contains("truncated"), "{m}");
}

#[test]
fn an_incompressible_gzip_file_is_inflated_from_the_file_not_from_memory() {
    // Noise compresses to about its own size: holding the compressed bytes would cost ~2x.
    let mut x = 0x2545_F491_4F6C_DD1Du64;
    let noise: Vec<u8> = (0..N * 2)
        .map(|_| {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x >> 24) as u8
        })
        .collect();
    let gz = gzip(&cat(nifti_header(4, 16, false), &noise));
    assert!(gz.len() > N * 2, "{} compressed bytes", gz.len());
    let f = InputFile::on_demand("noise.nii.gz", std::sync::Arc::new(io::MemorySource(gz)))
        .expect("head");
    let (r, peak) = peak_during(|| io::load(std::slice::from_ref(&f)));
    let v = r.expect("loads").volume;
    let voxel_bytes = v.voxels.byte_len();
    assert_eq!(
        v.voxels.raw_f32(1),
        f32::from(i16::from_le_bytes([noise[2], noise[3]]))
    );
    eprintln!("noise .nii.gz on demand: peak {peak} bytes for {voxel_bytes} voxel bytes");
    assert!(peak <= voxel_bytes + SLACK, "peak {peak} bytes");
}

/// [`dicom`] re-encoded as implicit VR little endian (no VR in the data set).
fn implicit(explicit: &[u8]) -> Vec<u8> {
    // The meta group (explicit, always) ends where its group length says.
    let group_len =
        u32::from_le_bytes([explicit[140], explicit[141], explicit[142], explicit[143]]);
    let meta_end = 144 + group_len as usize;
    let mut out = explicit[..meta_end].to_vec();
    let ts = b"1.2.840.10008.1.2.1\0";
    let at = out
        .windows(ts.len())
        .position(|w| w == ts)
        .expect("transfer syntax");
    // "1.2.840.10008.1.2" padded to the same 20 bytes.
    out[at..at + 20].copy_from_slice(b"1.2.840.10008.1.2\0\0\0");
    let mut p = meta_end;
    while p + 8 <= explicit.len() {
        let tag = &explicit[p..p + 4];
        let vr = &explicit[p + 4..p + 6];
        let (len, head) = if matches!(vr, b"OB" | b"OW" | b"SQ" | b"UN" | b"UT") {
            let l = &explicit[p + 8..p + 12];
            (u32::from_le_bytes([l[0], l[1], l[2], l[3]]) as usize, 12)
        } else {
            (
                usize::from(u16::from_le_bytes([explicit[p + 6], explicit[p + 7]])),
                8,
            )
        };
        out.extend_from_slice(tag);
        out.extend_from_slice(&(len as u32).to_le_bytes());
        out.extend_from_slice(&explicit[p + head..p + head + len]);
        p += head + len;
    }
    out
}

#[test]
fn implicit_little_endian_pixels_are_read_where_they_lie() {
    let slice = DIMS[0] * DIMS[1];
    let explicit: Vec<InputFile> = (0..DIMS[2])
        .map(|z| InputFile::new(format!("s{z:03}.dcm"), dicom(z, 1, z * slice)))
        .collect();
    let want = io::load(&explicit).expect("explicit loads").volume;
    let files: Vec<InputFile> = (0..DIMS[2])
        .map(|z| InputFile::new(format!("s{z:03}.dcm"), implicit(&dicom(z, 1, z * slice))))
        .collect();
    let (r, peak) = peak_during(|| io::load(&files));
    let v = r.unwrap_or_else(|e| panic!("{e}")).volume;
    assert_eq!(
        v,
        Volume {
            source: v.source.clone(),
            ..want.clone()
        }
    );
    assert!(
        peak <= v.voxels.byte_len() + SLACK,
        "in memory: input + {peak} bytes"
    );
    let on_demand: Vec<InputFile> = files
        .into_iter()
        .map(|f| {
            InputFile::on_demand(f.name, std::sync::Arc::new(io::MemorySource(f.bytes)))
                .expect("head")
        })
        .collect();
    let w = io::load(&on_demand).expect("on demand").volume;
    assert_eq!(w.voxels, want.voxels);
    // One multi-frame file: a parsed copy of its pixels would cost the voxels again.
    let f = [InputFile::new(
        "frames.dcm",
        implicit(&dicom(0, DIMS[2], 0)),
    )];
    let (r, peak) = peak_during(|| io::load(&f));
    let v = r.expect("multi-frame loads").volume;
    check_values("implicit multi-frame", &v, "i16");
    assert!(
        peak <= v.voxels.byte_len() + SLACK,
        "in memory: input + {peak} bytes"
    );
}

#[test]
fn a_gzip_header_longer_than_the_bytes_held_is_read_on_demand_too() {
    // A gzip FNAME of 10 KB: more than the head an on-demand file keeps (HEAD_BYTES).
    let nii = cat(nifti_header(2, 8, false), &samples("u8", false));
    let mut enc = flate2::GzBuilder::new()
        .filename(vec![b'n'; 10_000])
        .write(Vec::new(), flate2::Compression::fast());
    enc.write_all(&nii).expect("gzip");
    let gz = enc.finish().expect("gzip");
    let a = io::load(&[InputFile::new("long.nii.gz", gz.clone())]).expect("in memory");
    let f = InputFile::on_demand("long.nii.gz", std::sync::Arc::new(io::MemorySource(gz)))
        .expect("head");
    let b = io::load(&[f]).expect("on demand");
    assert_eq!(a.volume, b.volume);
    check_values("long gzip header", &b.volume, "u8");
}

#[test]
fn text_headers_longer_than_64_kib_are_read_whole_on_demand() {
    // A header line crossing 64 KiB (where an on-demand header is first parsed) and the field
    // after it must be read as in memory.
    let long = "x".repeat(70_000);
    let nrrd = cat(
        format!("NRRD0004\n# {long}\n").into_bytes(),
        &nrrd_header("short", "raw", "little", None)[9..],
    );
    let nrrd = cat(nrrd, &samples("i16", false));
    let mha = cat(
        format!("ObjectType = Image\nComment = {long}\n").into_bytes(),
        &mha_header("MET_SHORT", false, "LOCAL")[19..],
    );
    let mha = cat(mha, &samples("i16", false));
    for (name, bytes) in [("long.nrrd", nrrd), ("long.mha", mha)] {
        let a = io::load(&[InputFile::new(name, bytes.clone())]).expect("in memory");
        let f =
            InputFile::on_demand(name, std::sync::Arc::new(io::MemorySource(bytes))).expect("head");
        let b = io::load(&[f]).unwrap_or_else(|e| panic!("{name} on demand: {e}"));
        assert_eq!(a.volume, b.volume, "{name}");
        check_values(name, &b.volume, "i16");
    }
}

#[test]
fn one_large_frame_is_converted_in_pieces() {
    // One 4096 x 2048 frame: its samples go through the i64 scratch in pieces, not whole
    // (which would be 64 MiB beside 16 MiB of voxels).
    let (rows, cols) = (2048usize, 4096usize);
    let mut f = dicom(0, 1, 0);
    let at = f
        .windows(4)
        .rposition(|w| w == [0xE0, 0x7F, 0x10, 0x00])
        .expect("PixelData");
    f.truncate(at);
    for (tag, v) in [(0x0010u16, rows as u16), (0x0011, cols as u16)] {
        let p = f
            .windows(6)
            .position(|w| w == [0x28, 0x00, tag as u8, 0x00, b'U', b'S'])
            .expect("Rows/Columns");
        f[p + 8..p + 10].copy_from_slice(&v.to_le_bytes());
    }
    let pixels: Vec<u8> = (0..rows * cols)
        .flat_map(|i| ((i % 3000) as i16).to_le_bytes())
        .collect();
    f.extend_from_slice(&[0xE0, 0x7F, 0x10, 0x00, b'O', b'W', 0, 0]);
    f.extend_from_slice(&(pixels.len() as u32).to_le_bytes());
    f.extend_from_slice(&pixels);
    drop(pixels);
    let files = [InputFile::new("big-frame.dcm", f)];
    let (r, peak) = peak_during(|| io::load(&files));
    let v = r.expect("loads").volume;
    assert_eq!(v.dims, [cols, rows, 1]);
    assert_eq!(
        v.voxels.raw_f32(rows * cols - 1),
        ((rows * cols - 1) % 3000) as f32
    );
    let voxel_bytes = v.voxels.byte_len();
    eprintln!("one {cols} x {rows} frame: input + {peak} bytes for {voxel_bytes} voxel bytes");
    assert!(peak <= voxel_bytes + SLACK, "peak {peak} bytes");
}

#[test]
fn voxels_type_is_kept() {
    // The fast path reads stored bytes into the voxels as they are: a type mix-up would show.
    let f = InputFile::on_demand(
        "t.nii",
        std::sync::Arc::new(io::MemorySource(cat(
            nifti_header(512, 16, false),
            &samples("u16", false),
        ))),
    )
    .expect("head");
    let v = io::load(&[f]).expect("loads").volume;
    assert!(matches!(v.voxels, Voxels::U16(_)));
    check_values("nii u16", &v, "u16");
}

#[test]
fn the_viewers_load_of_a_large_volume_from_disk_peaks_within_one_and_a_half_times_the_voxels() {
    // The viewer's own path (`app::load::LoadJob` of a dropped or given path), a frame's step at
    // a time: its files are read on demand as the command line's are, so the file's bytes are
    // never held beside the voxels. 512 x 512 x 200 i16: 100 MiB of voxels.
    use shapecast::app::load::{LoadJob, LoadSource, LoadStep};
    let dims = [512usize, 512, 200];
    let mut nii = nifti_header(4, 16, false);
    for (i, d) in dims.iter().enumerate() {
        nii[42 + 2 * i..44 + 2 * i].copy_from_slice(&(*d as i16).to_le_bytes());
    }
    let n = dims.iter().product::<usize>();
    nii.reserve(n * 2);
    for i in 0..n {
        nii.extend_from_slice(&((i % 3001) as i16 - 1000).to_le_bytes());
    }
    let dir = temp_dir("viewer");
    let path = dir.join("large.nii");
    std::fs::write(&path, &nii).expect("write");
    drop(nii);
    let (outcome, peak) = peak_during(|| {
        let mut job = LoadJob::new(LoadSource::Paths(vec![path.clone()]));
        let mut steps = Vec::new();
        loop {
            match job.step() {
                LoadStep::Working { what, .. } => steps.push(what),
                LoadStep::Done(loaded) => return Ok((loaded, steps)),
                LoadStep::Failed(e) => return Err(e),
            }
        }
    });
    let (loaded, steps) = outcome.unwrap_or_else(|e| panic!("{e}"));
    let v = loaded.volume;
    assert_eq!(v.dims, dims);
    for i in [0, 1, 3000, 3001, n / 2, n - 1] {
        assert_eq!(
            v.voxels.raw_f32(i),
            ((i % 3001) as i16 - 1000) as f32,
            "voxel {i}"
        );
    }
    // The 100 MiB file was read over several steps (at most ~48 MB each), then decoded in one.
    let reading = steps.iter().filter(|s| s.starts_with("reading")).count();
    assert!(reading >= 3, "{steps:?}");
    let voxel_bytes = v.voxels.byte_len();
    eprintln!(
        "the viewer's load of a {voxel_bytes}-byte NIfTI from disk: peak {peak} bytes ({:.3}x), steps {steps:?}",
        peak as f64 / voxel_bytes as f64
    );
    assert!(peak <= voxel_bytes * 3 / 2 + SLACK, "peak {peak} bytes");
    std::fs::remove_dir_all(&dir).expect("clean up");
}

/// A file's bytes that count how many are read (the largest offset reached).
#[derive(Debug)]
struct CountedSource {
    bytes: Vec<u8>,
    reached: std::sync::atomic::AtomicU64,
}

impl io::FileSource for CountedSource {
    fn len(&self) -> u64 {
        self.bytes.len() as u64
    }

    fn read_exact_at(&self, offset: u64, buf: &mut [u8]) -> std::io::Result<()> {
        let end = offset as usize + buf.len();
        buf.copy_from_slice(self.bytes.get(offset as usize..end).ok_or_else(|| {
            std::io::Error::new(std::io::ErrorKind::UnexpectedEof, "past the end")
        })?);
        self.reached
            .fetch_max(end as u64, std::sync::atomic::Ordering::Relaxed);
        Ok(())
    }
}

/// Listing a DICOM series read on demand (from disk, a zip's entries, the browser's files)
/// reads each file's first 64 KiB, not the whole file, and lists what the whole files list;
/// implicit-VR files too. A header longer than that is read whole.
#[test]
fn listing_a_dicom_series_on_demand_reads_only_the_headers() {
    let slice = DIMS[0] * DIMS[1];
    for (label, make) in [
        ("explicit", (|b: Vec<u8>| b) as fn(Vec<u8>) -> Vec<u8>),
        ("implicit", |b: Vec<u8>| implicit(&b)),
    ] {
        let bytes: Vec<Vec<u8>> = (0..DIMS[2]).map(|z| make(dicom(z, 1, z * slice))).collect();
        let whole: Vec<InputFile> = bytes
            .iter()
            .enumerate()
            .map(|(z, b)| InputFile::new(format!("s{z:03}.dcm"), b.clone()))
            .collect();
        let sources: Vec<std::sync::Arc<CountedSource>> = bytes
            .into_iter()
            .map(|b| {
                std::sync::Arc::new(CountedSource {
                    bytes: b,
                    reached: Default::default(),
                })
            })
            .collect();
        let on_demand: Vec<InputFile> = sources
            .iter()
            .enumerate()
            .map(|(z, s)| InputFile::on_demand(format!("s{z:03}.dcm"), s.clone()).expect("head"))
            .collect();
        let limits = io::Limits::default();
        let want = io::list_series(&whole, &limits)
            .expect("lists")
            .expect("a series");
        let got = io::list_series(&on_demand, &limits)
            .expect("lists")
            .expect("a series");
        assert_eq!(format!("{want:?}"), format!("{got:?}"), "{label}");
        for s in &sources {
            let reached = s.reached.load(std::sync::atomic::Ordering::Relaxed);
            assert!(
                reached <= 64 << 10 && (s.bytes.len() as u64) > 2 * reached,
                "{label}: {reached} of {} bytes read to list the file",
                s.bytes.len()
            );
        }
        // The volume read from the same on-demand files is the one read from memory.
        let a = io::load(&whole).expect("loads").volume;
        let b = io::load(&on_demand).expect("loads").volume;
        assert_eq!(a.voxels, b.voxels, "{label}");
    }
    // A header longer than the prefix (a 100 kB private element before the pixels) still
    // lists and loads, read whole.
    let long = dicom_with_long_header(100_000);
    let f = InputFile::on_demand(
        "long.dcm",
        std::sync::Arc::new(CountedSource {
            bytes: long.clone(),
            reached: Default::default(),
        }),
    )
    .expect("head");
    let limits = io::Limits::default();
    let want = io::list_series(&[InputFile::new("long.dcm", long)], &limits).expect("lists");
    let got = io::list_series(&[f], &limits).expect("lists");
    assert_eq!(format!("{want:?}"), format!("{got:?}"));
}

/// [`dicom`] of one slice with a private element of `n` bytes before the series attributes.
fn dicom_with_long_header(n: usize) -> Vec<u8> {
    let mut f = dicom(0, 1, 0);
    let needle = [0x20, 0x00, 0x0E, 0x00, b'U', b'I'];
    let at = f
        .windows(needle.len())
        .position(|w| w == needle)
        .expect("SeriesInstanceUID");
    let mut private = Vec::new();
    element(&mut private, (0x0009, 0x1010), b"OB", &vec![7u8; n]);
    f.splice(at..at, private);
    f
}
