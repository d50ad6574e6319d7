// Packs a block of features (3 components, component-major f32, as the feature kernels write
// them) into Rgb9e5Ufloat texels (V, A, B with a shared exponent) in a staging buffer, which the
// host copies into a box of the method's feature texture (the format cannot be a storage
// texture), and keeps the largest value of each component (non-negative floats order like
// their bits) and their histograms for default gains. The box is `dims` voxels at texel
// (0, y0, z0); it is read from rows src_y0.. of the source block of `src_dims` (a brick's
// features with its halo rows); staging rows are `pitch` texels apart (copies need rows of a
// multiple of 256 bytes). The encoding is src/gpu/volume_texture.rs's `encode_rgb9e5`, the
// same exact f32 arithmetic, so the texels are the CPU twin's bit for bit.

struct Params {
    dims: vec3<u32>,     // the box written: nx, ny, nz
    z0: u32,             // first texture slice this chunk goes to (the host's copy)
    src_dims: vec3<u32>, // the source block
    src_y0: u32,         // first source row of the box
    y0: u32,             // first texture row it goes to (the host's copy)
    pitch: u32,          // staging texels per row
    src_z0: u32,         // first source slice of this chunk (dims.z slices from there)
    _pad1: u32,
}

// Storage, not uniform: see `params` in gaussian.wgsl (lavapipe's per-dispatch variants).
@group(0) @binding(0) var<storage, read> p: Params;
@group(0) @binding(1) var<storage, read> src: array<f32>;
@group(0) @binding(2) var<storage, read_write> dst: array<u32>;
// binding 3: the maxima and histograms (feature_stats.wgsl).

#import rgb9e5.wgsl
#import feature_stats.wgsl

@compute @workgroup_size(8, 8, 1)
fn main(@builtin(global_invocation_id) id: vec3<u32>, @builtin(local_invocation_index) li: u32) {
    stats_begin(li);
    if all(id < p.dims) {
        let s = p.src_dims;
        let n = s.x * s.y * s.z;
        let idx = id.x + s.x * (id.y + p.src_y0 + s.y * (id.z + p.src_z0));
        let v = vec3<f32>(
            finite_or_zero(src[idx]),
            finite_or_zero(src[n + idx]),
            finite_or_zero(src[2u * n + idx]),
        );
        dst[id.x + p.pitch * (id.y + p.dims.y * id.z)] = encode_rgb9e5(v);
        stats_count(v);
    }
    stats_end(li);
}
