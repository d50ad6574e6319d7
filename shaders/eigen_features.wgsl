// Per-voxel eigenvalues and feature maps of a symmetric tensor field given as six component
// buffers [xx, yy, zz, xy, xz, yz] on a slab (the Hessian, the general structure tensor), for the
// output slices out_z0 .. out_z0 + out_nz only (keep Params in sync with
// src/compute/eigen_features.rs). Twins: src/cpu/features.rs, src/cpu/structure_tensor.rs.
//
// Output, component-major over the output slices (n_out = nx * ny * out_nz, index uses
// k - out_z0). A dispatch computes the part part_k0 .. part_k0 + part_nk of the output slices
// (the feature job's paced steps; all of them by default), indexed as in the whole block:
// - mode 0 (features): 3 components (V, A, B) of map MAP_SIMPLE / MAP_LI / MAP_FRANGI (c), of
//   the eigenvalues (negated first when `negate`, the structure tensor's mapping). With
//   `accumulate`, each component keeps the maximum of what is there and the new value
//   (multi-scale: per voxel and feature, the maximum over scales).
// - mode 1 (eigenvalues): 4 components (l0, l1, l2, |T|_F): the sorted eigenvalues and the
//   Frobenius norm of the tensor they came from. With `accumulate`, a voxel is overwritten only
//   where the new tensor's norm is strictly larger than the stored one (multi-scale: the scale
//   whose normalised Hessian has the largest Frobenius norm, first scale on a tie, as the CPU).
// Without `accumulate` the values are written (use it for the first scale).
//
// `max_norm` folds the largest Frobenius norm over the output slices (and rows) into one u32 holding the
// f32's bits (atomicMax on the bits orders non-negative floats correctly), for Frangi's default
// c = half the largest norm over the WHOLE volume (every slab's output slices into one atomic).
#import common.wgsl
#import eigen.wgsl
#import feature_maps.wgsl

struct Params {
    dims: vec3<u32>,
    out_z0: u32,
    out_nz: u32,
    mode: u32,
    map: u32,
    accumulate: u32,
    frangi_c: f32,
    negate: u32,
    // Only the rows row0 .. row0 + n_rows are computed (a brick's core; n_rows 0 = all).
    row0: u32,
    n_rows: u32,
    part_k0: u32,
    part_nk: u32,
    _pad0: u32,
    _pad1: u32,
}

// Storage, not uniform: see `params` in gaussian.wgsl (lavapipe's per-dispatch variants). Each
// entry point binds 8 storage buffers with it, WebGPU's default limit per stage.
@group(0) @binding(0) var<storage, read> params: Params;
@group(0) @binding(1) var<storage, read> t_xx: array<f32>;
@group(0) @binding(2) var<storage, read> t_yy: array<f32>;
@group(0) @binding(3) var<storage, read> t_zz: array<f32>;
@group(0) @binding(4) var<storage, read> t_xy: array<f32>;
@group(0) @binding(5) var<storage, read> t_xz: array<f32>;
@group(0) @binding(6) var<storage, read> t_yz: array<f32>;
@group(0) @binding(7) var<storage, read_write> out: array<f32>;
@group(0) @binding(8) var<storage, read_write> norm_max: atomic<u32>;

fn inside(gid: vec3<u32>) -> bool {
    return gid.x < params.dims.x && gid.y < params.dims.y && gid.z < params.part_nk;
}

fn in_rows(gid: vec3<u32>) -> bool {
    return params.n_rows == 0u || (gid.y >= params.row0 && gid.y - params.row0 < params.n_rows);
}

fn slab_index(gid: vec3<u32>) -> u32 {
    return linear_index(gid.x, gid.y, params.out_z0 + params.part_k0 + gid.z, params.dims);
}

fn diag(idx: u32) -> vec3<f32> {
    return vec3<f32>(t_xx[idx], t_yy[idx], t_zz[idx]);
}

fn offdiag(idx: u32) -> vec3<f32> {
    return vec3<f32>(t_xy[idx], t_xz[idx], t_yz[idx]);
}

@compute @workgroup_size(8, 8, 1)
fn eigen_features(@builtin(global_invocation_id) gid: vec3<u32>) {
    if !inside(gid) || !in_rows(gid) {
        return;
    }
    let idx = slab_index(gid);
    let d = diag(idx);
    let o = offdiag(idx);
    let n_out = params.dims.x * params.dims.y * params.out_nz;
    let oi = gid.x + params.dims.x * (gid.y + params.dims.y * (params.part_k0 + gid.z));
    let l = eigenvalues_sorted(d, o);
    let acc = params.accumulate != 0u;
    if params.mode == 0u {
        var m = l;
        if params.negate != 0u {
            m = -l;
        }
        let f = map_features(m, params.map, params.frangi_c);
        for (var c = 0u; c < 3u; c = c + 1u) {
            let j = c * n_out + oi;
            var v = f[c];
            if acc {
                v = max(out[j], v);
            }
            out[j] = v;
        }
    } else {
        let norm = sym_frobenius(d, o);
        if !acc || norm > out[3u * n_out + oi] {
            out[oi] = l.x;
            out[n_out + oi] = l.y;
            out[2u * n_out + oi] = l.z;
            out[3u * n_out + oi] = norm;
        }
    }
}

var<workgroup> wg_max: atomic<u32>;

@compute @workgroup_size(8, 8, 1)
fn max_norm(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(local_invocation_index) li: u32,
) {
    if li == 0u {
        atomicStore(&wg_max, 0u);
    }
    workgroupBarrier();
    if inside(gid) && in_rows(gid) {
        let idx = slab_index(gid);
        let norm = sym_frobenius(diag(idx), offdiag(idx));
        // NaN fails the test (its bits would beat every number).
        if norm > 0.0 {
            atomicMax(&wg_max, bitcast<u32>(norm));
        }
    }
    workgroupBarrier();
    if li == 0u {
        atomicMax(&norm_max, atomicLoad(&wg_max));
    }
}
