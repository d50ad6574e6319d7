//! Reading a few texels of a feature texture back for the status bar, without blocking: the
//! copy and `map_async` are started in one frame and polled in the next ones (natively `poll`
//! also drives the device without waiting; in the browser the event loop completes the mapping).
//!
//! The status bar reads the features from the GPU rather than keeping a CPU copy: the GPU
//! pipeline writes them straight into the texture (a CPU copy of every method's features would
//! cost 12 bytes per voxel per method and a full readback), and a 16-byte readback per mouse
//! move is nothing.

use crate::gpu::GpuContext;
use crate::gpu::readback::{PendingRead, ReadbackError, copy_texel};
use crate::gpu::volume_texture::{FEATURE_TEXEL_BYTES, FeatureTexture, decode_feature_texels};

/// Bytes of one feature texel.
const TEXEL_BYTES: u64 = FEATURE_TEXEL_BYTES as u64;

/// A readback of `(V, A, B, 0)` at a few voxels, in flight.
pub struct TexelProbe {
    read: PendingRead,
    count: usize,
}

impl TexelProbe {
    /// Copies the texels at `voxels` (clamped into the volume; at a max-pooled level the
    /// texels of their blocks) and starts mapping them.
    pub fn start(ctx: &GpuContext, features: &FeatureTexture, voxels: &[[u32; 3]]) -> Self {
        let size = voxels.len().max(1) as u64 * TEXEL_BYTES;
        let read = PendingRead::start_with(ctx, size, "texel probe", |encoder, staging| {
            for (n, v) in voxels.iter().enumerate() {
                // The texel of the voxel (at a pooled level, its block's maximum).
                let origin = features.texel_of(*v);
                copy_texel(
                    encoder,
                    &features.texture,
                    origin,
                    staging,
                    n as u64 * TEXEL_BYTES,
                );
            }
        });
        Self {
            read,
            count: voxels.len(),
        }
    }

    /// The texels once mapped (in the order asked), `None` while the GPU is still busy.
    pub fn poll(&mut self, ctx: &GpuContext) -> Option<Result<Vec<[f32; 4]>, ReadbackError>> {
        let count = self.count;
        self.read
            .poll(ctx)
            .map(|bytes| bytes.map(|b| decode(&b, count)))
    }

    /// The texels, awaited (works on wasm; natively something must poll the device).
    pub async fn finish(self) -> Result<Vec<[f32; 4]>, ReadbackError> {
        let count = self.count;
        self.read.finish().await.map(|b| decode(&b, count))
    }

    /// Native only: waits for the texels.
    #[cfg(not(target_arch = "wasm32"))]
    pub fn wait(self, ctx: &GpuContext) -> Result<Vec<[f32; 4]>, ReadbackError> {
        let count = self.count;
        self.read.wait(ctx).map(|b| decode(&b, count))
    }
}

/// The first `count` feature texels `(V, A, B, 0)` of `bytes` as f32.
fn decode(bytes: &[u8], count: usize) -> Vec<[f32; 4]> {
    decode_feature_texels(bytes).take(count).collect()
}
