// 1-D correlation along one axis of a slab with replicated borders (twin: convolve_axis in
// src/cpu/gaussian.rs): out[i] = sum_t w[t] in[clamp(i + t - r)], taps w uploaded from the CPU's
// own `derivative_kernel` (keep Params in sync with src/compute/gaussian.rs).
//
// Three entry points:
// - `convolve_block`: each invocation computes BLOCK consecutive outputs along the pass axis
//   from one sliding window of inputs (BLOCK + 2r loads for BLOCK outputs instead of (2r + 1)
//   per output), taps in a uniform array. The window lives in vec4 registers and the loop is
//   written out by hand: on lavapipe (llvmpipe) every storage-buffer load is a per-lane scalar
//   loop, so loads and stores are what costs, and a private array indexed in a loop would be
//   spilled to memory.
// - `convolve_block3`: the same with BLOCK3 outputs and up to three kernels of one axis at once
//   (taps .x, .y, .z: e.g. orders 0, 1, 2), written to dst, dst1, dst2: one read of the input
//   for three results.
// - `convolve`: one output per invocation, taps in a storage buffer: the fallback for kernels
//   longer than MAX_TAPS (radius > 127).
//
// f32 care: the sum is taken about a reference value v_ref of the line (the centre voxel in
// `convolve`, the block's first output voxel in the block kernels),
// out = v_ref * sum(w) + sum w (v - v_ref), with sum(w) computed in f64 on the CPU (exactly 0
// for derivative kernels: cpu::gaussian::tap_sum): exact for constants (smoothing gives the
// constant, derivatives 0), and a large offset (air at -1000 HU)
// does not cost the derivatives their precision.
#import common.wgsl

struct Params {
    dims: vec3<u32>,
    // 0 = along i, 1 = along j, 2 = along k.
    axis: u32,
    // The kernel has 2 radius + 1 taps.
    radius: u32,
    // convolve_block3: how many of dst, dst1, dst2 to write (1..3).
    outputs: u32,
    // The box of outputs this dispatch computes: lo <= (i, j, k) < hi (hi <= dims). A pass
    // may be cut into parts across its lines (the feature job's paced steps), and restricted to
    // the outputs the next pass reads (a brick's halo is only read, not needed as output, by
    // later passes). Every output depends only on its own line, so parts give the whole pass's
    // bits; the block kernels keep their blocks aligned to the line, so a box gives the bits of
    // the whole slab's pass inside it.
    lo_x: u32,
    lo_y: u32,
    lo_z: u32,
    hi_x: u32,
    hi_y: u32,
    hi_z: u32,
    // Sum of each kernel's taps (x: the only kernel of `convolve` and `convolve_block`).
    tap_sum: vec4<f32>,
}

fn box_lo(axis: u32) -> u32 {
    return select(select(params.lo_z, params.lo_y, axis == 1u), params.lo_x, axis == 0u);
}

fn box_hi(axis: u32) -> u32 {
    return select(select(params.hi_z, params.hi_y, axis == 1u), params.hi_x, axis == 0u);
}

// Outputs per invocation of convolve_block (4 vec4 windows) and convolve_block3 (3 vec4
// windows, 3 kernels: 9 vec4 accumulators); keep in sync with src/compute/gaussian.rs.
const BLOCK: u32 = 16u;
const BLOCK3: u32 = 12u;
// Taps the uniform array holds (radius <= 127).
const MAX_TAPS: u32 = 256u;

struct UniformTaps {
    // w[t] = taps of offset t - radius, one kernel per component.
    w: array<vec4<f32>, MAX_TAPS>,
}

// A read-only storage buffer, not a uniform: lavapipe (Mesa 22.3) specialises a shader on the
// uniforms its loops and branches read, compiling and keeping a variant at every dispatch
// (~1.3 ms and ~260 KB each, never freed while the pipeline lives: 2 GB over a whole-body job).
@group(0) @binding(0) var<storage, read> params: Params;
@group(0) @binding(1) var<storage, read> src: array<f32>;
@group(0) @binding(2) var<storage, read> taps: array<f32>;
@group(0) @binding(3) var<storage, read_write> dst: array<f32>;
@group(0) @binding(4) var<uniform> utaps: UniformTaps;
@group(0) @binding(5) var<storage, read_write> dst1: array<f32>;
@group(0) @binding(6) var<storage, read_write> dst2: array<f32>;

