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

/// Loads one file named `name` from fuzz bytes; the result is irrelevant, a panic is a bug.
pub fn load_one(name: &str, data: &[u8]) {
    let _ = io::load_with(&[InputFile::new(name, data.to_vec())], &LIMITS);
}

/// Splits the input at its first 0xFF 0x00 0xFF 0x00 into a header and a data file, so that
/// detached formats (.nhdr + data, .mhd + .raw, .hdr + .img) are fuzzed too.
pub fn load_pair(header_name: &str, data_name: &str, data: &[u8]) {
    let split = data.windows(4).position(|w| w == [0xFF, 0x00, 0xFF, 0x00]);
    let (a, b) = match split {
        Some(p) => (&data[..p], &data[p + 4..]),
        None => (data, &[][..]),
    };
    let files = [
        InputFile::new(header_name, a.to_vec()),
        InputFile::new(data_name, b.to_vec()),
    ];
    let _ = io::load_with(&files, &LIMITS);
}
