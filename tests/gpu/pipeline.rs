//! The GPU feature pipeline against the CPU reference pipeline, on lavapipe: every method on
//! phantoms with anisotropic, thick-slice spacing (so the Hessian refines thick axes), dims
//! that are not multiples of the workgroup, brick processing (several bricks, tiled in y and z)
//! equal to one piece, and a 512-wide volume within WebGPU's default limits.

use shapecast::compute::hessian;
use shapecast::compute::pipeline::{FeatureJob, FeatureResult, JobOptions};
use shapecast::cpu::pipeline::{Method, Request, compute};
use shapecast::cpu::{Grid, TransferFunction};
use shapecast::gpu::GpuContext;
use shapecast::gpu::context::test_context;
use shapecast::phantom::{Phantom, Shape};
use shapecast::volume::Volume;

/// A nodule next to a vessel and a dark tube (airway-like), in soft tissue with mild noise.
pub(crate) fn scene(spacing_mm: [f64; 3], noise_hu: f64) -> Volume {
    let p = Phantom::new("scene", [0.0, 0.0, 0.0], [17.0, 15.0, 40.0], 40.0)
        .with(
            Shape::Sphere {
                centre_mm: [6.0, 7.0, 22.0],
                radius_mm: 3.0,
            },
            140.0,
        )
        .with(
            Shape::Cylinder {
                a_mm: [0.0, 7.5, 4.0],
                b_mm: [17.0, 7.5, 36.0],
                radius_mm: 1.8,
            },
            150.0,
        )
        .with(
            Shape::Cylinder {
                a_mm: [13.0, 0.0, 26.0],
                b_mm: [13.0, 15.0, 34.0],
                radius_mm: 1.5,
            },
            -60.0,
        );
    if noise_hu > 0.0 {
        p.render_noisy(spacing_mm, noise_hu, 7)
    } else {
        p.render(spacing_mm)
    }
}

fn run_gpu(
    ctx: &GpuContext,
    volume: &Volume,
    req: &Request,
    max_slab_voxels: Option<u64>,
) -> FeatureResult {
    run_gpu_with(
        ctx,
        volume,
        req,
        JobOptions {
            max_slab_voxels,
            ..JobOptions::default()
        },
    )
}

pub(crate) fn run_gpu_with(
    ctx: &GpuContext,
    volume: &Volume,
    req: &Request,
    options: JobOptions,
) -> FeatureResult {
    let options = JobOptions {
        export: true,
        ..options
    };
    let mut job = FeatureJob::with_options(ctx, volume, req, options).expect("job");
    job.run_blocking(ctx).expect("run");
    job.finish_result().expect("result")
}

/// Largest |gpu - cpu| over all components, relative to the largest |cpu|, and the fraction of
/// values within `tight` of it.
fn compare(gpu: &[Vec<f32>; 3], cpu: &[Vec<f32>; 3], tight: f64) -> (f64, f64) {
    let scale = cpu
        .iter()
        .flatten()
        .fold(0.0f64, |m, v| m.max(f64::from(v.abs())))
        .max(1e-12);
    let mut worst = 0.0f64;
    let (mut within, mut n) = (0usize, 0usize);
    for c in 0..3 {
        assert_eq!(gpu[c].len(), cpu[c].len());
        for (g, r) in gpu[c].iter().zip(&cpu[c]) {
            let e = f64::from((g - r).abs()) / scale;
            worst = worst.max(e);
            within += usize::from(e <= tight);
            n += 1;
        }
    }
    (worst, within as f64 / n as f64)
}

