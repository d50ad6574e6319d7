//! The MIP ray caster on the test adapter (lavapipe in CI) against its CPU twin, and against the
//! camera's own geometry: images agree to a level of 8 bits, picks to a voxel, anisotropic and
//! oblique volumes land where the camera projects them, slabs and MinIP do what they say.

use glam::{DMat3, DQuat, DVec3};
use shapecast::gpu::GpuContext;
use shapecast::gpu::context::test_context;
use shapecast::gpu::volume_texture::{FeatureTexture, RenderVolume};
use shapecast::render::camera::{Camera, ViewPreset};
use shapecast::render::raycast::{
    BrickSource, Channel, ChannelDisplay, FrameCost, Projection, RaycastTarget, Raycaster,
    RenderSettings, Scene, Slab, TwinScene, VolumeGeometry, cpu_twin, params,
};
use shapecast::volume::Volume;

/// A small LCG: test data without a dependency.
struct Lcg(u64);
impl Lcg {
    fn next(&mut self) -> f32 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((self.0 >> 40) as f32) / (1u64 << 24) as f32
    }
}

/// An oblique, anisotropic volume of odd size with smooth structure plus noise, and three
/// feature components with distinct maxima.
fn scene() -> (Volume, [Vec<f32>; 3]) {
    let dims = [13usize, 10, 7];
    let spacing = [0.7, 0.9, 2.5];
    let n = dims[0] * dims[1] * dims[2];
    let mut rng = Lcg(7);
    let mut values = Vec::with_capacity(n);
    let mut comps = [vec![0.0f32; n], vec![0.0f32; n], vec![0.0f32; n]];
    for k in 0..dims[2] {
        for j in 0..dims[1] {
            for i in 0..dims[0] {
                let (x, y, z) = (i as f32 - 6.0, j as f32 - 4.5, k as f32 - 3.0);
                let blob = 400.0 * (-(x * x + y * y + z * z) / 6.0).exp();
                values.push(-200.0 + blob + 300.0 * rng.next());
                let idx = i + dims[0] * (j + dims[1] * k);
                comps[0][idx] = 50.0 * rng.next() + 40.0 * (-(y * y) / 3.0).exp();
                comps[1][idx] = 30.0 * rng.next() * (x > 2.0) as u8 as f32;
                comps[2][idx] = 60.0 * (-((x + 3.0).powi(2) + z * z) / 2.0).exp() * rng.next();
            }
        }
    }
    let mut v = Volume::from_f32(dims, spacing, values);
    v.origin_mm = [-20.0, 35.0, 110.0];
    v.direction = DMat3::from_quat(DQuat::from_euler(glam::EulerRot::ZYX, 0.4, -0.25, 0.15));
    (v, comps)
}

struct Gpu {
    ctx: GpuContext,
    caster: Raycaster,
    volume: RenderVolume,
    features: FeatureTexture,
}

fn gpu(volume: &Volume, comps: &[Vec<f32>; 3]) -> Option<Gpu> {
    let ctx = test_context()?;
    let caster = Raycaster::new(&ctx).expect("shader");
    let rv = RenderVolume::upload(&ctx, volume).expect("upload");
    let dims = volume.dims.map(|d| d as u32);
    let features = FeatureTexture::from_components(&ctx, dims, comps, "test").expect("features");
    Some(Gpu {
        ctx,
        caster,
        volume: rv,
        features,
    })
}

/// Renders on the GPU and with the twin; returns (gpu rgba, twin rgba, gpu depths, twin depths).
#[allow(clippy::type_complexity)]
fn both(
    g: &Gpu,
    twin: &TwinScene,
    camera: &Camera,
    settings: &RenderSettings,
    size: [u32; 2],
    with_features: bool,
    skip: bool,
) -> (
    Vec<u8>,
    Vec<u8>,
    Vec<[f32; 2]>,
    Vec<[f32; 2]>,
    RaycastTarget,
) {
    let mut target = RaycastTarget::new(&g.ctx, size).expect("target");
    let feats = with_features.then_some(&g.features);
    let bricks = skip.then(|| g.caster.intensity_bricks(&g.ctx, &g.volume));
    let feature_bricks = skip.then(|| g.caster.feature_bricks(&g.ctx, &g.features));
    let scene = Scene {
        volume: &g.volume,
        features: feats,
        bricks: bricks.as_ref(),
        feature_bricks: feature_bricks.as_ref(),
    };
    assert_eq!(scene.skipping(), skip);
    g.caster
        .render(&g.ctx, &scene, camera, settings, &mut target, ..)
        .expect("render");
    let image = target.read_image_blocking(&g.ctx).expect("image");
    let depths = target.read_depths_blocking(&g.ctx).expect("depths");
    let p = params(
        &VolumeGeometry::of(&g.volume),
        camera,
        settings,
        size,
        feats.map(|f| f.max),
    );
    let p = if skip { p.with_skipping() } else { p };
    let t = cpu_twin(twin, &p);
    (image, t.rgba, depths, t.depths, target)
}

