//! Single-bit flips of every file of ../shared/data (issue 14): of its first 4 KiB and of its
//! compressed stream (and of its uncompressed voxel payload). No crash, no hang, no garbage.
//! The rule each load must follow depends on where the flipped bit lies:
//!
//! - checksummed compressed stream (gzip: .nii.gz, gzip NRRD, .raw.gz, all of it from its first
//!   byte; zlib: compressed MetaImage): the volume equals the original bit for bit, or the load
//!   is a typed error (the CRC-32 / Adler-32 covers every inflated byte). Adler-32 is weak: 4 of
//!   65,120 flips of mha.mha's stream decode, in zlib itself (flate2, Python's zlib), to other
//!   bytes with a matching Adler-32; where zlib accepts the flipped stream, the load must equal
//!   the volume its decoded bytes make (the same file stored uncompressed);
//! - uncompressed voxel payload (.img, native DICOM PixelData): the same volume (dims, geometry,
//!   rescale, type) with at most one voxel different (the one holding the flipped bit), or an
//!   error;
//! - compressed DICOM pixel data without a checksum (RLE, JPEG, JPEG 2000, JPEG-LS): the same
//!   dims, geometry and type (pixel values may change: the format cannot tell), or an error;
//! - metadata without a checksum (headers, DICOM attributes, a deflated DICOM data set): any
//!   consistent volume (voxel count = dims, finite positive spacing, finite geometry), since
//!   a header flip can change what the bytes mean, or an error;
//!
//! and always: no panic (caught per load), no load over `MAX_LOAD_S` (a watchdog aborts the
//! process, naming the case, after `HANG_S`), every error names one of the files given.
//!
//! In CI a seeded sample of flips per file and region runs (`SHAPECAST_BITFLIPS` flips per
//! region, 6 by default). `SHAPECAST_BITFLIPS=all` runs the whole sweep: every bit of the first
//! 4 KiB, and every bit of each compressed stream (streams over 64 KiB: every bit of 4,096
//! evenly spaced bytes and of the last 64 bytes, the trailer). `SHAPECAST_BITFLIP_ONLY=text`
//! keeps the sets whose label contains `text` (the whole sweep of everything takes days on two
//! cores; it is run by hand file by file).

use crate::common;

use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use shapecast::io::{self, InputFile, Loaded};
use shapecast::{Volume, Voxels};

/// A load slower than this fails the test (real loads here take well under a second).
const MAX_LOAD_S: f64 = 20.0;
/// A load this long is a hang: the watchdog aborts the process and names the case.
const HANG_S: u64 = 120;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Rule {
    /// Metadata without a checksum.
    Header,
    /// Uncompressed voxels.
    Payload,
    /// A stream whose checksum covers every byte.
    Checked,
    /// Compressed pixel data without a checksum.
    Unchecked,
}

/// A file's regions: (start, end, rule), covering the whole file.
type Regions = Vec<(usize, usize, Rule)>;

fn find(hay: &[u8], needle: &[u8]) -> Option<usize> {
    hay.windows(needle.len()).position(|w| w == needle)
}

/// The DICOM transfer syntax UID, read from the meta group.
fn transfer_syntax(b: &[u8]) -> Option<String> {
    let at = find(
        &b[..b.len().min(4096)],
        &[0x02, 0x00, 0x10, 0x00, b'U', b'I'],
    )?;
    let len = u16::from_le_bytes([*b.get(at + 6)?, *b.get(at + 7)?]) as usize;
    let v = b.get(at + 8..at + 8 + len)?;
    Some(
        String::from_utf8_lossy(v)
            .trim_end_matches(['\0', ' '])
            .to_owned(),
    )
}

