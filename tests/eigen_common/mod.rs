//! Random hard symmetric 3x3 matrices for the eigenvalue solvers' tests (tests/cpu/eigen.rs,
//! tests/gpu/eigen.rs), and how a solver's answer is scored against the f64 Jacobi reference.
#![allow(dead_code)]

/// A seeded generator (splitmix64), the same numbers on every platform.
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Self {
        Self(seed)
    }

    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    /// Uniform in [0, 1).
    pub fn unit(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Uniform in [lo, hi).
    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.unit()
    }

    /// +1 or -1.
    pub fn sign(&mut self) -> f64 {
        if self.next_u64() & 1 == 0 { 1.0 } else { -1.0 }
    }

    /// 10^u with u uniform in [lo, hi).
    pub fn log_uniform(&mut self, lo: f64, hi: f64) -> f64 {
        10f64.powf(self.range(lo, hi))
    }
}

/// `R diag(d) R^T` as `[xx, yy, zz, xy, xz, yz]`.
fn rotate(d: [f64; 3], r: [[f64; 3]; 3]) -> [f64; 6] {
    let a = |i: usize, j: usize| (0..3).map(|k| r[i][k] * d[k] * r[j][k]).sum::<f64>();
    [a(0, 0), a(1, 1), a(2, 2), a(0, 1), a(0, 2), a(1, 2)]
}

/// A rotation: uniform over SO(3) mostly (a random unit quaternion), but also about one
/// coordinate axis only (block-diagonal matrices with exact zeros, as in flat regions of a
/// scan) and the identity (diagonal matrices).
fn rotation(rng: &mut Rng) -> [[f64; 3]; 3] {
    match rng.next_u64() % 16 {
        0 => [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        1..=3 => {
            let axis = (rng.next_u64() % 3) as usize;
            let (s, c) = rng.range(0.0, std::f64::consts::TAU).sin_cos();
            let (p, q) = ((axis + 1) % 3, (axis + 2) % 3);
            let mut m = [[0.0; 3]; 3];
            m[axis][axis] = 1.0;
            m[p][p] = c;
            m[p][q] = -s;
            m[q][p] = s;
            m[q][q] = c;
            m
        }
        _ => {
            // Marsaglia: a uniform unit quaternion.
            let (u1, u2, u3) = (rng.unit(), rng.unit(), rng.unit());
            let (a, b) = ((1.0 - u1).sqrt(), u1.sqrt());
            let t2 = std::f64::consts::TAU * u2;
            let t3 = std::f64::consts::TAU * u3;
            let (w, x, y, z) = (a * t2.sin(), a * t2.cos(), b * t3.sin(), b * t3.cos());
            [
                [
                    1.0 - 2.0 * (y * y + z * z),
                    2.0 * (x * y - z * w),
                    2.0 * (x * z + y * w),
                ],
                [
                    2.0 * (x * y + z * w),
                    1.0 - 2.0 * (x * x + z * z),
                    2.0 * (y * z - x * w),
                ],
                [
                    2.0 * (x * z - y * w),
                    2.0 * (y * z + x * w),
                    1.0 - 2.0 * (x * x + y * y),
                ],
            ]
        }
    }
}

/// Eigenvalues of a hard kind, times an overall scale 10^(-6..6): spread out; near-double
/// roots of the same sign (tubes) or of opposite signs (magnitude ties), by 1e-9..1e-2;
/// near-triple roots (spheres); exact repeats; a zero; a wide range within one matrix
/// (1 : 1e-7). The matrix is then rotated (see [`rotation`]).
pub fn hard_eigenvalues(rng: &mut Rng) -> [f64; 3] {
    let scale = rng.log_uniform(-6.0, 6.0);
    let a = rng.range(-1.0, 1.0);
    let eps = |rng: &mut Rng| rng.sign() * rng.log_uniform(-9.0, -2.0);
    let d = match rng.next_u64() % 8 {
        0 | 1 => [a, rng.range(-1.0, 1.0), rng.range(-1.0, 1.0)],
        2 => [a, a * (1.0 + eps(rng)), rng.range(-1.0, 1.0)],
        3 => [a, -a * (1.0 + eps(rng)), rng.range(-1.0, 1.0)],
        4 => [a, a * (1.0 + eps(rng)), a * (1.0 + eps(rng))],
        5 => match rng.next_u64() % 4 {
            0 => [a, a, rng.range(-1.0, 1.0)],
            1 => [a, -a, 0.0],
            2 => [a, a, a],
            _ => [a, 0.0, 0.0],
        },
        _ => [
            a,
            rng.sign() * rng.log_uniform(-7.0, 0.0) * a.abs(),
            rng.sign() * rng.log_uniform(-7.0, 0.0) * a.abs(),
        ],
    };
    d.map(|x| x * scale)
}

/// A random hard symmetric matrix `[xx, yy, zz, xy, xz, yz]`.
pub fn hard_matrix(rng: &mut Rng) -> [f64; 6] {
    let d = hard_eigenvalues(rng);
    let r = rotation(rng);
    rotate(d, r)
}

/// Error of eigenvalues `got` against the reference `want` (both sorted by magnitude), as a
/// fraction of the largest |eigenvalue| of `want`: compared as sets sorted by value, since a
/// magnitude tie of opposite signs may sort either way within rounding. 0 for a zero matrix
/// answered with zeros.
pub fn relative_error(got: [f64; 3], want: [f64; 3]) -> f64 {
    let mut g = got;
    let mut w = want;
    g.sort_by(f64::total_cmp);
    w.sort_by(f64::total_cmp);
    let err = (0..3).map(|c| (g[c] - w[c]).abs()).fold(0.0, f64::max);
    let big = w.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    if got.iter().any(|x| x.is_nan()) {
        f64::INFINITY
    } else if big > 0.0 {
        err / big
    } else {
        err
    }
}

/// Whether `l` is sorted by decreasing magnitude (the contract of both solvers).
pub fn sorted_by_magnitude(l: [f64; 3]) -> bool {
    l[0].abs() >= l[1].abs() && l[1].abs() >= l[2].abs()
}
