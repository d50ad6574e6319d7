use super::*;

/// An ellipse over a PET hot spot (a Gaussian of SUV 10 centred on a voxel of both grids):
/// SUVmax is the spot's peak, SUVmean lies below it, SUVpeak is the mean of the PET voxels
/// within the 1 cm³ sphere about the peak (computed here by brute force), and the reading
/// names all three.
#[test]
fn an_ellipse_over_a_pet_reads_suvmax_mean_and_peak() {
    let mut ct = Volume::from_f32([40, 40, 10], [1.0, 1.0, 2.0], vec![0.0; 16_000]);
    ct.modality = crate::volume::Modality::Ct;
    let centre = DVec3::new(20.0, 20.0, 8.0);
    let (dims, spacing) = ([20usize, 20, 10], [2.0, 2.0, 2.0]);
    let suv = |p: DVec3| 10.0 * (-(p - centre).length_squared() / 32.0).exp() as f32;
    let mut values = Vec::new();
    for k in 0..dims[2] {
        for j in 0..dims[1] {
            for i in 0..dims[0] {
                values.push(suv(DVec3::new(
                    2.0 * i as f64,
                    2.0 * j as f64,
                    2.0 * k as f64,
                )));
            }
        }
    }
    let mut pet = Volume::from_f32(dims, spacing, values);
    pet.modality = crate::volume::Modality::Pt;
    pet.pet = Some(crate::volume::PetScale {
        units: "BQML".to_owned(),
        suv_factor: Some(1.0),
        rule: "test".to_owned(),
    });
    // The axial slice through the centre (z = 8 mm is CT slice 4), a 16 mm ellipse.
    let m = Measurement {
        kind: MeasureKind::Ellipse,
        pane: Some(SliceKind::Axial),
        a_mm: DVec3::new(12.0, 12.0, 8.0),
        b_mm: DVec3::new(28.0, 28.0, 8.0),
    };
    let stats = pet_region_stats(&ct, &pet, &m).expect("PET stats");
    assert!((stats.max - 10.0).abs() < 1e-5, "{stats:?}");
    assert!(stats.mean > 1.0 && stats.mean < 9.0, "{stats:?}");
    let (mut n, mut sum) = (0, 0.0);
    for (idx, &v) in pet.to_f32().iter().enumerate() {
        let p = DVec3::new(
            2.0 * (idx % 20) as f64,
            2.0 * ((idx / 20) % 20) as f64,
            2.0 * (idx / 400) as f64,
        );
        if (p - centre).length() <= PEAK_SPHERE_RADIUS_MM {
            n += 1;
            sum += f64::from(v);
        }
    }
    assert!(n > 20, "{n} voxels in the sphere");
    assert!((stats.peak - sum / f64::from(n)).abs() < 1e-6, "{stats:?}");
    assert!(stats.peak < f64::from(stats.max) && stats.peak > stats.mean);
    let entry = Entry::new(&ct, m).with_pet(&ct, Some(&pet));
    let text = entry.reading("HU");
    assert!(
        text.contains("SUVmax 10.00") && text.contains("SUVpeak"),
        "{text}"
    );
}

#[test]
fn text_round_trips_and_garbage_is_refused() {
    let m = Measurement {
        kind: MeasureKind::Ellipse,
        pane: Some(SliceKind::Coronal),
        a_mm: DVec3::new(-1.25, 0.1, 1e-7),
        b_mm: DVec3::new(300.0, -2.5, 17.333_333_333_333_332),
    };
    assert_eq!(Measurement::from_text(&m.to_text()), Some(m));
    let ruler = Measurement {
        kind: MeasureKind::Ruler,
        pane: None,
        ..m
    };
    assert!(
        ruler.to_text().starts_with("ruler,3d,"),
        "{}",
        ruler.to_text()
    );
    assert_eq!(Measurement::from_text(&ruler.to_text()), Some(ruler));
    for bad in [
        "ellipse,3d,1,2,3,4,5,6",
        "",
        "ruler",
        "ruler,axial,1,2,3,4,5",
        "ruler,axial,1,2,3,4,5,x",
        "ruler,oblique,1,2,3,4,5,6",
        "box,axial,1,2,3,4,5,6",
        "ruler,axial,1,2,3,4,5,inf",
    ] {
        assert_eq!(Measurement::from_text(bad), None, "{bad}");
    }
}

#[test]
fn ellipse_statistics_count_centres_inside() {
    // Values = 10 i + j on a 1 x 2 mm grid: the ellipse of half-axes 3 x 1 voxels centred on
    // voxel (5, 5) of slice 1 holds row 5 from i = 2 to 8, and (5, 4), (5, 6).
    let dims = [12, 10, 3];
    let values: Vec<f32> = (0..dims[0] * dims[1] * dims[2])
        .map(|n| {
            let (i, j) = (n % dims[0], (n / dims[0]) % dims[1]);
            (10 * i + j) as f32
        })
        .collect();
    let v = Volume::from_f32(dims, [1.0, 2.0, 3.0], values);
    let world = v.world_from_voxel();
    let m = Measurement {
        kind: MeasureKind::Ellipse,
        pane: Some(SliceKind::Axial),
        a_mm: world.transform_point3(DVec3::new(2.0, 4.0, 1.0)),
        b_mm: world.transform_point3(DVec3::new(8.0, 6.0, 1.0)),
    };
    let s = region_stats(&v, &m).expect("stats");
    let mut inside = Vec::new();
    for j in 0..dims[1] {
        for i in 0..dims[0] {
            let (du, dv) = ((i as f64 - 5.0) / 3.0, (j as f64 - 5.0) / 1.0);
            if du * du + dv * dv <= 1.0 {
                inside.push(v.value_at(i, j, 1) as f64);
            }
        }
    }
    assert_eq!(s.pixels, inside.len());
    let mean = inside.iter().sum::<f64>() / inside.len() as f64;
    assert!((s.mean - mean).abs() < 1e-9);
    assert_eq!(s.min, 25.0);
    assert_eq!(s.max, 85.0);
    assert!((s.area_mm2 - std::f64::consts::PI * 3.0 * 2.0).abs() < 1e-9);
    let ruler = Measurement {
        kind: MeasureKind::Ruler,
        ..m
    };
    assert!((ruler.length_mm() - (36.0f64 + 16.0).sqrt()).abs() < 1e-9);
    assert_eq!(region_stats(&v, &ruler), None);
}