/// Where a DICOM file's top-level PixelData value lies: (start, end, encapsulated).
fn pixel_data(b: &[u8], ts: &str) -> Option<(usize, usize, bool)> {
    let (tag, implicit) = match ts {
        "1.2.840.10008.1.2.2" => (vec![0x7F, 0xE0, 0x00, 0x10], false),
        "1.2.840.10008.1.2" => (vec![0xE0, 0x7F, 0x10, 0x00], true),
        _ => (vec![0xE0, 0x7F, 0x10, 0x00], false),
    };
    let mut from = 132;
    while let Some(p) = b.get(from..).and_then(|r| find(r, &tag)).map(|p| p + from) {
        from = p + 1;
        let (start, len) = if implicit {
            let l = b.get(p + 4..p + 8)?;
            (p + 8, u32::from_le_bytes([l[0], l[1], l[2], l[3]]))
        } else {
            let vr = b.get(p + 4..p + 6)?;
            if !matches!(vr, b"OB" | b"OW" | b"UN") {
                continue;
            }
            let l = b.get(p + 8..p + 12)?;
            let len = if ts == "1.2.840.10008.1.2.2" {
                u32::from_be_bytes([l[0], l[1], l[2], l[3]])
            } else {
                u32::from_le_bytes([l[0], l[1], l[2], l[3]])
            };
            (p + 12, len)
        };
        if len == u32::MAX {
            return Some((start, b.len(), true));
        }
        let end = start + len as usize;
        if end <= b.len() && b.len() - end < 4096 {
            return Some((start, end, false));
        }
    }
    None
}

fn regions(name: &str, b: &[u8]) -> Regions {
    let n = b.len();
    let lower = name.to_ascii_lowercase();
    if b.starts_with(&[0x1f, 0x8b]) {
        return vec![(0, n, Rule::Checked)];
    }
    if b.starts_with(b"NRRD000") {
        let end = find(b, b"\n\n").map_or(n, |p| p + 2);
        let gz = find(&b[..end], b"encoding: gzip").is_some();
        return vec![
            (0, end, Rule::Header),
            (end, n, if gz { Rule::Checked } else { Rule::Payload }),
        ];
    }
    if let Some(p) = find(b, b"ElementDataFile = LOCAL") {
        let end = b[p..]
            .iter()
            .position(|&c| c == b'\n')
            .map_or(n, |e| p + e + 1);
        let z = find(&b[..end], b"CompressedData = True").is_some();
        return vec![
            (0, end, Rule::Header),
            (end, n, if z { Rule::Checked } else { Rule::Payload }),
        ];
    }
    if lower.ends_with(".img") || lower.ends_with(".raw") {
        return vec![(0, n, Rule::Payload)];
    }
    if n >= 132 && &b[128..132] == b"DICM" {
        let ts = transfer_syntax(b).unwrap_or_default();
        if ts == "1.2.840.10008.1.2.1.99" {
            return vec![(0, n, Rule::Header)];
        }
        if let Some((s, e, encapsulated)) = pixel_data(b, &ts) {
            let rule = if encapsulated {
                Rule::Unchecked
            } else {
                Rule::Payload
            };
            return vec![(0, s, Rule::Header), (s, e, rule), (e, n, Rule::Header)];
        }
    }
    vec![(0, n, Rule::Header)]
}

fn rule_at(regions: &Regions, at: usize) -> Rule {
    regions
        .iter()
        .find(|(s, e, _)| (*s..*e).contains(&at))
        .map_or(Rule::Header, |r| r.2)
}

/// A deterministic xorshift generator.
struct Rng(u64);
impl Rng {
    fn below(&mut self, n: usize) -> usize {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 % n.max(1) as u64) as usize
    }
}

/// How many flips per region: `Some(k)` sampled, `None` the whole sweep.
fn budget() -> Option<usize> {
    match std::env::var("SHAPECAST_BITFLIPS") {
        Ok(v) if v == "all" => None,
        Ok(v) => Some(v.parse().unwrap_or(6)),
        Err(_) => Some(6),
    }
}