#[test]
fn gpu_matches_cpu_twin_images_and_picks() {
    let (volume, comps) = scene();
    let Some(g) = gpu(&volume, &comps) else {
        return;
    };
    eprintln!("adapter: {}", g.ctx.adapter_label());
    let twin = TwinScene::new(&volume, Some(&comps));
    let base = Camera::for_volume(
        &volume.world_from_voxel(),
        g.volume.dims,
        ViewPreset::Anterior,
    );
    let mut oblique = base;
    oblique.orbit(31.0, -17.0);
    oblique.zoom = 1.3;
    let mut left = base;
    left.set_preset(ViewPreset::Left);
    let mut gains = RenderSettings {
        window: (-100.0, 300.0),
        ..Default::default()
    };
    gains.channels[0].gain = 1.5;
    gains.channels[2].gain = 2.0;
    let slab = RenderSettings {
        slab: Some(Slab {
            centre_mm: volume
                .world_from_voxel()
                .transform_point3(DVec3::new(6.0, 4.0, 3.0)),
            thickness_mm: 5.0,
        }),
        ..gains
    };
    let minip = RenderSettings {
        projection: Projection::MinIp,
        ..gains
    };
    let cases: [(&str, Camera, RenderSettings, [u32; 2], bool); 6] = [
        ("anterior intensity", base, gains, [37, 29], false),
        ("anterior features", base, gains, [37, 29], true),
        ("oblique features", oblique, gains, [41, 33], true),
        ("left slab", left, slab, [31, 45], true),
        ("oblique minip", oblique, minip, [29, 29], true),
        (
            "superior no-blob",
            base.with_orbit(ViewPreset::Superior, 0.0, 0.0),
            RenderSettings {
                channels: [
                    ChannelDisplay::default(),
                    ChannelDisplay::default(),
                    ChannelDisplay {
                        on: false,
                        gain: 1.0,
                    },
                ],
                ..gains
            },
            [33, 27],
            true,
        ),
    ];
    for ((name, camera, settings, size, with_features), skip) in
        cases.into_iter().flat_map(|c| [(c, false), (c, true)])
    {
        let name = format!("{name}{}", if skip { ", skipping" } else { "" });
        let (gi, ti, gd, td, target) =
            both(&g, &twin, &camera, &settings, size, with_features, skip);
        assert_eq!(gi.len(), ti.len());
        let diffs: Vec<u8> = gi.iter().zip(&ti).map(|(a, b)| a.abs_diff(*b)).collect();
        let max = diffs.iter().copied().max().unwrap_or(0);
        let over1 = diffs.iter().filter(|&&d| d > 1).count();
        let lit = gi
            .chunks(4)
            .filter(|p| p[..3].iter().any(|&c| c > 0))
            .count();
        let coloured = gi
            .chunks(4)
            .filter(|p| p[0].abs_diff(p[1]) > 30 || p[1].abs_diff(p[2]) > 30)
            .count();
        // Picks: same channel, and the same sample or the next one along the ray.
        let view = target.rendered().copied().expect("rendered");
        let step = params(
            &VolumeGeometry::of(&g.volume),
            &camera,
            &settings,
            size,
            None,
        )
        .step_mm;
        let mut far_picks = 0;
        let mut far_voxels = 0;
        let mut misses = 0;
        for (n, (a, b)) in gd.iter().zip(&td).enumerate() {
            if a[1] < 0.0 || b[1] < 0.0 {
                misses += 1;
                assert_eq!(a[1], b[1], "{name}: hit on one side only at pixel {n}");
                continue;
            }
            if a[1] != b[1] || (a[0] - b[0]).abs() > 1.01 * step {
                far_picks += 1;
            }
            let px = [n as u32 % size[0], n as u32 / size[0]];
            let (pa, pb) = (view.pick_from(px, *a), view.pick_from(px, *b));
            let (Some(pa), Some(pb)) = (pa, pb) else {
                panic!("{name}: no pick")
            };
            if (0..3).any(|k| pa.voxel[k].abs_diff(pb.voxel[k]) > 1) {
                far_voxels += 1;
            }
        }
        let pixels = (size[0] * size[1]) as usize;
        eprintln!(
            "{name}: max diff {max} levels, {over1} of {} channel values > 1; {lit} lit, {coloured} coloured, {misses} misses; picks off by > 1 sample: {far_picks}, by > 1 voxel: {far_voxels}",
            diffs.len()
        );
        assert!(lit > pixels / 4, "{name}: image nearly blank ({lit} lit)");
        if with_features {
            assert!(
                coloured > pixels / 20,
                "{name}: no feature colour ({coloured})"
            );
        }
        assert!(max <= 2, "{name}: GPU and twin differ by {max} levels");
        assert!(
            over1 * 200 <= diffs.len(),
            "{name}: {over1} values differ by 2 levels"
        );
        assert!(
            far_picks * 100 <= pixels,
            "{name}: {far_picks} picks differ by more than a sample"
        );
        assert_eq!(far_voxels, 0, "{name}: picks differ by more than one voxel");
    }
}

