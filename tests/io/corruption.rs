//! Bad input never panics: every file of ../shared/data (and of tests/data) is truncated at many
//! points, bit-flipped, and has header fields set to extremes; each load must return Ok or Err.
//! Panics are caught per input and reported together with the mutation that caused them.
//! Bounded (a fixed, deterministic set of mutations and a 16 MiB voxel cap) so that the whole
//! file runs in well under a minute on two cores.

use crate::common;

use std::io::{Read, Write};
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::{Path, PathBuf};

use shapecast::io::{self, InputFile, Limits};

/// Small caps keep each attempt fast: a header claiming a big grid stops at the budget check.
const LIMITS: Limits = Limits {
    max_voxel_bytes: 16 << 20,
    max_decompressed_bytes: 64 << 20,
};

/// A deterministic xorshift generator (the test must be reproducible).
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
}

fn gunzip(bytes: &[u8]) -> Option<Vec<u8>> {
    let mut out = Vec::new();
    flate2::read::MultiGzDecoder::new(bytes)
        .take(64 << 20)
        .read_to_end(&mut out)
        .ok()?;
    Some(out)
}

fn gzip(bytes: &[u8]) -> Vec<u8> {
    let mut enc = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
    enc.write_all(bytes).expect("gzip to memory");
    enc.finish().expect("gzip to memory")
}

/// Header-field mutations of a decompressed file: binary NIfTI fields, numbers in a text
/// header, DICOM lengths and image-size attributes.
fn header_mutations(bytes: &[u8]) -> Vec<(String, Vec<u8>)> {
    let mut out = Vec::new();
    let put = |out: &mut Vec<(String, Vec<u8>)>, label: String, offset: usize, value: &[u8]| {
        if offset + value.len() <= bytes.len() {
            let mut b = bytes.to_vec();
            b[offset..offset + value.len()].copy_from_slice(value);
            out.push((label, b));
        }
    };
    let is_nifti1 = bytes.len() >= 348
        && (bytes[0..4] == 348i32.to_le_bytes() || bytes[0..4] == 348i32.to_be_bytes());
    if is_nifti1 {
        let i16s: [&[u8]; 4] = [&[0xff, 0x7f], &[0x00, 0x80], &[0xff, 0xff], &[0, 0]];
        let f32s = [f32::NAN, f32::INFINITY, -1.0, 1e30, 0.0];
        // dim[0..8], intent, datatype, bitpix, qform/sform codes.
        for off in (40..56).step_by(2).chain([68, 70, 72, 252, 254]) {
            for (n, v) in i16s.iter().enumerate() {
                put(
                    &mut out,
                    format!("i16 field at {off} = extreme {n}"),
                    off,
                    v,
                );
            }
        }
        // pixdim, vox_offset, scl_slope/inter, quatern, qoffset, srow.
        for off in (76..120).step_by(4).chain((256..328).step_by(4)) {
            for v in f32s {
                put(
                    &mut out,
                    format!("f32 field at {off} = {v}"),
                    off,
                    &v.to_le_bytes(),
                );
            }
        }
    }
    // Text headers (NRRD, MetaImage): each number of the header replaced by extremes.
    let text_end = if bytes.starts_with(b"NRRD") {
        bytes
            .windows(2)
            .position(|w| w == b"\n\n")
            .unwrap_or(bytes.len().min(4096))
    } else if bytes.starts_with(b"ObjectType") || bytes.starts_with(b"NDims") {
        bytes
            .windows(15)
            .position(|w| w == b"ElementDataFile")
            .unwrap_or(bytes.len().min(4096))
    } else {
        0
    };
    if text_end > 0 {
        let text = &bytes[..text_end.min(8192)];
        let mut tokens = Vec::new();
        let mut i = 0;
        while i < text.len() {
            if text[i].is_ascii_digit() {
                let start = i;
                while i < text.len()
                    && (text[i].is_ascii_digit()
                        || text[i] == b'.'
                        || text[i] == b'e'
                        || text[i] == b'-')
                {
                    i += 1;
                }
                tokens.push(start..i);
            } else {
                i += 1;
            }
        }
        for range in tokens.iter().take(40) {
            for replacement in ["0", "-1", "99999999999", "nan", "1e308", "4294967297"] {
                let mut b = bytes[..range.start].to_vec();
                b.extend_from_slice(replacement.as_bytes());
                b.extend_from_slice(&bytes[range.end..]);
                out.push((format!("number at {} = {replacement}", range.start), b));
            }
        }
    }
    // DICOM: attribute values and lengths of the image-size attributes and the pixel data.
    let is_dicom = bytes.len() > 132 && &bytes[128..132] == b"DICM";
    if is_dicom {
        let tags: [[u8; 4]; 9] = [
            [0x28, 0x00, 0x10, 0x00], // Rows
            [0x28, 0x00, 0x11, 0x00], // Columns
            [0x28, 0x00, 0x00, 0x01], // BitsAllocated
            [0x28, 0x00, 0x01, 0x01], // BitsStored
            [0x28, 0x00, 0x03, 0x01], // PixelRepresentation
            [0x28, 0x00, 0x02, 0x00], // SamplesPerPixel
            [0x28, 0x00, 0x08, 0x00], // NumberOfFrames
            [0xe0, 0x7f, 0x10, 0x00], // PixelData
            [0x20, 0x00, 0x32, 0x00], // ImagePositionPatient
        ];
        let scan = &bytes[..bytes.len().min(1 << 20)];
        let mut owned = Vec::new();
        for tag in tags {
            for (hit, at) in scan
                .windows(4)
                .enumerate()
                .filter(|(_, w)| *w == tag)
                .map(|(i, _)| i)
                .enumerate()
                .take(3)
            {
                for (label, off, value) in [
                    ("value16=0", at + 8, vec![0u8, 0]),
                    ("value16=ffff", at + 8, vec![0xff, 0xff]),
                    ("value16=1", at + 8, vec![1, 0]),
                    ("len16=ffff", at + 6, vec![0xff, 0xff]),
                    ("len16=0", at + 6, vec![0, 0]),
                    ("len32=ffffffff", at + 4, vec![0xff; 4]),
                    ("len32=7fffffff", at + 8, vec![0xff, 0xff, 0xff, 0x7f]),
                    ("value=digits", at + 8, b"99999999".to_vec()),
                ] {
                    owned.push((format!("tag {tag:02x?} #{hit} {label}"), off, value));
                }
            }
        }
        for (label, off, value) in owned {
            put(&mut out, label, off, &value);
        }
    }
    out
}