/// The (byte, bit) flips of one file: its first 4 KiB and its compressed stream (and its
/// uncompressed payload), sampled or whole.
fn flips(
    bytes: &[u8],
    regions: &Regions,
    seed: u64,
    per_region: Option<usize>,
) -> Vec<(usize, u8)> {
    let n = bytes.len();
    let head = 0..n.min(4096);
    let mut out = Vec::new();
    match per_region {
        Some(k) => {
            let mut rng = Rng(seed | 1);
            for _ in 0..k {
                out.push((rng.below(head.end), rng.below(8) as u8));
            }
            for (s, e, rule) in regions {
                if *rule != Rule::Header && e > s {
                    for _ in 0..k {
                        out.push((s + rng.below(e - s), rng.below(8) as u8));
                    }
                    // The last bytes of a stream are its trailer (CRC-32, ISIZE, Adler-32).
                    out.push((e - 1 - rng.below((e - s).min(8)), rng.below(8) as u8));
                }
            }
        }
        None => {
            let mut bytes_to_flip: Vec<usize> = head.collect();
            for (s, e, rule) in regions {
                if matches!(rule, Rule::Checked | Rule::Unchecked) {
                    if e - s <= 64 << 10 {
                        bytes_to_flip.extend(*s..*e);
                    } else {
                        bytes_to_flip.extend((0..4096).map(|i| s + i * (e - s) / 4096));
                        bytes_to_flip.extend(e - 64..*e);
                    }
                }
            }
            bytes_to_flip.sort_unstable();
            bytes_to_flip.dedup();
            for b in bytes_to_flip {
                out.extend((0..8).map(|bit| (b, bit)));
            }
        }
    }
    out
}

/// For a compressed MetaImage (zlib, whose Adler-32 is weak) that zlib decodes without an
/// error: the volume its decoded bytes make, stored uncompressed. `None` for anything else, or
/// when zlib refuses the stream.
fn adler_blind(file: &InputFile) -> Option<Volume> {
    use std::io::Read as _;
    let b = &file.bytes;
    let local = b"ElementDataFile = LOCAL\n";
    let start = find(b, local)? + local.len();
    let header = String::from_utf8_lossy(&b[..start]).into_owned();
    if !header.contains("CompressedData = True") {
        return None;
    }
    let mut decoded = Vec::new();
    flate2::read::ZlibDecoder::new(&b[start..])
        .take(1 << 30)
        .read_to_end(&mut decoded)
        .ok()?;
    let plain: String = header
        .lines()
        .filter(|l| !l.starts_with("CompressedDataSize"))
        .map(|l| {
            if l.starts_with("CompressedData") {
                "CompressedData = False\n".to_owned()
            } else {
                format!("{l}\n")
            }
        })
        .collect();
    let mut bytes = plain.into_bytes();
    bytes.extend_from_slice(&decoded);
    io::load(&[InputFile::new(file.name.clone(), bytes)])
        .ok()
        .map(|l| l.volume)
}

/// What a load came to, in a few words.
fn describe(r: &std::thread::Result<Result<Loaded, io::LoadError>>) -> String {
    match r {
        Err(_) => "a panic".to_owned(),
        Ok(Err(e)) => format!("the error {e}"),
        Ok(Ok(l)) => format!("a volume of {:?}", l.volume.dims),
    }
}

/// Two volumes the same, bit for bit (NaN voxels included).
fn identical(a: &Volume, b: &Volume) -> bool {
    let same_voxels = match (&a.voxels, &b.voxels) {
        (Voxels::F32(x), Voxels::F32(y)) => {
            x.len() == y.len() && x.iter().zip(y).all(|(p, q)| p.to_bits() == q.to_bits())
        }
        (x, y) => x == y,
    };
    same_voxels
        && a.dims == b.dims
        && a.spacing_mm == b.spacing_mm
        && a.origin_mm == b.origin_mm
        && a.direction == b.direction
        && a.value_slope.to_bits() == b.value_slope.to_bits()
        && a.value_intercept.to_bits() == b.value_intercept.to_bits()
        && a.modality == b.modality
        && a.warnings == b.warnings
}

fn same_grid(a: &Volume, b: &Volume) -> bool {
    a.dims == b.dims
        && a.spacing_mm == b.spacing_mm
        && a.origin_mm == b.origin_mm
        && a.direction == b.direction
        && a.voxels.type_name() == b.voxels.type_name()
}

fn consistent(v: &Volume) -> Result<(), String> {
    if v.voxels.len() != v.dims.iter().product::<usize>() {
        return Err(format!("{} voxels for dims {:?}", v.voxels.len(), v.dims));
    }
    if !v.spacing_mm.iter().all(|s| s.is_finite() && *s > 0.0) {
        return Err(format!("spacing {:?}", v.spacing_mm));
    }
    if !v.origin_mm.iter().all(|o| o.is_finite()) || !v.direction.is_finite() {
        return Err(format!(
            "origin {:?} direction {:?}",
            v.origin_mm, v.direction
        ));
    }
    Ok(())
}

