// Shape-encoding MIP ray caster (keep in sync with src/render/raycast/, whose `cpu_twin` follows
// this file line by line).
//
// One invocation per output pixel. The ray is marched in continuous voxel coordinates (the Rust
// side turns the orthographic camera's world rays into voxel space through the volume's
// voxel_from_world, so anisotropic and oblique volumes come out at their true shape), at
// t = k * step_mm for every integer k inside the volume's box [-0.5, n - 0.5] and the slab.
// Every sample is trilinear, done here with textureLoad (8 texels, borders replicated by
// clamping the position to [0, n - 1]), so the CPU twin can do exactly the same arithmetic.
//
// Per ray: the intensity MIP (or MinIP) and the MIP of each feature (V, A, B) with the depth t of
// each extreme (first along the ray on ties). Colour: grey = windowed intensity, then red (V),
// blue (A) and yellow (B) laid over it in that order, each with opacity clamp(F * scale, 0, 1).
// The pixel's depth is that of the channel contributing most to its colour (see `pick` below).
#import common.wgsl

struct Params {
    // Voxel coordinates of the centre of pixel (0, 0) at t = 0.
    origin_v: vec3<f32>,
    // Sample spacing along the ray, mm.
    step_mm: f32,
    // Voxel offset per pixel to the right.
    du_v: vec3<f32>,
    // Slab (depth range, mm) the samples must lie in.
    slab_lo: f32,
    // Voxel offset per pixel down.
    dv_v: vec3<f32>,
    slab_hi: f32,
    // Voxel offset per mm along the ray.
    dir_v: vec3<f32>,
    // 0 = MIP, 1 = MinIP (intensity only; features are always maxima).
    mode: u32,
    dims: vec3<u32>,
    // Bit 0: sample the feature texture. Bit 1: show the intensity (grey). Bit 2: hardware
    // trilinear filtering. Bit 3: skip bricks (bindings 6 and 7).
    flags: u32,
    // Opacity per unit feature value (gain / feature maximum; 0 = channel off).
    feature_scale: vec3<f32>,
    window_lo: f32,
    out_size: vec2<u32>,
    window_hi: f32,
    max_steps: u32,
    // First image row of this dispatch: a frame may be drawn in bands of rows over several
    // submissions (progressive rendering); each pixel's result does not depend on the band.
    row0: u32,
    // One past the last row of this dispatch.
    row_end: u32,
    // The feature texture's level: 0 a texel per voxel; L > 0 each texel the maximum of a block
    // of 2^L voxels per axis (max-pooled). A sample then takes the largest of the blocks its
    // eight voxels lie in: never below the full-resolution sample, so no maximum is lost.
    feature_level: u32,
    _pad1: u32,
}

// Storage, not uniform: see `params` in gaussian.wgsl (lavapipe's per-dispatch variants).
@group(0) @binding(0) var<storage, read> params: Params;
@group(0) @binding(1) var intensity: texture_3d<f32>;
@group(0) @binding(2) var features: texture_3d<f32>;
@group(0) @binding(3) var image: texture_storage_2d<rgba8unorm, write>;
// Per pixel: (depth t in mm of the dominant channel's extreme, channel): channel -1 = the ray
// missed the volume or the slab, 0 = intensity, 1 = vesselness, 2 = airwayness, 3 = blobness.
@group(0) @binding(4) var<storage, read_write> pick: array<vec2<f32>>;
// Linear, clamp-to-edge: the hardware trilinear path (flag bit 2).
@group(0) @binding(5) var linear_clamp: sampler;
// Brick extrema (raycast_bricks.wgsl): intensity (max, min), features (max V, max A, max B).
// Flag bit 3: skip bricks that cannot raise any running extreme (exact: a skipped sample could
// not have replaced one, as updates need a strictly larger value).
@group(0) @binding(6) var intensity_bricks: texture_3d<f32>;
@group(0) @binding(7) var feature_bricks: texture_3d<f32>;

const BIG: f32 = 3.0e38;
const BRICK: i32 = 8;

// The brick holding a sample (by its clamped position; on a face, either brick holds it).
fn brick_of(c: Cell) -> vec3<i32> {
    let nb = vec3<i32>(textureDimensions(intensity_bricks));
    return min(c.i0 / BRICK, nb - vec3<i32>(1));
}

