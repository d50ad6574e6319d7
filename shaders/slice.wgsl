// One slice of the volume for the slice panes (keep in sync with src/render/slice.rs and its CPU
// twin `cpu_twin`): the intensity windowed to grey, optionally overlaid with one method's
// features as the MIP composites them: over the grey, in this order, red = vesselness, blue =
// airwayness, yellow = blobness, each with opacity clamp(value * scale, 0, 1) * overlay opacity. Output pixel (x, y) is the voxel with
// `across` index x and `vertical` index y on slice `index` of the `fixed` axis; the pane flips
// the image for patient orientation when it draws it.
#import common.wgsl

struct Params {
    dims: vec3<u32>,
    fixed_axis: u32,
    across_axis: u32,
    vertical_axis: u32,
    index: u32,
    // 1: blend the features in; 0: grey only.
    overlay: u32,
    out_size: vec2<u32>,
    window_lo: f32,
    window_hi: f32,
    // Per feature (V, A, B): opacity = clamp(value * scale, 0, 1) * scale.w; 0 switches it off.
    scale: vec4<f32>,
    // The feature texture's level: L > 0 reads the max-pooled texel of the voxel's block.
    feature_level: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

// Storage, not uniform: see `params` in gaussian.wgsl (lavapipe's per-dispatch variants).
@group(0) @binding(0) var<storage, read> params: Params;
@group(0) @binding(1) var intensity: texture_3d<f32>;
@group(0) @binding(2) var features: texture_3d<f32>;
@group(0) @binding(3) var image: texture_storage_2d<rgba8unorm, write>;

// The MIP's colours (render::raycast::CHANNEL_COLOURS).
const VESSEL_RGB: vec3<f32> = vec3<f32>(1.0, 0.0, 0.0);
const AIRWAY_RGB: vec3<f32> = vec3<f32>(0.0, 0.4, 1.0);
const BLOB_RGB: vec3<f32> = vec3<f32>(1.0, 1.0, 0.0);

@compute @workgroup_size(8, 8, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= params.out_size.x || gid.y >= params.out_size.y {
        return;
    }
    var p = vec3<u32>(0u, 0u, 0u);
    p[params.fixed_axis] = params.index;
    p[params.across_axis] = gid.x;
    p[params.vertical_axis] = gid.y;
    let v = textureLoad(intensity, vec3<i32>(p), 0).r;
    let g = window01(v, params.window_lo, params.window_hi);
    var rgb = vec3<f32>(g, g, g);
    if params.overlay == 1u {
        let f = textureLoad(features, vec3<i32>(p >> vec3<u32>(params.feature_level)), 0).xyz;
        let a = clamp(f * params.scale.xyz, vec3<f32>(0.0), vec3<f32>(1.0)) * params.scale.w;
        rgb = rgb + (VESSEL_RGB - rgb) * a.x;
        rgb = rgb + (AIRWAY_RGB - rgb) * a.y;
        rgb = rgb + (BLOB_RGB - rgb) * a.z;
    }
    textureStore(image, vec2<i32>(gid.xy), vec4<f32>(rgb, 1.0));
}
