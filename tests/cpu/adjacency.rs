//! Adjacency (issue 4, "Checked by"; paper fig. 4, 5): a nodule r = 4 mm beside a vessel
//! r = 3 mm keeps its RST blobness but loses its Hessian blobness at sigma = r.

use crate::cpu_common;

use cpu_common::{Rendered, blobness, rst_eigen};
use shapecast::cpu::RstParams;
use shapecast::phantom::{self, NODULE_RADIUS_MM};

const S: [f64; 3] = [0.5; 3];

/// (RST relative blobness, Hessian-at-sigma=r relative blobness) at the sphere centre for a
/// surface gap, relative to the same sphere alone in the same box.
fn relative_blobness(gap_mm: f64) -> (f64, f64) {
    let params = RstParams::paper_defaults();
    let alone = Rendered::new(phantom::sphere_next_to_cylinder(gap_mm, false), S);
    let near = Rendered::new(phantom::sphere_next_to_cylinder(gap_mm, true), S);
    let rst = |r: &Rendered| blobness(rst_eigen(r, &r.gradient(0.7), [0.0; 3], &params));
    let hes = |r: &Rendered| blobness(r.hessian_eigen([0.0; 3], NODULE_RADIUS_MM));
    (rst(&near) / rst(&alone), hes(&near) / hes(&alone))
}

/// Two-sided: the RST keeps the nodule (0.9..1.02), the Hessian at sigma = r loses about half
/// of it near the vessel and recovers with the gap, within 0.06 of what docs/reproduction.md
/// reports (gap 1: 0.421, 2: 0.497, 4: 0.709), so that a Hessian which loses too little, or
/// all of it (a wrong sign or scale), fails as well.
#[test]
fn rst_keeps_and_hessian_loses_a_nodule_beside_a_vessel() {
    let mut last_hes = 0.0;
    for (gap_mm, hes_expected) in [(1.0, 0.421), (2.0, 0.497), (4.0, 0.709)] {
        let (rst, hes) = relative_blobness(gap_mm);
        println!("gap {gap_mm} mm: RST {rst:.3}, Hessian(sigma = r) {hes:.3}");
        assert!(
            (0.9..=1.02).contains(&rst),
            "RST relative blobness {rst} at gap {gap_mm}"
        );
        assert!(
            (hes - hes_expected).abs() <= 0.06,
            "Hessian relative blobness {hes} at gap {gap_mm} (expected {hes_expected} +- 0.06)"
        );
        assert!(
            hes > last_hes,
            "Hessian {hes} at gap {gap_mm} not above {last_hes}"
        );
        last_hes = hes;
    }
}

#[test]
fn every_sphere_of_the_string_keeps_its_rst_blobness() {
    let gap_mm = 1.0;
    let params = RstParams::paper_defaults();
    let alone = Rendered::new(phantom::sphere(NODULE_RADIUS_MM, phantom::CONTRAST_HU), S);
    let b_alone = blobness(rst_eigen(&alone, &alone.gradient(0.7), [0.0; 3], &params));
    let string = Rendered::new(phantom::sphere_string(gap_mm), S);
    let gv = string.gradient(0.7);
    for c in phantom::sphere_string_centres(gap_mm) {
        let rel = blobness(rst_eigen(&string, &gv, c, &params)) / b_alone;
        let hes = blobness(string.hessian_eigen(c, NODULE_RADIUS_MM))
            / blobness(alone.hessian_eigen([0.0; 3], NODULE_RADIUS_MM));
        println!("sphere at {c:?}: RST {rel:.3}, Hessian(sigma = r) {hes:.3}");
        assert!(
            (0.9..=1.05).contains(&rel),
            "sphere at {c:?}: RST relative blobness {rel}"
        );
        // The Hessian loses most of each sphere, the inner two (a neighbour on both sides)
        // more than the outer two: 0.179 and 0.438 measured, +-0.06.
        let expected = if c[0].abs() < 9.0 { 0.179 } else { 0.438 };
        assert!(
            (hes - expected).abs() <= 0.06,
            "sphere at {c:?}: Hessian relative blobness {hes} (expected {expected} +- 0.06)"
        );
    }
}