fn check_method(
    ctx: &GpuContext,
    volume: &Volume,
    req: &Request,
    tol: f64,
    frac_tight: Option<(f64, f64)>,
) {
    let grid = Grid::of(volume);
    let cpu = compute(&grid, &volume.to_f32(), req).expect("cpu");
    // A part of the compute grid per brick: at least three bricks once halos are counted (the
    // RST's halo, the rays' reach, is the widest).
    let c = req.resolve(&grid).expect("request").compute;
    let part = if req.method == Method::Rst {
        0.85
    } else {
        0.67
    };
    let cap = (c.dims[0] * c.dims[1]) as u64 * (part * c.dims[2] as f64) as u64;
    let gpu = run_gpu(ctx, volume, req, Some(cap));
    assert!(
        gpu.slabs >= 2,
        "{:?}: only {} bricks",
        req.method,
        gpu.slabs
    );
    let comps = gpu.components.as_ref().expect("exported");
    let (worst, _) = compare(comps, &cpu.components, tol);
    let cmax = cpu
        .components
        .iter()
        .flatten()
        .fold(0.0f32, |m, v| m.max(v.abs()));
    eprintln!(
        "{:?} {:?}: {} slabs, max |gpu-cpu| = {worst:.2e} of max {cmax:.3}",
        req.method, volume.dims, gpu.slabs
    );
    assert!(
        cmax > 0.05,
        "{:?}: features are all near zero ({cmax})",
        req.method
    );
    assert!(
        worst <= tol,
        "{:?}: max error {worst:.3e} > {tol:.0e}",
        req.method
    );
    if let Some((tight, frac)) = frac_tight {
        let (_, f) = compare(comps, &cpu.components, tight);
        eprintln!("  {:.3}% within {tight:.0e}", 100.0 * f);
        assert!(
            f >= frac,
            "{:?}: only {f:.4} within {tight:.0e}",
            req.method
        );
    }
    assert_eq!(gpu.tf, cpu.tf, "transfer functions differ");
}

#[test]
fn hessian_maps_match_the_cpu_on_thick_slices_in_slabs() {
    let Some(ctx) = test_context() else { return };
    // z thicker than 1.25 mm: the pipeline resamples per slab and maps back.
    let volume = scene([0.8, 0.9, 2.0], 0.0);
    for method in [Method::Hessian, Method::Li, Method::Frangi] {
        let mut req = Request::new(method);
        req.sigmas_mm = Some(vec![1.0, 2.0]);
        check_method(&ctx, &volume, &req, 1e-3, None);
    }
    let mut req = Request::new(Method::Hessian);
    req.sigmas_mm = Some(vec![1.0, 2.0]);
    req.eigen = true;
    check_method(&ctx, &volume, &req, 1e-3, None);
}

#[test]
fn structure_tensor_matches_the_cpu() {
    let Some(ctx) = test_context() else { return };
    let volume = scene([0.7, 0.7, 1.0], 0.0);
    let mut req = Request::new(Method::Gst);
    req.sigmas_mm = Some(vec![1.0, 1.5]);
    check_method(&ctx, &volume, &req, 1e-3, None);
}

/// A small RST request (26 rays, R 5 mm, dr 0.5 mm) with the automatic transfer function.
fn small_rst() -> Request {
    let mut req = Request::new(Method::Rst);
    req.rays = Some(26);
    req.radius_mm = Some(5.0);
    req.step_mm = Some(0.5);
    req
}

#[test]
fn rst_matches_the_cpu_with_the_automatic_transfer_function() {
    let Some(ctx) = test_context() else { return };
    // Noise so that the automatic transfer function has windows to measure (0..100 HU band).
    let volume = scene([0.9, 0.9, 1.5], 5.0);
    check_method(&ctx, &volume, &small_rst(), 1e-2, Some((1e-3, 0.995)));
}

#[test]
fn rst_on_refined_slices_matches_the_cpu_in_bricks_and_in_paced_rows() {
    let Some(ctx) = test_context() else { return };
    // 2.5 mm slices at dr 0.5 mm, --refine-slices: z refined by 2 for the rays (docs/science.md,
    // "Thick slices"), features at the input voxels; the automatic transfer function measured on
    // the refined grid as the twin measures it.
    let volume = scene([0.8, 0.8, 2.5], 5.0);
    let mut req = small_rst();
    assert_eq!(
        req.resolve(&Grid::of(&volume)).expect("request").factors,
        [1; 3]
    );
    req.refine_slices = true;
    let resolved = req.resolve(&Grid::of(&volume)).expect("request");
    assert_eq!(resolved.factors, [1, 1, 2]);
    check_method(&ctx, &volume, &req, 1e-2, Some((1e-3, 0.995)));
    // One row per step: the same features as whole slices.
    let (whole, _) = run_counting_rst_steps(&ctx, &volume, &req, JobOptions::default());
    let (rows, row_steps) = run_counting_rst_steps(
        &ctx,
        &volume,
        &req,
        JobOptions {
            step_seconds: Some(1e-12),
            ..JobOptions::default()
        },
    );
    let core_rows: usize = whole
        .bricks
        .iter()
        .map(|b| b.core_c[1].len() * b.out[2].len())
        .sum();
    assert_eq!(row_steps, core_rows, "one row of an input slice per step");
    let (worst, _) = compare(
        rows.components.as_ref().expect("exported"),
        whole.components.as_ref().expect("exported"),
        0.0,
    );
    assert_eq!(
        worst, 0.0,
        "row steps differ from whole slices by {worst:.2e}"
    );
}

