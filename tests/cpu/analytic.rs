//! Analytic patterns (issue 4, "Checked by"): eigenvalue signs and ratios of the Hessian and the
//! RST on a sphere, a cylinder, a slab, a dark sphere and an airway, and the Hessian against the
//! closed-form gamma-normalised values of a Gaussian-smoothed sphere and cylinder.

use crate::cpu_common;

use cpu_common::{Rendered, rst_eigen};
use shapecast::cpu::RstParams;
use shapecast::phantom::{self, Phantom};

const S: [f64; 3] = [0.5; 3];

/// max/min magnitude ratio of three eigenvalues that must all be negative.
fn spread_negative(l: [f64; 3]) -> f64 {
    assert!(l.iter().all(|&x| x < 0.0), "not all negative: {l:?}");
    l[0].abs() / l[2].abs()
}

/// Sphere r = 5 mm, checked with the Hessian at sigma = r / sqrt(3) (the scale of the largest
/// normalised response) and with the RST, at a voxel-centred and an off-centre sphere.
#[test]
fn bright_sphere_has_three_similar_negative_eigenvalues() {
    let centred = Rendered::new(phantom::sphere(5.0, 100.0), S);
    let off = Rendered::new(phantom::sphere(5.0, 100.0).shifted([0.24, 0.24, 0.24]), S);
    let params = RstParams::paper_defaults();
    let sigma = 5.0 / 3f64.sqrt();
    for (name, r, centre, limit) in [
        ("centred", &centred, [0.0; 3], 1.05),
        ("off-centre", &off, [0.24, 0.24, 0.24], 1.25),
    ] {
        let h = spread_negative(r.hessian_eigen(centre, sigma));
        // The RST is probed at the voxel the feature volume would hold (nearest to the centre).
        let gv = r.gradient(0.7);
        let voxel_mm = r.grid.position_mm(r.voxel(centre));
        let l = shapecast::cpu::rst_eigen_at(&gv, voxel_mm, &params);
        let t = spread_negative(l);
        println!("{name}: Hessian max/min {h:.4}, RST max/min {t:.4} ({l:?})");
        assert!(h <= limit, "{name} Hessian {h}");
        assert!(t <= limit, "{name} RST {t}");
    }
}

#[test]
fn cylinder_has_two_negative_and_a_vanishing_third() {
    // Along z the replicated border continues the cylinder, so a thin box suffices.
    let mut p = phantom::cylinder(3.0, 100.0, [0.0, 0.0, 1.0]);
    p.min_mm = [-12.0, -12.0, -2.0];
    p.max_mm = [12.0, 12.0, 2.0];
    let r = Rendered::new(p, S);
    let h = r.hessian_eigen([0.0; 3], 3.0);
    let gv = r.gradient(0.7);
    let t = rst_eigen(&r, &gv, [0.0; 3], &RstParams::paper_defaults());
    for (name, l) in [("Hessian", h), ("RST", t)] {
        println!("{name}: {l:?}");
        assert!(l[0] < 0.0 && l[1] < 0.0, "{name} {l:?}");
        assert!((l[0] / l[1]) < 1.05, "{name} {l:?}");
        assert!(l[2].abs() < 0.01 * l[0].abs(), "{name} {l:?}");
    }
}

#[test]
fn slab_has_one() {
    let mut p = phantom::slab(2.0, 100.0);
    p.min_mm = [-2.0, -2.0, -12.0];
    p.max_mm = [2.0, 2.0, 12.0];
    let r = Rendered::new(p, S);
    let h = r.hessian_eigen([0.0; 3], 2.0);
    let gv = r.gradient(0.7);
    let t = rst_eigen(&r, &gv, [0.0; 3], &RstParams::paper_defaults());
    for (name, l) in [("Hessian", h), ("RST", t)] {
        println!("{name}: {l:?}");
        assert!(l[0] < 0.0, "{name} {l:?}");
        assert!(
            l[1].abs() < 0.01 * l[0].abs() && l[2].abs() < 0.01 * l[0].abs(),
            "{name} {l:?}"
        );
    }
}

#[test]
fn dark_sphere_is_the_exact_mirror() {
    let bright = Rendered::new(phantom::sphere(5.0, 100.0).shifted([0.1, 0.0, 0.2]), S);
    let dark = Rendered::new(phantom::sphere(5.0, -100.0).shifted([0.1, 0.0, 0.2]), S);
    let params = RstParams::paper_defaults();
    let (gb, gd) = (bright.gradient(0.7), dark.gradient(0.7));
    for p in [[0.1, 0.0, 0.2], [2.0, 1.0, 0.0], [0.0, 4.5, 1.0]] {
        let hb = bright.hessian_eigen(p, 3.0);
        let hd = dark.hessian_eigen(p, 3.0);
        let tb = rst_eigen(&bright, &gb, p, &params);
        let td = rst_eigen(&dark, &gd, p, &params);
        for c in 0..3 {
            assert!(
                (hb[c] + hd[c]).abs() <= 1e-5 * hb[0].abs(),
                "Hessian {hb:?} {hd:?}"
            );
            assert!(
                (tb[c] + td[c]).abs() <= 1e-5 * tb[0].abs(),
                "RST {tb:?} {td:?}"
            );
        }
    }
}

