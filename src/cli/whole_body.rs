//! `shapecast bench --whole-body [INPUT]`: a whole-body-length CT built from a real series and
//! timed as the viewer meets it (issue "full-size scans", deliver 6). INPUT's slices (by default
//! the 512x512 chest series of ../shared/data) are repeated back and forth along z to
//! `--tile-z` slices (default 2000) at 0.8 mm, a whole-body PET/CT's slice spacing, and then:
//!
//! 1. load (read + tile) time and peak memory;
//! 2. upload of the intensity texture and its brick table;
//! 3. the first MIP as the viewer draws it: a coarse frame planned with [`FramePacer`]'s first
//!    guess, then the full-resolution frame in bands of rows, each timed on the GPU (the largest
//!    band is what a frame of the viewer waits on);
//! 4. one method's features with the feature job (bricks, as the app runs it), time and halo
//!    overhead;
//! 5. the MIP with the features, again in bands, written to `--png` if given.
//!
//! A benchmark, not a test: numbers go to docs/performance.md.

use std::path::{Path, PathBuf};

use anyhow::Context;
use web_time::Instant;

use crate::compute::pipeline::{FeatureJob, JobOptions, JobState};
use crate::cpu::Preset;
use crate::cpu::pipeline::{Method, Request};
use crate::gpu::GpuContext;
use crate::gpu::volume_texture::{FeatureTexture, RenderVolume};
use crate::render::camera::{Camera, ViewPreset};
use crate::render::raycast::{
    BrickSource, Bricks, FrameCost, FramePacer, FramePlan, RaycastTarget, Raycaster,
    RenderSettings, Scene,
};
use crate::volume::Volume;

/// Where the default series is, from the project's root.
pub const DEFAULT_SERIES: &str = "../shared/data/series/ct-chest-lung-kernel";
/// The slice spacing of the tiled volume, mm.
pub const WHOLE_BODY_SLICE_MM: f64 = 0.8;

pub struct Options<'a> {
    pub input: Option<&'a Path>,
    pub slices: usize,
    pub method: Method,
    pub preset: Preset,
    pub webgpu_limits: bool,
    pub budget_mib: Option<u64>,
    pub gpu_budget_mib: Option<u64>,
    pub size: [u32; 2],
    pub png: Option<&'a Path>,
}

fn peak_rss_mb() -> f64 {
    super::bench::peak_rss_mb().unwrap_or(f64::NAN)
}

/// What drawing one MIP as the viewer does cost: the coarse frame, the bands.
struct MipTiming {
    coarse_ms: Option<f64>,
    coarse_scale: f32,
    bands: usize,
    largest_band_ms: f64,
    full_ms: f64,
    rate: f64,
}

/// Draws a frame as the viewer does (coarse first when it is over the budget, then bands of
/// rows), waiting on the GPU after each dispatch to time it.
fn draw_like_the_viewer(
    ctx: &GpuContext,
    caster: &Raycaster,
    scene: &Scene<'_>,
    camera: &Camera,
    settings: &RenderSettings,
    size: [u32; 2],
    pacer: &mut FramePacer,
) -> anyhow::Result<(MipTiming, RaycastTarget)> {
    let wait = |ctx: &GpuContext| {
        ctx.device
            .poll(wgpu::PollType::wait_indefinitely())
            .context("waiting for the GPU")
    };
    pacer.set_scene(scene.features.is_some());
    let cost = FrameCost::of(scene.volume, camera, settings, size);
    let full = cost.total();
    let mut timing = MipTiming {
        coarse_ms: None,
        coarse_scale: 1.0,
        bands: 0,
        largest_band_ms: 0.0,
        full_ms: 0.0,
        rate: 0.0,
    };
    let started = Instant::now();
    if let FramePlan::Progressive { coarse_scale } = FramePlan::of(full, pacer.budget_samples()) {
        let small = size.map(|s| ((s as f32 * coarse_scale).round() as u32).max(1));
        let mut coarse = RaycastTarget::new(ctx, small)?;
        let t = Instant::now();
        let span = pacer.open(ctx);
        caster.render(ctx, scene, camera, settings, &mut coarse, ..)?;
        let s = f64::from(coarse_scale);
        pacer.submitted(ctx, full * s * s, span);
        wait(ctx)?;
        pacer.poll(ctx);
        timing.coarse_ms = Some(t.elapsed().as_secs_f64() * 1e3);
        timing.coarse_scale = coarse_scale;
    }
    let mut target = RaycastTarget::new(ctx, size)?;
    let mut row = 0;
    while row < size[1] {
        let end = cost.band_within(row, pacer.budget_samples());
        let t = Instant::now();
        let span = pacer.open(ctx);
        caster.render(ctx, scene, camera, settings, &mut target, row..end)?;
        pacer.submitted(ctx, cost.rows(row..end), span);
        wait(ctx)?;
        pacer.poll(ctx);
        let ms = t.elapsed().as_secs_f64() * 1e3;
        timing.largest_band_ms = timing.largest_band_ms.max(ms);
        timing.bands += 1;
        row = end;
    }
    timing.full_ms = started.elapsed().as_secs_f64() * 1e3;
    timing.rate = pacer.rate();
    Ok((timing, target))
}

