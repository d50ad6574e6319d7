// Central differences in mm of an (already smoothed) slab, borders replicated: the gradient of
// `GradientVolume::new` after its smoothing (src/cpu/rst.rs; keep in sync with src/compute/gradient.rs).
// g_a = (I[idx + e_a] - I[idx - e_a]) / (2 s_a), the neighbour index clamped into the slab, so at
// the first and last voxel of an axis the difference spans one voxel but is still divided by 2 s_a.
//
// Two entry points: `gradient` writes three f32 buffers gx, gy, gz; `gradient_packed` writes
// (I, gx, gy, gz) into an rgba32float 3D texture, the input of the RST kernel (rst.wgsl).
#import common.wgsl

struct Params {
    dims: vec3<u32>,
    _pad0: u32,
    // 2 * spacing (mm) per axis.
    two_spacing: vec3<f32>,
    _pad1: f32,
}

// Storage, not uniform: see `params` in gaussian.wgsl (lavapipe's per-dispatch variants).
@group(0) @binding(0) var<storage, read> params: Params;
@group(0) @binding(1) var<storage, read> intensity: array<f32>;
@group(0) @binding(2) var<storage, read_write> gx: array<f32>;
@group(0) @binding(3) var<storage, read_write> gy: array<f32>;
@group(0) @binding(4) var<storage, read_write> gz: array<f32>;
@group(0) @binding(5) var packed: texture_storage_3d<rgba32float, write>;

fn at(p: vec3<u32>) -> f32 {
    return intensity[linear_index(p.x, p.y, p.z, params.dims)];
}

// The gradient at voxel `v` (inside the slab).
fn gradient_at(v: vec3<u32>) -> vec3<f32> {
    // Saturating neighbours (replicated border).
    let lo = max(v, vec3<u32>(1u)) - vec3<u32>(1u);
    let hi = min(v + vec3<u32>(1u), params.dims - vec3<u32>(1u));
    return vec3<f32>(
        (at(vec3<u32>(hi.x, v.y, v.z)) - at(vec3<u32>(lo.x, v.y, v.z))) / params.two_spacing.x,
        (at(vec3<u32>(v.x, hi.y, v.z)) - at(vec3<u32>(v.x, lo.y, v.z))) / params.two_spacing.y,
        (at(vec3<u32>(v.x, v.y, hi.z)) - at(vec3<u32>(v.x, v.y, lo.z))) / params.two_spacing.z,
    );
}

fn inside(v: vec3<u32>) -> bool {
    return v.x < params.dims.x && v.y < params.dims.y && v.z < params.dims.z;
}

@compute @workgroup_size(8, 8, 1)
fn gradient(@builtin(global_invocation_id) gid: vec3<u32>) {
    if !inside(gid) {
        return;
    }
    let g = gradient_at(gid);
    let idx = linear_index(gid.x, gid.y, gid.z, params.dims);
    gx[idx] = g.x;
    gy[idx] = g.y;
    gz[idx] = g.z;
}

@compute @workgroup_size(8, 8, 1)
fn gradient_packed(@builtin(global_invocation_id) gid: vec3<u32>) {
    if !inside(gid) {
        return;
    }
    textureStore(packed, gid, vec4<f32>(at(gid), gradient_at(gid)));
}
