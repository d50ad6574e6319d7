// The radial structure tensor ray kernel (twin: `rst_tensor_at` in src/cpu/rst.rs, docs/science.md RST
// items 3-7; keep the structs in sync with src/compute/rst/mod.rs). One invocation per output voxel casts
// every ray from the voxel centre, samples the smoothed intensity I and the gradient g by
// trilinear interpolation (by default done here from 8 `textureLoad`s of the packed
// (I, gx, gy, gz) rgba32float texture that gradient.wgsl writes, positions clamped onto the slab:
// exactly `GradientVolume::sample`; with HARDWARE_FILTERING one `textureSampleLevel` through the
// linear sampler instead, see `sample_ig`), accumulates the opacity
// with the consistent rule or the paper's, stops a ray after the step where alpha >= 0.99, and
// writes the symmetrised tensor Ts = (T + T^T) / N_R, its eigenvalues, its features, or the
// number of samples taken, for the out_nz slices out_z0, out_z0 + z_stride, ... only (and, to
// split a slice into smaller dispatches, only its rows row0 .. row0 + n_rows; the output layout
// is the same). z_stride > 1 when the slab was refined along z (`GradientVolume::refined`).
//
// Positions are in slab voxel units: the voxel (i, j, k) at (i, j, k); a ray's step in voxels,
// dr * r_a / s_a, and its opacity length L_i are computed on the CPU in f64 (the twin's
// `opacity_length_mm`) and uploaded, so nothing here depends on the spacing directly.
#import common.wgsl
#import eigen.wgsl
#import feature_maps.wgsl

const RULE_CONSISTENT: u32 = 0u;
const RULE_PAPER: u32 = 1u;

const MODE_TENSOR: u32 = 0u;        // 6 components (xx, yy, zz, xy, xz, yz)
const MODE_EIGEN: u32 = 1u;         // 3 components, sorted by magnitude
const MODE_FEATURES: u32 = 2u;      // 3 components (V, A, B) with `map`
const MODE_SAMPLE_COUNT: u32 = 3u;  // 1 component: ray samples taken (excluding the centre)

struct Params {
    dims: vec3<u32>,
    n_rays: u32,
    out_z0: u32,
    out_nz: u32,
    // K = floor(R / dr + 1e-6).
    n_steps: u32,
    rule: u32,
    // dr (mm).
    step_mm: f32,
    // Paper rule: dr / smallest spacing.
    dr_vox: f32,
    d_min: f32,
    d_max: f32,
    mode: u32,
    // MAP_SIMPLE or MAP_LI (feature_maps.wgsl).
    map: u32,
    // Paper rule: stop once alpha >= alpha_stop.
    alpha_stop: f32,
    // Consistent rule: stop once the transmittance 1 - alpha <= trans_stop (= 1 - alpha_stop).
    trans_stop: f32,
    // Rows (j) of the output slices this dispatch computes.
    row0: u32,
    n_rows: u32,
    // Slab slices from one output slice to the next: 1, or z's refinement factor (the slab is
    // refined, the output is its input voxels).
    z_stride: u32,
    _pad: u32,
}

struct Ray {
    // xyz: unit direction r_i; w: opacity length L_i (mm).
    dir_len: vec4<f32>,
    // xyz: one step dr along the ray in voxels per axis, dr * r_a / s_a; w unused.
    step_vox: vec4<f32>,
}

// How the rays read (I, g), fixed per pipeline (src/compute/rst/mod.rs): false = 8 `textureLoad`s and
// the twin's weights in f32 (the bit-level twin tests); true = one `textureSampleLevel` with the
// linear clamp-to-edge sampler (the texture unit's weights: fewer fetches, within a tolerance of
// the twin). Only for a device with FLOAT32_FILTERABLE (rgba32float is not filterable in core
// WebGPU); the pipeline layout declares the texture filterable only then.
override HARDWARE_FILTERING: bool = false;
// For tests only (0 otherwise): the exact path with its weights truncated to multiples of
// 1 / EMULATED_WEIGHT_STEPS, as a texture unit with that many fractional steps computes them
// (CUDA documents 8 bits, 256 steps), to measure what hardware filtering costs on GPUs whose
// weights are coarser than lavapipe's.
override EMULATED_WEIGHT_STEPS: f32 = 0.0;