/// Makes a brick table as the viewer does (a frame's budget of slices at a time), timing the
/// largest step.
fn bricks_like_the_viewer(
    ctx: &GpuContext,
    caster: &Raycaster,
    source: BrickSource<'_>,
    pacer: &FramePacer,
) -> anyhow::Result<Bricks> {
    let mut bricks = caster.start_bricks(ctx, source);
    let slices = (pacer.budget_samples() / bricks.voxels_per_slice() as f64).clamp(1.0, 1e9) as u32;
    let (mut steps, mut largest, started) = (0, 0.0f64, Instant::now());
    while !bricks.complete() {
        let t = Instant::now();
        bricks.advance(caster, ctx, slices);
        ctx.device
            .poll(wgpu::PollType::wait_indefinitely())
            .context("waiting for the GPU")?;
        largest = largest.max(t.elapsed().as_secs_f64() * 1e3);
        steps += 1;
    }
    println!(
        "brick table ({}): {steps} step(s) of {slices} brick slice(s), largest {largest:.0} ms, {:.1} s in all",
        match source {
            BrickSource::Intensity(_) => "intensity",
            BrickSource::Features(_) => "features",
        },
        started.elapsed().as_secs_f64()
    );
    Ok(bricks)
}

fn report_mip(what: &str, t: &MipTiming) {
    match t.coarse_ms {
        Some(ms) => println!(
            "{what}: coarse frame at {:.0}% resolution in {ms:.0} ms, then the full frame in {} band(s), largest {:.0} ms, all done in {:.1} s (measured {:.0} M samples/s)",
            100.0 * t.coarse_scale,
            t.bands,
            t.largest_band_ms,
            t.full_ms / 1e3,
            t.rate / 1e6
        ),
        None => println!(
            "{what}: whole frame in {} band(s), largest {:.0} ms, done in {:.1} s",
            t.bands,
            t.largest_band_ms,
            t.full_ms / 1e3
        ),
    }
}

