// Packs a block of features (3 components, component-major f32, as the feature kernels write
// them) into a box of a method's Rgba16Float feature texture (V, A, B, 0), and keeps the
// largest value of each component (non-negative floats order like their bits) for default gains.
// The box is `dims` voxels at texel (0, y0, z0); it is read from rows src_y0.. of the source
// block of `src_dims` (a brick's features with its halo rows).

struct Params {
    dims: vec3<u32>,     // the box written: nx, ny, nz
    z0: u32,             // first texture slice it goes to
    src_dims: vec3<u32>, // the source block
    src_y0: u32,         // first source row of the box
    y0: u32,             // first texture row it goes to
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

@group(0) @binding(0) var<uniform> p: Params;
@group(0) @binding(1) var<storage, read> src: array<f32>;
@group(0) @binding(2) var dst: texture_storage_3d<rgba16float, write>;
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
        let idx = id.x + s.x * (id.y + p.src_y0 + s.y * id.z);
        let v = vec3<f32>(
            finite_or_zero(src[idx]),
            finite_or_zero(src[n + idx]),
            finite_or_zero(src[2u * n + idx]),
        );
        textureStore(dst, vec3<u32>(id.x, id.y + p.y0, id.z + p.z0), vec4<f32>(v, 0.0));
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
