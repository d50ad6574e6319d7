//! Packing feature blocks into a method's feature texture (shaders/pack_features.wgsl): the last
//! step of the slab pipeline, keeping the features on the GPU for rendering. The kernel encodes
//! shared-exponent texels into a staging buffer that is then copied into the texture's box; the
//! CPU twin is [`crate::gpu::volume_texture::encode_rgb9e5`], as
//! [`crate::gpu::volume_texture::FeatureTexture::from_components`] uses it.

use crate::gpu::kernel::Recorder;
use crate::gpu::kernel::{self, SlabGrid, WORKGROUP, params_buffer};
use crate::gpu::volume_texture::{
    FEATURE_TEXEL_BYTES, FeatureTexture, HISTOGRAM_BINS, histogram_quantile,
};
use crate::gpu::{GpuContext, checks, shaders};

/// Mirrors `Params` in pack_features.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
struct Params {
    dims: [u32; 3],
    z0: u32,
    src_dims: [u32; 3],
    src_y0: u32,
    y0: u32,
    pitch: u32,
    src_z0: u32,
    _pad: u32,
}
const _: () = assert!(std::mem::size_of::<Params>() == 48);

/// Mirrors `PoolParams` in pool_features.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
struct PoolParams {
    out_dims: [u32; 3],
    level: u32,
    src_dims: [u32; 3],
    src_y0: u32,
    box_y0: u32,
    box_ny: u32,
    box_z0: u32,
    box_nz: u32,
    src_z0: u32,
    out_y0: u32,
    out_z0: u32,
    pitch: u32,
    box_nx: u32,
    _pad: [u32; 3],
}
const _: () = assert!(std::mem::size_of::<PoolParams>() == 80);

/// Copies a staging box of `extent` texels (rows `row_bytes` apart, as many rows per slice as
/// the box has) into the feature texture at `origin`.
fn copy_staging(
    encoder: &mut wgpu::CommandEncoder,
    (staging, row_bytes): (&wgpu::Buffer, u32),
    dst: &FeatureTexture,
    origin: [u32; 3],
    extent: [u32; 3],
) {
    encoder.copy_buffer_to_texture(
        wgpu::TexelCopyBufferInfo {
            buffer: staging,
            layout: wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(row_bytes),
                rows_per_image: Some(extent[1]),
            },
        },
        wgpu::TexelCopyTextureInfo {
            texture: &dst.texture,
            mip_level: 0,
            origin: wgpu::Origin3d {
                x: origin[0],
                y: origin[1],
                z: origin[2],
            },
            aspect: wgpu::TextureAspect::All,
        },
        wgpu::Extent3d {
            width: extent[0],
            height: extent[1],
            depth_or_array_layers: extent[2],
        },
    );
}

/// One dispatch of a pooled pack: the box's slices `slices` (box-relative), written as the
/// pooled slices `out_z0 .. out_z0 + pnz`.
#[derive(Clone, Debug, PartialEq, Eq)]
struct PooledChunk {
    slices: std::ops::Range<u32>,
    out_z0: u32,
    pnz: u32,
}

/// The chunks of a box at voxel slice `z0` whose slices `slices` go into level `level`, each
/// writing at most `per_chunk` pooled slices: chunks end on a block's edge where the slices
/// allow, so that consecutive chunks share at most the pooled slice of a block they cut.
fn pooled_chunks(
    z0: u32,
    slices: std::ops::Range<u32>,
    level: u32,
    per_chunk: u32,
) -> impl Iterator<Item = PooledChunk> {
    let f = 1u32 << level.min(31);
    let voxels = per_chunk.max(1).saturating_mul(f);
    let mut s0 = slices.start;
    std::iter::from_fn(move || {
        if s0 >= slices.end {
            return None;
        }
        let z = z0 + s0;
        let end = ((z.saturating_add(voxels)) / f * f).max(z + 1) - z0;
        let s1 = end.min(slices.end);
        let out_z0 = z >> level;
        let pnz = (z0 + s1 - 1) / f + 1 - out_z0;
        let chunk = PooledChunk {
            slices: s0..s1,
            out_z0,
            pnz,
        };
        s0 = s1;
        Some(chunk)
    })
}