/// The mutated variants of one file.
fn mutations(bytes: &[u8], seed: u64) -> Vec<(String, Vec<u8>)> {
    let n = bytes.len();
    let mut out = Vec::new();
    let mut cuts = vec![
        0, 1, 2, 3, 4, 8, 16, 64, 127, 128, 131, 132, 200, 300, 347, 348, 351, 352, 400, 540, 544,
        1000, 2000,
    ];
    cuts.extend([
        n / 8,
        n / 4,
        n / 2,
        3 * n / 4,
        n.saturating_sub(100),
        n.saturating_sub(2),
        n.saturating_sub(1),
    ]);
    cuts.sort_unstable();
    cuts.dedup();
    for c in cuts.into_iter().filter(|&c| c < n) {
        out.push((format!("truncated to {c} bytes"), bytes[..c].to_vec()));
    }
    let mut rng = Rng(seed | 1);
    for f in 0..40 {
        // Most flips land in the header, where they change what the loader believes.
        let span = if f < 30 { n.min(2048) } else { n };
        if span == 0 {
            break;
        }
        let pos = rng.below(span);
        let bit = rng.below(8);
        let mut b = bytes.to_vec();
        b[pos] ^= 1 << bit;
        out.push((format!("bit {bit} of byte {pos} flipped"), b));
    }
    if bytes.starts_with(&[0x1f, 0x8b]) {
        // Field extremes inside the compressed stream: decompress, mutate the header, and
        // recompress as two gzip members (header, then the untouched rest compressed once),
        // which a gzip reader concatenates.
        if let Some(plain) = gunzip(bytes) {
            let head_len = plain.len().min(8192);
            let tail = gzip(&plain[head_len..]);
            for (label, b) in spread(header_mutations(&plain), MAX_HEADER_MUTATIONS) {
                let mut z = gzip(&b[..head_len.min(b.len())]);
                if b.len() >= head_len {
                    z.extend_from_slice(&tail);
                    // A text-header edit changes the length: keep the edited bytes past head_len.
                    if b.len() != plain.len() {
                        z = gzip(&b);
                    }
                }
                out.push((format!("gunzipped, {label}, regzipped"), z));
            }
        }
    } else {
        out.extend(spread(header_mutations(bytes), MAX_HEADER_MUTATIONS));
    }
    out
}