// Storage, not uniform: see `params` in gaussian.wgsl (lavapipe's per-dispatch variants).
@group(0) @binding(0) var<storage, read> params: Params;
// (I, gx, gy, gz) per voxel of the slab (one load gives all four, several times faster than four
// storage-buffer loads on lavapipe, and cached in 3D on GPUs).
@group(0) @binding(1) var volume: texture_3d<f32>;
@group(0) @binding(2) var<storage, read> rays: array<Ray>;
@group(0) @binding(3) var<storage, read_write> result: array<f32>;
// Linear and clamp-to-edge with HARDWARE_FILTERING; otherwise a nearest (non-filtering) sampler
// that is never used but must be bound (static use does not depend on override values).
@group(0) @binding(4) var volume_sampler: sampler;

// (I, gx, gy, gz) of voxel (x, y, z).
fn load(x: u32, y: u32, z: u32) -> vec4<f32> {
    return textureLoad(volume, vec3<u32>(x, y, z), 0);
}

// Trilinear (I, g) at a position in voxel units, clamped onto the slab (replicated border):
// `GradientVolume::sample`.
fn sample_ig(u_in: vec3<f32>) -> vec4<f32> {
    let top = params.dims - vec3<u32>(1u);
    let u = clamp(u_in, vec3<f32>(0.0), vec3<f32>(top));
    if HARDWARE_FILTERING {
        // Texel centres are at (voxel + 0.5) / dims in texture coordinates, so the texture unit
        // interpolates between the same 8 voxels with the same fractions (up to its own weight
        // precision: 8 fractional bits on many GPUs). The position is clamped above, as the twin
        // clamps it; the sampler's clamp-to-edge then only repeats the last voxel with weight 0
        // (or the texture unit's rounding of it), like `i1 = min(i0 + 1, top)` below.
        let uvw = (u + vec3<f32>(0.5)) / vec3<f32>(params.dims);
        return textureSampleLevel(volume, volume_sampler, uvw, 0.0);
    }
    let f = floor(u);
    let i0 = vec3<u32>(f);
    let i1 = min(i0 + vec3<u32>(1u), top);
    var t = u - f;
    if EMULATED_WEIGHT_STEPS > 0.0 {
        t = floor(t * EMULATED_WEIGHT_STEPS) / EMULATED_WEIGHT_STEPS;
    }
    let s = vec3<f32>(1.0) - t;
    var acc = (s.x * s.y * s.z) * load(i0.x, i0.y, i0.z);
    acc += (t.x * s.y * s.z) * load(i1.x, i0.y, i0.z);
    acc += (s.x * t.y * s.z) * load(i0.x, i1.y, i0.z);
    acc += (t.x * t.y * s.z) * load(i1.x, i1.y, i0.z);
    acc += (s.x * s.y * t.z) * load(i0.x, i0.y, i1.z);
    acc += (t.x * s.y * t.z) * load(i1.x, i0.y, i1.z);
    acc += (s.x * t.y * t.z) * load(i0.x, i1.y, i1.z);
    acc += (t.x * t.y * t.z) * load(i1.x, i1.y, i1.z);
    return acc;
}

// Opacity transfer function (paper eq. 3): `TransferFunction::eval`.
fn transfer(d: f32) -> f32 {
    if d <= params.d_min {
        return 0.0;
    }
    if d >= params.d_max {
        return 1.0;
    }
    return (d - params.d_min) / (params.d_max - params.d_min);
}

// 1 - exp(-x) for x >= 0, without the cancellation of `1.0 - exp(-x)` at small x (f32 has no
// expm1): Taylor to x^5 below 0.1 (truncation < 2e-8 relative).
fn one_minus_exp_neg(x: f32) -> f32 {
    if x < 0.1 {
        return x * (1.0 - x * (0.5 - x * (1.0 / 6.0 - x * (1.0 / 24.0 - x * (1.0 / 120.0)))));
    }
    return 1.0 - exp(-x);
}