#[test]
fn rst_paper_rule_with_an_explicit_transfer_function() {
    let Some(ctx) = test_context() else { return };
    let volume = scene([0.7, 0.8, 0.9], 0.0);
    let mut req = Request::new(Method::Rst);
    req.rays = Some(42);
    req.radius_mm = Some(4.0);
    req.rule = shapecast::cpu::OpacityRule::Paper;
    req.tf = Some(TransferFunction::PAPER_CT);
    check_method(&ctx, &volume, &req, 1e-2, Some((1e-3, 0.995)));
}

#[test]
fn bricks_give_the_same_result_as_one_piece_and_fill_the_texture() {
    let Some(ctx) = test_context() else { return };
    // 512 x 512 x 7 at 0.7 x 0.7 x 2 mm: refined to 13 slices for sigma 1.5 mm.
    let volume = wide_scene();
    let mut req = Request::new(Method::Li);
    req.sigmas_mm = Some(vec![1.5]);
    let one = run_gpu(&ctx, &volume, &req, None);
    let c = req.resolve(&Grid::of(&volume)).expect("request").compute;
    // A quarter of the compute grid per brick: tiling y as well costs less halo than z alone.
    let many = run_gpu(&ctx, &volume, &req, Some(c.len() as u64 / 4));
    assert_eq!(one.slabs, 1);
    assert!(many.slabs >= 3, "{} bricks", many.slabs);
    assert!(
        many.bricks.iter().any(|b| b.out[1].start > 0),
        "no brick tiles y: {:?}",
        many.bricks
    );
    let (worst, _) = compare(
        many.components.as_ref().expect("exported"),
        one.components.as_ref().expect("exported"),
        0.0,
    );
    eprintln!(
        "{} slabs vs one piece: max rel. difference {worst:.2e}",
        many.slabs
    );
    assert!(worst < 1e-5, "slabs differ from one piece by {worst:.2e}");
    // The texture holds what was exported, encoded as the CPU twin encodes it (shared-exponent
    // texels, bit for bit), and the maxima are the components'.
    let comps = many.components.as_ref().expect("exported");
    let texels = shapecast::gpu::volume_texture::read_texture_blocking(&ctx, &many.texture)
        .expect("texture readback");
    // The gain reference (99.9th percentile of positive values) is the CPU twin's, within one
    // histogram bin (2.2%), and below the maximum.
    let (_, p999) = shapecast::gpu::volume_texture::feature_statistics(comps);
    for (c, &cpu) in p999.iter().enumerate() {
        let gpu = many.texture.p999[c];
        eprintln!(
            "component {c}: p99.9 {gpu} (CPU {cpu}), max {}",
            many.texture.max[c]
        );
        assert!(
            (gpu - cpu).abs() <= 0.023 * cpu.max(1e-6),
            "p99.9 {c}: {gpu} vs {cpu}"
        );
        assert!(gpu <= many.texture.max[c] + 1e-6);
    }
    assert!(many.texture.p999[2] > 0.0, "blobness has a reference");
    for c in 0..3 {
        let max = comps[c].iter().copied().fold(0.0f32, f32::max);
        assert!(
            (many.texture.max[c] - max).abs() <= 1e-3 * max.max(1.0),
            "max {c}"
        );
        for (i, v) in comps[c].iter().enumerate() {
            let t = texels[4 * i + c];
            let want = shapecast::gpu::volume_texture::feature_texel([
                comps[0][i],
                comps[1][i],
                comps[2][i],
            ])[c];
            assert_eq!(t, want, "texel {i} comp {c}: {t} vs {want} (exported {v})");
        }
    }
}

#[test]
fn a_device_too_small_for_one_slice_is_refused_with_a_message() {
    let Some(ctx) = test_context() else { return };
    let volume = scene([0.8, 0.8, 1.0], 0.0);
    let req = Request::new(Method::Hessian);
    let options = JobOptions {
        max_slab_voxels: Some(10),
        ..JobOptions::default()
    };
    let err = FeatureJob::with_options(&ctx, &volume, &req, options)
        .err()
        .expect("refused");
    let msg = err.to_string();
    assert!(
        msg.contains("bricks") && msg.contains("voxels per buffer"),
        "{msg}"
    );
}

