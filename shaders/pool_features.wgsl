#import rgb9e5.wgsl
#import feature_stats.wgsl

// Packs a block of features (3 components, component-major f32, as pack_features.wgsl takes
// them) into a max-pooled level of a method's feature texture (level L: texel m holds, per channel, the maximum over the voxels m * 2^L .. (m + 1) * 2^L - 1 per axis). One
// invocation per pooled texel of the chunk's box; it takes the maximum over its block's voxels
// that lie in the box, and the texel's value already in the texture (a block the box cuts was
// partly written by the brick or chunk before; the texture starts at 0 and features are never
// negative, so the maximum of both is the block's), encoded rounding up (`encode_rgb9e5_up`:
// never below any voxel's full-resolution texel, and a texel read back re-encodes to itself).
// The maxima and histograms count every voxel
// of the box once, as `main` does, so the default gains do not depend on the level. Twin:
// src/gpu/volume_texture/pool.rs.

struct PoolParams {
    out_dims: vec3<u32>, // pooled texels written: staging box, at (0, out_y0, out_z0)
    level: u32,
    src_dims: vec3<u32>, // the source block
    src_y0: u32,         // first source row of the box
    box_y0: u32,         // voxel row of the box's first row
    box_ny: u32,
    box_z0: u32,         // voxel slice of this chunk's first slice
    box_nz: u32,         // slices of this chunk
    src_z0: u32,         // first source slice of this chunk
    out_y0: u32,         // pooled row of staging row 0
    out_z0: u32,         // pooled slice of staging slice 0
    pitch: u32,          // staging texels per row
    box_nx: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

@group(0) @binding(0) var<storage, read> pp: PoolParams;
@group(0) @binding(1) var<storage, read> src: array<f32>;
@group(0) @binding(2) var<storage, read_write> dst: array<u32>;
// binding 3: the maxima and histograms (feature_stats.wgsl).
@group(0) @binding(4) var existing: texture_3d<f32>;

@compute @workgroup_size(8, 8, 1)
fn pool(@builtin(global_invocation_id) id: vec3<u32>, @builtin(local_invocation_index) li: u32) {
    stats_begin(li);
    if all(id < pp.out_dims) {
        let f = 1u << pp.level;
        let s = pp.src_dims;
        let n = s.x * s.y * s.z;
        let at = vec3<u32>(id.x, id.y + pp.out_y0, id.z + pp.out_z0);
        let lo = max(at * f, vec3<u32>(0u, pp.box_y0, pp.box_z0));
        let hi = min(at * f + vec3<u32>(f), vec3<u32>(pp.box_nx, pp.box_y0 + pp.box_ny, pp.box_z0 + pp.box_nz));
        var m = textureLoad(existing, vec3<i32>(at), 0).xyz;
        for (var z = lo.z; z < hi.z; z++) {
            for (var y = lo.y; y < hi.y; y++) {
                for (var x = lo.x; x < hi.x; x++) {
                    let idx = x + s.x * (y - pp.box_y0 + pp.src_y0 + s.y * (z - pp.box_z0 + pp.src_z0));
                    let v = vec3<f32>(
                        finite_or_zero(src[idx]),
                        finite_or_zero(src[n + idx]),
                        finite_or_zero(src[2u * n + idx]),
                    );
                    m = max(m, v);
                    stats_count(v);
                }
            }
        }
        dst[id.x + pp.pitch * (id.y + pp.out_dims.y * id.z)] = encode_rgb9e5_up(m);
    }
    stats_end(li);
}