/// A bright spot in an oblique, anisotropic volume appears where the camera projects its world
/// position, and a click there lands on it: the geometry, independently of the twin.
#[test]
fn bright_spot_lands_where_the_camera_projects_it() {
    let dims = [21usize, 15, 9];
    let mut values = vec![0.0f32; dims[0] * dims[1] * dims[2]];
    let spot = [14usize, 5, 6];
    for dk in 0..2 {
        for dj in 0..2 {
            for di in 0..2 {
                values[spot[0] + di + dims[0] * (spot[1] + dj + dims[1] * (spot[2] + dk))] = 1000.0;
            }
        }
    }
    let mut volume = Volume::from_f32(dims, [0.6, 1.1, 3.0], values);
    volume.origin_mm = [40.0, -10.0, 5.0];
    volume.direction = DMat3::from_quat(DQuat::from_euler(glam::EulerRot::XYZ, 0.3, 0.5, -0.2));
    let comps = [
        vec![0.0; volume.voxel_count()],
        vec![0.0; volume.voxel_count()],
        vec![0.0; volume.voxel_count()],
    ];
    let Some(g) = gpu(&volume, &comps) else {
        return;
    };
    let centre_v = DVec3::new(
        spot[0] as f64 + 0.5,
        spot[1] as f64 + 0.5,
        spot[2] as f64 + 0.5,
    );
    let spot_world = volume.world_from_voxel().transform_point3(centre_v);
    let settings = RenderSettings {
        window: (0.0, 1000.0),
        ..Default::default()
    };
    let size = [64, 48];
    for (preset, yaw, pitch, zoom) in [
        (ViewPreset::Anterior, 0.0, 0.0, 1.0),
        (ViewPreset::Left, 20.0, 10.0, 1.5),
        (ViewPreset::Inferior, -35.0, 40.0, 2.0),
    ] {
        let mut camera = Camera::for_volume(&volume.world_from_voxel(), g.volume.dims, preset);
        camera.orbit(yaw, pitch);
        camera.zoom = zoom;
        let mut target = RaycastTarget::new(&g.ctx, size).expect("target");
        g.caster
            .render(
                &g.ctx,
                &Scene::new(&g.volume, None),
                &camera,
                &settings,
                &mut target,
                ..,
            )
            .expect("render");
        let image = target.read_image_blocking(&g.ctx).expect("image");
        let px = camera
            .project_to_pixel(spot_world, size)
            .expect("spot in view");
        let at = |p: [u32; 2]| image[4 * (p[0] + size[0] * p[1]) as usize];
        assert!(
            at(px) > 200,
            "{preset:?}: the spot is not at {px:?} ({})",
            at(px)
        );
        // The brightest pixels are all near the projected spot.
        for y in 0..size[1] {
            for x in 0..size[0] {
                if at([x, y]) > 200 {
                    let d = (x as i64 - px[0] as i64)
                        .abs()
                        .max((y as i64 - px[1] as i64).abs());
                    assert!(
                        d <= 8,
                        "{preset:?}: bright pixel ({x}, {y}) far from {px:?}"
                    );
                }
            }
        }
        let pick = target
            .pick_blocking(&g.ctx, px)
            .expect("readback")
            .expect("a hit");
        assert_eq!(pick.channel, Channel::Intensity);
        let off = pick.voxel_f - centre_v;
        assert!(
            off.abs().max_element() <= 1.0,
            "{preset:?}: pick at voxel {:?}, spot at {centre_v}",
            pick.voxel_f
        );
        assert!((pick.world_mm - spot_world).length() < 3.0, "{preset:?}");
    }
}

