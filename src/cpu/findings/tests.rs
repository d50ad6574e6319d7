use super::*;

/// A chest-like box: body (40 HU) with a lung (-850 HU) inside, air around.
fn chest(dims: [usize; 3], spacing: [f64; 3]) -> (Grid, Vec<f32>) {
    let grid = Grid::new(dims, spacing);
    let mut hu = vec![-1000.0f32; grid.len()];
    for (n, v) in hu.iter_mut().enumerate() {
        let [i, j, _] = grid.ijk(n);
        let body = i >= 3 && j >= 3 && i + 3 < dims[0] && j + 3 < dims[1];
        let lung = i >= 8 && j >= 8 && i + 8 < dims[0] && j + 8 < dims[1];
        *v = if lung {
            -850.0
        } else if body {
            40.0
        } else {
            -1000.0
        };
    }
    (grid, hu)
}

fn ball(grid: &Grid, hu: &mut [f32], feature: &mut [f32], c: [usize; 3], r_mm: f64, v: f32) {
    for n in 0..grid.len() {
        let d = distance_mm(grid, c, grid.ijk(n));
        if d <= r_mm {
            hu[n] = v;
        }
        feature[n] = feature[n].max((100.0 * (1.0 - d / (2.0 * r_mm))).max(0.0) as f32);
    }
}

/// A cropped volume: body everywhere (no air at its faces), a soft-tissue ball inside it and
/// the same ball cut by its first slice.
#[test]
fn a_structure_cut_by_the_volume_s_edge_is_counted_not_listed() {
    let grid = Grid::new([40, 40, 40], [2.0; 3]);
    let mut hu = vec![0.0f32; grid.len()];
    let mut feature = vec![0.0f32; grid.len()];
    ball(&grid, &mut hu, &mut feature, [20, 20, 20], 6.0, 60.0);
    ball(&grid, &mut hu, &mut feature, [10, 10, 1], 6.0, 60.0);
    let found = find(&grid, &hu, &feature, Preset::Vessels).expect("same lengths");
    let listed: Vec<[usize; 3]> = found.findings.iter().map(|f| f.voxel).collect();
    assert_eq!(listed, [[20, 20, 20]], "{found:?}");
    assert_eq!(found.cut, 1, "{found:?}");

    // Two slices have no inside along z: a ball in the plane is judged in it, not cut.
    let grid = Grid::new([40, 40, 2], [2.0; 3]);
    let mut hu = vec![0.0f32; grid.len()];
    let mut feature = vec![0.0f32; grid.len()];
    ball(&grid, &mut hu, &mut feature, [20, 20, 0], 6.0, 60.0);
    let found = find(&grid, &hu, &feature, Preset::Vessels).expect("same lengths");
    assert_eq!((found.findings.len(), found.cut), (1, 0), "{found:?}");
}

#[test]
fn a_nodule_in_the_lung_is_found_with_its_size_and_a_bone_blob_is_not() {
    let (grid, mut hu) = chest([60, 60, 60], [2.0; 3]);
    let mut feature = vec![0.0f32; grid.len()];
    // A 6 mm nodule in the lung; a brighter dense blob of the same size (bone) in the body.
    ball(&grid, &mut hu, &mut feature, [30, 30, 30], 6.0, 30.0);
    ball(&grid, &mut hu, &mut feature, [5, 30, 10], 6.0, 1200.0);
    // A calcified granuloma in the lung (900 HU): dense, not a nodule to follow.
    ball(&grid, &mut hu, &mut feature, [30, 44, 46], 4.0, 900.0);
    for (n, f) in feature.iter_mut().enumerate() {
        if grid.ijk(n)[0] < 12 {
            *f *= 2.0;
        }
    }
    let found = find(&grid, &hu, &feature, Preset::LungNodules).expect("same lengths");
    assert_eq!(found.findings.len(), 1, "{found:?}");
    let f = &found.findings[0];
    assert_eq!((f.rank, f.voxel), (1, [30, 30, 30]));
    // A digital ball of r = 6 mm on 2 mm voxels: 4/3 pi 3^3 = 113 voxels of 8 mm^3.
    assert!((f.volume_ml - 0.905).abs() < 0.1, "{f:?}");
    assert!((f.diameter_mm - 12.0).abs() < 1.0, "{f:?}");
    assert_eq!(f.mean_hu, 30.0);
    assert!(f.score > 1.0 && !f.bounded);
    assert_eq!(
        (found.dense, found.outside),
        (2, 0),
        "the bone blob and the calcified granuloma are dense: {found:?}"
    );
    assert_eq!(found.small, 0);
}

