//! The loaders compiled on their own for fuzzing: src/io depends only on src/volume (and never
//! on wgpu or egui), so the fuzz build includes just those two files and skips the GPU stack.

#[path = "../../src/volume.rs"]
pub mod volume;

#[path = "../../src/io/mod.rs"]
pub mod io;

use io::{InputFile, Limits};

/// Caps small enough that libFuzzer's 2 GB RSS limit is never reached by a legal allocation.
pub const LIMITS: Limits = Limits {
    max_voxel_bytes: 64 << 20,
    max_decompressed_bytes: 128 << 20,
};

/// Loads the files twice, from memory and read on demand (`InputFile::on_demand`, the native
/// command line's path): a panic is a bug, and so is a difference between the two (both must
/// load the same volume, or both refuse).
fn load_both(files: &[(&str, &[u8])]) {
    let in_memory: Vec<InputFile> = files
        .iter()
        .map(|(n, b)| InputFile::new(*n, b.to_vec()))
        .collect();
    let a = io::load_with(&in_memory, &LIMITS);
    drop(in_memory);
    let on_demand: Vec<InputFile> = files
        .iter()
        .filter_map(|(n, b)| {
            InputFile::on_demand(*n, std::sync::Arc::new(io::MemorySource(b.to_vec()))).ok()
        })
        .collect();
    let b = io::load_with(&on_demand, &LIMITS);
    match (&a, &b) {
        (Ok(x), Ok(y)) => assert!(
            same(&x.volume, &y.volume),
            "in memory and on demand loaded different volumes"
        ),
        (Err(_), Err(_)) => {}
        _ => panic!("in memory: {:?}; on demand: {:?}", a.as_ref().err(), b.as_ref().err()),
    }
}

/// Two volumes the same bit for bit (a NaN voxel equals a NaN voxel of the same bits).
fn same(a: &volume::Volume, b: &volume::Volume) -> bool {
    use volume::Voxels;
    let voxels = match (&a.voxels, &b.voxels) {
        (Voxels::F32(x), Voxels::F32(y)) => {
            x.len() == y.len() && x.iter().zip(y).all(|(p, q)| p.to_bits() == q.to_bits())
        }
        (x, y) => x == y,
    };
    let bits = |v: &[f64; 3]| v.map(f64::to_bits);
    voxels
        && a.dims == b.dims
        && bits(&a.spacing_mm) == bits(&b.spacing_mm)
        && bits(&a.origin_mm) == bits(&b.origin_mm)
        && a.direction.to_cols_array().map(f64::to_bits)
            == b.direction.to_cols_array().map(f64::to_bits)
        && a.value_slope.to_bits() == b.value_slope.to_bits()
        && a.value_intercept.to_bits() == b.value_intercept.to_bits()
        && a.modality == b.modality
        && a.source == b.source
        && a.warnings == b.warnings
}

/// Loads one file named `name` from fuzz bytes; the result is irrelevant, a panic is a bug.
pub fn load_one(name: &str, data: &[u8]) {
    load_both(&[(name, data)]);
}

/// Splits the input at its first 0xFF 0x00 0xFF 0x00 into a header and a data file, so that
/// detached formats (.nhdr + data, .mhd + .raw, .hdr + .img) are fuzzed too.
pub fn load_pair(header_name: &str, data_name: &str, data: &[u8]) {
    let split = data.windows(4).position(|w| w == [0xFF, 0x00, 0xFF, 0x00]);
    let (a, b) = match split {
        Some(p) => (&data[..p], &data[p + 4..]),
        None => (data, &[][..]),
    };
    load_both(&[(header_name, a), (data_name, b)]);
}
