//! A compute round trip on the test adapter (lavapipe in CI): upload a volume, run the axis MIP
//! kernel, read it back and compare with its CPU twin; and check the context asked for the
//! adapter's real limits.

use shapecast::gpu::axis_mip::{AxisMip, cpu_twin};
use shapecast::gpu::readback::read_f32_blocking;
use shapecast::gpu::{GpuVolume, context::test_context};
use shapecast::volume::Volume;

/// A volume whose size is not a multiple of the 8x8 workgroup, with distinct values everywhere.
fn test_volume() -> Volume {
    let dims = [13, 7, 11];
    let values = (0..dims[0] * dims[1] * dims[2])
        .map(|n| ((n * 7919) % 1000) as f32 - 500.0)
        .collect();
    Volume::from_f32(dims, [0.5, 0.7, 2.5], values)
}

#[test]
fn axis_mip_matches_cpu_twin() {
    let Some(ctx) = test_context() else { return };
    eprintln!("adapter: {}", ctx.adapter_label());
    let volume = test_volume();
    let gpu_volume = GpuVolume::upload(&ctx, &volume).expect("upload");
    let kernel = AxisMip::new(&ctx).expect("shader");
    let values = volume.to_f32();
    for axis in 0..3 {
        let out = kernel.run(&ctx, &gpu_volume, axis, (-500.0, 500.0));
        let n = (out.size[0] * out.size[1]) as usize;
        let gpu = read_f32_blocking(&ctx, &out.mip, n).expect("readback");
        let cpu = cpu_twin(&values, volume.dims, axis);
        assert_eq!(gpu, cpu, "axis {axis}: GPU and CPU MIPs differ");
    }
}

#[test]
fn context_uses_adapter_limits() {
    let Some(ctx) = test_context() else { return };
    let defaults = wgpu::Limits::default();
    eprintln!("{}", ctx.describe());
    // lavapipe offers far more than wgpu's defaults (2048 for 3D textures, 128 MiB buffers).
    assert!(ctx.limits.max_texture_dimension_3d >= defaults.max_texture_dimension_3d);
    assert!(ctx.limits.max_buffer_size >= defaults.max_buffer_size);
    if ctx.adapter_info.device_type == wgpu::DeviceType::Cpu {
        assert!(
            ctx.limits.max_texture_dimension_3d >= 4096,
            "{}",
            ctx.describe()
        );
        assert!(
            ctx.limits.max_buffer_size >= (1 << 31) - 1,
            "{}",
            ctx.describe()
        );
        assert!(
            ctx.float32_filterable(),
            "lavapipe offers FLOAT32_FILTERABLE"
        );
    }
}

#[test]
fn too_large_volume_is_refused_with_a_message() {
    let Some(ctx) = test_context() else { return };
    let mut volume = test_volume();
    // Claim a size beyond any buffer limit without allocating it.
    volume.dims = [1 << 12, 1 << 12, 1 << 12];
    let err = GpuVolume::check_fits(&ctx, &volume).expect_err("must not fit");
    let message = err.to_string();
    assert!(message.contains("4096x4096x4096"), "{message}");
}
