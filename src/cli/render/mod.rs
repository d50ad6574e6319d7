//! `shapecast render INPUT --out MIP.png`: the viewer's ray caster headless. Features come from
//! [`FeatureJob`] (the same job the app runs), the picture from [`Raycaster`]; `--pick PX,PY`
//! prints as JSON where that pixel's maximum came from (click-to-navigate without a browser),
//! `--bench N` times N frames, `--turntable N --out DIR/` writes N frames of a full turn about
//! the view's vertical axis (DIR/frame_0000.png, ...: a movie's frames).

mod output;
mod pet;

use std::path::PathBuf;

use anyhow::{Context, bail};
use glam::DVec3;

use crate::compute::pipeline::{FeatureJob, JobState};
use crate::cpu::Preset;
use crate::cpu::pipeline::{Method, Request};
use crate::gpu::GpuContext;
use crate::gpu::volume_texture::{FeatureTexture, RenderVolume};
use crate::io;
use crate::phantom::{self, Phantom};
use crate::render::camera::{Camera, ViewPreset};
use crate::render::raycast::{
    self, Pick, Projection, RaycastTarget, Raycaster, RenderSettings, Scene, Slab,
};
use crate::volume::{Modality, Volume};

use output::{bench, pick_json};
use pet::PetOverlay;

#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum RenderMethod {
    /// Intensity only (no features).
    Intensity,
    Hessian,
    Li,
    Frangi,
    Gst,
    Rst,
}

#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum OnlyArg {
    Vesselness,
    Airwayness,
    Blobness,
}

#[derive(clap::Args, Debug)]
pub struct RenderArgs {
    /// A volume file or folder (as `shapecast features` reads them), or `phantom:NAME`
    /// (e.g. phantom:bifurcation-nodules-far, phantom:demo).
    #[arg(required_unless_present = "dicomweb", conflicts_with = "dicomweb")]
    pub input: Option<String>,
    #[command(flatten)]
    pub dicomweb: crate::cli::dicomweb::DicomWebArgs,
    #[arg(long, value_enum, default_value = "rst")]
    pub method: RenderMethod,
    /// Preset view (radiological convention; see src/render/camera.rs).
    #[arg(long, value_enum, default_value = "anterior")]
    pub view: ViewPreset,
    /// Turn the view: positive yaw moves the viewer to the screen's right, degrees.
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    pub yaw_deg: f64,
    /// Turn the view: positive pitch moves the viewer up, degrees.
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    pub pitch_deg: f64,
    /// Magnification (1 = the volume's bounding sphere fills the shorter side).
    #[arg(long, default_value_t = 1.0)]
    pub zoom: f64,
    /// Image size, WxH.
    #[arg(long, default_value = "512x512")]
    pub size: String,
    /// Show only this feature (over the grey intensity).
    #[arg(long, value_enum)]
    pub only: Option<OnlyArg>,
    /// Slab thickness around the centre along the view, mm (default: the whole volume).
    #[arg(long)]
    pub slab_mm: Option<f64>,
    /// Centre of the view and of the slab, LPS mm X,Y,Z (default: the volume's centre).
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true)]
    pub centre_mm: Option<Vec<f64>>,
    /// lymph-nodes, lung-nodules, airways or vessels: the features' preset.
    #[arg(long, default_value = "lymph-nodes")]
    pub preset: String,
    /// Grey window LO,HI in HU (default: mediastinum for CT, lung for the lung and airway
    /// presets, the value range otherwise).
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true)]
    pub window: Option<Vec<f32>>,
    /// Feature gains: one for all, or V,A,B (1 = the 99.9th percentile of each feature's
    /// positive values is full colour).
    #[arg(long, value_delimiter = ',')]
    pub gain: Option<Vec<f32>>,
    /// Minimum intensity projection for the grey (airways).
    #[arg(long)]
    pub minip: bool,
    /// Leave the grey intensity out.
    #[arg(long)]
    pub no_intensity: bool,
    /// Trilinear interpolation by the texture unit instead of in the shader (faster; the
    /// default shader path matches the CPU twin exactly).
    #[arg(long)]
    pub hw_filter: bool,
    /// Do not skip empty space (same picture, slower; for comparisons).
    #[arg(long)]
    pub no_skip: bool,
    /// Plan the feature bricks with WebGPU's default limits (128 MiB per binding, 256 MiB per
    /// buffer), as many browsers grant, instead of this adapter's.
    #[arg(long)]
    pub webgpu_limits: bool,
    /// GPU memory for the volume textures, MiB (default: the adapter's rule, as the viewer).
    /// Over it the features are kept max-pooled at 1/2, 1/4, ... resolution.
    #[arg(long)]
    pub gpu_budget_mib: Option<u64>,
    /// Voxel spacing of a `phantom:` input, mm: one value or X,Y,Z.
    #[arg(long, value_delimiter = ',', default_value = "0.5")]
    pub spacing_mm: Vec<f64>,
    /// Output PNG (with --turntable: the folder the frames are written into).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Write N frames of a 360° turn about the view's vertical axis, 360/N degrees apart
    /// (the first is the view asked for), as DIR/frame_0000.png ... into the --out folder.
    #[arg(long)]
    pub turntable: Option<u32>,
    /// Store the --turntable frames back into the --dicomweb archive: a multi-frame true-colour
    /// Secondary Capture series in the source study (SeriesDescription "Shapecast shape MIP,
    /// ..."), referencing the source series; with the same credentials. --out is then optional.
    #[arg(long, requires = "dicomweb", requires = "turntable")]
    pub store: bool,
    /// Print, as JSON, where pixel PX,PY's maximum came from.
    #[arg(long, value_delimiter = ',')]
    pub pick: Option<Vec<u32>>,
    /// Render this many frames and print the frame time.
    #[arg(long)]
    pub bench: Option<u32>,
    /// A PET of the same patient (file or folder) fused over the picture in hot iron: its MIP
    /// along the same rays, read on its own grid in patient coordinates. `--pick` then adds the
    /// PET's value (SUV when the header allows) at the picked point.
    #[arg(long)]
    pub pet: Option<PathBuf>,
    /// The PET's window LO,HI in its display unit (SUV; default 0,10).
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true)]
    pub pet_window: Option<Vec<f32>>,
    /// How much the PET covers the picture where it is hot, 0..1.
    #[arg(long, default_value_t = 0.5)]
    pub pet_opacity: f32,
}

