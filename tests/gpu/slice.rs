//! The slice kernel (shaders/slice.wgsl) against its CPU twin on lavapipe, and the status bar's
//! texel probe against the values uploaded.

use shapecast::cpu::Components3;
use shapecast::gpu::volume_texture::{FeatureTexture, RenderVolume};
use shapecast::render::probe::TexelProbe;
use shapecast::render::slice::{
    Overlay, SliceError, SlicePlane, SliceRenderer, SliceRequest, cpu_twin, read_image_blocking,
};
use shapecast::volume::Volume;

const DIMS: [usize; 3] = [13, 10, 7];

/// Values from -1000 to about 1500 HU with fractions, different along every axis.
fn values() -> Vec<f32> {
    let mut v = Vec::new();
    for k in 0..DIMS[2] {
        for j in 0..DIMS[1] {
            for i in 0..DIMS[0] {
                v.push(-1000.0 + 97.3 * i as f32 + 41.7 * j as f32 + 113.1 * k as f32);
            }
        }
    }
    v
}

/// V in one corner, A in a band, B in a blob, zeros elsewhere, in HU-like units.
fn features() -> Components3 {
    let n = DIMS.iter().product::<usize>();
    let mut c: Components3 = std::array::from_fn(|_| vec![0.0; n]);
    for k in 0..DIMS[2] {
        for j in 0..DIMS[1] {
            for i in 0..DIMS[0] {
                let idx = i + DIMS[0] * (j + DIMS[1] * k);
                if i < 5 && j < 4 {
                    c[0][idx] = 10.0 * (i + j) as f32 + 3.3;
                }
                if j == 7 {
                    c[1][idx] = 25.0 + k as f32;
                }
                let d2 =
                    (i as f32 - 9.0).powi(2) + (j as f32 - 6.0).powi(2) + (k as f32 - 3.0).powi(2);
                if d2 < 6.0 {
                    c[2][idx] = 60.0 - 8.0 * d2;
                }
            }
        }
    }
    c
}

fn planes() -> Vec<SlicePlane> {
    let mut out = Vec::new();
    for (fixed, across, vertical) in [(2, 0, 1), (1, 0, 2), (0, 1, 2), (2, 1, 0), (0, 2, 1)] {
        for index in [0u32, 3, DIMS[fixed] as u32 - 1] {
            out.push(SlicePlane {
                fixed,
                across,
                vertical,
                index,
            });
        }
    }
    out
}

#[test]
fn gpu_slices_match_the_cpu_twin() {
    let Some(ctx) = shapecast::gpu::context::test_context() else {
        return;
    };
    let values = values();
    let mut volume = Volume::from_f32(DIMS, [0.7, 0.9, 2.5], values.clone());
    volume.source = "test".into();
    let rv = RenderVolume::upload(&ctx, &volume).expect("upload");
    let comps = features();
    let dims32 = DIMS.map(|d| d as u32);
    let ft =
        FeatureTexture::from_components(&ctx, dims32, &comps, "test features").expect("features");
    let renderer = SliceRenderer::new(&ctx).expect("pipeline");
    let overlay = Overlay {
        scale: [1.0 / 40.0, 1.0 / 20.0, 1.0 / 50.0],
        opacity: 0.8,
    };
    let mut worst = 0i32;
    let mut coloured_pixels = 0usize;
    let mut reuse = None;
    for plane in planes() {
        for (window, with_overlay) in [((-1000.0, 1500.0), false), ((-160.0, 240.0), true)] {
            let request = SliceRequest {
                plane,
                window,
                overlay: with_overlay.then_some(overlay),
            };
            let image = renderer
                .render(&ctx, &rv, Some(&ft), &request, reuse.take())
                .expect("render");
            assert_eq!(
                image.size,
                [DIMS[plane.across] as u32, DIMS[plane.vertical] as u32]
            );
            let gpu = read_image_blocking(&ctx, &image).expect("readback");
            let cpu = cpu_twin(&values, DIMS, Some(&comps), &request);
            assert_eq!(gpu.len(), cpu.len());
            for (n, (g, c)) in gpu.iter().zip(&cpu).enumerate() {
                for ch in 0..4 {
                    let d = (i32::from(g[ch]) - i32::from(c[ch])).abs();
                    worst = worst.max(d);
                    assert!(
                        d <= 1,
                        "{plane:?} {request:?} pixel {n} channel {ch}: GPU {g:?} CPU {c:?}"
                    );
                }
                if with_overlay && (c[0] != c[1] || c[1] != c[2]) {
                    coloured_pixels += 1;
                }
            }
            reuse = Some(image);
        }
    }
    eprintln!(
        "slice kernel vs CPU twin: worst channel difference {worst} (of 255); {coloured_pixels} coloured overlay pixels"
    );
    // The overlay must actually colour something (V corner, A band, B blob), or the test is moot.
    assert!(
        coloured_pixels > 100,
        "only {coloured_pixels} coloured pixels"
    );
}

