//! `shapecast bench [--size N | INPUT]`: times every stage of the GPU features on this machine's
//! adapter, the same work on the CPU reference, and (with `--vs-python`) scikit-image's Hessian
//! eigenvalues and Frangi on the same volume in the same run (issue 5). A benchmark, not a test.

mod pipeline;

use std::path::PathBuf;
use std::time::{Duration, Instant};

use anyhow::{Context, bail};

use crate::compute::eigen_features::{EigenFeatures, EigenPass, Mapping, TensorOutput};
use crate::compute::gaussian::{Gaussian, SeparableKernel};
use crate::compute::gradient::{Gradient, GradientBuffers, GradientOutput};
use crate::compute::hessian::{Hessian, HessianKernels};
use crate::compute::rst::{Rst, RstDispatch, RstInputs, RstOutput, RstRays};
use crate::cpu::features::{FeatureMap, HessianMethod, hessian_features_multiscale};
use crate::cpu::rst::{GradientVolume, RstParams, rst_tensor_at};
use crate::cpu::{Grid, Preset, gaussian_smooth, rays};
use crate::gpu::GpuContext;
use crate::gpu::kernel::{Recorder, SlabGrid, f32_buffer};
use crate::gpu::readback::read_f32_blocking;
use crate::phantom::{Phantom, Shape};
use crate::volume::Volume;

use pipeline::{pipeline_bench, scene};

#[derive(clap::Args, Debug)]
pub struct BenchArgs {
    /// A volume file or DICOM folder; without it, a synthetic N^3 scene at 1 mm.
    pub input: Option<PathBuf>,
    /// Edge of the synthetic volume, voxels.
    #[arg(long, default_value_t = 128)]
    pub size: usize,
    /// Which stages: all, hessian (smoothing + Hessian features) or rst (gradient + RST).
    #[arg(long, default_value = "all")]
    pub method: String,
    /// Preset (scales, ray length, transfer function).
    #[arg(long, default_value = "lymph-nodes")]
    pub preset: String,
    /// Hessian scales, mm (default: the preset's).
    #[arg(long, value_delimiter = ',')]
    pub sigma_mm: Option<Vec<f64>>,
    /// RST ray count.
    #[arg(long, default_value_t = 42)]
    pub rays: usize,
    /// RST step, mm.
    #[arg(long, default_value_t = crate::cpu::rst::DEFAULT_STEP_MM)]
    pub step_mm: f64,
    /// Voxels the CPU RST reference is timed on (its per-voxel cost is extrapolated).
    #[arg(long, default_value_t = 4000)]
    pub cpu_rst_voxels: usize,
    /// Skip the CPU reference.
    #[arg(long)]
    pub no_cpu: bool,
    /// Also time scikit-image (python3 with scikit-image and nibabel) on the same volume.
    #[arg(long)]
    pub vs_python: bool,
    /// Time the whole feature job (bricks, as the app and `features` run it) on INPUT and on
    /// the synthetic `--size`^3 scene in the same run: voxels/s of both, their ratio, bricks and
    /// halo overhead. `--method` is then hessian, li or rst.
    #[arg(long)]
    pub pipeline: bool,
    /// With --pipeline: plan with WebGPU's default limits instead of the adapter's.
    #[arg(long)]
    pub webgpu_limits: bool,
    /// With --pipeline and INPUT: repeat INPUT's slices along z to this many slices (a
    /// whole-body length from a real chest series, e.g. 2000) before timing.
    #[arg(long)]
    pub tile_z: Option<usize>,
    /// A whole-body-length CT: INPUT's slices (default: ../shared/data's 512x512 chest series)
    /// tiled along z to `--tile-z` slices (default 2000) at 0.8 mm; times load, upload, the
    /// first MIP as the viewer draws it (coarse, then bands), `--method`'s features (default
    /// hessian) and the feature MIP, with peak memory.
    #[arg(long)]
    pub whole_body: bool,
    /// With --whole-body: write the feature MIP here.
    #[arg(long)]
    pub png: Option<PathBuf>,
    /// With --pipeline or --whole-body: the feature job's memory budget for its bricks, MiB
    /// (default: the app's, `JobOptions::default`).
    #[arg(long)]
    pub budget_mib: Option<u64>,
    /// With --whole-body: GPU memory for the volume textures, MiB (default: the adapter's
    /// rule, as the viewer). Over it the features are kept max-pooled.
    #[arg(long)]
    pub gpu_budget_mib: Option<u64>,
}

