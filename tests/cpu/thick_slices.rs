//! The RST on thick slices (issue 33): spheres of radius 3, 4.7 and 7 mm, centre on a slice and
//! halfway between two, at 0.5 iso, 0.7 x 0.7 x 2.5, 0.9 iso and 0.6 x 0.6 x 5 mm, blobness at
//! the same physical point; thick axes refined as `--refine-slices` refines them, L_i from the
//! acquired spacing.

use crate::cpu_common;

use cpu_common::{Rendered, blobness};
use shapecast::cpu::{GradientVolume, RstParams, rst_refinement_factors};
use shapecast::phantom;

/// RST eigenvalues at the centre of a 100 HU sphere of `radius_mm` on `spacing_mm`, the centre on
/// a slice or halfway between two, with z refined by `f` (`None`: the pipeline's rule).
fn sphere_eigen(radius_mm: f64, spacing_mm: [f64; 3], between: bool, f: Option<usize>) -> [f64; 3] {
    let dz = if between { 0.5 * spacing_mm[2] } else { 0.0 };
    let mut p = phantom::sphere(radius_mm, 100.0).shifted([0.0, 0.0, dz]);
    let ray_mm = (radius_mm + 5.0).max(8.0);
    let half = radius_mm + ray_mm + 3.0;
    let half_z = (half / spacing_mm[2]).ceil() * spacing_mm[2];
    p.min_mm = [-half, -half, -half_z];
    p.max_mm = [half, half, half_z];
    let r = Rendered::new(p, spacing_mm);
    let mut params = RstParams::paper_defaults();
    params.radius_mm = ray_mm;
    let factors = match f {
        Some(f) => [1, 1, f],
        None => rst_refinement_factors(&r.grid, params.step_mm),
    };
    let gv = GradientVolume::refined(&r.grid, &r.values, 0.7, factors);
    let at = r.phantom.grid_mm([0.0, 0.0, dz]);
    shapecast::cpu::rst_eigen_at(&gv, at, &params)
}

fn sphere_blobness(radius_mm: f64, spacing_mm: [f64; 3], between: bool) -> f64 {
    blobness(sphere_eigen(radius_mm, spacing_mm, between, None))
}

const THIN: [f64; 3] = [0.5; 3];
const THREE: [[f64; 3]; 3] = [[0.5; 3], [0.7, 0.7, 2.5], [0.9; 3]];
const FIVE_MM: [f64; 3] = [0.6, 0.6, 5.0];

#[test]
fn the_pipeline_refines_thick_slices_for_the_rays() {
    use shapecast::cpu::Grid;
    let rule =
        |spacing: [f64; 3], dr: f64| rst_refinement_factors(&Grid::new([64, 64, 20], spacing), dr);
    assert_eq!(rule([0.6, 0.6, 5.0], 0.25), [1, 1, 5]);
    assert_eq!(rule([0.7, 0.7, 2.5], 0.25), [1, 1, 3]);
    assert_eq!(rule([0.646, 0.646, 8.0], 0.25), [1, 1, 8]);
    assert_eq!(rule([0.6, 0.6, 5.0], 0.5), [1, 1, 3]);
    // Isotropic grids and thin slices as they are.
    assert_eq!(rule([0.9; 3], 0.25), [1; 3]);
    // The pipeline refines for the rays only when asked (`features --refine-slices`).
    use shapecast::cpu::pipeline::{Method, Request};
    let grid = Grid::new([64, 64, 20], [0.6, 0.6, 5.0]);
    let mut req = Request::new(Method::Rst);
    assert_eq!(req.resolve(&grid).expect("request").factors, [1; 3]);
    req.refine_slices = true;
    assert_eq!(req.resolve(&grid).expect("request").factors, [1, 1, 5]);
    assert_eq!(rule([1.5; 3], 0.25), [1; 3]);
    assert_eq!(rule([0.7, 0.7, 1.0], 0.25), [1; 3]);
}

/// Slices up to 2.5 mm, r >= 3 mm: blobness at the same physical point within 10% over 0.5 iso,
/// 0.7 x 0.7 x 2.5 and 0.9 iso (issue 33's acceptance), centre on a slice and between slices.
#[test]
fn blobness_agrees_over_thin_and_2_5_mm_slices() {
    for radius in [3.0, 4.7, 7.0] {
        for between in [false, true] {
            let b: Vec<f64> = THREE
                .iter()
                .map(|&s| sphere_blobness(radius, s, between))
                .collect();
            let lo = b.iter().copied().fold(f64::INFINITY, f64::min);
            let hi = b.iter().copied().fold(0.0, f64::max);
            println!(
                "r {radius} mm, between slices {between}: {b:.3?}, spread {:.3}",
                hi / lo
            );
            assert!(lo > 5.0, "{b:?}");
            assert!(
                hi / lo <= 1.10,
                "r {radius}, between {between}: spread {:.3}",
                hi / lo
            );
        }
    }
}

/// 0.6 x 0.6 x 5 mm: spheres of r 4.7 and 7 mm keep >= 0.85 of their 0.5 mm blobness, centre on a
/// slice and between slices; r = 3 mm (0.6 x the slice thickness) is still reported as a blob
/// (three negative eigenvalues). Lower bounds only: a better reading may only raise them.
#[test]
fn blobness_holds_on_5_mm_slices() {
    for radius in [4.7, 7.0] {
        for between in [false, true] {
            let thin = sphere_blobness(radius, THIN, between);
            let thick = sphere_blobness(radius, FIVE_MM, between);
            println!(
                "r {radius} mm, between slices {between}: {thick:.3} vs {thin:.3} ({:.3})",
                thick / thin
            );
            assert!(
                thick >= 0.85 * thin,
                "r {radius}, between {between}: {}",
                thick / thin
            );
        }
    }
    for between in [false, true] {
        let l = sphere_eigen(3.0, FIVE_MM, between, None);
        println!("r 3 mm on 5 mm slices, between {between}: eigenvalues {l:.3?}");
        assert!(l.iter().all(|&v| v < 0.0), "{l:?}");
    }
}

/// Prints relative blobness for refinement factors 1..8 (docs/science.md, "Thick slices"):
/// `cargo test --release --test cpu -- --ignored --nocapture thick_slices::refinement_table`.
#[test]
#[ignore = "prints a table for docs/science.md"]
fn refinement_table() {
    for radius in [3.0, 4.7, 7.0] {
        let thin = blobness(sphere_eigen(radius, THIN, false, Some(1)));
        for spacing in [[0.7, 0.7, 2.5], FIVE_MM] {
            for between in [false, true] {
                let row: Vec<String> = [1, 2, 3, 4, 5, 6, 8]
                    .iter()
                    .map(|&f| {
                        let b = blobness(sphere_eigen(radius, spacing, between, Some(f)));
                        format!("{f}: {:.3}", b / thin)
                    })
                    .collect();
                println!(
                    "r {radius} {spacing:?} between {between}: {}",
                    row.join("  ")
                );
            }
        }
    }
}
