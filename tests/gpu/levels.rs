//! Max-pooled feature levels (the GPU budget's answer to a volume whose features do not fit):
//! the feature job writes a level that is the max-pool of its full-resolution features (the CPU
//! twin `pool_texels`), in bricks and in paced steps alike; the ray caster and the slice kernel
//! read a pooled texture as their twins do; and a pooled MIP never loses a maximum: every
//! pixel's feature is at least the full-resolution MIP's.

use glam::{DMat3, DQuat};
use shapecast::compute::pipeline::{FeatureResult, JobOptions};
use shapecast::cpu::pipeline::{Method, Request};
use shapecast::cpu::{Components3, Grid};
use shapecast::gpu::GpuContext;
use shapecast::gpu::context::test_context;
use shapecast::gpu::volume_texture::{
    FeatureTexture, RenderVolume, decode_rgb9e5, level_dims, pool_texels, read_texture_blocking,
};
use shapecast::render::camera::{Camera, ViewPreset};
use shapecast::render::raycast::{
    ChannelDisplay, RaycastTarget, Raycaster, RenderSettings, Scene, TwinScene, VolumeGeometry,
    cpu_twin, params,
};
use shapecast::render::slice::{Overlay, SlicePlane, SliceRenderer, SliceRequest, cpu_twin_level};
use shapecast::volume::Volume;

/// The pipeline tests' nodule beside a vessel and a dark tube, in noisy soft tissue (odd dims,
/// so that blocks are cut at the faces).
fn scene() -> Volume {
    super::pipeline::scene([0.9, 0.8, 1.1], 6.0)
}

/// Li at two scales, exported.
fn run(ctx: &GpuContext, volume: &Volume, options: JobOptions) -> FeatureResult {
    let mut req = Request::new(Method::Li);
    req.sigmas_mm = Some(vec![1.2, 2.0]);
    super::pipeline::run_gpu_with(ctx, volume, &req, options)
}

/// Texels of a feature texture, decoded.
fn texels(ctx: &GpuContext, t: &FeatureTexture) -> Vec<[f32; 3]> {
    read_texture_blocking(ctx, t)
        .expect("readback")
        .chunks_exact(4)
        .map(|c| [c[0], c[1], c[2]])
        .collect()
}

/// Each channel of `got` within one step of the texel's largest channel of `want` (the pooled
/// kernel re-encodes a block's maximum as its chunks arrive; the twin encodes it once).
fn assert_pooled(got: &[[f32; 3]], want: &[u32], what: &str) {
    assert_eq!(got.len(), want.len(), "{what}: texel count");
    let mut exact = 0;
    for (n, (g, &w)) in got.iter().zip(want).enumerate() {
        let w = decode_rgb9e5(w);
        let m = w[0].max(w[1]).max(w[2]);
        let step = (m / 256.0).max(2f32.powi(-24));
        for c in 0..3 {
            assert!(
                (g[c] - w[c]).abs() <= step,
                "{what}: texel {n} channel {c}: {} vs the twin's {}",
                g[c],
                w[c]
            );
        }
        exact += usize::from(*g == w);
    }
    eprintln!("{what}: {exact} of {} texels bit for bit", got.len());
    assert!(exact * 10 >= got.len() * 9, "{what}: {exact} exact");
}

