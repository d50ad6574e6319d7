// Eigenvalue feature maps (twin: src/cpu/features.rs and src/cpu/structure_tensor.rs). Input:
// eigenvalues l = (l0, l1, l2) sorted by magnitude (eigen.wgsl); output (V, A, B) =
// (vesselness, airwayness, blobness). Pure functions; import with `#import feature_maps.wgsl`.

// Which map `map_features` applies (the same numbers in src/compute/eigen_features.rs).
const MAP_SIMPLE: u32 = 0u;  // paper eq. 1
const MAP_LI: u32 = 1u;      // paper eq. 2 (Li et al. 2003)
const MAP_FRANGI: u32 = 2u;  // Frangi 1998: V bright tubes, A dark tubes, B = 0

// Paper eq. 1: V = |l1| if l0, l1 < 0; A = |l1| if l0, l1 > 0; B = |l2| if l0, l1, l2 < 0.
fn map_simple(l: vec3<f32>) -> vec3<f32> {
    let a = abs(l);
    let bright_tube = l.x < 0.0 && l.y < 0.0;
    let dark_tube = l.x > 0.0 && l.y > 0.0;
    let bright_blob = bright_tube && l.z < 0.0;
    return vec3<f32>(
        select(0.0, a.y, bright_tube),
        select(0.0, a.y, dark_tube),
        select(0.0, a.z, bright_blob),
    );
}

// Paper eq. 2: V = |l1|(|l1| - |l2|)/|l0| (l0, l1 < 0), A the same for l0, l1 > 0,
// B = |l2|^2/|l0| (all three < 0).
fn map_li(l: vec3<f32>) -> vec3<f32> {
    let a = abs(l);
    let bright_tube = l.x < 0.0 && l.y < 0.0;
    let dark_tube = l.x > 0.0 && l.y > 0.0;
    let bright_blob = bright_tube && l.z < 0.0;
    // |l0| > 0 whenever one of the conditions holds (it is the largest magnitude); the
    // division is guarded for the other voxels (select evaluates both sides).
    let inv0 = select(0.0, 1.0 / a.x, a.x > 0.0);
    let tube = a.y * (a.y - a.z) * inv0;
    let blob = a.z * (a.z * inv0);
    return vec3<f32>(
        select(0.0, tube, bright_tube),
        select(0.0, tube, dark_tube),
        select(0.0, blob, bright_blob),
    );
}

// Frangi's vesselness (alpha = beta = 0.5) for bright tubes (l0, l1 < 0) or dark ones
// (l0, l1 > 0); c is the structureness scale (c <= 0: that factor is 1, as the CPU's
// c^2 = MIN_POSITIVE gives).
fn frangi(l: vec3<f32>, c: f32, bright: bool) -> f32 {
    var right_sign = l.x > 0.0 && l.y > 0.0;
    if bright {
        right_sign = l.x < 0.0 && l.y < 0.0;
    }
    if !right_sign {
        return 0.0;
    }
    // alpha = beta = 0.5: 2 alpha^2 = 2 beta^2 = 0.5.
    let ra = l.y / l.x;
    let ra2 = ra * ra;
    // l2^2 / |l0 l1| without forming the product (no overflow).
    let rb2 = abs((l.z / l.x) * (l.z / l.y));
    let s2 = dot(l, l);
    var structure = 1.0;
    if c > 0.0 {
        structure = 1.0 - exp(-s2 / (2.0 * c * c));
    }
    return (1.0 - exp(-ra2 / 0.5)) * exp(-rb2 / 0.5) * structure;
}

// (V, A, B) = (Frangi bright, Frangi dark, 0).
fn map_frangi(l: vec3<f32>, c: f32) -> vec3<f32> {
    return vec3<f32>(frangi(l, c, true), frangi(l, c, false), 0.0);
}

// The map `map` (MAP_SIMPLE, MAP_LI, MAP_FRANGI with scale c) of eigenvalues l.
fn map_features(l: vec3<f32>, map: u32, c: f32) -> vec3<f32> {
    switch map {
        case 0u: { return map_simple(l); }
        case 1u: { return map_li(l); }
        default: { return map_frangi(l, c); }
    }
}

// The general structure tensor's mapping: its eigenvalues are never negative, so they are
// mapped as a bright structure's would be, i.e. the map applied to -l (B = the third
// eigenvalue, as in the paper's fig. 6d). `map` is MAP_SIMPLE or MAP_LI.
fn map_gst(l: vec3<f32>, map: u32, c: f32) -> vec3<f32> {
    return map_features(-l, map, c);
}