/// A real-size plane: 512 x 512 voxels (a chest CT's field of view) in 0.7 mm, a few slices
/// of 2 mm, with WebGPU's default limits forced (128 MiB per binding, 256 MiB per buffer) and a
/// small memory budget, so the volume runs in bricks tiled in y and z.
fn wide_scene() -> Volume {
    let p = Phantom::new("wide", [0.0, 0.0, 0.0], [358.0, 358.0, 14.0], 40.0)
        .with(
            Shape::Sphere {
                centre_mm: [180.0, 120.0, 7.0],
                radius_mm: 4.0,
            },
            140.0,
        )
        .with(
            Shape::Cylinder {
                a_mm: [0.0, 250.0, 2.0],
                b_mm: [358.0, 250.0, 12.0],
                radius_mm: 2.0,
            },
            150.0,
        );
    p.render_noisy([0.7, 0.7, 2.0], 5.0, 3)
}

#[test]
fn a_512_wide_volume_runs_in_bricks_within_webgpu_default_limits() {
    let Some(ctx) = test_context() else { return };
    let volume = wide_scene();
    assert_eq!(&volume.dims[..2], &[512, 512]);
    let grid = Grid::of(&volume);
    let values = volume.to_f32();
    let webgpu = JobOptions {
        limits: Some(wgpu::Limits::default()),
        memory_budget_bytes: 64 << 20,
        ..JobOptions::default()
    };
    let mut hessian = Request::new(Method::Li);
    hessian.sigmas_mm = Some(vec![1.5, 3.0]);
    let mut rst = Request::new(Method::Rst);
    rst.rays = Some(26);
    rst.radius_mm = Some(4.0);
    rst.step_mm = Some(0.5);
    for (req, tol) in [(hessian, 1e-3), (rst, 1e-2)] {
        let gpu = run_gpu_with(&ctx, &volume, &req, webgpu.clone());
        let cpu = compute(&grid, &values, &req).expect("cpu");
        let (worst, within) = compare(
            gpu.components.as_ref().expect("exported"),
            &cpu.components,
            1e-3,
        );
        eprintln!(
            "{:?} 512-wide: {} bricks, overhead {:.2}, max |gpu-cpu| {worst:.2e}, {:.3}% within 1e-3",
            req.method,
            gpu.slabs,
            gpu.overhead,
            100.0 * within
        );
        assert!(gpu.slabs >= 2, "{:?}: {} bricks", req.method, gpu.slabs);
        assert!(worst <= tol, "{:?}: {worst:.2e}", req.method);
        assert!(within >= 0.995, "{:?}: {within}", req.method);
        assert!(
            gpu.overhead >= 1.0 && gpu.overhead < 3.0,
            "{}",
            gpu.overhead
        );
    }
}

/// Runs `req` step by step as the viewer does and counts the steps that cast rays.
fn run_counting_rst_steps(
    ctx: &GpuContext,
    volume: &Volume,
    req: &Request,
    options: JobOptions,
) -> (FeatureResult, usize) {
    run_counting_steps(ctx, volume, req, options, "RST, slices")
}

/// Runs `req` step by step as the viewer does and counts the steps whose stage contains
/// `stage_part`.
fn run_counting_steps(
    ctx: &GpuContext,
    volume: &Volume,
    req: &Request,
    options: JobOptions,
    stage_part: &str,
) -> (FeatureResult, usize) {
    use shapecast::compute::pipeline::JobState;
    let options = JobOptions {
        export: true,
        ..options
    };
    let mut job = FeatureJob::with_options(ctx, volume, req, options).expect("job");
    let mut rst_steps = 0;
    let mut last_fraction = 0.0f32;
    loop {
        let before = job.submissions();
        match job.step(ctx).expect("step") {
            JobState::Done => break,
            JobState::Running { fraction, stage } => {
                assert!(
                    fraction >= last_fraction,
                    "progress went back: {fraction} after {last_fraction} ({stage})"
                );
                last_fraction = fraction;
                // Counted only when the step did work (it may find the GPU still busy).
                if stage.contains(stage_part) && job.submissions() > before {
                    rst_steps += 1;
                }
            }
        }
        ctx.device
            .poll(wgpu::PollType::wait_indefinitely())
            .expect("poll");
    }
    (job.finish_result().expect("result"), rst_steps)
}