/// A slab that leaves the spot out hides it; MinIP shows the darkest sample; a pixel outside
/// the volume is black and picks nothing.
#[test]
fn slab_minip_and_misses() {
    let dims = [11usize, 11, 11];
    let mut values = vec![100.0f32; 11 * 11 * 11];
    values[8 + 11 * (5 + 11 * 5)] = 1000.0; // bright at i = 8
    values[2 + 11 * (5 + 11 * 5)] = -900.0; // dark at i = 2
    let volume = Volume::from_f32(dims, [1.0; 3], values);
    let comps = [vec![0.0; 1331], vec![0.0; 1331], vec![0.0; 1331]];
    let Some(g) = gpu(&volume, &comps) else {
        return;
    };
    // Looking along -x (left view): both voxels on the ray through the centre.
    let mut camera =
        Camera::for_volume(&volume.world_from_voxel(), g.volume.dims, ViewPreset::Left);
    camera.zoom = 1.0;
    let size = [33, 33];
    let centre_px = camera
        .project_to_pixel(DVec3::new(5.0, 5.0, 5.0), size)
        .expect("centre");
    let render = |settings: RenderSettings| {
        let mut target = RaycastTarget::new(&g.ctx, size).expect("target");
        g.caster
            .render(
                &g.ctx,
                &Scene::new(&g.volume, None),
                &camera,
                &settings,
                &mut target,
                ..,
            )
            .expect("render");
        let image = target.read_image_blocking(&g.ctx).expect("image");
        let pick = target.pick_blocking(&g.ctx, centre_px).expect("readback");
        let corner = target.pick_blocking(&g.ctx, [0, 0]).expect("readback");
        (image, pick, corner)
    };
    let window = (-1000.0, 1000.0);
    let grey = |image: &Vec<u8>, p: [u32; 2]| image[4 * (p[0] + size[0] * p[1]) as usize];
    let full = RenderSettings {
        window,
        ..Default::default()
    };
    let (image, pick, corner) = render(full);
    assert_eq!(grey(&image, centre_px), 255);
    let pick = pick.expect("hit");
    assert!(pick.voxel[0].abs_diff(8) <= 1, "{pick:?}");
    // The box is framed by its bounding sphere: the image corner lies outside it.
    assert!(corner.is_none(), "{corner:?}");
    assert_eq!(&image[..4], &[0, 0, 0, 255]);
    // A 3 mm slab around x = 3 leaves the bright voxel out.
    let slab = RenderSettings {
        slab: Some(Slab {
            centre_mm: DVec3::new(3.0, 5.0, 5.0),
            thickness_mm: 3.0,
        }),
        ..full
    };
    let (image, pick, _) = render(slab);
    assert!(grey(&image, centre_px) < 160, "{}", grey(&image, centre_px));
    assert!(pick.expect("hit").voxel[0].abs_diff(3) <= 2);
    // MinIP finds the dark voxel.
    let minip = RenderSettings {
        projection: Projection::MinIp,
        ..full
    };
    let (image, pick, _) = render(minip);
    // -900 HU in the window -1000..1000: grey 0.05 (13 of 255) against 140 for the tissue.
    assert!(grey(&image, centre_px) < 20, "{}", grey(&image, centre_px));
    let pick = pick.expect("hit");
    assert!(pick.voxel[0].abs_diff(2) <= 1, "{pick:?}");
}

/// The hardware-filtered path (one trilinear sample by the texture unit instead of 8 loads)
/// against the exact CPU twin: the interpolation weights are the sampler's, so values and
/// picks agree within a tolerance, not exactly.
#[test]
fn hardware_filtering_matches_the_twin_within_tolerance() {
    let (volume, comps) = scene();
    let Some(g) = gpu(&volume, &comps) else {
        return;
    };
    let twin = TwinScene::new(&volume, Some(&comps));
    let base = Camera::for_volume(
        &volume.world_from_voxel(),
        g.volume.dims,
        ViewPreset::Anterior,
    );
    let mut oblique = base;
    oblique.orbit(-23.0, 38.0);
    oblique.zoom = 1.2;
    let settings = RenderSettings {
        window: (-100.0, 300.0),
        hardware_filtering: true,
        ..Default::default()
    };
    let minip = RenderSettings {
        projection: Projection::MinIp,
        ..settings
    };
    for (name, camera, settings, size) in [
        ("anterior", base, settings, [37, 29]),
        ("oblique", oblique, settings, [41, 35]),
        ("oblique minip", oblique, minip, [29, 31]),
    ] {
        let (gi, ti, gd, td, target) = both(&g, &twin, &camera, &settings, size, true, true);
        let diffs: Vec<u8> = gi.iter().zip(&ti).map(|(a, b)| a.abs_diff(*b)).collect();
        let max = diffs.iter().copied().max().unwrap_or(0);
        let over2 = diffs.iter().filter(|&&d| d > 2).count();
        let view = target.rendered().copied().expect("rendered");
        let (mut hits, mut far) = (0, 0);
        for (n, (a, b)) in gd.iter().zip(&td).enumerate() {
            let px = [n as u32 % size[0], n as u32 / size[0]];
            if let (Some(pa), Some(pb)) = (view.pick_from(px, *a), view.pick_from(px, *b)) {
                hits += 1;
                if (0..3).any(|k| pa.voxel[k].abs_diff(pb.voxel[k]) > 1) {
                    far += 1;
                }
            }
        }
        eprintln!(
            "hardware {name}: max diff {max} levels, {over2} of {} values > 2; {far} of {hits} picks > 1 voxel apart",
            diffs.len()
        );
        assert!(hits > 100);
        assert!(max <= 8, "{name}: {max} levels");
        assert!(
            over2 * 100 <= diffs.len(),
            "{name}: {over2} values > 2 levels"
        );
        assert!(
            far * 50 <= hits,
            "{name}: {far} of {hits} picks more than a voxel apart"
        );
    }
}