// Where the ray o + t d leaves the region whose clamped positions lie in brick b.
fn brick_exit(o: vec3<f32>, d: vec3<f32>, b: vec3<i32>) -> f32 {
    let nb = vec3<i32>(textureDimensions(intensity_bricks));
    var te = BIG;
    for (var a = 0; a < 3; a = a + 1) {
        if d[a] > 1e-20 && b[a] < nb[a] - 1 {
            te = min(te, (f32((b[a] + 1) * BRICK) - o[a]) / d[a]);
        } else if d[a] < -1e-20 && b[a] > 0 {
            te = min(te, (f32(b[a] * BRICK) - o[a]) / d[a]);
        }
    }
    return te;
}

fn intensity_skippable(b: vec3<i32>, best_i: f32, minip: bool) -> bool {
    let bi = textureLoad(intensity_bricks, b, 0);
    if minip {
        return bi.y >= best_i;
    }
    return bi.x <= best_i;
}

// Only the channels shown count: a hidden channel's extreme never colours or picks.
fn features_skippable(b: vec3<i32>, best_f: vec3<f32>) -> bool {
    let bf = textureLoad(feature_bricks, b, 0);
    for (var ch = 0; ch < 3; ch = ch + 1) {
        if params.feature_scale[ch] > 0.0 && bf[ch] > best_f[ch] {
            return false;
        }
    }
    return true;
}

// The t interval of the ray o + t d inside the box [-0.5, n - 0.5] (empty if x > y).
fn box_interval(o: vec3<f32>, d: vec3<f32>) -> vec2<f32> {
    var t0 = -BIG;
    var t1 = BIG;
    for (var a = 0; a < 3; a = a + 1) {
        let lo = -0.5;
        let hi = f32(params.dims[a]) - 0.5;
        if abs(d[a]) < 1e-20 {
            if o[a] < lo || o[a] > hi {
                return vec2<f32>(1.0, 0.0);
            }
        } else {
            let ta = (lo - o[a]) / d[a];
            let tb = (hi - o[a]) / d[a];
            t0 = max(t0, min(ta, tb));
            t1 = min(t1, max(ta, tb));
        }
    }
    return vec2<f32>(t0, t1);
}

fn lerp1(a: f32, b: f32, t: f32) -> f32 {
    return a + (b - a) * t;
}

fn lerp4(a: vec4<f32>, b: vec4<f32>, t: f32) -> vec4<f32> {
    return a + (b - a) * t;
}

struct Cell {
    i0: vec3<i32>,
    i1: vec3<i32>,
    f: vec3<f32>,
}

fn cell_of(q: vec3<f32>) -> Cell {
    let top = vec3<f32>(params.dims - vec3<u32>(1u));
    let qc = clamp(q, vec3<f32>(0.0), top);
    let base = floor(qc);
    var c: Cell;
    c.i0 = vec3<i32>(base);
    c.i1 = min(c.i0 + vec3<i32>(1), vec3<i32>(params.dims - vec3<u32>(1u)));
    c.f = qc - base;
    return c;
}

// Bit 2 of flags: sample with the texture unit's trilinear filter instead of 8 textureLoads.
// Faster, but its interpolation weights are the hardware's (e.g. 8 bits on many GPUs), so the
// CPU twin matches only within a tolerance.
fn filtered() -> bool {
    return (params.flags & 4u) != 0u;
}

fn uvw_of(q: vec3<f32>) -> vec3<f32> {
    return (q + vec3<f32>(0.5)) / vec3<f32>(params.dims);
}

fn intensity_at(c: Cell, q: vec3<f32>) -> f32 {
    if filtered() {
        return textureSampleLevel(intensity, linear_clamp, uvw_of(q), 0.0).r;
    }
    let v000 = textureLoad(intensity, vec3<i32>(c.i0.x, c.i0.y, c.i0.z), 0).r;
    let v100 = textureLoad(intensity, vec3<i32>(c.i1.x, c.i0.y, c.i0.z), 0).r;
    let v010 = textureLoad(intensity, vec3<i32>(c.i0.x, c.i1.y, c.i0.z), 0).r;
    let v110 = textureLoad(intensity, vec3<i32>(c.i1.x, c.i1.y, c.i0.z), 0).r;
    let v001 = textureLoad(intensity, vec3<i32>(c.i0.x, c.i0.y, c.i1.z), 0).r;
    let v101 = textureLoad(intensity, vec3<i32>(c.i1.x, c.i0.y, c.i1.z), 0).r;
    let v011 = textureLoad(intensity, vec3<i32>(c.i0.x, c.i1.y, c.i1.z), 0).r;
    let v111 = textureLoad(intensity, vec3<i32>(c.i1.x, c.i1.y, c.i1.z), 0).r;
    let v00 = lerp1(v000, v100, c.f.x);
    let v10 = lerp1(v010, v110, c.f.x);
    let v01 = lerp1(v001, v101, c.f.x);
    let v11 = lerp1(v011, v111, c.f.x);
    return lerp1(lerp1(v00, v10, c.f.y), lerp1(v01, v11, c.f.y), c.f.z);
}

