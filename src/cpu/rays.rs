//! The ray direction sets of the RST (paper section 4.1, docs/science.md RST item 2): 42 vertices of
//! a once-subdivided icosahedron, and 26, 98, 218, 386 directions to the surface cells of a
//! k x k x k cube (k = 3, 5, 7, 9).

/// The counts [`ray_set`] offers.
pub const RAY_COUNTS: [usize; 5] = [26, 42, 98, 218, 386];

/// Unit ray directions for `count` rays, or `None` if `count` is not one of [`RAY_COUNTS`].
/// The order is fixed (GPU kernels upload the same list).
pub fn ray_set(count: usize) -> Option<Vec<[f64; 3]>> {
    match count {
        42 => Some(icosahedron_subdivided()),
        26 => Some(cube_surface(3)),
        98 => Some(cube_surface(5)),
        218 => Some(cube_surface(7)),
        386 => Some(cube_surface(9)),
        _ => None,
    }
}

fn normalise(v: [f64; 3]) -> [f64; 3] {
    let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    v.map(|c| c / n)
}

/// 12 icosahedron vertices plus the 30 edge midpoints pushed onto the unit sphere.
fn icosahedron_subdivided() -> Vec<[f64; 3]> {
    let phi = (1.0 + 5f64.sqrt()) / 2.0;
    let mut v: Vec<[f64; 3]> = Vec::with_capacity(42);
    for a in [-1.0, 1.0] {
        for b in [-phi, phi] {
            v.push([0.0, a, b]);
            v.push([a, b, 0.0]);
            v.push([b, 0.0, a]);
        }
    }
    let vertices: Vec<[f64; 3]> = v.iter().map(|&p| normalise(p)).collect();
    // Edges join vertices at the minimal distance (2 before normalisation).
    let mut out = vertices.clone();
    for i in 0..v.len() {
        for j in i + 1..v.len() {
            let d2: f64 = (0..3).map(|a| (v[i][a] - v[j][a]).powi(2)).sum();
            if (d2 - 4.0).abs() < 1e-9 {
                out.push(normalise(std::array::from_fn(|a| v[i][a] + v[j][a])));
            }
        }
    }
    out
}

/// Directions from the centre of a k x k x k cube to the centres of its surface cells.
fn cube_surface(k: i64) -> Vec<[f64; 3]> {
    let h = (k - 1) / 2;
    let mut out = Vec::new();
    for z in -h..=h {
        for y in -h..=h {
            for x in -h..=h {
                if x.abs() == h || y.abs() == h || z.abs() == h {
                    out.push(normalise([x as f64, y as f64, z as f64]));
                }
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_and_isotropy() {
        for n in RAY_COUNTS {
            let rays = ray_set(n).expect("known count");
            assert_eq!(rays.len(), n);
            // Point-symmetric sets: the sum of directions vanishes and sum r r^T = n/3 I
            // approximately (exactly for the icosahedron).
            let mut m = [[0.0f64; 3]; 3];
            for r in &rays {
                for a in 0..3 {
                    for b in 0..3 {
                        m[a][b] += r[a] * r[b];
                    }
                }
            }
            for (a, row) in m.iter().enumerate() {
                for (b, v) in row.iter().enumerate() {
                    let want = if a == b { n as f64 / 3.0 } else { 0.0 };
                    assert!((v - want).abs() < 1e-9, "{n}: {m:?}");
                }
            }
        }
        assert!(ray_set(41).is_none());
    }
}