pub fn parse_size(s: &str) -> anyhow::Result<[u32; 2]> {
    let (w, h) = s
        .split_once(['x', 'X'])
        .with_context(|| format!("--size {s:?}: expected WxH, e.g. 768x768"))?;
    let w: u32 = w.trim().parse().with_context(|| format!("--size {s:?}"))?;
    let h: u32 = h.trim().parse().with_context(|| format!("--size {s:?}"))?;
    if w == 0 || h == 0 || w > 16384 || h > 16384 {
        bail!("--size {s:?}: each side must be 1..16384");
    }
    Ok([w, h])
}

/// Loads `INPUT`: a file or folder, or `phantom:NAME`.
pub fn load_input(input: &str, spacing_mm: &[f64]) -> anyhow::Result<Volume> {
    if let Some(name) = input.strip_prefix("phantom:") {
        if name == "demo" {
            return Ok(phantom::demo());
        }
        let p = Phantom::by_name(name, None).with_context(|| {
            format!(
                "unknown phantom {name:?}; known: {}, {}",
                phantom::NAMES.join(", "),
                phantom::EXTRA_NAMES.join(", ")
            )
        })?;
        let spacing = crate::cli::phantom::spacing3(spacing_mm)?;
        return Ok(p.render_noisy(spacing, p.default_noise_hu, 1));
    }
    let path = PathBuf::from(input);
    let files = crate::cli::features::read_input(&path)?;
    let loaded = io::load(&files).with_context(|| format!("loading {input}"))?;
    for n in &loaded.notes {
        eprintln!("note: {n}");
    }
    for w in &loaded.volume.warnings {
        eprintln!("warning: {w}");
    }
    Ok(loaded.volume)
}

fn method(m: RenderMethod) -> Option<Method> {
    match m {
        RenderMethod::Intensity => None,
        RenderMethod::Hessian => Some(Method::Hessian),
        RenderMethod::Li => Some(Method::Li),
        RenderMethod::Frangi => Some(Method::Frangi),
        RenderMethod::Gst => Some(Method::Gst),
        RenderMethod::Rst => Some(Method::Rst),
    }
}

/// The grey window a radiologist would start with (0-10 SUV for a PET in SUV).
pub fn default_window(volume: &Volume, preset: Preset) -> (f32, f32) {
    if volume.modality == Modality::Ct {
        match preset {
            Preset::LungNodules | Preset::Airways => (-1350.0, 150.0),
            _ => (-160.0, 240.0),
        }
    } else if volume.unit() == "SUV" {
        PET_WINDOW
    } else {
        volume.value_range().unwrap_or((0.0, 1.0))
    }
}

/// The PET window nuclear-medicine readers start with, SUV.
const PET_WINDOW: (f32, f32) = (0.0, 10.0);

