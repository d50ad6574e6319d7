//! Closed-form eigenvalues of a symmetric 3x3 matrix (trigonometric solution of the cubic),
//! sorted by magnitude as the paper orders them: |l0| >= |l1| >= |l2|.

/// A symmetric 3x3 matrix as its six distinct entries `[xx, yy, zz, xy, xz, yz]`.
pub type Sym3 = [f64; 6];

/// Eigenvalues of a symmetric matrix, sorted by decreasing magnitude (ties keep the more
/// negative first, so the order is deterministic).
///
/// Smith's trigonometric method: with `q = tr/3`, `p = sqrt(tr((A - qI)^2) / 6)` and
/// `r = det((A - qI) / p) / 2`, the roots are `q + 2p cos(acos(r)/3 + 2 pi m / 3)`, m = 0, 1, 2.
pub fn eigenvalues_sorted(m: &Sym3) -> [f64; 3] {
    let [a00, a11, a22, a01, a02, a12] = *m;
    let p1 = a01 * a01 + a02 * a02 + a12 * a12;
    let mut e = if p1 == 0.0 {
        [a00, a11, a22]
    } else {
        let q = (a00 + a11 + a22) / 3.0;
        let p2 = (a00 - q).powi(2) + (a11 - q).powi(2) + (a22 - q).powi(2) + 2.0 * p1;
        let p = (p2 / 6.0).sqrt();
        let (b00, b11, b22) = ((a00 - q) / p, (a11 - q) / p, (a22 - q) / p);
        let (b01, b02, b12) = (a01 / p, a02 / p, a12 / p);
        let det = b00 * (b11 * b22 - b12 * b12) - b01 * (b01 * b22 - b12 * b02)
            + b02 * (b01 * b12 - b11 * b02);
        // Rounding can push |r| a hair past 1 for (nearly) repeated roots.
        let r = (det / 2.0).clamp(-1.0, 1.0);
        let phi = r.acos() / 3.0;
        let e0 = q + 2.0 * p * phi.cos();
        let e2 = q + 2.0 * p * (phi + 2.0 * std::f64::consts::PI / 3.0).cos();
        let e1 = 3.0 * q - e0 - e2;
        [e0, e1, e2]
    };
    e.sort_by(|x, y| y.abs().total_cmp(&x.abs()).then(x.total_cmp(y)));
    e
}

/// Eigenvalues by the cyclic Jacobi method in f64, sorted as [`eigenvalues_sorted`] sorts them:
/// the slow, independent reference the closed forms (this file's and eigen.wgsl's) are tested
/// against. Each rotation zeroes one off-diagonal entry; sweeps repeat until the off-diagonal
/// part is below f64 resolution of the diagonal (quadratic convergence: ~5 sweeps), at most 50.
pub fn eigenvalues_jacobi(m: &Sym3) -> [f64; 3] {
    let [a00, a11, a22, a01, a02, a12] = *m;
    let mut a = [[a00, a01, a02], [a01, a11, a12], [a02, a12, a22]];
    for _ in 0..50 {
        let off = a[0][1].abs() + a[0][2].abs() + a[1][2].abs();
        let diag = a[0][0].abs() + a[1][1].abs() + a[2][2].abs();
        if off == 0.0 || off <= 1e-18 * diag {
            break;
        }
        for (p, q) in [(0, 1), (0, 2), (1, 2)] {
            if a[p][q] == 0.0 {
                continue;
            }
            // Rotation angle from cot(2 theta) = (a_qq - a_pp) / (2 a_pq), the smaller root.
            let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
            let t = if theta.is_finite() {
                theta.signum() / (theta.abs() + theta.hypot(1.0))
            } else {
                0.0
            };
            let t = if theta == 0.0 { 1.0 } else { t };
            let c = 1.0 / t.hypot(1.0);
            let s = t * c;
            for row in a.iter_mut() {
                let (kp, kq) = (row[p], row[q]);
                row[p] = c * kp - s * kq;
                row[q] = s * kp + c * kq;
            }
            let (rp, rq) = (a[p], a[q]);
            a[p] = std::array::from_fn(|k| c * rp[k] - s * rq[k]);
            a[q] = std::array::from_fn(|k| s * rp[k] + c * rq[k]);
        }
    }
    let mut e = [a[0][0], a[1][1], a[2][2]];
    e.sort_by(|x, y| y.abs().total_cmp(&x.abs()).then(x.total_cmp(y)));
    e
}

/// Frobenius norm of a symmetric matrix.
pub fn frobenius(m: &Sym3) -> f64 {
    (m[0] * m[0] + m[1] * m[1] + m[2] * m[2] + 2.0 * (m[3] * m[3] + m[4] * m[4] + m[5] * m[5]))
        .sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn diagonal_sorted_by_magnitude() {
        assert_eq!(
            eigenvalues_sorted(&[1.0, -3.0, 2.0, 0.0, 0.0, 0.0]),
            [-3.0, 2.0, 1.0]
        );
    }

    #[test]
    fn rotated_matrix_matches_known_eigenvalues() {
        // R diag(-5, 2, 0.5) R^T with R a rotation about z by 30 degrees, then about x by 40.
        let (c1, s1) = (30f64.to_radians().cos(), 30f64.to_radians().sin());
        let (c2, s2) = (40f64.to_radians().cos(), 40f64.to_radians().sin());
        let rz = [[c1, -s1, 0.0], [s1, c1, 0.0], [0.0, 0.0, 1.0]];
        let rx = [[1.0, 0.0, 0.0], [0.0, c2, -s2], [0.0, s2, c2]];
        let mut r = [[0.0; 3]; 3];
        for i in 0..3 {
            for j in 0..3 {
                r[i][j] = (0..3).map(|k| rx[i][k] * rz[k][j]).sum();
            }
        }
        let d = [-5.0, 2.0, 0.5];
        let a = |i: usize, j: usize| (0..3).map(|k| r[i][k] * d[k] * r[j][k]).sum::<f64>();
        let e = eigenvalues_sorted(&[a(0, 0), a(1, 1), a(2, 2), a(0, 1), a(0, 2), a(1, 2)]);
        for (x, y) in e.iter().zip(d) {
            assert!((x - y).abs() < 1e-12, "{e:?}");
        }
    }

    #[test]
    fn repeated_roots_are_stable() {
        let e = eigenvalues_sorted(&[-2.0, -2.0, -2.0, 1e-17, 0.0, 0.0]);
        for x in e {
            assert!((x + 2.0).abs() < 1e-9, "{e:?}");
        }
    }
}