/// The feature job's options for a benchmark: WebGPU's default limits if asked for, the
/// memory budget if given.
pub(crate) fn job_options(
    webgpu_limits: bool,
    budget_mib: Option<u64>,
) -> crate::compute::pipeline::JobOptions {
    let defaults = crate::compute::pipeline::JobOptions::default();
    crate::compute::pipeline::JobOptions {
        limits: webgpu_limits.then(wgpu::Limits::default),
        memory_budget_bytes: budget_mib.map_or(defaults.memory_budget_bytes, |m| m << 20),
        ..defaults
    }
}

/// `volume` with its slices repeated back and forth along z to `nz` slices (no seam; compact
/// voxels kept).
pub(crate) fn tile_along_z(volume: &Volume, nz: usize) -> Volume {
    use crate::volume::Voxels;
    fn tile<T: Copy>(v: &[T], plane: usize, n: usize, nz: usize) -> Vec<T> {
        let period = (2 * n).saturating_sub(1).max(1);
        let mut out = Vec::with_capacity(plane * nz);
        for k in 0..nz {
            let p = k % period;
            let src = if p < n { p } else { period - p };
            out.extend_from_slice(&v[src * plane..(src + 1) * plane]);
        }
        out
    }
    let plane = volume.dims[0] * volume.dims[1];
    let n = volume.dims[2].max(1);
    let voxels = match &volume.voxels {
        Voxels::Packed(p) => return tile_along_z(&volume.with_voxels(p.unpack()), nz),
        Voxels::U8(v) => Voxels::U8(tile(v, plane, n, nz)),
        Voxels::I16(v) => Voxels::I16(tile(v, plane, n, nz)),
        Voxels::U16(v) => Voxels::U16(tile(v, plane, n, nz)),
        Voxels::F32(v) => Voxels::F32(tile(v, plane, n, nz)),
    };
    Volume {
        dims: [volume.dims[0], volume.dims[1], nz],
        spacing_mm: volume.spacing_mm,
        origin_mm: volume.origin_mm,
        direction: volume.direction,
        voxels,
        value_slope: volume.value_slope,
        value_intercept: volume.value_intercept,
        modality: volume.modality,
        pet: volume.pet.clone(),
        frame_of_reference: volume.frame_of_reference.clone(),
        source: format!("{} tiled along z to {nz} slices", volume.source),
        warnings: volume.warnings.clone(),
    }
}

/// The process's peak resident memory (Linux), MB.
pub(crate) fn peak_rss_mb() -> Option<f64> {
    status_mb("VmHWM:")
}

/// The process's resident memory now (Linux), MB.
pub(crate) fn rss_mb() -> Option<f64> {
    status_mb("VmRSS:")
}

fn status_mb(key: &str) -> Option<f64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with(key))?;
    let kb: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb / 1024.0)
}

struct Row {
    stage: &'static str,
    gpu: Option<Duration>,
    cpu: Option<(Duration, bool)>,
    note: String,
}

fn ms(d: Duration) -> f64 {
    d.as_secs_f64() * 1e3
}

/// Records with `f`, submits, and waits for the GPU: the wall time of the GPU work.
fn timed(
    ctx: &GpuContext,
    f: impl FnOnce(&mut wgpu::CommandEncoder) -> anyhow::Result<()>,
) -> anyhow::Result<Duration> {
    ctx.device.poll(wgpu::PollType::wait_indefinitely())?;
    let t = Instant::now();
    let mut enc = ctx
        .device
        .create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("bench"),
        });
    f(&mut enc)?;
    ctx.queue.submit([enc.finish()]);
    ctx.device.poll(wgpu::PollType::wait_indefinitely())?;
    Ok(t.elapsed())
}