#[test]
fn the_job_writes_the_max_pool_of_its_features_in_bricks_and_steps() {
    let Some(ctx) = test_context() else { return };
    let volume = scene();
    let dims = volume.dims.map(|d| d as u32);
    let mut req = Request::new(Method::Li);
    req.sigmas_mm = Some(vec![1.2, 2.0]);
    let c = req.resolve(&Grid::of(&volume)).expect("request").compute;
    // Bricks of about 60% of the volume (their edges cut blocks), and stored a slice per step.
    let cap = (c.dims[0] * c.dims[1]) as u64 * (c.dims[2] as u64 * 6 / 10);
    for (level, options) in [
        (1, JobOptions::default()),
        (
            1,
            JobOptions {
                max_slab_voxels: Some(cap),
                step_seconds: Some(1e-12),
                ..JobOptions::default()
            },
        ),
        (
            2,
            JobOptions {
                max_slab_voxels: Some(cap),
                ..JobOptions::default()
            },
        ),
    ] {
        // The same job at full resolution: the same bricks, so the same features.
        let full = run(&ctx, &volume, options.clone());
        let comps: &Components3 = full.components.as_ref().expect("exported");
        let pooled = run(
            &ctx,
            &volume,
            JobOptions {
                feature_level: level,
                ..options
            },
        );
        let what = format!("level {level}, {} brick(s)", pooled.slabs);
        assert!(pooled.slabs > 1 || full.slabs == 1);
        assert_eq!(pooled.texture.level, level);
        assert_eq!(pooled.texture.dims, dims);
        assert_eq!(pooled.texture.texture_dims, level_dims(dims, level));
        // The features are computed at full resolution either way.
        assert!(
            pooled.components.as_ref() == Some(comps),
            "{what}: exported features differ"
        );
        // The default gains do not depend on the level.
        assert_eq!(pooled.texture.max, full.texture.max, "{what}: maxima");
        assert_eq!(pooled.texture.p999, full.texture.p999, "{what}: p99.9");
        assert_pooled(
            &texels(&ctx, &pooled.texture),
            &pool_texels(comps, dims, level),
            &what,
        );
    }
}

/// The brightest value of colour channel `k` per pixel.
fn channel(image: &[u8], k: usize) -> Vec<u8> {
    image.chunks_exact(4).map(|p| p[k]).collect()
}

#[test]
fn a_pooled_mip_matches_its_twin_and_keeps_every_maximum() {
    let Some(ctx) = test_context() else { return };
    let mut volume = scene();
    volume.direction = DMat3::from_quat(DQuat::from_euler(glam::EulerRot::YXZ, 0.3, -0.2, 0.1));
    let full = run(&ctx, &volume, JobOptions::default());
    let comps = full.components.expect("exported");
    let dims = volume.dims.map(|d| d as u32);
    let caster = Raycaster::new(&ctx).expect("shader");
    let rv = RenderVolume::upload(&ctx, &volume).expect("upload");
    let dense = FeatureTexture::from_components(&ctx, dims, &comps, "dense").expect("features");
    let base = Camera::for_volume(&volume.world_from_voxel(), dims, ViewPreset::Anterior);
    let mut oblique = base;
    oblique.orbit(35.0, -20.0);
    // Features only, one channel at a time: a pixel's colour then grows with its maximum.
    let only = |c: usize| {
        let mut s = RenderSettings {
            show_intensity: false,
            ..RenderSettings::default()
        };
        for k in 0..3 {
            s.channels[k] = ChannelDisplay {
                on: k == c,
                gain: 1.0,
            };
        }
        s
    };
    let size = [44, 40];
    for level in [1, 2] {
        let pooled = FeatureTexture::from_components_level(&ctx, dims, level, &comps, "pooled")
            .expect("pooled");
        let twin = TwinScene::pooled(&volume, Some(&comps), level);
        // The pooled brick table is its twin's.
        let fb = caster.feature_bricks(&ctx, &pooled);
        let gfb = fb.read_blocking(&ctx).expect("bricks");
        let tfb = twin.feature_bricks.as_ref().expect("twin bricks");
        for (n, (g, t)) in gfb.iter().zip(tfb).enumerate() {
            assert_eq!(g[..3], t[..3], "level {level}: feature brick {n}");
        }
        let bricks = caster.intensity_bricks(&ctx, &rv);
        for (name, camera) in [("anterior", base), ("oblique", oblique)] {
            for (c, k) in [(0usize, 0usize), (2, 1)] {
                // Vesselness shows in red (channel 0), blobness in green (yellow's, channel 1).
                let settings = only(c);
                let render = |features: &FeatureTexture, skip: bool| {
                    let mut target = RaycastTarget::new(&ctx, size).expect("target");
                    let feature_bricks = skip.then(|| caster.feature_bricks(&ctx, features));
                    let scene = Scene {
                        volume: &rv,
                        features: Some(features),
                        bricks: skip.then_some(&bricks),
                        feature_bricks: feature_bricks.as_ref(),
                    };
                    caster
                        .render(&ctx, &scene, &camera, &settings, &mut target, ..)
                        .expect("render");
                    (
                        target.read_image_blocking(&ctx).expect("image"),
                        target.read_depths_blocking(&ctx).expect("depths"),
                    )
                };
                let what = format!("level {level}, {name}, feature {c}");
                let (gi, gd) = render(&pooled, false);
                let (si, sd) = render(&pooled, true);
                assert_eq!(gi, si, "{what}: skipping changed the picture");
                assert_eq!(gd, sd, "{what}: skipping changed the depths");
                let p = params(
                    &VolumeGeometry::of(&rv),
                    &camera,
                    &settings,
                    size,
                    Some(pooled.reference()),
                );
                let t = cpu_twin(&twin, &p);
                let ts = cpu_twin(&twin, &p.with_skipping());
                assert_eq!(t.rgba, ts.rgba, "{what}: twin skipping");
                let worst = gi
                    .iter()
                    .zip(&t.rgba)
                    .map(|(a, b)| a.abs_diff(*b))
                    .max()
                    .unwrap_or(0);
                assert!(worst <= 1, "{what}: GPU and twin differ by {worst} levels");
                // No maximum lost: every pixel at least as bright as at full resolution.
                let (di, _) = render(&dense, false);
                let (pc, dc) = (channel(&gi, k), channel(&di, k));
                let dimmer = pc
                    .iter()
                    .zip(&dc)
                    .filter(|(p, d)| u16::from(**p) + 1 < u16::from(**d))
                    .count();
                let lit = dc.iter().filter(|&&d| d > 20).count();
                let brightest = (dc.iter().max(), pc.iter().max());
                eprintln!(
                    "{what}: {lit} lit pixels, {dimmer} dimmer than full resolution, brightest {brightest:?}"
                );
                assert!(lit > 30, "{what}: nothing to compare ({lit} lit)");
                assert_eq!(dimmer, 0, "{what}: pixels dimmer than full resolution");
            }
        }
    }
}

