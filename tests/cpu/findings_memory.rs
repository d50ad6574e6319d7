//! What a findings list costs in memory beyond its two inputs (the CT in HU and the blobness, 4
//! bytes a voxel each), counted by the allocator: the viewer makes the list in the tab, where a
//! whole-body CT's voxels are counted in hundreds of millions (issue "Findings": no list costs
//! more than the features themselves, whose texture is 4 bytes a voxel). The masks are a byte a
//! voxel each (lung, air around the body); flood fills go breadth first (a front, not most of
//! the air, on their queue) and the reference percentile is selected from histograms, never by
//! collecting the domain's values; the gate builds only the masks it reads. Measured here: 1.4
//! (lung nodules: one mask) and 2.4 (lymph nodes: two masks) bytes
//! a voxel; before those changes 15.7. The viewer reads the CT through its compact voxels
//! (`cpu::Samples`), so its list costs the blobness (read back over its own texels) and these.

use shapecast::cpu::findings::{Gate, find, reference};
use shapecast::cpu::{Grid, Preset};
use shapecast::volume::{Volume, Voxels};

use crate::counting::peak_during;

/// A chest-like CT: air around an elliptic body of soft tissue (40 HU), two lungs (-850 HU)
/// with a few nodules (40 HU), and blobness peaks at the nodules and in the tissue.
fn chest(dims: [usize; 3]) -> (Grid, Vec<f32>, Vec<f32>) {
    let grid = Grid::new(dims, [1.5, 1.5, 2.0]);
    let [nx, ny, nz] = dims;
    let mut hu = vec![-1000.0f32; grid.len()];
    let mut blob = vec![0.0f32; grid.len()];
    let nodules = [
        [0.3, 0.45, 0.5],
        [0.7, 0.5, 0.3],
        [0.32, 0.6, 0.7],
        [0.5, 0.8, 0.5],
    ];
    for k in 0..nz {
        for j in 0..ny {
            for i in 0..nx {
                let (x, y, z) = (
                    i as f64 / nx as f64,
                    j as f64 / ny as f64,
                    k as f64 / nz as f64,
                );
                let n = grid.index(i, j, k);
                let body = ((x - 0.5) / 0.42).powi(2) + ((y - 0.5) / 0.36).powi(2) < 1.0;
                if !body {
                    continue;
                }
                hu[n] = 40.0 + ((i * 7 + j * 13 + k * 3) % 11) as f32 - 5.0;
                for cx in [0.3, 0.7] {
                    let lung = ((x - cx) / 0.15).powi(2)
                        + ((y - 0.5) / 0.25).powi(2)
                        + ((z - 0.5) / 0.45).powi(2)
                        < 1.0;
                    if lung {
                        hu[n] = -850.0;
                    }
                }
                for c in nodules {
                    let d2 = ((x - c[0]) * nx as f64 * 1.5).powi(2)
                        + ((y - c[1]) * ny as f64 * 1.5).powi(2)
                        + ((z - c[2]) * nz as f64 * 2.0).powi(2);
                    if d2 < 36.0 {
                        hu[n] = 40.0;
                    }
                    blob[n] += (100.0 * (-d2 / 18.0).exp()) as f32;
                }
                blob[n] += ((i * 31 + j * 17 + k * 7) % 5) as f32 * 0.1;
            }
        }
    }
    (grid, hu, blob)
}

#[test]
fn a_findings_list_costs_at_most_three_bytes_a_voxel_beyond_its_inputs() {
    let (grid, hu, blob) = chest([160, 140, 60]);
    let voxels = grid.len() as f64;
    for preset in [Preset::LungNodules, Preset::LymphNodes] {
        let (found, peak) = peak_during(|| find(&grid, &hu, &blob, preset));
        let found = found.unwrap_or_else(|e| panic!("{preset:?}: {e}"));
        let per_voxel = peak as f64 / voxels;
        eprintln!(
            "{preset:?}: {} findings, peak {:.2} bytes a voxel beyond the inputs",
            found.findings.len(),
            per_voxel
        );
        assert!(!found.findings.is_empty(), "{preset:?}: no findings");
        assert!(per_voxel <= 3.0, "{preset:?}: {per_voxel:.2} bytes a voxel");
    }
    // The reference a PET's hot spots read the CT's shape against.
    let (r, peak) = peak_during(|| reference(&grid, &hu, &blob, Gate::SoftTissue));
    eprintln!(
        "soft-tissue reference {r}: peak {:.2} bytes a voxel",
        peak as f64 / voxels
    );
    assert!(r > 0.0);
    assert!(peak as f64 / voxels <= 3.0);
}

/// The viewer's way: the CT read through its own 2-byte voxels (no f32 copy), the same list.
#[test]
fn a_findings_list_read_through_the_ct_voxels_is_the_same_and_costs_no_copy() {
    let (grid, hu, blob) = chest([160, 140, 60]);
    let voxels = grid.len() as f64;
    let mut ct = Volume::from_f32(grid.dims, grid.spacing_mm, hu.clone());
    ct.voxels = Voxels::I16(hu.iter().map(|&v| v as i16).collect());
    assert_eq!(ct.to_f32(), hu, "the phantom's HU are whole numbers");
    for preset in [Preset::LungNodules, Preset::LymphNodes] {
        let want = find(&grid, &hu, &blob, preset);
        let (got, peak) = peak_during(|| find(&grid, &ct, &blob, preset));
        assert_eq!(got, want, "{preset:?}");
        let per_voxel = peak as f64 / voxels;
        eprintln!("{preset:?} through the voxels: peak {per_voxel:.2} bytes a voxel");
        assert!(per_voxel <= 3.0, "{preset:?}: {per_voxel:.2} bytes a voxel");
    }
}
