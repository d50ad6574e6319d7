//! Degenerate but valid input (issue 13, item 3), through the delivered pipelines (the CPU
//! reference and, where there is an adapter, the GPU's): a constant volume gives zero features
//! for every method, and a NaN or infinite voxel inside a blob is replaced by its row's nearest
//! finite value instead of blanking the blob's features.

use shapecast::compute::pipeline::{FeatureJob, JobOptions};
use shapecast::cpu::Grid;
use shapecast::cpu::pipeline::{Method, Request, compute};
use shapecast::gpu::GpuContext;
use shapecast::gpu::context::test_context;
use shapecast::phantom::{Phantom, Shape};
use shapecast::volume::Volume;

const METHODS: [Method; 5] = [
    Method::Hessian,
    Method::Li,
    Method::Frangi,
    Method::Gst,
    Method::Rst,
];

fn cpu(volume: &Volume, req: &Request) -> [Vec<f32>; 3] {
    compute(&Grid::of(volume), &volume.to_f32(), req)
        .expect("cpu")
        .components
}

fn gpu(ctx: &GpuContext, volume: &Volume, req: &Request) -> [Vec<f32>; 3] {
    let options = JobOptions {
        export: true,
        ..JobOptions::default()
    };
    let mut job = FeatureJob::with_options(ctx, volume, req, options).expect("job");
    job.run_blocking(ctx).expect("run");
    job.finish_result()
        .expect("result")
        .components
        .expect("exported")
}

fn max_abs(c: &[Vec<f32>; 3]) -> f32 {
    c.iter().flatten().fold(
        0.0f32,
        |m, v| if v.is_nan() { f32::NAN } else { m.max(v.abs()) },
    )
}

/// 20^3 voxels of 1 mm at 40 HU (soft tissue): no structure anywhere.
fn constant() -> Volume {
    Volume::from_f32([20; 3], [1.0; 3], vec![40.0; 8000])
}

#[test]
fn a_constant_volume_gives_zero_features_on_the_cpu() {
    let v = constant();
    let mut nonzero = Vec::new();
    for method in METHODS {
        for eigen in [false, true] {
            let mut req = Request::new(method);
            req.eigen = eigen;
            let m = max_abs(&cpu(&v, &req));
            eprintln!("CPU {method:?} (eigen {eigen}): largest |feature| {m:e}");
            if m != 0.0 {
                nonzero.push((method, eigen, m));
            }
        }
    }
    assert!(
        nonzero.is_empty(),
        "CPU: features of a constant: {nonzero:?}"
    );
}

#[test]
fn a_constant_volume_gives_zero_features_on_the_gpu() {
    let Some(ctx) = test_context() else { return };
    let v = constant();
    let mut nonzero = Vec::new();
    for method in METHODS {
        for eigen in [false, true] {
            let mut req = Request::new(method);
            req.eigen = eigen;
            let m = max_abs(&gpu(&ctx, &v, &req));
            eprintln!("GPU {method:?} (eigen {eigen}): largest |feature| {m:e}");
            if m != 0.0 {
                nonzero.push((method, eigen, m));
            }
        }
    }
    assert!(
        nonzero.is_empty(),
        "GPU: features of a constant: {nonzero:?}"
    );
}

/// A bright sphere (r 4 mm, +100 HU over 40 HU) at the centre of 21^3 voxels of 1 mm, and the
/// index of its centre voxel.
fn sphere() -> (Volume, usize) {
    let p = Phantom::new("nan-sphere", [-10.0; 3], [10.0; 3], 40.0).with(
        Shape::Sphere {
            centre_mm: [0.0; 3],
            radius_mm: 4.0,
        },
        140.0,
    );
    let v = p.render([1.0; 3]);
    assert_eq!(v.dims, [21; 3]);
    let c = v.linear_index(10, 10, 10);
    (v, c)
}

/// The sphere with its centre voxel and one beside it missing (NaN, +inf).
fn holed(v: &Volume, c: usize) -> Volume {
    let mut values = v.to_f32();
    values[c] = f32::NAN;
    values[c + 21 * 21] = f32::INFINITY;
    let mut h = Volume::from_f32(v.dims, v.spacing_mm, values);
    h.origin_mm = v.origin_mm;
    h
}

/// Blobness (B) at the sphere's centre with and without the missing voxels, per method that
/// has one, and the ratio that must stay near 1 (a missing voxel moves it as one wrong voxel
/// of the blob's own value would: not at all here, its row neighbour has the same value).
fn check_blob(run: &dyn Fn(&Volume, &Request) -> [Vec<f32>; 3], what: &str) {
    let (clean, c) = sphere();
    let holed = holed(&clean, c);
    assert_eq!(holed.non_finite_count(), 2);
    for method in [Method::Hessian, Method::Li, Method::Rst] {
        let req = Request::new(method);
        let a = run(&clean, &req);
        let b = run(&holed, &req);
        let (ba, bb) = (a[2][c], b[2][c]);
        eprintln!(
            "{what} {method:?}: blobness at the centre {ba:.3} clean, {bb:.3} with NaN and inf"
        );
        assert!(
            ba > 1.0,
            "{what} {method:?}: no blobness on the clean sphere ({ba})"
        );
        assert!(
            (bb / ba - 1.0).abs() <= 1e-3,
            "{what} {method:?}: {bb} with the missing voxels vs {ba}"
        );
        assert!(
            max_abs(&b).is_finite(),
            "{what} {method:?}: NaN in the features"
        );
    }
}

