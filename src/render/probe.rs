//! Reading a few texels of a feature texture back for the status bar, without blocking: the
//! copy and `map_async` are started in one frame and polled in the next ones (natively `poll`
//! also drives the device without waiting; in the browser the event loop completes the mapping).
//!
//! The status bar reads the features from the GPU rather than keeping a CPU copy: the GPU
//! pipeline writes them straight into the texture (a CPU copy of every method's features would
//! cost 12 bytes per voxel per method and a full readback), and a 16-byte readback per mouse
//! move is nothing.

use crate::gpu::GpuContext;
use crate::gpu::readback::ReadbackError;
use crate::gpu::volume_texture::FeatureTexture;

/// Bytes of one `Rgba16Float` texel.
const TEXEL_BYTES: u64 = 8;

type Receiver = futures_channel::oneshot::Receiver<Result<(), wgpu::BufferAsyncError>>;

/// A readback of `(V, A, B, 0)` at a few voxels, in flight.
pub struct TexelProbe {
    staging: wgpu::Buffer,
    count: usize,
    receiver: Receiver,
}

impl TexelProbe {
    /// Copies the texels at `voxels` (clamped into the texture) and starts mapping them.
    pub fn start(ctx: &GpuContext, features: &FeatureTexture, voxels: &[[u32; 3]]) -> Self {
        let count = voxels.len().max(1);
        let size = count as u64 * TEXEL_BYTES;
        let staging = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("texel probe"),
            size,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let mut encoder = ctx
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("texel probe"),
            });
        for (n, v) in voxels.iter().enumerate() {
            let origin: [u32; 3] =
                std::array::from_fn(|a| v[a].min(features.dims[a].saturating_sub(1)));
            encoder.copy_texture_to_buffer(
                wgpu::TexelCopyTextureInfo {
                    texture: &features.texture,
                    mip_level: 0,
                    origin: wgpu::Origin3d {
                        x: origin[0],
                        y: origin[1],
                        z: origin[2],
                    },
                    aspect: wgpu::TextureAspect::All,
                },
                wgpu::TexelCopyBufferInfo {
                    buffer: &staging,
                    layout: wgpu::TexelCopyBufferLayout {
                        offset: n as u64 * TEXEL_BYTES,
                        bytes_per_row: None,
                        rows_per_image: None,
                    },
                },
                wgpu::Extent3d {
                    width: 1,
                    height: 1,
                    depth_or_array_layers: 1,
                },
            );
        }
        ctx.queue.submit([encoder.finish()]);
        let (sender, receiver) = futures_channel::oneshot::channel();
        staging.map_async(wgpu::MapMode::Read, .., move |result| {
            // The probe may have been dropped (the mouse moved on); nothing to do then.
            let _ = sender.send(result);
        });
        Self {
            staging,
            count: voxels.len(),
            receiver,
        }
    }

    /// The texels once mapped (in the order asked), `None` while the GPU is still busy.
    pub fn poll(&mut self, ctx: &GpuContext) -> Option<Result<Vec<[f32; 4]>, ReadbackError>> {
        #[cfg(not(target_arch = "wasm32"))]
        if let Err(e) = ctx.device.poll(wgpu::PollType::Poll) {
            return Some(Err(e.into()));
        }
        #[cfg(target_arch = "wasm32")]
        let _ = ctx;
        match self.receiver.try_recv() {
            Ok(None) => None,
            Ok(Some(Ok(()))) => Some(self.read()),
            Ok(Some(Err(e))) => Some(Err(e.into())),
            Err(_) => Some(Err(ReadbackError::Lost)),
        }
    }

    fn read(&self) -> Result<Vec<[f32; 4]>, ReadbackError> {
        let bytes = self
            .staging
            .slice(..)
            .get_mapped_range()
            .map_err(|e| ReadbackError::Range(e.to_string()))?
            .to_vec();
        self.staging.unmap();
        let halves: Vec<half::f16> = bytemuck::pod_collect_to_vec(&bytes);
        Ok(halves
            .chunks_exact(4)
            .take(self.count)
            .map(|t| [t[0].to_f32(), t[1].to_f32(), t[2].to_f32(), t[3].to_f32()])
            .collect())
    }

    /// Native only: waits for the texels.
    #[cfg(not(target_arch = "wasm32"))]
    pub fn wait(mut self, ctx: &GpuContext) -> Result<Vec<[f32; 4]>, ReadbackError> {
        ctx.device.poll(wgpu::PollType::wait_indefinitely())?;
        self.poll(ctx).unwrap_or(Err(ReadbackError::Lost))
    }
}