#[test]
fn airway_lumen_has_two_positive() {
    let mut p = phantom::airway();
    p.min_mm[2] = -2.0;
    p.max_mm[2] = 2.0;
    let r = Rendered::new(p, S);
    // The Hessian needs a scale below the lumen radius: at sigma = 3 mm the smoothing lumps the
    // thin bright wall into the centre and the lumen reads as a bright tube (the paper's point
    // about hollow structures, section 2.5).
    let wide = r.hessian_eigen([0.0; 3], 3.0);
    println!("Hessian at sigma 3 mm (wall smeared in): {wide:?}");
    let h = r.hessian_eigen([0.0; 3], 2.0);
    let gv = r.gradient(0.7);
    // The airway preset's transfer function (100/300 HU).
    let mut params = RstParams::paper_defaults();
    params.tf = shapecast::cpu::Preset::Airways.transfer_function();
    let t = rst_eigen(&r, &gv, [0.0; 3], &params);
    for (name, l) in [("Hessian", h), ("RST", t)] {
        println!("{name}: {l:?}");
        assert!(l[0] > 0.0 && l[1] > 0.0, "{name} {l:?}");
        assert!(l[2].abs() < 0.05 * l[0].abs(), "{name} {l:?}");
    }
}

/// Closed forms for a ball (radius R, contrast C) and an infinite cylinder smoothed by a
/// Gaussian of sigma s, at the centre, times s^2:
/// ball: each eigenvalue = -C (4 pi R^3 / 3) (2 pi s^2)^(-3/2) exp(-R^2 / 2 s^2);
/// cylinder: the two = -C R^2 / (2 s^2) exp(-R^2 / 2 s^2), the third 0.
#[test]
fn hessian_matches_analytic_gamma_normalised_values() {
    let c = 100.0;
    let ball = |r: f64, s: f64| {
        -c * (4.0 * std::f64::consts::PI * r.powi(3) / 3.0)
            * (2.0 * std::f64::consts::PI * s * s).powf(-1.5)
            * (-r * r / (2.0 * s * s)).exp()
    };
    let cyl = |r: f64, s: f64| -c * r * r / (2.0 * s * s) * (-r * r / (2.0 * s * s)).exp();
    let sph = Rendered::new(phantom::sphere(5.0, c as f32), S);
    let mut p = phantom::cylinder(3.0, c as f32, [0.0, 0.0, 1.0]);
    p.min_mm = [-15.0, -15.0, -1.0];
    p.max_mm = [15.0, 15.0, 1.0];
    let cy = Rendered::new(p, S);
    for sigma in [2.0, 5.0 / 3f64.sqrt(), 4.0] {
        let l = sph.hessian_eigen([0.0; 3], sigma);
        let want = ball(5.0, sigma);
        println!("sphere sigma {sigma:.3}: {l:?} vs {want:.4}");
        for x in l {
            assert!(
                (x / want - 1.0).abs() <= 0.03,
                "sphere sigma {sigma}: {l:?} vs {want}"
            );
        }
    }
    for sigma in [1.5, 3.0 / 2f64.sqrt(), 3.0] {
        let l = cy.hessian_eigen([0.0; 3], sigma);
        let want = cyl(3.0, sigma);
        println!("cylinder sigma {sigma:.3}: {l:?} vs {want:.4}");
        for x in &l[..2] {
            assert!(
                (x / want - 1.0).abs() <= 0.03,
                "cylinder sigma {sigma}: {l:?} vs {want}"
            );
        }
        assert!(l[2].abs() <= 0.01 * want.abs());
    }
}

/// The whole-volume Hessian and the per-voxel one are the same computation.
#[test]
fn hessian_volume_agrees_with_hessian_at() {
    let r = Rendered::new(
        Phantom::by_name("sphere-cylinder", Some(1.0)).expect("known"),
        [0.7, 0.7, 1.2],
    );
    let h = shapecast::cpu::hessian_volume(&r.grid, &r.values, 2.0, true);
    for p in [[0.0; 3], [3.0, 1.0, -2.0], [8.0, 0.0, 0.0]] {
        let ijk = r.voxel(p);
        let idx = r.grid.index(ijk[0], ijk[1], ijk[2]);
        let at = shapecast::cpu::hessian_at(&r.grid, &r.values, ijk, 2.0, true);
        for c in 0..6 {
            assert!(
                (f64::from(h[c][idx]) - at[c]).abs() <= 1e-3 + 1e-4 * at[c].abs(),
                "{c}: {} vs {}",
                h[c][idx],
                at[c]
            );
        }
    }
}
