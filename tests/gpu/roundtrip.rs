//! The test adapter (lavapipe in CI): the context asks for the adapter's real limits, and a
//! volume too large for the device is refused with a message naming its size.

use shapecast::gpu::context::test_context;
use shapecast::gpu::volume_texture::check_dims;

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
    // A size beyond any 3D texture limit, checked without allocating it.
    let err = check_dims(&ctx, [1 << 13, 1 << 13, 1 << 13]).expect_err("must not fit");
    let message = err.to_string();
    assert!(message.contains("8192"), "{message}");
}
