//! Real-CT conspicuity (issue 13, deliver 2, last bullet): on lung2 of ../shared/data (chest CT,
//! 0.63 x 0.63 x 5 mm, a labelled ~45 mm mass in the left lower lobe), the lesion's peak Hessian
//! Li and RST Li blobness (lung preset) over the 99.9th percentile of the lung, and its rank
//! among the lung's blobs (`shapecast::cpu::conspicuity`; docs/reproduction.md, the same study
//! as `shapecast reproduce`). Plus the lung mask and the ranking on a synthetic chest.

use crate::common;

use shapecast::cpu::Grid;
use shapecast::cpu::conspicuity::{
    LesionStudy, Region, conspicuity, grow_mm, lesion_study, lung_mask,
};

/// lung2's image (HU) and label on their grid, or `None` (with the visible message of
/// `common::shared_data`) without ../shared/data.
fn lung2() -> Option<(Grid, Vec<f32>, Vec<f32>)> {
    let image = common::shared_data("ct/lung2_image.nrrd")?;
    let label = common::shared_data("ct/lung2_label.nrrd")?;
    let load = |p: &std::path::Path| {
        shapecast::io::load(&[common::input(p)])
            .unwrap_or_else(|e| panic!("{}: {e}", p.display()))
            .volume
    };
    let (image, label) = (load(&image), load(&label));
    assert_eq!(image.dims, label.dims, "image and label grids");
    Some((Grid::of(&image), image.to_f32(), label.to_f32()))
}

/// The study `shapecast reproduce` reports: the label's box grown by 20 mm (a crop of about an
/// eighth of the volume, so that the CPU reference finishes in minutes).
#[test]
fn lung2_mass_conspicuity() {
    let Some((grid, hu, label)) = lung2() else {
        return;
    };
    let lesion: Vec<bool> = label.iter().map(|&v| v != 0.0).collect();
    let b = Region::bounding(&grid, &lesion).expect("label");
    let m: [usize; 3] = std::array::from_fn(|a| (20.0 / grid.spacing_mm[a]).ceil() as usize);
    let region = b.grown(&grid, m);
    let t = std::time::Instant::now();
    let s = lesion_study(&grid, &hu, &label, region).expect("study");
    println!("{s:#?}\n{:.1} s", t.elapsed().as_secs_f64());
    // The lung preset's transfer function; the whole volume's noise (5.6 HU) does not raise it.
    assert_eq!((s.tf.d_min, s.tf.d_max), (100.0, 300.0));
    let noise = s.noise_sigma_hu.expect("noise");
    assert!((3.0..=10.0).contains(&noise), "noise {noise}");
    // Lower bounds, the side that matters (issue 33's acceptance). Measured: RST Li peak / lung
    // p99.9 5.89 (31.8 / 5.40), ranked first.
    let rst = &s.rst_li;
    assert!(rst.ratio >= 4.0, "RST ratio {}", rst.ratio);
    assert_eq!(rst.rank, 1, "RST: {rst:?}");
    // Measured: Hessian Li 3.76, rank 2, with the preset's scales below half the 5 mm slices
    // dropped (sigma 3-9 mm; docs/science.md, "Thick slices"). With sigma 1.5 and 2 mm it was
    // 2.02, rank 4: three vessel junctions locked to the slices responded more.
    let hes = &s.hessian_li;
    assert!(hes.ratio >= 1.8, "Hessian ratio {}", hes.ratio);
    assert!(hes.rank <= 2, "Hessian: {hes:?}");
    // The peaks lie on the label, and the lung outside the zone is a few tens of thousands of
    // voxels.
    for c in [rst, hes] {
        let [i, j, k] = c.lesion_peak_voxel;
        assert!(lesion[grid.index(i, j, k)]);
        assert!(
            (50_000..=120_000).contains(&c.lung_voxels),
            "{}",
            c.lung_voxels
        );
    }
    agrees_with_the_independent_study(&s, "conspicuity_independent.json");
    // Scales beyond the preset's (sigma up to 18 mm, sigma sqrt3 about the mass's radius) do not
    // lift the Hessian's lesion peak in the independent study: its rank is the method's.
    let json = independent_json("conspicuity_independent.json");
    let wide = &json["hessian_li_wide"];
    let wide_peak = wide["lesion_peak"].as_f64().expect("wide peak");
    assert!(
        (wide_peak - json["hessian_li"]["lesion_peak"].as_f64().expect("peak")).abs()
            <= 0.01 * wide_peak,
        "{wide_peak}"
    );
    assert!(wide["rank"].as_f64().expect("wide rank") > 1.0);
}