/// Where a packed box comes from and goes to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PackBox {
    /// The source block (3 components of these dims, component-major).
    pub src_dims: [u32; 3],
    /// First source row of the box.
    pub src_y0: u32,
    /// Rows of the box (all of `src_dims`'s x and z).
    pub ny: u32,
    /// Texel of the box's first voxel: (0, y0, z0).
    pub y0: u32,
    pub z0: u32,
}

impl PackBox {
    /// A whole block into slices `z0..` of the texture.
    pub fn slices(dims: [u32; 3], z0: u32) -> Self {
        Self {
            src_dims: dims,
            src_y0: 0,
            ny: dims[1],
            y0: 0,
            z0,
        }
    }
}

/// The pack pipeline and the running maxima of the features it packed.
pub struct Pack {
    pipeline: wgpu::ComputePipeline,
    /// Into a max-pooled level (pool_features.wgsl).
    pool: wgpu::ComputePipeline,
    /// Three u32 (float bits of the non-negative maxima), `COPY_SRC` for readback.
    pub maxima: wgpu::Buffer,
    /// The staging buffer, kept and reused by every chunk (grown when a box needs more) instead
    /// of one made per paced step (thousands of steps in a whole-body job).
    staging: std::sync::Mutex<Option<wgpu::Buffer>>,
}

impl Pack {
    pub fn new(ctx: &GpuContext) -> Result<Self, shaders::ShaderSourceError> {
        let module = shaders::create_module(&ctx.device, "pack_features.wgsl")?;
        let pipeline = checks::labelled_pipeline(ctx, "pack_features", &module, "main");
        let pool_module = shaders::create_module(&ctx.device, "pool_features.wgsl")?;
        let pool = checks::labelled_pipeline(ctx, "pool_features", &pool_module, "pool");
        let maxima = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("feature maxima and histograms"),
            size: Self::MAXIMA_BYTES,
            usage: wgpu::BufferUsages::STORAGE
                | wgpu::BufferUsages::COPY_SRC
                | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        Ok(Self {
            pipeline,
            pool,
            maxima,
            staging: std::sync::Mutex::new(None),
        })
    }

    /// Records: the box `at` of the block `src` (3 components, component-major) into `dst`.
    pub fn record(
        &self,
        rec: &mut Recorder<'_>,
        src: &wgpu::Buffer,
        dst: &FeatureTexture,
        at: PackBox,
    ) {
        self.record_slices(rec, src, dst, at, 0..at.src_dims[2]);
    }

    /// [`Self::record`] for the box's slices `slices` only (the feature job's paced steps):
    /// every texel and every count of the maxima and histograms is the same however the box
    /// is cut (maxima and counts are order-free atomics).
    pub fn record_slices(
        &self,
        rec: &mut Recorder<'_>,
        src: &wgpu::Buffer,
        dst: &FeatureTexture,
        at: PackBox,
        slices: std::ops::Range<u32>,
    ) {
        if dst.level > 0 {
            self.record_pooled_slices(rec, src, dst, at, slices);
            return;
        }
        let [nx, ny] = [at.src_dims[0], at.ny];
        let nz = slices.end.min(at.src_dims[2]);
        // Copies into a texture take rows of a multiple of 256 bytes; the staging buffer of one
        // chunk of slices stays within one storage binding.
        let row_bytes =
            (nx * FEATURE_TEXEL_BYTES).next_multiple_of(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT);
        let pitch = row_bytes / FEATURE_TEXEL_BYTES;
        let limit = rec
            .ctx
            .limits
            .max_storage_buffer_binding_size
            .min(rec.ctx.limits.max_buffer_size);
        let slice_bytes = u64::from(row_bytes) * u64::from(ny);
        let chunk = (limit / slice_bytes.max(1)).clamp(1, u64::from(nz.max(1))) as u32;
        // One staging buffer for the whole box's chunks (wgpu orders the copy before the next
        // chunk's writes), sized for the largest chunk a box of this size can take.
        let box_chunk = (limit / slice_bytes.max(1)).clamp(1, u64::from(at.src_dims[2].max(1)));
        // Kept only within the binding limit (a slice larger than it is the only one refused).
        let staging = self.staging(rec.ctx, (slice_bytes * box_chunk).max(4), limit);
        let mut src_z0 = slices.start;
        while src_z0 < nz {
            let dims = [nx, ny, chunk.min(nz - src_z0)];
            // Slices src_z0.. of the box: encoded into the staging buffer, then copied.
            self.record_chunk(
                rec.ctx,
                rec.encoder,
                (src, at),
                dst,
                &staging,
                (dims, src_z0, pitch),
            );
            src_z0 += dims[2];
        }
    }

