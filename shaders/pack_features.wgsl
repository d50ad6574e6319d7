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
// maxima[0..3]: the largest value of each component (float bits); maxima[4 + c * BINS + b]:
// the histogram of component c's positive values (bins of src/gpu/volume_texture.rs, the twin).
@group(0) @binding(3) var<storage, read_write> maxima: array<atomic<u32>>;

const BINS: u32 = 960u;
const BINS_PER_OCTAVE: f32 = 32.0;
const LOWEST_OCTAVE: f32 = -10.0;

fn bin_of(v: f32) -> u32 {
    let b = floor((log2(v) - LOWEST_OCTAVE) * BINS_PER_OCTAVE);
    return u32(clamp(b, 0.0, f32(BINS - 1u)));
}

var<workgroup> wg_max: array<atomic<u32>, 3>;

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

@compute @workgroup_size(8, 8, 1)
fn main(@builtin(global_invocation_id) id: vec3<u32>, @builtin(local_invocation_index) li: u32) {
    if li < 3u {
        atomicStore(&wg_max[li], 0u);
    }
    workgroupBarrier();
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
        for (var c = 0u; c < 3u; c++) {
            atomicMax(&wg_max[c], bitcast<u32>(max(v[c], 0.0)));
            if v[c] > 0.0 {
                atomicAdd(&maxima[4u + c * BINS + bin_of(v[c])], 1u);
            }
        }
    }
    workgroupBarrier();
    if li < 3u {
        atomicMax(&maxima[li], atomicLoad(&wg_max[li]));
    }
}