// A max-pooled level: the largest of the texels of the blocks holding the sample's 8 voxels.
fn pooled_features_at(c: Cell) -> vec4<f32> {
    let l = vec3<u32>(params.feature_level);
    let a = vec3<i32>(vec3<u32>(c.i0) >> l);
    let b = vec3<i32>(vec3<u32>(c.i1) >> l);
    var m = textureLoad(features, a, 0);
    m = max(m, textureLoad(features, vec3<i32>(b.x, a.y, a.z), 0));
    m = max(m, textureLoad(features, vec3<i32>(a.x, b.y, a.z), 0));
    m = max(m, textureLoad(features, vec3<i32>(b.x, b.y, a.z), 0));
    m = max(m, textureLoad(features, vec3<i32>(a.x, a.y, b.z), 0));
    m = max(m, textureLoad(features, vec3<i32>(b.x, a.y, b.z), 0));
    m = max(m, textureLoad(features, vec3<i32>(a.x, b.y, b.z), 0));
    m = max(m, textureLoad(features, b, 0));
    return m;
}

fn features_at(c: Cell, q: vec3<f32>) -> vec4<f32> {
    if params.feature_level > 0u {
        return pooled_features_at(c);
    }
    if filtered() {
        return textureSampleLevel(features, linear_clamp, uvw_of(q), 0.0);
    }
    let v000 = textureLoad(features, vec3<i32>(c.i0.x, c.i0.y, c.i0.z), 0);
    let v100 = textureLoad(features, vec3<i32>(c.i1.x, c.i0.y, c.i0.z), 0);
    let v010 = textureLoad(features, vec3<i32>(c.i0.x, c.i1.y, c.i0.z), 0);
    let v110 = textureLoad(features, vec3<i32>(c.i1.x, c.i1.y, c.i0.z), 0);
    let v001 = textureLoad(features, vec3<i32>(c.i0.x, c.i0.y, c.i1.z), 0);
    let v101 = textureLoad(features, vec3<i32>(c.i1.x, c.i0.y, c.i1.z), 0);
    let v011 = textureLoad(features, vec3<i32>(c.i0.x, c.i1.y, c.i1.z), 0);
    let v111 = textureLoad(features, vec3<i32>(c.i1.x, c.i1.y, c.i1.z), 0);
    let v00 = lerp4(v000, v100, c.f.x);
    let v10 = lerp4(v010, v110, c.f.x);
    let v01 = lerp4(v001, v101, c.f.x);
    let v11 = lerp4(v011, v111, c.f.x);
    return lerp4(lerp4(v00, v10, c.f.y), lerp4(v01, v11, c.f.y), c.f.z);
}