/// The frame time of the MIP for a 256^3 volume at 768x768 (a benchmark, not a timed test):
/// `cargo test --test gpu -- --ignored --nocapture raycast::bench`. Synthetic spheres and
/// cylinders with synthetic features (the features' content does not change the cost: every
/// sample loads them). Each frame turns the view by 2 degrees, as a drag does, and waits for
/// the GPU.
#[test]
#[ignore = "benchmark: run explicitly"]
fn bench_256_cubed_at_768() {
    let Some(ctx) = test_context() else { return };
    let n = 256usize;
    let dims = [n; 3];
    let mut values = vec![0.0f32; n * n * n];
    let mut comps = [
        vec![0.0f32; n * n * n],
        vec![0.0f32; n * n * n],
        vec![0.0f32; n * n * n],
    ];
    let spheres = [
        ([80.0, 100.0, 128.0], 14.0),
        ([170.0, 150.0, 100.0], 10.0),
        ([128.0, 190.0, 180.0], 18.0),
    ];
    for k in 0..n {
        for j in 0..n {
            for i in 0..n {
                let p = [i as f64, j as f64, k as f64];
                let idx = i + n * (j + n * k);
                let in_vessel = ((p[0] - 128.0).powi(2) + (p[1] - 128.0).powi(2)).sqrt() < 8.0
                    || ((p[1] - 90.0).powi(2) + (p[2] - 140.0).powi(2)).sqrt() < 6.0;
                let in_sphere = spheres.iter().any(|(c, r)| {
                    ((p[0] - c[0]).powi(2) + (p[1] - c[1]).powi(2) + (p[2] - c[2]).powi(2)).sqrt()
                        < *r
                });
                values[idx] = if in_vessel || in_sphere {
                    200.0
                } else {
                    40.0 + ((idx * 7919) % 23) as f32
                };
                comps[0][idx] = if in_vessel { 50.0 } else { 0.0 };
                comps[2][idx] = if in_sphere { 30.0 } else { 0.0 };
            }
        }
    }
    let volume = Volume::from_f32(dims, [0.7, 0.7, 0.7], values);
    let caster = Raycaster::new(&ctx).expect("shader");
    let rv = RenderVolume::upload(&ctx, &volume).expect("upload");
    let features =
        FeatureTexture::from_components(&ctx, [256; 3], &comps, "bench").expect("features");
    drop(comps);
    let size = [768, 768];
    let mut target = RaycastTarget::new(&ctx, size).expect("target");
    let frames = 3;
    eprintln!("adapter: {}", ctx.adapter_label());
    let bricks = caster.intensity_bricks(&ctx, &rv);
    let feature_bricks = caster.feature_bricks(&ctx, &features);
    for (name, hw, with_features, zoom, skip) in [
        ("intensity, shader trilinear", false, false, 1.0, false),
        (
            "intensity, shader trilinear, skipping",
            false,
            false,
            1.0,
            true,
        ),
        ("intensity, hardware trilinear", true, false, 1.0, false),
        (
            "intensity, hardware trilinear, skipping",
            true,
            false,
            1.0,
            true,
        ),
        (
            "intensity + features, shader trilinear",
            false,
            true,
            1.0,
            false,
        ),
        (
            "intensity + features, hardware trilinear",
            true,
            true,
            1.0,
            false,
        ),
        (
            "intensity + features, hardware trilinear, skipping",
            true,
            true,
            1.0,
            true,
        ),
        (
            "intensity + features, hardware trilinear, skipping, volume fills the view",
            true,
            true,
            1.7,
            true,
        ),
    ] {
        let settings = RenderSettings {
            window: (0.0, 250.0),
            hardware_filtering: hw,
            ..Default::default()
        };
        let mut camera =
            Camera::for_volume(&volume.world_from_voxel(), [256; 3], ViewPreset::Anterior);
        camera.zoom = zoom;
        let feats = with_features.then_some(&features);
        let scene = Scene {
            volume: &rv,
            features: feats,
            bricks: skip.then_some(&bricks),
            feature_bricks: skip.then_some(&feature_bricks),
        };
        // Warm-up frame: pipeline compilation.
        caster
            .render(&ctx, &scene, &camera, &settings, &mut target, ..)
            .expect("render");
        ctx.device
            .poll(wgpu::PollType::wait_indefinitely())
            .expect("poll");
        let mut times = Vec::new();
        for _ in 0..frames {
            camera.orbit(2.0, 0.0);
            let t = std::time::Instant::now();
            caster
                .render(&ctx, &scene, &camera, &settings, &mut target, ..)
                .expect("render");
            ctx.device
                .poll(wgpu::PollType::wait_indefinitely())
                .expect("poll");
            times.push(t.elapsed().as_secs_f64() * 1e3);
        }
        let mean = times.iter().sum::<f64>() / times.len() as f64;
        let min = times.iter().copied().fold(f64::INFINITY, f64::min);
        eprintln!(
            "bench 256^3 @ 768x768, {name} (zoom {zoom}): mean {mean:.0} ms, min {min:.0} ms over {frames} frames"
        );
    }
}