#[test]
fn missing_voxels_do_not_blank_a_blob_on_the_cpu() {
    check_blob(&cpu, "CPU");
}

#[test]
fn missing_voxels_do_not_blank_a_blob_on_the_gpu() {
    let Some(ctx) = test_context() else { return };
    check_blob(&|v, r| gpu(&ctx, v, r), "GPU");
}

#[test]
fn loading_a_file_with_nan_voxels_warns_with_their_count() {
    let (clean, c) = sphere();
    let holed = holed(&clean, c);
    let bytes = shapecast::io::nifti::write_volume("holed.nii", &holed).expect("writes");
    let loaded =
        shapecast::io::load(&[shapecast::io::InputFile::new("holed.nii", bytes)]).expect("loads");
    // The file keeps the NaN and the infinity; the loader says how many there are.
    assert_eq!(loaded.volume.non_finite_count(), 2);
    assert!(
        loaded
            .volume
            .warnings
            .iter()
            .any(|w| w.starts_with("2 of 9261 voxels are NaN or infinite")),
        "{:?}",
        loaded.volume.warnings
    );
}

#[test]
fn non_finite_voxels_take_the_nearest_finite_value_of_their_row() {
    let nan = f32::NAN;
    // Row 0: a NaN between 1 and 5 (tie: the lower index wins), +inf at the end.
    // Row 1: all missing: the minimum finite value of its slice (-3).
    // Row 2: -inf at the start.
    let values = vec![
        1.0,
        nan,
        5.0,
        f32::INFINITY,
        nan,
        nan,
        nan,
        nan,
        f32::NEG_INFINITY,
        -3.0,
        7.0,
        8.0,
    ];
    let v = Volume::from_f32([4, 3, 1], [1.0; 3], values);
    let want = [
        1.0, 1.0, 5.0, 5.0, -3.0, -3.0, -3.0, -3.0, -3.0, -3.0, 7.0, 8.0,
    ];
    assert_eq!(v.to_f32(), want);
    assert_eq!(v.non_finite_count(), 7);
    assert!(
        v.non_finite_warning()
            .is_some_and(|w| w.starts_with("7 of 12"))
    );
    // Any chunking gives the same values (a chunk may start or end inside a row).
    for chunk in 1..=12 {
        let mut got = Vec::new();
        let mut start = 0;
        while start < 12 {
            let len = chunk.min(12 - start);
            let mut out = vec![0.0; len];
            v.values_into(start, &mut out);
            got.extend(out);
            start += len;
        }
        assert_eq!(got, want, "chunks of {chunk}");
    }
    // Nothing finite at all: zeros.
    let v = Volume::from_f32([2, 1, 1], [1.0; 3], vec![nan, nan]);
    assert_eq!(v.to_f32(), [0.0, 0.0]);
    assert!(
        Volume::from_f32([1, 1, 1], [1.0; 3], vec![2.0])
            .non_finite_warning()
            .is_none()
    );
}

#[test]
fn rows_without_a_finite_value_take_their_slice_minimum_and_missing_slices_the_volume_minimum() {
    let (nan, inf) = (f32::NAN, f32::INFINITY);
    // Slice 0: a missing row (its slice's minimum, 5). Slice 1: missing (the volume's, 2).
    // Slice 2: a missing row (its slice's, 2).
    let values = vec![5.0, 6.0, nan, nan, nan, nan, nan, inf, 9.0, 2.0, inf, nan];
    let v = Volume::from_f32([2, 2, 3], [1.0; 3], values);
    let want = [5.0, 6.0, 5.0, 5.0, 2.0, 2.0, 2.0, 2.0, 9.0, 2.0, 2.0, 2.0];
    for chunk in 1..=12 {
        let mut got = Vec::new();
        let mut start = 0;
        while start < 12 {
            let len = chunk.min(12 - start);
            let mut out = vec![0.0; len];
            v.values_into(start, &mut out);
            got.extend(out);
            start += len;
        }
        assert_eq!(got, want, "chunks of {chunk}");
    }
}

/// Scales far wider than the grid holds (spacings of 1e-6 mm) are capped with a warning instead
/// of building kernels of millions of taps (issue 13 item 3): the request runs, and says so.
#[test]
fn scales_wider_than_the_volume_are_capped_with_a_warning() {
    use shapecast::cpu::Grid;
    use shapecast::cpu::pipeline::{Method, Request, compute};
    let grid = Grid::new([24, 24, 24], [1e-6; 3]);
    let values: Vec<f32> = (0..grid.len())
        .map(|n| {
            let [i, j, k] = grid.ijk(n);
            let d2 = [i, j, k]
                .iter()
                .map(|&c| (c as f64 - 11.5).powi(2))
                .sum::<f64>();
            if d2 < 25.0 { 140.0 } else { 40.0 }
        })
        .collect();
    let req = Request::new(Method::Li);
    let resolved = req.resolve(&grid).expect("request");
    let cap = 24e-6 / 6.0;
    assert!(
        resolved.sigmas_mm.iter().all(|&s| s <= cap * (1.0 + 1e-12)),
        "{resolved:?}"
    );
    let out = compute(&grid, &values, &req).expect("features");
    let warning = out.notes.iter().find(|n| n.contains("capped"));
    assert!(warning.is_some(), "{:?}", out.notes);
    // The blob still stands out at its centre.
    let centre = grid.index(12, 12, 12);
    assert!(
        out.components[2][centre] > 0.0,
        "blobness {}",
        out.components[2][centre]
    );
}