@compute @workgroup_size(8, 8, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let xy = vec2<u32>(gid.x, gid.y + params.row0);
    if xy.x >= params.out_size.x || xy.y >= min(params.out_size.y, params.row_end) {
        return;
    }
    let pixel = xy.x + params.out_size.x * xy.y;
    let o = params.origin_v + params.du_v * f32(xy.x) + params.dv_v * f32(xy.y);
    let d = params.dir_v;
    let span = box_interval(o, d);
    let t0 = max(span.x, params.slab_lo);
    let t1 = min(span.y, params.slab_hi);
    let k0 = i32(ceil(t0 / params.step_mm));
    let k1 = i32(floor(t1 / params.step_mm));
    let count = min(k1 - k0 + 1, i32(params.max_steps));
    if t0 > t1 || count <= 0 {
        // Missed: the background, white when the grey is inverted (a PET MIP's paper).
        var bg = 0.0;
        if (params.flags & 16u) != 0u && (params.flags & 2u) != 0u {
            bg = 1.0;
        }
        textureStore(image, vec2<i32>(xy), vec4<f32>(bg, bg, bg, 1.0));
        pick[pixel] = vec2<f32>(0.0, -1.0);
        return;
    }

    let minip = params.mode == 1u;
    let use_features = (params.flags & 1u) != 0u;
    var best_i = BIG;
    if !minip {
        best_i = -BIG;
    }
    var t_i = 0.0;
    var best_f = vec3<f32>(-BIG);
    var t_f = vec3<f32>(0.0);
    let skip = (params.flags & 8u) != 0u;
    var last_brick = vec3<i32>(-1);
    // Within the current brick: whether its intensity / features cannot raise the running
    // extremes, so their loads are skipped (exact: updates need a strictly larger value).
    var skip_i = false;
    var skip_f = false;
    var n = 0;
    loop {
        if n >= count {
            break;
        }
        let t = f32(k0 + n) * params.step_mm;
        let q = o + d * t;
        let c = cell_of(q);
        if skip {
            let b = brick_of(c);
            if any(b != last_brick) {
                last_brick = b;
                skip_i = intensity_skippable(b, best_i, minip);
                skip_f = !use_features || features_skippable(b, best_f);
                if skip_i && skip_f {
                    // Jump to the last sample still inside the brick (a margin keeps rounding
                    // from skipping a sample beyond it).
                    let te = min(brick_exit(o, d, b), t1) - 0.01 * params.step_mm;
                    let next = i32(floor(te / params.step_mm)) - k0;
                    if next > n {
                        n = next;
                        continue;
                    }
                }
            }
        }
        if !skip_i {
            let v = intensity_at(c, q);
            if minip {
                if v < best_i {
                    best_i = v;
                    t_i = t;
                }
            } else if v > best_i {
                best_i = v;
                t_i = t;
            }
        }
        if use_features && !skip_f {
            let f = features_at(c, q);
            if f.x > best_f.x {
                best_f.x = f.x;
                t_f.x = t;
            }
            if f.y > best_f.y {
                best_f.y = f.y;
                t_f.y = t;
            }
            if f.z > best_f.z {
                best_f.z = f.z;
                t_f.z = t;
            }
        }
        n = n + 1;
    }

    var g = window01(best_i, params.window_lo, params.window_hi);
    if (params.flags & 2u) == 0u {
        g = 0.0;
    }
    var a = vec3<f32>(0.0);
    if use_features {
        a = clamp(best_f * params.feature_scale, vec3<f32>(0.0), vec3<f32>(1.0));
    }
    // Bit 4 of flags: the grey drawn inverted (a PET MIP); `g` keeps its meaning for picks.
    var grey = g;
    if (params.flags & 16u) != 0u && (params.flags & 2u) != 0u {
        grey = 1.0 - g;
    }
    var rgb = vec3<f32>(grey);
    rgb = rgb + (vec3<f32>(1.0, 0.0, 0.0) - rgb) * a.x;
    rgb = rgb + (vec3<f32>(0.0, 0.4, 1.0) - rgb) * a.y;
    rgb = rgb + (vec3<f32>(1.0, 1.0, 0.0) - rgb) * a.z;
    textureStore(image, vec2<i32>(xy), vec4<f32>(rgb, 1.0));

    // The dominant channel: the largest share of the final colour. Yellow lies on top with
    // share a.z, blue under it a.y (1 - a.z), red a.x (1 - a.y) (1 - a.z), grey the rest times
    // its visibility (brightness for a MIP, darkness for a MinIP). Ties go to the earlier
    // channel, intensity first.
    var vis = g;
    if minip {
        vis = 1.0 - g;
    }
    if (params.flags & 2u) == 0u {
        vis = 0.0;
    }
    let w3 = a.z;
    let w2 = a.y * (1.0 - a.z);
    let w1 = a.x * (1.0 - a.y) * (1.0 - a.z);
    let w0 = vis * (1.0 - a.x) * (1.0 - a.y) * (1.0 - a.z);
    var best_w = w0;
    var channel = 0.0;
    var depth = t_i;
    if w1 > best_w {
        best_w = w1;
        channel = 1.0;
        depth = t_f.x;
    }
    if w2 > best_w {
        best_w = w2;
        channel = 2.0;
        depth = t_f.y;
    }
    if w3 > best_w {
        best_w = w3;
        channel = 3.0;
        depth = t_f.z;
    }
    pick[pixel] = vec2<f32>(depth, channel);
}