/// Empty-space skipping is exact: with and without bricks the GPU draws the same picture and
/// depths, the twin too, and the twin evaluates far fewer samples. The brick kernel matches its
/// CPU twin exactly.
#[test]
fn skipping_is_exact_and_skips() {
    let dims = [41usize, 36, 23];
    let n = dims[0] * dims[1] * dims[2];
    let mut rng = Lcg(11);
    let mut values = Vec::with_capacity(n);
    let mut comps = [vec![0.0f32; n], vec![0.0f32; n], vec![0.0f32; n]];
    let spheres = [
        ([10.0, 12.0, 8.0], 4.0),
        ([30.0, 20.0, 15.0], 5.0),
        ([22.0, 28.0, 5.0], 3.0),
    ];
    for k in 0..dims[2] {
        for j in 0..dims[1] {
            for i in 0..dims[0] {
                let p = [i as f32, j as f32, k as f32];
                let idx = i + dims[0] * (j + dims[1] * k);
                let vessel = ((p[0] - 20.0).powi(2) + (p[2] - 11.0).powi(2)).sqrt() < 2.5;
                let sphere = spheres.iter().any(|(c, r)| {
                    ((p[0] - c[0]).powi(2) + (p[1] - c[1]).powi(2) + (p[2] - c[2]).powi(2)).sqrt()
                        < *r
                });
                // Noise in the lower half only: homogeneous tissue above (as in a noise-free
                // phantom), where intensity bricks skip too.
                let noise = if k < 12 { 20.0 * rng.next() } else { 0.0 };
                values.push(if vessel || sphere {
                    300.0
                } else {
                    20.0 + noise
                });
                comps[0][idx] = if vessel { 40.0 + rng.next() } else { 0.0 };
                comps[2][idx] = if sphere { 25.0 + rng.next() } else { 0.0 };
            }
        }
    }
    let mut volume = Volume::from_f32(dims, [0.8, 0.6, 1.9], values);
    volume.direction = DMat3::from_quat(DQuat::from_euler(glam::EulerRot::YXZ, 0.2, -0.3, 0.1));
    volume.origin_mm = [5.0, -7.0, 30.0];
    let Some(g) = gpu(&volume, &comps) else {
        return;
    };
    let twin = TwinScene::new(&volume, Some(&comps));
    // The brick kernel.
    let b = g.caster.intensity_bricks(&g.ctx, &g.volume);
    let fb = g.caster.feature_bricks(&g.ctx, &g.features);
    assert_eq!(b.dims, [5, 5, 3]);
    let (gb, gfb) = (
        b.read_blocking(&g.ctx).expect("bricks"),
        fb.read_blocking(&g.ctx).expect("bricks"),
    );
    // Made a brick slice at a time (as the viewer spreads a large table over frames): the
    // same table, and skipping only once it is complete.
    let mut stepped = g
        .caster
        .start_bricks(&g.ctx, BrickSource::Features(&g.features));
    let mut steps = 0;
    while !stepped.complete() {
        let scene = Scene {
            volume: &g.volume,
            features: Some(&g.features),
            bricks: Some(&b),
            feature_bricks: Some(&stepped),
        };
        assert!(!scene.skipping(), "skipping with an incomplete table");
        assert!(stepped.advance(&g.caster, &g.ctx, 1) > 0);
        steps += 1;
    }
    assert_eq!(steps, 3);
    assert_eq!(stepped.read_blocking(&g.ctx).expect("bricks"), gfb);
    let tb = twin.bricks.as_ref().expect("twin bricks");
    let tfb = twin.feature_bricks.as_ref().expect("twin feature bricks");
    for (n, (x, y)) in gb.iter().zip(tb).enumerate() {
        assert_eq!((x[0], x[1]), (y[0], y[1]), "intensity brick {n}");
    }
    for (n, (x, y)) in gfb.iter().zip(tfb).enumerate() {
        assert_eq!(x[..3], y[..3], "feature brick {n}");
    }

    let base = Camera::for_volume(
        &volume.world_from_voxel(),
        g.volume.dims,
        ViewPreset::Anterior,
    );
    let mut oblique = base;
    oblique.orbit(40.0, -25.0);
    oblique.zoom = 1.4;
    let settings = RenderSettings {
        window: (0.0, 300.0),
        ..Default::default()
    };
    let mut only_blobs = settings;
    only_blobs.channels[0].on = false;
    let cases = [
        ("anterior", base, settings, true),
        ("oblique", oblique, settings, true),
        ("oblique intensity only", oblique, settings, false),
        ("oblique blobness only", oblique, only_blobs, true),
        (
            "superior minip",
            base.with_orbit(ViewPreset::Superior, 10.0, 0.0),
            RenderSettings {
                projection: Projection::MinIp,
                ..settings
            },
            true,
        ),
        (
            "left slab",
            base.with_orbit(ViewPreset::Left, 0.0, 0.0),
            RenderSettings {
                slab: Some(Slab {
                    centre_mm: volume
                        .world_from_voxel()
                        .transform_point3(DVec3::new(20.0, 18.0, 11.0)),
                    thickness_mm: 9.0,
                }),
                ..settings
            },
            true,
        ),
    ];
    let size = [47, 39];
    for (name, camera, settings, with_features) in cases {
        let (gi0, ti0, gd0, _, _) = both(&g, &twin, &camera, &settings, size, with_features, false);
        let (gi1, ti1, gd1, td1, _) =
            both(&g, &twin, &camera, &settings, size, with_features, true);
        assert_eq!(gi0, gi1, "{name}: skipping changed the GPU picture");
        assert_eq!(gd0, gd1, "{name}: skipping changed the GPU depths");
        assert_eq!(ti0, ti1, "{name}: skipping changed the twin's picture");
        assert_eq!(gi1, ti1, "{name}: GPU and twin differ with skipping");
        assert_eq!(gd1, td1, "{name}: GPU and twin depths differ with skipping");
        let p = params(
            &VolumeGeometry::of(&g.volume),
            &camera,
            &settings,
            size,
            with_features.then_some(g.features.max),
        );
        let all = cpu_twin(&twin, &p);
        let skipped = cpu_twin(&twin, &p.with_skipping());
        eprintln!(
            "{name}: skipping evaluates {} of {} intensity samples, {} of {} feature samples",
            skipped.samples, all.samples, skipped.feature_samples, all.feature_samples
        );
        assert!(all.samples > 10_000, "{name}: {} samples", all.samples);
        assert!(
            skipped.samples * 10 < all.samples * 9,
            "{name}: {} of {} intensity samples",
            skipped.samples,
            all.samples
        );
        if with_features {
            assert!(
                skipped.feature_samples * 10 < all.feature_samples * 7,
                "{name}: {} of {} feature samples",
                skipped.feature_samples,
                all.feature_samples
            );
        }
    }
}

