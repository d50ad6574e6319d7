//! A volume's physical values on the GPU as an f32 storage buffer, uploaded chunk by chunk so that
//! the CPU never holds a second full-size f32 copy.

use crate::gpu::GpuContext;
use crate::volume::Volume;

/// Why a volume could not be put on the GPU.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum UploadError {
    #[error(
        "the volume ({nx}x{ny}x{nz} voxels, {bytes} bytes as f32) is larger than this GPU allows in one buffer ({limit} bytes)"
    )]
    TooLarge {
        nx: usize,
        ny: usize,
        nz: usize,
        bytes: u64,
        limit: u64,
    },
    #[error("the volume is empty ({nx}x{ny}x{nz} voxels)")]
    Empty { nx: usize, ny: usize, nz: usize },
}

/// A volume's values (f32, physical units) in a storage buffer.
pub struct GpuVolume {
    pub buffer: wgpu::Buffer,
    pub dims: [u32; 3],
    pub spacing_mm: [f32; 3],
}

/// Voxels converted to f32 per upload chunk (16 MiB of f32).
const CHUNK_VOXELS: usize = 4 << 20;

impl GpuVolume {
    /// The size in bytes a volume needs on the GPU, checked against the device's limits.
    pub fn check_fits(ctx: &GpuContext, volume: &Volume) -> Result<u64, UploadError> {
        let [nx, ny, nz] = volume.dims;
        if volume.voxel_count() == 0 {
            return Err(UploadError::Empty { nx, ny, nz });
        }
        let bytes = volume.voxel_count() as u64 * 4;
        let limit = ctx
            .limits
            .max_buffer_size
            .min(ctx.limits.max_storage_buffer_binding_size);
        let dims_fit = [nx, ny, nz].iter().all(|&d| u32::try_from(d).is_ok());
        if bytes > limit || !dims_fit {
            return Err(UploadError::TooLarge {
                nx,
                ny,
                nz,
                bytes,
                limit,
            });
        }
        Ok(bytes)
    }

    pub fn upload(ctx: &GpuContext, volume: &Volume) -> Result<Self, UploadError> {
        let bytes = Self::check_fits(ctx, volume)?;
        let buffer = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("volume values"),
            size: bytes,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let n = volume.voxel_count();
        let mut chunk = vec![0f32; CHUNK_VOXELS.min(n)];
        let mut start = 0;
        while start < n {
            let len = CHUNK_VOXELS.min(n - start);
            volume.values_into(start, &mut chunk[..len]);
            ctx.queue.write_buffer(
                &buffer,
                start as u64 * 4,
                bytemuck::cast_slice(&chunk[..len]),
            );
            start += len;
        }
        let to_u32 = |d: usize| u32::try_from(d).unwrap_or(u32::MAX);
        Ok(Self {
            buffer,
            dims: volume.dims.map(to_u32),
            spacing_mm: volume.spacing_mm.map(|s| s as f32),
        })
    }
}