    /// [`Self::record_slices`] into a max-pooled level: each chunk of the box's slices becomes
    /// the pooled texels its voxels fall in, each the maximum of its block's voxels in the
    /// chunk and of what the texture holds already (blocks that the box's or the chunk's edges
    /// cut are finished by the next one). The box spans whole rows along x.
    fn record_pooled_slices(
        &self,
        rec: &mut Recorder<'_>,
        src: &wgpu::Buffer,
        dst: &FeatureTexture,
        at: PackBox,
        slices: std::ops::Range<u32>,
    ) {
        let level = dst.level;
        let f = dst.block();
        let nx = at.src_dims[0];
        let nz = slices.end.min(at.src_dims[2]);
        if nz <= slices.start || at.ny == 0 || nx == 0 {
            return;
        }
        let pnx = nx.div_ceil(f);
        let out_y0 = at.y0 >> level;
        let pny = (at.y0 + at.ny - 1) / f + 1 - out_y0;
        let row_bytes =
            (pnx * FEATURE_TEXEL_BYTES).next_multiple_of(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT);
        let pitch = row_bytes / FEATURE_TEXEL_BYTES;
        let limit = rec
            .ctx
            .limits
            .max_storage_buffer_binding_size
            .min(rec.ctx.limits.max_buffer_size);
        let pooled_slice_bytes = u64::from(row_bytes) * u64::from(pny);
        // Pooled slices per chunk: a chunk ends on a block's edge (or after one voxel slice),
        // so it writes at most this many.
        let pooled_per_chunk = (limit / pooled_slice_bytes.max(1)).clamp(1, 1 << 15) as u32;
        let staging = self.staging(
            rec.ctx,
            (pooled_slice_bytes * u64::from(pooled_per_chunk)).max(4),
            limit,
        );
        for chunk in pooled_chunks(at.z0, slices.start..nz, level, pooled_per_chunk) {
            let PooledChunk {
                slices: std::ops::Range { start: s0, end: s1 },
                out_z0,
                pnz,
            } = chunk;
            let box_z0 = at.z0 + s0;
            let box_nz = s1 - s0;
            let out_dims = [pnx, pny, pnz];
            let params = params_buffer(
                &rec.ctx.device,
                "pool params",
                &PoolParams {
                    out_dims,
                    level,
                    src_dims: at.src_dims,
                    src_y0: at.src_y0,
                    box_y0: at.y0,
                    box_ny: at.ny,
                    box_z0,
                    box_nz,
                    src_z0: s0,
                    out_y0,
                    out_z0,
                    pitch,
                    box_nx: nx,
                    _pad: [0; 3],
                },
            );
            let bind = kernel::bind_group(
                &rec.ctx.device,
                "pool",
                &self.pool,
                [
                    params.as_entire_binding(),
                    src.as_entire_binding(),
                    staging.as_entire_binding(),
                    self.maxima.as_entire_binding(),
                    wgpu::BindingResource::TextureView(&dst.view),
                ],
            );
            let groups = SlabGrid::new(out_dims, [1.0; 3]).workgroups(WORKGROUP);
            checks::dispatch(rec.encoder, "pool", &self.pool, &bind, groups);
            copy_staging(
                rec.encoder,
                (&staging, row_bytes),
                dst,
                [0, out_y0, out_z0],
                out_dims,
            );
        }
    }