pub fn run(opts: &Options<'_>) -> anyhow::Result<()> {
    let t0 = Instant::now();
    let input: PathBuf = opts
        .input
        .map_or_else(|| PathBuf::from(DEFAULT_SERIES), Path::to_path_buf);
    let files = super::features::read_input(&input)?;
    let loaded = crate::io::load(&files)
        .with_context(|| format!("loading {}", input.display()))?
        .volume;
    drop(files);
    let source_dims = loaded.dims;
    let mut volume: Volume = super::bench::tile_along_z(&loaded, opts.slices.max(1));
    drop(loaded);
    volume.spacing_mm[2] = WHOLE_BODY_SLICE_MM;
    let load_s = t0.elapsed().as_secs_f64();
    let dense_mb = volume.voxels.byte_len() >> 20;
    // Packed as the native viewer keeps it.
    let t = Instant::now();
    crate::app::pack_if_large(&mut volume);
    let pack_s = t.elapsed().as_secs_f64();
    // Shared with the feature job, as the viewer does: one copy of the voxels.
    let volume = std::sync::Arc::new(volume);
    println!(
        "volume: {:?} voxels ({:.0} M, {dense_mb} MB as stored, {} MB kept as {} in {pack_s:.1} s) from {} ({source_dims:?}) tiled along z at {WHOLE_BODY_SLICE_MM} mm",
        volume.dims,
        volume.dims.iter().product::<usize>() as f64 / 1e6,
        volume.voxels.byte_len() >> 20,
        volume.voxels.type_name(),
        input.display(),
    );
    println!(
        "load + tile: {load_s:.1} s; peak resident memory {:.0} MB",
        peak_rss_mb()
    );

    let ctx = pollster::block_on(GpuContext::new_headless())?;
    println!("adapter: {}", ctx.adapter_label());
    // Slab by slab, as the viewer spreads it over frames (each slab waited for, so that its
    // time is the GPU's too).
    let t = Instant::now();
    let (render_volume, mut upload) = RenderVolume::create(&ctx, &volume)?;
    let (mut slabs, mut largest_s) = (0usize, 0f64);
    loop {
        let step = Instant::now();
        let done = upload.step(&ctx, &volume, &render_volume)?;
        ctx.device
            .poll(wgpu::PollType::wait_indefinitely())
            .context("waiting for the GPU")?;
        slabs += 1;
        largest_s = largest_s.max(step.elapsed().as_secs_f64());
        if done {
            break;
        }
    }
    let caster = Raycaster::new(&ctx)?;
    println!(
        "upload (R16Float texture): {:.1} s in {slabs} slabs of at most 16 MiB, largest {:.0} ms; peak resident memory {:.0} MB",
        t.elapsed().as_secs_f64(),
        largest_s * 1e3,
        peak_rss_mb()
    );
    let mut pacer = FramePacer::new(Some(crate::app::mip_view::MipView::FRAME_BUDGET_S));
    let bricks = bricks_like_the_viewer(
        &ctx,
        &caster,
        BrickSource::Intensity(&render_volume),
        &pacer,
    )?;

    let camera = Camera::for_volume(
        &render_volume.world_from_voxel,
        render_volume.dims,
        ViewPreset::Anterior,
    );
    let settings = RenderSettings {
        window: (-1000.0, 400.0),
        hardware_filtering: true,
        ..Default::default()
    };
    let scene = Scene {
        volume: &render_volume,
        features: None,
        bricks: Some(&bricks),
        feature_bricks: None,
    };
    let (timing, _) = draw_like_the_viewer(
        &ctx, &caster, &scene, &camera, &settings, opts.size, &mut pacer,
    )?;
    report_mip("intensity MIP", &timing);
    if let Some(ms) = timing.coarse_ms {
        println!(
            "time to first MIP (load, upload, coarse frame): {:.1} s",
            t0.elapsed().as_secs_f64() - (timing.full_ms - ms) / 1e3
        );
    }

    let mut request = Request::new(opts.method);
    request.preset = opts.preset;
    // Paced as the viewer paces its steps, the features at the level the GPU budget allows.
    let dims = volume.dims.map(|d| u32::try_from(d).unwrap_or(u32::MAX));
    let max_dim = if opts.webgpu_limits {
        wgpu::Limits::default().max_texture_dimension_3d
    } else {
        ctx.limits.max_texture_dimension_3d
    };
    let (gpu_budget, feature_level) =
        crate::gpu::budget::plan_features(&ctx, dims, opts.gpu_budget_mib, max_dim);
    println!(
        "GPU budget {} MiB ({:?}): features at {}",
        gpu_budget.mib(),
        gpu_budget.source,
        crate::gpu::budget::level_text(feature_level)
    );
    let options = JobOptions {
        step_seconds: Some(crate::app::features::STEP_SECONDS),
        feature_level,
        ..super::bench::job_options(opts.webgpu_limits, opts.budget_mib)
    };
    let t = Instant::now();
    let mut job = FeatureJob::shared(&ctx, std::sync::Arc::clone(&volume), &request, options)?;
    let rss = || super::bench::rss_mb().unwrap_or(f64::NAN);
    println!("feature job created: resident memory {:.0} MB", rss());
    // Resident memory as the job goes (what holds memory: the texture, the bricks' buffers).
    let mut trace = Vec::new();
    let mut next_trace = 0.0;
    // Step by step as the viewer does, each step waited for: a step is what a frame of the
    // viewer may wait behind while the job runs (issue "full-size scans", deliver 5).
    let mut steps_ms = Vec::new();
    let mut largest = (0.0f64, String::new());
    loop {
        let t = Instant::now();
        let state = job.step(&ctx)?;
        ctx.device
            .poll(wgpu::PollType::wait_indefinitely())
            .context("waiting for the GPU")?;
        let ms = t.elapsed().as_secs_f64() * 1e3;
        match state {
            JobState::Done => break,
            JobState::Running { stage, fraction } => {
                if f64::from(fraction) >= next_trace {
                    trace.push(format!("{:.0}% {:.0} MB", 100.0 * fraction, rss()));
                    next_trace += 0.1;
                }
                if ms > largest.0 {
                    largest = (ms, stage);
                }
                steps_ms.push(ms);
            }
        }
    }
    steps_ms.sort_by(f64::total_cmp);
    let quantile = |q: f64| {
        let i = ((steps_ms.len() as f64 * q) as usize).min(steps_ms.len().saturating_sub(1));
        steps_ms.get(i).copied().unwrap_or(0.0)
    };
    let over = |ms: f64| steps_ms.iter().filter(|&&t| t > ms).count();
    println!(
        "feature job: {} step(s), median {:.0} ms, 95th percentile {:.0} ms, 99th {:.0} ms, {} over 200 ms, {} over 500 ms, largest {:.0} ms ({})",
        steps_ms.len(),
        quantile(0.5),
        quantile(0.95),
        quantile(0.99),
        over(200.0),
        over(500.0),
        largest.0,
        largest.1
    );
    println!("resident memory while the job ran: {}", trace.join(", "));
    let (bricks_n, overhead) = (job.slab_count(), job.overhead());
    let features: FeatureTexture = job.finish().context("the feature job did not finish")?;
    let secs = t.elapsed().as_secs_f64();
    let n = volume.dims.iter().product::<usize>() as f64;
    println!(
        "{:?} features: {secs:.1} s ({:.2} M voxels/s), {bricks_n} brick(s), halo overhead {overhead:.2}{}; peak resident memory {:.0} MB",
        opts.method,
        n / secs / 1e6,
        if opts.webgpu_limits {
            ", planned with WebGPU's default limits"
        } else {
            ""
        },
        peak_rss_mb()
    );
    let feature_bricks =
        bricks_like_the_viewer(&ctx, &caster, BrickSource::Features(&features), &pacer)?;
    let scene = Scene {
        features: Some(&features),
        feature_bricks: Some(&feature_bricks),
        ..scene
    };
    let (timing, target) = draw_like_the_viewer(
        &ctx, &caster, &scene, &camera, &settings, opts.size, &mut pacer,
    )?;
    report_mip("feature MIP", &timing);
    if let Some(png) = opts.png {
        let rgba = target.read_image_blocking(&ctx)?;
        image::save_buffer(
            png,
            &rgba,
            opts.size[0],
            opts.size[1],
            image::ExtendedColorType::Rgba8,
        )
        .with_context(|| format!("writing {}", png.display()))?;
        println!("MIP written to {}", png.display());
    }
    println!(
        "total {:.1} s; peak resident memory {:.0} MB",
        t0.elapsed().as_secs_f64(),
        peak_rss_mb()
    );
    Ok(())
}