#[test]
fn rst_steps_paced_to_the_device_give_the_same_features() {
    let Some(ctx) = test_context() else { return };
    let volume = scene([0.9, 0.9, 1.5], 5.0);
    let mut req = Request::new(Method::Rst);
    req.rays = Some(26);
    req.radius_mm = Some(4.0);
    req.step_mm = Some(0.5);
    // Whole slices per step (the CLI's way).
    let (fixed, fixed_steps) = run_counting_rst_steps(&ctx, &volume, &req, JobOptions::default());
    assert_eq!(fixed.slabs, 1);
    let core = &fixed.bricks[0].core_c;
    let rows = core[1].len() * core[2].len();
    // Paced to nothing: every step is one row of one slice.
    let (rows_only, row_steps) = run_counting_rst_steps(
        &ctx,
        &volume,
        &req,
        JobOptions {
            step_seconds: Some(1e-12),
            ..JobOptions::default()
        },
    );
    // Paced to a long step: from one row, growing at most twofold per step up to whole slices.
    let (growing, growing_steps) = run_counting_rst_steps(
        &ctx,
        &volume,
        &req,
        JobOptions {
            step_seconds: Some(10.0),
            ..JobOptions::default()
        },
    );
    eprintln!(
        "RST steps: fixed {fixed_steps}, one row each {row_steps} ({rows} core rows), growing {growing_steps}"
    );
    assert_eq!(row_steps, rows, "one row per step");
    assert!(fixed_steps < growing_steps && growing_steps < rows / 2);
    for (what, paced) in [("one row", &rows_only), ("growing", &growing)] {
        let (worst, _) = compare(
            paced.components.as_ref().expect("exported"),
            fixed.components.as_ref().expect("exported"),
            0.0,
        );
        assert_eq!(
            worst, 0.0,
            "{what} steps differ from whole slices by {worst:.2e}"
        );
    }
}

#[test]
fn hessian_passes_paced_to_the_device_give_the_same_features() {
    let Some(ctx) = test_context() else { return };
    // z refined by 2 (1.5 mm slices, sigma 1 mm), two bricks: every pass of every scale is cut.
    let volume = scene([0.9, 0.9, 1.5], 5.0);
    let mut req = Request::new(Method::Li);
    req.sigmas_mm = Some(vec![1.0, 2.5]);
    let c = req.resolve(&Grid::of(&volume)).expect("request").compute;
    let cap = (c.dims[0] * c.dims[1]) as u64 * (0.67 * c.dims[2] as f64) as u64;
    let capped = |step_seconds| JobOptions {
        max_slab_voxels: Some(cap),
        step_seconds,
        ..JobOptions::default()
    };
    // Whole passes (the CLI's way).
    let (whole, whole_steps) = run_counting_steps(&ctx, &volume, &req, capped(None), "Hessian");
    assert!(whole.slabs >= 2, "{} bricks", whole.slabs);
    // One line per step: each convolution pass cut into its lines (the slab's rows for the z
    // pass, the core's slices for the others, which compute only what the core needs), the
    // eigenvalue pass into core slices.
    let (lines, line_steps) =
        run_counting_steps(&ctx, &volume, &req, capped(Some(1e-12)), "Hessian");
    // From one line, growing at most twofold per step.
    let (growing, growing_steps) =
        run_counting_steps(&ctx, &volume, &req, capped(Some(10.0)), "Hessian");
    let scales = 2;
    let expected: usize = whole
        .bricks
        .iter()
        .map(|b| {
            let (ny, core_nz) = (b.slab_c[1].len(), b.core_c[2].len());
            scales * (ny + hessian::PASSES * core_nz)
        })
        .sum();
    eprintln!(
        "Hessian steps: whole passes {whole_steps}, one line each {line_steps} (expected {expected}), growing {growing_steps}"
    );
    assert_eq!(whole_steps, whole.slabs * scales * (hessian::PASSES + 1));
    assert_eq!(line_steps, expected, "one line per step");
    assert!(whole_steps < growing_steps && growing_steps < line_steps / 2);
    let read = |r: &FeatureResult| {
        shapecast::gpu::volume_texture::read_texture_blocking(&ctx, &r.texture)
            .expect("texture readback")
    };
    let whole_texels = read(&whole);
    for (what, paced) in [("one line", &lines), ("growing", &growing)] {
        let (worst, _) = compare(
            paced.components.as_ref().expect("exported"),
            whole.components.as_ref().expect("exported"),
            0.0,
        );
        assert_eq!(
            worst, 0.0,
            "{what} steps differ from whole passes by {worst:.2e}"
        );
        // Stored a slice per step too: the same texels, maxima and 99.9th percentiles.
        assert!(read(paced) == whole_texels, "{what}: texels differ");
        assert_eq!(paced.texture.max, whole.texture.max, "{what}: maxima");
        assert_eq!(paced.texture.p999, whole.texture.p999, "{what}: p99.9");
    }
}