/// The chest CT of LUNG-PET-CT-Dx in ../shared/data (0.65 x 0.65 x 8 mm, an irregular mass in
/// the right lower lung beside the hilum) with the label scripts/label_lung_pet_ct_dx.py drew
/// from one seed (docs/reproduction/lung_pet_ct_dx_label.nii.gz, in the project).
#[test]
fn lung_pet_ct_dx_mass_conspicuity() {
    let Some(folder) = common::shared_data("series/ct-chest-lung-kernel") else {
        return;
    };
    let image = shapecast::io::load(&common::inputs_in(&folder))
        .expect("series")
        .volume;
    let label_path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("docs/reproduction/lung_pet_ct_dx_label.nii.gz");
    let label = shapecast::io::load(&[common::input(&label_path)])
        .expect("label")
        .volume;
    assert_eq!(image.dims, label.dims, "image and label grids");
    assert_eq!(
        image.spacing_mm, label.spacing_mm,
        "image and label spacing"
    );
    let grid = Grid::of(&image);
    let (hu, label) = (image.to_f32(), label.to_f32());
    let lesion: Vec<bool> = label.iter().map(|&v| v != 0.0).collect();
    let b = Region::bounding(&grid, &lesion).expect("label");
    let m: [usize; 3] = std::array::from_fn(|a| (20.0 / grid.spacing_mm[a]).ceil() as usize);
    let t = std::time::Instant::now();
    let s = lesion_study(&grid, &hu, &label, b.grown(&grid, m)).expect("study");
    println!("{s:#?}\n{:.1} s", t.elapsed().as_secs_f64());
    // The lung preset's transfer function: the lung kernel's noise does not raise it.
    assert_eq!((s.tf.d_min, s.tf.d_max), (100.0, 300.0));
    // Lower bounds. Measured: Hessian Li peak / lung p99.9 15.0 with the scales of the 8 mm
    // slices (sigma 4.5-9 mm; 3.49 with 1.5-9 mm), RST Li 69.6 (46.3 / 0.66): both rank the
    // mass first (at 8 mm slices the lung's vessels barely stop the rays of the 100/300 HU
    // function).
    let (hes, rst) = (&s.hessian_li, &s.rst_li);
    assert!(hes.ratio >= 1.8, "Hessian ratio {}", hes.ratio);
    assert_eq!(hes.rank, 1, "Hessian: {hes:?}");
    assert!(rst.ratio >= 4.0, "RST ratio {}", rst.ratio);
    assert_eq!(rst.rank, 1, "RST: {rst:?}");
    for c in [rst, hes] {
        let [i, j, k] = c.lesion_peak_voxel;
        assert!(lesion[grid.index(i, j, k)]);
    }
    agrees_with_the_independent_study(&s, "conspicuity_independent_lung_pet_ct_dx.json");
}

/// docs/reproduction/`name`, written by scripts/conspicuity_independent.py.
fn independent_json(name: &str) -> serde_json::Value {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("docs/reproduction")
        .join(name);
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| {
        panic!(
            "{}: {e} (run scripts/conspicuity_independent.py)",
            path.display()
        )
    });
    serde_json::from_str(&text).expect("json")
}

/// The study against an independent implementation's (numpy/scipy from SCIENCE.md,
/// scripts/conspicuity_independent.py, its numbers in docs/reproduction/`name`) on the same
/// region: the same lesion peak, lung percentile, ratio and rank, within the two
/// implementations' differences (scipy truncates kernels at 4 sigma, SCIENCE.md at 3 sigma + 1
/// voxel): 3% for the Hessian, 1% for the RST (no refinement there).
fn agrees_with_the_independent_study(s: &LesionStudy, name: &str) {
    let json = independent_json(name);
    let (region, hes, rst) = (&s.region, &s.hessian_li, &s.rst_li);
    let region_of = |key: &str| -> Vec<usize> {
        json[key]
            .as_array()
            .expect(key)
            .iter()
            .filter_map(|v| v.as_u64().map(|v| v as usize))
            .collect()
    };
    assert_eq!(
        region_of("region_lo"),
        region.lo.to_vec(),
        "not the same region"
    );
    assert_eq!(
        region_of("region_hi"),
        region.hi.to_vec(),
        "not the same region"
    );
    // The Hessian within 3% (scipy's kernels differ a little), the RST within 1% (its own ray
    // caster, no refinement); the same rank for both.
    for (method, key, ours, tolerance) in [
        ("Hessian Li", "hessian_li", hes, 0.03),
        ("RST Li", "rst_li", rst, 0.01),
    ] {
        let theirs = &json[key];
        let num = |key: &str| theirs[key].as_f64().expect(key);
        println!(
            "independent {method}: peak {:.2}, p99.9 {:.2}, ratio {:.3}, rank {}; ours: {:.2}, {:.2}, {:.3}, {}",
            num("lesion_peak"),
            num("lung_p999"),
            num("ratio"),
            num("rank"),
            ours.lesion_peak,
            ours.lung_p999,
            ours.ratio,
            ours.rank
        );
        for (what, ours, them) in [
            ("lesion peak", ours.lesion_peak, num("lesion_peak")),
            ("lung p99.9", ours.lung_p999, num("lung_p999")),
            ("ratio", ours.ratio, num("ratio")),
            (
                "strongest other",
                ours.strongest_other.0,
                num("strongest_other"),
            ),
        ] {
            // The Hessian's lung p99.9 (and so its ratio) differs more since the scales below
            // half the slice spacing are dropped: measured 3.8% (lung2) and 7.5% (LUNG-PET-CT-Dx)
            // where the peaks agree within 1%. The percentile now comes from weak responses at
            // sigma >= 3 mm, about 1.1 refined voxels along z, where the two samplings of the
            // kernel part most; not pinned down further (docs/reproduction.md).
            let tolerance = if key == "hessian_li" && matches!(what, "lung p99.9" | "ratio") {
                0.10
            } else {
                tolerance
            };
            assert!(
                (ours - them).abs() <= tolerance * them,
                "{method} {what}: ours {ours}, independent {them}"
            );
        }
        assert_eq!(ours.rank as f64, num("rank"), "{method} rank");
    }
}