@compute @workgroup_size(8, 8, 1)
fn rst(@builtin(global_invocation_id) gid: vec3<u32>) {
    let j = params.row0 + gid.y;
    if gid.x >= params.dims.x || gid.y >= params.n_rows || j >= params.dims.y
        || gid.z >= params.out_nz {
        return;
    }
    let z = params.out_z0 + gid.z * params.z_stride;
    let x = vec3<f32>(f32(gid.x), f32(j), f32(z));
    // The centre is a voxel: with HARDWARE_FILTERING read it exactly (one load), as the trilinear
    // weights (1, 0, ...) of the exact path do.
    var centre: vec4<f32>;
    if HARDWARE_FILTERING {
        centre = load(gid.x, j, z);
    } else {
        centre = sample_ig(x);
    }
    // Ts = (T + T^T) accumulated as its diagonal (xx, yy, zz) and off-diagonal (xy, xz, yz).
    var diag = vec3<f32>(0.0);
    var off = vec3<f32>(0.0);
    var samples = 0u;
    for (var ri = 0u; ri < params.n_rays; ri += 1u) {
        let ray = rays[ri];
        let r = ray.dir_len.xyz;
        let dstep = ray.step_vox.xyz;
        // The ray's weighted gradient sum (later times r^T).
        var acc = vec3<f32>(0.0);
        if params.rule == RULE_CONSISTENT {
            let len = ray.dir_len.w;
            // tau_k = 0.5 (f_{k-1} + f_k) dr / L_i; alpha tracked as the transmittance 1 - alpha,
            // so that the weights alpha_k - alpha_{k-1} = trans_{k-1} (1 - exp(-tau_k)) keep
            // their relative precision in f32.
            let tau_scale = 0.5 * params.step_mm / len;
            var trans = 1.0;
            var f_prev = 0.0;
            var g_prev = centre.yzw;
            for (var k = 1u; k <= params.n_steps; k += 1u) {
                let smp = sample_ig(x + f32(k) * dstep);
                samples += 1u;
                let fk = transfer(abs(smp.x - centre.x));
                let w = trans * one_minus_exp_neg((f_prev + fk) * tau_scale);
                acc += (w * 0.5) * (g_prev + smp.yzw);
                trans -= w;
                if trans <= params.trans_stop {
                    break;
                }
                f_prev = fk;
                g_prev = smp.yzw;
            }
            acc *= len;
        } else {
            var alpha = 0.0;
            for (var k = 1u; k <= params.n_steps; k += 1u) {
                let smp = sample_ig(x + f32(k) * dstep);
                samples += 1u;
                let fk = transfer(abs(smp.x - centre.x));
                alpha = alpha + (1.0 - alpha) * min(1.0, fk * params.dr_vox);
                acc += alpha * smp.yzw;
                if alpha >= params.alpha_stop {
                    break;
                }
            }
            acc *= params.step_mm;
        }
        diag += 2.0 * acc * r;
        off += vec3<f32>(
            acc.x * r.y + acc.y * r.x,
            acc.x * r.z + acc.z * r.x,
            acc.y * r.z + acc.z * r.y,
        );
    }
    let n = f32(max(params.n_rays, 1u));
    diag = diag / n;
    off = off / n;

    let n_out = params.dims.x * params.dims.y * params.out_nz;
    let o = gid.x + params.dims.x * (j + params.dims.y * gid.z);
    switch params.mode {
        case MODE_TENSOR: {
            result[o] = diag.x;
            result[o + n_out] = diag.y;
            result[o + 2u * n_out] = diag.z;
            result[o + 3u * n_out] = off.x;
            result[o + 4u * n_out] = off.y;
            result[o + 5u * n_out] = off.z;
        }
        case MODE_SAMPLE_COUNT: {
            result[o] = f32(samples);
        }
        default: {
            var v = eigenvalues_sorted(diag, off);
            if params.mode == MODE_FEATURES {
                v = map_features(v, params.map, 0.0);
            }
            result[o] = v.x;
            result[o + n_out] = v.y;
            result[o + 2u * n_out] = v.z;
        }
    }
}
