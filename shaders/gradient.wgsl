// Central differences in mm of an (already smoothed) slab, borders replicated: the gradient of
// `GradientVolume::new` after its smoothing (src/cpu/rst.rs; keep in sync with src/gpu/gradient.rs).
// g_a = (I[idx + e_a] - I[idx - e_a]) / (2 s_a), the neighbour index clamped into the slab, so at
// the first and last voxel of an axis the difference spans one voxel but is still divided by 2 s_a.
#import common.wgsl

struct Params {
    dims: vec3<u32>,
    _pad0: u32,
    // 2 * spacing (mm) per axis.
    two_spacing: vec3<f32>,
    _pad1: f32,
}

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> intensity: array<f32>;
@group(0) @binding(2) var<storage, read_write> gx: array<f32>;
@group(0) @binding(3) var<storage, read_write> gy: array<f32>;
@group(0) @binding(4) var<storage, read_write> gz: array<f32>;

fn at(p: vec3<u32>) -> f32 {
    return intensity[linear_index(p.x, p.y, p.z, params.dims)];
}

@compute @workgroup_size(8, 8, 1)
fn gradient(@builtin(global_invocation_id) gid: vec3<u32>) {
    let d = params.dims;
    if gid.x >= d.x || gid.y >= d.y || gid.z >= d.z {
        return;
    }
    // Saturating neighbours (replicated border).
    let lo = max(gid, vec3<u32>(1u)) - vec3<u32>(1u);
    let hi = min(gid + vec3<u32>(1u), d - vec3<u32>(1u));
    let idx = linear_index(gid.x, gid.y, gid.z, d);
    gx[idx] = (at(vec3<u32>(hi.x, gid.y, gid.z)) - at(vec3<u32>(lo.x, gid.y, gid.z))) / params.two_spacing.x;
    gy[idx] = (at(vec3<u32>(gid.x, hi.y, gid.z)) - at(vec3<u32>(gid.x, lo.y, gid.z))) / params.two_spacing.y;
    gz[idx] = (at(vec3<u32>(gid.x, gid.y, hi.z)) - at(vec3<u32>(gid.x, gid.y, lo.z))) / params.two_spacing.z;
}
