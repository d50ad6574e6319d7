//! Reading GPU buffers back to the CPU, for export and tests only (rendering keeps data on the
//! GPU). Uses `map_async`; only native code may block on the device, never wasm.

use crate::gpu::GpuContext;

/// Why a readback failed.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ReadbackError {
    #[error("mapping the GPU buffer for reading failed: {0}")]
    Map(#[from] wgpu::BufferAsyncError),
    #[error("the GPU device was lost before the readback finished")]
    Lost,
    #[error("the mapped GPU buffer could not be read: {0}")]
    Range(String),
    #[error("waiting for the GPU failed: {0}")]
    Poll(#[from] wgpu::PollError),
    #[error("{bytes} bytes to read back, more than one buffer of this device holds ({max} bytes)")]
    TooLarge { bytes: u64, max: u64 },
    #[error("{bytes} bytes to read back, more than this tab or process could reserve")]
    OutOfMemory { bytes: u64 },
}

/// Copies `size` bytes of `src` into a staging buffer and returns them once mapped.
///
/// Native callers may drive it with [`read_bytes_blocking`]; on wasm, await it (the browser's
/// event loop completes the mapping).
pub async fn read_bytes(
    ctx: &GpuContext,
    src: &wgpu::Buffer,
    size: u64,
) -> Result<Vec<u8>, ReadbackError> {
    PendingRead::start(ctx, src, size).finish().await
}

fn start_read(
    ctx: &GpuContext,
    src: &wgpu::Buffer,
    size: u64,
) -> (
    wgpu::Buffer,
    futures_channel::oneshot::Receiver<Result<(), wgpu::BufferAsyncError>>,
) {
    start_copies(ctx, size, "readback", |encoder, staging| {
        encoder.copy_buffer_to_buffer(src, 0, staging, 0, size);
    })
}

/// A staging buffer of `size` bytes that `record` fills (copies from buffers or textures),
/// submitted, and mapped once the GPU is done: the one way anything is read back.
fn start_copies(
    ctx: &GpuContext,
    size: u64,
    label: &str,
    record: impl FnOnce(&mut wgpu::CommandEncoder, &wgpu::Buffer),
) -> (
    wgpu::Buffer,
    futures_channel::oneshot::Receiver<Result<(), wgpu::BufferAsyncError>>,
) {
    let staging = ctx.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size,
        usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    let mut encoder = ctx
        .device
        .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some(label) });
    record(&mut encoder, &staging);
    ctx.queue.submit([encoder.finish()]);
    let (sender, receiver) = futures_channel::oneshot::channel();
    staging.map_async(wgpu::MapMode::Read, .., move |result| {
        // The receiver may have been dropped (cancelled readback); nothing to do then.
        let _ = sender.send(result);
    });
    (staging, receiver)
}