/// Progressive rendering: a frame drawn in bands of rows (uneven bands, some not whole
/// workgroups, with empty-space skipping and hardware filtering on) is the same, byte for byte
/// and depth for depth, as the frame drawn whole; a band leaves the other rows untouched.
#[test]
fn bands_of_rows_draw_the_same_frame() {
    let (volume, comps) = scene();
    let Some(g) = gpu(&volume, &comps) else {
        return;
    };
    let mut camera = Camera::for_volume(
        &volume.world_from_voxel(),
        g.volume.dims,
        ViewPreset::Anterior,
    );
    camera.orbit(30.0, 20.0);
    let settings = RenderSettings {
        window: (-200.0, 400.0),
        hardware_filtering: true,
        ..Default::default()
    };
    let size = [61, 47];
    let bricks = g.caster.intensity_bricks(&g.ctx, &g.volume);
    let feature_bricks = g.caster.feature_bricks(&g.ctx, &g.features);
    let scene = Scene {
        volume: &g.volume,
        features: Some(&g.features),
        bricks: Some(&bricks),
        feature_bricks: Some(&feature_bricks),
    };
    let mut whole = RaycastTarget::new(&g.ctx, size).expect("target");
    g.caster
        .render(&g.ctx, &scene, &camera, &settings, &mut whole, ..)
        .expect("render");
    let (image, depths) = (
        whole.read_image_blocking(&g.ctx).expect("image"),
        whole.read_depths_blocking(&g.ctx).expect("depths"),
    );
    assert!(image.chunks(4).any(|p| p[0] > 100), "the frame is blank");

    let mut banded = RaycastTarget::new(&g.ctx, size).expect("target");
    // One band first: rows outside it stay as the new target was (zeros).
    g.caster
        .render(&g.ctx, &scene, &camera, &settings, &mut banded, 5..9)
        .expect("band");
    let partial = banded.read_image_blocking(&g.ctx).expect("image");
    let row = size[0] as usize * 4;
    assert_eq!(partial[5 * row..9 * row], image[5 * row..9 * row]);
    assert!(
        partial[..5 * row].iter().all(|&b| b == 0),
        "rows above touched"
    );
    assert!(
        partial[9 * row..].iter().all(|&b| b == 0),
        "rows below touched"
    );
    for rows in [0..5, 9..16, 16..17, 17..40, 40..100] {
        g.caster
            .render(&g.ctx, &scene, &camera, &settings, &mut banded, rows)
            .expect("band");
    }
    assert_eq!(banded.read_image_blocking(&g.ctx).expect("image"), image);
    assert_eq!(banded.read_depths_blocking(&g.ctx).expect("depths"), depths);

    // The cost model counts the samples the rays take (the twin's count, without skipping),
    // plus 4 per ray for its setup; bands within a budget.
    let cost = FrameCost::of(&g.volume, &camera, &settings, size);
    let p = params(
        &VolumeGeometry::of(&g.volume),
        &camera,
        &settings,
        size,
        Some(g.features.max),
    );
    let twin = cpu_twin(&TwinScene::new(&volume, Some(&comps)), &p);
    let rays = f64::from(size[0] * size[1]);
    assert_eq!(cost.total() - 4.0 * rays, twin.samples as f64);
    assert!(twin.samples > 1000);
    let budget = cost.total() / 5.0;
    let mut row = 0;
    let mut bands = 0;
    while row < size[1] {
        let end = cost.band_within(row, budget);
        assert!(end > row);
        assert!(cost.rows(row..end) <= budget || end == row + 1);
        row = end;
        bands += 1;
    }
    assert!((5..=12).contains(&bands), "{bands} bands");
}