/// A `LO,HI` window argument, checked.
fn window_arg(name: &str, w: &[f32]) -> anyhow::Result<(f32, f32)> {
    let [lo, hi] = w[..] else {
        bail!("{name} takes LO,HI");
    };
    if !(lo.is_finite() && hi.is_finite() && hi > lo) {
        bail!("{name} {lo},{hi}: need LO < HI");
    }
    Ok((lo, hi))
}

/// Runs the feature job to the end, printing its progress to stderr.
pub fn compute_features(
    ctx: &GpuContext,
    volume: &std::sync::Arc<Volume>,
    request: &Request,
    webgpu_limits: bool,
    gpu_budget_mib: Option<u64>,
) -> anyhow::Result<FeatureTexture> {
    let dims = volume.dims.map(|d| u32::try_from(d).unwrap_or(u32::MAX));
    let limits = webgpu_limits.then(wgpu::Limits::default);
    let max_dim = limits
        .as_ref()
        .unwrap_or(&ctx.limits)
        .max_texture_dimension_3d;
    let (budget, feature_level) =
        crate::gpu::budget::plan_features(ctx, dims, gpu_budget_mib, max_dim);
    if feature_level > 0 {
        eprintln!(
            "features kept at {} within the GPU budget of {} MiB",
            crate::gpu::budget::level_text(feature_level),
            budget.mib()
        );
    }
    let options = crate::compute::pipeline::JobOptions {
        limits,
        feature_level,
        ..Default::default()
    };
    let mut job = FeatureJob::shared(ctx, std::sync::Arc::clone(volume), request, options)?;
    eprintln!(
        "{} brick(s), halo overhead {:.2}",
        job.slab_count(),
        job.overhead()
    );
    let started = web_time::Instant::now();
    let mut shown = String::new();
    loop {
        match job.step(ctx)? {
            JobState::Done => break,
            JobState::Running { fraction, stage } => {
                // One line per stage, not per poll.
                if stage != shown {
                    eprintln!("{stage}: {:3.0}%", 100.0 * fraction);
                    shown = stage;
                }
                ctx.device
                    .poll(wgpu::PollType::wait_indefinitely())
                    .map_err(|e| anyhow::anyhow!("waiting for the GPU: {e}"))?;
            }
        }
    }
    for n in job.notes() {
        eprintln!("{n}");
    }
    eprintln!(
        "{:?} features on {:?} voxels in {:.1} s",
        request.method,
        volume.dims,
        started.elapsed().as_secs_f64()
    );
    job.finish()
        .context("the feature job finished without features")
}

