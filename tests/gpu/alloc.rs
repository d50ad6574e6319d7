//! A texture larger than the device's memory: refused with an error that names it, not a
//! panic (wgpu-core's default handler panics on an uncaptured out-of-memory error). lavapipe
//! keeps textures in host memory and refuses an allocation larger than its heap at once, so a
//! texture of 4096^3 texels (the largest 3D texture it allows) is refused for real here.

use shapecast::gpu::alloc::{AllocCheck, Allocation};
use shapecast::gpu::context::test_context;
use shapecast::gpu::volume_texture::{FeatureTexture, RenderVolumeError};

#[test]
fn a_feature_texture_beyond_the_devices_memory_is_an_error_that_names_it() {
    let Some(ctx) = test_context() else { return };
    let side = ctx.limits.max_texture_dimension_3d.min(4096);
    // 4 bytes a texel: 275 GB at 4096^3, far beyond the host memory lavapipe allocates from.
    let dims = [side; 3];
    match FeatureTexture::new_checked(&ctx, dims, "features") {
        Err(RenderVolumeError::OutOfMemory {
            what,
            bytes,
            detail,
        }) => {
            assert_eq!(what, "features");
            assert_eq!(bytes, u64::from(side).pow(3) * 4);
            assert!(!detail.is_empty());
        }
        Err(e) => panic!("another error: {e}"),
        Ok(_) => panic!("a {side}^3 feature texture was granted on this device"),
    }
    // The device goes on: a small texture after the refusal is granted.
    let (small, mut check) =
        FeatureTexture::new_checked(&ctx, [8, 8, 8], "features").expect("a small texture");
    assert_eq!(check.poll(), Allocation::Granted);
    assert_eq!(small.dims, [8, 8, 8]);
}

#[test]
fn an_allocation_check_answers_natively_at_once() {
    let Some(ctx) = test_context() else { return };
    let (_buffer, mut check) = AllocCheck::around(&ctx, || {
        ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("alloc check"),
            size: 1 << 20,
            usage: wgpu::BufferUsages::STORAGE,
            mapped_at_creation: false,
        })
    });
    assert_eq!(check.poll(), Allocation::Granted);
}
