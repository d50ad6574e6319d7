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

/// A feature texture read back in slabs of whole slices (what the findings do where one buffer
/// cannot hold the volume's features: WebGPU's 256 MiB is a 512 x 512 x 256 texture) gives the
/// texels of one whole read, in order, and refuses only a slice larger than the limit.
#[test]
fn a_texture_read_in_slabs_equals_one_whole_read() {
    use shapecast::gpu::readback::{PendingSlabs, PendingTexture, ReadbackError};
    use shapecast::gpu::volume_texture::FeatureTexture;
    let Some(ctx) = shapecast::gpu::context::test_context() else {
        return;
    };
    // Odd sizes: rows padded to 256 bytes, a last slab shorter than the others.
    let dims = [70u32, 33, 29];
    let n = dims.iter().map(|&d| d as usize).product::<usize>();
    let comps: [Vec<f32>; 3] =
        std::array::from_fn(|c| (0..n).map(|i| (i * (c + 1) % 997) as f32 + 0.5).collect());
    let tex = FeatureTexture::from_components(&ctx, dims, &comps, "slabs").expect("texture");
    let whole = PendingTexture::start(&ctx, &tex.texture, dims, 4)
        .wait(&ctx)
        .expect("whole read");
    assert_eq!(whole.len(), n * 4);
    // One padded slice is 512 x 33 bytes: slabs of 4 slices, 8 of them.
    let slice = 512 * 33;
    let slabs = PendingSlabs::start(&ctx, &tex.texture, dims, 4, 4 * slice + 100).expect("slabs");
    assert_eq!(slabs.slabs(), 8);
    let read = slabs.wait(&ctx).expect("slab read");
    assert!(read == whole, "slab read differs from the whole read");
    // A limit below one slice is refused with the sizes, not read in part.
    match PendingSlabs::start(&ctx, &tex.texture, dims, 4, slice - 1) {
        Err(ReadbackError::TooLarge { bytes, max }) => {
            assert_eq!((bytes, max), (slice, slice - 1));
        }
        Err(e) => panic!("unexpected error {e}"),
        Ok(_) => panic!("a slice larger than the limit was accepted"),
    }
}