/// Header mutations per file: enough to reach every field, few enough to stay fast.
const MAX_HEADER_MUTATIONS: usize = 60;

/// At most `max` items, evenly spread over `v` (deterministic).
fn spread<T>(v: Vec<T>, max: usize) -> Vec<T> {
    let n = v.len();
    if n <= max {
        return v;
    }
    v.into_iter()
        .enumerate()
        .filter(|(i, _)| i * max / n != (i + 1) * max / n)
        .map(|(_, x)| x)
        .collect()
}

/// Where a file's checksummed compressed stream starts: a gzip file (.nii.gz, .raw.gz) from
/// its first byte, an NRRD with gzip encoding after its header, a MetaImage with
/// CompressedData after its ElementDataFile line. A bit flipped from there on must be refused
/// or change nothing (gzip's CRC-32, zlib's Adler-32), never load other voxels.
fn checksummed_from(bytes: &[u8]) -> Option<usize> {
    if bytes.starts_with(&[0x1f, 0x8b]) {
        return Some(0);
    }
    let head = &bytes[..bytes.len().min(1 << 16)];
    let text = String::from_utf8_lossy(head);
    if bytes.starts_with(b"NRRD") && text.contains("encoding: gzip") {
        return head.windows(2).position(|w| w == b"\n\n").map(|p| p + 2);
    }
    if text.contains("CompressedData = True") {
        let at = head.windows(15).position(|w| w == b"ElementDataFile")?;
        return head[at..]
            .iter()
            .position(|&b| b == b'\n')
            .map(|p| at + p + 1);
    }
    None
}

/// "bit B of byte P flipped" -> P.
fn flipped_byte(what: &str) -> Option<usize> {
    what.strip_suffix(" flipped")?
        .rsplit(' ')
        .next()?
        .parse()
        .ok()
}

/// Loads `files` with file `target` replaced by each mutation; returns the mutations that
/// panicked, and those that flipped a bit of a checksummed stream and still loaded voxels
/// other than the original's.
fn corrupt_and_load(label: &str, files: &[InputFile], target: usize, seed: u64) -> Vec<String> {
    let mut panics = Vec::new();
    let mut variants = mutations(&files[target].bytes, seed);
    if files[target].bytes.len() > 256 << 10 {
        // Each attempt on a big file inflates and decodes megabytes: fewer, spread variants.
        variants = spread(variants, 45);
    }
    let checksummed = checksummed_from(&files[target].bytes);
    let original = checksummed.and_then(|_| io::load_with(files, &LIMITS).ok());
    for (what, bytes) in variants {
        let mut set = files.to_vec();
        set[target].bytes = bytes;
        let result = catch_unwind(AssertUnwindSafe(|| io::load_with(&set, &LIMITS)));
        let Ok(result) = result else {
            panics.push(format!("{label} ({}): {what}", files[target].name));
            continue;
        };
        if let (Some(from), Some(orig), Some(at), Ok(loaded)) =
            (checksummed, &original, flipped_byte(&what), &result)
            && at >= from
            && (loaded.volume.dims != orig.volume.dims
                || loaded.volume.voxels != orig.volume.voxels)
        {
            panics.push(format!(
                "{label} ({}): {what} in the compressed stream loaded other voxels without an error",
                files[target].name
            ));
        }
    }
    panics
}

fn single(path: &Path) -> Vec<InputFile> {
    vec![common::input(path)]
}

