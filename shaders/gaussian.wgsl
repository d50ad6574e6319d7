// 1-D correlation along one axis of a slab with replicated borders (twin: convolve_axis in
// src/cpu/gaussian.rs): out[i] = sum_t w[t] in[clamp(i + t - r)], taps w uploaded from the CPU's
// own `derivative_kernel` (keep Params in sync with src/gpu/gaussian.rs).
//
// f32 care: the sum is taken about the centre value, out = v_c * sum(w) + sum w (v - v_c), with
// sum(w) computed in f64 on the CPU: exact for constants (smoothing gives v_c, derivatives 0),
// and a large offset (air at -1000 HU) does not cost the derivatives their precision.
#import common.wgsl

struct Params {
    dims: vec3<u32>,
    // 0 = along i, 1 = along j, 2 = along k.
    axis: u32,
    // The kernel has 2 radius + 1 taps.
    radius: u32,
    tap_sum: f32,
    _pad0: u32,
    _pad1: u32,
}

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> src: array<f32>;
@group(0) @binding(2) var<storage, read> taps: array<f32>;
@group(0) @binding(3) var<storage, read_write> dst: array<f32>;

@compute @workgroup_size(8, 8, 1)
fn convolve(@builtin(global_invocation_id) gid: vec3<u32>) {
    let dims = params.dims;
    if gid.x >= dims.x || gid.y >= dims.y || gid.z >= dims.z {
        return;
    }
    let centre = linear_index(gid.x, gid.y, gid.z, dims);
    var stride = 1u;
    var pos = gid.x;
    var n = dims.x;
    if params.axis == 1u {
        stride = dims.x;
        pos = gid.y;
        n = dims.y;
    } else if params.axis == 2u {
        stride = dims.x * dims.y;
        pos = gid.z;
        n = dims.z;
    }
    let base = centre - pos * stride;
    let vc = src[centre];
    let r = i32(params.radius);
    let last = i32(n) - 1;
    var acc = 0.0;
    for (var t = 0; t <= 2 * r; t = t + 1) {
        let q = u32(clamp(i32(pos) + t - r, 0, last));
        acc = acc + taps[t] * (src[base + q * stride] - vc);
    }
    dst[centre] = vc * params.tap_sum + acc;
}