pub fn run(args: RenderArgs) -> anyhow::Result<()> {
    if args.out.is_none() && args.pick.is_none() && args.bench.is_none() && !args.store {
        bail!("nothing to do: give --out MIP.png, --pick PX,PY, --bench N or --store");
    }
    if let Some(n) = args.turntable {
        if !(1..=3600).contains(&n) {
            bail!("--turntable {n}: give 1 to 3600 frames");
        }
        if args.out.is_none() && !args.store {
            bail!("--turntable needs --out DIR/ for its frames (or --store)");
        }
        if let Some(dir) = args.out.as_ref().filter(|d| d.exists() && !d.is_dir()) {
            bail!(
                "--turntable writes frames into a folder; {} is a file",
                dir.display()
            );
        }
    }
    let size = parse_size(&args.size)?;
    let preset = crate::cli::preset(&args.preset)?;
    let pick_pixel = match args.pick.as_deref() {
        None => None,
        Some([x, y]) if *x < size[0] && *y < size[1] => Some([*x, *y]),
        Some(p) => bail!("--pick {p:?}: expected PX,PY inside the {size:?} image"),
    };
    if !(args.zoom.is_finite() && args.zoom > 0.0) {
        bail!("--zoom must be positive");
    }
    let mut archive = None;
    let volume = match &args.input {
        Some(input) => load_input(input, &args.spacing_mm)?,
        None => {
            let (loaded, opened) = args.dicomweb.open()?;
            archive = Some(opened);
            for n in &loaded.notes {
                eprintln!("note: {n}");
            }
            for w in &loaded.volume.warnings {
                eprintln!("warning: {w}");
            }
            loaded.volume
        }
    };
    // Shared with the feature job: one copy of the voxels.
    let volume = std::sync::Arc::new(volume);
    let ctx = pollster::block_on(GpuContext::new_headless())?;
    let render_volume = RenderVolume::upload(&ctx, &volume)?;
    let pet = PetOverlay::load(&ctx, &args, &volume)?;
    if pet.is_some() && args.turntable.is_some() {
        bail!("--pet with --turntable is not supported yet: render the fused frames one by one");
    }
    let features = match method(args.method) {
        None => None,
        Some(m) => {
            let mut request = Request::new(m);
            request.preset = preset;
            Some(compute_features(
                &ctx,
                &volume,
                &request,
                args.webgpu_limits,
                args.gpu_budget_mib,
            )?)
        }
    };

    let mut camera = Camera::for_volume(
        &render_volume.world_from_voxel,
        render_volume.dims,
        args.view,
    );
    if let Some(c) = &args.centre_mm {
        let [x, y, z] = c[..] else {
            bail!("--centre-mm takes X,Y,Z");
        };
        camera.centre_mm = DVec3::new(x, y, z);
    }
    camera.orbit(args.yaw_deg, args.pitch_deg);
    camera.zoom = args.zoom;

    let mut settings = RenderSettings {
        window: default_window(&volume, preset),
        ..Default::default()
    };
    if let Some(w) = &args.window {
        settings.window = window_arg("--window", w)?;
    }
    if let Some(g) = &args.gain {
        let gains = match g[..] {
            [x] => [x; 3],
            [v, a, b] => [v, a, b],
            _ => bail!("--gain takes one value or V,A,B"),
        };
        for (c, gain) in settings.channels.iter_mut().zip(gains) {
            c.gain = gain;
        }
    }
    if let Some(only) = args.only {
        let keep = only as usize;
        for (c, ch) in settings.channels.iter_mut().enumerate() {
            ch.on = c == keep;
        }
    }
    settings.projection = if args.minip {
        Projection::MinIp
    } else {
        Projection::Mip
    };
    settings.show_intensity = !args.no_intensity;
    settings.hardware_filtering = args.hw_filter;
    if let Some(t) = args.slab_mm {
        if !(t.is_finite() && t > 0.0) {
            bail!("--slab-mm must be positive");
        }
        settings.slab = Some(Slab {
            centre_mm: camera.centre_mm,
            thickness_mm: t,
        });
    }

    let caster = Raycaster::new(&ctx)?;
    let bricks = (!args.no_skip).then(|| caster.intensity_bricks(&ctx, &render_volume));
    let feature_bricks = match (&features, args.no_skip) {
        (Some(f), false) => Some(caster.feature_bricks(&ctx, f)),
        _ => None,
    };
    let scene = Scene {
        volume: &render_volume,
        features: features.as_ref(),
        bricks: bricks.as_ref(),
        feature_bricks: feature_bricks.as_ref(),
    };
    let mut target = RaycastTarget::new(&ctx, size)?;
    caster.render(&ctx, &scene, &camera, &settings, &mut target, ..)?;

    let shot = Shot {
        ctx: &ctx,
        caster: &caster,
        scene: &scene,
        camera: &camera,
        settings: &settings,
    };
    if let Some(frames) = args.bench {
        bench(&shot, &mut target, frames)?;
    }
    if let Some(n) = args.turntable {
        let frames = turntable(&shot, &mut target, n, args.out.as_deref(), args.store)?;
        if let (true, Some(archive)) = (args.store, &archive) {
            let rotation = crate::io::dicomweb::stow::Rotation {
                width: size[0],
                height: size[1],
                frames: &frames,
                description: rotation_description(args.method, preset),
                derivation: format!(
                    "Shapecast {}: maximum intensity projection of the {} features ({} preset) over the grey window {:.0}..{:.0}, {n} views {:.1} degrees apart about the vertical axis, starting {:?}",
                    env!("CARGO_PKG_VERSION"),
                    method_name(args.method),
                    preset.name(),
                    settings.window.0,
                    settings.window.1,
                    360.0 / f64::from(n),
                    args.view
                ),
                step_deg: 360.0 / f64::from(n),
                stable_key: None,
            };
            archive.store_rotation(&rotation)?;
        }
    } else if let Some(out) = &args.out {
        let mut rgba = target.read_image_blocking(&ctx)?;
        if let Some(pet) = &pet {
            pet.fuse(&ctx, &caster, &camera, size, &mut rgba)?;
        }
        image::save_buffer(
            out,
            &rgba,
            size[0],
            size[1],
            image::ExtendedColorType::Rgba8,
        )
        .with_context(|| format!("writing {}", out.display()))?;
        eprintln!(
            "{} {:?} {}x{} -> {}",
            volume.source,
            args.method,
            size[0],
            size[1],
            out.display()
        );
    }
    if let Some(pixel) = pick_pixel {
        let pick = target.pick_blocking(&ctx, pixel)?;
        let mut json = pick_json(&ctx, &volume, features.as_ref(), args.method, pixel, pick)?;
        if let (Some(pet), Some(p)) = (&pet, pick) {
            // The PET's value at the picked 3D point, read on its own grid.
            json["pet"] = serde_json::json!({
                "value": pet.volume.value_at_world(p.world_mm),
                "unit": pet.volume.unit(),
            });
            if pet.volume.unit() == "SUV" {
                json["suv"] = serde_json::json!(pet.volume.value_at_world(p.world_mm));
            }
        }
        println!("{}", serde_json::to_string_pretty(&json)?);
    }
    Ok(())
}