#[test]
fn corrupted_shared_data_never_panics() {
    let Some(root) = common::shared_data("") else {
        return;
    };
    let mut sets: Vec<(String, Vec<InputFile>, usize)> = Vec::new();
    let mut paths: Vec<PathBuf> = Vec::new();
    for sub in ["formats", "ct"] {
        for e in std::fs::read_dir(root.join(sub)).expect("data dir") {
            paths.push(e.expect("entry").path());
        }
    }
    paths.sort();
    for p in &paths {
        let name = p
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        if name.ends_with(".txt") {
            continue;
        }
        sets.push((name, single(p), 0));
    }
    // Pairs: corrupt the header and the data file in turn.
    for (h, d) in [
        ("formats/ras.hdr", "formats/ras.img"),
        (
            "formats/multishell-DWI-451dir.nhdr",
            "formats/multishell-DWI-451dir.raw.gz",
        ),
    ] {
        let files = vec![common::input(&root.join(h)), common::input(&root.join(d))];
        sets.push((format!("{h} pair"), files.clone(), 0));
        sets.push((format!("{d} pair"), files, 1));
    }
    // One slice of each series, alone and within a small series.
    for series in [
        "ct-3slice-liver",
        "mr-prostate-adc-oblique",
        "ct-head-64px",
        "ct-chest-lung-kernel",
    ] {
        let mut files = common::inputs_in(&root.join("series").join(series));
        files.truncate(3);
        sets.push((format!("{series} slice"), vec![files[0].clone()], 0));
        sets.push((format!("{series} in series"), files, 1));
    }
    let started = std::time::Instant::now();
    let mut panics = Vec::new();
    for (seed, (label, files, target)) in sets.iter().enumerate() {
        let t = std::time::Instant::now();
        panics.extend(corrupt_and_load(label, files, *target, seed as u64 + 1));
        eprintln!("{label}: {:.2?}", t.elapsed());
    }
    eprintln!(
        "corrupted {} inputs in {:.1?}",
        sets.len(),
        started.elapsed()
    );
    assert!(
        panics.is_empty(),
        "{} corrupted inputs panicked:\n{}",
        panics.len(),
        panics.join("\n")
    );
}

#[test]
fn corrupted_bundled_data_never_panics() {
    let dir = common::test_data("");
    let mut panics = Vec::new();
    let mut count = 0;
    for (seed, f) in common::inputs_in(&dir).into_iter().enumerate() {
        if f.name.ends_with(".txt")
            || f.name.ends_with(".md")
            || f.name.contains("fuzz-regressions")
        {
            continue;
        }
        let name = f.name.clone();
        panics.extend(corrupt_and_load(&name, &[f], 0, seed as u64 + 100));
        count += 1;
    }
    assert!(count > 0, "no bundled test data in {}", dir.display());
    assert!(
        panics.is_empty(),
        "{} corrupted inputs panicked:\n{}",
        panics.len(),
        panics.join("\n")
    );
}

/// Inputs that once crashed a fuzz target (tests/data/fuzz-regressions/<format>/) load
/// without a panic.
#[test]
fn fuzz_regressions_do_not_panic() {
    let dir = common::test_data("fuzz-regressions");
    if !dir.exists() {
        return;
    }
    for f in common::inputs_in(&dir) {
        if f.name.ends_with(".md") {
            continue;
        }
        let name = f.name.clone();
        let r = catch_unwind(AssertUnwindSafe(|| {
            io::load_with(&[f], &LIMITS).map(|_| ())
        }));
        let Ok(result) = r else {
            panic!("{name} panicked");
        };
        // An input that once exhausted memory must now be refused before allocating.
        if name.contains("oom-") {
            let Err(e) = result else {
                panic!("{name} loaded");
            };
            // dicom-rs says "Could not read N value bytes" only after it has allocated and
            // zero-filled them; the length walk must refuse the file first.
            let message = e.to_string();
            assert!(
                !message.contains("value bytes"),
                "{name} was refused only after dicom-rs allocated: {message}"
            );
        }
    }
}
