// Brick extrema for the MIP ray caster's empty-space skipping (keep in sync with
// src/render/raycast/, `cpu_bricks`).
//
// Brick b (per axis) covers the continuous voxel positions [b * B, (b + 1) * B] (the last brick
// ends at n - 1), so every trilinear sample whose clamped position lies in it reads only voxels
// b * B ..= min((b + 1) * B, n - 1): the brick's extrema over those voxels bound the sample.
// Values are the textures' own half floats, so the extrema are exact in Rgba16Float.
//
// bricks_intensity writes (max, min, 0, 0) of the intensity; bricks_features (max V, max A,
// max B, 0) of the features.

const BRICK: u32 = 8u;

// A pass makes the brick slices z0 .. z0 + nz (the viewer spreads a large volume's table over
// frames).
// `level`: the source's level (features may be max-pooled: texel m holds the maximum of the
// voxels m * 2^level ..); `dims`: the volume's voxels, which the bricks cover.
struct Slices {
    z0: u32,
    nz: u32,
    level: u32,
    _pad0: u32,
    dims: vec3<u32>,
    _pad1: u32,
}

@group(0) @binding(0) var source: texture_3d<f32>;
@group(0) @binding(1) var bricks: texture_storage_3d<rgba16float, write>;
// Storage, not uniform: see `params` in gaussian.wgsl (lavapipe's per-dispatch variants).
@group(0) @binding(2) var<storage, read> slices: Slices;

// The source texels of brick b: its voxels, or at a pooled level the blocks that hold them.
fn voxel_range(b: vec3<u32>) -> array<vec3<u32>, 2> {
    let n = slices.dims;
    let lo = b * BRICK;
    let hi = min(lo + vec3<u32>(BRICK), n - vec3<u32>(1u));
    let l = vec3<u32>(slices.level);
    return array<vec3<u32>, 2>(lo >> l, hi >> l);
}

@compute @workgroup_size(4, 4, 4)
fn bricks_intensity(@builtin(global_invocation_id) id: vec3<u32>) {
    let nb = textureDimensions(bricks);
    let gid = vec3<u32>(id.xy, id.z + slices.z0);
    if any(gid >= nb) || id.z >= slices.nz {
        return;
    }
    let r = voxel_range(gid);
    var hi = -3.0e38;
    var lo = 3.0e38;
    for (var k = r[0].z; k <= r[1].z; k = k + 1u) {
        for (var j = r[0].y; j <= r[1].y; j = j + 1u) {
            for (var i = r[0].x; i <= r[1].x; i = i + 1u) {
                let v = textureLoad(source, vec3<u32>(i, j, k), 0).r;
                hi = max(hi, v);
                lo = min(lo, v);
            }
        }
    }
    textureStore(bricks, gid, vec4<f32>(hi, lo, 0.0, 0.0));
}

@compute @workgroup_size(4, 4, 4)
fn bricks_features(@builtin(global_invocation_id) id: vec3<u32>) {
    let nb = textureDimensions(bricks);
    let gid = vec3<u32>(id.xy, id.z + slices.z0);
    if any(gid >= nb) || id.z >= slices.nz {
        return;
    }
    let r = voxel_range(gid);
    var hi = vec3<f32>(-3.0e38);
    for (var k = r[0].z; k <= r[1].z; k = k + 1u) {
        for (var j = r[0].y; j <= r[1].y; j = j + 1u) {
            for (var i = r[0].x; i <= r[1].x; i = i + 1u) {
                hi = max(hi, textureLoad(source, vec3<u32>(i, j, k), 0).rgb);
            }
        }
    }
    textureStore(bricks, gid, vec4<f32>(hi, 0.0));
}
