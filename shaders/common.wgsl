// Shared WGSL helpers, imported by other shaders with `#import common.wgsl`.
// Voxel index convention (as in src/volume.rs): i fastest, index = i + nx * (j + ny * k).

fn linear_index(i: u32, j: u32, k: u32, dims: vec3<u32>) -> u32 {
    return i + dims.x * (j + dims.y * k);
}

// Maps a value to 0..1 through a window [lo, hi] (CT window/level as lo = L - W/2, hi = L + W/2).
fn window01(v: f32, lo: f32, hi: f32) -> f32 {
    return clamp((v - lo) / max(hi - lo, 1e-6), 0.0, 1.0);
}