pub fn run(args: BenchArgs) -> anyhow::Result<()> {
    let preset = Preset::from_name(&args.preset).context("unknown --preset")?;
    if args.whole_body {
        use crate::cpu::pipeline::Method;
        let method = match args.method.as_str() {
            "hessian" | "all" => Method::Hessian,
            "li" => Method::Li,
            "rst" => Method::Rst,
            m => bail!("--whole-body --method {m}: hessian, li or rst"),
        };
        return super::whole_body::run(&super::whole_body::Options {
            input: args.input.as_deref(),
            slices: args.tile_z.unwrap_or(2000),
            method,
            preset,
            webgpu_limits: args.webgpu_limits,
            budget_mib: args.budget_mib,
            gpu_budget_mib: args.gpu_budget_mib,
            size: [768, 768],
            png: args.png.as_deref(),
        });
    }
    if args.pipeline {
        return pipeline_bench(&args, preset);
    }
    let volume = match &args.input {
        Some(path) => {
            let files = super::features::read_input(path)?;
            crate::io::load(&files)
                .with_context(|| format!("loading {}", path.display()))?
                .volume
        }
        None => scene(args.size),
    };
    let which = args.method.as_str();
    if !matches!(which, "all" | "hessian" | "rst") {
        bail!("--method {which}: all, hessian or rst");
    }
    let ctx = pollster::block_on(GpuContext::new_headless())?;
    let grid = Grid::of(&volume);
    let n = grid.len() as u64;
    let slab = SlabGrid::new(
        volume.dims.map(|d| d as u32),
        volume.spacing_mm.map(|s| s as f32),
    );
    let sigmas = args.sigma_mm.clone().unwrap_or_else(|| preset.sigmas_mm());
    let values = volume.to_f32();
    let limit = ctx.limits.max_storage_buffer_binding_size;
    if n * 4 > limit {
        bail!(
            "the bench runs the volume in one piece: {:?} voxels need {} MB per buffer, this GPU binds at most {} MB (use a smaller --size)",
            volume.dims,
            (n * 4) >> 20,
            limit >> 20
        );
    }
    println!("adapter: {}", ctx.adapter_label());
    println!(
        "volume: {:?} voxels at {:?} mm ({:.1} M voxels), {}",
        volume.dims,
        volume.spacing_mm,
        n as f64 / 1e6,
        volume.source
    );
    let threads = rayon::current_num_threads();
    let mut rows = Vec::new();
    let d = &ctx.device;
    let input = f32_buffer(d, "bench input", n);
    let tmp = f32_buffer(d, "bench tmp", n);
    let t = Instant::now();
    ctx.queue
        .write_buffer(&input, 0, bytemuck::cast_slice(&values));
    ctx.device.poll(wgpu::PollType::wait_indefinitely())?;
    rows.push(Row {
        stage: "upload",
        gpu: Some(t.elapsed()),
        cpu: None,
        note: format!("{} MB f32", (n * 4) >> 20),
    });
    let gaussian = Gaussian::new(&ctx)?;
    let smooth_out = f32_buffer(d, "bench smoothed", n);
    // Records the smoothing of the input into `smooth_out` with `kernel`.
    let smooth = |e: &mut wgpu::CommandEncoder, kernel: &SeparableKernel| {
        let mut r = Recorder::new(&ctx, e);
        gaussian.record_separable(&mut r, &slab, kernel, &input, &tmp, &smooth_out)
    };
    let mut python_sigmas = None;
    let mut hessian_gpu = None;
    if which != "rst" {
        let kernel = SeparableKernel::smooth(&ctx, 1.0, volume.spacing_mm);
        let g = timed(&ctx, |e| Ok(smooth(e, &kernel)?))?;
        let cpu = (!args.no_cpu).then(|| {
            let t = Instant::now();
            let _ = gaussian_smooth(&grid, &values, 1.0);
            (t.elapsed(), false)
        });
        rows.push(Row {
            stage: "smoothing (sigma 1 mm)",
            gpu: Some(g),
            cpu,
            note: String::new(),
        });
        // Hessian features: every scale, eq. 1 map, max over scales.
        let hessian = Hessian::new(&ctx)?;
        let eigen = EigenFeatures::new(&ctx)?;
        let comps: Vec<wgpu::Buffer> = (0..6).map(|_| f32_buffer(d, "bench hessian", n)).collect();
        // Output in z-blocks, each within the binding limit (the whole 256^3 output is not).
        let plane = u64::from(slab.dims[0]) * u64::from(slab.dims[1]);
        let block = ((limit / (12 * plane)).max(1) as u32).min(slab.dims[2]);
        let blocks: Vec<(u32, u32, wgpu::Buffer)> = (0..slab.dims[2])
            .step_by(block as usize)
            .map(|z0| {
                let nz = block.min(slab.dims[2] - z0);
                (
                    z0,
                    nz,
                    f32_buffer(d, "bench features", 3 * plane * u64::from(nz)),
                )
            })
            .collect();
        let kernels: Vec<HessianKernels> = sigmas
            .iter()
            .map(|&s| HessianKernels::new(&ctx, s, volume.spacing_mm, true))
            .collect();
        let g = timed(&ctx, |e| {
            for (i, k) in kernels.iter().enumerate() {
                let c: [&wgpu::Buffer; 6] = std::array::from_fn(|j| &comps[j]);
                hessian.record(&mut Recorder::new(&ctx, e), &slab, k, &input, &tmp, c)?;
                for (z0, nz, out) in &blocks {
                    eigen.record(
                        &mut Recorder::new(&ctx, e),
                        &slab,
                        c,
                        (*z0, *nz),
                        EigenPass::Output {
                            what: TensorOutput::hessian(Mapping::Map(FeatureMap::Simple)),
                            accumulate: i > 0,
                            out,
                        },
                    )?;
                }
            }
            Ok(())
        })?;
        hessian_gpu = Some(g);
        let cpu = (!args.no_cpu).then(|| {
            let t = Instant::now();
            let _ = hessian_features_multiscale(
                &grid,
                &values,
                &sigmas,
                HessianMethod::Map(FeatureMap::Simple),
            );
            (t.elapsed(), false)
        });
        rows.push(Row {
            stage: "Hessian features",
            gpu: Some(g),
            cpu,
            note: format!(
                "{} scales {:?} mm, eigenvalues + eq. 1",
                sigmas.len(),
                sigmas
            ),
        });
        let t = Instant::now();
        let mut bytes = 0;
        for (_, nz, out) in &blocks {
            bytes += read_f32_blocking(&ctx, out, (3 * plane * u64::from(*nz)) as usize)?.len() * 4;
        }
        rows.push(Row {
            stage: "readback (3 features)",
            gpu: Some(t.elapsed()),
            cpu: None,
            note: format!("{} MB", bytes >> 20),
        });
        python_sigmas = Some(sigmas.clone());
    }
    if which != "hessian" {
        let gradient = Gradient::new(&ctx)?;
        let gbufs: Vec<wgpu::Buffer> = (0..3).map(|_| f32_buffer(d, "bench gradient", n)).collect();
        let kernel =
            SeparableKernel::smooth(&ctx, crate::cpu::rst::DEFAULT_SIGMA_G_MM, volume.spacing_mm);
        let gb = GradientBuffers {
            gx: &gbufs[0],
            gy: &gbufs[1],
            gz: &gbufs[2],
        };
        // The RST reads (I, g) packed in one texture; the structure tensor reads g as buffers.
        let packed = crate::compute::gradient::packed_texture(&ctx, &slab, "bench (I, g)")?;
        let g = timed(&ctx, |e| {
            smooth(e, &kernel)?;
            gradient.record(
                &mut Recorder::new(&ctx, e),
                &slab,
                &smooth_out,
                GradientOutput::Buffers(gb),
            )?;
            let packed = GradientOutput::Packed(&packed);
            gradient.record(&mut Recorder::new(&ctx, e), &slab, &smooth_out, packed)?;
            Ok(())
        })?;
        let mut gv = None;
        let cpu = (!args.no_cpu).then(|| {
            let t = Instant::now();
            gv = Some(GradientVolume::new(
                &grid,
                &values,
                crate::cpu::rst::DEFAULT_SIGMA_G_MM,
            ));
            (t.elapsed(), false)
        });
        rows.push(Row {
            stage: "smoothing (sigma_g) + gradient",
            gpu: Some(g),
            cpu,
            note: String::new(),
        });
        let rays = rays::ray_set(args.rays).context("--rays: 26, 42, 98, 218 or 386")?;
        let params = RstParams {
            rays,
            radius_mm: preset.radius_mm(),
            step_mm: args.step_mm,
            tf: preset.transfer_function(),
            rule: crate::cpu::OpacityRule::Consistent,
        };
        let rst = Rst::new(&ctx)?;
        let ray_set = RstRays::new(
            &ctx,
            &params,
            volume.spacing_mm,
            crate::cpu::rst::DEFAULT_SIGMA_G_MM,
        )?;
        let inputs = RstInputs {
            volume: &packed,
            rays: &ray_set,
        };
        // Slices per dispatch: a few million voxel-rays each, so no dispatch runs for minutes.
        let plane = u64::from(slab.dims[0]) * u64::from(slab.dims[1]);
        let per = ((4u64 << 20) / (plane * u64::from(ray_set.ray_count())).max(1)).max(1) as u32;
        let out = f32_buffer(d, "bench rst", 3 * plane * u64::from(per));
        let mut total = Duration::ZERO;
        let mut z = 0;
        while z < slab.dims[2] {
            let nz = per.min(slab.dims[2] - z);
            let dispatch = RstDispatch {
                z_stride: 1,
                grid: slab,
                out_z0: z,
                out_nz: nz,
                rows: None,
                output: RstOutput::Features(FeatureMap::Li),
            };
            total += timed(&ctx, |e| {
                Ok(rst.record(&mut Recorder::new(&ctx, e), &inputs, &dispatch, &out)?)
            })?;
            z += nz;
        }
        // Ray samples: counted on the middle slices, extrapolated to the volume.
        let mid = slab.dims[2] / 2;
        let nz = per.min(slab.dims[2] - mid).min(4);
        let count_out = f32_buffer(d, "bench rst count", plane * u64::from(nz));
        timed(&ctx, |e| {
            let dispatch = RstDispatch {
                z_stride: 1,
                grid: slab,
                out_z0: mid,
                out_nz: nz,
                rows: None,
                output: RstOutput::SampleCount,
            };
            Ok(rst.record(&mut Recorder::new(&ctx, e), &inputs, &dispatch, &count_out)?)
        })?;
        let counts = read_f32_blocking(&ctx, &count_out, (plane * u64::from(nz)) as usize)?;
        let per_voxel =
            counts.iter().map(|&c| f64::from(c)).sum::<f64>() / counts.len().max(1) as f64;
        let samples = per_voxel * n as f64;
        let cpu = match (&gv, args.no_cpu) {
            (Some(gv), false) => Some((cpu_rst(gv, &grid, &params, args.cpu_rst_voxels), true)),
            _ => None,
        };
        rows.push(Row {
            stage: "RST (Li features)",
            gpu: Some(total),
            cpu,
            note: format!(
                "{} rays, R {} mm, dr {} mm: {:.1} samples/voxel, {:.2} G ray samples/s",
                ray_set.ray_count(),
                params.radius_mm,
                params.step_mm,
                per_voxel,
                samples / total.as_secs_f64() / 1e9
            ),
        });
    }
    println!();
    println!(
        "| stage | GPU ms | GPU M voxels/s | CPU reference ms ({threads} threads) | CPU / GPU | notes |"
    );
    println!("|---|---:|---:|---:|---:|---|");
    for r in &rows {
        let gpu = r.gpu.map_or("-".to_owned(), |g| format!("{:.1}", ms(g)));
        let rate = r.gpu.map_or("-".to_owned(), |g| {
            format!("{:.1}", n as f64 / g.as_secs_f64() / 1e6)
        });
        let (cpu, ratio) = match (r.cpu, r.gpu) {
            (Some((c, extrapolated)), Some(g)) => (
                format!(
                    "{:.0}{}",
                    ms(c),
                    if extrapolated { " (extrapolated)" } else { "" }
                ),
                format!("{:.1}x", c.as_secs_f64() / g.as_secs_f64()),
            ),
            _ => ("-".to_owned(), "-".to_owned()),
        };
        println!(
            "| {} | {gpu} | {rate} | {cpu} | {ratio} | {} |",
            r.stage, r.note
        );
    }
    if args.vs_python {
        let sigmas =
            python_sigmas.context("--vs-python times the Hessian: use --method all or hessian")?;
        let py = python_bench(&volume, &sigmas)?;
        let hess = hessian_gpu.context("no GPU Hessian time")?;
        println!();
        println!("scikit-image {} on the same volume (numpy {}):", py.0, py.1);
        println!(
            "| Hessian eigenvalues, {} scales | {:.0} ms | GPU Hessian features {:.0} ms | GPU is {:.1}x faster |",
            sigmas.len(),
            py.2 * 1e3,
            ms(hess),
            py.2 / hess.as_secs_f64()
        );
        println!(
            "| Frangi, {} scales | {:.0} ms | GPU Hessian features {:.0} ms | GPU is {:.1}x faster |",
            sigmas.len(),
            py.3 * 1e3,
            ms(hess),
            py.3 / hess.as_secs_f64()
        );
    }
    Ok(())
}

