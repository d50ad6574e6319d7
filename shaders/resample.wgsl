// Trilinear resampling between two grids (twin: resample_linear in src/cpu/resample.rs; keep
// Params and Tap in sync with src/compute/resample.rs). Destination voxel (i, j, k) reads the
// source at per-axis positions whose two neighbours and weight are precomputed on the CPU in
// f64 (one Tap per destination index and axis: x taps, then y, then z), positions clamped into
// the source as the CPU does. `components` volumes are stored component-major in both buffers.
#import common.wgsl

struct Params {
    src_dims: vec3<u32>,
    components: u32,
    dst_dims: vec3<u32>,
    _pad0: u32,
}

struct Tap {
    i0: u32,
    i1: u32,
    // Weight of i1.
    w: f32,
    _pad0: u32,
}

// Storage, not uniform: see `params` in gaussian.wgsl (lavapipe's per-dispatch variants).
@group(0) @binding(0) var<storage, read> params: Params;
@group(0) @binding(1) var<storage, read> src: array<f32>;
@group(0) @binding(2) var<storage, read> taps: array<Tap>;
@group(0) @binding(3) var<storage, read_write> dst: array<f32>;

fn lerp(a: f32, b: f32, w: f32) -> f32 {
    return a + (b - a) * w;
}

fn at(base: u32, x: u32, y: u32, z: u32) -> f32 {
    return src[base + linear_index(x, y, z, params.src_dims)];
}

@compute @workgroup_size(8, 8, 1)
fn resample(@builtin(global_invocation_id) gid: vec3<u32>) {
    let d = params.dst_dims;
    if gid.x >= d.x || gid.y >= d.y || gid.z >= d.z {
        return;
    }
    let tx = taps[gid.x];
    let ty = taps[d.x + gid.y];
    let tz = taps[d.x + d.y + gid.z];
    let s = params.src_dims;
    let n_src = s.x * s.y * s.z;
    let n_dst = d.x * d.y * d.z;
    let out = linear_index(gid.x, gid.y, gid.z, d);
    for (var c = 0u; c < params.components; c = c + 1u) {
        let b = c * n_src;
        let c00 = lerp(at(b, tx.i0, ty.i0, tz.i0), at(b, tx.i1, ty.i0, tz.i0), tx.w);
        let c10 = lerp(at(b, tx.i0, ty.i1, tz.i0), at(b, tx.i1, ty.i1, tz.i0), tx.w);
        let c01 = lerp(at(b, tx.i0, ty.i0, tz.i1), at(b, tx.i1, ty.i0, tz.i1), tx.w);
        let c11 = lerp(at(b, tx.i0, ty.i1, tz.i1), at(b, tx.i1, ty.i1, tz.i1), tx.w);
        dst[c * n_dst + out] = lerp(lerp(c00, c10, ty.w), lerp(c01, c11, ty.w), tz.w);
    }
}