/// A synthetic chest: air, a body of soft tissue touching no border, two lungs (-850 HU) with a
/// vessel through one and a nodule in the other, and bowel gas too small to be lung.
fn chest() -> (Grid, Vec<f32>) {
    let grid = Grid::new([60, 50, 12], [3.0, 3.0, 5.0]);
    let hu = (0..grid.len())
        .map(|n| {
            let [i, j, k] = grid.ijk(n);
            let (x, y) = (i as f64 - 29.5, j as f64 - 24.5);
            let in_body = (x / 27.0).powi(2) + (y / 21.0).powi(2) <= 1.0;
            let lung = |cx: f64| ((x - cx) / 9.0).powi(2) + (y / 14.0).powi(2) <= 1.0 && k >= 2;
            let vessel = (x + 14.0).abs() <= 1.0 && (y - 2.0).abs() <= 1.0;
            let nodule = (x - 14.0).powi(2) + y.powi(2) <= 9.0 && (5..=6).contains(&k);
            let gas = (x + 1.0).powi(2) + (y - 17.0).powi(2) <= 2.0 && k < 4;
            if !in_body {
                -1000.0
            } else if (lung(-14.0) && !vessel) || (lung(14.0) && !nodule) {
                -850.0
            } else if gas {
                -1000.0
            } else {
                40.0
            }
        })
        .collect();
    (grid, hu)
}

#[test]
fn lung_mask_holds_the_lungs_and_their_contents_only() {
    let (grid, hu) = chest();
    let mask = lung_mask(&grid, &hu);
    let at = |i: usize, j: usize, k: usize| mask[grid.index(i, j, k)];
    // Lung parenchyma of both lungs, the vessel and the nodule inside them.
    assert!(at(16, 25, 6) && at(44, 25, 6));
    assert!(at(15, 26, 6), "vessel");
    assert!(at(43, 24, 5), "nodule");
    // Not the air outside the body, the body wall, the mediastinum, the bowel gas, nor the
    // slices below the lungs.
    assert!(!at(0, 0, 6) && !at(3, 25, 6));
    assert!(!at(30, 25, 6), "mediastinum");
    assert!(!at(28, 41, 1), "bowel gas");
    assert!(!at(16, 25, 1));
    let n = mask.iter().filter(|m| **m).count();
    // Two ellipses of ~9 x 14 voxels' half-axes over 10 slices (178 ml each).
    assert!((7_000..=9_000).contains(&n), "{n}");
}

#[test]
fn conspicuity_ranks_blobs_above_the_lesion_peak() {
    let (grid, hu) = chest();
    let lung = lung_mask(&grid, &hu);
    let lesion: Vec<bool> = (0..grid.len())
        .map(|n| {
            let [i, j, k] = grid.ijk(n);
            (42..=45).contains(&i) && (23..=26).contains(&j) && (5..=6).contains(&k)
        })
        .collect();
    let zone = grow_mm(&grid, &lesion, 10.0);
    // The zone reaches 10 mm: 3 voxels in-plane (9 mm, not 12), 2 slices (10 mm, not 15).
    assert!(zone[grid.index(48, 24, 5)] && !zone[grid.index(49, 24, 5)]);
    assert!(zone[grid.index(43, 24, 8)] && !zone[grid.index(43, 24, 9)]);
    // A feature: 1 in the lung, 10 at the lesion, 12 at two separate spots of the other lung.
    let mut f: Vec<f32> = lung.iter().map(|&l| if l { 1.0 } else { 0.0 }).collect();
    for (n, l) in lesion.iter().enumerate() {
        if *l {
            f[n] = 10.0;
        }
    }
    for [i, j, k] in [[14, 20, 4], [15, 20, 4], [16, 30, 8]] {
        f[grid.index(i, j, k)] = 12.0;
    }
    let c = conspicuity(&grid, &Region::all(&grid), &f, &lung, &lesion, &zone).expect("lung");
    assert_eq!(c.lesion_peak, 10.0);
    assert_eq!(c.rank, 3, "{c:?}");
    assert_eq!(c.strongest_other.0, 12.0);
    // Three of several thousand lung voxels are above 1: the 99.9th percentile is 1.
    assert_eq!(c.lung_p999, 1.0);
    assert_eq!(c.ratio, 10.0);
}
