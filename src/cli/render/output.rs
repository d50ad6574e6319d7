//! `render --bench N` (frame times) and `render --pick PX,PY` (where a pixel's maximum came
//! from, as JSON).

use super::*;

pub(super) fn bench(
    shot: &Shot<'_>,
    target: &mut RaycastTarget,
    frames: u32,
) -> anyhow::Result<()> {
    let (ctx, scene) = (shot.ctx, shot.scene);
    // The first frame (already submitted) compiles the pipeline: wait for it before timing.
    ctx.device
        .poll(wgpu::PollType::wait_indefinitely())
        .context("waiting for the GPU")?;
    let mut times = Vec::new();
    let mut cam = *shot.camera;
    for _ in 0..frames.max(1) {
        // Turn a little every frame, as a drag does.
        cam.orbit(2.0, 0.0);
        let t = web_time::Instant::now();
        shot.caster
            .render(ctx, scene, &cam, shot.settings, target, ..)?;
        ctx.device
            .poll(wgpu::PollType::wait_indefinitely())
            .context("waiting for the GPU")?;
        times.push(t.elapsed().as_secs_f64() * 1e3);
    }
    let mean = times.iter().sum::<f64>() / times.len() as f64;
    let min = times.iter().copied().fold(f64::INFINITY, f64::min);
    eprintln!(
        "bench: {} frames of {}x{} over {:?} voxels ({}) on {}: mean {mean:.1} ms, min {min:.1} ms",
        times.len(),
        target.size[0],
        target.size[1],
        scene.volume.dims,
        match (scene.features.is_some(), scene.skipping()) {
            (true, true) => "intensity + features, skipping empty space",
            (true, false) => "intensity + features, no skipping",
            (false, true) => "intensity only, skipping empty space",
            (false, false) => "intensity only, no skipping",
        },
        ctx.adapter_label()
    );
    let ms = |x: f64| (x * 1e3).round() / 1e3;
    println!(
        "{}",
        serde_json::json!({
            "frame_ms_mean": ms(mean),
            "frame_ms_min": ms(min),
            "frames": times.len(),
        })
    );
    Ok(())
}

pub(super) fn pick_json(
    ctx: &GpuContext,
    volume: &Volume,
    features: Option<&FeatureTexture>,
    method: RenderMethod,
    pixel: [u32; 2],
    pick: Option<Pick>,
) -> anyhow::Result<serde_json::Value> {
    use serde_json::json;
    let Some(p) = pick else {
        return Ok(json!({ "pixel": pixel, "hit": false }));
    };
    let [i, j, k] = p.voxel;
    let mut out = json!({
        "pixel": pixel,
        "hit": true,
        "channel": p.channel.name(),
        "depth_mm": p.depth_mm,
        "lps_mm": [p.world_mm.x, p.world_mm.y, p.world_mm.z],
        "voxel": p.voxel,
        "voxel_continuous": [p.voxel_f.x, p.voxel_f.y, p.voxel_f.z],
        "intensity": volume.value_at(i, j, k),
    });
    if let Some(f) = features {
        let v = raycast::read_feature_texel_blocking(ctx, f, p.voxel)?;
        out["method"] = json!(format!("{method:?}").to_lowercase());
        out["features"] = json!({
            "vesselness": v[0],
            "airwayness": v[1],
            "blobness": v[2],
        });
        // Kept max-pooled within the GPU budget: the values are the voxel's block's maxima.
        out["feature_level"] = json!(f.level);
    }
    Ok(out)
}