/// Values beyond a half float (a PET in Bq/ml or counts, up to 10^6) are kept: the texture holds
/// them times a power of two, the window follows, and the brightest pixel of the MIP picks the
/// hottest voxel, not one clipped to 65504 beside it (the bladder and an injection site were one
/// white before). The picture is the CPU twin's.
#[test]
fn values_up_to_a_million_keep_their_order_in_the_mip() {
    let dims = [24usize, 20, 16];
    let n = dims[0] * dims[1] * dims[2];
    let mut values = vec![100.0f32; n];
    let hot = [17usize, 12, 9];
    let warm = [5usize, 6, 4];
    let at = |p: [usize; 3]| p[0] + dims[0] * (p[1] + dims[1] * p[2]);
    // The hottest spot (the bladder), and one just above a half float's largest value (an
    // injection site), each a voxel and its six neighbours.
    for (centre, peak) in [(hot, 1.0e6f32), (warm, 65_700.0)] {
        values[at(centre)] = peak;
        for a in 0..3 {
            for d in [-1i64, 1] {
                let mut q = centre;
                q[a] = (q[a] as i64 + d) as usize;
                values[at(q)] = 0.5 * peak;
            }
        }
    }
    let volume = Volume::from_f32(dims, [4.0, 4.0, 4.0], values);
    let comps = [vec![0.0f32; n], vec![0.0f32; n], vec![0.0f32; n]];
    let Some(g) = gpu(&volume, &comps) else {
        return;
    };
    assert_eq!(
        g.volume.value_scale,
        1.0 / 32.0,
        "10^6 is scaled into 2^14..2^15"
    );
    let twin = TwinScene::new(&volume, None);
    let camera = Camera::for_volume(
        &g.volume.world_from_voxel,
        g.volume.dims,
        ViewPreset::Anterior,
    );
    let settings = RenderSettings {
        window: (0.0, 1.3e6),
        ..Default::default()
    };
    let size = [96, 96];
    let (image, twin_rgba, depths, _, target) =
        both(&g, &twin, &camera, &settings, size, false, false);
    for (a, b) in image.iter().zip(&twin_rgba) {
        assert!(a.abs_diff(*b) <= 1, "GPU and twin differ: {a} vs {b}");
    }
    // The brightest pixel, and where its maximum came from.
    let brightest = (0..size[0] as usize * size[1] as usize)
        .max_by_key(|&p| image[4 * p])
        .expect("pixels");
    let pixel = [
        (brightest % size[0] as usize) as u32,
        (brightest / size[0] as usize) as u32,
    ];
    // A spike of one voxel and its neighbours, sampled 2 mm apart along the ray and between
    // voxel centres across it: well above the warm spot, below the peak.
    assert!(
        image[4 * brightest] >= 96,
        "1e6 of 1.3e6 is bright: {}",
        image[4 * brightest]
    );
    let view = *target.rendered().expect("a frame");
    let pick = view.pick_from(pixel, depths[brightest]).expect("a hit");
    let off = (0..3)
        .map(|a| (pick.voxel[a] as f64 - hot[a] as f64).abs() * 4.0)
        .fold(0.0, f64::max);
    assert!(off <= 8.0, "picked {:?}, hottest {hot:?}", pick.voxel);
    // The warm spot stays below the hot one: 65,700 of 1.3e6 is grey level ~13, not white.
    let warm_pixel = (0..size[0] as usize * size[1] as usize)
        .filter(|&p| {
            let pk = view.pick_from(
                [(p % size[0] as usize) as u32, (p / size[0] as usize) as u32],
                depths[p],
            );
            pk.is_some_and(|k| k.voxel == warm)
        })
        .map(|p| image[4 * p])
        .max()
        .expect("the warm spot is seen");
    assert!(
        (8..=20).contains(&warm_pixel),
        "warm spot grey {warm_pixel}"
    );
}