@compute @workgroup_size(8, 8, 1)
fn convolve(@builtin(global_invocation_id) id: vec3<u32>) {
    let dims = params.dims;
    // The dispatch spans the box only.
    let gid = id + vec3<u32>(params.lo_x, params.lo_y, params.lo_z);
    if gid.x >= params.hi_x || gid.y >= params.hi_y || gid.z >= params.hi_z {
        return;
    }
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
    dst[centre] = vc * params.tap_sum.x + acc;
}

// One line of voxels along the pass axis, and the first output voxel of this invocation's block.
struct Line {
    base: u32,
    stride: u32,
    n: u32,
    start: u32,
    // Outputs lo .. hi of the line are stored (the box along the pass axis).
    lo: u32,
    hi: u32,
    ok: bool,
}

// The block kernels run over (a, b, block) of the box: a and b the two other axes (a the
// faster one), the blocks along the pass axis from the block boundary at or below the box's
// start (the same blocks, so the same bits, as a pass over the whole line).
fn line_of(gid: vec3<u32>, block: u32) -> Line {
    let d = params.dims;
    var l: Line;
    var ax = 0u;
    var bx = 1u;
    var na = d.x;
    var nb = d.y;
    var sa = 1u;
    var sb = d.x;
    l.stride = d.x * d.y;
    l.n = d.z;
    if params.axis == 0u {
        ax = 1u;
        bx = 2u;
        na = d.y;
        nb = d.z;
        sa = d.x;
        sb = d.x * d.y;
        l.stride = 1u;
        l.n = d.x;
    } else if params.axis == 1u {
        ax = 0u;
        bx = 2u;
        na = d.x;
        nb = d.z;
        sa = 1u;
        sb = d.x * d.y;
        l.stride = d.x;
        l.n = d.y;
    }
    let a = gid.x + box_lo(ax);
    let b = gid.y + box_lo(bx);
    l.base = a * sa + b * sb;
    l.lo = box_lo(params.axis);
    l.hi = min(box_hi(params.axis), l.n);
    l.start = (l.lo / block) * block + gid.z * block;
    l.ok = a < na && a < box_hi(ax) && b < nb && b < box_hi(bx) && l.start < l.hi;
    return l;
}

fn stored(l: Line, p: u32) -> bool {
    return p >= l.lo && p < l.hi;
}

// The input at position p of the line, borders replicated, minus v_ref.
fn at(l: Line, p: i32, vref: f32) -> f32 {
    return src[l.base + u32(clamp(p, 0, i32(l.n) - 1)) * l.stride] - vref;
}

fn window4(l: Line, p: i32, vref: f32) -> vec4<f32> {
    return vec4<f32>(at(l, p, vref), at(l, p + 1, vref), at(l, p + 2, vref), at(l, p + 3, vref));
}

// Writes the outputs m .. m + 3 of the block (those inside the line).
fn store4(l: Line, m: u32, v: vec4<f32>) {
    let p = l.start + m;
    let i = l.base + p * l.stride;
    if stored(l, p) {
        dst[i] = v.x;
    }
    if stored(l, p + 1u) {
        dst[i + l.stride] = v.y;
    }
    if stored(l, p + 2u) {
        dst[i + 2u * l.stride] = v.z;
    }
    if stored(l, p + 3u) {
        dst[i + 3u * l.stride] = v.w;
    }
}

fn store4_1(l: Line, m: u32, v: vec4<f32>) {
    let p = l.start + m;
    let i = l.base + p * l.stride;
    if stored(l, p) {
        dst1[i] = v.x;
    }
    if stored(l, p + 1u) {
        dst1[i + l.stride] = v.y;
    }
    if stored(l, p + 2u) {
        dst1[i + 2u * l.stride] = v.z;
    }
    if stored(l, p + 3u) {
        dst1[i + 3u * l.stride] = v.w;
    }
}

fn store4_2(l: Line, m: u32, v: vec4<f32>) {
    let p = l.start + m;
    let i = l.base + p * l.stride;
    if stored(l, p) {
        dst2[i] = v.x;
    }
    if stored(l, p + 1u) {
        dst2[i + l.stride] = v.y;
    }
    if stored(l, p + 2u) {
        dst2[i + 2u * l.stride] = v.z;
    }
    if stored(l, p + 3u) {
        dst2[i + 3u * l.stride] = v.w;
    }
}