/// A full turn of the shape MIP from the anterior view, as `render --turntable` draws it with
/// its defaults: `n` RGBA frames of `size`, the preset's grey window, every channel on.
pub fn rotation_frames(
    ctx: &GpuContext,
    volume: &Volume,
    features: Option<&FeatureTexture>,
    preset: Preset,
    size: [u32; 2],
    n: u32,
) -> anyhow::Result<Vec<Vec<u8>>> {
    let render_volume = RenderVolume::upload(ctx, volume)?;
    let camera = Camera::for_volume(
        &render_volume.world_from_voxel,
        render_volume.dims,
        ViewPreset::Anterior,
    );
    let settings = RenderSettings {
        window: default_window(volume, preset),
        ..Default::default()
    };
    let caster = Raycaster::new(ctx)?;
    let bricks = caster.intensity_bricks(ctx, &render_volume);
    let feature_bricks = features.map(|f| caster.feature_bricks(ctx, f));
    let scene = Scene {
        volume: &render_volume,
        features,
        bricks: Some(&bricks),
        feature_bricks: feature_bricks.as_ref(),
    };
    let mut target = RaycastTarget::new(ctx, size)?;
    let shot = Shot {
        ctx,
        caster: &caster,
        scene: &scene,
        camera: &camera,
        settings: &settings,
    };
    turntable(&shot, &mut target, n, None, true)
}

/// The series' description after "Shapecast", e.g. "shape MIP, RST, lymph-nodes".
pub fn rotation_description(method: RenderMethod, preset: Preset) -> String {
    match method {
        RenderMethod::Intensity => "MIP".to_owned(),
        m => format!("shape MIP, {}, {}", method_name(m), preset.name()),
    }
}

pub fn method_name(method: RenderMethod) -> &'static str {
    match method {
        RenderMethod::Intensity => "intensity",
        RenderMethod::Hessian => "Hessian",
        RenderMethod::Li => "Li",
        RenderMethod::Frangi => "Frangi",
        RenderMethod::Gst => "GST",
        RenderMethod::Rst => "RST",
    }
}

/// What a render draws and how: the device, the ray caster, the scene, the camera and the
/// settings (`render --bench` and `--turntable` turn the camera from there).
#[derive(Clone, Copy)]
pub(super) struct Shot<'a> {
    pub ctx: &'a GpuContext,
    pub caster: &'a Raycaster,
    pub scene: &'a Scene<'a>,
    pub camera: &'a Camera,
    pub settings: &'a RenderSettings,
}

/// Frames `0..n` of a full turn: frame `f` is the view turned by `360 f / n` degrees about its
/// vertical axis, written as `dir/frame_FFFF.png` when a folder is given; returned as RGBA
/// when `keep` (else none are kept: a long turn is written frame by frame).
fn turntable(
    shot: &Shot<'_>,
    target: &mut RaycastTarget,
    n: u32,
    dir: Option<&std::path::Path>,
    keep: bool,
) -> anyhow::Result<Vec<Vec<u8>>> {
    let Shot {
        ctx,
        caster,
        scene,
        camera,
        settings,
    } = *shot;
    if let Some(dir) = dir {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    let started = web_time::Instant::now();
    let mut frames = Vec::with_capacity(if keep { n as usize } else { 0 });
    for f in 0..n {
        caster.render(ctx, scene, &camera.turntable(f, n), settings, target, ..)?;
        let rgba = target.read_image_blocking(ctx)?;
        if let Some(dir) = dir {
            let out = dir.join(format!("frame_{f:04}.png"));
            image::save_buffer(
                &out,
                &rgba,
                target.size[0],
                target.size[1],
                image::ExtendedColorType::Rgba8,
            )
            .with_context(|| format!("writing {}", out.display()))?;
        }
        if keep {
            frames.push(rgba);
        }
    }
    eprintln!(
        "turntable: {n} frames of {}x{} in {:.1} s{}",
        target.size[0],
        target.size[1],
        started.elapsed().as_secs_f64(),
        dir.map(|d| format!(" -> {}/frame_0000.png ...", d.display()))
            .unwrap_or_default()
    );
    Ok(frames)
}