#[test]
fn the_percentile_is_the_nearest_rank_of_the_sorted_values() {
    let sorted = |v: &[f32]| {
        let mut f: Vec<f32> = v.iter().copied().filter(|x| x.is_finite()).collect();
        if f.is_empty() {
            return 0.0;
        }
        let k = ((0.999 * f.len() as f64).ceil() as usize).clamp(1, f.len()) - 1;
        *f.select_nth_unstable_by(k, f32::total_cmp).1
    };
    let mut rng = crate::cpu::testing::Lcg::new(7);
    let mut next = || rng.unit();
    let cases: Vec<Vec<f32>> = vec![
        vec![],
        vec![f32::NAN, f32::INFINITY],
        vec![3.0],
        vec![-0.0, 0.0, -0.0],
        (0..5000).map(|_| next() * 200.0 - 100.0).collect(),
        (0..20_000)
            .map(|i| if i % 3 == 0 { 0.0 } else { next() * 1e-3 })
            .collect(),
        (0..3000)
            .map(|i| [1.0, 2.0, f32::NAN, -5.0][i % 4])
            .collect(),
        (0..10_000).map(|_| (next() * 60.0 - 30.0).exp2()).collect(),
    ];
    for v in cases {
        let want = sorted(&v);
        let got = percentile_999(|| v.iter().copied());
        assert_eq!(
            got.to_bits(),
            want.to_bits(),
            "{} values: {got} vs {want}",
            v.len()
        );
    }
}

#[test]
fn maxima_of_one_structure_are_one_finding_ranked_by_their_peak() {
    let (grid, mut hu) = chest([60, 60, 40], [2.0; 3]);
    let mut feature = vec![0.0f32; grid.len()];
    ball(&grid, &mut hu, &mut feature, [20, 20, 20], 5.0, 20.0);
    ball(&grid, &mut hu, &mut feature, [40, 40, 20], 8.0, 20.0);
    // A second, weaker maximum inside the larger nodule.
    feature[grid.index(42, 40, 20)] = 150.0;
    feature[grid.index(40, 40, 20)] = 160.0;
    let found = find(&grid, &hu, &feature, Preset::LungNodules).expect("same lengths");
    let peaks: Vec<_> = found.findings.iter().map(|f| (f.rank, f.voxel)).collect();
    assert_eq!(peaks, [(1, [40, 40, 20]), (2, [20, 20, 20])]);
    assert_eq!(found.findings[0].merged, 1);
    assert!(found.findings[0].diameter_mm > found.findings[1].diameter_mm);
}

#[test]
fn lymph_node_findings_stay_in_soft_tissue_away_from_the_skin() {
    let (grid, mut hu) = chest([60, 60, 40], [2.0; 3]);
    let mut feature = vec![0.0f32; grid.len()];
    // Near the skin (within 10 mm of the air outside): dropped. In the lung: dropped. A
    // faint background keeps the reference above zero, as real tissue's feature does.
    feature.fill(1.0);
    ball(&grid, &mut hu, &mut feature, [30, 5, 20], 2.0, 40.0);
    ball(&grid, &mut hu, &mut feature, [30, 30, 20], 4.0, 40.0);
    let found = find(&grid, &hu, &feature, Preset::LymphNodes).expect("same lengths");
    assert!(found.findings.is_empty(), "{found:?}");
    assert_eq!(found.outside, 2);
    let (grid, mut hu) = chest([80, 80, 40], [2.0; 3]);
    for v in hu.iter_mut().filter(|v| **v < -800.0 && **v > -900.0) {
        *v = -80.0; // fat where the lung was
    }
    let mut feature = vec![0.0f32; grid.len()];
    ball(&grid, &mut hu, &mut feature, [40, 40, 20], 5.0, 45.0);
    let found = find(&grid, &hu, &feature, Preset::LymphNodes).expect("same lengths");
    assert_eq!(found.findings.len(), 1, "{found:?}");
    assert_eq!(found.findings[0].voxel, [40, 40, 20]);
}

#[test]
fn a_feature_of_the_wrong_size_is_an_error_and_an_empty_volume_has_no_findings() {
    let grid = Grid::new([4, 4, 4], [1.0; 3]);
    let err = find(&grid, &[0.0f32; 64][..], &[0.0; 63], Preset::LungNodules);
    assert!(matches!(
        err,
        Err(FindingsError::Length { feature: 63, .. })
    ));
    let none =
        find(&grid, &[0.0f32; 64][..], &[0.0; 64], Preset::LymphNodes).expect("same lengths");
    assert!(none.findings.is_empty());
}