/// Records the copy of one texel of `texture` (3D, or 2D with `texel[2] == 0`) to `offset` in
/// `dst`.
pub fn copy_texel(
    encoder: &mut wgpu::CommandEncoder,
    texture: &wgpu::Texture,
    texel: [u32; 3],
    dst: &wgpu::Buffer,
    offset: u64,
) {
    encoder.copy_texture_to_buffer(
        wgpu::TexelCopyTextureInfo {
            texture,
            mip_level: 0,
            origin: wgpu::Origin3d {
                x: texel[0],
                y: texel[1],
                z: texel[2],
            },
            aspect: wgpu::TextureAspect::All,
        },
        wgpu::TexelCopyBufferInfo {
            buffer: dst,
            layout: wgpu::TexelCopyBufferLayout {
                offset,
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

fn finish_read(staging: &wgpu::Buffer, size: u64) -> Result<Vec<u8>, ReadbackError> {
    let bytes = staging
        .slice(..size)
        .get_mapped_range()
        .map_err(|e| ReadbackError::Range(e.to_string()))?
        .to_vec();
    staging.unmap();
    Ok(bytes)
}

/// Native only: the mapping's result once the device has been polled to idle. When several
/// threads share the device (the tests), another thread's poll may have taken this mapping's
/// callback and not run it yet, so the result can arrive just after our poll returns: block on
/// it (a dropped sender means the device was lost).
#[cfg(not(target_arch = "wasm32"))]
fn wait_mapped(
    receiver: futures_channel::oneshot::Receiver<Result<(), wgpu::BufferAsyncError>>,
) -> Result<(), ReadbackError> {
    Ok(pollster::block_on(receiver).map_err(|_| ReadbackError::Lost)??)
}

/// Native only: reads a buffer back, blocking until the GPU is done.
#[cfg(not(target_arch = "wasm32"))]
pub fn read_bytes_blocking(
    ctx: &GpuContext,
    src: &wgpu::Buffer,
    size: u64,
) -> Result<Vec<u8>, ReadbackError> {
    let (staging, receiver) = start_read(ctx, src, size);
    ctx.device.poll(wgpu::PollType::wait_indefinitely())?;
    wait_mapped(receiver)?;
    finish_read(&staging, size)
}

/// Native only: the texels of `texture` (a box of `size` from its origin, `bytes_per_texel`
/// each) as tightly packed rows, x fastest, blocking.
#[cfg(not(target_arch = "wasm32"))]
pub fn read_texture_blocking(
    ctx: &GpuContext,
    texture: &wgpu::Texture,
    size: [u32; 3],
    bytes_per_texel: u32,
) -> Result<Vec<u8>, ReadbackError> {
    PendingTexture::start(ctx, texture, size, bytes_per_texel).wait(ctx)
}

/// The texels of a texture being read back (a box of `size` from its origin), polled per
/// frame like [`PendingRead`]. Rows are copied at wgpu's 256-byte row alignment and unpadded
/// when they arrive: the result is tightly packed rows, x fastest.
pub struct PendingTexture {
    read: PendingRead,
    /// Bytes of one row as wanted, and as copied (padded).
    row: usize,
    padded: usize,
    rows: usize,
}

impl PendingTexture {
    /// Records and submits the copy of `size` texels of `texture` (which needs `COPY_SRC`),
    /// `bytes_per_texel` each, and starts mapping them.
    pub fn start(
        ctx: &GpuContext,
        texture: &wgpu::Texture,
        size: [u32; 3],
        bytes_per_texel: u32,
    ) -> Self {
        Self::start_at(ctx, texture, 0, size, bytes_per_texel)
    }

    /// [`Self::start`] for the box of `size` whose first slice is `z0`.
    pub fn start_at(
        ctx: &GpuContext,
        texture: &wgpu::Texture,
        z0: u32,
        size: [u32; 3],
        bytes_per_texel: u32,
    ) -> Self {
        let [w, h, d] = size;
        let row = w * bytes_per_texel;
        let padded =
            row.div_ceil(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT) * wgpu::COPY_BYTES_PER_ROW_ALIGNMENT;
        let bytes = u64::from(padded) * u64::from(h) * u64::from(d);
        let read =
            PendingRead::start_with(ctx, bytes.max(4), "texture readback", |encoder, staging| {
                encoder.copy_texture_to_buffer(
                    wgpu::TexelCopyTextureInfo {
                        origin: wgpu::Origin3d { x: 0, y: 0, z: z0 },
                        ..texture.as_image_copy()
                    },
                    wgpu::TexelCopyBufferInfo {
                        buffer: staging,
                        layout: wgpu::TexelCopyBufferLayout {
                            offset: 0,
                            bytes_per_row: Some(padded),
                            rows_per_image: Some(h),
                        },
                    },
                    wgpu::Extent3d {
                        width: w,
                        height: h,
                        depth_or_array_layers: d,
                    },
                );
            });
        Self {
            read,
            row: row as usize,
            padded: padded.max(1) as usize,
            rows: h as usize * d as usize,
        }
    }

    /// The texels once mapped, `None` while the GPU is still busy (never blocks).
    pub fn poll(&mut self, ctx: &GpuContext) -> Option<Result<Vec<u8>, ReadbackError>> {
        let bytes = self.read.poll(ctx)?;
        Some(bytes.map(|b| self.unpad(&b)))
    }

    /// Native only: waits for the texels.
    #[cfg(not(target_arch = "wasm32"))]
    pub fn wait(self, ctx: &GpuContext) -> Result<Vec<u8>, ReadbackError> {
        let (row, padded, rows) = (self.row, self.padded, self.rows);
        let bytes = self.read.wait(ctx)?;
        Ok(unpad(&bytes, row, padded, rows))
    }

    fn unpad(&self, bytes: &[u8]) -> Vec<u8> {
        unpad(bytes, self.row, self.padded, self.rows)
    }
}

/// A texture read back in slabs of whole slices, each copy within `max_bytes` (a volume's
/// features may exceed one buffer of the device: WebGPU's default 256 MiB is a 512 x 512 x 256
/// Rgb9e5 texture): one slab in flight at a time, polled per frame, the texels gathered into one
/// tightly packed array (x fastest) as they arrive.
pub struct PendingSlabs {
    texture: wgpu::Texture,
    size: [u32; 3],
    bytes_per_texel: u32,
    /// Slices per slab.
    slab: u32,
    /// The first slice not yet asked for.
    next_z: u32,
    current: Option<PendingTexture>,
    out: Vec<u8>,
}

impl PendingSlabs {
    /// Starts reading `size` texels of `texture` (which needs `COPY_SRC`) from its origin,
    /// `bytes_per_texel` each, in slabs of at most `max_bytes` (and the device's buffer limit).
    /// [`ReadbackError::TooLarge`] when one slice does not fit.
    pub fn start(
        ctx: &GpuContext,
        texture: &wgpu::Texture,
        size: [u32; 3],
        bytes_per_texel: u32,
        max_bytes: u64,
    ) -> Result<Self, ReadbackError> {
        let [w, h, d] = size;
        let slice = (padded_row_bytes(w, bytes_per_texel) * u64::from(h)).max(1);
        let max = max_bytes.min(ctx.limits.max_buffer_size);
        if slice > max {
            return Err(ReadbackError::TooLarge { bytes: slice, max });
        }
        let slab = (max / slice).clamp(1, u64::from(d.max(1))) as u32;
        let total = u64::from(w) * u64::from(h) * u64::from(d) * u64::from(bytes_per_texel);
        // Reserved once, and refused with a message where the tab (wasm32: 4 GiB of address
        // space) or the process cannot hold it, instead of aborting on a failed allocation.
        let mut out = Vec::new();
        usize::try_from(total)
            .ok()
            .and_then(|n| out.try_reserve_exact(n).ok())
            .ok_or(ReadbackError::OutOfMemory { bytes: total })?;
        let mut this = Self {
            texture: texture.clone(),
            size,
            bytes_per_texel,
            slab,
            next_z: 0,
            current: None,
            out,
        };
        this.start_next(ctx);
        Ok(this)
    }

    /// Slabs the whole read takes.
    pub fn slabs(&self) -> u32 {
        self.size[2].div_ceil(self.slab.max(1))
    }

    fn start_next(&mut self, ctx: &GpuContext) {
        let [w, h, d] = self.size;
        if self.next_z >= d {
            return;
        }
        let n = self.slab.min(d - self.next_z);
        self.current = Some(PendingTexture::start_at(
            ctx,
            &self.texture,
            self.next_z,
            [w, h, n],
            self.bytes_per_texel,
        ));
        self.next_z += n;
    }

    /// All the texels once every slab arrived; `None` while one is in flight (never blocks).
    /// A slab that arrived starts the next.
    pub fn poll(&mut self, ctx: &GpuContext) -> Option<Result<Vec<u8>, ReadbackError>> {
        let Some(current) = self.current.as_mut() else {
            // Nothing in flight: every slab arrived (or the texture has no slices).
            return Some(Ok(std::mem::take(&mut self.out)));
        };
        let bytes = current.poll(ctx)?;
        self.current = None;
        match bytes {
            Ok(b) => self.out.extend_from_slice(&b),
            Err(e) => return Some(Err(e)),
        }
        if self.next_z < self.size[2] {
            self.start_next(ctx);
            return None;
        }
        Some(Ok(std::mem::take(&mut self.out)))
    }

    /// Native only: waits for every slab.
    #[cfg(not(target_arch = "wasm32"))]
    pub fn wait(mut self, ctx: &GpuContext) -> Result<Vec<u8>, ReadbackError> {
        loop {
            if let Some(done) = self.poll(ctx) {
                return done;
            }
            ctx.device.poll(wgpu::PollType::wait_indefinitely())?;
        }
    }
}

/// Bytes of one row of `w` texels as a texture copy lays it out (wgpu's 256-byte alignment).
fn padded_row_bytes(w: u32, bytes_per_texel: u32) -> u64 {
    (u64::from(w) * u64::from(bytes_per_texel))
        .div_ceil(u64::from(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT))
        * u64::from(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT)
}

/// The first `row` bytes of each of the first `rows` rows of `padded` bytes.
fn unpad(bytes: &[u8], row: usize, padded: usize, rows: usize) -> Vec<u8> {
    bytes
        .chunks(padded)
        .take(rows)
        .flat_map(|r| &r[..row.min(r.len())])
        .copied()
        .collect()
}

/// Native only: reads an f32 buffer back, blocking.
#[cfg(not(target_arch = "wasm32"))]
pub fn read_f32_blocking(
    ctx: &GpuContext,
    src: &wgpu::Buffer,
    count: usize,
) -> Result<Vec<f32>, ReadbackError> {
    let bytes = read_bytes_blocking(ctx, src, count as u64 * 4)?;
    Ok(bytemuck::pod_collect_to_vec(&bytes))
}

/// A readback in flight, polled without blocking: what a step-by-step job (one step per frame)
/// uses on every platform. Natively `poll` also drives the device; in the browser the event loop
/// completes the mapping between frames.
pub struct PendingRead {
    staging: wgpu::Buffer,
    size: u64,
    receiver: futures_channel::oneshot::Receiver<Result<(), wgpu::BufferAsyncError>>,
}

impl PendingRead {
    /// Copies `size` bytes of `src` (which needs `COPY_SRC`) and starts mapping them.
    pub fn start(ctx: &GpuContext, src: &wgpu::Buffer, size: u64) -> Self {
        let (staging, receiver) = start_read(ctx, src, size);
        Self {
            staging,
            size,
            receiver,
        }
    }

    /// `size` bytes that `record` copies into the staging buffer it is given (e.g. texels of a
    /// texture), then mapped.
    pub fn start_with(
        ctx: &GpuContext,
        size: u64,
        label: &str,
        record: impl FnOnce(&mut wgpu::CommandEncoder, &wgpu::Buffer),
    ) -> Self {
        let (staging, receiver) = start_copies(ctx, size, label, record);
        Self {
            staging,
            size,
            receiver,
        }
    }

    /// The bytes once mapped, `None` while the GPU is still busy.
    pub fn poll(&mut self, ctx: &GpuContext) -> Option<Result<Vec<u8>, ReadbackError>> {
        #[cfg(not(target_arch = "wasm32"))]
        if let Err(e) = ctx.device.poll(wgpu::PollType::Poll) {
            return Some(Err(e.into()));
        }
        #[cfg(target_arch = "wasm32")]
        let _ = ctx;
        match self.receiver.try_recv() {
            Ok(None) => None,
            Ok(Some(Ok(()))) => Some(finish_read(&self.staging, self.size)),
            Ok(Some(Err(e))) => Some(Err(e.into())),
            Err(_) => Some(Err(ReadbackError::Lost)),
        }
    }

    /// The bytes, awaited (works on wasm, where the browser completes the mapping; natively
    /// something must poll the device, see [`Self::wait`]).
    pub async fn finish(self) -> Result<Vec<u8>, ReadbackError> {
        self.receiver.await.map_err(|_| ReadbackError::Lost)??;
        finish_read(&self.staging, self.size)
    }

    /// Native only: waits for the bytes.
    #[cfg(not(target_arch = "wasm32"))]
    pub fn wait(self, ctx: &GpuContext) -> Result<Vec<u8>, ReadbackError> {
        ctx.device.poll(wgpu::PollType::wait_indefinitely())?;
        wait_mapped(self.receiver)?;
        finish_read(&self.staging, self.size)
    }
}
