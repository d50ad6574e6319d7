// One component g_a * g_b of the outer product g g^T of a gradient field given as three
// component buffers (keep Params in sync with src/compute/structure_tensor.rs). The six products
// are then smoothed with a Gaussian of the neighbourhood scale rho (gaussian.wgsl) and mapped by
// eigen_features.wgsl. Twin: src/cpu/structure_tensor.rs.
#import common.wgsl

struct Params {
    dims: vec3<u32>,
    a: u32,
    b: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

// Storage, not uniform: see `params` in gaussian.wgsl (lavapipe's per-dispatch variants).
@group(0) @binding(0) var<storage, read> params: Params;
@group(0) @binding(1) var<storage, read> g_x: array<f32>;
@group(0) @binding(2) var<storage, read> g_y: array<f32>;
@group(0) @binding(3) var<storage, read> g_z: array<f32>;
@group(0) @binding(4) var<storage, read_write> product: array<f32>;

fn component(axis: u32, idx: u32) -> f32 {
    switch axis {
        case 0u: { return g_x[idx]; }
        case 1u: { return g_y[idx]; }
        default: { return g_z[idx]; }
    }
}

@compute @workgroup_size(8, 8, 1)
fn outer_product(@builtin(global_invocation_id) gid: vec3<u32>) {
    let dims = params.dims;
    if gid.x >= dims.x || gid.y >= dims.y || gid.z >= dims.z {
        return;
    }
    let idx = linear_index(gid.x, gid.y, gid.z, dims);
    product[idx] = component(params.a, idx) * component(params.b, idx);
}
