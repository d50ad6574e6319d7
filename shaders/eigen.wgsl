// Closed-form eigenvalues of a symmetric 3x3 matrix, sorted by magnitude |l0| >= |l1| >= |l2|
// (ties: the more negative first). The twin is src/cpu/eigen.rs (same algorithm, in f64 there).
// Pure functions; import with `#import eigen.wgsl`.
//
// A symmetric matrix is passed as two vectors: d = (xx, yy, zz) and o = (xy, xz, yz).
//
// f32 care: the matrix is first divided by its largest absolute entry (so nothing overflows or
// underflows in the squares and the determinant, whatever the units), and a matrix whose
// off-diagonal part is below 1e-12 of that entry is treated as diagonal (Weyl: the eigenvalues
// then move by less than 1e-12 of the largest entry), which also keeps p away from 0 before the
// division by it. The trigonometric argument is clamped to [-1, 1] (near-repeated roots).

const EIGEN_TWO_PI_3: f32 = 2.0943951023931953;

// True when x sorts before y: larger magnitude first, the more negative first on a tie.
fn eigen_before(x: f32, y: f32) -> bool {
    return abs(x) > abs(y) || (abs(x) == abs(y) && x < y);
}

// The three values sorted by decreasing magnitude.
fn eigen_sort_by_magnitude(e: vec3<f32>) -> vec3<f32> {
    var a = e.x;
    var b = e.y;
    var c = e.z;
    if eigen_before(b, a) { let t = a; a = b; b = t; }
    if eigen_before(c, b) { let t = b; b = c; c = t; }
    if eigen_before(b, a) { let t = a; a = b; b = t; }
    return vec3<f32>(a, b, c);
}

// Eigenvalues of the symmetric matrix (d, o), unsorted (Smith's trigonometric method).
fn eigenvalues_unsorted(d_in: vec3<f32>, o_in: vec3<f32>) -> vec3<f32> {
    let s = max(max(max(abs(d_in.x), abs(d_in.y)), max(abs(d_in.z), abs(o_in.x))),
                max(abs(o_in.y), abs(o_in.z)));
    if !(s > 0.0) {
        // All zero (or NaN input, which stays NaN through the sum below).
        return d_in + o_in * 0.0;
    }
    let d = d_in / s;
    let o = o_in / s;
    let p1 = dot(o, o);
    if p1 < 1e-24 {
        return d * s;
    }
    let q = (d.x + d.y + d.z) / 3.0;
    let dq = d - vec3<f32>(q);
    let p2 = dot(dq, dq) + 2.0 * p1;
    let p = sqrt(p2 / 6.0);
    let b = dq / p;
    let bo = o / p;
    // det(B) with B = (A - qI) / p; bo = (b01, b02, b12).
    let det = b.x * (b.y * b.z - bo.z * bo.z)
        - bo.x * (bo.x * b.z - bo.z * bo.y)
        + bo.y * (bo.x * bo.z - b.y * bo.y);
    let r = clamp(det * 0.5, -1.0, 1.0);
    let phi = acos(r) / 3.0;
    let e0 = q + 2.0 * p * cos(phi);
    let e2 = q + 2.0 * p * cos(phi + EIGEN_TWO_PI_3);
    let e1 = 3.0 * q - e0 - e2;
    return vec3<f32>(e0, e1, e2) * s;
}

// Eigenvalues (l0, l1, l2) of the symmetric matrix (d, o), |l0| >= |l1| >= |l2|.
fn eigenvalues_sorted(d: vec3<f32>, o: vec3<f32>) -> vec3<f32> {
    return eigen_sort_by_magnitude(eigenvalues_unsorted(d, o));
}

// Frobenius norm of the symmetric matrix (d, o), scaled so that no square overflows.
fn sym_frobenius(d: vec3<f32>, o: vec3<f32>) -> f32 {
    let s = max(max(max(abs(d.x), abs(d.y)), max(abs(d.z), abs(o.x))),
                max(abs(o.y), abs(o.z)));
    if !(s > 0.0) {
        return s;
    }
    let ds = d / s;
    let os = o / s;
    return s * sqrt(dot(ds, ds) + 2.0 * dot(os, os));
}
