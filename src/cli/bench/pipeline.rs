//! `bench --pipeline`'s whole feature jobs, timed (seconds, bricks, halo overhead), and the
//! synthetic scene the size-only benchmark runs on.

use super::*;

/// One whole feature job, timed: seconds, bricks, halo overhead.
pub(super) fn time_job(
    ctx: &GpuContext,
    volume: &Volume,
    req: &crate::cpu::pipeline::Request,
    options: crate::compute::pipeline::JobOptions,
) -> anyhow::Result<(f64, usize, f64)> {
    use crate::compute::pipeline::FeatureJob;
    let t = Instant::now();
    let mut job = FeatureJob::with_options(ctx, volume, req, options)?;
    job.run_blocking(ctx)?;
    let secs = t.elapsed().as_secs_f64();
    Ok((secs, job.slab_count(), job.overhead()))
}

/// `bench --pipeline`: the feature job on the input and on the reference scene.
pub(super) fn pipeline_bench(args: &BenchArgs, preset: Preset) -> anyhow::Result<()> {
    use crate::cpu::pipeline::{Method, Request};
    let method = match args.method.as_str() {
        "hessian" | "all" => Method::Hessian,
        "li" => Method::Li,
        "rst" => Method::Rst,
        m => bail!("--pipeline --method {m}: hessian, li or rst"),
    };
    let mut req = Request::new(method);
    req.preset = preset;
    req.sigmas_mm = args.sigma_mm.clone();
    req.rays = Some(args.rays);
    req.step_mm = Some(args.step_mm);
    let ctx = pollster::block_on(GpuContext::new_headless())?;
    println!("adapter: {}", ctx.adapter_label());
    let reference = scene(args.size);
    let mut rates = Vec::new();
    let mut inputs: Vec<(String, Volume)> = vec![(format!("scene {0}^3", args.size), reference)];
    if let Some(path) = &args.input {
        let t = Instant::now();
        let files = crate::cli::features::read_input(path)?;
        let volume = crate::io::load(&files)
            .with_context(|| format!("loading {}", path.display()))?
            .volume;
        println!(
            "loaded {} in {:.1} s",
            path.display(),
            t.elapsed().as_secs_f64()
        );
        let volume = match args.tile_z {
            Some(nz) => tile_along_z(&volume, nz),
            None => volume,
        };
        inputs.push((path.display().to_string(), volume));
    }
    for (name, volume) in &inputs {
        let options = job_options(args.webgpu_limits, args.budget_mib);
        let (secs, bricks, overhead) = time_job(&ctx, volume, &req, options)?;
        let n = volume.dims.iter().product::<usize>() as f64;
        // Voxels of the grid the method computes on (the Hessian refines thick axes).
        let n_c = req
            .resolve(&Grid::of(volume))
            .map_or(n, |r| r.compute.len() as f64);
        let rate = n_c / secs;
        println!(
            "{method:?} on {name}: {:?} voxels at {:.2?} mm ({:.1} M compute voxels), {secs:.1} s, {:.3} M compute voxels/s ({:.3} M input voxels/s), {bricks} brick(s), halo overhead {overhead:.2}",
            volume.dims,
            volume.spacing_mm,
            n_c / 1e6,
            rate / 1e6,
            n / secs / 1e6
        );
        rates.push(rate);
        if let Some(mb) = peak_rss_mb() {
            println!("peak resident memory so far: {mb:.0} MB");
        }
    }
    if let [reference, input] = rates[..] {
        println!(
            "input / scene rate: {:.2} (compute voxels/s of the input over the {}^3 scene's)",
            input / reference,
            args.size
        );
    }
    Ok(())
}

/// A scene of nodules and vessels filling `n` mm at 1 mm, with 10 HU noise.
pub(super) fn scene(n: usize) -> Volume {
    let e = n as f64 - 1.0;
    let f = |x: f64| x * e;
    let mut p = Phantom::new("bench", [0.0; 3], [e; 3], 40.0);
    for (c, r) in [
        ([0.3, 0.4, 0.5], 0.05),
        ([0.65, 0.6, 0.4], 0.04),
        ([0.5, 0.72, 0.7], 0.06),
        ([0.72, 0.3, 0.62], 0.03),
    ] {
        p = p.with(
            Shape::Sphere {
                centre_mm: c.map(f),
                radius_mm: (r * e).max(2.0),
            },
            140.0,
        );
    }
    for (a, b, r) in [
        ([0.5, 0.5, 0.0], [0.5, 0.5, 1.0], 0.03),
        ([0.0, 0.1, 0.5], [1.0, 0.9, 0.5], 0.025),
        ([0.2, 0.0, 0.2], [0.8, 1.0, 0.9], 0.02),
    ] {
        p = p.with(
            Shape::Cylinder {
                a_mm: a.map(f),
                b_mm: b.map(f),
                radius_mm: (r * e).max(1.5),
            },
            150.0,
        );
    }
    p.render_noisy([1.0; 3], 10.0, 1)
}
