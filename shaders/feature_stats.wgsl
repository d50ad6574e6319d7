// Shared by the pack and pool kernels: the largest value of each feature and their histograms
// (the default gains; src/gpu/volume_texture/histogram.rs holds the bins' twin), counted once
// per voxel. A kernel calls `stats_begin` and `stats_end` in uniform control flow around its
// work and `stats_count` for each voxel.

// maxima[0..3]: the largest value of each component (float bits); maxima[4 + c * BINS + b]:
// the histogram of component c's positive values.
@group(0) @binding(3) var<storage, read_write> maxima: array<atomic<u32>>;

const BINS: u32 = 960u;
const BINS_PER_OCTAVE: f32 = 32.0;
const LOWEST_OCTAVE: f32 = -10.0;

var<workgroup> wg_max: array<atomic<u32>, 3>;

fn bin_of(v: f32) -> u32 {
    let b = floor((log2(v) - LOWEST_OCTAVE) * BINS_PER_OCTAVE);
    return u32(clamp(b, 0.0, f32(BINS - 1u)));
}

fn stats_begin(li: u32) {
    if li < 3u {
        atomicStore(&wg_max[li], 0u);
    }
    workgroupBarrier();
}

// One voxel's (V, A, B), already clamped (non-negative floats order like their bits).
fn stats_count(v: vec3<f32>) {
    for (var c = 0u; c < 3u; c++) {
        atomicMax(&wg_max[c], bitcast<u32>(max(v[c], 0.0)));
        if v[c] > 0.0 {
            atomicAdd(&maxima[4u + c * BINS + bin_of(v[c])], 1u);
        }
    }
}

fn stats_end(li: u32) {
    workgroupBarrier();
    if li < 3u {
        atomicMax(&maxima[li], atomicLoad(&wg_max[li]));
    }
}