#[test]
fn a_slice_of_pooled_features_matches_its_twin() {
    let Some(ctx) = test_context() else { return };
    let volume = scene();
    let full = run(&ctx, &volume, JobOptions::default());
    let comps = full.components.expect("exported");
    let dims = volume.dims.map(|d| d as u32);
    let rv = RenderVolume::upload(&ctx, &volume).expect("upload");
    let renderer = SliceRenderer::new(&ctx).expect("shader");
    let values = volume.to_f32();
    let reference = full.texture.reference();
    let overlay = Overlay {
        scale: reference.map(|r| if r > 0.0 { 1.0 / r } else { 0.0 }),
        opacity: 0.8,
    };
    for level in [1, 2] {
        let pooled = FeatureTexture::from_components_level(&ctx, dims, level, &comps, "pooled")
            .expect("pooled");
        for (fixed, across, vertical) in [(2, 0, 1), (1, 0, 2), (0, 1, 2)] {
            let request = SliceRequest {
                plane: SlicePlane {
                    fixed,
                    across,
                    vertical,
                    index: dims[fixed] / 2 + 1,
                },
                window: (-100.0, 200.0),
                overlay: Some(overlay),
            };
            let image = renderer
                .render(&ctx, &rv, Some(&pooled), &request, None)
                .expect("slice");
            let gpu = shapecast::render::slice::read_image_blocking(&ctx, &image).expect("read");
            let twin = cpu_twin_level(&values, volume.dims, Some(&comps), level, &request);
            let worst = gpu
                .iter()
                .zip(&twin)
                .flat_map(|(a, b)| (0..4).map(move |k| a[k].abs_diff(b[k])))
                .max()
                .unwrap_or(0);
            assert!(
                worst <= 1,
                "level {level}, plane {fixed}: GPU and twin differ by {worst}"
            );
        }
    }
}
