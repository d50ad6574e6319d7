//! GPU pipeline against the CPU reference on crops of the real CTs of ../shared/data, every
//! method (issue 13, item 4): below 1e-3 of the largest value except at rare decision ties
//! (see `check`).

use crate::common;

use shapecast::compute::pipeline::{FeatureJob, JobOptions};
use shapecast::cpu::Grid;
use shapecast::cpu::pipeline::{Method, Request, compute};
use shapecast::gpu::GpuContext;
use shapecast::gpu::context::test_context;
use shapecast::volume::Volume;

/// A crop of at most `size` voxels per axis around the centre of a CT of ../shared/data, in HU,
/// with the file's spacing.
fn crop(rel: &str, size: [usize; 3]) -> Option<Volume> {
    let path = common::shared_data(rel)?;
    let v = shapecast::io::load(&[common::input(&path)])
        .expect("loads")
        .volume;
    let all = v.to_f32();
    let n: [usize; 3] = std::array::from_fn(|a| size[a].min(v.dims[a]));
    let lo: [usize; 3] = std::array::from_fn(|a| (v.dims[a] - n[a]) / 2);
    let mut values = Vec::with_capacity(n[0] * n[1] * n[2]);
    for k in 0..n[2] {
        for j in 0..n[1] {
            for i in 0..n[0] {
                values.push(all[v.linear_index(lo[0] + i, lo[1] + j, lo[2] + k)]);
            }
        }
    }
    Some(Volume::from_f32(n, v.spacing_mm, values))
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

/// Per voxel, the largest |gpu - cpu| over the components relative to the largest |cpu| of the
/// volume, sorted; and that largest |cpu|.
fn errors(gpu: &[Vec<f32>; 3], cpu: &[Vec<f32>; 3]) -> (Vec<f64>, f64) {
    let largest = cpu
        .iter()
        .flatten()
        .fold(0.0f64, |m, v| m.max(f64::from(v.abs())))
        .max(f64::MIN_POSITIVE);
    let mut e: Vec<f64> = (0..cpu[0].len())
        .map(|i| {
            (0..3)
                .map(|c| f64::from((gpu[c][i] - cpu[c][i]).abs()) / largest)
                .fold(
                    0.0,
                    |m, x| if x.is_nan() { f64::INFINITY } else { m.max(x) },
                )
        })
        .collect();
    e.sort_by(f64::total_cmp);
    (e, largest)
}

/// GPU against CPU for each method: at most one voxel in 5000 (and at most 2) may differ by
/// more than 1e-3 of the largest value. That much is left for decision ties, which f32 and f64
/// may decide either way (not checked voxel by voxel here; tests/gpu/eigen.rs and
/// tests/gpu/hessian.rs do that on the kernels): the eq. 1 map jumps where |l1| = |l2| with opposite signs (V = |l1| or
/// 0), and multi-scale eigenvalues where two scales' norms tie. The 99.9th percentile must stay
/// below 1e-4. Eigenvalue outputs must be sorted by magnitude at every voxel, on both sides
/// (issue 13: features are taken back from a refined grid by subsampling, never interpolated). Measured on the crops below: no voxel above 1e-3
/// (worst: the RST 1.1e-4, the rest below 4e-6); on a 32^3 crop of the 1.5 mm CT, 2 voxels of
/// 32,768 of the eq. 1 map (3.6e-3). The crops are small to keep the test near a minute.
fn check(rel: &str, size: [usize; 3], methods: &[(Method, bool)]) {
    let Some(ctx) = test_context() else { return };
    let Some(volume) = crop(rel, size) else {
        return;
    };
    let grid = Grid::of(&volume);
    let values = volume.to_f32();
    let mut failures = Vec::new();
    for &(method, eigen) in methods {
        let mut req = Request::new(method);
        req.eigen = eigen;
        let cpu = compute(&grid, &values, &req).expect("cpu").components;
        let g = gpu(&ctx, &volume, &req);
        if eigen {
            for (side, l) in [("CPU", &cpu), ("GPU", &g)] {
                let unsorted = (0..grid.len())
                    .filter(|&i| {
                        !(l[0][i].abs() >= l[1][i].abs() && l[1][i].abs() >= l[2][i].abs())
                    })
                    .count();
                assert_eq!(
                    unsorted, 0,
                    "{rel}: {side} eigenvalues not sorted by magnitude at {unsorted} voxels"
                );
            }
        }
        let (e, largest) = errors(&g, &cpu);
        let n = e.len();
        let over = e.iter().filter(|&&x| x > 1e-3).count();
        let p999 = e[(n * 999) / 1000];
        let worst = e[n - 1];
        eprintln!(
            "{rel} {:?} at {:?} mm, {method:?} (eigen {eigen}): worst {worst:.2e} of the largest ({largest:.2}), 99.9th percentile {p999:.2e}, {over} of {n} voxels above 1e-3",
            volume.dims, volume.spacing_mm
        );
        if over > (n / 5000).max(2) || p999.is_nan() || p999 >= 1e-4 {
            failures.push((method, eigen, worst, over, p999));
        }
    }
    assert!(failures.is_empty(), "{rel}: {failures:?}");
}

/// Every method, and the Hessian's eigenvalues (refined on thick axes, subsampled back).
const FEATURES: [(Method, bool); 6] = [
    (Method::Hessian, false),
    (Method::Hessian, true),
    (Method::Li, false),
    (Method::Frangi, false),
    (Method::Gst, false),
    (Method::Rst, false),
];

#[test]
fn chest_ct_1_5_mm_features() {
    check("ct/aorta_ct_cropped.nii.gz", [28; 3], &FEATURES);
}

#[test]
fn abdomen_ct_3_mm_features() {
    check("ct/example_ct_sm.nii.gz", [28; 3], &FEATURES);
}

#[test]
fn chest_ct_5_mm_features() {
    check("ct/lung2_image.nrrd", [40, 40, 10], &FEATURES);
}

/// The Hessian's and the RST's eigenvalues on a larger crop.
#[test]
fn chest_ct_1_5_mm_eigenvalues() {
    check(
        "ct/aorta_ct_cropped.nii.gz",
        [40; 3],
        &[(Method::Hessian, true), (Method::Rst, true)],
    );
}

/// Compact features (issue "full-size scans", deliver 3): the MIP drawn from the 4-byte
/// shared-exponent feature texels is within 2 grey levels (of 255) of the MIP drawn from the
/// 8-byte half floats they replaced, on the real features of the 5 mm chest CT (RST, lung
/// preset, and the Hessian), from three directions, through the ray caster's CPU twin (exact
/// to the GPU, tested in tests/gpu/raycast.rs).
#[test]
fn compact_feature_texels_keep_the_mip_within_two_grey_levels() {
    use shapecast::cpu::Preset;
    use shapecast::render::camera::{Camera, ViewPreset};
    use shapecast::render::raycast::{RenderSettings, TwinScene, VolumeGeometry, cpu_twin, params};
    let Some(volume) = crop("ct/lung2_image.nrrd", [128, 128, 30]) else {
        return;
    };
    let Some(ctx) = test_context() else { return };
    for (method, preset) in [
        (Method::Rst, Preset::LungNodules),
        (Method::Li, Preset::LungNodules),
    ] {
        let mut req = Request::new(method);
        req.preset = preset;
        let comps = gpu(&ctx, &volume, &req);
        let compact = TwinScene::new(&volume, Some(&comps));
        let mut halves = TwinScene::new(&volume, Some(&comps));
        let half = |v: f32| half::f16::from_f32(v.clamp(-65504.0, 65504.0)).to_f32();
        halves.features = Some(
            (0..volume.voxel_count())
                .map(|n| [half(comps[0][n]), half(comps[1][n]), half(comps[2][n]), 0.0])
                .collect(),
        );
        let geometry = VolumeGeometry::of_volume(&volume);
        let settings = RenderSettings {
            window: (-1000.0, 400.0),
            ..Default::default()
        };
        // The largest difference from the half-float MIP (grey levels of 255), and the pixels
        // with colour, over three views.
        let compare = |scene: &TwinScene| {
            let mut worst = 0u8;
            let mut coloured = 0usize;
            for view in [ViewPreset::Anterior, ViewPreset::Superior, ViewPreset::Left] {
                let camera = Camera::for_volume(&geometry.world_from_voxel, geometry.dims, view);
                let p = params(
                    &geometry,
                    &camera,
                    &settings,
                    [128, 128],
                    halves.feature_max,
                );
                let (a, b) = (cpu_twin(scene, &p), cpu_twin(&halves, &p));
                for (x, y) in a.rgba.chunks(4).zip(b.rgba.chunks(4)) {
                    for c in 0..3 {
                        worst = worst.max(x[c].abs_diff(y[c]));
                    }
                    coloured += usize::from(x[0].abs_diff(x[2]) > 60);
                }
            }
            (worst, coloured)
        };
        let (worst, coloured) = compare(&compact);
        eprintln!("{method:?}: largest difference {worst} grey levels, {coloured} coloured pixels");
        assert!(
            coloured > 500,
            "{method:?}: hardly any colour ({coloured} pixels)"
        );
        assert!(worst <= 2, "{method:?}: {worst} grey levels apart");

        // Why features are not kept in 2 bytes (issue 11 asks for it, docs/performance.md has
        // the measurements): WebGPU's 2-byte filterable formats hold two 8-bit channels, so
        // V and A would share one (the larger of the two, relative to its maximum, kept), or
        // the features would be kept on a grid twice as coarse along an axis. Even before any
        // quantisation, both move the Hessian's MIP far beyond 2 grey levels: V and A meet at
        // a voxel's multi-scale maxima, and the features' detail is finer than 2 voxels.
        let max = compact.feature_max.unwrap_or([1.0; 3]);
        let dims = volume.dims;
        let at = |i: usize, j: usize, k: usize| i + dims[0] * (j + dims[1] * k);
        let merged: Vec<[f32; 4]> = (0..volume.voxel_count())
            .map(|n| {
                let [v, a, b] = [comps[0][n], comps[1][n], comps[2][n]].map(|x| half(x.max(0.0)));
                if v / max[0] >= a / max[1] {
                    [v, 0.0, b, 0.0]
                } else {
                    [0.0, a, b, 0.0]
                }
            })
            .collect();
        // Kept at even x, linear between (what sampling a half-width texture gives).
        let coarse: Vec<[f32; 4]> = (0..volume.voxel_count())
            .map(|n| {
                let (i, j, k) = (
                    n % dims[0],
                    (n / dims[0]) % dims[1],
                    n / (dims[0] * dims[1]),
                );
                let (i0, i1) = if i % 2 == 0 || i + 1 >= dims[0] {
                    (i - i % 2, i - i % 2)
                } else {
                    (i - 1, i + 1)
                };
                let (n0, n1) = (at(i0, j, k), at(i1, j, k));
                let f = |c: usize| half(0.5 * (comps[c][n0].max(0.0) + comps[c][n1].max(0.0)));
                [f(0), f(1), f(2), 0.0]
            })
            .collect();
        let mut alt = TwinScene::new(&volume, Some(&comps));
        alt.features = Some(merged);
        let (merged_worst, _) = compare(&alt);
        alt.features = Some(coarse);
        let (coarse_worst, _) = compare(&alt);
        eprintln!(
            "{method:?}: V and A in one channel: {merged_worst} grey levels; a grid twice as coarse in x: {coarse_worst}"
        );
        assert!(coarse_worst > 10, "{method:?}: coarse grid {coarse_worst}");
        if method == Method::Li {
            assert!(
                merged_worst > 10,
                "{method:?}: V and A merged {merged_worst}"
            );
        }
    }
}

/// Over budget, the features are kept max-pooled (issue "any length", deliver 4), measured on
/// the real CTA of ../shared/data (Li, vessels preset), through the ray caster's CPU twin (the
/// GPU's, pixel for pixel, in tests/gpu/levels.rs), at a zoom where a pooled texel is about one
/// pixel. Asserted: with one feature shown alone, no pixel of the pooled picture is dimmer than
/// the full-resolution picture at the same zoom (no maximum is lost). Printed: how far each of
/// the two is from the full-resolution MIP drawn at 2x (4x) the pixels and max-pooled to the same
/// size (what the pane would show if it could draw every voxel): the share of channel values
/// within 2 grey levels, the pixels dimmer than it, the largest excess.
#[test]
fn pooled_features_keep_every_maximum_of_a_real_cta() {
    use shapecast::cpu::Preset;
    use shapecast::render::camera::{Camera, ViewPreset};
    use shapecast::render::raycast::{
        ChannelDisplay, RenderSettings, TwinScene, VolumeGeometry, cpu_twin, params,
    };
    let Some(volume) = crop("ct/aorta_ct_cropped.nii.gz", [96, 96, 96]) else {
        return;
    };
    let Some(ctx) = test_context() else { return };
    let mut req = Request::new(Method::Li);
    req.preset = Preset::Vessels;
    let comps = gpu(&ctx, &volume, &req);
    let full = TwinScene::new(&volume, Some(&comps));
    let geometry = VolumeGeometry::of_volume(&volume);
    let composite = RenderSettings {
        window: (-200.0, 600.0),
        ..Default::default()
    };
    // One feature alone on black: its colour channel (red for V, green for yellow B) grows with
    // the feature's maximum along the ray.
    let alone = |c: usize| {
        let mut s = RenderSettings {
            show_intensity: false,
            ..composite
        };
        for k in 0..3 {
            s.channels[k] = ChannelDisplay {
                on: k == c,
                gain: 1.0,
            };
        }
        s
    };
    for level in [1u32, 2] {
        let pooled = TwinScene::pooled(&volume, Some(&comps), level);
        let f = 1usize << level;
        for (what, settings, channel) in [
            ("composite", composite, None),
            ("vesselness", alone(0), Some(0)),
            ("blobness", alone(2), Some(1)),
        ] {
            // [pooled, dense at the same zoom]: values within 2 levels of the max-pooled fine
            // picture, values dimmer than it, largest excess; and pooled dimmer than dense.
            let mut stats = [(0usize, 0usize, 0u8); 2];
            let (mut total, mut lost) = (0usize, 0usize);
            for view in [ViewPreset::Anterior, ViewPreset::Superior, ViewPreset::Left] {
                let camera = Camera::for_volume(&geometry.world_from_voxel, geometry.dims, view);
                // The crop's 96 voxels across the picture: a pooled texel per pixel.
                let n = 96 / f;
                let p = params(
                    &geometry,
                    &camera,
                    &settings,
                    [n as u32; 2],
                    full.feature_max,
                );
                let fine = [(n * f) as u32; 2];
                let pictures = [cpu_twin(&pooled, &p), cpu_twin(&full, &p)];
                let b = cpu_twin(
                    &full,
                    &params(&geometry, &camera, &settings, fine, full.feature_max),
                );
                for y in 0..n {
                    for x in 0..n {
                        for c in 0..3 {
                            // The fine pixels under this one, max-pooled.
                            let mut m = 0u8;
                            for dy in 0..f {
                                for dx in 0..f {
                                    let q = (x * f + dx) + n * f * (y * f + dy);
                                    m = m.max(b.rgba[4 * q + c]);
                                }
                            }
                            total += 1;
                            let at = 4 * (x + n * y) + c;
                            for (s, pic) in stats.iter_mut().zip(&pictures) {
                                let v = pic.rgba[at];
                                s.0 += usize::from(v.abs_diff(m) <= 2);
                                s.1 += usize::from(u16::from(v) + 2 < u16::from(m));
                                s.2 = s.2.max(v.saturating_sub(m));
                            }
                            let (v, d) = (pictures[0].rgba[at], pictures[1].rgba[at]);
                            if channel == Some(c) && u16::from(v) + 1 < u16::from(d) {
                                lost += 1;
                            }
                        }
                    }
                }
            }
            let share = |s: usize| 100.0 * s as f64 / total as f64;
            eprintln!(
                "level {level}, {what}: against the max-pooled fine MIP, pooled {:.1}% within 2 levels ({} dimmer, largest excess {}), dense at this zoom {:.1}% ({} dimmer, largest excess {}); pooled dimmer than dense: {lost}",
                share(stats[0].0),
                stats[0].1,
                stats[0].2,
                share(stats[1].0),
                stats[1].1,
                stats[1].2
            );
            assert_eq!(lost, 0, "level {level}, {what}: a maximum lost");
            // Pooled is at least as close to what a full-detail pane would show as the dense
            // picture at this zoom, in what it must not lose: pixels dimmer than it.
            assert!(
                stats[0].1 <= stats[1].1,
                "level {level}, {what}: pooled loses more than dense"
            );
        }
    }
}