/// Checks one flipped load against its rule; `Err` describes a violation.
fn check(
    rule: Rule,
    good: &Volume,
    got: &Result<Loaded, io::LoadError>,
    names: &[String],
) -> Result<(), String> {
    let v = match got {
        Err(e) => {
            let m = e.to_string();
            let named = names.iter().any(|n| m.contains(n.as_str())) || m.contains("DICOM series");
            return if named {
                Ok(())
            } else {
                Err(format!("the error names no file: {m}"))
            };
        }
        Ok(l) => &l.volume,
    };
    consistent(v)?;
    match rule {
        Rule::Header => Ok(()),
        Rule::Checked => {
            if identical(good, v) {
                Ok(())
            } else {
                Err("a flip in a checksummed stream loaded a different volume".to_owned())
            }
        }
        Rule::Unchecked => {
            if same_grid(good, v) {
                Ok(())
            } else {
                Err("a flip in compressed pixel data changed the grid or type".to_owned())
            }
        }
        Rule::Payload => {
            if !same_grid(good, v)
                || good.value_slope != v.value_slope
                || good.value_intercept != v.value_intercept
            {
                return Err("a flip in the voxel payload changed more than voxels".to_owned());
            }
            let differ = (0..v.voxels.len())
                .filter(|&i| good.voxels.raw_f32(i).to_bits() != v.voxels.raw_f32(i).to_bits())
                .count();
            if differ <= 1 {
                Ok(())
            } else {
                Err(format!(
                    "a flip in the voxel payload changed {differ} voxels"
                ))
            }
        }
    }
}

/// The watchdog's view of the load in progress: when it started (ms since `epoch`, 0 = none)
/// and what it is.
struct Watch {
    epoch: Instant,
    started_ms: AtomicU64,
    case: Mutex<String>,
}

fn watchdog() -> Arc<Watch> {
    let w = Arc::new(Watch {
        epoch: Instant::now(),
        started_ms: AtomicU64::new(0),
        case: Mutex::new(String::new()),
    });
    let seen = Arc::clone(&w);
    std::thread::spawn(move || {
        loop {
            std::thread::sleep(Duration::from_secs(1));
            let s = seen.started_ms.load(Ordering::Relaxed);
            let now = seen.epoch.elapsed().as_millis() as u64;
            if s > 0 && now.saturating_sub(s) > HANG_S * 1000 {
                let case = seen.case.lock().map(|c| c.clone()).unwrap_or_default();
                eprintln!("HANG: {case} has been loading for over {HANG_S} s");
                std::process::abort();
            }
        }
    });
    w
}

/// One set of files (a single file, a header with its data file, a series) and which of its
/// files get flipped.
struct Set {
    label: String,
    files: Vec<InputFile>,
    flipped: Vec<usize>,
}

fn sets() -> Option<Vec<Set>> {
    let root = common::shared_data("")?;
    let mut out = Vec::new();
    let read = |p: &Path| common::input(p);
    for dir in ["ct", "formats"] {
        let mut paths: Vec<PathBuf> = std::fs::read_dir(root.join(dir))
            .expect("lists ../shared/data")
            .filter_map(Result::ok)
            .map(|e| e.path())
            .filter(|p| !p.to_string_lossy().ends_with(".txt"))
            .collect();
        paths.sort();
        for p in &paths {
            let name = p
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default();
            // A data file is flipped with its header (below), not on its own.
            if name.ends_with(".img") || name.ends_with(".raw.gz") {
                continue;
            }
            let mut files = vec![read(p)];
            for companion in ["ras.img", "multishell-DWI-451dir.raw.gz"] {
                let stem = companion.split('.').next().unwrap_or_default();
                if name.starts_with(stem) {
                    files.push(read(&root.join(dir).join(companion)));
                }
            }
            let flipped = (0..files.len()).collect();
            out.push(Set {
                label: format!("{dir}/{name}"),
                files,
                flipped,
            });
        }
    }
    let mut series: Vec<PathBuf> = std::fs::read_dir(root.join("series"))
        .expect("lists ../shared/data/series")
        .filter_map(Result::ok)
        .map(|e| e.path())
        .filter(|p| p.is_dir())
        .collect();
    series.sort();
    for d in series {
        let files = common::inputs_in(&d);
        // The first, middle and last file of the series are flipped, one at a time.
        let n = files.len();
        let mut flipped = vec![0, n / 2, n.saturating_sub(1)];
        flipped.dedup();
        out.push(Set {
            label: format!(
                "series/{}",
                d.file_name()
                    .map(|n| n.to_string_lossy().into_owned())
                    .unwrap_or_default()
            ),
            files,
            flipped,
        });
    }
    Some(out)
}