#[test]
fn grey_slices_follow_the_window_and_axes() {
    // Independent of the twin: the pixel of voxel (i, j, k) on each plane is the windowed value.
    let Some(ctx) = shapecast::gpu::context::test_context() else {
        return;
    };
    let values = values();
    let volume = Volume::from_f32(DIMS, [1.0; 3], values.clone());
    let rv = RenderVolume::upload(&ctx, &volume).expect("upload");
    let renderer = SliceRenderer::new(&ctx).expect("pipeline");
    let plane = SlicePlane {
        fixed: 1,
        across: 2,
        vertical: 0,
        index: 4,
    };
    let window = (-1000.0, 2000.0);
    let image = renderer
        .render(
            &ctx,
            &rv,
            None,
            &SliceRequest {
                plane,
                window,
                overlay: None,
            },
            None,
        )
        .expect("render");
    let px = read_image_blocking(&ctx, &image).expect("readback");
    // Pixel (x = k, y = i) on slice j = 4.
    for (i, k) in [(0, 0), (12, 6), (5, 2)] {
        let v = values[i + DIMS[0] * (4 + DIMS[1] * k)];
        let want = ((v + 1000.0) / 3000.0 * 255.0).round();
        let got = f32::from(px[k + DIMS[2] * i][0]);
        assert!(
            (got - want).abs() <= 1.5,
            "voxel ({i}, 4, {k}): {got} vs {want}"
        );
    }
}

#[test]
fn bad_requests_are_errors() {
    let Some(ctx) = shapecast::gpu::context::test_context() else {
        return;
    };
    let volume = Volume::from_f32(DIMS, [1.0; 3], values());
    let rv = RenderVolume::upload(&ctx, &volume).expect("upload");
    let renderer = SliceRenderer::new(&ctx).expect("pipeline");
    let req = |fixed, across, vertical, index| SliceRequest {
        plane: SlicePlane {
            fixed,
            across,
            vertical,
            index,
        },
        window: (0.0, 1.0),
        overlay: None,
    };
    assert!(matches!(
        renderer.render(&ctx, &rv, None, &req(2, 2, 1, 0), None),
        Err(SliceError::Axes(_))
    ));
    assert!(matches!(
        renderer.render(&ctx, &rv, None, &req(2, 0, 1, 7), None),
        Err(SliceError::Index { .. })
    ));
    let other = FeatureTexture::new(&ctx, [2, 2, 2], "other").expect("texture");
    assert!(matches!(
        renderer.render(&ctx, &rv, Some(&other), &req(2, 0, 1, 0), None),
        Err(SliceError::FeatureDims(..))
    ));
}

#[test]
fn texel_probe_reads_the_uploaded_features() {
    let Some(ctx) = shapecast::gpu::context::test_context() else {
        return;
    };
    let comps = features();
    let ft = FeatureTexture::from_components(&ctx, DIMS.map(|d| d as u32), &comps, "probe")
        .expect("features");
    let voxels = [[1u32, 2, 3], [9, 6, 3], [4, 7, 5], [12, 9, 6]];
    let texels = TexelProbe::start(&ctx, &ft, &voxels)
        .wait(&ctx)
        .expect("probe");
    assert_eq!(texels.len(), voxels.len());
    for (v, t) in voxels.iter().zip(&texels) {
        let idx = v[0] as usize + DIMS[0] * (v[1] as usize + DIMS[1] * v[2] as usize);
        // Exactly the shared-exponent texel the upload encoded.
        let texel = shapecast::gpu::volume_texture::feature_texel([
            comps[0][idx],
            comps[1][idx],
            comps[2][idx],
        ]);
        for c in 0..3 {
            let want = comps[c][idx];
            assert_eq!(t[c], texel[c], "voxel {v:?} component {c}");
            assert!(
                (t[c] - want).abs() <= texel.iter().copied().fold(0.0, f32::max) / 512.0 + 1e-6,
                "voxel {v:?} component {c}: {} vs {want}",
                t[c]
            );
        }
        assert_eq!(t[3], 0.0);
    }
    // The blob centre and the vessel corner are non-zero: the probe did not read zeros.
    assert!(texels[1][2] > 50.0 && texels[0][0] > 30.0, "{texels:?}");
}
