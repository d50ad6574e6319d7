// Axis-aligned maximum intensity projection of a scalar volume (keep in sync with
// src/gpu/axis_mip.rs). Pass 1 (`project`) writes the maximum of every line along `axis` into a
// storage buffer; pass 2 (`colorize`) windows that image into an rgba8 texture for display.
#import common.wgsl

struct Params {
    dims: vec3<u32>,
    // 0 = along i, 1 = along j, 2 = along k.
    axis: u32,
    // Width and height of the projection image.
    out_size: vec2<u32>,
    window_lo: f32,
    window_hi: f32,
}

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> volume: array<f32>;
@group(0) @binding(2) var<storage, read_write> mip: array<f32>;

// The voxel at position `t` along the projection axis of output pixel (u, v). The image's u runs
// along the first remaining axis and v along the second (axis 0 -> (j, k), 1 -> (i, k), 2 -> (i, j)).
fn voxel_of(u: u32, v: u32, t: u32) -> vec3<u32> {
    switch params.axis {
        case 0u: { return vec3<u32>(t, u, v); }
        case 1u: { return vec3<u32>(u, t, v); }
        default: { return vec3<u32>(u, v, t); }
    }
}

@compute @workgroup_size(8, 8, 1)
fn project(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= params.out_size.x || gid.y >= params.out_size.y {
        return;
    }
    let depth = params.dims[params.axis];
    var m = -3.4e38;
    for (var t = 0u; t < depth; t = t + 1u) {
        let p = voxel_of(gid.x, gid.y, t);
        m = max(m, volume[linear_index(p.x, p.y, p.z, params.dims)]);
    }
    mip[gid.x + params.out_size.x * gid.y] = m;
}

@group(0) @binding(3) var image: texture_storage_2d<rgba8unorm, write>;

@compute @workgroup_size(8, 8, 1)
fn colorize(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= params.out_size.x || gid.y >= params.out_size.y {
        return;
    }
    let g = window01(mip[gid.x + params.out_size.x * gid.y], params.window_lo, params.window_hi);
    textureStore(image, vec2<i32>(gid.xy), vec4<f32>(g, g, g, 1.0));
}