/// CPU RST per-voxel cost on `count` voxels spread over the volume (threads), extrapolated to
/// every voxel.
fn cpu_rst(gv: &GradientVolume, grid: &Grid, params: &RstParams, count: usize) -> Duration {
    use rayon::prelude::*;
    let n = grid.len();
    let count = count.clamp(1, n);
    let stride = (n / count).max(1);
    let t = Instant::now();
    let _: Vec<_> = (0..count)
        .into_par_iter()
        .map(|i| rst_tensor_at(gv, grid.position_mm(grid.ijk((i * stride) % n)), params))
        .collect();
    t.elapsed().mul_f64(n as f64 / count as f64)
}

/// (skimage version, numpy version, Hessian eigenvalue seconds, Frangi seconds).
fn python_bench(volume: &Volume, sigmas: &[f64]) -> anyhow::Result<(String, String, f64, f64)> {
    let dir = std::env::temp_dir().join(format!("shapecast-bench-{}", std::process::id()));
    std::fs::create_dir_all(&dir)?;
    let path = dir.join("volume.nii");
    let values = volume.to_f32();
    let bytes = crate::io::nifti::write(
        &path.to_string_lossy(),
        volume,
        &[values.as_slice()],
        crate::io::nifti::WriteIntent::None,
    )?;
    std::fs::write(&path, bytes)?;
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/scripts/bench_skimage.py");
    let sig: Vec<String> = sigmas.iter().map(|s| s.to_string()).collect();
    let out = std::process::Command::new("python3")
        .arg(script)
        .arg(&path)
        .arg("--sigma-mm")
        .arg(sig.join(","))
        .output()
        .context("running python3 scripts/bench_skimage.py")?;
    let _ = std::fs::remove_dir_all(&dir);
    if !out.status.success() {
        bail!(
            "scripts/bench_skimage.py failed (pip install scikit-image nibabel numpy): {}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
    let v: serde_json::Value =
        serde_json::from_slice(&out.stdout).context("bench_skimage.py output")?;
    let s = |k: &str| v[k].as_str().unwrap_or("?").to_owned();
    let f = |k: &str| v[k].as_f64().unwrap_or(f64::NAN);
    Ok((
        s("skimage"),
        s("numpy"),
        f("hessian_eigen_s"),
        f("frangi_s"),
    ))
}
