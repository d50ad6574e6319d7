//! Nodules at a vessel bifurcation (issue 13, item 6: untested until now; paper fig. 5, 6):
//! three nodules r = 4 mm near a Y of vessels r = 3 mm keep their RST blobness and lose part of
//! their Hessian blobness (sigma = r), more at a 1 mm gap than at 3 mm, within 0.06 of what
//! docs/reproduction.md reports (crotch, beside a branch, in front of the branch point).

mod cpu_common;

use cpu_common::{Rendered, blobness, rst_eigen};
use shapecast::cpu::RstParams;
use shapecast::phantom::{self, NODULE_RADIUS_MM};

const S: [f64; 3] = [0.5; 3];

#[test]
fn nodules_at_a_bifurcation_keep_their_rst_and_lose_their_hessian_blobness() {
    let params = RstParams::paper_defaults();
    let alone = Rendered::new(phantom::sphere(NODULE_RADIUS_MM, phantom::CONTRAST_HU), S);
    let rst_alone = blobness(rst_eigen(&alone, &alone.gradient(0.7), [0.0; 3], &params));
    let hes_alone = blobness(alone.hessian_eigen([0.0; 3], NODULE_RADIUS_MM));
    let names = ["crotch", "beside a branch", "in front"];
    let mut hes_by_gap = Vec::new();
    for (gap_mm, expected) in [(3.0, [0.475, 0.603, 0.480]), (1.0, [0.200, 0.407, 0.253])] {
        let scene = Rendered::new(phantom::bifurcation_nodules(gap_mm), S);
        let gv = scene.gradient(0.7);
        let centres = phantom::bifurcation_nodule_centres(gap_mm);
        let mut hes_here = Vec::new();
        for ((c, name), want) in centres.iter().zip(names).zip(expected) {
            let rst = blobness(rst_eigen(&scene, &gv, *c, &params)) / rst_alone;
            let hes = blobness(scene.hessian_eigen(*c, NODULE_RADIUS_MM)) / hes_alone;
            println!("gap {gap_mm} mm, {name}: RST {rst:.3}, Hessian(sigma = r) {hes:.3}");
            assert!(
                (0.9..=1.05).contains(&rst),
                "gap {gap_mm} mm, {name}: RST relative blobness {rst}"
            );
            assert!(
                (hes - want).abs() <= 0.06,
                "gap {gap_mm} mm, {name}: Hessian relative blobness {hes} (expected {want} +- 0.06)"
            );
            hes_here.push(hes);
        }
        hes_by_gap.push(hes_here);
    }
    // Nearer vessels cost the Hessian more at every nodule.
    for n in 0..3 {
        assert!(
            hes_by_gap[1][n] < hes_by_gap[0][n],
            "{}: {hes_by_gap:?}",
            names[n]
        );
    }
}