#[test]
fn single_bit_flips_of_the_shared_files_are_refused_or_explained() {
    let Some(sets) = sets() else {
        return;
    };
    let per_region = budget();
    let watch = watchdog();
    let mut failures = Vec::new();
    let (mut loads, mut refused, mut identical_loads) = (0usize, 0usize, 0usize);
    let mut slowest = (0.0f64, String::new());
    let started = Instant::now();
    let only = std::env::var("SHAPECAST_BITFLIP_ONLY").unwrap_or_default();
    for (si, set) in sets.into_iter().enumerate() {
        if !set.label.contains(only.as_str()) {
            continue;
        }
        let names: Vec<String> = set.files.iter().map(|f| f.name.clone()).collect();
        // A file this build cannot load (JPEG-LS) is still flipped: each load must then be an
        // error naming it, or a consistent volume.
        let good = io::load(&set.files).ok().map(|l| l.volume);
        let mut files = set.files;
        for &fi in &set.flipped {
            let original = files[fi].bytes.clone();
            let regions = regions(&files[fi].name, &original);
            let seed = 0x9E37_79B9_7F4A_7C15u64 ^ ((si as u64) << 32) ^ fi as u64;
            for (byte, bit) in flips(&original, &regions, seed, per_region) {
                let rule = rule_at(&regions, byte);
                let case = format!(
                    "{} ({}): byte {byte} bit {bit} ({rule:?})",
                    set.label, files[fi].name
                );
                files[fi].bytes[byte] ^= 1 << bit;
                if let Ok(mut c) = watch.case.lock() {
                    c.clone_from(&case);
                }
                watch.started_ms.store(
                    watch.epoch.elapsed().as_millis().max(1) as u64,
                    Ordering::Relaxed,
                );
                let t = Instant::now();
                let got = catch_unwind(AssertUnwindSafe(|| io::load(&files)));
                let took = t.elapsed().as_secs_f64();
                // The same flipped files read on demand (disk, the browser's bytes: compressed
                // DICOM frames and raw payloads are then read where they lie) load the same.
                let on_demand: Vec<InputFile> = files
                    .iter()
                    .map(|f| {
                        InputFile::on_demand(
                            f.name.clone(),
                            Arc::new(io::MemorySource(f.bytes.clone())),
                        )
                        .expect("reads the head")
                    })
                    .collect();
                let got_on_demand = catch_unwind(AssertUnwindSafe(|| io::load(&on_demand)));
                watch.started_ms.store(0, Ordering::Relaxed);
                match (&got, &got_on_demand) {
                    (Ok(Ok(a)), Ok(Ok(b))) if identical(&a.volume, &b.volume) => {}
                    (Ok(Err(_)), Ok(Err(_))) => {}
                    (_, Err(_)) => failures.push(format!("{case}: panicked on demand")),
                    _ => failures.push(format!(
                        "{case}: on demand {} where in memory {}",
                        describe(&got_on_demand),
                        describe(&got)
                    )),
                }
                files[fi].bytes[byte] ^= 1 << bit;
                loads += 1;
                if took > slowest.0 {
                    slowest = (took, case.clone());
                }
                if took > MAX_LOAD_S {
                    failures.push(format!("{case}: took {took:.1} s"));
                }
                match got {
                    Err(_) => failures.push(format!("{case}: panicked")),
                    Ok(r) => {
                        match &r {
                            Err(_) => refused += 1,
                            Ok(l) if good.as_ref().is_some_and(|g| identical(g, &l.volume)) => {
                                identical_loads += 1
                            }
                            Ok(_) => {}
                        }
                        let verdict = match &good {
                            // zlib's Adler-32 misses some changes (zlib itself accepts the
                            // stream): the load must then be what the stream decodes to.
                            Some(g) if rule == Rule::Checked => match adler_blind(&files[fi]) {
                                Some(decoded) => check(rule, &decoded, &r, &names),
                                None => check(rule, g, &r, &names),
                            },
                            Some(g) => check(rule, g, &r, &names),
                            None => check(
                                Rule::Header,
                                &Volume::from_f32([1, 1, 1], [1.0; 3], vec![0.0]),
                                &r,
                                &names,
                            ),
                        };
                        if let Err(why) = verdict {
                            failures.push(format!("{case}: {why}"));
                        }
                    }
                }
            }
            assert_eq!(files[fi].bytes, original, "restored");
        }
    }
    eprintln!(
        "{loads} flipped loads in {:.1} s: {refused} refused, {identical_loads} identical, {} other (explained by their rule); slowest {:.2} s ({})",
        started.elapsed().as_secs_f64(),
        loads - refused - identical_loads,
        slowest.0,
        slowest.1
    );
    assert!(
        failures.is_empty(),
        "{} flips broke their rule:\n{}",
        failures.len(),
        failures.join("\n")
    );
}