    /// The kept staging buffer, at least `bytes` long (one longer than `limit` is made for this
    /// use and not kept).
    fn staging(&self, ctx: &GpuContext, bytes: u64, limit: u64) -> wgpu::Buffer {
        let mut kept = self
            .staging
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        match kept.as_ref() {
            Some(b) if b.size() >= bytes => b.clone(),
            _ => {
                let b = ctx.device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some("pack staging"),
                    size: bytes,
                    usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
                    mapped_at_creation: false,
                });
                if bytes <= limit {
                    *kept = Some(b.clone());
                }
                b
            }
        }
    }

    fn record_chunk(
        &self,
        ctx: &GpuContext,
        encoder: &mut wgpu::CommandEncoder,
        (src, at): (&wgpu::Buffer, PackBox),
        dst: &FeatureTexture,
        staging: &wgpu::Buffer,
        (dims, src_z0, pitch): ([u32; 3], u32, u32),
    ) {
        let block = SlabGrid::new(dims, [1.0; 3]);
        let [nx, ny, nz] = dims;
        let row_bytes = pitch * FEATURE_TEXEL_BYTES;
        let params = params_buffer(
            &ctx.device,
            "pack params",
            &Params {
                dims,
                z0: at.z0 + src_z0,
                src_dims: at.src_dims,
                src_y0: at.src_y0,
                y0: at.y0,
                pitch,
                src_z0,
                _pad: 0,
            },
        );
        let bind = kernel::bind_group(
            &ctx.device,
            "pack",
            &self.pipeline,
            [
                params.as_entire_binding(),
                src.as_entire_binding(),
                staging.as_entire_binding(),
                self.maxima.as_entire_binding(),
            ],
        );
        let groups = block.workgroups(WORKGROUP);
        checks::dispatch(encoder, "pack", &self.pipeline, &bind, groups);
        copy_staging(
            encoder,
            (staging, row_bytes),
            dst,
            [0, at.y0, at.z0 + src_z0],
            [nx, ny, nz],
        );
    }

    /// Bytes of [`Pack::maxima`]: three maxima, a pad, three histograms.
    pub const MAXIMA_BYTES: u64 = 4 * (4 + 3 * HISTOGRAM_BINS as u64);

    /// The 99.9th percentile of each component's positive values from a readback of
    /// [`Pack::maxima`], clamped to its maximum.
    pub fn decode_p999(bytes: &[u8], max: [f32; 3]) -> [f32; 3] {
        let words: Vec<u32> = bytes
            .chunks_exact(4)
            .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .collect();
        std::array::from_fn(|c| {
            let start = 4 + c * HISTOGRAM_BINS;
            words
                .get(start..start + HISTOGRAM_BINS)
                .map_or(0.0, |h| histogram_quantile(h, 0.999, max[c]))
        })
    }

    /// The maxima from the bytes of a readback of [`Pack::maxima`].
    pub fn decode_maxima(bytes: &[u8]) -> [f32; 3] {
        std::array::from_fn(|c| {
            bytes
                .get(4 * c..4 * c + 4)
                .map_or(0.0, |b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every slice in one chunk, in order; no chunk writes more pooled slices than it may; the
    /// pooled slices are those the box's voxels fall in, shared only where a block is cut.
    #[test]
    fn pooled_chunks_cover_the_slices_within_their_size() {
        for level in 1..=3u32 {
            let f = 1u32 << level;
            for z0 in [0u32, 1, 5, 8] {
                for (start, end) in [(0u32, 1u32), (0, 37), (3, 29), (7, 8)] {
                    for per in [1u32, 2, 5, 100] {
                        let chunks: Vec<PooledChunk> =
                            pooled_chunks(z0, start..end, level, per).collect();
                        let mut next = start;
                        for c in &chunks {
                            assert_eq!(c.slices.start, next);
                            assert!(c.slices.end > c.slices.start);
                            assert!(c.pnz <= per, "{c:?} over {per}");
                            assert_eq!(c.out_z0, (z0 + c.slices.start) / f);
                            assert_eq!(c.out_z0 + c.pnz, (z0 + c.slices.end - 1) / f + 1);
                            next = c.slices.end;
                        }
                        assert_eq!(next, end);
                        if per >= 100 {
                            assert_eq!(chunks.len(), 1);
                        }
                    }
                }
            }
        }
    }
}