@compute @workgroup_size(8, 8, 1)
fn convolve_block(@builtin(global_invocation_id) gid: vec3<u32>) {
    let l = line_of(gid, BLOCK);
    if !l.ok {
        return;
    }
    let r = i32(params.radius);
    // Input position under tap 0 for output 0; output m at step t reads p0 + m + t.
    let p0 = i32(l.start) - r;
    let vref = src[l.base + l.start * l.stride];
    // Window: w0..w3 hold the inputs under tap t for outputs 0..15.
    var w0 = window4(l, p0, vref);
    var w1 = window4(l, p0 + 4, vref);
    var w2 = window4(l, p0 + 8, vref);
    var w3 = window4(l, p0 + 12, vref);
    var a0 = vec4<f32>(0.0);
    var a1 = vec4<f32>(0.0);
    var a2 = vec4<f32>(0.0);
    var a3 = vec4<f32>(0.0);
    for (var t = 0; t < 2 * r; t = t + 1) {
        let w = utaps.w[t].x;
        a0 += w * w0;
        a1 += w * w1;
        a2 += w * w2;
        a3 += w * w3;
        w0 = vec4<f32>(w0.yzw, w1.x);
        w1 = vec4<f32>(w1.yzw, w2.x);
        w2 = vec4<f32>(w2.yzw, w3.x);
        w3 = vec4<f32>(w3.yzw, at(l, p0 + i32(BLOCK) + t, vref));
    }
    let w = utaps.w[2 * r].x;
    a0 += w * w0;
    a1 += w * w1;
    a2 += w * w2;
    a3 += w * w3;
    let c = vref * params.tap_sum.x;
    store4(l, 0u, c + a0);
    store4(l, 4u, c + a1);
    store4(l, 8u, c + a2);
    store4(l, 12u, c + a3);
}

@compute @workgroup_size(8, 8, 1)
fn convolve_block3(@builtin(global_invocation_id) gid: vec3<u32>) {
    let l = line_of(gid, BLOCK3);
    if !l.ok {
        return;
    }
    let r = i32(params.radius);
    let p0 = i32(l.start) - r;
    let vref = src[l.base + l.start * l.stride];
    var w0 = window4(l, p0, vref);
    var w1 = window4(l, p0 + 4, vref);
    var w2 = window4(l, p0 + 8, vref);
    // a<kernel>_<window>
    var ax0 = vec4<f32>(0.0);
    var ax1 = vec4<f32>(0.0);
    var ax2 = vec4<f32>(0.0);
    var ay0 = vec4<f32>(0.0);
    var ay1 = vec4<f32>(0.0);
    var ay2 = vec4<f32>(0.0);
    var az0 = vec4<f32>(0.0);
    var az1 = vec4<f32>(0.0);
    var az2 = vec4<f32>(0.0);
    for (var t = 0; t < 2 * r; t = t + 1) {
        let w = utaps.w[t];
        ax0 += w.x * w0;
        ax1 += w.x * w1;
        ax2 += w.x * w2;
        ay0 += w.y * w0;
        ay1 += w.y * w1;
        ay2 += w.y * w2;
        az0 += w.z * w0;
        az1 += w.z * w1;
        az2 += w.z * w2;
        w0 = vec4<f32>(w0.yzw, w1.x);
        w1 = vec4<f32>(w1.yzw, w2.x);
        w2 = vec4<f32>(w2.yzw, at(l, p0 + i32(BLOCK3) + t, vref));
    }
    let w = utaps.w[2 * r];
    ax0 += w.x * w0;
    ax1 += w.x * w1;
    ax2 += w.x * w2;
    ay0 += w.y * w0;
    ay1 += w.y * w1;
    ay2 += w.y * w2;
    az0 += w.z * w0;
    az1 += w.z * w1;
    az2 += w.z * w2;
    let c = vref * params.tap_sum;
    store4(l, 0u, c.x + ax0);
    store4(l, 4u, c.x + ax1);
    store4(l, 8u, c.x + ax2);
    if params.outputs > 1u {
        store4_1(l, 0u, c.y + ay0);
        store4_1(l, 4u, c.y + ay1);
        store4_1(l, 8u, c.y + ay2);
    }
    if params.outputs > 2u {
        store4_2(l, 0u, c.z + az0);
        store4_2(l, 4u, c.z + az1);
        store4_2(l, 8u, c.z + az2);
    }
}