#[test]
fn regions_are_found_in_the_shared_files() {
    // The rule map itself: a wrong map would check the wrong rule.
    let Some(root) = common::shared_data("formats") else {
        return;
    };
    let at = |name: &str| {
        let b = std::fs::read(root.join(name)).expect("reads");
        (regions(name, &b), b.len())
    };
    let (r, n) = at("liver.dcm");
    assert_eq!(
        r.iter().filter(|x| x.2 == Rule::Payload).count(),
        1,
        "{r:?}"
    );
    let p = r.iter().find(|x| x.2 == Rule::Payload).expect("payload");
    // A segmentation: one bit per voxel of the loaded frames.
    let v = io::load(&[common::input(&root.join("liver.dcm"))])
        .expect("loads")
        .volume;
    assert_eq!(p.1 - p.0, v.voxel_count() / 8, "{r:?} of {n}");
    let (r, _) = at("emri_small_big_endian.dcm");
    let p = r.iter().find(|x| x.2 == Rule::Payload).expect("payload");
    assert_eq!(p.1 - p.0, 64 * 64 * 10 * 2, "{r:?}");
    let (r, _) = at("liver_rle.dcm");
    assert!(r.iter().any(|x| x.2 == Rule::Unchecked), "{r:?}");
    let (r, n) = at("FLAIR.nrrd");
    assert!(
        r[1].2 == Rule::Checked && r[1].1 == n && r[0].1 > 100,
        "{r:?}"
    );
    let (r, _) = at("mha.mha");
    assert_eq!(r[1].2, Rule::Checked, "{r:?}");
    let (r, n) = at("shear.nii.gz");
    assert_eq!(r, vec![(0, n, Rule::Checked)]);
}

#[test]
fn flips_that_adler32_cannot_see_load_what_zlib_decodes() {
    // Found by the whole sweep: these flips of mha.mha's zlib stream decode (in zlib itself)
    // to other bytes whose Adler-32 matches. Nothing can refuse them; the load must be exactly
    // what the stream decodes to, never anything of the loader's own making.
    let Some(path) = common::shared_data("formats/mha.mha") else {
        return;
    };
    let mut f = common::input(&path);
    let good = io::load(std::slice::from_ref(&f)).expect("loads").volume;
    for (byte, bit) in [(34526, 5), (38147, 3), (131568, 5), (131673, 6)] {
        f.bytes[byte] ^= 1 << bit;
        let got = io::load(std::slice::from_ref(&f))
            .expect("zlib accepts it too")
            .volume;
        let decoded = adler_blind(&f).expect("zlib decodes it");
        assert!(
            !identical(&good, &got),
            "byte {byte} bit {bit}: no change to explain"
        );
        assert!(identical(&decoded, &got), "byte {byte} bit {bit}");
        f.bytes[byte] ^= 1 << bit;
    }
}
