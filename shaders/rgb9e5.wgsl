// Shared by the pack and pool kernels: the Rgb9e5 encoding (src/gpu/volume_texture/rgb9e5.rs
// is its CPU twin, bit for bit) and the clamping of a feature value.

const F16_MAX: f32 = 65504.0;

const RGB9E5_MAX: f32 = 65408.0;

// 2^k for an integer k in f32's normal range, exactly.
fn pow2(k: i32) -> f32 {
    return bitcast<f32>(u32(k + 127) << 23u);
}

// EXT_texture_shared_exponent's encoding with round to nearest; every step is exact in f32
// (products by powers of two, additions of 0.5 to values whose ulp allows it, floor).
fn encode_rgb9e5(v: vec3<f32>) -> u32 {
    let c = min(max(v, vec3<f32>(0.0)), vec3<f32>(RGB9E5_MAX));
    let m = max(c.x, max(c.y, c.z));
    let e_m = i32((bitcast<u32>(m) >> 23u) & 0xffu) - 127;
    var e = max(e_m, -16) + 16;
    let top = floor(m * pow2(24 - e) + 0.5);
    if top >= 512.0 {
        e = e + 1;
    }
    let scale = pow2(24 - e);
    let q = min(vec3<u32>(floor(c * scale + vec3<f32>(0.5))), vec3<u32>(511u));
    return q.x | (q.y << 9u) | (q.z << 18u) | (u32(e) << 27u);
}

fn finite_or_zero(v: f32) -> f32 {
    // NaN fails every comparison; infinities are clamped below.
    if !(v == v) {
        return 0.0;
    }
    return clamp(v, -F16_MAX, F16_MAX);
}

// The same encoding rounding up: every channel's texel value is at least its input, and at
// least what `encode_rgb9e5` gives it alone or beside smaller channels (a power-of-two grid
// holds the finer ones' points). A max-pooled texel is encoded so: it never falls below a
// voxel of its block as a full-resolution texel holds it. Twin: `encode_rgb9e5_up`.
fn encode_rgb9e5_up(v: vec3<f32>) -> u32 {
    let c = min(max(v, vec3<f32>(0.0)), vec3<f32>(RGB9E5_MAX));
    let m = max(c.x, max(c.y, c.z));
    let e_m = i32((bitcast<u32>(m) >> 23u) & 0xffu) - 127;
    var e = max(e_m, -16) + 16;
    if ceil(m * pow2(24 - e)) > 511.0 {
        e = e + 1;
    }
    let scale = pow2(24 - e);
    let q = min(vec3<u32>(ceil(c * scale)), vec3<u32>(511u));
    return q.x | (q.y << 9u) | (q.z << 18u) | (u32(e) << 27u);
}
