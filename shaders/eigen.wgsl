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
// division by it. The trigonometric argument is clamped to [-1, 1] (near-repeated roots), and
// the trigonometric values are refined (see eigenvalues_unsorted) so that near-repeated roots
// keep f32 accuracy.

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

// Eigenvalues of the symmetric matrix (d, o), unsorted.
//
// Smith's trigonometric method gives all three (q + 2p cos(acos(r)/3 + 2 pi m/3)), as on the
// CPU. In f32 that alone loses accuracy: GPUs' acos/cos are approximations (~1e-5 relative on
// lavapipe), and near a double root (tubes: l0 ~ l1; spheres: all three) the roots of the cubic
// move with the square root of the rounding error of its coefficients (~3e-4). So the
// trigonometric values only locate the most isolated eigenvalue; then (Kopp's hybrid method)
// its eigenvector v comes from the cross products of the rows of A - lI, the eigenvalue is the
// Rayleigh quotient v^T A v (error quadratic in v's error), and the other two are those of the
// 2x2 matrix A restricted to the plane orthogonal to v, in closed form without cancellation.
// Every step is then accurate to ~1e-7 of the largest entry.
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
    // ea >= eb >= ec.
    let ea = q + 2.0 * p * cos(phi);
    let ec = q + 2.0 * p * cos(phi + EIGEN_TWO_PI_3);
    let eb = 3.0 * q - ea - ec;
    var lam = ea;
    if ea - eb < eb - ec {
        lam = ec;
    }
    // Eigenvector of lam: the largest cross product of two rows of A - lam I.
    let r0 = vec3<f32>(d.x - lam, o.x, o.y);
    let r1 = vec3<f32>(o.x, d.y - lam, o.z);
    let r2 = vec3<f32>(o.y, o.z, d.z - lam);
    let c01 = cross(r0, r1);
    let c02 = cross(r0, r2);
    let c12 = cross(r1, r2);
    let n01 = dot(c01, c01);
    let n02 = dot(c02, c02);
    let n12 = dot(c12, c12);
    var v = c01;
    var nv = n01;
    if n02 > nv {
        v = c02;
        nv = n02;
    }
    if n12 > nv {
        v = c12;
        nv = n12;
    }
    if !(nv > 1e-30) {
        // A is (numerically) a multiple of I along every direction: any basis will do.
        v = vec3<f32>(1.0, 0.0, 0.0);
        nv = 1.0;
    }
    v = v * inverseSqrt(nv);
    // An orthonormal basis (v, u, w): u from the axis least aligned with v.
    let av = abs(v);
    var axis = vec3<f32>(1.0, 0.0, 0.0);
    if av.y <= av.x && av.y <= av.z {
        axis = vec3<f32>(0.0, 1.0, 0.0);
    } else if av.z <= av.x && av.z <= av.y {
        axis = vec3<f32>(0.0, 0.0, 1.0);
    }
    let u = normalize(cross(v, axis));
    let w = cross(v, u);
    let amul = mat3x3<f32>(
        vec3<f32>(d.x, o.x, o.y),
        vec3<f32>(o.x, d.y, o.z),
        vec3<f32>(o.y, o.z, d.z),
    );
    let l_iso = dot(v, amul * v);
    let au = amul * u;
    let aw = amul * w;
    let m00 = dot(u, au);
    let m01 = dot(u, aw);
    let m11 = dot(w, aw);
    let mid = 0.5 * (m00 + m11);
    let half = length(vec2<f32>(0.5 * (m00 - m11), m01));
    return vec3<f32>(l_iso, mid + half, mid - half) * s;
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
