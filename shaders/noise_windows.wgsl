// The noise estimator of docs/science.md (RST item 8), GPU part: on the
// smoothed intensity, the standard deviation of every w x w in-plane window (tiled from (0, 0)
// without overlap) that lies wholly inside the band; -1 for windows that do not. The median over
// all windows of the volume is taken on the CPU (src/cpu/tf.rs has the twin).

struct Params {
    dims: vec3<u32>, // the slab: nx, ny, nz
    z0: u32,         // first slice of the slab to measure
    nz: u32,         // slices to measure
    nwx: u32,        // windows per row
    nwy: u32,        // windows per column
    w: u32,          // window side (11)
    band_lo: f32,
    band_hi: f32,
    _pad0: u32,
    _pad1: u32,
}

// Storage, not uniform: see `params` in gaussian.wgsl (lavapipe's per-dispatch variants).
@group(0) @binding(0) var<storage, read> p: Params;
@group(0) @binding(1) var<storage, read> smoothed: array<f32>;
@group(0) @binding(2) var<storage, read_write> sigmas: array<f32>; // nwx * nwy * nz

fn value(i: u32, j: u32, k: u32) -> f32 {
    return smoothed[i + p.dims.x * (j + p.dims.y * k)];
}

@compute @workgroup_size(8, 8, 1)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= p.nwx || id.y >= p.nwy || id.z >= p.nz {
        return;
    }
    let i0 = id.x * p.w;
    let j0 = id.y * p.w;
    let k = p.z0 + id.z;
    let out = id.x + p.nwx * (id.y + p.nwy * id.z);
    // Two passes (mean, then squared deviations): well conditioned in f32.
    var s = 0.0;
    for (var j = j0; j < j0 + p.w; j++) {
        for (var i = i0; i < i0 + p.w; i++) {
            let v = value(i, j, k);
            if !(v >= p.band_lo && v <= p.band_hi) {
                sigmas[out] = -1.0;
                return;
            }
            s += v;
        }
    }
    let n = f32(p.w * p.w);
    let mean = s / n;
    var s2 = 0.0;
    for (var j = j0; j < j0 + p.w; j++) {
        for (var i = i0; i < i0 + p.w; i++) {
            let d = value(i, j, k) - mean;
            s2 += d * d;
        }
    }
    sigmas[out] = sqrt(s2 / (n - 1.0));
}
